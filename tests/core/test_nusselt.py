"""Hemisphere-base projection form factors (core/nusselt.py): the Nusselt analog.

Oracles: per-pixel ray casting (which pixel centres see a polygon: the rasteriser must count
exactly those), the contour formula ``core.exact.point_polygon_form_factor`` (continuum values of
point-to-polygon form factors), Howell's closed forms (opposed squares, the unit cube), shadows
whose visible parts are known exactly, the identities (closed scenes sum to 1) and the symmetry of
the method itself (rotating the eye frame is rotating the scene the other way).
"""

from types import SimpleNamespace

import numpy as np
import pytest

from bench import scenes as samples
from builders import box_quads, centred_square as square, quad_patches as make_patches
from core import nusselt
from core.constants import tol
from core.exact import exact_rows, point_polygon_form_factor
from core.hemicube import hemicube_rows
from core.nusselt import base_pixels, nusselt_rows
from core.patches import make_patches as real_patches

UP = np.array([0.0, 0.0, 1.0])

#: Howell's catalogue (shared/reference/form_factors.md).
CUBE_OPPOSITE = 0.199824895698
CUBE_ADJACENT = 0.200043776075

#: Pixel-count error statistics. A pixel crossed by a polygon's projected boundary counts whole
#: or not at all by its centre: an error of (indicator - covered fraction), about uniform in
#: [-1/2, 1/2] (variance 1/12) and of random sign from pixel to pixel. A curve of length L
#: crosses about (4 / pi) L / h pixels of side h. SIGMAS standard deviations of the sum bound the
#: error of one polygon (6: a false alarm once in 5e8 polygons).
SIGMAS = 6.0
PIXEL_VARIANCE = 1.0 / 12.0
CROSSINGS_PER_LENGTH = 4.0 / np.pi


#: Howell's catalogue values are given to 12 digits.
CATALOGUE_DIGITS = 1e-11

#: Pixels are tested in float32, so a pixel centre within ~1e-6 pixel of an edge may go either
#: way: comparisons of whole pixel counts allow one pixel (measured: 0 differences over 120
#: rectangles against ray casting; 0 between a rotated frame and the scene turned back).
PIXEL_SLACK = 1

#: Rows of a closed scene sum to 1 up to float64 rounding of a sum of at most 2P terms.
SUM_TOL = 1e-12

#: Unit cube, 8 x 8 source points: the one-point source quadrature (the midpoint oracle is
#: 4.7e-4 and 1.2e-4 off Howell) and the pixels against the midpoint oracle (measured 7.9e-4 and
#: 1.5e-4 at R = 64, 1.0e-4 and 2.8e-5 at R = 256: about half of these).
CUBE_MIDPOINT_TOL = 6e-4
CUBE_PIXEL_TOL = {64: 1.5e-3, 256: 3e-4}

#: Opposed squares 2 apart from 8 x 8 source points: the midpoint rule (measured 6.8e-5).
OPPOSED_MIDPOINT_TOL = 1e-4

#: exact_rows' visible fraction from 256 stratified rays against these rows (measured 8.4e-4
#: for the partly shadowed target, 1.3e-4 for the unshadowed blocker).
EXACT_RAYS_TOL = 2e-3

#: A duplicated face ties at every pixel: the smaller copy's share of the total (measured
#: 0.497; giving every tie to one copy makes it 0).
TIE_SHARE_MIN = 0.4

#: Rows over ROTATIONS random rotations: their mean is within STANDARD_ERRORS of its noise plus
#: the radial bias that rotation does not remove (pixel rings, the rim normalisation: measured
#: up to 2.1 % at R = 32 with 4000 rotations); the unrotated frame's worst error (8.3 %) is more
#: than ALIASING_GAIN times the mean's (measured 2.2 %).
ROTATIONS = 1000
STANDARD_ERRORS = 4.0
RADIAL_BIAS = 0.03
ALIASING_GAIN = 2.0

