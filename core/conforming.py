"""Conforming output of the element hierarchy: convex-ring triangulation, the hanging-midpoint
templates, interpolation weights over the user's faces, and the OutputMesh.

Pure geometry (no light): :mod:`core.hierarchy` builds the leaves; this module turns leaves whose
edges carry a neighbour's point into triangles over their own boundary points only (no Steiner
points, so every output vertex is an element vertex the driver has a value for), and expresses
every output corner against the scene's corners for the writer.
"""

import numpy as np

from .geometry import quads_convex, ragged, split_concave_quads, triangulate_polygon
from .outmesh import OutputMesh

#: Sine of the turn at a ring vertex below which the vertex counts as flat (a point lying on the
#: straight edge between its neighbours, i.e. a hanging point). Rounding of points placed on an
#: edge leaves sines around 1e-15; a genuine element corner is many orders of magnitude above.
FLAT_SINE = 1e-9

#: Point-triangle pairs evaluated at once by parent_weights (memory: ~0.5 kB per pair).
PAIR_CHUNK = 1 << 20


def clip_convex_rings(pos, count, normals, flat=None):
    """Triangulate convex polygons, some of whose vertices lie on straight edges, without new
    points and without zero-area triangles.

    Ear clipping in vectorised rounds (one Python iteration per removed vertex, over all rings at
    once): each round clips, in every ring, a strictly convex vertex, preferring one next to a
    flat vertex (clipping it makes that flat vertex a strict corner, so the number of strict
    corners never drops below three and no ear is ever degenerate), then the best-shaped ear.

    Parameters
    ----------
    pos : (n, K, 3) float64
        Ring vertices, counter-clockwise about ``normals``; slots ``>= count`` are ignored.
    count : (n,) int64
        Vertices per ring (3..K).
    normals : (n, 3) float64
        Unit normal of each ring.
    flat : (n, K) bool, optional
        Vertices known to lie on the edge between their neighbours (hanging points). Given, the
        flatness is tracked combinatorially (a clipped vertex's neighbours become corners), so
        points off their line by input rounding (float32 coordinates) never form a sliver ear;
        by default it comes from the turn at each vertex (``FLAT_SINE``).

    Returns
    -------
    tris : (T, 3) int64
        Local vertex slots of the triangles, counter-clockwise like the ring.
    owner : (T,) int64
        Ring of each triangle (``count[i] - 2`` triangles per ring, grouped by round, not ring).
    """
    pos = np.asarray(pos, dtype=np.float64)
    n, K = pos.shape[:2]
    count = np.asarray(count, dtype=np.int64)
    ring = np.broadcast_to(np.arange(K), (n, K)).copy()
    known = flat is not None
    flag = np.asarray(flat, dtype=bool).copy() if known else None
    c = count.copy()
    out_t, out_o = [], []
    active = np.flatnonzero(c >= 3)
    j = np.arange(K)
    while active.size:
        done = c[active] == 3
        out_t.append(ring[active[done], :3])
        out_o.append(active[done])
        act = active[~done]
        if act.size == 0:
            break
        r, cc = ring[act], c[act][:, None]
        ip, inx = (j - 1) % cc, (j + 1) % cc
        rp, rn = np.take_along_axis(r, ip, axis=1), np.take_along_axis(r, inx, axis=1)
        rows = act[:, None]
        P, Pp, Pn = pos[rows, r], pos[rows, rp], pos[rows, rn]
        e1, e2, e3 = P - Pp, Pn - P, Pp - Pn
        l1, l2, l3 = (np.linalg.norm(e, axis=2) for e in (e1, e2, e3))
        tiny = np.finfo(float).tiny
        sine = np.einsum("ikj,ij->ik", np.cross(e1, e2), normals[act]) / np.maximum(l1 * l2, tiny)
        in_ring = j[None, :] < cc
        if known:
            strict = ~np.take_along_axis(flag[act], r, axis=1) & in_ring
        else:
            strict = (sine > FLAT_SINE) & in_ring
        is_flat = ~strict & in_ring
        near_flat = (np.take_along_axis(is_flat, ip, axis=1)
                     | np.take_along_axis(is_flat, inx, axis=1))
        # Smallest angle of the ear (law of sines: proportional to the shortest side / area).
        area2 = np.abs(sine) * l1 * l2
        shape = area2 / np.maximum(np.maximum(np.maximum(l1, l2), l3) ** 2, tiny)
        score = np.where(strict, shape + 2.0 * near_flat, -np.inf)
        pick = np.argmax(score, axis=1)[:, None]
        out_t.append(np.concatenate([np.take_along_axis(rp, pick, 1), np.take_along_axis(r, pick, 1),
                                     np.take_along_axis(rn, pick, 1)], axis=1))
        out_o.append(act)
        if known:       # the clipped vertex's neighbours are corners of the rest
            rows1 = act
            flag[rows1, np.take_along_axis(rp, pick, 1)[:, 0]] = False
            flag[rows1, np.take_along_axis(rn, pick, 1)[:, 0]] = False
        shift = np.minimum(j[None, :] + (j[None, :] >= pick), K - 1)
        ring[act] = np.take_along_axis(r, shift, axis=1)
        c[act] -= 1
        active = act
    tris = np.concatenate(out_t).astype(np.int64) if out_t else np.zeros((0, 3), np.int64)
    owner = np.concatenate(out_o).astype(np.int64) if out_o else np.zeros(0, np.int64)
    return tris, owner


