"""The element hierarchy: tiling, 2:1 balance, conformity (no T-junctions), welding, templates,
parent weights and the output mesh.

Oracles are geometric and independent of the tree's own bookkeeping: areas against the scene's
Newell face areas, T-junctions by brute-force point-on-segment tests, edge multisets, point-in-
polygon by ray crossing, linear functions interpolated exactly.
"""

import numpy as np
import pytest

from core.conforming import TEMPLATE_VARIANTS, TEMPLATES, clip_convex_rings, parent_weights, triangulate_hanging
from core.contacts import split_at_contacts
from core.hierarchy import ElementTree, output_mesh
from core.outmesh import OutputMesh
from core.patches import make_patches
from core.scene import scene_from_polygons

#: Float64 rounding in sums of a few thousand leaf areas of O(1) size.
AREA_RTOL = 1e-12
#: A point lies on a segment (T-junction test) within this times the segment length.
ON_SEGMENT_REL = 1e-9
#: Two distinct points of one object are never closer than this times the smallest leaf size.
DUPLICATE_REL = 1e-6
#: Positions reproduced by parent weights within this times the polygon's size.
POSITION_RTOL = 1e-9
#: Output face normals agree with their scene face's: cosine at least 1 - this.
NORMAL_COS_SLACK = 1e-9

RHO = [[0.5, 0.5, 0.5], [0.6, 0.3, 0.2]]
LE = [[1.0, 1.0, 1.0], [0.0, 0.0, 0.0]]


def _rotation(rng):
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return q * np.sign(np.linalg.det(q))


def room_scene(rotate_seed=None):
    """A room as an architect models it: a concave L-shaped n-gon floor and ceiling, one quad per
    wall except one wall made of two triangles, and a box (its own object, no bottom) standing
    on the floor, so contact cuts apply. Optionally rotated off the axes."""
    L = [(0, 0), (6, 0), (6, 3), (3, 3), (3, 5), (0, 5)]
    h = 3.0
    polys, objs, mats = [], [], []
    polys.append([(x, y, 0.0) for x, y in L])
    polys.append([(x, y, h) for x, y in L[::-1]])
    objs += [0, 0]
    mats += [1, 0]                               # the ceiling emits
    for i in range(len(L)):
        (x0, y0), (x1, y1) = L[i], L[(i + 1) % len(L)]
        q = [(x0, y0, 0.0), (x0, y0, h), (x1, y1, h), (x1, y1, 0.0)]    # normal into the room
        if i == 0:
            polys += [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]
            objs += [0, 0]
            mats += [1, 1]
        else:
            polys.append(q)
            objs.append(0)
            mats.append(1)
    x0, y0, z0, x1, y1, z1 = 1.0, 1.0, 0.0, 2.2, 1.7, 0.8
    for p in ([(x0, y0, z1), (x1, y0, z1), (x1, y1, z1), (x0, y1, z1)],
              [(x0, y0, z0), (x1, y0, z0), (x1, y0, z1), (x0, y0, z1)],
              [(x1, y0, z0), (x1, y1, z0), (x1, y1, z1), (x1, y0, z1)],
              [(x1, y1, z0), (x0, y1, z0), (x0, y1, z1), (x1, y1, z1)],
              [(x0, y1, z0), (x0, y0, z0), (x0, y0, z1), (x0, y1, z1)]):
        polys.append(p)
        objs.append(1)
        mats.append(1)
    verts = np.array([v for p in polys for v in p], dtype=np.float64)
    if rotate_seed is not None:
        rng = np.random.default_rng(rotate_seed)
        verts = verts @ _rotation(rng).T + rng.normal(size=3) * 10.0
    idx, n = [], 0
    for p in polys:
        idx.append(list(range(n, n + len(p))))
        n += len(p)
    # Weld the room's own vertices (shared edges), as a modeller's mesh has them.
    uniq, inv = np.unique(np.round(verts, 9), axis=0, return_inverse=True)
    inv = inv.reshape(-1)
    first = np.full(uniq.shape[0], -1)
    first[inv[::-1]] = np.arange(inv.size)[::-1]
    idx = [[int(inv[i]) for i in p] for p in idx]
    return scene_from_polygons(verts[first], idx, mats, RHO, LE, face_objects=objs,
                               object_names=["room", "box"])


