"""Tests of core/exact.py: the contour formula against closed forms, identities and occlusion."""

from types import SimpleNamespace

import numpy as np
import pytest

import core.exact as ex
from bench.scenes import room_with_boxes
from core import patches as core_patches
from core.exact import (
    _clip_halfspace, exact_rows, hybrid_rows, near_pairs, point_polygon_form_factor, ray_triangles,
)
from core.hemicube import hemicube_rows
from core.raycast import build_bvh

#: The closed forms below are exact and the contour formula has no discretisation: only float64
#: rounding (~1e-15 per term) and, for area-to-area values, Gauss-Legendre quadrature error
#: (8 x 8 points: 1e-11 on the unit-cube faces) separate them. 1e-9 leaves a wide margin while
#: being far tighter than the 1e-6 required.
TIGHT = 1e-9

F_CORNER = 0.1385316060        # dA under one corner of a c x c square at height c
F_OPPOSITE = 0.199824895698    # unit cube, opposite faces
F_ADJACENT = 0.200043776075    # unit cube, adjacent faces


def corner_rectangle(a, b, c):
    """Howell's dA-to-parallel-rectangle closed form, corner above the point."""
    A, B = a / c, b / c
    return (A / np.sqrt(1 + A * A) * np.arctan(B / np.sqrt(1 + A * A))
            + B / np.sqrt(1 + B * B) * np.arctan(A / np.sqrt(1 + B * B))) / (2 * np.pi)


def make_patches(quads):
    """A Patches stand-in from (P, 4, 3) planar quads: only the fields exact.py reads."""
    c = np.asarray(quads, float)
    cross = np.cross(c[:, 2] - c[:, 0], c[:, 3] - c[:, 1])        # quad area vector
    norm = np.linalg.norm(cross, axis=1)
    return SimpleNamespace(corners=c, centres=c.mean(axis=1), normals=cross / norm[:, None],
                           areas=norm / 2)


def square(origin, u, v):
    o, u, v = (np.asarray(a, float) for a in (origin, u, v))
    return np.array([o, o + u, o + u + v, o + v])


def gauss_area_ff(source_quad, normal, polygon, order=8):
    """Area-to-polygon form factor by Gauss-Legendre quadrature of the point formula over a
    parallelogram source (independent of exact.py's own source quadrature)."""
    g, w = np.polynomial.legendre.leggauss(order)
    g, w = (g + 1) / 2, w / 2
    o, u, v = source_quad[0], source_quad[1] - source_quad[0], source_quad[3] - source_quad[0]
    pts = o + g[:, None, None] * u + g[None, :, None] * v
    f = point_polygon_form_factor(pts.reshape(-1, 3), np.tile(normal, (order * order, 1)),
                                  polygon[None])
    return float((np.outer(w, w).ravel() * f[:, 0]).sum())


def cube_patches(n):
    """Unit cube, each face an n x n grid of quads with inward normals."""
    s = 1.0 / n
    quads = []
    for axis in range(3):
        for side in (0.0, 1.0):
            e = np.eye(3)
            u, v = e[(axis + 1) % 3], e[(axis + 2) % 3]
            if side == 1.0:                     # inward normal = -axis: swap u, v
                u, v = v, u
            for i in range(n):
                for j in range(n):
                    o = e[axis] * side + u * i * s + v * j * s
                    quads.append(square(o, u * s, v * s))
    return make_patches(quads)


# ----------------------------------------------------------------------------- closed forms
def test_corner_of_a_square_at_height_equal_to_its_side():
    sq = square([0, 0, 1], [1, 0, 0], [0, 1, 0])
    f = point_polygon_form_factor([[0, 0, 0]], [[0, 0, 1]], sq[None])
    assert abs(f[0, 0] - F_CORNER) < TIGHT


@pytest.mark.parametrize("a,b,c", [(1, 1, 1), (2, 0.5, 1.5), (0.1, 3, 0.7)])
def test_corner_rectangle_closed_form(a, b, c):
    rect = square([0, 0, c], [a, 0, 0], [0, b, 0])
    f = point_polygon_form_factor([[0, 0, 0]], [[0, 0, 1]], rect[None])
    assert abs(f[0, 0] - corner_rectangle(a, b, c)) < TIGHT