def _build_templates():
    """Triangles per hanging pattern, as slots into (p0, p1, p2, p3, m01, m12, m23, m30).

    Code = pattern bits (1 << edge slot) + 16 for triangles (edge slot 2 of a triangle, p2 -> p3,
    has zero length and never hangs). Built once by clipping a few canonical shapes (square,
    oblongs, parallelograms; right, flat and tall triangles): with the hanging points flagged the
    clipping is combinatorial, so every variant is valid for every convex quad / triangle, and
    the variants differ only in which diagonals they take (chosen per element by shape).
    """
    quads = [[[0, 0], [1, 0], [1, 1], [0, 1]], [[0, 0], [2, 0], [2, 1], [0, 1]],
             [[0, 0], [1, 0], [1, 2], [0, 2]], [[0, 0], [1, 0], [1.8, 1], [0.8, 1]],
             [[0, 0], [1, 0], [0.2, 1], [-0.8, 1]]]
    tris = [[[0, 0], [1, 0], [0, 1]], [[0, 0], [1, 0], [0.5, 0.25]], [[0, 0], [1, 0], [1.2, 1.5]],
            [[0, 0], [1, 0], [-0.3, 1.5]]]
    variants = {}
    for is_tri, shapes in ((False, quads), (True, tris)):
        edges = (0, 1, 3) if is_tri else (0, 1, 2, 3)
        for shape in shapes:
            shape = np.column_stack([np.array(shape, float), np.zeros(len(shape))])
            if is_tri:
                shape = np.vstack([shape, shape[2:]])
            for pattern in range(1, 16):
                if any(pattern >> e & 1 for e in range(4) if e not in edges):
                    continue
                slots, pts, flat = [], [], []
                for e in edges:
                    slots.append(e if not (is_tri and e == 3) else 2)
                    pts.append(shape[slots[-1]])
                    flat.append(False)
                    if pattern >> e & 1:
                        slots.append(4 + e)
                        pts.append((shape[e] + shape[(e + 1) % 4]) / 2)
                        flat.append(True)
                t, _ = clip_convex_rings(np.array(pts)[None], np.array([len(pts)]),
                                         np.array([[0.0, 0.0, 1.0]]), np.array([flat]))
                tmpl = np.array(slots)[t]
                known = variants.setdefault(pattern + 16 * is_tri, [])
                canon = sorted(tuple(np.roll(tr, -int(np.argmin(tr)))) for tr in tmpl.tolist())
                if all(canon != sorted(tuple(np.roll(tr, -int(np.argmin(tr)))) for tr in k.tolist())
                       for k in known):
                    known.append(tmpl)
    return variants


#: code -> list of (t, 3) slot arrays into (p0, p1, p2, p3, m01, m12, m23, m30), the first from
#: the square / right triangle; see _build_templates.
TEMPLATE_VARIANTS = _build_templates()
#: code -> the first variant.
TEMPLATES = {code: v[0] for code, v in TEMPLATE_VARIANTS.items()}