#: Against the hemicube (a box with a tilted plate): mean L1 distance of a row at R = 256
#: (measured 5.8e-3) and its fall from R = 64 (measured 5.8x); RMS against exact_rows at
#: R = 128 (measured 3.2e-4; hemicube 3.7e-4; exact_rows' own ray noise is about 1e-4).
HEMICUBE_L1_TOL = 1e-2
HEMICUBE_L1_FALL = 4.0
EXACT_RMS_TOL = 6e-4
EXACT_RMS_VS_HEMICUBE = 2.0

#: Where it breaks. Small patches low over the horizon: relative RMS 8.7x the hemicube's at
#: R = 64 (1.83 against 0.21); the same near the zenith: about equal (0.136 against 0.133).
HORIZON_RATIO_MIN = 4.0
ZENITH_RATIO = (0.5, 2.0)
#: Opposed unit squares one apart from the centre point: +19.8 % from either method (their
#: difference 8.5e-5 at R = 256).
PROXIMITY_ERROR = (0.18, 0.22)
METHODS_AGREE = 1e-3
#: Straight chords between the projected corners keep 63 % of a large near square.
CHORD_SHARE_MAX = 0.8

# ------------------------------------------------------------------------------------------
# Helpers and the independent oracles
# ------------------------------------------------------------------------------------------

def eye_of(patches, source=0):
    """The eye of a front source node, as the method places it (offset along the normal)."""
    v = np.asarray(patches.corners).reshape(-1, 3)
    diag = np.linalg.norm(v.max(axis=0) - v.min(axis=0))
    return patches.centres[source] + tol.surface_offset * diag * patches.normals[source]


def lambert(eye, poly, normal=UP):
    """Unoccluded point-to-polygon form factor (core.exact's contour formula)."""
    return float(point_polygon_form_factor([eye], [normal], np.asarray(poly)[None])[0, 0])


def counted_directions(resolution):
    """Unit directions (n, 3) of the counted pixels of an axis-aligned eye frame (float64)."""
    r = resolution
    c = -1 + (np.arange(r) + 0.5) * 2.0 / r
    x, y = np.meshgrid(c, c)                       # row i: y, column j: x (pixel i R + j)
    x, y = x.ravel(), y.ravel()
    inside = x * x + y * y < 1
    return np.stack([x, y, np.sqrt(np.maximum(1 - x * x - y * y, 0))], axis=1)[inside]


def ray_cast_share(eye, quad, resolution):
    """Fraction of the counted pixels whose centre ray hits the planar convex ``quad``."""
    d = counted_directions(resolution)
    normal = np.cross(quad[1] - quad[0], quad[2] - quad[0])
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((quad[0] - eye) @ normal) / (d @ normal)
    hit = eye + t[:, None] * d
    ok = t > 0
    for k in range(4):
        edge = quad[(k + 1) % 4] - quad[k]
        ok &= np.cross(edge, hit - quad[k]) @ normal >= 0
    return ok.sum() / d.shape[0]


def projected_perimeter(eye, poly, samples=400):
    """Length of the base-disk projection of a polygon's boundary (above the horizon)."""
    total = 0.0
    for k in range(len(poly)):
        t = np.linspace(0, 1, samples)[:, None]
        p = poly[k] + t * (poly[(k + 1) % len(poly)] - poly[k]) - eye
        u = p / np.linalg.norm(p, axis=1, keepdims=True)
        seg = np.linalg.norm(np.diff(u[:, :2], axis=0), axis=1)
        total += seg[(u[:-1, 2] > 0) & (u[1:, 2] > 0)].sum()
    return total


def pixel_tolerance(eye, polys, value, resolution):
    """SIGMAS-sigma bound on |pixel count - contour value| for the region bounded by ``polys``.

    The boundary term (see SIGMAS) plus the rim bias: every counted pixel weighs 1/n, while a
    continuum pixel weighs h^2 / pi, so all values are scaled by pi / (n h^2) (measured -0.95 %
    at R = 32, -0.34 % at 64, -0.19 % at 128, +0.007 % at 256: the disk's pixel count).
    """
    h = 2.0 / resolution
    n = base_pixels(resolution)[4]
    length = sum(projected_perimeter(eye, p) for p in polys)
    crossings = CROSSINGS_PER_LENGTH * length / h
    boundary = SIGMAS * np.sqrt(crossings * PIXEL_VARIANCE) * h * h / np.pi
    return boundary + abs(np.pi / (n * h * h) - 1) * value