@pytest.mark.parametrize("n_sides", [6, 64, 2000])
def test_coaxial_regular_polygon_against_the_disc(n_sides):
    # The inscribed regular polygon contains the disc of radius r cos(pi/N) and lies inside the
    # disc of radius r; F grows with the region seen, so it is bracketed by the two disc values
    # (a rigorous, formula-independent bound whose width is the area deficit). The hand-derived
    # closed form for the polygon (each edge: beta = its subtended angle, cos gamma =
    # r cos(pi/N) / sqrt(h^2 + r^2 cos^2(pi/N))) pins it to rounding.
    r, h = 0.8, 0.6
    phi = 2 * np.pi * np.arange(n_sides) / n_sides
    poly = np.column_stack([r * np.cos(phi), r * np.sin(phi), np.full(n_sides, h)])
    f = point_polygon_form_factor([[0, 0, 0]], [[0, 0, 1]], poly[None])[0, 0]
    disc = lambda rad: rad * rad / (h * h + rad * rad)
    c = np.cos(np.pi / n_sides)
    assert disc(r * c) <= f <= disc(r)
    beta = np.arccos((r * r * np.cos(2 * np.pi / n_sides) + h * h) / (r * r + h * h))
    closed = n_sides / (2 * np.pi) * beta * r * c / np.sqrt(h * h + r * r * c * c)
    assert abs(f - closed) < TIGHT
    if n_sides == 2000:
        assert abs(f - disc(r)) < 1e-6


def test_unit_cube_opposite_faces_by_quadrature():
    bottom = square([0, 0, 0], [1, 0, 0], [0, 1, 0])
    top = square([0, 0, 1], [1, 0, 0], [0, 1, 0])
    assert abs(gauss_area_ff(bottom, [0, 0, 1], top) - F_OPPOSITE) < TIGHT


def test_unit_cube_adjacent_faces_by_quadrature():
    bottom = square([0, 0, 0], [1, 0, 0], [0, 1, 0])
    wall = square([0, 0, 0], [0, 1, 0], [0, 0, 1])
    assert abs(gauss_area_ff(bottom, [0, 0, 1], wall) - F_ADJACENT) < TIGHT


def test_exact_rows_source_quadrature_matches_closed_forms():
    pat = make_patches([square([0, 0, 0], [1, 0, 0], [0, 1, 0]),     # floor, up
                        square([0, 0, 1], [0, 1, 0], [1, 0, 0]),     # ceiling, down
                        square([0, 0, 0], [0, 1, 0], [0, 0, 1])])    # wall x = 0, +x
    rows = exact_rows(pat, [0], source_order=8)
    assert abs(rows[0, 1] - F_OPPOSITE) < TIGHT
    assert abs(rows[0, 2] - F_ADJACENT) < TIGHT
    # centre point only: four corner rectangles of half size at height 1
    centre = exact_rows(pat, [0], source_order=1)
    assert abs(centre[0, 1] - 4 * corner_rectangle(0.5, 0.5, 1.0)) < TIGHT
    assert np.all(rows[:, 3:] == 0) and rows[0, 0] == 0      # facing sides, never itself


# ----------------------------------------------------------------------------- identities
def test_sum_rule_and_sides_in_a_closed_cube():
    pat = cube_patches(3)
    p = pat.corners.shape[0]
    rows = exact_rows(pat, np.arange(2 * p), rays=4)
    # Inside a closed convex box every front node sees the whole hemisphere, all of it on the
    # front sides of the walls; the back nodes look outwards and see nothing.
    np.testing.assert_allclose(rows[:p].sum(axis=1), 1.0, atol=TIGHT)
    assert np.all(rows[:p, p:] == 0)
    assert np.all(rows[p:] == 0)


