"""The adaptive element hierarchy: welded leaf elements over the scene's patches, split in four
where the driver asks, kept 2:1 balanced, and output as conforming polygons.

Pure geometry; which leaves to split (by light contrast) is the driver's business.

- Level 0 is a :class:`core.patches.Patches` (normally after the contact cuts). Its corners are
  welded per object, with a tolerance relative to the local element size. Points that lie inside
  another element's edge (T-junctions: the crossing points of contact cuts, or user meshes that
  do not match) are made conforming once, by re-triangulating the element over its boundary
  points (:func:`core.conforming.clip_convex_rings`); from there on every T-junction is a midpoint.
- A split puts a point at each edge midpoint (shared with the neighbour across the edge: one
  table from edge key to midpoint) and, for quads, the centre. Point ids never change, so values
  the driver keeps per point stay valid.
- 2:1 balance: a leaf is split when a finer neighbour along one of its hanging edges is split, so
  at most one midpoint hangs on any edge and the templates of :mod:`core.conforming` suffice.

Sizes: V points, E leaves, P patches.

Examples
--------
Two 1 m squares (floor and emitter) in 0.5 m patches; split one floor patch: its two
neighbours then carry a hanging midpoint each and are triangulated in the output.

>>> import numpy as np
>>> from core.patches import make_patches
>>> from core.scene import scene_from_polygons
>>> square = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=float)
>>> scene = scene_from_polygons(np.vstack([square, square[::-1] + [0, 0, 1]]),
...                             [[0, 1, 2, 3], [4, 5, 6, 7]], [0, 1],
...                             [[0.5] * 3, [0.0] * 3], [[0.0] * 3, [1.0] * 3],
...                             face_objects=[0, 1], object_names=("floor", "emitter"))
>>> tree = ElementTree.from_patches(scene, make_patches(scene, 0.5))
>>> tree.n_leaves
8
>>> mask = np.zeros(tree.n_leaves, dtype=bool)
>>> mask[0] = True
>>> tree, parent = tree.split(mask)
>>> tree.n_leaves, int(tree.hanging().sum())
(11, 2)
>>> polys = tree.conforming()
>>> sorted(set(polys["face_sizes"].tolist()))
[3, 4]
"""

import numpy as np

from . import constants
from .conforming import (clip_convex_rings, output_mesh,  # noqa: F401 (API)
                         triangulate_hanging)
from .geometry import newell_normals_areas, pairs_by_key, ragged
from .patches import (QUAD_CHILDREN, TRI_CHILDREN, Patches, assemble_patches, connected_labels,
                      material_table)

#: Points of one object closer than this times the local element size (longest edge of the
#: smallest element using them) are one point.
WELD_REL = 1e-8

#: A point lies inside an element edge (a T-junction) when its distance from the edge's line is
#: at most this times the edge length (or FLOAT32_SLACK times the coordinates' magnitude, within
#: ON_EDGE_SLANT) and it is at least this far (relative) from both ends.
ON_EDGE_REL = 1e-6

#: Blender hands over float32 coordinates: a vertex modelled on an edge is off its line by up to
#: a few float32 roundings of the coordinates (``tol.float32``).
FLOAT32_SLACK = constants.tol.float32

#: ... but only within this slant (3 degrees) of the edge as seen from its nearer end: far from
#: the origin the rounding (1.4 cm at 30 km) exceeds the small pieces that cuts leave at
#: objects' corners, whose points would otherwise be taken as lying on their neighbours' edges
#: (a point 1.2 cm from an edge's end in another direction) and give zero-area triangles
#: (docs/stability.md, class 10 with shadow_cuts). A user's vertex rounded 2 mm off an edge
#: is still found at 4 cm or more from the edge's ends.
ON_EDGE_SLANT = 0.05

#: Edge keys are lo * KEY_BASE + hi (point ids below 2**31).
KEY_BASE = np.int64(1) << np.int64(31)


def _key(a, b):
    a, b = np.asarray(a, np.int64), np.asarray(b, np.int64)
    return np.minimum(a, b) * KEY_BASE + np.maximum(a, b)


