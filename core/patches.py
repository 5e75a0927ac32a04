"""Patches: the faces of a scene split into small conforming quads and triangles.

Each valid face becomes *elements*: a convex quad stays one, a triangle stays one, a concave quad
or an n-gon is triangulated first (ear clipping in its plane). Each element becomes a grid:

- a convex quad: an ``n x m`` bilinear grid of quads;
- a triangle whose edges need equal segment counts: an ``n x n`` grid of triangles;
- any other triangle: a *fan strip*, the quad (A, B, C, C) collapsed at the corner C opposite its
  shortest edge AB: ``n`` columns along AB, ``m`` rows towards C, the last row triangles.

The grids are conforming across faces: every mesh edge (a pair of vertex indices, after welding
vertices at bit-identical positions) gets one segment count, the same for every face sharing it,
and the points along it are computed from its lower vertex index by one expression, so
neighbouring faces place bit-identical points and no T-junction appears. A grid needs equal
counts on the opposite edges of a quad, on the two edges CA and CB of a fan strip and on all three
edges of a grid triangle; counts are therefore shared by *classes* of tied edges (connected
components, found by vectorised label propagation), each class taking the largest
``ceil(length / max_edge)`` of its members. No patch edge is then longer than ``max_edge``: a
bilinear grid line is a convex combination of the element's opposite edges, divided by a count at
least as large as either needs.

Trade-off to know: ties propagate along quad strips (as in any structured mesh); a thin sliver
quad keeps its short direction coarse, a needle triangle becomes one column of a fan strip, but
a short edge opposite a long one in the same quad is split as finely as the long one.
"""

from dataclasses import dataclass

import numpy as np

from .constants import tol
from .errors import SettingsError
from .geometry import (newell_normals_areas, quads_convex, ragged as _ragged,
                       split_concave_quads, triangulate_polygon)

#: Largest patch count make_patches builds; beyond it a too small max_edge would exhaust memory
#: (about 0.5 kB per patch with the temporaries) long before a solve could finish.
MAX_PATCHES = 5_000_000


@dataclass(frozen=True, eq=False)
class Patches:
    """The patches of a scene (read-only arrays).

    Attributes
    ----------
    corners : (P, 4, 3) float64
        Patch polygons, counter-clockwise about the normal; a triangle repeats its last corner
        (``corners[:, 3] == corners[:, 2]``).
    centres : (P, 3) float64
        Area centroids.
    normals : (P, 3) float64
        Unit Newell normals.
    areas : (P,) float64
        Newell areas (m^2).
    face : (P,) int64
        Scene face of each patch; the patches of a face are contiguous.
    face_patch_start : (F + 1,) int64
        CSR offsets: the patches of face f are ``face_patch_start[f]:face_patch_start[f + 1]``.
    material : (P,) int64
        Material of each patch (that of its face).
    incidence_vertex, incidence_patch, incidence_corner : (K,) int64
        One entry per patch corner that is an original scene vertex: the vertex, the patch and the
        scene corner (loop) of the patch's face at that vertex.
    incidence_slot : (K,) int64 or None
        Which of the patch's corners (0..3) that vertex is; used by :func:`subdivide_patches`.
        An addition to the design contract; ``None`` when a caller builds Patches by hand.
    """

    corners: np.ndarray
    centres: np.ndarray
    normals: np.ndarray
    areas: np.ndarray
    face: np.ndarray
    face_patch_start: np.ndarray
    material: np.ndarray
    incidence_vertex: np.ndarray
    incidence_patch: np.ndarray
    incidence_corner: np.ndarray
    incidence_slot: np.ndarray = None

    @property
    def n_patches(self):
        return int(self.corners.shape[0])

    @property
    def is_triangle(self):
        """(P,) bool: patches that are triangles (last corner repeated)."""
        return triangle_mask(self.corners)


def triangle_mask(corners):
    """(P,) bool: which of the 4-corner polygons ``corners`` (P, 4, 3) are triangles (last corner
    repeated)."""
    return np.all(corners[:, 3] == corners[:, 2], axis=1)