def level0(scene, max_edge=1.0):
    patches, _, _ = split_at_contacts(scene, make_patches(scene, max_edge))
    return patches, ElementTree.from_patches(scene, patches)


def random_tree(seed, rounds=4, p=0.3, rotate_seed=None):
    scene = room_scene(rotate_seed)
    patches, tree = level0(scene)
    rng = np.random.default_rng(seed)
    for _ in range(rounds):
        tree, _ = tree.split(rng.random(tree.n_leaves) < p)
    return scene, patches, tree


def _points_inside_segments(points, a, b, candidates, with_t=False, tol=ON_SEGMENT_REL):
    """(S,) int: how many of ``candidates`` (point ids) lie strictly inside each segment a-b
    (and, ``with_t``, the largest distance of their parameters from 0.5).

    Brute force over the candidates whose x lies in the segment's x range (a sort and two
    searches), then the exact test on every such (segment, point) pair.
    """
    from core.geometry import ragged
    P = points[np.asarray(candidates)]
    order = np.argsort(P[:, 0], kind="stable")
    P, px = P[order], P[order, 0]
    A, B = points[a], points[b]
    lo = np.searchsorted(px, np.minimum(A[:, 0], B[:, 0]) - 1e-9, side="left")
    hi = np.searchsorted(px, np.maximum(A[:, 0], B[:, 0]) + 1e-9, side="right")
    seg, k, _ = ragged(hi - lo)
    Q = P[lo[seg] + k]
    d = B[seg] - A[seg]
    L2 = np.sum(d * d, axis=1)
    t = np.sum((Q - A[seg]) * d, axis=1) / L2
    off = np.linalg.norm(np.cross(d, Q - A[seg]), axis=1) / np.sqrt(L2)
    inside = (t > ON_SEGMENT_REL) & (t < 1 - ON_SEGMENT_REL) & (off <= tol * np.sqrt(L2))
    counts = np.bincount(seg[inside], minlength=a.size)
    if with_t:
        dev = np.zeros(a.size)
        np.maximum.at(dev, seg[inside], np.abs(t[inside] - 0.5))
        return counts, dev
    return counts


def _polygon_edges(polys):
    cv, sizes, starts = polys["corner_verts"], polys["face_sizes"], polys["face_starts"]
    f = np.repeat(np.arange(sizes.size), sizes)
    local = np.arange(cv.size) - starts[f]
    return cv, cv[starts[f] + (local + 1) % sizes[f]], f


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_leaves_tile_every_face(seed):
    scene, _, tree = random_tree(seed, rotate_seed=seed)
    area = np.bincount(tree.leaf_face, tree.areas, minlength=scene.n_faces)
    np.testing.assert_allclose(area, scene.face_areas, rtol=AREA_RTOL)
    assert tree.leaf_level.max() >= 3
    # Leaves of a face are contiguous and in face order (the Patches contract).
    assert np.all(np.diff(tree.leaf_face) >= 0)


@pytest.mark.parametrize("seed", [3, 4])
def test_balance_at_most_one_midpoint_per_edge(seed):
    scene, _, tree = random_tree(seed, rounds=5, p=0.2, rotate_seed=seed)
    obj = np.asarray(scene.face_objects)[tree.leaf_face]
    a = tree.leaves
    b = np.roll(a, -1, axis=1)
    valid = a != b
    for o in np.unique(obj):
        rows = obj == o
        ea, eb = a[rows][valid[rows]], b[rows][valid[rows]]
        ids = np.unique(a[rows])
        n_inside, dev = _points_inside_segments(tree.points, ea, eb, ids, with_t=True)
        assert n_inside.max() <= 1
        # The one point inside, if any, is the midpoint.
        hang = n_inside == 1
        assert hang.any() and dev.max() <= 1e-12
        # hanging() reports exactly these edges.
        assert np.array_equal(tree.hanging()[rows][valid[rows]], hang)