def random_quad(rng, low):
    """A random planar rectangle (counter-clockwise about some normal) near the origin, its
    centre at height >= ``low``."""
    centre = rng.uniform([-2, -2, low], [2, 2, 2])
    a, b = rng.normal(size=3), rng.normal(size=3)
    a *= rng.uniform(0.1, 1.0) / np.linalg.norm(a)
    b -= a * (a @ b) / (a @ a)
    b *= rng.uniform(0.1, 1.0) / np.linalg.norm(b)
    return np.array([centre - a - b, centre + a - b, centre + a + b, centre - a + b])


def howell_opposed(a, b, c):
    """Howell C-11: identical directly opposed rectangles a x b at distance c."""
    x, y = a / c, b / c
    return 2 / (np.pi * x * y) * (
        np.log(np.sqrt((1 + x * x) * (1 + y * y) / (1 + x * x + y * y)))
        + x * np.sqrt(1 + y * y) * np.arctan(x / np.sqrt(1 + y * y))
        + y * np.sqrt(1 + x * x) * np.arctan(y / np.sqrt(1 + x * x))
        - x * np.arctan(x) - y * np.arctan(y))


def test_oracles_against_closed_forms():
    # The helpers themselves: Howell C-11 at the unit cube, and the pixel directions (their
    # count is the method's own normalisation).
    assert howell_opposed(1.0, 1.0, 1.0) == pytest.approx(CUBE_OPPOSITE, abs=CATALOGUE_DIGITS)
    for r in (16, 64, 256):
        assert counted_directions(r).shape[0] == base_pixels(r)[4]
        # Gauss's circle problem: the count differs from the disk's area (in pixels) by at
        # most the pixels its rim passes through; a quarter of the rim, monotone over R / 2
        # columns and R / 2 rows, passes through at most R + 1 (measured difference: 7.7 at
        # R = 32).
        assert abs(base_pixels(r)[4] - np.pi * r * r / 4) <= 4 * r + 4


# ------------------------------------------------------------------------------------------
# Validation
# ------------------------------------------------------------------------------------------

def _pair():
    return make_patches([square(0, 0, 0, 1), square(0, 0, 1, 1, False)])


@pytest.mark.parametrize("bad, error", [(3, ValueError), (0, ValueError), (-2, ValueError),
                                        (4.0, TypeError), (True, TypeError),
                                        (4096, ValueError)])
def test_resolution_is_validated(bad, error):
    with pytest.raises(error, match="resolution"):
        nusselt_rows(_pair(), [0], resolution=bad)


@pytest.mark.parametrize("bad, error", [([4], ValueError), ([-1], ValueError),
                                        ([[0]], ValueError), ([0.0], TypeError)])
def test_sources_are_validated(bad, error):
    with pytest.raises(error, match="sources"):
        nusselt_rows(_pair(), bad)


def test_other_arguments_are_validated():
    patches = _pair()
    with pytest.raises(TypeError, match="rng"):
        nusselt_rows(patches, [0], rotate=True)
    with pytest.raises(TypeError, match="rotate"):
        nusselt_rows(patches, [0], rotate="yes")
    with pytest.raises(TypeError, match="patches"):
        nusselt_rows(np.zeros((2, 4, 3)), [0])
    bad = SimpleNamespace(**vars(patches))
    bad.normals = 2 * patches.normals
    with pytest.raises(ValueError, match="normals must be unit"):
        nusselt_rows(bad, [0])


