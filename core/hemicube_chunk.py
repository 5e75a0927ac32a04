"""One chunk of hemicubes at a time: eye frames, visible pairs, items, then the rows.

:func:`rows_in_chunks` cuts the sources into chunks sized for memory; for each chunk,
:func:`chunk_rows` puts the scene's distinct corners in every eye frame, drops the pairs that
cannot be seen, sorts the others onto the faces they reach (clipping those that straddle a
face's near plane) and hands them to the rasteriser (:mod:`core.hemicube_raster`); the z-buffer's
items then sum the delta form factors (:mod:`core.hemicube_delta`) into the rows. With a
directional sky (``Scene.sky``, :mod:`core.sky`), the pixels no item covers also give each eye
its light from the sky.
"""

import threading
import time

import numpy as np

from .constants import tol
from .geometry import unique_rows
from .hemicube_delta import flat_delta_form_factors
from .hemicube_raster import F32, FRAG_SLOTS, LITTLE_ENDIAN, ZBuffer, draw_items, pixel_coords
from .parallel import remember_cut, share
from .sky import gathered

#: Work per internal chunk of sources: (source, polygon) pairs and hemicube pixels. Bounded so
#: that the transient arrays of one chunk stay in the tens of megabytes while still amortising
#: NumPy's per-call overhead over many sources.
_CHUNK_PAIRS = 60_000
_CHUNK_PIXELS = 600_000


class Geometry:
    """Source-independent data of the polygons: distinct corners, planes, scene scale."""

    def __init__(self, polys, poly_patch, normals):
        polys = np.ascontiguousarray(polys, dtype=np.float64)             # (Q, 4, 3)
        self.poly_patch = np.asarray(poly_patch, dtype=np.int64)          # (Q,)
        flat = polys.reshape(-1, 3)
        lo, hi = flat.min(0), flat.max(0)
        self.diag = float(np.linalg.norm(hi - lo)) or 1.0
        # Shared corners are transformed once per source, so every polygon sees bit-identical
        # eye-frame coordinates of a shared vertex (no cracks along shared edges).
        first, inverse = unique_rows(flat)
        self.verts = flat[first]
        self.poly_v = inverse.reshape(-1, 4)                              # (Q, 4)
        # Planes oriented along the patch normal: eye above the plane = front-facing.
        n = np.cross(polys[:, 1] - polys[:, 0], polys[:, 2] - polys[:, 0]) \
            + np.cross(polys[:, 2] - polys[:, 0], polys[:, 3] - polys[:, 0])
        n[np.sum(n * normals[self.poly_patch], axis=1) < 0] *= -1.0
        length = np.linalg.norm(n, axis=1)
        n /= np.where(length > 0, length, 1.0)[:, None]
        self.plane_n, self.plane_c = n, np.sum(n * polys[:, 0], axis=1)

    def cut(self, sel, poly_patch):
        """The Geometry of polygons ``sel`` (ascending) alone, their items numbered
        ``poly_patch``: what drawing them alone gives. A polygon's plane is its own; the shared
        corners are those they use, in this one's (sorted) order, found without a sort."""
        g = Geometry.__new__(Geometry)
        g.poly_patch = np.asarray(poly_patch, dtype=np.int64)
        ids = self.poly_v[sel]
        used = np.zeros(self.verts.shape[0], dtype=bool)
        used[ids] = True
        g.verts = self.verts[used]
        g.poly_v = (np.cumsum(used) - 1)[ids]
        g.diag = float(np.linalg.norm(g.verts.max(axis=0) - g.verts.min(axis=0))) or 1.0
        g.plane_n, g.plane_c = self.plane_n[sel], self.plane_c[sel]
        remember_cut(g, self, sel, g.poly_patch)
        return g