def test_split_keeps_point_ids_and_parent_areas():
    scene, _, tree = random_tree(5, rounds=2)
    rng = np.random.default_rng(7)
    mask = rng.random(tree.n_leaves) < 0.25
    new, parent = tree.split(mask)
    assert np.array_equal(new.points[:tree.points.shape[0]], tree.points)
    assert parent.shape == (new.n_leaves,)
    np.testing.assert_allclose(np.bincount(parent, new.areas, minlength=tree.n_leaves), tree.areas,
                               rtol=1e-12, atol=1e-15)
    counts = np.bincount(parent, minlength=tree.n_leaves)
    assert np.all(counts[mask] == 4)
    assert np.all(np.isin(counts, [1, 4]))
    split = counts == 4
    assert np.array_equal(new.leaf_level, tree.leaf_level[parent] + split[parent])
    assert np.array_equal(new.leaf_face, tree.leaf_face[parent])
    # Leaves not split keep their corners.
    same = ~split[parent]
    assert np.array_equal(new.leaves[same], tree.leaves[parent[same]])


@pytest.mark.parametrize("rounds", [0, 4])
def test_conforming_has_no_t_junctions(rounds):
    scene, _, tree = random_tree(11, rounds=rounds, rotate_seed=2)
    open_objects = _assert_conforming(scene, tree)
    assert open_objects == [1]                  # the room is closed, the box has no bottom


def t_junction_wall(float32_offset=None):
    """One object, as SketchUp exports it: a wall quad with two quads on top whose shared vertex
    lies inside the wall's top edge (a T-junction in the user's mesh), non-axis-aligned;
    optionally moved ``float32_offset`` metres away and rounded to float32 as Blender stores it
    (the T-point is then off the wall's edge by float32 rounding)."""
    v = np.array([[0, 0, 0], [4, 0, 0], [4, 0, 1], [0, 0, 1], [1.5, 0, 1],
                  [0, 0, 2.2], [1.5, 0, 2.2], [4, 0, 2.2]], float)
    R = _rotation(np.random.default_rng(8))
    v = v @ R.T
    if float32_offset is not None:
        v = (v + float32_offset).astype(np.float32).astype(np.float64)
    return scene_from_polygons(v, [[0, 1, 2, 3],
                                         [3, 4, 6, 5], [4, 2, 7, 6]], [1, 1, 0], RHO, LE)


@pytest.mark.parametrize("rounds, offset", [(0, None), (3, None), (0, 50.0), (3, 50.0), (0, 3e4),
                                           (3, 3e4)])
def test_user_t_junctions_are_made_conforming(rounds, offset):
    scene = t_junction_wall(offset)
    patches = make_patches(scene, 0.7)         # misaligned points along the shared line
    tree = ElementTree.from_patches(scene, patches)
    assert tree.n_leaves > patches.n_patches   # the wall's top row was re-triangulated
    rng = np.random.default_rng(rounds)
    for _ in range(rounds):
        tree, _ = tree.split(rng.random(tree.n_leaves) < 0.4)
    # At 30 km the float32 corners (2 mm apart from their true places) leave the quads warped:
    # the scene's Newell area and the elements' triangles differ by 1.6e-4 (1e-3 allowed).
    rtol = AREA_RTOL if offset is None else 1e-6 if offset < 1e3 else 1e-3
    np.testing.assert_allclose(np.bincount(tree.leaf_face, tree.areas, minlength=3),
                               scene.face_areas, rtol=rtol)
    assert _assert_conforming(scene, tree,
                              on_segment=ON_SEGMENT_REL if offset is None else 1e-5) == [0]