def test_empty_sources_and_inputs_not_mutated():
    patches = _pair()
    before = {k: v.copy() for k, v in vars(patches).items()}
    sources = np.array([0, 1, 2, 3])
    rows = nusselt_rows(patches, sources, resolution=8)
    assert rows.shape == (4, 4) and rows.dtype == np.float64
    assert nusselt_rows(patches, [], resolution=8).shape == (0, 4)
    assert all(np.array_equal(before[k], v) for k, v in vars(patches).items())
    assert np.array_equal(sources, [0, 1, 2, 3])


# ------------------------------------------------------------------------------------------
# The rasteriser against ray casting, the values against the contour formula
# ------------------------------------------------------------------------------------------

@pytest.mark.parametrize("resolution", [16, 64, 256])
def test_pixels_are_those_whose_ray_hits_the_polygon(resolution):
    # Random rectangles around a point source, many crossing its horizon (centres down to
    # z = -0.5) or seen from behind: the row must count exactly the counted pixels whose
    # centre ray hits the rectangle (curved projected edges, bounding boxes, horizon). Pixels
    # are tested in float32 (PIXEL_SLACK).
    rng = np.random.default_rng(5)
    n = base_pixels(resolution)[4]
    for _ in range(40):
        quad = random_quad(rng, low=-0.5)
        patches = make_patches([square(0, 0, 0, 0.01), quad])
        row = nusselt_rows(patches, [0], resolution=resolution)[0]
        eye = eye_of(patches)
        front = (eye - quad.mean(axis=0)) @ patches.normals[1] > 0
        assert row[3 if front else 1] == 0                       # the other side: nothing
        share = ray_cast_share(eye, quad, resolution)
        assert abs(row[1 if front else 3] - share) <= PIXEL_SLACK / n


@pytest.mark.parametrize("resolution", [64, 128, 256])
def test_point_to_polygon_against_the_contour_formula(resolution):
    # Random rectangles wholly above the source's horizon: the pixel count converges to the
    # continuum value within the statistical bound of its boundary pixels (pixel_tolerance;
    # measured worst error / bound over these 40 rectangles: 0.35, 0.42, 0.47 at R = 64, 128,
    # 256; worst errors 1.6e-3, 9.8e-4, 2.7e-4).
    rng = np.random.default_rng(11)
    worst = 0.0
    for _ in range(40):
        quad = random_quad(rng, low=0.2)
        quad[:, 2] += max(0.0, 0.1 - quad[:, 2].min())           # lowest corner >= 0.1
        patches = make_patches([square(0, 0, 0, 0.01), quad])
        row = nusselt_rows(patches, [0], resolution=resolution)[0]
        eye = eye_of(patches)
        exact = lambert(eye, quad)
        err = abs(row[1] + row[3] - exact)
        worst = max(worst, err / pixel_tolerance(eye, [quad], exact, resolution))
    assert worst < 1.0


# ------------------------------------------------------------------------------------------
# Closed forms
# ------------------------------------------------------------------------------------------

def _cube_faces(n, resolution):
    corners, face = box_quads((1.0, 1.0, 1.0), 1.0 / n)
    patches = make_patches(corners)
    p = len(corners)
    sources = np.flatnonzero(face == 0)                        # the x = 0 face, normal +x
    rows = nusselt_rows(patches, sources, resolution=resolution)[:, :p]
    far = np.array([[1, 0, 0], [1, 1, 0], [1, 1, 1], [1, 0, 1]], dtype=float)
    side = np.array([[0, 0, 0], [1, 0, 0], [1, 0, 1], [0, 0, 1]], dtype=float)
    points, normals = patches.centres[sources], patches.normals[sources]
    mid = [point_polygon_form_factor(points, normals, f[None])[:, 0].mean() for f in (far, side)]
    return rows[:, face == 1].sum(axis=1).mean(), rows[:, face == 2].sum(axis=1).mean(), mid


