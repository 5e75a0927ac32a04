"""Polygon helpers: Newell vectors, convexity, concave-quad split, ear clipping."""

import numpy as np
import pytest

from core.geometry import (corner_turns, newell_normals_areas, newell_vectors, plane_basis,
                           quads_convex, split_concave_quads, triangulate_polygon)
from core.geometry import pairs_by_key, sum_at, unique_rows

#: Float64 rounding of sums of a few cross products of O(1) coordinates.
TIGHT = 1e-12


def tri_area_vectors(a, b, c):
    """Independent oracle: 0.5 (b - a) x (c - a) for arrays (n, 3)."""
    return 0.5 * np.cross(b - a, c - a)


def shoelace(xy):
    x, y = xy[:, 0], xy[:, 1]
    return 0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y)


def test_newell_unit_square_and_triangle():
    sq = np.array([[[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]],
                   [[0, 0, 0], [2, 0, 0], [0, 0, 3], [0, 0, 3]]], dtype=float)  # padded triangle
    normals, areas = newell_normals_areas(sq)
    np.testing.assert_allclose(areas, [1.0, 3.0], rtol=TIGHT)
    np.testing.assert_allclose(normals, [[0, 0, 1], [0, -1, 0]], atol=TIGHT)


def test_newell_sizes_equal_padding():
    rng = np.random.default_rng(1)
    polys = rng.normal(size=(20, 6, 3))
    sizes = rng.integers(3, 7, size=20)
    padded = polys.copy()
    for i, s in enumerate(sizes):       # test-side padding by repeating the last corner
        padded[i, s:] = padded[i, s - 1]
    np.testing.assert_allclose(newell_vectors(polys, sizes), newell_vectors(padded), atol=TIGHT)


def test_newell_of_non_planar_quad_is_sum_of_its_triangles():
    rng = np.random.default_rng(2)
    q = rng.normal(size=(50, 4, 3))
    expected = (tri_area_vectors(q[:, 0], q[:, 1], q[:, 2])
                + tri_area_vectors(q[:, 0], q[:, 2], q[:, 3]))
    np.testing.assert_allclose(newell_vectors(q), expected, atol=TIGHT)


def test_newell_far_from_origin_keeps_digits():
    sq = np.array([[[0, 0, 0], [1e-3, 0, 0], [1e-3, 1e-3, 0], [0, 1e-3, 0]]]) + 1e4
    _, area = newell_normals_areas(sq)
    # Centering first: the error is rounding of 1e4-sized coordinates (~1e-12) times 1e-3 sides.
    np.testing.assert_allclose(area, [1e-6], rtol=1e-8)


def test_zero_area_polygon_has_zero_normal():
    line = np.array([[[0, 0, 0], [1, 0, 0], [2, 0, 0]]], dtype=float)
    normals, areas = newell_normals_areas(line)
    assert areas[0] == 0 and np.all(normals[0] == 0)


def test_convexity_square_dart_straight_and_flipped():
    quads = np.array([
        [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]],          # square
        [[0, 0, 0], [2, 0, 0], [0.5, 0.5, 0], [0, 2, 0]],      # dart: reflex at corner 2
        [[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0]],          # straight corner 1 (a triangle)
    ], dtype=float)
    up = np.tile([0.0, 0.0, 1.0], (3, 1))
    np.testing.assert_array_equal(quads_convex(quads, up), [True, False, True])
    np.testing.assert_array_equal(quads_convex(quads[:1], -up[:1]), [False])
    turns = corner_turns(quads[1:2], up[:1])
    assert np.argmin(turns[0]) == 2 and turns[0, 2] < 0


def test_split_concave_quad_covers_it():
    dart = np.array([[[0.5, 0.5, 0], [0, 2, 0], [0, 0, 0], [2, 0, 0]]])   # reflex at corner 0
    up = np.array([[0.0, 0.0, 1.0]])
    tris = split_concave_quads(dart, up)[0]
    pts = dart[0][tris]
    signed = tri_area_vectors(pts[:, 0], pts[:, 1], pts[:, 2])[:, 2]
    assert np.all(signed > 0)
    np.testing.assert_allclose(signed.sum(), shoelace(dart[0][:, :2]), rtol=TIGHT)
    assert np.all(np.any(tris == 0, axis=1))     # the diagonal starts at the reflex corner