def test_reciprocity_between_unequal_patches():
    pat = make_patches([square([0, 0, 0], [2, 0, 0], [0, 0.5, 0]),
                        square([0.3, 0.1, 0.7], [0, 0.8, 0.1], [0.6, 0, 0]),
                        square([-0.2, 0, 0.1], [0, 0.7, 0], [0, 0, 0.5])])
    # No two patches touch or hide each other (the wall tops out below the tilted patch), so the
    # integrands are smooth and 16 x 16 Gauss points converge to ~1e-12 (8 x 8 leaves 2e-6
    # here: the 2 m long source spans several distances to the others).
    rows = exact_rows(pat, [0, 1, 2], source_order=16)
    p = 3
    for i in range(p):
        for j in range(p):
            if i != j:
                fij = rows[i, j] + rows[i, j + p]
                fji = rows[j, i] + rows[j, i + p]
                assert fij > 0
                assert abs(pat.areas[i] * fij - pat.areas[j] * fji) < TIGHT


# ----------------------------------------------------------------------------- clipping, planes
def test_polygon_crossing_the_tangent_plane_counts_its_upper_part_only():
    wall = square([1, -0.5, -1], [0, 1, 0], [0, 0, 2])        # z from -1 to 1
    upper = square([1, -0.5, 0], [0, 1, 0], [0, 0, 1])        # z from 0 to 1, needs no clipping
    f = point_polygon_form_factor([[0, 0, 0]], [[0, 0, 1]], np.stack([wall, upper]))
    assert f[0, 0] > 0
    assert abs(f[0, 0] - f[0, 1]) < TIGHT
    # A tilted normal: compare with the polygon pre-clipped by hand along its crossing line.
    n = np.array([0.3, 0.0, 1.0])
    tri = np.array([[1.0, 0.0, -1.0], [1.0, 1.0, 2.0], [1.0, -1.0, 2.0]])
    # plane 0.3 x + z = 0 at x = 1: z = -0.3; the edges cross it at y = +-0.7 / 3 * 1 ...
    h = tri @ n
    cut = lambda a, b: tri[a] + (tri[b] - tri[a]) * h[a] / (h[a] - h[b])
    clipped = np.array([cut(0, 1), tri[1], tri[2], cut(2, 0)])
    g = point_polygon_form_factor([[0, 0, 0]], [n], np.stack([tri[[0, 1, 2, 2]], clipped]))
    assert abs(g[0, 0] - g[0, 1]) < TIGHT


def test_clip_halfspace_corners():
    r = np.array([[[0, 0, -1], [2, 0, 1], [0, 2, 1.0]]])
    poly, count = _clip_halfspace(r, r[..., 2])
    assert count.tolist() == [4]
    expected = np.array([[1, 0, 0], [2, 0, 1], [0, 2, 1], [0, 1, 0]], float)
    np.testing.assert_allclose(poly[0], expected)
    below = r.copy()
    below[..., 2] -= 5
    _, count = _clip_halfspace(below, below[..., 2])
    assert count.tolist() == [0]


@pytest.mark.parametrize("centre", [(0.5, 0.5), (3.0, 0.5)])
def test_polygon_in_the_points_plane_is_zero(centre):
    sq = square([0, 0, 0], [1, 0, 0], [0, 1, 0])
    x = [[centre[0], centre[1], 0.0]]
    for n in ([0, 0, 1], [0, 0, -1]):
        assert point_polygon_form_factor(x, [n], sq[None])[0, 0] == 0.0


def test_polygon_below_the_tangent_plane_is_zero():
    sq = square([0, 0, -1], [1, 0, 0], [0, 1, 0])
    assert point_polygon_form_factor([[0, 0, 0]], [[0, 0, 1]], sq[None])[0, 0] == 0.0