@pytest.mark.parametrize("resolution", [64, 256])
def test_unit_cube_faces_against_howell(resolution):
    # Opposite and adjacent faces (perpendicular squares sharing an edge), area-averaged over
    # 8 x 8 source points. Two errors: the source quadrature (one point per patch: the
    # midpoint oracle: same points, exact values) and the pixels (the box's edges project to
    # curves that cut pixels at every angle, unlike on a hemicube's faces): CUBE_*_TOL.
    opposite, adjacent, (mid_opp, mid_adj) = _cube_faces(8, resolution)
    pixel, midpoint = CUBE_PIXEL_TOL[resolution], CUBE_MIDPOINT_TOL
    assert abs(mid_opp - CUBE_OPPOSITE) < midpoint and abs(mid_adj - CUBE_ADJACENT) < midpoint
    assert abs(opposite - mid_opp) < pixel and abs(adjacent - mid_adj) < pixel
    assert opposite == pytest.approx(CUBE_OPPOSITE, abs=midpoint + pixel)
    assert adjacent == pytest.approx(CUBE_ADJACENT, abs=midpoint + pixel)


def test_opposed_squares_against_howell():
    # Unit squares 2 apart (Howell C-11 with X = Y = 0.5), the source split 8 x 8, the target
    # whole: the area average of the rows against the closed form. Source quadrature
    # (OPPOSED_MIDPOINT_TOL) plus pixels (R = 256: the statistical bound of one square, 5.7e-4;
    # measured 1.1e-4).
    n, gap, resolution = 8, 2.0, 256
    cells = (np.arange(n) + 0.5) / n - 0.5
    sources = [square(x, y, 0, 1.0 / n) for x in cells for y in cells]
    target = square(0, 0, gap, 1.0, facing_up=False)
    patches = make_patches(sources + [target])
    rows = nusselt_rows(patches, np.arange(n * n), resolution=resolution)
    closed = howell_opposed(1.0, 1.0, gap)
    eye = eye_of(patches)
    bound = pixel_tolerance(eye, [target], closed, resolution) + OPPOSED_MIDPOINT_TOL
    assert rows[:, n * n].mean() == pytest.approx(closed, abs=bound)


# ------------------------------------------------------------------------------------------
# Identities and visibility
# ------------------------------------------------------------------------------------------

@pytest.mark.parametrize("resolution, rotate", [(16, False), (64, False), (64, True),
                                                (50, True)])
def test_rows_sum_to_one_inside_a_closed_box(resolution, rotate):
    # Every counted pixel inside a closed, conforming mesh sees a polygon: a shared edge's
    # great-circle test is bit for bit negated on its other side, so no pixel falls between.
    corners, _ = box_quads((1.0, 1.5, 2.0), 0.25)
    patches = make_patches(corners)
    p = len(corners)
    rows = nusselt_rows(patches, np.arange(p), resolution=resolution, rotate=rotate,
                        rng=np.random.default_rng(7))
    assert np.allclose(rows.sum(axis=1), 1.0, rtol=0, atol=SUM_TOL)
    assert rows[:, p:].sum() == 0
    assert rows[np.arange(p), np.arange(p)].sum() == 0          # no patch sees itself


def test_real_patches_of_a_sample_scene():
    patches = real_patches(samples.unit_cube(n=3), max_edge=0.5)
    p = patches.centres.shape[0]
    rows = nusselt_rows(patches, np.arange(2 * p), resolution=32)
    # Inward-facing closed cube: front nodes see everything, back nodes (outside) nothing.
    assert np.allclose(rows[:p].sum(axis=1), 1.0, rtol=0, atol=SUM_TOL)
    assert rows[p:].sum() == 0


def test_rows_do_not_depend_on_chunks_or_blocks(monkeypatch):
    # Sources are cut into chunks, items into groups of equal padded box size and fragment
    # blocks; none of this may change a bit (a lost or doubled fragment would).
    corners, _ = box_quads((1.0, 1.0, 1.0), 0.25)
    slab = [square(0.5, 0.5, 0.4, 0.5), square(0.5, 0.5, 0.4, 0.5, facing_up=False)]
    patches = make_patches(np.concatenate([corners, slab]))
    sources = np.arange(0, len(patches.areas), 5)
    whole = nusselt_rows(patches, sources, resolution=32, rotate=True, rng=2)
    monkeypatch.setattr(nusselt, "_FRAGMENT_BLOCK", 5)
    monkeypatch.setattr(nusselt, "_CHUNK_PAIRS", 100)
    assert np.array_equal(whole, nusselt_rows(patches, sources, resolution=32, rotate=True,
                                              rng=2))