def test_floating_t_junctions_are_made_conforming():
    """A lintel quad resting on a wall's top edge, same object, no vertex shared: its bottom
    corners lie inside the wall's edge and the wall's patch corners inside the lintel's."""
    v = np.array([[0, 0, 0], [4, 0, 0], [4, 0, 1], [0, 0, 1],
                  [1.3, 0, 1], [3.1, 0, 1], [3.1, 0, 1.5], [1.3, 0, 1.5]], float)
    v = v @ _rotation(np.random.default_rng(9)).T
    scene = scene_from_polygons(v, [[0, 1, 2, 3], [4, 5, 6, 7]], [1, 0], RHO, LE)
    patches = make_patches(scene, 0.45)
    tree = ElementTree.from_patches(scene, patches)
    assert tree.n_leaves > patches.n_patches
    rng = np.random.default_rng(1)
    for _ in range(3):
        tree, _ = tree.split(rng.random(tree.n_leaves) < 0.4)
        np.testing.assert_allclose(np.bincount(tree.leaf_face, tree.areas, minlength=2),
                                   scene.face_areas, rtol=AREA_RTOL)
        polys = tree.conforming()
        a, b, _ = _polygon_edges(polys)
        key = np.unique(np.stack([np.minimum(a, b), np.maximum(a, b)], 1), axis=0)
        assert _points_inside_segments(tree.points, key[:, 0], key[:, 1],
                                       np.unique(polys["corner_verts"])).max() == 0


def _assert_conforming(scene, tree, on_segment=ON_SEGMENT_REL):
    """Check the conforming output object by object; returns the objects with open boundaries."""
    polys = tree.conforming()
    a, b, f = _polygon_edges(polys)
    obj = np.asarray(scene.face_objects)[polys["face_parent"][f]]
    open_objects = []
    for o in np.unique(obj):
        sel = obj == o
        key, counts = np.unique(np.stack([np.minimum(a[sel], b[sel]), np.maximum(a[sel], b[sel])], 1),
                                axis=0, return_counts=True)
        assert counts.max() == 2
        # No object point strictly inside any output edge: every edge is conforming.
        ids = np.unique(polys["corner_verts"][obj == o])
        assert _points_inside_segments(tree.points, key[:, 0], key[:, 1], ids, tol=on_segment).max() == 0
        # Edges used once lie on the object's boundary (its scene edges used by one face).
        sc, sf = scene.face_corner_indices()
        sv = np.asarray(scene.corner_verts)[sc]
        nxt = np.r_[sc[1:], 0]
        last = np.r_[sf[1:] != sf[:-1], True]
        nxt = np.where(last, np.asarray(scene.face_starts)[sf], nxt)
        sa, sb = sv, np.asarray(scene.corner_verts)[nxt]
        sel_s = np.asarray(scene.face_objects)[sf] == o
        sk, sc_count = np.unique(np.stack([np.minimum(sa, sb), np.maximum(sa, sb)], 1)[sel_s],
                                 axis=0, return_counts=True)
        bound = sk[sc_count == 1]
        once = key[counts == 1]
        if once.shape[0] == 0:
            continue
        open_objects.append(int(o))
        mid = (tree.points[once[:, 0]] + tree.points[once[:, 1]]) / 2
        A, B = scene.vertices[bound[:, 0]], scene.vertices[bound[:, 1]]
        d = B - A
        t = np.clip(np.einsum("mbj,bj->mb", mid[:, None] - A[None], d) / np.sum(d * d, 1), 0, 1)
        dist = np.linalg.norm(A[None] + t[..., None] * d[None] - mid[:, None], axis=2).min(axis=1)
        assert np.all(dist <= 1e-9)
    return open_objects


def test_conforming_faces_tile_with_positive_area_and_parent_normals():
    scene, _, tree = random_tree(12, rounds=4, rotate_seed=5)
    polys = tree.conforming()
    pts = tree.points
    sizes, starts, cv = polys["face_sizes"], polys["face_starts"], polys["corner_verts"]
    assert set(np.unique(sizes)) <= {3, 4}
    poly = pts[cv[starts[:, None] + np.minimum(np.arange(4)[None], sizes[:, None] - 1)]]
    v = np.zeros((sizes.size, 3))
    for k in range(4):
        v += np.cross(poly[:, k], poly[:, (k + 1) % 4])
    v /= 2
    area = np.linalg.norm(v, axis=1)
    parent = polys["face_parent"]
    assert np.all(area > 1e-9 * tree.sizes[polys["face_leaf"]] ** 2)
    cos = np.einsum("ij,ij->i", v / area[:, None], scene.face_normals[parent])
    assert cos.min() >= 1 - NORMAL_COS_SLACK
    np.testing.assert_allclose(np.bincount(parent, area, minlength=scene.n_faces), scene.face_areas,
                               rtol=AREA_RTOL)
    # Unsplit leaves without hanging edges stay as they are: quads stay quads.
    plain = ~tree.hanging().any(axis=1)
    n_quads_plain = np.count_nonzero(plain & ~tree.is_triangle)
    assert np.count_nonzero(sizes == 4) == n_quads_plain