def test_orientation_and_start_corner_do_not_matter():
    rng = np.random.default_rng(11)
    # random convex quads (parallelograms) and triangles padded by repetition
    o = rng.uniform(-1, 1, (40, 3))
    u, v = rng.normal(size=(40, 3)), rng.normal(size=(40, 3))
    quads = np.stack([o, o + u, o + u + v, o + v], axis=1)
    tris = np.stack([o, o + u, o + v, o + v], axis=1)
    polys = np.concatenate([quads, tris])
    x = rng.normal(size=(5, 3)) * 0.3
    n = rng.normal(size=(5, 3))
    f = point_polygon_form_factor(x, n, polys)
    assert np.all(f >= 0) and (f > 0).mean() > 0.3
    np.testing.assert_allclose(point_polygon_form_factor(x, n, polys[:, ::-1]), f, atol=1e-13)
    np.testing.assert_allclose(point_polygon_form_factor(x, n, np.roll(polys, 1, axis=1)), f,
                               atol=1e-13)
    # normals are normalised: scaling them changes nothing
    np.testing.assert_allclose(point_polygon_form_factor(x, 3 * n, polys), f, atol=1e-13)


def test_point_polygon_does_not_mutate_inputs():
    rng = np.random.default_rng(12)
    x, n, polys = rng.normal(size=(3, 3)), rng.normal(size=(3, 3)), rng.normal(size=(4, 4, 3))
    copies = [a.copy() for a in (x, n, polys)]
    point_polygon_form_factor(x, n, polys)
    for a, b in zip(copies, (x, n, polys)):
        np.testing.assert_array_equal(a, b)


def test_chunking_does_not_change_the_result(monkeypatch):
    rng = np.random.default_rng(13)
    x, n, polys = rng.normal(size=(30, 3)), rng.normal(size=(30, 3)), rng.normal(size=(20, 4, 3))
    whole = point_polygon_form_factor(x, n, polys)
    monkeypatch.setattr(ex, "PAIR_CHUNK", 7)
    np.testing.assert_array_equal(point_polygon_form_factor(x, n, polys), whole)


def test_point_in_the_polygons_plane_sees_it_edge_on():
    # Room corner: a point on the wall's corner or bottom edge lies in the wall's plane: F = 0
    # exactly, whatever its own normal (the contour sum alone would give a partial winding
    # angle on the boundary: 0.088 at the corner for the tilted normal). Just off the plane, at
    # distance x from the bottom edge, the wall fills almost half the hemisphere: F -> 1/2
    # (closed-form limit: a half-plane through the point), linearly in x (0.78 x measured).
    wall = square([0, 0, 0], [0, 1, 0], [0, 0, 1])
    for x in ([0.0, 0.0, 0.0], [0.0, 0.5, 0.0], [0.0, 0.3, 0.4]):
        for n in ([1.0, 0.0, 1.0], [0.0, 0.0, 1.0], [1.0, 0.2, 0.0]):
            assert point_polygon_form_factor([x], [n], wall[None])[0, 0] == 0.0
    near = point_polygon_form_factor([[1e-7, 0.5, 0.0], [1e-9, 0.5, 0.0]], [[0, 0, 1.0]] * 2,
                                     wall[None])[:, 0]
    np.testing.assert_allclose(near, 0.5, atol=1e-6)
    assert np.all(near < 0.5)


def test_exact_and_hybrid_rows_do_not_mutate_patches():
    pat = blocked_pair(0.5)
    before = {k: np.array(v, copy=True) for k, v in vars(pat).items()}
    exact_rows(pat, [0, 1, 3], source_order="adaptive")
    hybrid_rows(pat, [0, 1, 3], resolution=16)
    for k, v in before.items():
        np.testing.assert_array_equal(getattr(pat, k), v)


# ----------------------------------------------------------------------------- visibility
def blocked_pair(blocker_width, flip_target=False):
    src = square([0, 0, 0], [1, 0, 0], [0, 1, 0])                       # up
    tgt = square([0, 0, 1], [0, 1, 0], [1, 0, 0])                       # down, facing src
    if flip_target:
        tgt = tgt[::-1]
    quads = [src, tgt]
    if blocker_width > 0:
        # a plate at z = 0.5 covering x < blocker_width (and beyond the sides in y)
        quads.append(square([-1, -1, 0.5], [blocker_width + 1, 0, 0], [0, 3, 0]))
    return make_patches(quads)