def _check_max_edge(max_edge):
    try:
        h = float(max_edge)
    except (TypeError, ValueError):
        raise SettingsError(f"max_edge must be a positive number of metres; got {max_edge!r}") from None
    if not np.isfinite(h) or h <= 0:
        raise SettingsError(f"max_edge must be a positive finite number of metres; got {max_edge!r}")
    return h


def check_scene(scene):
    needed = ("vertices", "corner_verts", "face_starts", "face_sizes", "face_materials",
              "face_normals", "face_valid")
    missing = [name for name in needed if not hasattr(scene, name)]
    if missing:
        raise TypeError(f"scene must be a core.scene.Scene; got {type(scene).__name__} "
                        f"without {', '.join(missing)}")


def connected_labels(n, a, b):
    """Component label (smallest member) of every node of the graph with links (a[k], b[k]).

    Min-label propagation with root hooking and pointer jumping: a handful of vectorised rounds
    (about log of the longest chain), no loop over links.
    """
    label = np.arange(n, dtype=np.int64)
    if a.size == 0:
        return label
    while True:
        la, lb = label[a], label[b]
        m = np.minimum(la, lb)
        new = label.copy()
        np.minimum.at(new, la, m)     # hook the roots of both ends onto the smaller label
        np.minimum.at(new, lb, m)
        np.minimum.at(new, a, m)
        np.minimum.at(new, b, m)
        while True:                   # labels only decrease, so jumping terminates
            jumped = new[new]
            if np.array_equal(jumped, new):
                break
            new = jumped
        if np.array_equal(new, label):
            return label
        label = new


def _triangular_set(limit):
    """Element, i, j of every (i, j) with i, j >= 0 and i + j <= limit[e], rows j in order."""
    rows = np.maximum(limit + 1, 0)
    row_elem, row_j, _ = _ragged(rows)
    row_len = limit[row_elem] + 1 - row_j
    row_of, i, _ = _ragged(row_len)
    return row_elem[row_of], i, row_j[row_of]


def _tri_point_index(start, n, i, j):
    """Index of grid point (i, j) of a triangle grid of order n whose points start at ``start``."""
    return start + j * (n + 1) - (j * (j - 1)) // 2 + i


class _EdgePoints:
    """Canonical points along mesh edges: identical for every face that shares the edge.

    ``lo``/``hi`` are the (welded) vertex ids of each edge, ``lo < hi``; points are interpolated
    from ``lo``, so both faces evaluate the same expression on the same operands.
    """

    def __init__(self, vertices, counts, edge_lo, edge_hi):
        self.vertices, self.counts, self.lo, self.hi = vertices, counts, edge_lo, edge_hi

    def along(self, edge, start_vertex, k):
        """Point k of ``counts[edge]`` segments along ``edge``, counted from ``start_vertex``."""
        count = self.counts[edge]
        lo, hi = self.lo[edge], self.hi[edge]
        kk = np.where(start_vertex == lo, k, count - k)
        p_lo, p_hi = self.vertices[lo], self.vertices[hi]
        return p_lo + (p_hi - p_lo) * (kk / count)[:, None]