def test_no_duplicate_points():
    scene, _, tree = random_tree(13, rounds=4, rotate_seed=1)
    used = np.unique(tree.leaves)
    assert used.size == tree.points.shape[0]
    obj_of_point = np.zeros(tree.points.shape[0], np.int64)
    obj_of_point[tree.leaves.ravel()] = np.repeat(np.asarray(scene.face_objects)[tree.leaf_face], 4)
    tol = DUPLICATE_REL * tree.sizes.min()
    for o in np.unique(obj_of_point):
        P = tree.points[obj_of_point == o]
        P = P[np.argsort(P[:, 0], kind="stable")]
        # Every pair within tol in x is compared (a sliding window over the x order).
        for shift in range(1, P.shape[0]):
            close_x = P[shift:, 0] - P[:-shift, 0] <= tol
            if not close_x.any():
                break
            d = np.linalg.norm(P[shift:] - P[:-shift], axis=1)
            assert d[close_x].min() > tol


def test_weld_is_relative_to_the_local_size():
    """Two quads of one object whose shared corners differ by rounding-sized offsets are welded,
    at millimetre scale, far from the origin; corners 1e-5 of the size apart are not."""
    for scale, offset in ((1e-3, 1e3), (1.0, 0.0)):
        v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
                      [1, 0, 0], [2, 0, 0], [2, 1, 0], [1, 1, 0]], float) * scale + offset
        v[4, 0] += 1e-10 * scale
        v[7, 1] -= 3e-11 * scale
        scene = scene_from_polygons(v, [[0, 1, 2, 3], [4, 5, 6, 7]], [0, 0], RHO, LE)
        tree = ElementTree.from_patches(scene, make_patches(scene, 10.0 * scale))
        assert tree.points.shape[0] == 6
        v[4, 0] += 1e-5 * scale
        scene = scene_from_polygons(v, [[0, 1, 2, 3], [4, 5, 6, 7]], [0, 0], RHO, LE)
        tree = ElementTree.from_patches(scene, make_patches(scene, 10.0 * scale))
        assert tree.points.shape[0] == 7


def _convex_ring(rng, n_corners, n_extra, inward=0.0):
    """A random convex polygon in a random plane with points inserted on its edges (moved
    ``inward`` times the edge length towards the inside, as float32 rounding may); returns the
    points, the normal and which points were inserted."""
    ang = np.sort(rng.uniform(0, 2 * np.pi, n_corners))
    r = rng.uniform(0.5, 1.5, n_corners)
    xy = np.stack([np.cos(ang), np.sin(ang)], 1) * r[:, None]
    # Convex hull order: keep the corners that are strictly convex.
    hull = _hull(xy)
    pts, flat = [], []
    for i in range(len(hull)):
        p, q = hull[i], hull[(i + 1) % len(hull)]
        pts.append(p)
        flat.append(False)
        inner = np.array([-(q - p)[1], (q - p)[0]])          # left of p -> q: inside
        for t in np.sort(rng.uniform(0.05, 0.95, rng.integers(0, n_extra + 1))):
            pts.append(p + t * (q - p) + inward * inner)
            flat.append(True)
    pts = np.array(pts)
    R = _rotation(rng)
    return np.column_stack([pts, np.zeros(len(pts))]) @ R.T, R[:, 2], np.array(flat)


def _hull(xy):
    """Monotone chain convex hull (counter-clockwise, strictly convex corners)."""
    pts = sorted(map(tuple, xy))

    def half(points):
        h = []
        for p in points:
            while len(h) >= 2 and ((h[-1][0] - h[-2][0]) * (p[1] - h[-2][1])
                                   - (h[-1][1] - h[-2][1]) * (p[0] - h[-2][0])) <= 0:
                h.pop()
            h.append(p)
        return h
    lower, upper = half(pts), half(pts[::-1])
    return np.array(lower[:-1] + upper[:-1])


