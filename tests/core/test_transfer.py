"""core.transfer: fan triangulation, barycentric weights, interpolation, corner projection."""

import numpy as np
import pytest

from core.transfer import (CORNER_INSET, barycentric, face_frames, fan, interpolate,
                           nearest_corners, padded_polygons, project_corners)

#: Float64 rounding of a few products of O(1) numbers.
TIGHT = 1e-12


def grid(n, size=1.0, z=0.0):
    """An n x n grid of quads over [0, size]^2 at height z, normal +z: (points, cv, fs, fz)."""
    xs = np.linspace(0.0, size, n + 1)
    pts = np.array([(x, y, z) for y in xs for x in xs])
    faces = [(j * (n + 1) + i, j * (n + 1) + i + 1, (j + 1) * (n + 1) + i + 1,
              (j + 1) * (n + 1) + i) for j in range(n) for i in range(n)]
    cv = np.array(faces, dtype=np.int64).ravel()
    fz = np.full(len(faces), 4, dtype=np.int64)
    return pts, cv, np.cumsum(fz) - fz, fz


def test_fan_covers_each_polygon_once():
    # Oracle: the fan triangles' area vectors (independent cross products) sum to each
    # polygon's shoelace area, and there are size - 2 of them per face.
    rng = np.random.default_rng(0)
    sizes = np.array([3, 4, 5, 7])
    starts = np.cumsum(sizes) - sizes
    angles = np.concatenate([np.sort(rng.uniform(0, 2 * np.pi, s)) for s in sizes])
    radius = rng.uniform(0.5, 1.5, angles.size)
    pts = np.c_[radius * np.cos(angles), radius * np.sin(angles), np.zeros(angles.size)]
    tris = fan(starts, sizes)
    assert tris.shape == (int((sizes - 2).sum()), 3)
    p0, p1, p2 = (pts[tris[:, k]] for k in range(3))
    area = 0.5 * np.cross(p1 - p0, p2 - p0)[:, 2]
    owner = np.repeat(np.arange(sizes.size), sizes - 2)
    for f, (s, k) in enumerate(zip(starts, sizes)):
        xy = pts[s:s + k, :2]
        shoelace = 0.5 * np.sum(xy[:, 0] * np.roll(xy[:, 1], -1) - np.roll(xy[:, 0], -1) * xy[:, 1])
        np.testing.assert_allclose(area[owner == f].sum(), shoelace, atol=TIGHT)


def test_barycentric_recovers_the_weights_inside_and_clips_outside():
    rng = np.random.default_rng(1)
    a, b, c = (rng.normal(size=(200, 3)) for _ in range(3))
    w = rng.dirichlet([1.0, 1.0, 1.0], size=200)
    p = w[:, :1] * a + w[:, 1:2] * b + w[:, 2:] * c
    np.testing.assert_allclose(barycentric(p, a, b, c), w, atol=1e-9)
    outside = barycentric(a + 2.0 * (b - a), a, b, c)        # beyond b on the edge ab
    assert np.all(outside >= 0) and np.allclose(outside.sum(axis=1), 1.0)
    np.testing.assert_allclose(outside, np.tile([0.0, 1.0, 0.0], (200, 1)), atol=1e-9)


def test_barycentric_degenerate_triangle_puts_weight_on_a():
    a = np.zeros((1, 3))
    got = barycentric(np.ones((1, 3)), a, a, a)
    np.testing.assert_array_equal(got, [[1.0, 0.0, 0.0]])


def test_interpolate_reproduces_a_linear_field():
    # A linear field sampled at corners, interpolated with barycentric weights, is the field at
    # the weighted point (an identity of affine maps).
    rng = np.random.default_rng(2)
    pts = rng.normal(size=(30, 3))
    field = pts @ np.array([[1.0, 2.0], [-0.5, 0.3], [0.2, 0.0]]) + [0.1, -0.2]
    src = rng.integers(0, 30, size=(50, 3))
    w = rng.dirichlet([1.0, 1.0, 1.0], size=50)
    at = np.einsum("nk,nkd->nd", w, pts[src])
    expected = at @ np.array([[1.0, 2.0], [-0.5, 0.3], [0.2, 0.0]]) + [0.1, -0.2]
    np.testing.assert_allclose(interpolate(field, src, w), expected, atol=TIGHT)


@pytest.mark.parametrize("bad", [np.zeros((5, 2), dtype=int), np.full((5, 3), 99)])
def test_interpolate_rejects_bad_sources(bad):
    with pytest.raises(ValueError, match="sources"):
        interpolate(np.zeros((10, 3)), bad, np.zeros((5, 3)))


def test_padded_polygons_and_face_frames():
    pts, cv, fs, fz = grid(2, size=2.0)
    poly = padded_polygons(pts, cv, fs, fz)
    assert poly.shape == (4, 4, 3)
    normals, centroids = face_frames(pts, cv, fs, fz)
    np.testing.assert_allclose(normals, np.tile([0.0, 0.0, 1.0], (4, 1)), atol=TIGHT)
    np.testing.assert_allclose(centroids[:, :2], [[0.5, 0.5], [1.5, 0.5], [0.5, 1.5], [1.5, 1.5]],
                               atol=TIGHT)


@pytest.mark.parametrize("bad", [
    dict(points=np.zeros((4, 2))),
    dict(face_sizes=np.array([5])),
    dict(corner_verts=np.array([0, 1, 2, 9])),
])
def test_layout_validation_names_the_argument(bad):
    args = dict(points=np.zeros((4, 3)), corner_verts=np.arange(4), face_starts=np.array([0]),
                face_sizes=np.array([4]))
    args.update(bad)
    with pytest.raises(ValueError, match=next(iter(bad))):
        face_frames(**args)


def test_project_corners_onto_a_finer_copy_gives_each_corner_its_own_position():
    # Oracle: the target is a 4 x 4 refinement of the same 1 x 1 quad (tilted and moved); the
    # position field interpolated at each original corner is that corner, up to the inset of
    # the sample (CORNER_INSET of the corner-to-centroid distance).
    rot = np.linalg.qr(np.random.default_rng(3).normal(size=(3, 3)))[0]
    shift = np.array([3.0, -1.0, 2.0])
    orig = list(grid(1, size=2.0))
    fine = list(grid(4, size=2.0))
    orig[0] = orig[0] @ rot.T + shift
    fine[0] = fine[0] @ rot.T + shift
    src, w = project_corners(tuple(orig), tuple(fine))
    got = interpolate(fine[0][fine[1]], src, w)
    expected = orig[0][orig[1]]
    np.testing.assert_allclose(got, expected, atol=2 * CORNER_INSET * np.sqrt(2) + 1e-9)


def test_project_corners_falls_back_to_the_nearest_agreeing_corner():
    # The target faces away (normal -z) and is far off to the side: no ray can hit it, so each
    # corner takes the nearest target corner -- here all of them one corner with weight 1.
    orig = grid(1)
    pts, cv, fs, fz = grid(1, size=0.1)
    far = (pts + [5.0, 5.0, 0.0], cv[::-1].copy(), fs, fz)
    src, w = project_corners(orig, far)
    assert np.all(w[:, 0] == 1.0) and np.all(w[:, 1:] == 0.0)
    expected = nearest_corners(orig[0][orig[1]], np.tile([0.0, 0.0, 1.0], (4, 1)), far)
    np.testing.assert_array_equal(src[:, 0], expected)
    # Brute force: the target corner closest to the original corner (5, 5) direction is (5, 5).
    assert np.allclose(far[0][far[1][src[:, 0]]][:, :2], [5.0, 5.0])