def test_full_blocker_hides_everything_and_no_blocker_hides_nothing():
    open_rows = exact_rows(blocked_pair(0.0), [0])
    unocc = point_polygon_form_factor([[0.5, 0.5, 0]], [[0, 0, 1]],
                                      square([0, 0, 1], [1, 0, 0], [0, 1, 0])[None])[0, 0]
    assert abs(open_rows[0, 1] - unocc) < TIGHT
    closed = exact_rows(blocked_pair(2.0), [0])
    assert closed[0, 1] == 0.0 and closed[0, 4] == 0.0
    assert closed[0, 5] > 0                       # the blocker (normal +z) is seen from its back


def test_half_blocker_against_the_visible_half():
    # From the source centre (0.5, 0.5, 0), the plate z = 0.5, x < 0.5 hides exactly the target
    # points with x < 0.5: the visible form factor is that of the half square x in [0.5, 1],
    # i.e. half of the whole by symmetry. 256 stratified rays: the kernel-weighted estimate is
    # within 1% (its jitter noise, measured ~0.2% over seeds).
    rows = exact_rows(blocked_pair(0.5), [0], rays=256, rng=np.random.default_rng(1))
    half = point_polygon_form_factor([[0.5, 0.5, 0]], [[0, 0, 1]],
                                     square([0.5, 0, 1], [0.5, 0, 0], [0, 1, 0])[None])[0, 0]
    assert abs(rows[0, 1] / half - 1) < 0.01


def test_side_seen_decides_the_column():
    p = 2
    front = exact_rows(blocked_pair(0.0), [0])
    back = exact_rows(blocked_pair(0.0, flip_target=True), [0])
    assert front[0, 1] > 0 and front[0, 1 + p] == 0
    assert back[0, 1] == 0 and abs(back[0, 1 + p] - front[0, 1]) < TIGHT
    # the back node of the source looks down, away from the target
    assert np.all(exact_rows(blocked_pair(0.0), [p]) == 0)


def test_seeded_reproducibility():
    pat = blocked_pair(0.5)
    a = exact_rows(pat, [0, 1], rng=np.random.default_rng(5))
    b = exact_rows(pat, [0, 1], rng=np.random.default_rng(5))
    c = exact_rows(pat, [0, 1], rng=np.random.default_rng(6))
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    np.testing.assert_array_equal(exact_rows(pat, [0, 1]), exact_rows(pat, [0, 1]))  # rng=None


def test_shared_bvh_gives_the_same_rows():
    pat = blocked_pair(0.5)
    bvh = build_bvh(ray_triangles(pat)[0])
    np.testing.assert_array_equal(exact_rows(pat, [0], rng=np.random.default_rng(2), bvh=bvh),
                                  exact_rows(pat, [0], rng=np.random.default_rng(2)))


def test_closed_room_with_boxes_sum_rule_and_hemicube_agreement():
    # Real patches of the sample room (closed, two boxes on the floor): every front node sees
    # the room's inside only, so each exact row sums to 1 *with occlusion*; without the rays the
    # boxes would be counted twice and the sums exceed 1. Against the hemicube (an independent
    # program, R = 128) the rows agree to the hemicube's aliasing plus ray noise.
    # Tolerances: rays = 16 gave row sums within 5.3e-3 of 1 and L1 row differences <= 3.8%
    # over 4 seeds x 8 sources; the test allows 4x and 2x that.

    pat = core_patches.make_patches(room_with_boxes(150), 10.0)
    p = pat.centres.shape[0]
    src = np.random.default_rng(0).choice(p, 8, replace=False)
    rows = exact_rows(pat, src, rays=16, rng=np.random.default_rng(1))
    np.testing.assert_allclose(rows.sum(axis=1), 1.0, atol=0.02)
    unoccluded = point_polygon_form_factor(pat.centres, pat.normals, pat.corners)
    np.fill_diagonal(unoccluded, 0.0)
    assert unoccluded.sum(axis=1).max() > 1.1
    hemi = hemicube_rows(pat, src, resolution=128)
    assert np.abs(rows - hemi).sum(axis=1).max() < 0.08