@pytest.mark.parametrize("inward", [0.0, 1e-7, -1e-7])
def test_clip_convex_rings_tiles_without_degenerate_triangles(inward):
    rng = np.random.default_rng(3)
    rings = [_convex_ring(rng, rng.integers(3, 8), 3, inward) for _ in range(200)]
    K = max(len(p) for p, _, _ in rings)
    pos = np.zeros((len(rings), K, 3))
    flat = np.zeros((len(rings), K), bool)
    count = np.array([len(p) for p, _, _ in rings])
    for i, (p, _, f) in enumerate(rings):
        pos[i, :len(p)] = p
        flat[i, :len(p)] = f
    normals = np.array([n for _, n, _ in rings])
    # Exactly on their edges, the flat points are found from the geometry; off by rounding,
    # they must be named.
    tris, owner = clip_convex_rings(pos, count, normals, None if inward == 0 else flat)
    assert np.array_equal(np.bincount(owner, minlength=len(rings)), count - 2)
    t = pos[owner[:, None], tris]
    signed = np.einsum("ij,ij->i", np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), normals[owner]) / 2
    assert signed.min() > 1e-6
    ring_area = np.array([np.linalg.norm(sum(np.cross(p[k], p[(k + 1) % len(p)])
                                             for k in range(len(p)))) / 2 for p, _, _ in rings])
    np.testing.assert_allclose(np.bincount(owner, signed), ring_area, rtol=1e-12)
    # Every ring vertex is used (no T-junction left on the boundary).
    used = np.zeros(pos.shape[:2], bool)
    used[owner[:, None], tris] = True
    assert np.all(used == (np.arange(K)[None] < count[:, None]))


@pytest.mark.parametrize("code", sorted(TEMPLATES))
def test_templates_on_random_convex_elements(code):
    """Every hanging pattern triangulates random convex quads / triangles: positive areas, the
    element's area, and each boundary sub-edge once, each inner edge twice."""
    rng = np.random.default_rng(code)
    is_tri = code >= 16
    n = 50
    ids = np.arange(n * 8).reshape(n, 8)
    pts = np.zeros((n * 8, 3))
    normals = []
    for e in range(n):
        while True:
            ring, normal, _ = _convex_ring(rng, 3 if is_tri else 4, 0)
            if len(ring) == (3 if is_tri else 4):
                break
        corners = ring if not is_tri else np.vstack([ring, ring[2:]])
        pts[ids[e, :4]] = corners
        pts[ids[e, 4:]] = (corners + np.roll(corners, -1, axis=0)) / 2
        normals.append(normal)
    leaves = ids[:, :4].copy()
    if is_tri:
        leaves[:, 3] = leaves[:, 2]
    hang = (code % 16 >> np.arange(4)) & 1
    mids = np.where(hang[None].astype(bool), ids[:, 4:], -1)
    normals = np.array(normals)
    c = pts[leaves]
    area = np.linalg.norm(sum(np.cross(c[:, k], c[:, (k + 1) % 4]) for k in range(4)), axis=1) / 2
    table = np.concatenate([leaves, mids], axis=1)
    worst = []
    for tmpl in TEMPLATE_VARIANTS[code]:        # each variant alone, then the per-leaf choice
        cv = table[:, tmpl]                     # (n, t, 3)
        t = pts[cv]
        signed = np.einsum("itj,ij->it", np.cross(t[:, :, 1] - t[:, :, 0], t[:, :, 2] - t[:, :, 0]),
                           normals) / 2
        assert signed.min() > 0
        np.testing.assert_allclose(signed.sum(axis=1), area, rtol=1e-12)
        edges = np.sort(np.stack([cv, np.roll(cv, -1, axis=2)], 3).reshape(-1, 2), axis=1)
        key, count = np.unique(edges, axis=0, return_counts=True)
        n_boundary = (3 if is_tri else 4) + int(hang.sum())
        assert np.count_nonzero(count == 1) == n * n_boundary
        assert count.max() == 2
        longest = np.max([np.sum((t[:, :, k] - t[:, :, (k + 1) % 3]) ** 2, axis=2) for k in range(3)],
                         axis=0)
        worst.append((2 * signed / longest).min(axis=1))
    out = triangulate_hanging(leaves, np.full(n, is_tri), mids, pts)
    assert np.all(out["face_sizes"] == 3)
    t = pts[out["corner_verts"].reshape(-1, 3)]
    signed = np.einsum("ij,ij->i", np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]),
                       normals[out["face_leaf"]]) / 2
    np.testing.assert_allclose(np.bincount(out["face_leaf"], signed), area, rtol=1e-12)
    longest = np.max([np.sum((t[:, k] - t[:, (k + 1) % 3]) ** 2, axis=1) for k in range(3)], axis=0)
    chosen = np.full(n, np.inf)
    np.minimum.at(chosen, out["face_leaf"], 2 * signed / longest)
    np.testing.assert_allclose(chosen, np.max(worst, axis=0), rtol=1e-9)