def _lookup(sorted_keys, keys):
    """Index of each key in ``sorted_keys``, -1 where absent."""
    keys = np.asarray(keys)
    if sorted_keys.size == 0:
        return np.full(keys.shape, -1, np.int64)
    i = np.minimum(np.searchsorted(sorted_keys, keys), sorted_keys.size - 1)
    return np.where(sorted_keys[i] == keys, i, -1)


def _edges(leaves):
    """Edge slot k runs leaves[:, k] -> leaves[:, k+1]; slot 2 of a triangle is empty."""
    a = leaves
    b = np.roll(leaves, -1, axis=1)
    valid = a != b
    return a, b, valid


def _geometry(points, leaves):
    corners = points[leaves]
    normals, areas = newell_normals_areas(corners)
    sizes = np.linalg.norm(np.roll(corners, -1, axis=1) - corners, axis=2).max(axis=1)
    return normals, areas, sizes


class ElementTree:
    """Leaf elements of the hierarchy (read-only arrays; operations return new trees).

    Attributes
    ----------
    points : (V, 3) float64
        Welded element vertices (world metres). Point ids stay valid across :meth:`split`.
    leaves : (E, 4) int64
        Point ids of each leaf, counter-clockwise about its normal; a triangle repeats its last
        corner (``leaves[:, 3] == leaves[:, 2]``). The leaves of a scene face are contiguous and
        in face order.
    leaf_face, leaf_patch, leaf_level, material : (E,) int64
        Scene face, level-0 patch (index into the Patches the tree was built from), level (0 for
        the patches) and material of each leaf.
    normals : (E, 3) float64
    areas, sizes : (E,) float64
        Newell area and longest edge.
    """

    def __init__(self, points, leaves, leaf_face, leaf_patch, leaf_level, material, mid_keys,
                 mid_points, inc_key, inc_vertex, inc_corner, face_materials, point_parents=None):
        self.points = points
        self.leaves = leaves
        self.leaf_face = leaf_face
        self.leaf_patch = leaf_patch
        self.leaf_level = leaf_level
        self.material = material
        self.normals, self.areas, self.sizes = _geometry(points, leaves)
        # Sorted edge keys that have a midpoint, and its point id.
        self._mid_keys, self._mid_points = mid_keys, mid_points
        # Sorted (point * F + face) of scene corners at points, with their vertex and corner.
        self._inc_key, self._inc_vertex, self._inc_corner = inc_key, inc_vertex, inc_corner
        self._face_materials = face_materials
        # (V, 4) int64: the points a split point was made from (an edge's two, padded with -1,
        # or a quad's four); -1 rows for the level-0 points.
        if point_parents is None:
            point_parents = np.full((points.shape[0], 4), -1, np.int64)
        self.point_parents = point_parents
        for arr in (points, leaves, leaf_face, leaf_patch, leaf_level, material, self.normals,
                    self.areas, self.sizes, point_parents):
            arr.setflags(write=False)

    @property
    def n_leaves(self):
        return int(self.leaves.shape[0])

    @property
    def is_triangle(self):
        """(E,) bool: leaves that are triangles."""
        return self.leaves[:, 3] == self.leaves[:, 2]

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_patches(cls, scene, patches):
        """Level 0 of the hierarchy: the patches, welded and made conforming.

        Parameters
        ----------
        scene : core.scene.Scene
        patches : core.patches.Patches
            ``P`` patches of ``scene`` (from make_patches, normally after
            :func:`core.contacts.split_at_contacts`).

        Returns
        -------
        ElementTree
            One leaf per patch, except patches with another element's point inside an edge,
            which become triangles over their boundary points (``leaf_patch`` names the patch).
        """
        if not isinstance(patches, Patches):
            raise TypeError(f"patches must be a core.patches.Patches; got {type(patches).__name__}")
        for name in ("face_objects", "face_valid", "n_faces"):
            if not hasattr(scene, name):
                raise TypeError(f"scene must be a core.scene.Scene; got {type(scene).__name__}")
        n_faces = patches.face_patch_start.shape[0] - 1
        if n_faces != scene.n_faces:
            raise ValueError(f"patches were made for {n_faces} faces; scene has {scene.n_faces}")
        corners = np.asarray(patches.corners, dtype=np.float64)
        P = corners.shape[0]
        face = np.asarray(patches.face, dtype=np.int64)
        obj = np.asarray(scene.face_objects, dtype=np.int64)[face]
        sizes = np.linalg.norm(np.roll(corners, -1, axis=1) - corners, axis=2).max(axis=1)
        points, point_obj, pid = _weld(corners.reshape(-1, 3), np.repeat(obj, 4),
                                       np.repeat(sizes, 4))
        pid = _canonical_corners(pid.reshape(P, 4))
        # Scene corners at points: (point, face) -> (scene vertex, scene corner).
        ip, islot = patches.incidence_patch, patches.incidence_slot
        if islot is None:
            raise ValueError("patches.incidence_slot is None: from_patches needs Patches made by "
                             "make_patches / split_at_contacts")
        ikey = pid[ip, islot] * np.int64(n_faces) + face[ip]
        ikey, first = np.unique(ikey, return_index=True)
        # Patches that welding left with fewer than three corners have no area: no leaf.
        sel = np.flatnonzero((pid[:, 0] != pid[:, 1]) & (pid[:, 1] != pid[:, 2])
                             & (pid[:, 2] != pid[:, 0]))
        leaves, leaf_patch = _conform_level0(points, point_obj, pid[sel],
                                             np.asarray(patches.normals)[sel])
        leaf_patch = sel[leaf_patch]
        face_materials = material_table(patches)
        leaf_face = face[leaf_patch]
        zero = np.zeros(0, np.int64)
        return cls(points, leaves, leaf_face, leaf_patch, np.zeros(leaves.shape[0], np.int64),
                   face_materials[leaf_face], zero, zero, ikey,
                   np.asarray(patches.incidence_vertex)[first],
                   np.asarray(patches.incidence_corner)[first], face_materials)

    # ------------------------------------------------------------------ refinement
    def hanging(self):
        """(E, 4) bool: edge slots (k -> k+1) of each leaf that carry a neighbour's midpoint."""
        return self._hanging_mids() >= 0

    def _hanging_mids(self):
        a, b, valid = _edges(self.leaves)
        i = _lookup(self._mid_keys, _key(a, b))
        return np.where(valid & (i >= 0), self._mid_points[np.maximum(i, 0)], -1) \
            if self._mid_keys.size else np.full(a.shape, -1, np.int64)

    def balance(self, mask):
        """The smallest superset of ``mask`` whose split keeps neighbours within one level.

        A leaf must split when a finer neighbour along one of its hanging edges splits (that
        would put a quarter point on its edge); this propagates to ever coarser leaves, so the
        iteration count is bounded by the number of levels.
        """
        mask = self._check_mask(mask).copy()
        a, b, valid = _edges(self.leaves)
        mids = self._hanging_mids()
        hl, hs = np.nonzero(mids >= 0)
        if hl.size == 0:
            return mask
        m = mids[hl, hs]
        k1, k2 = _key(a[hl, hs], m), _key(m, b[hl, hs])
        keys = _key(a, b)
        while True:
            marked = np.unique(keys[mask[:, None] & valid])
            hit = (_lookup(marked, k1) >= 0) | (_lookup(marked, k2) >= 0)
            new = mask.copy()
            new[hl[hit]] = True
            if np.array_equal(new, mask):
                return mask
            mask = new

    def split(self, mask):
        """Split the marked leaves (and those balance needs) in four.

        Parameters
        ----------
        mask : (E,) bool

        Returns
        -------
        tree : ElementTree
            Children replace their leaf in place (faces stay contiguous); old point ids are kept,
            new points appended.
        parent : (E_new,) int64
            Leaf of ``self`` each new leaf is or came from.
        """
        mask = self.balance(mask)
        E = self.n_leaves
        marked = np.flatnonzero(mask)
        if marked.size == 0:
            return self, np.arange(E, dtype=np.int64)
        pts = self.points
        V = pts.shape[0]
        lm = self.leaves[marked]
        tri = self.is_triangle[marked]
        a, b, valid = _edges(lm)
        need = np.unique(_key(a, b)[valid])
        fresh = need[_lookup(self._mid_keys, need) < 0]
        lo, hi = fresh // KEY_BASE, fresh % KEY_BASE
        new_mid = (pts[lo] + pts[hi]) / 2.0       # (a + b) / 2 commutes: both sides agree
        mid_keys = np.concatenate([self._mid_keys, fresh])
        mid_points = np.concatenate([self._mid_points, V + np.arange(fresh.size, dtype=np.int64)])
        o = np.argsort(mid_keys, kind="stable")
        mid_keys, mid_points = mid_keys[o], mid_points[o]
        mids = np.where(valid, mid_points[np.maximum(_lookup(mid_keys, _key(a, b)), 0)], lm[:, 2:3])
        quads = np.flatnonzero(~tri)
        centre = np.full(marked.size, -1, np.int64)
        centre[quads] = V + fresh.size + np.arange(quads.size)
        new_centre = pts[lm[quads]].sum(axis=1) / 4.0
        points = np.concatenate([pts, new_mid, new_centre])
        table = np.concatenate([lm, mids, centre[:, None]], axis=1)      # (M, 9)

        n_child = np.where(mask, 4, 1)
        parent, child, _ = ragged(n_child)
        leaves = self.leaves[parent]
        slot_of = np.zeros(E, np.int64)
        slot_of[marked] = np.arange(marked.size)
        s = np.flatnonzero(mask[parent])
        ms = slot_of[parent[s]]
        which = np.where(tri[ms][:, None], TRI_CHILDREN[child[s]], QUAD_CHILDREN[child[s]])
        leaves[s] = np.take_along_axis(table[ms], which, axis=1)
        level = self.leaf_level[parent] + mask[parent]
        none = np.full_like(lo, -1)
        made_from = np.concatenate([self.point_parents, np.stack([lo, hi, none, none], 1),
                                    lm[quads]])
        tree = ElementTree(points, leaves, self.leaf_face[parent], self.leaf_patch[parent], level,
                           self.material[parent], mid_keys, mid_points, self._inc_key,
                           self._inc_vertex, self._inc_corner, self._face_materials, made_from)
        return tree, parent.astype(np.int64)

    def _check_mask(self, mask):
        if not isinstance(mask, np.ndarray) or mask.dtype != bool or mask.shape != (self.n_leaves,):
            got = (f"{mask.dtype} {mask.shape}" if isinstance(mask, np.ndarray)
                   else type(mask).__name__)
            raise ValueError(f"mask must be a bool array of shape ({self.n_leaves},) (one entry "
                             f"per leaf); got {got}")
        return mask

    # ------------------------------------------------------------------ output
    def conforming(self):
        """Conforming polygons (triangles and quads) over ``self.points``.

        Leaves without hanging midpoints are kept (quads stay quads); the others are
        triangulated by the template of their hanging pattern, over their corners and the
        hanging midpoints only (of the template's variants, the one with the best-shaped worst
        triangle for that leaf).

        Returns
        -------
        dict
            corner_verts (C,), face_starts (F,), face_sizes (F,) in {3, 4}, face_parent (F,)
            scene face, face_leaf (F,) leaf; all int64, faces in leaf order.
        """
        out = triangulate_hanging(self.leaves, self.is_triangle, self._hanging_mids(), self.points)
        out["face_parent"] = self.leaf_face[out["face_leaf"]]
        return out

    def as_patches(self):
        """The leaves as a :class:`core.patches.Patches` (one patch per leaf, same order)."""
        corners = self.points[self.leaves]
        E = self.n_leaves
        slots = np.broadcast_to(np.arange(4), (E, 4))
        use = slots < np.where(self.is_triangle, 3, 4)[:, None]
        leaf = np.broadcast_to(np.arange(E)[:, None], (E, 4))[use]
        slot = slots[use]
        n_faces = self._face_materials.shape[0]
        key = self.leaves[use] * np.int64(n_faces) + self.leaf_face[leaf]
        i = _lookup(self._inc_key, key)
        hit = i >= 0
        return assemble_patches(corners, self.leaf_face, self._face_materials, n_faces,
                         self._inc_vertex[i[hit]], leaf[hit], self._inc_corner[i[hit]], slot[hit])


