"""Tests of core/hemicube.py: delta form factors, rasterisation, z-buffer, sides, accuracy.

Oracles: closed forms (hemicube face shares, coaxial disc, unit cube), Lambert's contour formula
for a point and a polygon (an independent implementation below), the identities (closed scene
rows sum to 1, reciprocity) and geometric constructions whose visible parts are known exactly.
Scenes are built here from explicit quads; ``patch_triangles`` splits them as the bake does.
"""

from types import SimpleNamespace

import numpy as np
import pytest

from bench import scenes as samples
from core.constants import tol
from core.hemicube import (FACE_NAMES, delta_form_factors, draw_polygons, hemicube_rows,
                           polygon_rows)
from core.patches import patch_triangles

from builders import box_quads, centred_square as square, quad_patches as make_patches

#: Howell's catalogue (shared/reference/form_factors.md).
CUBE_OPPOSITE = 0.199824895698
CUBE_ADJACENT = 0.200043776075
TOP_SHARE = 0.5541264240
SIDE_SHARE = 0.1114683940


# ------------------------------------------------------------------------------------------
# Scene helpers and the independent oracle
# ------------------------------------------------------------------------------------------

def clip_to_hemisphere(poly, point, normal):
    """Sutherland-Hodgman clip of a polygon (K, 3) to the half-space above a point's plane."""
    d = (poly - point) @ normal
    out = []
    for k in range(len(poly)):
        a, b, da, db = poly[k], poly[(k + 1) % len(poly)], d[k], d[(k + 1) % len(poly)]
        if da >= 0:
            out.append(a)
        if (da >= 0) != (db >= 0):
            out.append(a + (b - a) * (da / (da - db)))
    return np.array(out)


def lambert(point, normal, poly):
    """Point-to-polygon form factor F = 1/(2 pi) sum beta_k cos gamma_k, unoccluded.

    The polygon is clipped to the hemisphere above the point first (reference formula).
    """
    poly = clip_to_hemisphere(np.asarray(poly, dtype=float), point, normal)
    if len(poly) < 3:
        return 0.0
    a = poly - point
    b = np.roll(a, -1, axis=0)
    cross = np.cross(a, b)
    norm = np.linalg.norm(cross, axis=1)
    ok = norm > 0
    angle = np.arctan2(norm, np.sum(a * b, axis=1))
    return abs(np.sum(angle[ok] * (cross[ok] @ normal) / norm[ok])) / (2.0 * np.pi)


def test_lambert_oracle_matches_closed_forms():
    # The oracle itself against Howell: corner formula a = b = c = 1 and the unit cube value
    # at the centre of a face (4 corner rectangles of 0.5 x 0.5 at height 1).
    corner = lambert(np.zeros(3), np.array([0, 0, 1.0]), square(0.5, 0.5, 1.0, 1.0))
    assert corner == pytest.approx(0.1385316060, abs=1e-10)
    a = b = 0.5
    f = 1 / (2 * np.pi) * 2 * (a / np.sqrt(1 + a * a) * np.arctan(b / np.sqrt(1 + a * a)))
    centre = lambert(np.zeros(3), np.array([0, 0, 1.0]), square(0, 0, 1.0, 1.0))
    assert centre == pytest.approx(4 * f, abs=1e-12)


# ------------------------------------------------------------------------------------------
# Delta form factors
# ------------------------------------------------------------------------------------------