class Scene:
    """Per-call constants: the geometry, the resolution's pixel layout, culling, and the sky
    (``sky``: a :class:`core.sky.Sky` whose light the empty pixels gather, or None)."""

    def __init__(self, geometry, n_patches, resolution, cull_back):
        g = self.geometry = geometry
        self.poly_patch, self.verts, self.poly_v = g.poly_patch, g.verts, g.poly_v
        # Corners as (5, Q), the first repeated: edge k runs from corner k to k + 1.
        self.poly_v_t = np.ascontiguousarray(g.poly_v[:, [0, 1, 2, 3, 0]].T)
        self.verts_t = np.ascontiguousarray(g.verts.T)                     # (3, U)
        self.plane_n_t = np.ascontiguousarray(g.plane_n.T)                 # (3, Q)
        self.plane_c, self.diag = g.plane_c, g.diag
        self.near = tol.hemicube_near * g.diag
        self.n_patches = n_patches
        self.r = resolution
        self.npix = 3 * resolution * resolution
        self.cull_back = cull_back
        self.h = 2.0 / resolution
        # Pixel-buffer layout of one hemicube: top R x R, then four sides R/2 x R (row-major).
        r = resolution
        self.face_offset = np.array([0] + [r * r + k * r * r // 2 for k in range(4)], np.int64)
        self.face_rows = np.array([r] + [r // 2] * 4, np.int64)
        self.face_rows_f = self.face_rows.astype(F32)
        self.sky = None

    def tiled(self, s_n):
        """The delta form factors of ``s_n`` hemicubes in buffer order, (s_n 3 R^2,)."""
        n = s_n * self.npix
        tiled = _kept("dff", self.r)
        if tiled is None or tiled.size < n:
            tiled = _keep("dff", self.r, np.tile(flat_delta_form_factors(self.r), s_n))
        return tiled[:n]

    def zbuffer(self, s_n):
        """A cleared z-buffer of ``s_n`` hemicubes plus FRAG_SLOTS cells of padding."""
        n = s_n * self.npix + FRAG_SLOTS
        zbuf = _kept("zbuf", None)
        if zbuf is None or zbuf.size < n:
            zbuf = _keep("zbuf", None, np.empty(n, dtype=np.int64))
        zbuf = zbuf[:n]
        zbuf.fill(0)
        return zbuf


#: Buffers kept across chunks and calls (the z-buffer, the delta form factors tiled over a
#: chunk's hemicubes): mapping megabytes afresh for every chunk costs a page fault per 4 kB,
#: more than filling them. One of each per thread (bakes run in worker threads), and only up
#: to _BUFFER_BYTES each (a chunk's z-buffer up to R = 1024).
_BUFFER_STORE = threading.local()
_BUFFER_BYTES = 1 << 25


def _kept(name, tag):
    """This thread's buffer ``name`` if it was kept with ``tag``, else None."""
    tag_array = getattr(_BUFFER_STORE, name, None)
    return tag_array[1] if tag_array is not None and tag_array[0] == tag else None


def _keep(name, tag, array):
    """Keep ``array`` (returned) as this thread's buffer ``name`` with ``tag``, if small enough."""
    setattr(_BUFFER_STORE, name, (tag, array) if array.nbytes <= _BUFFER_BYTES else None)
    return array


def chunk_rows(sc, eyes, frames, timings, sky_out=None):
    """Form-factor rows of one chunk of sources: (S, 2P). With ``sc.sky``, the sky's light
    through each eye's empty pixels goes into ``sky_out`` (S, 3)."""
    # Divisions by zero, overflow and NaN are expected and masked throughout (edge-on
    # polygons, lines parallel to the rows, vertices on the eye plane).
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
        return _chunk_rows_raw(sc, eyes, frames, timings, sky_out)


def _chunk_rows_raw(sc, eyes, frames, timings, sky_out):
    """:func:`chunk_rows` with floating-point warnings already silenced."""
    tic = time.process_time()
    s_n = eyes.shape[0]
    near, h = sc.near, sc.h
    n_u = sc.verts.shape[0]
    tv = sc.poly_v

    # 1. Unique vertices in every eye frame (S, U); each vertex is classified once per source
    # into the face whose pyramid holds it (-1: below the horizon or nearer than the near
    # plane) and given pixel coordinates on that face.
    # einsum, not matmul: BLAS would run these thin products on several threads.
    eye_c = np.einsum("sij,sj->si", frames, eyes)
    # float32 from here: relative 6e-8 of the scene size is far below a pixel's footprint.
    vx, vy, vz = ((np.einsum("sj,ju->su", frames[:, k], sc.verts_t) - eye_c[:, k:k + 1])
                  .astype(F32) for k in range(3))
    pj, pi, pw, face = pixel_coords(vx, vy, vz, None, h)
    ok = (pw >= near) & (vz >= 0)
    cls = ((face + 1) * ok - 1).astype(np.int8).ravel()
    pjiw = np.stack([pj.ravel(), pi.ravel(), pw.ravel()])                # (3, S U)

    # Pairs: not wholly below the near plane, not edge-on, optionally not back-facing.
    top_z = np.maximum.reduce([np.take(vz, tv[:, k], axis=1) for k in range(4)])
    dist = np.einsum("sj,jq->sq", eyes, sc.plane_n_t) - sc.plane_c        # eye above plane
    keep = (top_z >= near) & (dist != 0.0)
    if sc.cull_back:
        keep &= dist > 0.0
    ps, pt = np.nonzero(keep)
    back = dist[ps, pt] < 0.0
    # (5, pairs) flat vertex ids; take keeps the result C-ordered (a[:, idx] would not, and
    # reductions over its first axis would then run a 4-long inner loop per pair).
    vid = ps * n_u + np.take(sc.poly_v_t, pt, axis=1)
    c0 = cls[vid[0]]
    single = (c0 == cls[vid[1]]) & (c0 == cls[vid[2]]) & (c0 == cls[vid[3]]) & (c0 >= 0)
    q_fast = np.flatnonzero(single)
    q_gen = np.flatnonzero(~single)
    t1 = time.process_time()

    # 2. Items. Polygons inside one face's pyramid (convex) go to that face only. The others
    # are tested against every face: wholly in front of its near plane -> the same rasteriser
    # (the face's bounds crop them), straddling it -> clipped (general items).
    verts = np.take(pjiw, np.take(vid, q_fast, axis=1), axis=1)           # (3, 5, n)
    face = c0[q_fast].astype(np.int64)
    (face_s, pair_s, verts_s), general = _split_general(
        sc, np.take(vid, q_gen, axis=1), q_gen, vx.ravel(), vy.ravel(), vz.ravel())
    t2 = time.process_time()

    # 3. Row spans, drawn into the z-buffer as they are made (4.). Items are numbered in the
    # order of item_pair (the tie rule depends on it).
    zb = ZBuffer(sc.zbuffer(s_n), timed=timings is not None)
    n_rows, n_frag = draw_items(zb, verts, face, q_fast, ps, 0, sc)
    n = draw_items(zb, verts_s, face_s, pair_s, ps, q_fast.size, sc)
    n_rows, n_frag = n_rows + n[0], n_frag + n[1]
    item_pair = [q_fast, pair_s]
    zb_spans = zb.seconds
    t3 = time.process_time()
    if general is not None:
        face_g, pair_g, verts_g, bbox = general
        n = draw_items(zb, verts_g, face_g, pair_g, ps, q_fast.size + pair_s.size, sc,
                        near_line=True, bbox=bbox)
        n_rows, n_frag = n_rows + n[0], n_frag + n[1]
        item_pair.append(pair_g)
    item_pair = np.concatenate(item_pair)
    zb.flush()
    fill_cracks(zb.keys, s_n, sc)
    t4 = time.process_time()
    # The z-buffer is drawn while spans are made: reported apart.
    t3, t4 = t3 - zb_spans, t4 - zb.seconds
    t5 = t4 + zb.seconds

    # 5. Accumulate delta form factors per item, then items into their (source, node) cell.
    # |low word of a key| is the item (negated in odd cells for the tie rule; 0: empty).
    n_cols = 2 * sc.n_patches
    n_cells = s_n * sc.npix
    low = zb.keys.view(np.int32)[0 if LITTLE_ENDIAN else 1::2][:n_cells]
    per_item = np.bincount(np.abs(low).astype(np.intp), weights=sc.tiled(s_n),
                           minlength=item_pair.size + 1)[1:]              # item 0: nothing
    cell = ps[item_pair] * n_cols + sc.poly_patch[pt[item_pair]] + sc.n_patches * back[item_pair]
    out = np.bincount(cell, weights=per_item, minlength=s_n * n_cols)
    t6 = time.process_time()
    if sc.sky is not None:
        sky_out[:] = gathered(sc.sky, frames, (low == 0).reshape(s_n, sc.npix),
                              sc.tiled(1))
    t7 = time.process_time()
    if timings is not None:
        for name, dt in (("cull", t1 - tic), ("items", t2 - t1), ("spans", t3 - t2),
                         ("general", t4 - t3), ("zbuffer", t5 - t4), ("accumulate", t6 - t5),
                         ("sky", t7 - t6)):
            timings[name] = timings.get(name, 0.0) + dt
        for name, n in (("pairs", ps.size), ("general_pairs", q_gen.size),
                        ("items", item_pair.size), ("rows", n_rows),
                        ("fragments", n_frag)):
            timings["n_" + name] = timings.get("n_" + name, 0) + int(n)
    return out.reshape(s_n, n_cols)


def _split_general(sc, vid, q_gen, vx, vy, vz):
    """Sort the pairs ``q_gen`` (not inside one pyramid) onto faces.

    Parameters
    ----------
    sc : Scene
    vid : (5, g) int
        Flat vertex ids (source * U + vertex) of the pairs' corners, the first repeated.
    q_gen : (g,) int
        The pairs.
    vx, vy, vz : (S U,) float32
        Eye-frame coordinates of the chunk's vertices.

    Returns
    -------
    items : (face (n,), pair (n,), verts (3, 5, n))
        Items wholly in front of their face's near plane and overlapping the face (the
        rasteriser crops them to the face), face by face.
    general : (face (m,), pair (m,), verts (3, 5, m), (imin (m,), imax (m,))) or None
        Items straddling their face's near plane and overlapping the face once clipped there,
        with the projected row interval of the clipped polygon.
    """
    near, h, width = sc.near, sc.h, sc.r
    xyz = (vx[vid], vy[vid], vz[vid])                                     # (5, g) each
    items, general = [], []
    for face in range(5):
        n_rows = float(sc.face_rows[face])
        jiw = np.stack(pixel_coords(*xyz, face, h))                      # (3, 5, g)
        w = jiw[2]
        wmin, wmax = np.minimum.reduce(w), np.maximum.reduce(w)
        front = np.flatnonzero(wmin >= near)
        sub = np.take(jiw, front, axis=2)
        pj = sub[0] / sub[2]
        pi = sub[1] / sub[2]
        hit = (np.minimum.reduce(pj) <= width - 0.5) & (np.maximum.reduce(pj) >= -0.5) \
            & (np.minimum.reduce(pi) <= n_rows - 0.5) & (np.maximum.reduce(pi) >= -0.5)
        sel = np.flatnonzero(hit)
        items.append((np.full(sel.size, face, dtype=np.int64), q_gen[front[sel]],
                      np.take(sub, sel, axis=2)))
        cut = np.flatnonzero((wmin < near) & (wmax >= near))
        if cut.size:
            sub = np.take(jiw, cut, axis=2)
            # Most of these (polygons crossing the eye's plane, seen through the sides) lie
            # wholly beyond one of the planes through the eye and the face's borders: dropped
            # before clipping, with a margin far above rounding so that the clipped test
            # below would drop them too.
            j, i, w = sub[:, :4]
            margin = F32(_PYRAMID_MARGIN) * np.maximum.reduce(np.abs(j) + np.abs(i) + np.abs(w))
            beyond = (np.maximum.reduce(j + 0.5 * w) < -margin) \
                | (np.minimum.reduce(j - (width - 0.5) * w) > margin) \
                | (np.maximum.reduce(i + 0.5 * w) < -margin) \
                | (np.minimum.reduce(i - (n_rows - 0.5) * w) > margin)
            near_cut = np.flatnonzero(~beyond)
            cut, sub = cut[near_cut], np.take(sub, near_cut, axis=2)
            lo, hi = _clipped_bbox(sub, near)
            hit = (lo[0] <= width - 0.5) & (hi[0] >= -0.5) \
                & (lo[1] <= n_rows - 0.5) & (hi[1] >= -0.5)
            keep = np.flatnonzero(hit)
            if keep.size:
                general.append((np.full(keep.size, face, dtype=np.int64), q_gen[cut[keep]],
                                np.take(sub, keep, axis=2), lo[1][keep], hi[1][keep]))
    items = tuple(np.concatenate(part, axis=-1) for part in zip(*items))
    if not general:
        return items, None
    face, pair, verts, lo, hi = (np.concatenate(part, axis=-1) for part in zip(*general))
    return items, (face, pair, verts, (lo, hi))


#: Relative margin (of a polygon's largest |J| + |I| + |W|) by which all its corners must lie
#: beyond a plane of a face's pyramid for it to be dropped from that face unclipped; float32
#: rounding of the clipped bounding box is ~1e-6 of that.
_PYRAMID_MARGIN = 1e-4


def _clipped_bbox(verts, near):
    """Projected bounding box (lo (J, I), hi (J, I)) of polygons clipped at W = near, float64.

    ``verts``: (3, 5, n) (J, I, W) of the corners, the first repeated; at least one corner is
    in front. The clipped polygon's corners are the front corners and the crossings of the
    edges with the near plane (at W = near exactly, so projected by dividing by near).
    """
    a, b = verts[:, :4], verts[:, 1:]                                     # edge k: a -> b
    front_a, front_b = a[2] >= near, b[2] >= near
    crosses = front_a != front_b
    t = (near - a[2]) / (b[2] - a[2])
    lo, hi = [], []
    for c in range(2):
        proj = np.where(front_a, a[c] / a[2], np.nan)
        cut = np.where(crosses, (a[c] + t * (b[c] - a[c])) / near, np.nan)
        lo.append(np.fmin.reduce(np.fmin(proj, cut)).astype(np.float64))
        hi.append(np.fmax.reduce(np.fmax(proj, cut)).astype(np.float64))
    return lo, hi


def fill_cracks(keys, s_n, sc):
    """Fill the empty pixels of ``s_n`` hemicubes' z-buffer ``keys`` whose four neighbours on
    their face are all drawn, with the nearest neighbour's fragment (in place).

    Polygons that share an edge leave no gap (the rasteriser's spans; module doc of
    :mod:`core.hemicube_raster`), but the patches of an adaptive hierarchy meet at T-junctions:
    a corner of one patch lies on the edge of its coarser neighbour, and the edges of the two
    sides are different lines that agree only up to rounding. A pixel centre on such a junction
    can fall between both, and the hemicube sees through a closed room there (measured: one top
    pixel, 0.22 % of a floor patch's row at R = 16, 4e-6 of the emitted power escaped a closed
    room). An opening that leaves a single pixel empty with all four neighbours drawn is below
    the resolution anyway: it is read as its nearest neighbour, like the crack.
    """
    cells = keys[:s_n * sc.npix].reshape(s_n, sc.npix)
    r = sc.r
    for off, rows in zip(sc.face_offset, sc.face_rows):          # five faces
        face = cells[:, off:off + rows * r].reshape(s_n, rows, r)
        inner = face[:, 1:-1, 1:-1]
        up, down = face[:, :-2, 1:-1], face[:, 2:, 1:-1]
        left, right = face[:, 1:-1, :-2], face[:, 1:-1, 2:]
        hole = (inner == 0) & (up != 0) & (down != 0) & (left != 0) & (right != 0)
        if hole.any():
            s, i, j = np.nonzero(hole)
            near = np.maximum.reduce([up[s, i, j], down[s, i, j], left[s, i, j],
                                      right[s, i, j]])
            face[s, i + 1, j + 1] = near


def rows_in_chunks(sc, eyes, frames, out, timings, sky_out=None):
    """Fill ``out`` (S, 2P) with the rows of every eye, in chunks sized for memory; shared among
    worker processes when a bake uses them (:mod:`core.parallel`; not when ``timings`` are
    being taken). With ``sc.sky``, ``sky_out`` (S, 3) gets each eye's light from the sky."""
    if timings is None and share(sc, eyes, frames, out, sky_out):
        return
    _prime_allocator()
    chunk = max(1, min(_CHUNK_PAIRS // sc.poly_v.shape[0], _CHUNK_PIXELS // sc.npix))
    for start in range(0, eyes.shape[0], chunk):
        stop = min(start + chunk, eyes.shape[0])
        out[start:stop] = chunk_rows(sc, eyes[start:stop], frames[start:stop], timings,
                                     None if sky_out is None else sky_out[start:stop])


#: A chunk allocates and frees some 20 MB of temporaries. glibc's malloc returns freed memory
#: at the top of its heap to the system once more than its trim threshold (initially 128 kB)
#: is free there, and every chunk then pays a page fault per 4 kB to get it back: a fifth of
#: the run time at R = 64. glibc raises that threshold to twice the size of any freed block
#: it had mapped apart (up to 32 MB, see mallopt(3), M_MMAP_THRESHOLD), so freeing one such
#: block once keeps the chunks' memory in the process. Elsewhere (another malloc) it only
#: costs one allocation.
_ALLOCATOR_PRIME_BYTES = 16 << 20
_PRIMED = []


def _prime_allocator():
    """Allocate and free one _ALLOCATOR_PRIME_BYTES block, once per process."""
    if not _PRIMED:
        np.empty(_ALLOCATOR_PRIME_BYTES, dtype=np.uint8)
        _PRIMED.append(True)