def test_blocker_casts_its_exact_shadow():
    # From a point source, a 0.4 blocker at height 0.5 shadows the 1 x 1 target at height 1 on
    # the square twice its size: the target's visible part is the target minus that shadow,
    # known exactly (contour formula on the parts); the blocker takes its own unoccluded value.
    # Tolerance: the pixel bound of the regions' boundaries at R = 256.
    target = square(0, 0, 1, 1.0, facing_up=False)
    blocker = square(0.2, 0.1, 0.5, 0.4, facing_up=False)
    patches = make_patches([square(0, 0, 0, 0.01), target, blocker])
    eye = eye_of(patches)
    shadowed = np.array([[0, -0.2, 1], [0.5, -0.2, 1], [0.5, 0.5, 1], [0, 0.5, 1]])
    visible = lambert(eye, target) - lambert(eye, shadowed)
    resolution = 256
    row = nusselt_rows(patches, [0], resolution=resolution)[0]
    assert row[1] == pytest.approx(visible, abs=pixel_tolerance(eye, [target, shadowed],
                                                                visible, resolution))
    f_blocker = lambert(eye, blocker)
    assert row[2] == pytest.approx(f_blocker, abs=pixel_tolerance(eye, [blocker], f_blocker,
                                                                  resolution))
    # The exact method sees the same (its visible fraction from 256 stratified rays is the
    # noisier one: 9.3e-4 off the visible value here; EXACT_RAYS_TOL).
    ex = exact_rows(patches, [0], rays=256, rng=np.random.default_rng(0))[0]
    assert abs(ex[1] - row[1]) < EXACT_RAYS_TOL and abs(ex[2] - row[2]) < EXACT_RAYS_TOL


def test_depth_ties_are_shared_by_pixel_parity():
    # Two copies of one target (a duplicated face) tie at every pixel: the ties go to one copy
    # in even pixel columns and to the other in odd ones, so each gets half the form factor,
    # within one pixel per pixel row covered (all going to one copy would break reciprocity in
    # symmetric scenes, where faces meet along lines of pixel centres).
    target = square(0.1, 0.2, 1.0, 1.0, facing_up=False)
    patches = make_patches([square(0, 0, 0, 0.01), target, target])
    resolution = 64
    row = nusselt_rows(patches, [0], resolution=resolution)[0]
    eye = eye_of(patches)
    total = lambert(eye, target)
    assert row[1] + row[2] == pytest.approx(total, abs=pixel_tolerance(eye, [target], total,
                                                                      resolution))
    rows_covered = resolution          # at most every pixel row of the base
    assert abs(row[1] - row[2]) <= rows_covered / base_pixels(resolution)[4]
    assert min(row[1], row[2]) > TIE_SHARE_MIN * total


def test_back_sides_go_to_back_nodes():
    # Target above the source facing away: seen from behind -> column q + P. A source on the
    # back side of patch 0 (node P) looks down and sees a floor below.
    patches = make_patches([square(0, 0, 0, 1.0), square(0, 0, 1, 1.0, facing_up=True),
                            square(0, 0, -1, 1.0, facing_up=True)])
    p, resolution = 3, 128
    rows = nusselt_rows(patches, [0, p], resolution=resolution)
    eye = eye_of(patches)
    expect = lambert(eye, square(0, 0, 1, 1.0))
    bound = pixel_tolerance(eye, [square(0, 0, 1, 1.0)], expect, resolution)
    assert rows[0, 1] == 0 and rows[0, p + 1] == pytest.approx(expect, abs=bound)
    assert rows[1, 2] == pytest.approx(expect, abs=bound)        # the mirror image, front side
    assert rows[1].sum() == rows[1, 2] and rows[0].sum() == rows[0, p + 1]