def test_plane_basis_is_right_handed():
    rng = np.random.default_rng(3)
    for n in rng.normal(size=(5, 3)):
        n /= np.linalg.norm(n)
        u, v = plane_basis(n)
        np.testing.assert_allclose(np.stack([u, v, n]) @ np.stack([u, v, n]).T, np.eye(3), atol=TIGHT)
        np.testing.assert_allclose(np.cross(u, v), n, atol=TIGHT)


def point_in_polygon(pts, poly):
    """Even-odd rule, independent of the triangulation; pts (n, 2), poly (k, 2)."""
    x, y = pts[:, 0:1], pts[:, 1:2]
    a, b = poly[None, :, :], np.roll(poly, -1, axis=0)[None, :, :]
    crosses = (a[..., 1] > y) != (b[..., 1] > y)
    t = (y - a[..., 1]) / np.where(b[..., 1] == a[..., 1], 1.0, b[..., 1] - a[..., 1])
    xi = a[..., 0] + t * (b[..., 0] - a[..., 0])
    return np.sum(crosses & (x < xi), axis=1) % 2 == 1


def in_triangles(pts, tri):
    """(n, t) bool: point strictly inside each triangle (t, 3, 2)."""
    def side(p, q):
        return ((q[None, :, 0] - p[None, :, 0]) * (pts[:, None, 1] - p[None, :, 1])
                - (q[None, :, 1] - p[None, :, 1]) * (pts[:, None, 0] - p[None, :, 0]))
    return (side(tri[:, 0], tri[:, 1]) > 0) & (side(tri[:, 1], tri[:, 2]) > 0) & \
           (side(tri[:, 2], tri[:, 0]) > 0)


POLYGONS = {
    "L": [[0, 0], [2, 0], [2, 1], [1, 1], [1, 2], [0, 2]],
    "comb": [[0, 0], [5, 0], [5, 3], [4, 3], [4, 1], [3, 1], [3, 3], [2, 3], [2, 1], [1, 1],
             [1, 3], [0, 3]],
    "pentagon": [[np.cos(a), np.sin(a)] for a in np.linspace(0, 2 * np.pi, 6)[:-1]],
    "star": [[(1 + (k % 2)) * np.cos(a), (1 + (k % 2)) * np.sin(a)]
             for k, a in enumerate(np.linspace(0, 2 * np.pi, 15)[:-1])],
    "collinear": [[0, 0], [1, 0], [2, 0], [2, 1], [1, 1], [0, 1]],
}


@pytest.mark.parametrize("name", sorted(POLYGONS))
def test_ear_clipping_tiles_the_polygon(name):
    xy = np.array(POLYGONS[name], dtype=float)
    # Put it in a tilted plane in 3-D, and triangulate there.
    rot = np.linalg.qr(np.random.default_rng(4).normal(size=(3, 3)))[0]
    if np.linalg.det(rot) < 0:
        rot[:, 0] *= -1
    pts3 = np.c_[xy, np.zeros(len(xy))] @ rot.T + [3.0, -1.0, 2.0]
    normal = rot[:, 2]
    tris = triangulate_polygon(pts3, normal)
    assert tris.shape == (len(xy) - 2, 3)
    t2 = xy[tris]
    signed = 0.5 * ((t2[:, 1, 0] - t2[:, 0, 0]) * (t2[:, 2, 1] - t2[:, 0, 1])
                    - (t2[:, 1, 1] - t2[:, 0, 1]) * (t2[:, 2, 0] - t2[:, 0, 0]))
    assert np.all(signed > 0)
    np.testing.assert_allclose(signed.sum(), shoelace(xy), rtol=TIGHT)
    # Every sample point inside the polygon lies in exactly one triangle, outside in none.
    rng = np.random.default_rng(5)
    lo, hi = xy.min(axis=0) - 0.1, xy.max(axis=0) + 0.1
    samples = lo + (hi - lo) * rng.random((4000, 2))
    hits = in_triangles(samples, t2).sum(axis=1)
    inside = point_in_polygon(samples, xy)
    assert np.all(hits[~inside] == 0)
    assert np.all(hits[inside] <= 1)
    # Points on a diagonal are in no open triangle; they are measure zero, so almost all inside
    # samples must be hit exactly once.
    assert np.mean(hits[inside] == 1) > 0.999