def make_patches(scene, max_edge):
    """Split every valid face of a scene into conforming patches no longer than ``max_edge``.

    Parameters
    ----------
    scene : Scene
        With ``F`` faces; faces with ``face_valid`` False make no patches.
    max_edge : float
        Longest allowed patch edge, scene metres (> 0). Edges that are a whole multiple of it
        may exceed it by ``tol.edge_count`` relative (float64 rounding).

    Returns
    -------
    Patches
        ``P`` patches, those of each face contiguous and in face order.

    Raises
    ------
    SettingsError
        ``max_edge`` not a positive finite number, or so small that more than ``MAX_PATCHES``
        patches would be made.

    Notes
    -----
    See the module docstring for the scheme. Measured patch counts (``max_edge`` 0.5 / 0.25 /
    0.1 m): ``bench.scenes.cornell_box()`` 35 / 84 / 336; ``bench.scenes.room_with_boxes(2000)`` 1966 /
    2294 / 17694 (at 0.5 m every input quad already is one patch).
    """
    h = _check_max_edge(max_edge)
    check_scene(scene)
    vertices = np.asarray(scene.vertices, dtype=np.float64)
    corner_verts = np.asarray(scene.corner_verts, dtype=np.int64)
    face_starts = np.asarray(scene.face_starts, dtype=np.int64)
    face_sizes = np.asarray(scene.face_sizes, dtype=np.int64)
    face_normals = np.asarray(scene.face_normals, dtype=np.float64)
    valid = np.asarray(scene.face_valid, dtype=bool)
    n_faces = face_starts.shape[0]

    quad_loops, quad_face, tri_loops, tri_face = _elements(vertices, corner_verts, face_starts,
                                                           face_sizes, face_normals, valid)

    # Mesh edges of all elements, keyed by their vertex pair. Vertices at bit-identical positions
    # are welded first, so faces of different objects (or split meshes) that meet along an edge
    # with coincident corners are conforming too.
    weld_points, weld = np.unique(vertices, axis=0, return_inverse=True)
    weld = weld.reshape(-1)

    # A triangle whose edges need unequal counts becomes a quad collapsed at the corner opposite
    # its shortest edge (A, B, C, C): rows parallel to AB fan into C. It ties only CA and BC, so
    # the short edge stays coarse (needles do not explode) and ties do not flood triangle meshes.
    tri_pts = vertices[corner_verts[tri_loops]]
    tri_len = np.linalg.norm(np.roll(tri_pts, -1, axis=1) - tri_pts, axis=2)
    tri_own = np.maximum(np.ceil(tri_len / h * (1.0 - tol.edge_count)), 1.0)
    fan = tri_own.min(axis=1) < tri_own.max(axis=1)
    k = np.argmax(tri_len[fan] <= tri_len[fan].min(1, keepdims=True) * (1 + tol.edge_tie), 1)
    fan_loops = np.take_along_axis(tri_loops[fan], (k[:, None] + np.array([0, 1, 2, 2])) % 3, axis=1)
    n_plain = quad_loops.shape[0]
    quad_loops = np.concatenate([quad_loops, fan_loops])
    quad_face = np.concatenate([quad_face, tri_face[fan]])
    tri_loops, tri_face = tri_loops[~fan], tri_face[~fan]
    collapsed = np.arange(quad_loops.shape[0]) >= n_plain

    qv = weld[corner_verts[quad_loops]]
    tv = weld[corner_verts[tri_loops]]
    ea = np.concatenate([qv.ravel(), tv.ravel()])
    eb = np.concatenate([np.roll(qv, -1, axis=1).ravel(), np.roll(tv, -1, axis=1).ravel()])
    lo, hi = np.minimum(ea, eb), np.maximum(ea, eb)
    n_weld = np.int64(weld_points.shape[0])
    keys, edge_of = np.unique(lo * n_weld + hi, return_inverse=True)
    edge_of = edge_of.reshape(-1)
    edge_lo, edge_hi = keys // n_weld, keys % n_weld
    n_q = quad_loops.shape[0]
    q_edges = edge_of[:4 * n_q].reshape(n_q, 4)
    t_edges = edge_of[4 * n_q:].reshape(-1, 3)

    length = np.linalg.norm(weld_points[edge_hi] - weld_points[edge_lo], axis=1)
    own = np.maximum(np.ceil(length / h * (1.0 - tol.edge_count)), 1.0)
    # Ties: opposite edges of a quad (not the collapsed edge C-C of a fan), all edges of a triangle.
    links_a = np.concatenate([q_edges[~collapsed, 0], q_edges[:, 1], t_edges[:, 0], t_edges[:, 1]])
    links_b = np.concatenate([q_edges[~collapsed, 2], q_edges[:, 3], t_edges[:, 1], t_edges[:, 2]])
    label = connected_labels(keys.shape[0], links_a, links_b)
    class_count = np.zeros(keys.shape[0])
    np.maximum.at(class_count, label, own)
    counts_f = class_count[label]
    n_q_grid, m_q_grid = counts_f[q_edges[:, 0]], counts_f[q_edges[:, 1]]
    n_t_grid = counts_f[t_edges[:, 0]] if t_edges.size else np.zeros(0)
    total = float(np.sum(n_q_grid * m_q_grid) + np.sum(n_t_grid ** 2))
    if total > MAX_PATCHES:
        raise SettingsError(f"max_edge = {h!r} m would make {total:.3g} patches (limit {MAX_PATCHES}); "
                            f"use a larger max_edge")
    counts = counts_f.astype(np.int64)
    edges = _EdgePoints(weld_points, counts, edge_lo, edge_hi)

    q = _quad_grids(vertices, corner_verts, weld, quad_loops, q_edges, counts, edges, collapsed)
    t = _tri_grids(vertices, corner_verts, weld, tri_loops, t_edges, counts, edges)
    corners = np.concatenate([q[0], t[0]])
    elem_face = np.concatenate([quad_face[q[1]], tri_face[t[1]]])
    n_quad_patches = q[0].shape[0]
    inc_patch = np.concatenate([q[2], t[2] + n_quad_patches])
    inc_loop = np.concatenate([q[3], t[3]])
    inc_slot = np.concatenate([q[4], t[4]])
    inc_patch, inc_loop, inc_slot = _alias_duplicate_corners(
        face_starts, face_sizes, valid, weld[corner_verts], elem_face[inc_patch], inc_patch,
        inc_loop, inc_slot)

    order = np.argsort(elem_face, kind="stable")
    rank = np.empty_like(order)
    rank[order] = np.arange(order.shape[0])
    return assemble_patches(corners[order], elem_face[order], np.asarray(scene.face_materials, np.int64),
                     n_faces, corner_verts[inc_loop], rank[inc_patch], inc_loop, inc_slot)