def _quality(tri_pts):
    """(..., ) smallest triangle quality (2 area / longest edge^2) over axis -3 of (..., t, 3, 3)."""
    e = np.roll(tri_pts, -1, axis=-2) - tri_pts
    area2 = np.linalg.norm(np.cross(e[..., 0, :], -e[..., 2, :]), axis=-1)
    longest = np.max(np.einsum("...ij,...ij->...i", e, e), axis=-1)
    return (area2 / np.maximum(longest, np.finfo(float).tiny)).min(axis=-1)


def triangulate_hanging(leaves, is_tri, mids, points=None):
    """Conforming polygons of leaves whose edges carry their neighbours' midpoints.

    Parameters
    ----------
    leaves : (E, 4) int64
        Point ids of the leaves (triangles repeat the last corner).
    is_tri : (E,) bool
    mids : (E, 4) int64
        Point id of the midpoint hanging on each edge slot, -1 where none.
    points : (V, 3) float64, optional
        Given, each leaf takes the variant of its template whose worst triangle is best shaped;
        otherwise the first variant.

    Returns
    -------
    dict
        corner_verts (C,), face_starts (F,), face_sizes (F,), face_leaf (F,), all int64; the
        faces of each leaf consecutive, leaves in order.
    """
    E = leaves.shape[0]
    hang = mids >= 0
    code = (hang * (1 << np.arange(4))).sum(axis=1) + 16 * is_tri
    plain = ~hang.any(axis=1)
    table = np.concatenate([leaves, mids], axis=1)
    poly = [np.where(is_tri[plain, None], leaves[plain][:, [0, 1, 2, 2]], leaves[plain])]
    size = [np.where(is_tri[plain], 3, 4)]
    leaf = [np.flatnonzero(plain)]
    local = [np.zeros(leaf[0].size, np.int64)]
    for c in np.unique(code[~plain]):          # one pass per hanging pattern (at most 22)
        sel = np.flatnonzero(code == c)
        options = TEMPLATE_VARIANTS[int(c)] if points is not None else TEMPLATES[int(c)][None]
        t = options[0].shape[0]                 # every variant of a pattern has as many triangles
        tri = table[sel][:, np.asarray(options)]                         # (n, variants, t, 3)
        if len(options) > 1:
            best = np.argmax(_quality(points[tri]), axis=1)
            tri = tri[np.arange(sel.size), best]
        else:
            tri = tri[:, 0]
        poly.append(np.concatenate([tri, tri[:, :, 2:]], axis=2).reshape(-1, 4))
        size.append(np.full(sel.size * t, 3, np.int64))
        leaf.append(np.repeat(sel, t))
        local.append(np.tile(np.arange(t), sel.size))
    poly, size = np.concatenate(poly), np.concatenate(size)
    leaf, local = np.concatenate(leaf), np.concatenate(local)
    order = np.lexsort((local, leaf))
    poly, size, leaf = poly[order], size[order], leaf[order]
    keep = np.arange(4)[None, :] < size[:, None]
    starts = np.cumsum(size) - size
    return dict(corner_verts=poly[keep].astype(np.int64), face_starts=starts.astype(np.int64),
                face_sizes=size.astype(np.int64), face_leaf=leaf.astype(np.int64))