# ------------------------------------------------------------------------------------------
# Rotation
# ------------------------------------------------------------------------------------------

def _grid_scene(size=0.4):
    g = np.arange(-1, 1, size) + size / 2
    targets = [square(x, y, 1.0, size, facing_up=False) for x in g for y in g]
    return make_patches([square(0, 0, 0, 0.01)] + targets), np.array(targets)


def test_rotating_the_frame_is_rotating_the_scene():
    # A rotated eye frame (angle a from the rng, as documented) must give exactly the rows of
    # the unrotated frame with the targets turned by -a about the source's normal (pixels on
    # an edge within float32 rounding aside: PIXEL_SLACK; the rotation moves up to 8 pixels
    # of a target).
    patches, targets = _grid_scene()
    rotated = nusselt_rows(patches, [0], resolution=64, rotate=True, rng=9)[0]
    angle = np.random.default_rng(9).uniform(0.0, 2.0 * np.pi, size=1)[0]
    c, s = np.cos(-angle), np.sin(-angle)
    turn = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    turned = make_patches([square(0, 0, 0, 0.01)] + list(targets @ turn.T))
    plain = nusselt_rows(turned, [0], resolution=64)[0]
    assert np.abs(rotated - plain).max() <= PIXEL_SLACK / base_pixels(64)[4]
    assert np.array_equal(rotated, nusselt_rows(patches, [0], resolution=64, rotate=True,
                                                rng=np.random.default_rng(9))[0])


def test_rotation_averages_aliasing_out():
    # Averaged over random rotations the rows approach the contour values (ROTATIONS: the
    # worst error over the tolerance is 0.63 here); the unrotated frame aliases.
    patches, targets = _grid_scene()
    n = len(targets)
    eye = eye_of(patches)
    exact = point_polygon_form_factor([eye], [UP], targets)[0]
    rows = nusselt_rows(patches, np.zeros(ROTATIONS, dtype=int), resolution=32, rotate=True,
                        rng=3)[:, 1:n + 1]
    mean, spread = rows.mean(axis=0), rows.std(axis=0)
    noise = STANDARD_ERRORS * spread / np.sqrt(ROTATIONS)
    assert np.all(np.abs(mean - exact) <= noise + RADIAL_BIAS * exact)
    plain = nusselt_rows(patches, [0], resolution=32)[0, 1:n + 1]
    assert np.abs(plain / exact - 1).max() > ALIASING_GAIN * np.abs(mean / exact - 1).max()
    assert not np.array_equal(rows[0], rows[1])


# ------------------------------------------------------------------------------------------
# Against the hemicube, and where it breaks
# ------------------------------------------------------------------------------------------

def _box_with_blocker():
    corners, _ = box_quads((1.0, 1.5, 2.0), 0.5)
    plate = square(0.5, 0.75, 1.0, 0.5, facing_up=False)
    centre = plate.mean(axis=0)
    c, s = np.cos(0.4), np.sin(0.4)
    tilt = np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    return make_patches(np.concatenate([corners, [(plate - centre) @ tilt.T + centre]]))


def test_agrees_with_the_hemicube_as_resolution_grows():
    # A closed box with a tilted plate in it: both methods estimate the same point-source rows,
    # so their difference (mean L1 per row) must shrink with R, and both agree with the exact
    # method's rays (64 per pair) about equally (HEMICUBE_*, EXACT_RMS_*).
    patches = _box_with_blocker()
    sources = np.arange(len(patches.areas))
    diff = {}
    for resolution in (64, 256):
        a = nusselt_rows(patches, sources, resolution=resolution)
        b = hemicube_rows(patches, sources, resolution=resolution)
        diff[resolution] = np.abs(a - b).sum(axis=1).mean()
    assert diff[256] < HEMICUBE_L1_TOL and diff[256] < diff[64] / HEMICUBE_L1_FALL
    exact = exact_rows(patches, sources, rays=64, rng=np.random.default_rng(0))
    seen = exact > 0
    rms = {name: np.sqrt(np.mean((f(patches, sources, resolution=128) - exact)[seen] ** 2))
           for name, f in (("nusselt", nusselt_rows), ("hemicube", hemicube_rows))}
    assert rms["nusselt"] < EXACT_RMS_TOL
    assert rms["nusselt"] < EXACT_RMS_VS_HEMICUBE * rms["hemicube"]


