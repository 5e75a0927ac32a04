"""Tests of core/raycast.py: BVH traversal against brute force and geometric edge cases."""

import numpy as np
import pytest

from core.raycast import BVH, LEAF_SIZE, any_hit, build_bvh, closest_hit
import core.raycast as rc


def brute_force(tris, o, d, t_max):
    """Independent oracle: every ray against every triangle with the plain (loop-free, no tree)
    textbook Moller-Trumbore, closest hit per ray, ties to the lowest index."""
    tris = np.asarray(tris, float)
    v0, e1, e2 = tris[:, 0], tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]
    d_ = d[:, None, :]
    p = np.cross(d_, e2[None])
    det = np.einsum("ntj,tj->nt", p, e1)
    s = o[:, None, :] - v0[None]
    with np.errstate(divide="ignore", invalid="ignore"):
        u = np.einsum("ntj,ntj->nt", s, p) / det
        q = np.cross(s, e1[None])
        v = np.einsum("ntj,ntj->nt", np.broadcast_to(d_, q.shape), q) / det
        t = np.einsum("tj,ntj->nt", e2, q) / det
    ok = (np.abs(det) > 1e-14) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
    ok &= t < np.broadcast_to(np.asarray(t_max, float), (o.shape[0],))[:, None]
    t = np.where(ok, t, np.inf)
    best = t.min(axis=1)
    tri = np.where(np.isfinite(best), np.argmin(t, axis=1), -1)
    return best, tri


def random_scene(rng, n_tri, spread=0.08):
    centres = rng.uniform(-1, 1, (n_tri, 1, 3))
    return centres + rng.normal(0, spread, (n_tri, 3, 3))


@pytest.mark.parametrize("n_tri", [1, 3, LEAF_SIZE + 1, 200, 800])
@pytest.mark.parametrize("seed", [0, 1])
def test_closest_hit_matches_brute_force(n_tri, seed):
    rng = np.random.default_rng(seed)
    tris = random_scene(rng, n_tri)
    o = rng.uniform(-1.5, 1.5, (3000, 3))
    d = rng.normal(size=(3000, 3))
    aim = tris.mean(axis=1)[rng.integers(0, n_tri, 1000)]
    d[:1000] = aim - o[:1000]                   # a third aimed at centroids: many hits
    t_max = rng.uniform(0.2, 3.0, 3000)
    t_max[::3] = np.inf
    bvh = build_bvh(tris)
    t, tri = closest_hit(bvh, o, d, t_max)
    tb, trib = brute_force(tris, o, d, t_max)
    # Random rays almost never graze an edge, where the slack tol.barycentric could matter: the
    # winning triangle must agree exactly, t to rounding (same formula, different operand order).
    assert np.array_equal(tri, trib)
    np.testing.assert_allclose(t, tb, rtol=1e-12)
    assert (tri >= 0).mean() > 0.2             # the test exercises hits, not only misses
    np.testing.assert_array_equal(any_hit(bvh, o, d, t_max), trib >= 0)


def test_rays_from_outside_a_dense_box_hit_the_first_face():
    # A closed unit cube of 12 triangles: a ray from outside towards the centre hits the face it
    # enters at the analytic distance.
    v = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    tris = np.array([[v[a], v[b], v[c]] for a, b, c, e in quads] +
                    [[v[a], v[c], v[e]] for a, b, c, e in quads])
    rng = np.random.default_rng(3)
    target = rng.uniform(0.2, 0.8, (500, 3))
    o = target + np.array([0.0, 0.0, 2.0])               # above the top face z = 1
    t, tri = closest_hit(build_bvh(tris), o, target - o)
    # direction = target - o has length 2 along -z: the plane z = 1 is reached at t = (z + 1) / 2
    np.testing.assert_allclose(t, (target[:, 2] + 1.0) / 2.0, rtol=1e-12)
    assert set(np.unique(tri)) <= {5, 11}                 # the two triangles of quad (1, 5, 7, 3)


def test_t_max_is_strict():
    tri = np.array([[[0, 0, 1], [1, 0, 1], [0, 1, 1]]], float)
    bvh = build_bvh(tri)
    o = np.array([[0.2, 0.2, 0.0]] * 3)
    d = np.array([[0, 0, 1.0]] * 3)
    t, idx = closest_hit(bvh, o, d, np.array([1.0, 1.0 + 1e-9, np.inf]))
    assert idx.tolist() == [-1, 0, 0]                    # hit exactly at t = t_max: not counted
    np.testing.assert_allclose(t[1:], 1.0)
    assert any_hit(bvh, o, d, np.array([1.0, 1.0 + 1e-9, 0.5])).tolist() == [False, True, False]