def _weld(xyz, obj, size):
    """Merge points of one object closer than WELD_REL x their local size.

    Returns unique points (V, 3), their objects (V,) and the point id of every input point.
    Exact duplicates first; near ones by hashing on 8 half-shifted grids of twice the largest
    tolerance (two points within half a cell share a cell in one of them), joined by connected
    components.
    """
    rows = np.column_stack([obj.astype(np.float64), xyz])
    uniq, inv = np.unique(rows, axis=0, return_inverse=True)
    inv = inv.reshape(-1)
    n = uniq.shape[0]
    if n == 0:
        return np.zeros((0, 3)), np.zeros(0, np.int64), np.zeros(0, np.int64)
    tol = np.full(n, np.inf)
    np.minimum.at(tol, inv, WELD_REL * size)
    tol = np.where(np.isfinite(tol), tol, 0.0)
    pts, uobj = uniq[:, 1:], uniq[:, 0].astype(np.int64)
    cell = 2.0 * float(tol.max())
    ii, jj = [], []
    if cell > 0:
        base = pts.min(axis=0)
        for shift in np.array(np.meshgrid([0, 1], [0, 1], [0, 1])).reshape(3, -1).T:
            q = np.floor((pts - base) / cell + shift / 2.0).astype(np.int64)
            _, g = np.unique(np.column_stack([uobj, q]), axis=0, return_inverse=True)
            i, j = pairs_by_key(g.reshape(-1))
            k = i < j
            ii.append(i[k])
            jj.append(j[k])
        i, j = np.concatenate(ii), np.concatenate(jj)
        close = np.linalg.norm(pts[i] - pts[j], axis=1) <= np.maximum(tol[i], tol[j])
        label = connected_labels(n, i[close], j[close])
    else:
        label = np.arange(n)
    rep, merged = np.unique(label, return_inverse=True)
    return pts[rep].copy(), uobj[rep], merged.reshape(-1)[inv].astype(np.int64)