def _alias_duplicate_corners(face_starts, face_sizes, valid, corner_pos, inc_face, inc_patch,
                             inc_loop, inc_slot):
    """Share incidence among corners of one face at one position (a zero-length edge).

    Such corners are dropped from the elements or split between them; each of them takes every
    patch of its face at that position, once. ``corner_pos`` is the welded vertex id of every
    corner, ``inc_face`` the face of every entry's patch.
    """
    faces = np.repeat(np.arange(face_starts.shape[0], dtype=np.int64), face_sizes)
    loops = np.repeat(face_starts, face_sizes) + _ragged(face_sizes)[1]
    faces, loops = faces[valid[faces]], loops[valid[faces]]
    scale = np.int64(corner_pos.max() + 1) if corner_pos.size else np.int64(1)
    loop_key = faces * scale + corner_pos[loops]
    uniq, inverse, count = np.unique(loop_key, return_inverse=True, return_counts=True)
    dup = count[inverse.reshape(-1)] > 1
    if not dup.any():
        return inc_patch, inc_loop, inc_slot
    dup_loops, dup_keys = loops[dup], loop_key[dup]
    is_dup_loop = np.zeros(corner_pos.shape[0], dtype=bool)
    is_dup_loop[dup_loops] = True
    # One entry per (position key, patch) among the entries of the duplicated corners.
    from_dup = np.flatnonzero(is_dup_loop[inc_loop])
    entry_key = inc_face[from_dup] * scale + corner_pos[inc_loop[from_dup]]
    pairs = np.stack([entry_key, inc_patch[from_dup]], axis=1)
    _, first = np.unique(pairs, axis=0, return_index=True)
    rep = from_dup[first]                       # sorted by (key, patch)
    rep_key = entry_key[first]
    lo = np.searchsorted(rep_key, dup_keys, side="left")
    hi = np.searchsorted(rep_key, dup_keys, side="right")
    owner, local, _ = _ragged(hi - lo)
    pick = rep[lo[owner] + local]
    keep = ~is_dup_loop[inc_loop]
    return (np.concatenate([inc_patch[keep], inc_patch[pick]]),
            np.concatenate([inc_loop[keep], dup_loops[owner]]),
            np.concatenate([inc_slot[keep], inc_slot[pick]]))