def test_adaptive_source_quadrature_for_a_panel_just_under_a_ceiling():
    # A 0.67 m ceiling patch (facing down) with a luminaire 5 cm below it, seen from its back:
    # the point formula swings from ~1 to ~0 within ~5 cm across the source, which a fixed
    # 3 x 3 rule gets 36% wrong. Oracle: midpoint rule with 600 x 600 points, independent of
    # the Gauss rule (converged: 1200 x 1200 agrees to 4e-9). ADAPTIVE_TOL = 1e-3 between
    # successive orders bounds the error near 1e-4; allow 1e-3.
    s_ = 0.6667
    ceiling = square([2.0, 1.3, 3.0], [0, s_, 0], [s_, 0, 0])                 # faces -z
    panel = square([2.4, 1.7, 2.95], [0, 0.6, 0], [0.6, 0, 0])                  # faces -z
    pat = make_patches([ceiling, panel])
    n = 600
    g = (np.arange(n) + 0.5) / n
    pts = np.array([2.0, 1.3, 3.0]) + g[:, None, None] * [s_, 0, 0] + g[None, :, None] * [0, s_, 0]
    ref = point_polygon_form_factor(pts.reshape(-1, 3), np.tile([0, 0, -1.0], (n * n, 1)),
                                    panel[None]).mean()
    rows = exact_rows(pat, [0], source_order="adaptive")
    assert rows[0, 1] == 0                                      # the panel's front faces away
    assert abs(rows[0, 3] / ref - 1) < 1e-3
    assert abs(exact_rows(pat, [0], source_order=3)[0, 3] / ref - 1) > 0.2


# ----------------------------------------------------------------------------- hybrid
def test_near_pairs_uses_the_larger_patch_size():
    pat = make_patches([square([0, 0, 0], [1, 0, 0], [0, 1, 0]),
                        square([0, 0, 2.5], [0.1, 0, 0], [0, 0.1, 0]),
                        square([0, 0, 9], [1, 0, 0], [0, 1, 0])])
    rows, tgts = near_pairs(pat, np.array([0, 1, 4]), 3.0)
    pairs = set(zip(rows.tolist(), tgts.tolist()))
    assert pairs == {(0, 1), (1, 0), (2, 0)}      # node 4 = back of patch 1, not itself


def test_hybrid_replaces_near_pairs_with_area_averaged_values():
    pat = make_patches([square([0, 0, 0], [1, 0, 0], [0, 1, 0]),
                        square([0, 0, 1], [0, 1, 0], [1, 0, 0])])
    rows = hybrid_rows(pat, [0, 1], resolution=32)
    # Adaptive source quadrature settles at 8 x 8 points here (1e-11, see the quadrature test);
    # ADAPTIVE_TOL (1e-3 between successive orders) only bounds it by ~1e-4: allow 3e-4.
    # The centre point alone would be +19.8% off.
    np.testing.assert_allclose(rows[:, [1, 0]].diagonal(), F_OPPOSITE, rtol=3e-4)
    plain = hybrid_rows(pat, [0, 1], resolution=32, near=0.0)    # hemicube from the centre
    assert plain[0, 1] > 1.15 * F_OPPOSITE                         # the +20% proximity error


def test_hybrid_keeps_the_hemicube_row_sums_in_the_room():
    # Sum rule: conserve=True rescales far entries so each row sums like the hemicube's row
    # (identity to rounding). The ceiling patches over the luminaire (5 cm gap) are the case
    # where plain replacement overshoots: their rows exceed 1 without it.

    pat = core_patches.make_patches(room_with_boxes(300), 10.0)
    panel_centre = pat.centres[pat.material == 4].mean(axis=0)
    near_panel = np.linalg.norm(pat.centres[:, :2] - panel_centre[:2], axis=1) < 0.8
    ceiling = np.flatnonzero((pat.centres[:, 2] > 2.99) & near_panel)
    src = np.concatenate([ceiling, [0, 50, 100]])
    hemi = hemicube_rows(pat, src, resolution=64)
    rows = hybrid_rows(pat, src, resolution=64)
    np.testing.assert_allclose(rows.sum(axis=1), hemi.sum(axis=1), atol=1e-12)
    raw = hybrid_rows(pat, src, resolution=64, conserve=False)
    assert raw.sum(axis=1).max() > 1.05
    assert np.all(rows >= 0)