def _inside_polygon(xy, poly):
    """Even-odd ray crossing: (m,) bool for points xy (m, 2) in polygon poly (k, 2)."""
    inside = np.zeros(xy.shape[0], bool)
    for i in range(len(poly)):
        (x0, y0), (x1, y1) = poly[i], poly[(i + 1) % len(poly)]
        cross = (y0 > xy[:, 1]) != (y1 > xy[:, 1])
        with np.errstate(divide="ignore", invalid="ignore"):
            xc = x0 + (xy[:, 1] - y0) * (x1 - x0) / (y1 - y0)
        inside ^= cross & (xy[:, 0] < xc)
    return inside


@pytest.mark.parametrize("scale", [1e-3, 1.0, 1e3])
def test_parent_weights_reproduce_positions_and_linear_functions(scale):
    rng = np.random.default_rng(int(scale * 1000) % 97)
    shapes = [np.array([[0, 0], [2, 0], [2, 1], [1, 1], [1, 2], [0, 2]], float),     # L, concave
              np.array([[0, 0], [1, 0], [0.3, 0.3], [0, 1]], float),                   # concave quad
              np.array([[0, 0], [1, 0.1], [1.2, 1], [0.1, 0.9]], float),               # convex quad
              np.array([[0, 0], [1, 0], [0.2, 0.8]], float),                            # triangle
              np.array([[np.cos(a) * (1 + 0.5 * (k % 2)), np.sin(a) * (1 + 0.5 * (k % 2))]
                        for k, a in enumerate(np.linspace(0, 2 * np.pi, 12, endpoint=False))])]  # star
    verts, polys, xs, faces = [], [], [], []
    n = 0
    for f, shape in enumerate(shapes):
        R = _rotation(rng)
        origin = rng.normal(size=3) * 5 * scale
        v3 = origin + (np.column_stack([shape, np.zeros(len(shape))]) * scale) @ R.T
        verts.append(v3)
        polys.append(list(range(n, n + len(shape))))
        n += len(shape)
        lo, hi = shape.min(0), shape.max(0)
        cand = rng.uniform(lo, hi, size=(400, 2))
        cand = np.vstack([cand[_inside_polygon(cand, shape)], shape])    # corners too
        xs.append(origin + (np.column_stack([cand, np.zeros(len(cand))]) * scale) @ R.T)
        faces.append(np.full(len(cand), f))
    scene = scene_from_polygons(np.vstack(verts), polys, [0] * len(shapes), RHO, LE)
    x, fp = np.vstack(xs), np.concatenate(faces)
    src, w = parent_weights(scene, fp, x)
    assert src.shape == (x.shape[0], 3) and w.shape == (x.shape[0], 3)
    assert w.min() >= 0
    np.testing.assert_allclose(w.sum(axis=1), 1.0, rtol=0, atol=1e-12)
    # Sources are corners of the point's own face.
    face_of_corner = np.repeat(np.arange(scene.n_faces), scene.face_sizes)
    assert np.all(face_of_corner[src] == fp[:, None])
    pos = np.einsum("ck,ckj->cj", w, scene.vertices[scene.corner_verts[src]])
    np.testing.assert_allclose(pos, x, rtol=0, atol=POSITION_RTOL * 10 * scale)
    # A linear function of position is interpolated exactly (an affine UV map).
    g, c0 = rng.normal(size=3) / scale, 0.3
    f_corner = scene.vertices[scene.corner_verts] @ g + c0
    np.testing.assert_allclose(np.einsum("ck,ck->c", w, f_corner[src]), x @ g + c0, atol=1e-8)