def _elements(vertices, corner_verts, face_starts, face_sizes, face_normals, valid):
    """Quads (convex) and triangles, as scene corner (loop) ids, with their faces."""
    quad_loops, quad_face, tri_loops, tri_face = [], [], [], []

    f3 = np.flatnonzero(valid & (face_sizes == 3))
    tri_loops.append(face_starts[f3][:, None] + np.arange(3))
    tri_face.append(f3)

    f4 = np.flatnonzero(valid & (face_sizes == 4))
    loops4 = face_starts[f4][:, None] + np.arange(4)
    pts4 = vertices[corner_verts[loops4]]
    zero_edge = np.all(pts4 == np.roll(pts4, -1, axis=1), axis=2)         # (n, 4)
    has_zero = zero_edge.any(axis=1)
    convex = quads_convex(pts4, face_normals[f4]) & ~has_zero
    quad_loops.append(loops4[convex])
    quad_face.append(f4[convex])
    # A quad with a zero-length edge k -> k+1 is the triangle without corner k+1.
    k = np.argmax(zero_edge[has_zero], axis=1)
    keep = (k[:, None] + np.array([0, 2, 3])) % 4
    tri_loops.append(np.take_along_axis(loops4[has_zero], keep, axis=1))
    tri_face.append(f4[has_zero])
    concave = ~convex & ~has_zero
    split = split_concave_quads(pts4[concave], face_normals[f4[concave]])  # (n, 2, 3)
    lc = loops4[concave]
    tri_loops.append(np.take_along_axis(lc[:, None, :], split, axis=2).reshape(-1, 3))
    tri_face.append(np.repeat(f4[concave], 2))

    for f in np.flatnonzero(valid & (face_sizes > 4)):    # set-up loop, one per n-gon face
        loops = face_starts[f] + np.arange(face_sizes[f])
        tris = triangulate_polygon(vertices[corner_verts[loops]], face_normals[f])
        tri_loops.append(loops[tris])
        tri_face.append(np.full(tris.shape[0], f, dtype=np.int64))

    return (np.concatenate(quad_loops).reshape(-1, 4).astype(np.int64),
            np.concatenate(quad_face).astype(np.int64),
            np.concatenate(tri_loops).reshape(-1, 3).astype(np.int64),
            np.concatenate(tri_face).astype(np.int64))