def test_invalid_polygons_shape():
    with pytest.raises(ValueError, match=r"polygons must have shape \(n, K, 3\).*\(4, 3\)"):
        newell_vectors(np.zeros((4, 3)))


def test_invalid_polygons_nan():
    with pytest.raises(ValueError, match="polygons must be finite"):
        newell_vectors(np.full((1, 3, 3), np.nan))


def test_invalid_sizes():
    with pytest.raises(ValueError, match=r"sizes must lie in \[3, 4\]"):
        newell_vectors(np.zeros((2, 4, 3)), sizes=np.array([3, 5]))


def test_invalid_normals_shape():
    with pytest.raises(ValueError, match=r"normals must have shape \(1, 3\); got \(3,\)"):
        corner_turns(np.zeros((1, 4, 3)), np.array([0.0, 0.0, 1.0]))


def test_invalid_triangulation_normal():
    with pytest.raises(ValueError, match="normal must be a non-zero finite"):
        triangulate_polygon(np.eye(3), [0.0, 0.0, 0.0])


def test_invalid_triangulation_points():
    with pytest.raises(ValueError, match=r"points must have shape \(k, 3\) with k >= 3; got \(2, 3\)"):
        triangulate_polygon(np.zeros((2, 3)), [0.0, 0.0, 1.0])


def test_pairs_by_key_lists_every_ordered_pair_within_each_group():
    keys = np.array([5, 2, 5, 9, 2, 5])
    i, j = pairs_by_key(keys)
    got = sorted(zip(i.tolist(), j.tolist()))
    want = sorted((a, b) for a in range(6) for b in range(6) if keys[a] == keys[b])
    assert got == want
    e_i, e_j = pairs_by_key(np.zeros(0, dtype=np.int64))
    assert e_i.size == 0 and e_j.size == 0
    with pytest.raises(ValueError, match=r"keys must have shape \(n,\); got \(2, 2\)"):
        pairs_by_key(np.zeros((2, 2)))


@pytest.mark.parametrize("seed", range(5))
def test_sum_at_is_add_at_bit_for_bit(seed):
    """Oracle: np.add.at (the same sums, in the same order: equal bits, not within a tolerance)."""
    rng = np.random.default_rng(seed)
    m, n = int(rng.integers(0, 2000)), 37
    index = rng.integers(0, n, m)
    values = rng.normal(size=(m, 3)) * 10.0 ** rng.integers(-8, 8, (m, 1))
    want = np.zeros((n, 3))
    np.add.at(want, index, values)
    assert np.array_equal(sum_at(index, values, n), want)
    want1 = np.zeros(n)
    np.add.at(want1, index, values[:, 0])
    assert np.array_equal(sum_at(index, values[:, 0], n), want1)


@pytest.mark.parametrize("seed", range(5))
def test_unique_rows_answers_as_np_unique_with_an_axis(seed):
    """Oracle: np.unique(axis=0)'s first occurrences and inverse, with ties, repeated rows and
    signed zeros (-0.0 and 0.0 are one value to both)."""
    rng = np.random.default_rng(seed)
    keys = rng.integers(-2, 3, (int(rng.integers(1, 3000)), 6)).astype(np.float64)
    keys[rng.random(keys.shape) < 0.2] = -0.0
    _, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    got_first, got_inverse = unique_rows(keys)
    assert np.array_equal(got_first, first)
    assert np.array_equal(got_inverse, inverse.reshape(-1))
    assert unique_rows(np.zeros((0, 4)))[0].size == 0