def test_parent_weights_chunks_agree(monkeypatch):
    """Evaluated in many small chunks (as for a huge n-gon) the weights are the same."""
    import core.conforming as conforming
    scene = room_scene(rotate_seed=3)
    _, tree = level0(scene, 0.5)
    polys = tree.conforming()
    fp = polys["face_parent"][np.repeat(np.arange(polys["face_sizes"].size), polys["face_sizes"])]
    x = tree.points[polys["corner_verts"]]
    src, w = parent_weights(scene, fp, x)
    monkeypatch.setattr(conforming, "PAIR_CHUNK", 7)
    src2, w2 = parent_weights(scene, fp, x)
    assert np.array_equal(src, src2) and np.array_equal(w, w2)


def test_output_mesh_and_as_patches():
    scene, patches, tree = random_tree(21, rounds=3, rotate_seed=4)
    polys = tree.conforming()
    C = polys["corner_verts"].size
    colours = np.random.default_rng(0).random((C, 3))
    out = output_mesh(scene, tree, polys, colours)
    assert isinstance(out, OutputMesh)
    pos = np.einsum("ck,ckj->cj", out.corner_weights,
                    scene.vertices[scene.corner_verts[out.corner_sources]])
    np.testing.assert_allclose(pos, out.vertices[out.corner_verts], atol=1e-9)
    assert np.array_equal(out.corner_colours, colours)
    p = tree.as_patches()
    assert p.n_patches == tree.n_leaves
    np.testing.assert_allclose(p.areas, tree.areas)
    # Incidence: every corner of every valid scene face is a corner of some leaf, at its vertex.
    valid_corners = np.flatnonzero(np.repeat(scene.face_valid, scene.face_sizes))
    assert np.array_equal(np.unique(p.incidence_corner), valid_corners)
    at = p.corners[p.incidence_patch, p.incidence_slot]
    np.testing.assert_allclose(at, scene.vertices[p.incidence_vertex], atol=1e-12)
    assert np.array_equal(np.unique(patches.incidence_corner), valid_corners)


def test_module_example_runs():
    import doctest

    import core.hierarchy
    result = doctest.testmod(core.hierarchy)
    assert result.attempted >= 8 and result.failed == 0


def test_errors_name_the_argument():
    scene, patches, tree = random_tree(0, rounds=1)
    E = tree.n_leaves
    with pytest.raises(ValueError, match="mask"):
        tree.split(np.zeros(E + 1, bool))
    with pytest.raises(ValueError, match="mask"):
        tree.split(np.zeros(E, np.int64))
    with pytest.raises(ValueError, match="mask"):
        tree.split([False] * E)
    with pytest.raises(TypeError, match="patches"):
        ElementTree.from_patches(scene, patches.corners)
    with pytest.raises(ValueError, match="patches"):
        ElementTree.from_patches(t_junction_wall(), patches)
    with pytest.raises(ValueError, match="face_parent_of_corner"):
        parent_weights(scene, np.array([0.5]), np.zeros((1, 3)))
    with pytest.raises(ValueError, match="face_parent_of_corner"):
        parent_weights(scene, np.array([scene.n_faces]), np.zeros((1, 3)))
    with pytest.raises(ValueError, match="positions"):
        parent_weights(scene, np.array([0, 1]), np.zeros((1, 3)))
    polys = tree.conforming()
    with pytest.raises(ValueError, match="corner_colours"):
        output_mesh(scene, tree, polys, np.zeros((3, 3)))