def _quad_grids(vertices, corner_verts, weld, loops, q_edges, counts, edges, collapsed):
    """Bilinear n x m grids of the convex quad elements.

    ``collapsed`` marks triangles stored as quads (A, B, C, C): their last row of cells are
    triangles (C repeated in slots 2 and 3) and every one of them touches C.

    Returns (corners (Pq, 4, 3), element of each patch, incidence patch, loop and slot).
    """
    n = counts[q_edges[:, 0]]
    m = counts[q_edges[:, 1]]
    vid = corner_verts[loops]
    A, B, C, D = (vertices[vid[:, k]] for k in range(4))

    elem, local, pstart = _ragged((n + 1) * (m + 1))
    ne, me = n[elem], m[elem]
    i, j = local % (ne + 1), local // (ne + 1)
    u, v = (i / ne)[:, None], (j / me)[:, None]
    pts = (1 - u) * (1 - v) * A[elem] + u * (1 - v) * B[elem] + u * v * C[elem] + (1 - u) * v * D[elem]
    # Boundary points come from the canonical edge formula, so both faces of an edge agree.
    for mask, e, start, k in (
            (j == 0, 0, 0, i),            # edge A -> B
            (i == ne, 1, 1, j),           # edge B -> C
            (j == me, 2, 3, i),           # edge D -> C
            (i == 0, 3, 0, j)):           # edge A -> D
        sel = np.flatnonzero(mask)
        pts[sel] = edges.along(q_edges[elem[sel], e], weld[vid[elem[sel], start]], k[sel])
    for ci, cj, c in ((0, 0, 0), (ne, 0, 1), (ne, me, 2), (0, me, 3)):
        sel = np.flatnonzero((i == ci) & (j == cj))
        pts[sel] = vertices[vid[elem[sel], c]]

    celem, clocal, cstart = _ragged(n * m)
    nc = n[celem]
    ci, cj = clocal % nc, clocal // nc
    base = pstart[celem] + cj * (nc + 1) + ci
    idx = np.stack([base, base + 1, base + nc + 2, base + nc + 1], axis=1)
    corners = pts[idx]

    n_el = loops.shape[0]
    cell = np.stack([np.zeros(n_el, np.int64), n - 1, n * m - 1, n * (m - 1)], axis=1)
    keep = np.ones((n_el, 4), dtype=bool)
    keep[collapsed, 3] = False                      # C is reported once per fan cell, below
    inc_patch = (cstart[:, None] + cell)[keep]
    inc_loop = loops[keep]
    inc_slot = np.broadcast_to(np.arange(4), (n_el, 4))[keep]
    # Fan cells (i, m - 1), i < n - 1, also touch C (slot 2); (n - 1, m - 1) is already listed.
    fe, fi, _ = _ragged(np.where(collapsed, n - 1, 0))
    inc_patch = np.concatenate([inc_patch, cstart[fe] + n[fe] * (m[fe] - 1) + fi])
    inc_loop = np.concatenate([inc_loop, loops[fe, 2]])
    inc_slot = np.concatenate([inc_slot, np.full(fe.shape[0], 2)])
    return corners, celem, inc_patch, inc_loop, inc_slot.astype(np.int64)