def test_breaks_for_small_patches_low_over_the_horizon():
    # Every pixel has the same form factor, so pixel rings crowd together at the rim: at R = 64
    # the outermost ring spans 14 degrees of elevation. 0.2 m squares on a wall 3 m away, their
    # centres 3 and 7 degrees above the source's horizon, alias badly (relative RMS over 16
    # rotations, against the hemicube, whose side faces resolve low elevations finely); the
    # same squares seen near the zenith (scaled to the same angular size) do as well as on the
    # hemicube (HORIZON_RATIO_MIN, ZENITH_RATIO).
    def rms(targets, method):
        patches = make_patches([square(0, 0, 0, 0.01)] + targets)
        n = len(targets)
        exact = point_polygon_form_factor([eye_of(patches)], [UP], np.array(targets))[0]
        rows = method(patches, np.zeros(16, dtype=int), resolution=64, rotate=True, rng=1)
        return np.sqrt(np.mean((rows[:, 1:n + 1] / exact - 1) ** 2))

    corners = np.array([[0, -0.1, -0.1], [0, -0.1, 0.1], [0, 0.1, 0.1], [0, 0.1, -0.1]])
    low = [corners + [3, y, z] for y in np.arange(-0.9, 1, 0.2) for z in (0.15, 0.35)]
    s = 0.2 / 3
    high = [square(x, y, 1.0, s, facing_up=False) for x in np.arange(-0.3, 0.3, s) + s / 2
            for y in (-s / 2, s / 2)]
    assert rms(low, nusselt_rows) > HORIZON_RATIO_MIN * rms(low, hemicube_rows)
    low_ratio, high_ratio = ZENITH_RATIO
    assert low_ratio < rms(high, nusselt_rows) / rms(high, hemicube_rows) < high_ratio


def test_breaks_for_near_patches_like_the_hemicube():
    # The source is its centre point: opposed unit squares one unit apart get the centre's
    # value 0.2395, +19.8 % over the area-to-area closed form (Howell C-11), from either method.
    patches = make_patches([square(0, 0, 0, 1.0), square(0, 0, 1, 1.0, facing_up=False)])
    closed = howell_opposed(1.0, 1.0, 1.0)
    nus = nusselt_rows(patches, [0], resolution=256)[0, 1]
    hem = hemicube_rows(patches, [0], resolution=256)[0, 1]
    low, high = PROXIMITY_ERROR
    assert low < nus / closed - 1 < high and abs(nus - hem) < METHODS_AGREE


def test_projected_edges_must_be_curved():
    # A 2 x 2 square 0.3 above the source (off centre) projects to a region whose edges are
    # ellipse arcs. Joining its projected corners by straight chords, as a straight-edged
    # rasteriser of the unsplit polygon would, loses 37 % of its form factor here; Doi & Itoh
    # split such polygons into small triangles for that reason. The great-circle pixel tests
    # need no split: the row is within the pixel bound of the contour value.
    quad = square(0.5, 0.3, 0.3, 2.0, facing_up=False)
    patches = make_patches([square(0, 0, 0, 0.01), quad])
    eye = eye_of(patches)
    exact = lambert(eye, quad)
    u = (quad - eye) / np.linalg.norm(quad - eye, axis=1, keepdims=True)
    x, y = u[:, 0], u[:, 1]
    chords = abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))) / 2 / np.pi
    assert chords < CHORD_SHARE_MAX * exact
    row = nusselt_rows(patches, [0], resolution=128)[0]
    assert row[1] == pytest.approx(exact, abs=pixel_tolerance(eye, [quad], exact, 128))
