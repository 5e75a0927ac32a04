"""Hemisphere-base projection form factors: the Nusselt analog (Doi & Itoh 1998), vectorised.

From an eye at a source node's centre (local frame: z along the viewing normal), every polygon
is projected onto the unit hemisphere and then orthographically onto the hemisphere's base, the
unit disk; the form factor of what is visible is its projected area divided by pi (Nusselt's
analog). The base square [-1, 1]^2 is an R x R pixel grid; the pixels whose centres lie inside
the disk are counted, each with the same weight 1 / (their number), so a closed scene sums to 1.

Curved edges. A polygon edge projects to an arc of a great circle, which the base shows as an
arc of an ellipse. Pixels are tested against the great circles themselves: pixel (x, y) is the
direction d = (x, y, sqrt(1 - x^2 - y^2)), inside a convex polygon (seen from the eye) when
``s (v_k x v_k+1) . d >= 0`` for every edge (v_k its corners in the eye frame, s the polygon's
winding as seen from the eye). This is the exact curved projection at the cost of straight edge
functions (one more product per edge, with d_z from a table), so polygons need neither the
triangle subdivision that straight-edged rasterisation of the projection needs (Doi & Itoh) nor
a clip to the horizon: pixels exist only above it. The edge normal of an edge shared by two
polygons is the same product with its factors swapped, i.e. bit for bit its negation, so the
two sides classify every pixel complementarily: a closed mesh leaves no crack (a pixel exactly
on the edge goes to both, and the z-buffer keeps one).

Per chunk of sources (array operations over the chunk; the Python loops run over chunks, groups
of items of equal padded box size, blocks of pixels and a polygon's four edges):

1. *Pairs*: every distinct corner is put in each eye frame once; (source, polygon) pairs with no
   corner above the horizon or seen edge-on are dropped; a polygon seen from behind its patch
   normal is routed to the back node q + P.
2. *Bounding boxes* of each pair's projection above the horizon: the box of the projected
   corners widened by the arcs' sagitta for polygons wholly above the horizon, the exact box
   (:func:`_bounds`) for those that cross it.
3. *Pixel tests*: items are grouped by box size padded to a few sizes, and each group is tested
   as a (rows, columns, items) broadcast against the items' edge normals (no per-pixel gather of
   an item's data); depth is the exact inverse distance along the pixel's direction,
   ``1/t = g . d`` with ``g`` the polygon's plane seen from the eye.
4. *Z-buffer*: 64-bit keys, the float32 bits of 1/t (high) and the item (low); ``np.maximum.at``
   keeps the nearest per pixel. Depth ties are shared between the two polygons by pixel parity,
   as in :mod:`core.hemicube_raster`.
5. *Accumulate*: ``np.bincount`` counts each item's pixels, then the items into their (source,
   node) cells.

Accuracy and cost against the hemicube: ``tests/core/test_nusselt.py``, ``bench/bench_nusselt.py``.
"""

import numpy as np

from .hemicube import check_resolution, drawn_polygons, eye_frames, make_rng, patch_geometry
from .validate import check_bool, check_sources

#: Work per chunk of sources: (source, polygon) pairs (the pair arrays are about 400 bytes per
#: pair: 24 MB) and z-buffer pixels (8 bytes each). Same bounds as the hemicube's chunks.
_CHUNK_PAIRS = 60_000
_CHUNK_PIXELS = 600_000

#: Pixels tested at once (about 40 bytes each in flight: 10 MB); the box of an item larger
#: than that is tested in bands of rows.
_FRAGMENT_BLOCK = 1 << 18

#: Slack (in pixels) on each side of a bounding box. The box is computed in float64 (error
#: ~1e-13 pixel) but pixels are tested in float32 (a pixel within ~1e-5 pixel of an edge may be
#: classified either way): a pixel that the float32 test puts inside must lie in the box, or
#: the polygon on the other side of the edge, which classifies it as outside, leaves a crack.
_BOX_SLACK = 1e-3

#: Low mantissa bits of the float32 1/t cleared in the key, so that two polygons meeting at a
#: pixel tie exactly and the pixels along their meeting line are shared alternately (tie to
#: the larger item in even pixels, the smaller in odd ones): 2^-19 = 2e-6 relative depth
#: resolution is left (as the hemicube, see core.hemicube_raster._DEPTH_DROP).
_DEPTH_DROP = 4
_DEPTH_MASK = np.int64((1 << 31) - (1 << _DEPTH_DROP))
_LOW_WORD = np.int64((1 << 32) - 1)