def _face_triangles(scene, faces):
    """Triangulation of the given scene faces as scene corner triples.

    Returns tri_corners (T, 3) int64 and, per entry of ``faces`` (unique, sorted), the CSR
    offsets into them: start (n + 1,).
    """
    starts = np.asarray(scene.face_starts)[faces]
    sizes = np.asarray(scene.face_sizes)[faces]
    normals = np.asarray(scene.face_normals)[faces]
    verts = np.asarray(scene.vertices, dtype=np.float64)
    cv = np.asarray(scene.corner_verts)
    tris, owner = [], []
    i3 = np.flatnonzero(sizes == 3)
    tris.append(starts[i3][:, None] + np.arange(3))
    owner.append(i3)
    i4 = np.flatnonzero(sizes == 4)
    loops = starts[i4][:, None] + np.arange(4)
    pts = verts[cv[loops]]
    convex = quads_convex(pts, normals[i4])
    split = np.where(convex[:, None, None], np.array([[0, 1, 2], [0, 2, 3]]),
                     split_concave_quads(pts, normals[i4]))
    tris.append(np.take_along_axis(loops[:, None, :], split, axis=2).reshape(-1, 3))
    owner.append(np.repeat(i4, 2))
    for i in np.flatnonzero(sizes > 4):         # set-up loop, one per n-gon face
        loops = starts[i] + np.arange(sizes[i])
        t = triangulate_polygon(verts[cv[loops]], normals[i])
        tris.append(loops[t])
        owner.append(np.full(t.shape[0], i, np.int64))
    tris, owner = np.concatenate(tris).astype(np.int64), np.concatenate(owner).astype(np.int64)
    order = np.argsort(owner, kind="stable")
    counts = np.bincount(owner, minlength=faces.size)
    start = np.zeros(faces.size + 1, np.int64)
    np.cumsum(counts, out=start[1:])
    return tris[order], start


def parent_weights(scene, face_parent_of_corner, positions):
    """Barycentric weights of points over three corners of the scene face they lie in.

    Parameters
    ----------
    scene : core.scene.Scene
    face_parent_of_corner : (C,) int
        Scene face each point lies in (a valid face).
    positions : (C, 3) float
        The points (world metres), in (or within rounding of) their face's plane.

    Returns
    -------
    corner_sources : (C, 3) int64
        Three scene corners of the face: the triangle of its triangulation (ear clipping for
        n-gons, the inner diagonal for concave quads) that contains the point.
    corner_weights : (C, 3) float64
        Barycentric weights, >= 0, summing to 1: ``sum_k w[c, k] * X[corner_sources[c, k]]``
        reproduces the point for X = the corners' positions (a planar face), and interpolates
        any per-corner value (UVs) linearly over that triangle.

    Raises
    ------
    ValueError
        Arrays of the wrong shape, faces out of range or dropped as degenerate, non-finite
        positions.
    """
    fp = np.asarray(face_parent_of_corner)
    if fp.ndim != 1 or (fp.size and not np.issubdtype(fp.dtype, np.integer)):
        raise ValueError(f"face_parent_of_corner must be an integer array of shape (C,); "
                         f"got {fp.dtype} {fp.shape}")
    C = fp.shape[0]
    x = np.asarray(positions, dtype=np.float64)
    if x.shape != (C, 3):
        raise ValueError(f"positions must have shape ({C}, 3) like face_parent_of_corner; got {x.shape}")
    if not np.all(np.isfinite(x)):
        raise ValueError("positions must be finite; got NaN or inf")
    fp = fp.astype(np.int64)
    F = scene.n_faces
    if C and (fp.min() < 0 or fp.max() >= F):
        raise ValueError(f"face_parent_of_corner must index the scene's {F} faces; "
                         f"got values in [{fp.min()}, {fp.max()}]")
    bad = ~np.asarray(scene.face_valid)[fp]
    if np.any(bad):
        f = int(fp[np.flatnonzero(bad)[0]])
        raise ValueError(f"face_parent_of_corner names {scene.face_label(f)}, which was dropped "
                         f"as degenerate")
    if C == 0:
        return np.zeros((0, 3), np.int64), np.zeros((0, 3), np.float64)
    faces, inv = np.unique(fp, return_inverse=True)
    inv = inv.reshape(-1)
    tri, start = _face_triangles(scene, faces)
    n_tri = start[1:] - start[:-1]
    if np.any(n_tri == 0):
        f = int(faces[np.flatnonzero(n_tri == 0)[0]])
        raise ValueError(f"face_parent_of_corner names {scene.face_label(f)}, which has no "
                         f"triangle of non-zero area")
    # Every point against every triangle of its face (n-gons: a few dozen), keep the best; in
    # chunks of at most PAIR_CHUNK pairs so a many-sided floor under 1e5 points stays in memory.
    per_point = n_tri[inv]
    ends = np.cumsum(per_point)
    sources = np.zeros((C, 3), np.int64)
    weights = np.zeros((C, 3), np.float64)
    lo = 0
    while lo < C:
        base = ends[lo - 1] if lo else 0
        hi = max(int(np.searchsorted(ends, base + PAIR_CHUNK, side="right")), lo + 1)
        s, w = _best_triangle(scene, tri, start[inv[lo:hi]], per_point[lo:hi], x[lo:hi])
        sources[lo:hi], weights[lo:hi] = s, w
        lo = hi
    return sources, weights