# ----------------------------------------------------------------------------- invalid input
@pytest.fixture
def pat():
    return blocked_pair(0.0)


def test_points_shape_is_checked():
    with pytest.raises(ValueError, match=r"points must have shape \(S, 3\); got \(3,\)"):
        point_polygon_form_factor([0, 0, 0], [[0, 0, 1]], np.zeros((1, 3, 3)))


def test_normals_shape_is_checked():
    with pytest.raises(ValueError, match=r"normals must have shape \(1, 3\) like points"):
        point_polygon_form_factor([[0, 0, 0]], [[0, 0, 1], [0, 0, 1]], np.zeros((1, 3, 3)))


def test_zero_normal_is_rejected():
    with pytest.raises(ValueError, match="normals must be non-zero; row 0"):
        point_polygon_form_factor([[0, 0, 0]], [[0, 0, 0]], np.zeros((1, 3, 3)))


def test_polygons_shape_is_checked():
    with pytest.raises(ValueError, match=r"polygons must have shape \(Q, K, 3\) with K >= 3"):
        point_polygon_form_factor([[0, 0, 0]], [[0, 0, 1]], np.zeros((1, 2, 3)))


def test_nan_polygon_is_rejected():
    with pytest.raises(ValueError, match="polygons must be finite"):
        point_polygon_form_factor([[0, 0, 0]], [[0, 0, 1]], np.full((1, 3, 3), np.nan))


def test_sources_out_of_range(pat):
    with pytest.raises(ValueError, match=r"sources must be node ids in \[0, 4\); got 4"):
        exact_rows(pat, [4])


def test_sources_must_be_integers(pat):
    with pytest.raises(TypeError, match="sources must hold integer node ids; got dtype float64"):
        exact_rows(pat, [0.5])
    with pytest.raises(ValueError, match="sources must be a 1-D array of integer node ids"):
        exact_rows(pat, [[0]])


def test_rays_must_be_positive(pat):
    with pytest.raises(ValueError, match="rays must be an integer >= 1; got 0"):
        exact_rows(pat, [0], rays=0)


def test_rng_type(pat):
    with pytest.raises(TypeError, match="rng must be a numpy.random.Generator"):
        exact_rows(pat, [0], rng=3)


def test_bvh_must_match_the_patches(pat):
    with pytest.raises(ValueError, match="bvh must be built over ray_triangles"):
        exact_rows(pat, [0], bvh=build_bvh(np.ones((1, 3, 3))))


def test_bvh_over_the_same_count_of_other_triangles_is_rejected(pat):
    tris, _ = ray_triangles(pat)
    with pytest.raises(ValueError, match="other triangles"):
        exact_rows(pat, [0], bvh=build_bvh(tris[::-1]))


def test_patches_type(pat):
    with pytest.raises(TypeError, match=r"patches must be a Patches \(needs .corners\)"):
        exact_rows(np.zeros((2, 4, 3)), [0])


def test_source_order_must_be_positive(pat):
    with pytest.raises(ValueError, match="source_order must be an integer >= 1 or 'adaptive'"):
        exact_rows(pat, [0], source_order=0)


def test_conserve_must_be_bool(pat):
    with pytest.raises(TypeError, match="conserve must be a bool"):
        hybrid_rows(pat, [0], conserve="yes")


def test_near_must_be_non_negative(pat):
    with pytest.raises(ValueError, match="near must be a finite number >= 0"):
        hybrid_rows(pat, [0], near=-1.0)