#: Smallest 1/t stored: a pixel that passes every edge test of a polygon whose plane it grazes
#: may get 1/t <= 0 by rounding (a hit at near-infinite distance); it must still count as a hit.
_MIN_INV_DEPTH = np.float32(1e-30)

F32 = np.float32


def base_pixels(resolution):
    """The pixels of the base square and which of them count.

    Returns
    -------
    inside : (R^2,) bool
        Pixel ``i R + j`` (row i along y, column j along x) has its centre inside the unit disk.
    x_col, y_row : (R,) float32
        Centre coordinates of the columns and of the rows.
    z_pix : (R^2,) float32
        sqrt(1 - x^2 - y^2) of each pixel centre: its direction on the hemisphere is
        (x, y, z); NaN outside the disk.
    count : int
        Number of counted pixels (each weighs 1 / count).
    """
    r = check_resolution(resolution)
    c = -1.0 + (np.arange(r) + 0.5) * (2.0 / r)
    r2 = (c[None, :] ** 2 + c[:, None] ** 2).ravel()
    inside = r2 < 1.0                              # never = 1: x, y are odd multiples of 1/R
    with np.errstate(invalid="ignore"):
        z_pix = np.sqrt(np.where(inside, 1.0 - r2, np.nan)).astype(F32)
    return inside, c.astype(F32), c.astype(F32), z_pix, int(inside.sum())