def _best_triangle(scene, tri, first_tri, n_tri, x):
    """Sources and weights of points x (n, 3) over the best of their n_tri triangles."""
    pt, k, _ = ragged(n_tri)
    t = first_tri[pt] + k
    verts = np.asarray(scene.vertices, dtype=np.float64)
    A, B, Cc = (verts[np.asarray(scene.corner_verts)[tri[t, i]]] for i in range(3))
    # Relative to A, so large coordinates (a km from the origin) lose nothing.
    v0, v1, v2 = B - A, Cc - A, x[pt] - A
    d00, d01, d11 = (np.einsum("ij,ij->i", a, b) for a, b in ((v0, v0), (v0, v1), (v1, v1)))
    d20, d21 = np.einsum("ij,ij->i", v2, v0), np.einsum("ij,ij->i", v2, v1)
    den = d00 * d11 - d01 * d01
    ok = den > 1e-24 * np.maximum(d00 * d11, np.finfo(float).tiny)
    safe = np.where(ok, den, 1.0)
    wb = (d11 * d20 - d01 * d21) / safe
    wc = (d00 * d21 - d01 * d20) / safe
    w = np.stack([1.0 - wb - wc, wb, wc], axis=1)
    score = np.where(ok, w.min(axis=1), -np.inf)
    # Best triangle per point: the largest smallest weight (inside if >= 0); pt is sorted.
    order = np.lexsort((-score, pt))
    best = order[np.r_[0, np.flatnonzero(np.diff(pt[order])) + 1]]
    # Points on an edge or outside by rounding get tiny negative weights: clip, renormalise.
    w = np.clip(w[best], 0.0, None)
    w /= w.sum(axis=1, keepdims=True)
    return tri[t[best]], w


def output_mesh(scene, tree, polygons, corner_colours):
    """The OutputMesh of a tree's conforming polygons with the driver's corner colours.

    Parameters
    ----------
    scene : core.scene.Scene
    tree : core.hierarchy.ElementTree
    polygons : dict
        ``tree.conforming()``.
    corner_colours : (C, 3) float
        Outgoing radiance at every output corner.

    Returns
    -------
    core.outmesh.OutputMesh
    """
    for key in ("corner_verts", "face_starts", "face_sizes", "face_parent"):
        if key not in polygons:
            raise ValueError(f"polygons must be tree.conforming(); missing {key!r}")
    cv = np.asarray(polygons["corner_verts"], dtype=np.int64)
    sizes = np.asarray(polygons["face_sizes"], dtype=np.int64)
    colours = np.asarray(corner_colours, dtype=np.float64)
    if colours.shape != (cv.size, 3):
        raise ValueError(f"corner_colours must have shape ({cv.size}, 3), one row per output "
                         f"corner; got {colours.shape}")
    parent = np.asarray(polygons["face_parent"], dtype=np.int64)
    face_of_corner = np.repeat(np.arange(sizes.size), sizes)
    # Weights depend on (point, scene face) only: compute them once per pair.
    pair = np.stack([cv, parent[face_of_corner]], axis=1)
    uniq, inv = np.unique(pair, axis=0, return_inverse=True)
    inv = inv.reshape(-1)
    sources, weights = parent_weights(scene, uniq[:, 1], tree.points[uniq[:, 0]])
    sources, weights = sources[inv], weights[inv]
    return OutputMesh(vertices=np.asarray(tree.points, dtype=np.float64), corner_verts=cv,
                      face_starts=np.asarray(polygons["face_starts"], dtype=np.int64),
                      face_sizes=sizes, face_parent=parent, corner_colours=colours,
                      corner_sources=sources, corner_weights=weights)