@pytest.mark.parametrize("resolution", [2, 16, 64, 256])
def test_delta_form_factors_shapes_and_normalisation(resolution):
    d = delta_form_factors(resolution)
    assert tuple(d) == FACE_NAMES
    assert d["top"].shape == (resolution, resolution)
    for name in FACE_NAMES[1:]:
        assert d[name].shape == (resolution // 2, resolution)
    total = sum(a.sum() for a in d.values())
    assert total == pytest.approx(1.0, abs=1e-13)          # float64 summation of <= 2e5 terms
    assert np.array_equal(d["top"], d["top"].T)              # symmetric in x and y
    assert np.array_equal(d["top"], d["top"][::-1])


@pytest.mark.parametrize("resolution", [16, 32, 64, 128, 256])
def test_raw_delta_form_factors_sum_to_one_plus_054_over_r2(resolution):
    # The pixels are a midpoint rule for the hemisphere's projected solid angle (exactly 1);
    # its error is c / R^2 with c -> 0.5420 (Richardson over R = 256, 512).
    d = delta_form_factors(resolution, normalised=False)
    excess = (sum(a.sum() for a in d.values()) - 1.0) * resolution ** 2
    assert 0.541 < excess < 0.545


@pytest.mark.parametrize("resolution", [32, 64, 128, 256])
def test_face_shares_converge_to_the_exact_values(resolution):
    # Midpoint error of each face integral is O(1/R^2): measured leading coefficients are
    # -0.155 (top) and +0.039 (side); tolerances 0.17/R^2 and 0.045/R^2.
    d = delta_form_factors(resolution)
    assert abs(d["top"].sum() - TOP_SHARE) < 0.17 / resolution ** 2
    for name in FACE_NAMES[1:]:
        assert abs(d[name].sum() - SIDE_SHARE) < 0.045 / resolution ** 2


def test_exact_face_shares_from_the_corner_formula():
    # Independent check of the reference numbers: top = 4 corner rectangles (a = b = c = 1),
    # side = (1 - top) / 4 since the whole hemicube sums to 1.
    top = 4 * lambert(np.zeros(3), np.array([0, 0, 1.0]), square(0.5, 0.5, 1.0, 1.0))
    assert top == pytest.approx(TOP_SHARE, abs=1e-9)
    assert (1 - top) / 4 == pytest.approx(SIDE_SHARE, abs=1e-9)


# ------------------------------------------------------------------------------------------
# Validation
# ------------------------------------------------------------------------------------------

@pytest.mark.parametrize("bad, error", [(3, ValueError), (0, ValueError), (-2, ValueError),
                                        (4.0, TypeError), (True, TypeError),
                                        (4096, ValueError)])
def test_resolution_is_validated(bad, error):
    with pytest.raises(error, match="resolution"):
        delta_form_factors(bad)
    patches = make_patches([square(0, 0, 0, 1), square(0, 0, 1, 1, False)])
    with pytest.raises(error, match="resolution"):
        hemicube_rows(patches, [0], resolution=bad)


@pytest.mark.parametrize("bad, error", [([2 * 2], ValueError), ([-1], ValueError),
                                        ([[0]], ValueError), ([0.0], TypeError)])
def test_sources_are_validated(bad, error):
    patches = make_patches([square(0, 0, 0, 1), square(0, 0, 1, 1, False)])
    with pytest.raises(error, match="sources"):
        hemicube_rows(patches, bad)


def test_other_arguments_are_validated():
    patches = make_patches([square(0, 0, 0, 1), square(0, 0, 1, 1, False)])
    with pytest.raises(TypeError, match="rng"):
        hemicube_rows(patches, [0], rotate=True)
    with pytest.raises(TypeError, match="rotate"):
        hemicube_rows(patches, [0], rotate="yes")
    with pytest.raises(TypeError, match="cull_back"):
        hemicube_rows(patches, [0], cull_back=None)
    with pytest.raises(TypeError, match="patches"):
        hemicube_rows(np.zeros((2, 4, 3)), [0])
    bad = SimpleNamespace(**vars(patches))
    bad.normals = bad.normals[:1]
    with pytest.raises(ValueError, match="normals"):
        hemicube_rows(bad, [0])
    bad.normals = 2 * patches.normals
    with pytest.raises(ValueError, match="normals must be unit"):
        hemicube_rows(bad, [0])
    bad = SimpleNamespace(**vars(patches))
    bad.centres = np.where(bad.centres == 0, np.nan, bad.centres)
    with pytest.raises(ValueError, match="centres must be finite"):
        hemicube_rows(bad, [0])


def test_empty_sources_and_inputs_not_mutated():
    patches = make_patches([square(0, 0, 0, 1), square(0, 0, 1, 1, False)])
    before = {k: v.copy() for k, v in vars(patches).items()}
    sources = np.array([0, 1, 2, 3])
    rows = hemicube_rows(patches, sources, resolution=8)
    assert rows.shape == (4, 4) and rows.dtype == np.float64
    assert hemicube_rows(patches, [], resolution=8).shape == (0, 4)
    assert all(np.array_equal(before[k], v) for k, v in vars(patches).items())
    assert np.array_equal(sources, [0, 1, 2, 3])


# ------------------------------------------------------------------------------------------
# Accuracy against closed forms
# ------------------------------------------------------------------------------------------

@pytest.mark.parametrize("resolution", [64, 128, 256])
def test_differential_area_to_coaxial_disc(resolution):
    # Source: a tiny patch at the origin facing +z; disc of radius r at height h as a
    # 256-gon fan. Closed form r^2 / (h^2 + r^2); the polygon misses the area deficit
    # (F(disc) - F(polygon), known exactly from Lambert). The pixel error is the rim's: each
    # pixel the rim crosses is in or out whole, a bounded +-dF error of random sign, so the
    # sum is within 3 sqrt(n) dF (6 sigma) for n rim pixels of delta form factor dF.
    h, r, n = 1.0, 0.8, 256
    theta = 2 * np.pi * np.arange(n) / n
    rim = np.stack([r * np.cos(theta), r * np.sin(theta), np.full(n, h)], axis=1)
    fan = [np.array([[0, 0, h], rim[(k + 1) % n], rim[k], rim[k]]) for k in range(n)]
    patches = make_patches([square(0, 0, 0, 0.01)] + fan)
    rows = hemicube_rows(patches, [0], resolution=resolution)
    closed = r * r / (h * h + r * r)
    deficit = closed - lambert(np.zeros(3), np.array([0, 0, 1.0]), rim)
    assert 0 < deficit < 1e-4
    pixel = 2.0 / resolution
    rim_pixels = 2 * np.pi * (r / h) / pixel
    d_f = pixel ** 2 / (np.pi * (1 + (r / h) ** 2) ** 2)
    tolerance = deficit + 3 * np.sqrt(rim_pixels) * d_f
    assert abs(rows[0, 1:n + 1].sum() - closed) < tolerance
    assert rows[0, n + 1:].sum() == 0                          # nothing seen from behind


def _cube_face_averages(n, resolution):
    corners, face = box_quads((1.0, 1.0, 1.0), 1.0 / n)
    patches = make_patches(corners)
    p = len(corners)
    sources = np.flatnonzero(face == 0)                        # the x = 0 face, normal +x
    rows = hemicube_rows(patches, sources, resolution=resolution)[:, :p]
    opposite = rows[:, face == 1].sum(axis=1).mean()
    adjacent = rows[:, face == 2].sum(axis=1).mean()
    # Midpoint oracle: the same source points, exact point-to-face form factors.
    far = np.array([[1, 0, 0], [1, 1, 0], [1, 1, 1], [1, 0, 1]], dtype=float)
    side = np.array([[0, 0, 0], [1, 0, 0], [1, 0, 1], [0, 0, 1]], dtype=float)
    mid_opp = np.mean([lambert(patches.centres[s], patches.normals[s], far) for s in sources])
    mid_adj = np.mean([lambert(patches.centres[s], patches.normals[s], side) for s in sources])
    return opposite, adjacent, mid_opp, mid_adj


def test_unit_cube_face_form_factors():
    # Area average over 8 x 8 source patches of the x = 0 face. Two errors: the source
    # quadrature (one point per patch: 0.03 / n^2 measured, 5e-4 at n = 8) and the hemicube
    # (< 1e-4 at R = 64, next test); tolerance 1e-3 covers both with margin.
    opposite, adjacent, mid_opp, mid_adj = _cube_face_averages(8, 64)
    assert opposite == pytest.approx(CUBE_OPPOSITE, abs=1e-3)
    assert adjacent == pytest.approx(CUBE_ADJACENT, abs=1e-3)
    assert abs(mid_opp - CUBE_OPPOSITE) < 6e-4 and abs(mid_adj - CUBE_ADJACENT) < 6e-4


def test_unit_cube_error_shrinks_with_resolution():
    # Against the midpoint oracle (same source points), so only the hemicube error remains.
    # Opposite face: its edges fall on pixel boundaries (aligned hemicube, 4 x 4 sources) so
    # the error is the smooth midpoint-rule error, O(1/R^2): a factor ~4 per doubling.
    # Adjacent face: its far edge and the cube's corner edges (the top face's diagonals, where
    # the tie rule shares pixels alternately) alias: first-order, sign-varying terms that the
    # average over 8 x 8 sources damps; at least 4x smaller from R = 32 to R = 128, and always
    # far below the weight of one diagonal of pixels (~5e-3 at R = 32).
    opp, adj = {}, {}
    for r in (32, 64, 128):
        o, _, mid_o, _ = _cube_face_averages(4, r)
        _, a, _, mid_a = _cube_face_averages(8, r)
        opp[r], adj[r] = abs(o - mid_o), abs(a - mid_a)
    assert 3.5 < opp[32] / opp[64] < 4.5 and 3.5 < opp[64] / opp[128] < 4.5
    assert opp[32] < 5e-5
    assert adj[128] < adj[32] / 4 and max(adj.values()) < 2e-4


# ------------------------------------------------------------------------------------------
# Identities
# ------------------------------------------------------------------------------------------

@pytest.mark.parametrize("resolution, rotate", [(16, False), (64, False), (64, True),
                                                (50, True)])
def test_rows_sum_to_one_inside_a_closed_box(resolution, rotate):
    # Every pixel of every hemicube inside a closed, conforming mesh sees a triangle: shared
    # edges are rasterised without cracks (bit-identical bounds), whatever the hemicube's
    # orientation. Only front sides are visible from inside.
    corners, _ = box_quads((1.0, 1.5, 2.0), 0.25)
    patches = make_patches(corners)
    p = len(corners)
    rows = hemicube_rows(patches, np.arange(p), resolution=resolution, rotate=rotate,
                         rng=np.random.default_rng(7))
    assert np.allclose(rows.sum(axis=1), 1.0, rtol=0, atol=1e-12)
    assert rows[:, p:].sum() == 0
    assert rows[np.arange(p), np.arange(p)].sum() == 0          # no patch sees itself


@pytest.mark.parametrize("resolution", [32, 64, 128])
def test_depth_ties_are_shared_in_a_symmetric_cube(resolution):
    # One patch per face of a unit cube: every hemicube sees the cube's corner edges along
    # the diagonals of its top face, where pixel centres lie on the line that two faces share
    # at equal depth. Giving every tie to the same side skews F_ij against F_ji by about two
    # half-diagonals of pixels (measured 4.8e-3 at R = 32); sharing them alternately must keep
    # the skew below one half-diagonal's weight (its pixels beyond the opposite face, u > 0.5).
    corners, _ = box_quads((1.0, 1.0, 1.0), 1.0)
    patches = make_patches(corners)
    rows = hemicube_rows(patches, np.arange(6), resolution=resolution)[:, :6]
    u = -1 + (np.arange(resolution) + 0.5) * 2.0 / resolution
    top = delta_form_factors(resolution)["top"]
    half_diagonal = top[np.arange(resolution), np.arange(resolution)][u > 0.5].sum()
    assert np.abs(rows - rows.T).max() < half_diagonal
    assert np.allclose(rows.sum(axis=1), 1.0, atol=1e-12)


def test_reciprocity_between_box_faces():
    # A_a F_ab = A_b F_ba for the faces of a 1 x 1.5 x 2 box (area sums over patches of 0.25).
    # Each side carries its own source-quadrature error (~1 % at this patch size, see the cube
    # test: 0.0019 / 0.2 at n = 4) and pixel error; tolerance 1 % relative.
    corners, face = box_quads((1.0, 1.5, 2.0), 0.25)
    patches = make_patches(corners)
    p = len(corners)
    rows = hemicube_rows(patches, np.arange(p), resolution=64)[:, :p]
    af = patches.areas[:, None] * rows
    faces = np.array([[af[face == a][:, face == b].sum() for b in range(6)] for a in range(6)])
    off = ~np.eye(6, dtype=bool)
    assert np.all(faces[off] > 0.05)
    rel = np.abs(faces - faces.T)[off] / faces[off]
    assert rel.max() < 0.01


# ------------------------------------------------------------------------------------------
# Visibility: occlusion, z-buffer, sides, clipping
# ------------------------------------------------------------------------------------------

def test_blocker_hides_exactly_its_shadow():
    # From the centre of the source, a blocker of half the size at half the height covers
    # exactly the target's projection: the target is hidden (but for rim pixels) and the
    # blocker gets the target's unoccluded form factor.
    patches = make_patches([square(0, 0, 0, 1.0), square(0, 0, 1, 1.0, False),
                            square(0, 0, 0.5, 0.5, False)])
    unoccluded = lambert(np.zeros(3), np.array([0, 0, 1.0]), square(0, 0, 1, 1.0))
    rows = hemicube_rows(patches, [0], resolution=128)
    assert rows[0, 1] < 2e-3                                    # rim pixels only
    assert rows[0, 2] == pytest.approx(unoccluded, abs=2e-3)
    alone = hemicube_rows(make_patches(patches.corners[:2]), [0], resolution=128)
    assert alone[0, 1] == pytest.approx(unoccluded, abs=2e-3)


def test_z_buffer_is_per_pixel_for_intersecting_polygons():
    # Two squares crossing along x = 0: A (z = 1 + 0.3 x) is nearer for x < 0, B for x > 0.
    # Any per-triangle drawing order (painter's algorithm) gives one of them whole; the
    # z-buffer must give each its visible half, whose form factor Lambert gives exactly.
    def tilted(slope):
        xy = np.array([[-0.5, -0.5], [0.5, -0.5], [0.5, 0.5], [-0.5, 0.5]])[::-1]
        return np.column_stack([xy, 1 + slope * xy[:, 0]])
    a, b = tilted(0.3), tilted(-0.3)
    source = square(0, 0, 0, 0.01)
    n = np.array([0, 0, 1.0])
    half_a = np.array([[-0.5, -0.5, 0.85], [0, -0.5, 1], [0, 0.5, 1], [-0.5, 0.5, 0.85]])
    half_b = np.array([[0, -0.5, 1], [0.5, -0.5, 0.85], [0.5, 0.5, 0.85], [0, 0.5, 1]])
    expect_a, expect_b = lambert(np.zeros(3), n, half_a), lambert(np.zeros(3), n, half_b)
    for order in ([source, a, b], [source, b, a]):
        patches = make_patches(order)
        rows = hemicube_rows(patches, [0], resolution=256)[0]
        got = {tuple(np.round(patches.centres[k], 6)): rows[k] for k in (1, 2)}
        got_a = got[tuple(np.round(a.mean(axis=0), 6))]
        got_b = got[tuple(np.round(b.mean(axis=0), 6))]
        # Pixel error along the crossing line and the rims at R = 256: < 5e-3.
        assert got_a == pytest.approx(expect_a, abs=5e-3)
        assert got_b == pytest.approx(expect_b, abs=5e-3)
        assert abs(got_a - got_b) < 1e-2                        # symmetric halves


def test_back_side_hits_land_in_back_columns():
    # Target above the source with its normal pointing away: seen from behind -> q + P.
    patches = make_patches([square(0, 0, 0, 1.0), square(0, 0, 1, 1.0, facing_up=True)])
    p = 2
    expect = lambert(np.zeros(3), np.array([0, 0, 1.0]), square(0, 0, 1, 1.0))
    rows = hemicube_rows(patches, [0], resolution=64)
    assert rows[0, 1] == 0
    assert rows[0, p + 1] == pytest.approx(expect, abs=1e-4)   # 1/R^2 error, see cube test
    culled = hemicube_rows(patches, [0], resolution=64, cull_back=True)
    assert culled.sum() == 0                                    # not drawn: light escapes


def test_back_facing_blocker_occludes_unless_culled():
    # A blocker seen from behind still hides the target (both sides occlude); with
    # cull_back it is not drawn and the target is fully visible.
    patches = make_patches([square(0, 0, 0, 1.0), square(0, 0, 1, 1.0, False),
                            square(0, 0, 0.5, 0.5, facing_up=True)])
    rows = hemicube_rows(patches, [0], resolution=128)[0]
    assert rows[1] < 2e-3 and rows[3 + 2] > 0.2
    culled = hemicube_rows(patches, [0], resolution=128, cull_back=True)[0]
    assert culled[1] == pytest.approx(rows[3 + 2], abs=2e-3) and culled[3 + 2] == 0


def test_source_on_the_back_side_looks_along_minus_normal():
    # Patch 0 faces +z; a target below it facing up is seen by node P + 0 only.
    patches = make_patches([square(0, 0, 0, 1.0), square(0, 0, -1, 1.0, facing_up=True)])
    p = 2
    expect = lambert(np.zeros(3), np.array([0, 0, -1.0]), square(0, 0, -1, 1.0))
    rows = hemicube_rows(patches, [0, p + 0], resolution=64)
    assert rows[0].sum() == 0
    assert rows[1, 1] == pytest.approx(expect, abs=1e-4)
    assert rows[1, p + 1] == 0 and rows[1, p] == 0              # no self-hit from behind


def pixel_rays(resolution):
    """Directions (3 R^2, 3) of the pixel centres in buffer order, in the eye frame.

    An unrotated hemicube of an axis-aligned square facing +z has the world axes as its
    frame (x along the first edge), so these are world directions too.
    """
    h = 2.0 / resolution
    u = -1 + (np.arange(resolution) + 0.5) * h
    top_v, side_v = u, (np.arange(resolution // 2) + 0.5) * h
    parts = []
    for face in range(5):
        uu, vv = np.meshgrid(u, top_v if face == 0 else side_v)
        one = np.ones_like(uu)
        xyz = {0: (uu, vv, one), 1: (one, uu, vv), 2: (-one, -uu, vv), 3: (-uu, one, vv),
               4: (uu, -one, vv)}[face]
        parts.append(np.stack([a.ravel() for a in xyz], axis=1))
    return np.concatenate(parts)


def covered_by_wall(eye, rays, x, y_range, z_range):
    """Exact per-pixel coverage of the rectangle {x} x y_range x z_range (ray casting)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (x - eye[0]) / rays[:, 0]
    hit = eye + t[:, None] * rays
    return (t > 0) & (hit[:, 1] >= y_range[0]) & (hit[:, 1] <= y_range[1]) \
        & (hit[:, 2] >= z_range[0]) & (hit[:, 2] <= z_range[1])


@pytest.mark.parametrize("resolution", [16, 64, 128])
@pytest.mark.parametrize("bottom", [-5.0, 0.0])
def test_wall_crossing_or_touching_the_eye_plane_is_clipped(resolution, bottom):
    # A large wall x = 0.3 reaching down to z = -5 (crossing the source's plane, passing beside
    # the eye) or to z = 0 (a wall standing on the source's floor, its bottom edge in the
    # plane). Oracle: cast each pixel's ray at the wall; the row must be exactly the sum of the
    # delta form factors of the pixels whose centre ray hits it. Projecting the vertices below
    # the plane would wrap them through infinity onto the other side of the hemicube.
    wall = np.array([[0.3, -5, bottom], [0.3, 5, bottom], [0.3, 5, 5], [0.3, -5, 5]])[::-1]
    patches = make_patches([square(0, 0, 0, 0.01), wall])
    rows = hemicube_rows(patches, [0], resolution=resolution)[0]
    eye = np.zeros(3)
    hit = covered_by_wall(eye, pixel_rays(resolution), 0.3, (-5, 5), (max(bottom, 0), 5))
    d = delta_form_factors(resolution)
    dff = np.concatenate([d[name].ravel() for name in FACE_NAMES])
    assert rows[1] + rows[3] == pytest.approx(dff[hit].sum(), abs=1e-12)
    assert rows.sum() == pytest.approx(rows[1] + rows[3])      # the rest escapes
    # And the continuum value (Lambert on the part above the plane): a straight edge misses
    # at most one pixel row or column of its face, <= 0.82 / R each, 4 edges at most.
    expect = lambert(eye, np.array([0, 0, 1.0]), wall)
    assert rows[1] + rows[3] == pytest.approx(expect, abs=3.3 / resolution)


def test_geometry_nearer_than_the_near_plane_is_clipped():
    # Along each face's axis, geometry nearer than near = tol.hemicube_near x scene diagonal is
    # cut away. A wall x = near / 3 beside the eye is then invisible through the
    # +x face (all of it is nearer than near along x). Through the top face (axis z) the ray
    # of column u meets it at z = x / u, kept while z >= near: 0 < u <= 1/3; through the
    # +y face (axis y, u = -x / y) at y = -x / u: -1/3 <= u < 0; the -y face mirrors it.
    source = square(0, 0, 0, 0.01)
    diagonal = np.linalg.norm([0.01, 2.0, 2.0])                 # bounding box of the scene
    wall_x = tol.hemicube_near * diagonal / 3                       # inside the source's x extent
    wall = np.array([[wall_x, -1, -1], [wall_x, 1, -1], [wall_x, 1, 1], [wall_x, -1, 1]])[::-1]
    patches = make_patches([source, wall])
    rows = hemicube_rows(patches, [0], resolution=64)[0]
    u = -1 + (np.arange(64) + 0.5) / 32
    d = delta_form_factors(64)
    expect = d["top"][:, (u > 0) & (u <= 1 / 3)].sum() + d["+y"][:, (u < 0) & (u >= -1 / 3)].sum() \
        + d["-y"][:, (u > 0) & (u <= 1 / 3)].sum()
    assert rows[1] + rows[3] == pytest.approx(expect, abs=1e-12)


# ------------------------------------------------------------------------------------------
# Rotation
# ------------------------------------------------------------------------------------------

def _aliasing_scene():
    g = np.arange(-1, 1, 0.2) + 0.1
    targets = [square(x, y, 1.0, 0.2, facing_up=False) for x in g for y in g]
    offsets = (np.arange(4) - 1.5) * 0.01
    sources = [square(x, y, 0.0, 0.01) for x in offsets for y in offsets]
    patches = make_patches(sources + targets)
    exact = np.array([[lambert(patches.centres[s], np.array([0, 0, 1.0]), t) for t in targets]
                      for s in range(len(sources))])
    return patches, len(sources), exact


def test_rotation_is_seeded_and_reproducible():
    patches, n_src, _ = _aliasing_scene()
    src = np.arange(n_src)
    a = hemicube_rows(patches, src, resolution=32, rotate=True, rng=np.random.default_rng(3))
    b = hemicube_rows(patches, src, resolution=32, rotate=True, rng=np.random.default_rng(3))
    c = hemicube_rows(patches, src, resolution=32, rotate=True, rng=np.random.default_rng(4))
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)
    assert np.array_equal(a, hemicube_rows(patches, src, resolution=32, rotate=True, rng=3))


def test_rotation_reduces_aliasing_on_small_distant_patches():
    # A 10 x 10 grid of 0.2 squares at distance 1 seen from 16 nearby source points. With the
    # hemicube aligned to the grid, every target edge rounds to whole pixel rows the same way
    # for every source (systematic aliasing); rotated hemicubes cut edges at random angles, so
    # the errors shrink and average out over sources. Reference (form_factors.md): ~9 % RMS
    # at R = 32 and ~1.2 % at R = 128 for this configuration.
    patches, n_src, exact = _aliasing_scene()
    src = np.arange(n_src)
    rms = {}
    for resolution in (32, 128):
        for rotate in (False, True):
            rows = hemicube_rows(patches, src, resolution=resolution, rotate=rotate,
                                 rng=np.random.default_rng(1))[:, n_src:len(patches.areas)]
            single = np.sqrt(np.mean((rows / exact - 1) ** 2))
            averaged = np.sqrt(np.mean((rows.mean(axis=0) / exact.mean(axis=0) - 1) ** 2))
            rms[resolution, rotate] = single, averaged
    for resolution in (32, 128):
        assert rms[resolution, True][0] < rms[resolution, False][0] / 1.5
        assert rms[resolution, True][1] < rms[resolution, False][1] / 2
    assert rms[32, True][0] < 0.12 and rms[128, True][0] < 0.02


# ------------------------------------------------------------------------------------------
# Quads drawn whole
# ------------------------------------------------------------------------------------------

def test_only_planar_convex_quads_are_drawn_whole():
    flat = square(0, 0, 0, 1.0)
    warped = flat.copy()
    warped[2, 2] = 0.1                                           # 4th corner off the plane
    concave = np.array([[0, 0, 0], [1, 0, 0], [0.3, 0.3, 0], [0, 1, 0]], dtype=float)
    triangle = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 1, 0]], dtype=float)
    patches = make_patches([flat, warped, concave, triangle])
    polys, poly_patch = draw_polygons(patches)
    assert sorted(poly_patch.tolist()) == [0, 1, 1, 2, 2, 3]
    assert np.array_equal(polys[poly_patch == 0][0], flat)
    tris = polys[poly_patch != 0]
    assert np.array_equal(tris[:, 3], tris[:, 2])              # triangles repeat a corner


def test_quads_whole_cover_the_same_pixels_as_their_triangles():
    # With rotated hemicubes no pixel centre lies exactly on a box edge, so drawing a planar
    # quad whole or as two triangles must give the same rows, but for the odd pixel whose
    # centre ties two polygons at equal depth (at most a few pixels' delta form factor).
    corners, _ = box_quads((1.0, 1.5, 2.0), 0.25)
    patches = make_patches(corners)
    p = len(corners)
    polys, poly_patch = draw_polygons(patches)
    assert polys.shape[0] == p                                   # all drawn whole
    tris, tri_patch = patch_triangles(patches)
    args = (patches.centres, patches.normals, patches.corners, np.arange(p))
    whole = polygon_rows(polys, poly_patch, *args, resolution=64, rotate=True, rng=5)
    split = polygon_rows(tris, tri_patch, *args, resolution=64, rotate=True, rng=5)
    differ = np.abs(whole - split) > 1e-12                       # above summation rounding
    assert differ.sum() <= 0.001 * differ.size
    assert np.abs(whole - split).max() <= 3 * delta_form_factors(64)["top"].max()


# ------------------------------------------------------------------------------------------
# Integration with core.patches
# ------------------------------------------------------------------------------------------

def test_setup_cache_follows_the_patches_object():
    # hemicube_rows caches the per-scene setup of the last Patches object: alternating between
    # two scenes must give each its own rows, equal to an uncached computation.
    patches_mod = pytest.importorskip("core.patches")
    cube = patches_mod.make_patches(samples.unit_cube(n=2), max_edge=0.5)
    squares = patches_mod.make_patches(samples.opposed_squares(n=2), max_edge=0.5)
    first = hemicube_rows(cube, [0, 1], resolution=16)
    other = hemicube_rows(squares, [0, 1], resolution=16)
    again = hemicube_rows(cube, [0, 1], resolution=16)
    assert np.array_equal(first, again)
    polys, poly_patch = draw_polygons(squares)
    fresh = polygon_rows(polys, poly_patch, squares.centres, squares.normals, squares.corners,
                         [0, 1], resolution=16)
    assert np.array_equal(other, fresh)


def test_with_real_patches_of_a_sample_scene():
    patches_mod = pytest.importorskip("core.patches")
    scene = samples.unit_cube(n=3)
    patches = patches_mod.make_patches(scene, max_edge=0.5)
    p = patches.centres.shape[0]
    rows = hemicube_rows(patches, np.arange(2 * p), resolution=32)
    # Inward-facing closed cube: front nodes see everything, back nodes (outside) nothing.
    assert np.allclose(rows[:p].sum(axis=1), 1.0, atol=1e-12)
    assert rows[p:].sum() == 0