def nusselt_rows(patches, sources, *, resolution=64, rotate=False, rng=None):
    """Form-factor rows of source nodes by hemisphere-base projection (the Nusselt analog).

    Parameters
    ----------
    patches : Patches
        From :func:`core.patches.make_patches` (uses ``centres``, ``normals``, ``corners``;
        non-planar or concave quads are drawn as their triangles, as by the hemicube).
    sources : (S,) int
        Node ids in [0, 2P): node p looks along the normal of patch p, node p + P along its
        opposite, both from the patch centre (offset by ``tol.surface_offset`` x scene diagonal
        along the viewing direction so that coplanar neighbours are not seen).
    resolution : int, optional
        R, even, 2 <= R <= 2048: the base square is R x R pixels, of which about
        pi R^2 / 4 (those with their centre inside the unit disk) are counted.
    rotate : bool, optional
        Rotate each eye frame about its normal by a uniform random angle drawn from ``rng``
        (one per source, in order), which turns aliasing into unbiased noise.
    rng : numpy.random.Generator or int, optional
        Required when ``rotate`` is True.

    Returns
    -------
    (S, 2P) float64
        Row s: fraction of the energy leaving source s that reaches each node (front q, back
        q + P). A row sums to 1 minus the escaped fraction; every entry is a whole number of
        pixels over the counted pixels.

    Notes
    -----
    The source is a point (its centre), as for the hemicube: the same proximity error for
    patches near each other relative to their size. Pixels have equal form-factor weight, so
    their angular size grows towards the horizon (a ring of pixels at the rim spans 14 degrees
    of elevation at R = 64): small patches low over the horizon alias more than on a hemicube.
    Cost: see ``bench/bench_nusselt.py``.
    """
    centres, normals, corners = patch_geometry(patches)
    resolution = check_resolution(resolution)
    n_patches = centres.shape[0]
    src = check_sources(sources, 2 * n_patches)
    check_bool("rotate", rotate)
    angles = make_rng(rng).uniform(0.0, 2.0 * np.pi, size=src.size) if rotate else None
    out = np.zeros((src.size, 2 * n_patches))
    if src.size == 0:
        return out
    _, _, geometry = drawn_polygons(patches, normals)
    eyes, frames = eye_frames(centres, normals, corners, src, n_patches, geometry.diag, angles)
    pixels = base_pixels(resolution)
    n_poly = geometry.poly_v.shape[0]
    chunk = max(1, min(_CHUNK_PAIRS // n_poly, _CHUNK_PIXELS // resolution ** 2))
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        for start in range(0, src.size, chunk):
            stop = min(start + chunk, src.size)
            out[start:stop] = _chunk_rows(geometry, n_patches, pixels, resolution,
                                          eyes[start:stop], frames[start:stop])
    return out


def _cross(a, b):
    """a x b of (3, ...) component stacks, in a fixed order of operations, so that
    ``_cross(b, a)`` is bit for bit ``-_cross(a, b)`` (IEEE: x - y == -(y - x))."""
    return np.stack([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                     a[0] * b[1] - a[1] * b[0]])


def _chunk_rows(geo, n_patches, pixels, r, eyes, frames):
    """Rows (S, 2P) of one chunk of eyes (S, 3) with frames (S, 3, 3)."""
    s_n = eyes.shape[0]
    n_u = geo.verts.shape[0]
    # 1. Distinct corners in every eye frame, (S, U) each (einsum, not matmul: BLAS would run
    # these thin products on several threads); float32 from here, as in the hemicube.
    eye_c = np.einsum("sij,sj->si", frames, eyes)
    v64 = [np.einsum("sj,uj->su", frames[:, k], geo.verts) - eye_c[:, k:k + 1]
           for k in range(3)]
    v32 = [a.astype(F32).ravel() for a in v64]
    norm = np.sqrt(v64[0] ** 2 + v64[1] ** 2 + v64[2] ** 2)
    u32 = [(a / norm).astype(F32).ravel() for a in v64]
    poly_v = np.ascontiguousarray(geo.poly_v.T)                           # (4, Q)
    corner_z = [np.take(v32[2].reshape(s_n, n_u), poly_v[k], axis=1) for k in range(4)]
    dist = np.einsum("sj,qj->sq", eyes, geo.plane_n) - geo.plane_c       # > 0: seen from front
    ps, pt = np.nonzero((np.maximum.reduce(corner_z) > 0) & (dist != 0.0))
    back = dist[ps, pt] < 0.0
    above = np.minimum.reduce(corner_z)[ps, pt] >= 0
    # (4, n) flat vertex ids of the pairs' corners, the first repeated (edge k: k -> k + 1).
    flat = ps * n_u + np.take(poly_v[[0, 1, 2, 3, 0]], pt, axis=1)
    v = np.stack([np.take(a, flat) for a in v32])                         # (3, 5, n)

    # Edge normals, oriented so that the polygon's inside is >= 0 (a triangle's repeated corner
    # gives a zero edge, which constrains nothing), unit length. Depth: the polygon's plane
    # N . x = det in the eye frame, N = sum_k v_k x v_k+1 (Newell), so 1/t = (N / det) . d.
    raw = _cross(v[:, :4], v[:, 1:])                                      # (3, 4, n)
    newell = raw.sum(axis=1)
    det = np.einsum("kn,kn->n", newell, v[:, 0])
    length = np.sqrt(raw[0] * raw[0] + raw[1] * raw[1] + raw[2] * raw[2])  # same for -raw
    c = raw * (np.sign(det) / np.where(length > 0, length, 1))
    params = np.concatenate([c.reshape(12, -1), newell / det])           # (15, n) float32
    params[:, det == 0] = np.nan                  # edge-on or degenerate: covers no pixel

    # 2. Bounding boxes in pixels: padded corner boxes for polygons above the horizon, exact
    # ones for those that cross it.
    box = _padded_bounds(np.stack([np.take(a, flat) for a in u32]), r)
    cut = np.flatnonzero(~above)
    if cut.size:
        v_cut = np.stack([np.take(a.ravel(), flat[:, cut]) for a in v64])
        exact = _bounds(v_cut[:, :4], v_cut[:, 1:], _cross(v_cut[:, :4], v_cut[:, 1:]),
                        c[:, :, cut], r)
        for whole, part in zip(box, exact):
            whole[cut] = part

    # 3.-4. The pixels of the boxes, tested and drawn group by group.
    keys = np.zeros(s_n * r * r, dtype=np.int64)
    for idx, offset, rows, cols in _groups(*box):
        _draw(keys, pixels, r, idx, offset, rows, cols, *box, ps, params)

    # 5. Pixels per item, items into (source, node) cells.
    low = keys & _LOW_WORD
    cell = np.arange(keys.size)
    item = np.where(cell & 1, (np.int64(1 << 32) - low) & _LOW_WORD, low)
    per_item = np.bincount(item, minlength=ps.size + 1)[1:]
    n_cols = 2 * n_patches
    target = ps * n_cols + geo.poly_patch[pt] + n_patches * back
    out = np.bincount(target, weights=per_item, minlength=s_n * n_cols)
    return out.reshape(s_n, n_cols) / pixels[4]


def _padded_bounds(u, r):
    """Pixel boxes [j0, j1, i0, i1], (n,) int64 each, of polygons wholly above the horizon.

    An edge's arc between unit corners a and b lies within its sagitta, 1 - cos(theta / 2) <=
    (1 - a . b) / 2, of the chord; the base projection shortens distances. So the box of the
    projected corners, widened by the largest such bound over the edges, holds the polygon.

    u : (3, 5, n) float32, the corners' unit directions (the first repeated).
    """
    dot = np.einsum("ken,ken->en", u[:, :4], u[:, 1:])
    pad = 0.5 * (1 - np.minimum.reduce(dot))
    return _pixel_range(np.minimum.reduce(u[0, :4]) - pad, np.maximum.reduce(u[0, :4]) + pad,
                        np.minimum.reduce(u[1, :4]) - pad, np.maximum.reduce(u[1, :4]) + pad,
                        r)


def _pixel_range(x_lo, x_hi, y_lo, y_hi, r):
    """Columns j0..j1 and rows i0..i1 of the pixel centres within [x_lo, x_hi] x [y_lo, y_hi],
    widened by _BOX_SLACK pixels: [j0, j1, i0, i1], empty when j1 < j0 or i1 < i0."""
    h = 2.0 / r
    out = []
    for lo, hi in ((x_lo, x_hi), (y_lo, y_hi)):
        # NaN (a corner at the eye itself, not a direction): the whole base.
        lo = (np.nan_to_num(np.asarray(lo, np.float64), nan=-1.0) + 1.0) / h - 0.5 - _BOX_SLACK
        hi = (np.nan_to_num(np.asarray(hi, np.float64), nan=1.0) + 1.0) / h - 0.5 + _BOX_SLACK
        out.append(np.clip(np.ceil(lo), 0, r).astype(np.int64))
        out.append(np.clip(np.floor(hi), -1, r - 1).astype(np.int64))
    return out


#: Box sizes (pixels, per axis) that items are padded to, so that each group of equal padded
#: size is tested as one (rows, columns, items) broadcast with no per-pixel gathers of the items'
#: edges: exact up to 4, then steps of at most 1.5x (the padding wastes at most half the pixels
#: of an axis; most items in a room at R = 64 are 1-3 pixels wide).
_SIZES = np.array([1, 2, 3, 4, 6, 8, 12, 16, 24, 32, 48, 64, 96, 128, 192, 256, 384, 512, 768,
                   1024, 1536, 2048])


def _groups(j0, j1, i0, i1):
    """Items by padded box size, at most _FRAGMENT_BLOCK pixels at a time: yields (items (m,)
    int64, first row offset, rows, columns); a box larger than that comes in bands of rows."""
    rows, cols = i1 - i0 + 1, j1 - j0 + 1
    live = np.flatnonzero((rows > 0) & (cols > 0))
    if live.size == 0:
        return
    key = np.searchsorted(_SIZES, rows[live]) * _SIZES.size + np.searchsorted(_SIZES, cols[live])
    order = np.argsort(key, kind="stable")
    live, key = live[order], key[order]
    bounds = np.flatnonzero(np.diff(key)) + 1
    for start, stop in zip(np.r_[0, bounds], np.r_[bounds, key.size]):
        n_rows, n_cols = (int(_SIZES[k]) for k in divmod(int(key[start]), _SIZES.size))
        band = min(n_rows, max(1, _FRAGMENT_BLOCK // n_cols))
        step = max(1, _FRAGMENT_BLOCK // (band * n_cols))
        for a in range(start, stop, step):
            for offset in range(0, n_rows, band):
                yield live[a:min(a + step, stop)], offset, min(band, n_rows - offset), n_cols


def _draw(keys, pixels, r, idx, offset, n_rows, n_cols, j0, j1, i0, i1, ps, params):
    """Test the (n_rows, n_cols) pixels from rows i0 + offset, columns j0 of the boxes of items
    ``idx`` against their edges and draw the hits into ``keys``.

    Padding past a box (clamped to the grid: it repeats the last row or column) needs no mask:
    a pixel outside the box is outside the polygon and fails its edge tests, and a repeated one
    is drawn twice with the same key. Pixels outside the disk have d_z = NaN, which fails every
    comparison.
    """
    _, x_col, y_row, z_pix, _ = pixels
    col = np.minimum(j0[idx] + np.arange(n_cols)[:, None], r - 1)        # (W, m)
    row = np.minimum(i0[idx] + offset + np.arange(n_rows)[:, None], r - 1)  # (H, m)
    pix = (row * r)[:, None] + col                                        # (H, W, m)
    dx, dy, dz = x_col[col], y_row[row][:, None], np.take(z_pix, pix)
    p = params[:, idx]
    worst = None
    for e in range(4):
        edge = p[e] * dx + p[4 + e] * dy                                  # (H, W, m)
        edge += p[8 + e] * dz
        worst = edge if worst is None else np.minimum(worst, edge, out=worst)
    hit = np.flatnonzero(worst >= 0)                                      # NaN: False
    inv = p[12] * dx + p[13] * dy
    inv += p[14] * dz
    owner = idx[hit % idx.size]
    pix, inv = pix.ravel()[hit], inv.ravel()[hit]
    np.maximum(inv, _MIN_INV_DEPTH, out=inv)
    depth = inv.view(np.int32).astype(np.int64) & _DEPTH_MASK
    cell = ps[owner] * (r * r) + pix
    item = owner + 1                                                      # 0: empty pixel
    low = np.where(cell & 1, (np.int64(1 << 32) - item) & _LOW_WORD, item)
    np.maximum.at(keys, cell, (depth << 32) | low)


def _bounds(a, b, raw, c, r):
    """Pixel boxes [j0, j1, i0, i1] of polygons' projections above the horizon, exactly.

    The extremes of x and y over a convex spherical polygon cut at the horizon lie at: its
    corners above the horizon; the points where its edges cross the horizon; the stationary
    points of x and y along its edge arcs (the direction e projected into the edge's plane,
    ``e - (e . m) m`` with m the plane's unit normal, when that lies within the arc); and the
    rim points (+-1, 0), (0, +-1) when they lie inside the polygon.

    Parameters
    ----------
    a, b : (3, 4, n) float64
        Eye-frame corners of each polygon's edges: edge k runs from a[:, k] to b[:, k].
    raw : (3, 4, n) float64
        a x b.
    c : (3, 4, n) float
        The edge normals oriented to the polygon's inside (0 for a degenerate edge).
    r : int
    """
    xs, ys, valid = [], [], []
    norm = np.sqrt(np.einsum("ken,ken->en", a, a))
    xs.append(a[0] / norm), ys.append(a[1] / norm), valid.append(a[2] >= 0.0)
    crosses = (a[2] >= 0.0) != (b[2] >= 0.0)
    t = a[2] / (a[2] - b[2])
    px, py = a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])
    pn = np.hypot(px, py)
    xs.append(px / pn), ys.append(py / pn), valid.append(crosses & (pn > 0.0))
    length = np.sqrt(np.einsum("ken,ken->en", raw, raw))
    m = raw / length
    for axis in range(2):
        e = np.zeros((3, 1, 1))
        e[axis] = 1.0
        p = e - m[axis] * m
        p /= np.sqrt(np.einsum("ken,ken->en", p, p))
        after_a = np.einsum("ken,ken->en", _cross(a, p), raw)
        before_b = np.einsum("ken,ken->en", _cross(p, b), raw)
        ok = (length > 0.0) & np.isfinite(p[0])
        for sign in (1.0, -1.0):                                        # p and -p
            xs.append(sign * p[0]), ys.append(sign * p[1])
            valid.append(ok & (sign * after_a >= 0.0) & (sign * before_b >= 0.0)
                         & (sign * p[2] >= 0.0))
    n = a.shape[2]
    for axis in range(2):
        for sign in (1.0, -1.0):
            xs.append(np.full((1, n), sign if axis == 0 else 0.0))
            ys.append(np.full((1, n), sign if axis == 1 else 0.0))
            valid.append(np.all(sign * c[axis] >= 0.0, axis=0, keepdims=True))
    xs, ys, valid = (np.concatenate(part, axis=0) for part in (xs, ys, valid))
    return _pixel_range(np.where(valid, xs, np.inf).min(axis=0),
                        np.where(valid, xs, -np.inf).max(axis=0),
                        np.where(valid, ys, np.inf).min(axis=0),
                        np.where(valid, ys, -np.inf).max(axis=0), r)