def _tri_grids(vertices, corner_verts, weld, loops, t_edges, counts, edges):
    """n x n triangle grids of the triangle elements; same returns as _quad_grids."""
    n_el = loops.shape[0]
    if n_el == 0:
        z = np.zeros(0, dtype=np.int64)
        return np.zeros((0, 4, 3)), z, z, z, z
    n = counts[t_edges[:, 0]]
    vid = corner_verts[loops]
    A, B, C = (vertices[vid[:, k]] for k in range(3))

    elem, i, j = _triangular_set(n)
    npts = (n + 1) * (n + 2) // 2
    pstart = np.cumsum(npts) - npts
    ne = n[elem]
    wb, wc = (i / ne)[:, None], (j / ne)[:, None]
    pts = (1 - wb - wc) * A[elem] + wb * B[elem] + wc * C[elem]
    for mask, e, start, k in (
            (j == 0, 0, 0, i),            # edge A -> B
            (i + j == ne, 1, 1, j),       # edge B -> C
            (i == 0, 2, 0, j)):           # edge C -> A, counted from A
        sel = np.flatnonzero(mask)
        pts[sel] = edges.along(t_edges[elem[sel], e], weld[vid[elem[sel], start]], k[sel])
    for ci, cj, c in ((0, 0, 0), (ne, 0, 1), (0, ne, 2)):
        sel = np.flatnonzero((i == ci) & (j == cj))
        pts[sel] = vertices[vid[elem[sel], c]]

    ue, ui, uj = _triangular_set(n - 1)             # "up" cells (i, j), (i+1, j), (i, j+1)
    de, di, dj = _triangular_set(n - 2)             # "down" cells (i+1, j), (i+1, j+1), (i, j+1)
    up = np.stack([_tri_point_index(pstart[ue], n[ue], ui, uj),
                   _tri_point_index(pstart[ue], n[ue], ui + 1, uj),
                   _tri_point_index(pstart[ue], n[ue], ui, uj + 1)], axis=1)
    down = np.stack([_tri_point_index(pstart[de], n[de], di + 1, dj),
                     _tri_point_index(pstart[de], n[de], di + 1, dj + 1),
                     _tri_point_index(pstart[de], n[de], di, dj + 1)], axis=1)
    # Keep each element's cells together: sort by element, up cells before down cells.
    cell_elem = np.concatenate([ue, de])
    order = np.argsort(cell_elem, kind="stable")
    idx = np.concatenate([up, down])[order]
    cell_elem = cell_elem[order]
    corners = pts[idx[:, [0, 1, 2, 2]]]

    # Up cells of element e come first in its block, row by row: (0, 0) is cell 0, (n-1, 0) is
    # cell n-1, and (0, n-1) is the last up cell, n(n+1)/2 - 1.
    cstart = np.cumsum(n * n) - n * n
    cell = np.stack([np.zeros(n_el, np.int64), n - 1, n * (n + 1) // 2 - 1], axis=1)
    inc_patch = (cstart[:, None] + cell).ravel()
    inc_loop = loops.ravel()
    inc_slot = np.broadcast_to(np.arange(3), (n_el, 3)).ravel()
    return corners, cell_elem, inc_patch, inc_loop, inc_slot.astype(np.int64)


def _centroids(corners, normals):
    """Area centroids of quads (two triangles 0-1-2, 0-2-3) and triangles; (P, 3)."""
    p0, p1, p2, p3 = corners[:, 0], corners[:, 1], corners[:, 2], corners[:, 3]
    a1 = np.einsum("ij,ij->i", np.cross(p1 - p0, p2 - p0), normals)
    a2 = np.einsum("ij,ij->i", np.cross(p2 - p0, p3 - p0), normals)
    c1 = (p0 + p1 + p2) / 3.0
    c2 = (p0 + p2 + p3) / 3.0
    total = a1 + a2
    ok = np.abs(total) > 0
    safe = np.where(ok, total, 1.0)
    centre = (a1[:, None] * c1 + a2[:, None] * c2) / safe[:, None]
    return np.where(ok[:, None], centre, corners.mean(axis=1))


def assemble_patches(corners, face, face_materials, n_faces, inc_vertex, inc_patch, inc_loop,
                     inc_slot):
    """A :class:`Patches` from its corners and incidence arrays (also used by core.contacts)."""
    normals, areas = newell_normals_areas(corners)
    centres = _centroids(corners, normals)
    counts = np.bincount(face, minlength=n_faces)
    start = np.zeros(n_faces + 1, dtype=np.int64)
    np.cumsum(counts, out=start[1:])
    order = np.lexsort((inc_slot, inc_patch))
    arrays = dict(corners=corners, centres=centres, normals=normals, areas=areas,
                  face=face.astype(np.int64), face_patch_start=start,
                  material=face_materials[face].astype(np.int64),
                  incidence_vertex=inc_vertex[order].astype(np.int64),
                  incidence_patch=inc_patch[order].astype(np.int64),
                  incidence_corner=inc_loop[order].astype(np.int64),
                  incidence_slot=inc_slot[order].astype(np.int64))
    for arr in arrays.values():
        arr.setflags(write=False)
    return Patches(**arrays)


def patch_triangles(patches):
    """Triangles of all patches, for rasterising and ray casting.

    Parameters
    ----------
    patches : Patches

    Returns
    -------
    tris : (T, 3, 3) float64
        Quad patch p gives (c0, c1, c2) and (c0, c2, c3); a triangle patch only (c0, c1, c2).
        Counter-clockwise about the patch normal, grouped by patch.
    tri_patch : (T,) int64
        Patch of each triangle.
    """
    corners = np.asarray(patches.corners, dtype=np.float64)
    if corners.ndim != 3 or corners.shape[1:] != (4, 3):
        raise ValueError(f"patches.corners must have shape (P, 4, 3); got {corners.shape}")
    is_quad = ~triangle_mask(corners)
    first = corners[:, [0, 1, 2]]
    second = corners[is_quad][:, [0, 2, 3]]
    tris = np.concatenate([first, second])
    tri_patch = np.concatenate([np.arange(corners.shape[0]), np.flatnonzero(is_quad)]).astype(np.int64)
    order = np.argsort(tri_patch, kind="stable")
    return tris[order], tri_patch[order]


#: Children of a split quad, as indices into (p0, p1, p2, p3, m01, m12, m23, m30, centre); child k
#: holds parent corner k in its slot k. A triangle (p3 == p2, so m23 == p2, m30 == m20) uses the
#: second table: three corner triangles and the middle one, each repeating its last corner.
QUAD_CHILDREN = np.array([[0, 4, 8, 7], [4, 1, 5, 8], [8, 5, 2, 6], [7, 8, 6, 3]])
TRI_CHILDREN = np.array([[0, 4, 7, 7], [4, 1, 5, 5], [7, 5, 2, 2], [4, 5, 7, 7]])


def subdivide_patches(patches, mask):
    """Split the marked patches in four, for adaptive refinement.

    Quads split on their midpoint grid (edge midpoints and the bilinear centre), triangles at
    their edge midpoints. Unmarked patches are kept as they are, so T-junctions may appear
    between a split patch and an unsplit neighbour (harmless: colours are read only at original
    vertices, whose incidence is kept).

    Parameters
    ----------
    patches : Patches
        ``P`` patches, as made by :func:`make_patches` (needs ``incidence_slot``).
    mask : (P,) bool
        Patches to split.

    Returns
    -------
    new : Patches
        ``P' = P + 3 * mask.sum()`` patches, still contiguous per face; the children of a patch
        replace it in place, in order.
    parent : (P',) int64
        Index in ``patches`` of the patch each new patch comes from.
    """
    if not isinstance(patches, Patches):
        raise TypeError(f"patches must be a Patches; got {type(patches).__name__}")
    n_p = patches.n_patches
    mask = np.asarray(mask)
    if mask.shape != (n_p,) or mask.dtype != bool:
        raise ValueError(f"mask must be a bool array of shape ({n_p},); got {mask.dtype} {mask.shape}")
    if patches.incidence_slot is None:
        raise ValueError("patches.incidence_slot is None: subdivide_patches needs Patches made by "
                         "make_patches (it must know which corner each incident vertex is)")
    c = patches.corners
    n_child = np.where(mask, 4, 1)
    parent, child, child_start = _ragged(n_child)
    marked = np.flatnonzero(mask)
    slot_of = np.zeros(n_p, dtype=np.int64)
    slot_of[marked] = np.arange(marked.shape[0])
    m = c[marked]
    p0, p1, p2, p3 = m[:, 0], m[:, 1], m[:, 2], m[:, 3]
    # Midpoints as (a + b) / 2: addition commutes, so a neighbour splitting the same edge agrees.
    table = np.stack([p0, p1, p2, p3, (p0 + p1) / 2, (p1 + p2) / 2, (p2 + p3) / 2, (p3 + p0) / 2,
                      (p0 + p1 + p2 + p3) / 4], axis=1)
    tri = patches.is_triangle
    new_corners = c[parent]
    s = np.flatnonzero(mask[parent])
    which = np.where(tri[parent[s]][:, None], TRI_CHILDREN[child[s]], QUAD_CHILDREN[child[s]])
    new_corners[s] = np.take_along_axis(table[slot_of[parent[s]]], which[:, :, None], axis=1)

    inc_p = patches.incidence_patch
    new_inc = child_start[inc_p] + np.where(mask[inc_p], patches.incidence_slot, 0)
    n_faces = patches.face_patch_start.shape[0] - 1
    new = assemble_patches(new_corners, patches.face[parent], material_table(patches), n_faces,
                    patches.incidence_vertex, new_inc, patches.incidence_corner,
                    patches.incidence_slot)
    return new, parent.astype(np.int64)


def material_table(patches):
    """A face -> material table that reproduces ``patches.material`` (faces without patches: 0)."""
    n_faces = patches.face_patch_start.shape[0] - 1
    table = np.zeros(n_faces, dtype=np.int64)
    table[patches.face] = patches.material
    return table