def test_ray_through_a_shared_edge_hits_the_lower_index_and_never_leaks():
    # Two triangles of a unit square share the diagonal x = y; rays aimed exactly at it.
    sq = np.array([[[0, 0, 0], [1, 0, 0], [1, 1, 0]], [[0, 0, 0], [1, 1, 0], [0, 1, 0]]], float)
    s = np.linspace(0.05, 0.95, 19)
    o = np.stack([s, s, np.ones_like(s)], axis=1)
    d = np.tile([0.0, 0.0, -1.0], (s.size, 1))
    for tris, expected in ((sq, 0), (sq[::-1], 0)):
        t, idx = closest_hit(build_bvh(tris), o, d)
        assert np.all(idx == expected)
        np.testing.assert_allclose(t, 1.0)


def test_ray_in_the_plane_of_a_triangle_along_its_edge_misses():
    tri = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]]], float)
    bvh = build_bvh(tri)
    o = np.array([[-1.0, 0.0, 0.0], [-1.0, 0.3, 0.0]])    # along the edge y = 0, and in-plane
    d = np.array([[1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    t, idx = closest_hit(bvh, o, d)
    assert idx.tolist() == [-1, -1] and np.all(np.isinf(t))
    assert not any_hit(bvh, o, d).any()


def test_parallel_axis_rays_with_zero_direction_components():
    # Axis-aligned rays (two direction components exactly 0) against an axis-aligned flat grid:
    # exercises the 0 * inf case of the slab test and flat (zero-thickness) boxes.
    n = 10
    xs = np.linspace(0, 1, n + 1)
    tris = []
    for i in range(n):
        for j in range(n):
            a, b, c, e = ([xs[i], xs[j], 0.5], [xs[i + 1], xs[j], 0.5],
                          [xs[i + 1], xs[j + 1], 0.5], [xs[i], xs[j + 1], 0.5])
            tris += [[a, b, c], [a, c, e]]
    tris = np.array(tris)
    rng = np.random.default_rng(4)
    xy = rng.uniform(0, 1, (400, 2))
    o = np.column_stack([xy, np.zeros(400)])
    d = np.tile([0.0, 0.0, 1.0], (400, 1))
    t, idx = closest_hit(build_bvh(tris), o, d)
    np.testing.assert_allclose(t, 0.5)
    tb, ib = brute_force(tris, o, d, np.inf)
    assert np.array_equal(idx, ib)
    # Rays starting exactly on a slab plane (x = 0, the grid's border) and parallel to it.
    o2 = np.column_stack([np.zeros(50), rng.uniform(0.01, 0.99, 50), np.zeros(50)])
    t2, idx2 = closest_hit(build_bvh(tris), o2, np.tile([0.0, 0.0, 1.0], (50, 1)))
    assert np.all(idx2 >= 0)


def test_many_rays_cross_chunk_boundaries(monkeypatch):
    monkeypatch.setattr(rc, "RAY_CHUNK", 97)
    rng = np.random.default_rng(5)
    tris = random_scene(rng, 300)
    o = rng.uniform(-1.5, 1.5, (1000, 3))
    d = rng.normal(size=(1000, 3))
    t, tri = closest_hit(build_bvh(tris), o, d)
    assert np.array_equal(tri, brute_force(tris, o, d, np.inf)[1])


def test_inputs_are_not_mutated_and_degenerate_triangles_are_never_hit():
    rng = np.random.default_rng(6)
    tris = random_scene(rng, 50)
    tris[7] = tris[7, 0]                                    # a point: zero area
    tris[9, 2] = tris[9, 1]                                 # a segment
    o = rng.uniform(-1.5, 1.5, (2000, 3))
    d = rng.normal(size=(2000, 3))
    copies = tris.copy(), o.copy(), d.copy()
    bvh = build_bvh(tris)
    _, tri = closest_hit(bvh, o, d)
    assert not np.isin(tri, [7, 9]).any()
    for a, b in zip(copies, (tris, o, d)):
        np.testing.assert_array_equal(a, b)


def test_tree_is_balanced_and_leaves_cover_every_triangle():
    tris = random_scene(np.random.default_rng(7), 1000)
    bvh = build_bvh(tris)
    leaves = bvh.child < 0
    assert np.all(bvh.count[leaves] <= LEAF_SIZE)
    slots = np.concatenate([np.arange(s, s + c)
                            for s, c in zip(bvh.start[leaves], bvh.count[leaves])])
    assert np.array_equal(np.sort(slots), np.arange(1000))
    assert np.array_equal(np.sort(bvh.order), np.arange(1000))
    assert bvh.depth == int(np.ceil(np.log2(1000 / LEAF_SIZE))) + 1   # median split: balanced
    # every node box contains its triangles
    for node in np.flatnonzero(leaves)[:50]:
        members = tris[bvh.order[bvh.start[node]:bvh.start[node] + bvh.count[node]]]
        assert np.all(members.min(axis=(0, 1)) >= bvh.lo[node])
        assert np.all(members.max(axis=(0, 1)) <= bvh.hi[node])


def test_stored_rows_are_the_triangles_and_boxes_and_travel_as_fields():
    """The tree keeps one row per coordinate (what the traversal reads); its views in rows of
    points are the triangles themselves, and a tree rebuilt from its fields (as a worker process
    receives it, core.parallel) answers every ray the same."""
    rng = np.random.default_rng(3)
    tris = random_scene(rng, 300)
    bvh = build_bvh(tris)
    assert bvh.planes.flags.c_contiguous and bvh.corners.flags.c_contiguous
    sorted_tris = tris[bvh.order]
    np.testing.assert_array_equal(bvh.v0, sorted_tris[:, 0])
    np.testing.assert_array_equal(bvh.e1, sorted_tris[:, 1] - sorted_tris[:, 0])
    np.testing.assert_array_equal(bvh.e2, sorted_tris[:, 2] - sorted_tris[:, 0])
    np.testing.assert_array_equal(bvh.boxes[:, 0], bvh.lo)
    np.testing.assert_array_equal(bvh.boxes[:, 1], bvh.hi)
    assert np.all(bvh.lo[0] <= tris.min(axis=(0, 1))) and np.all(bvh.hi[0] >= tris.max(axis=(0, 1)))
    copy = BVH(**{k: np.array(v) if isinstance(v, np.ndarray) else v
                  for k, v in vars(bvh).items()})
    o = rng.uniform(-1.5, 1.5, (2000, 3))
    d = rng.normal(size=(2000, 3))
    for a, b in zip(closest_hit(bvh, o, d), closest_hit(copy, o, d)):
        np.testing.assert_array_equal(a, b)
    assert (closest_hit(bvh, o, d)[1] >= 0).mean() > 0.05


@pytest.fixture
def small_bvh():
    return build_bvh(np.array([[[0, 0, 1], [1, 0, 1], [0, 1, 1]]], float))


def test_build_bvh_rejects_bad_shape():
    with pytest.raises(ValueError, match=r"triangles must have shape \(T, 3, 3\); got \(2, 3\)"):
        build_bvh(np.zeros((2, 3)))


def test_build_bvh_rejects_empty():
    with pytest.raises(ValueError, match="at least one triangle"):
        build_bvh(np.zeros((0, 3, 3)))


def test_build_bvh_rejects_nan():
    tris = np.zeros((3, 3, 3))
    tris[1, 2, 0] = np.nan
    with pytest.raises(ValueError, match="triangle 1 holds NaN"):
        build_bvh(tris)


def test_closest_hit_rejects_non_bvh():
    with pytest.raises(TypeError, match="bvh must be a BVH"):
        closest_hit(np.zeros((1, 3, 3)), np.zeros((1, 3)), np.ones((1, 3)))


def test_closest_hit_rejects_bad_origins(small_bvh):
    with pytest.raises(ValueError, match=r"origins must have shape \(N, 3\); got \(3,\)"):
        closest_hit(small_bvh, np.zeros(3), np.ones((1, 3)))


def test_closest_hit_rejects_mismatched_directions(small_bvh):
    with pytest.raises(ValueError, match=r"directions must have shape \(2, 3\)"):
        closest_hit(small_bvh, np.zeros((2, 3)), np.ones((1, 3)))


def test_closest_hit_rejects_zero_direction(small_bvh):
    with pytest.raises(ValueError, match="row 1 is zero"):
        closest_hit(small_bvh, np.zeros((2, 3)), np.array([[0, 0, 1.0], [0, 0, 0]]))


def test_closest_hit_rejects_nan_origin(small_bvh):
    with pytest.raises(ValueError, match="origins must be finite"):
        closest_hit(small_bvh, np.full((1, 3), np.nan), np.ones((1, 3)))


def test_any_hit_rejects_bad_t_max(small_bvh):
    with pytest.raises(ValueError, match="t_max must be > 0"):
        any_hit(small_bvh, np.zeros((2, 3)), np.ones((2, 3)), np.array([1.0, 0.0]))


def test_any_hit_rejects_t_max_shape(small_bvh):
    with pytest.raises(ValueError, match=r"t_max must be a float or have shape \(2,\)"):
        any_hit(small_bvh, np.zeros((2, 3)), np.ones((2, 3)), np.ones(3))


def test_bvh_type_is_exported():
    assert isinstance(build_bvh(np.ones((1, 3, 3))), BVH)