#: Spatial hash of :func:`_points_on_edges`: at most this many (edge, cell) pairs; beyond it
#: the cells grow (long edges among short ones).
MAX_EDGE_CELLS = 1 << 24


def _points_on_edges(points, point_obj, a, b, edge_obj):
    """Points of the edge's object strictly inside edges a -> b (V points, n edges).

    Cells of about the median edge length, keyed with the object; each edge visits the cells of
    its bounding box (grown by the tolerance) and tests the points there exactly.

    Returns edge (m,) int64, point (m,) int64, parameter t in (0, 1) along a -> b (m,) float64.
    """
    empty = (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0))
    if a.size == 0:
        return empty
    A, B = points[a], points[b]
    d = B - A
    L = np.linalg.norm(d, axis=1)
    slack = FLOAT32_SLACK * np.maximum(np.abs(A).max(1), np.abs(B).max(1))
    tol = np.maximum(ON_EDGE_REL * L, np.minimum(slack, 0.5 * ON_EDGE_SLANT * L))
    lo = np.minimum(A, B) - tol[:, None]
    hi = np.maximum(A, B) + tol[:, None]
    base = points.min(axis=0)
    extent = float((points.max(axis=0) - base).max())
    cell = max(float(np.median(L)), extent / 2.0 ** 16, np.finfo(float).tiny)
    while True:
        n = np.int64(np.floor(extent / cell)) + 2
        c0 = np.clip(np.floor((lo - base) / cell), 0, n - 1).astype(np.int64)
        c1 = np.clip(np.floor((hi - base) / cell), 0, n - 1).astype(np.int64)
        span = c1 - c0 + 1
        count = span.prod(axis=1)
        if count.sum() <= MAX_EDGE_CELLS:
            break
        cell *= 2.0
    pc = np.clip(np.floor((points - base) / cell), 0, n - 1).astype(np.int64)
    pkey = ((point_obj * n + pc[:, 0]) * n + pc[:, 1]) * n + pc[:, 2]
    order = np.argsort(pkey, kind="stable")
    sk = pkey[order]
    e, j, _ = ragged(count)
    sy, sz = span[e, 1], span[e, 2]
    key = ((edge_obj[e] * n + c0[e, 0] + j // (sy * sz)) * n + c0[e, 1] + (j // sz) % sy) * n \
        + c0[e, 2] + j % sz
    first = np.searchsorted(sk, key, side="left")
    pe, pj, _ = ragged(np.searchsorted(sk, key, side="right") - first)
    edge, q = e[pe], order[first[pe] + pj]
    X, D, Q = A[edge], d[edge], points[q] - A[edge]
    L2 = np.maximum(L[edge] ** 2, np.finfo(float).tiny)
    t = np.einsum("ij,ij->i", Q, D) / L2
    off = np.linalg.norm(np.cross(D, Q), axis=1) / np.sqrt(L2)
    lens = np.minimum(slack[edge], ON_EDGE_SLANT * np.minimum(t, 1.0 - t) * L[edge])
    ok = ((t > ON_EDGE_REL) & (t < 1 - ON_EDGE_REL)
          & (off <= np.maximum(ON_EDGE_REL * L[edge], lens))
          & (q != a[edge]) & (q != b[edge]))
    return edge[ok], q[ok], t[ok]


def _canonical_corners(pid):
    """Drop repeated consecutive corners (welded or collapsed): a quad with one becomes the
    triangle (a, b, c, c). Patches left with fewer than three corners keep their ids (they have
    no area and are dropped by the caller)."""
    dup = pid == np.roll(pid, -1, axis=1)
    order = np.argsort(dup, axis=1, kind="stable")
    kept = np.take_along_axis(pid, order, axis=1)
    n = 4 - dup.sum(axis=1)
    last = np.take_along_axis(kept, np.maximum(n - 1, 0)[:, None], axis=1)
    return np.where(np.arange(4)[None, :] < n[:, None], kept, last)


def _conform_level0(points, point_obj, pid, normals):
    """Re-triangulate patches with another patch's point inside one of their edges.

    Every point of the same object lying strictly inside a patch edge (within ON_EDGE_REL of
    its length, or float32 rounding of the coordinates) is found by a spatial hash
    (:func:`_points_on_edges`) and inserted into the patch's boundary ring, ordered by slot +
    edge parameter; a point inside a sub-edge lies inside the whole edge, so one pass finds all.

    Returns leaves (E, 4) int64 and the patch of each leaf.
    """
    P = pid.shape[0]
    is_tri = pid[:, 3] == pid[:, 2]
    k = np.where(is_tri, 3, 4)
    slots = np.broadcast_to(np.arange(4), (P, 4))
    use = slots < k[:, None]
    e_leaf = np.broadcast_to(np.arange(P)[:, None], (P, 4))[use]
    e_slot = slots[use]
    a = pid[use]
    b = pid[e_leaf, (e_slot + 1) % k[e_leaf]]
    edge, q, t = _points_on_edges(points, point_obj, a, b, point_obj[a])
    if edge.size == 0:
        return pid.copy(), np.arange(P, dtype=np.int64)
    e_pos = np.concatenate([e_slot.astype(np.float64), e_slot[edge] + t])
    e_pt = np.concatenate([a, q])
    e_leaf = np.concatenate([e_leaf, e_leaf[edge]])
    count = np.bincount(e_leaf, minlength=P)
    fix = np.flatnonzero(count > k)
    order = np.lexsort((e_pos, e_leaf))
    e_leaf, e_pt, e_pos = e_leaf[order], e_pt[order], e_pos[order]
    K = int(count.max())
    start = np.cumsum(count) - count
    sel = np.isin(e_leaf, fix)
    row = np.searchsorted(fix, e_leaf[sel])
    col = np.arange(e_leaf.size)[sel] - start[e_leaf[sel]]
    ring = np.zeros((fix.size, K), np.int64)
    ring[row, col] = e_pt[sel]
    ring = np.where(np.arange(K)[None, :] < count[fix][:, None], ring, ring[:, :1])
    flat = np.zeros((fix.size, K), bool)
    flat[row, col] = e_pos[sel] != np.floor(e_pos[sel])       # inserted points, not corners
    tris, owner = clip_convex_rings(points[ring], count[fix], normals[fix], flat)
    tri_pts = np.take_along_axis(ring[owner], tris, axis=1)
    # Leaves: unchanged patches and the triangles of the fixed ones, in patch order.
    keep = np.ones(P, bool)
    keep[fix] = False
    leaf_patch = np.concatenate([np.flatnonzero(keep), fix[owner]])
    leaves = np.concatenate([pid[keep], tri_pts[:, [0, 1, 2, 2]]])
    o = np.argsort(leaf_patch, kind="stable")
    return leaves[o], leaf_patch[o]
