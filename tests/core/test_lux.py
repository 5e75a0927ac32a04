"""Illuminance in lux (core.lux): at arbitrary points after a bake, on EN 12464-1 grids, and at
every output corner. Oracles: the point light's inverse-square law, the corner-rectangle form
factor (Lambert), the white furnace (a closed room of uniform radiance), and the grid rule's
published table (EN 12464-1: 0.2 m for 1 m, 1 m for 10 m, 5 m for 100 m)."""

import numpy as np
import pytest

from builders import box_quads, centred_square
from core import BakeSettings, bake, make_lights, make_scene, relight, scene_from_polygons
from core import lux as L

LM = L.LUMENS_PER_WATT


def _floor(size=4.0, rho=0.5, **kw):
    s = size / 2
    V = np.array([[-s, -s, 0], [s, -s, 0], [s, s, 0], [-s, s, 0]], float)
    return scene_from_polygons(V, [[0, 1, 2, 3]], [0], reflectance=[[rho] * 3],
                               emission=[[0.0] * 3], **kw)


def _corner_rect(a, b, c):
    """Form factor from a point to an a x b rectangle parallel to it at distance c, the point
    under one corner (form_factors.md)."""
    A, B = a / c, b / c
    return (A / np.sqrt(1 + A * A) * np.arctan(B / np.sqrt(1 + A * A))
            + B / np.sqrt(1 + B * B) * np.arctan(A / np.sqrt(1 + B * B))) / (2 * np.pi)


def test_grid_spacing_follows_en_12464_1():
    # The standard's own examples (rounded there to 0.05 m) and its 10 m cap.
    for d, p in [(1.0, 0.2), (2.0, 0.3), (5.0, 0.6), (10.0, 1.0), (100.0, 5.0)]:
        assert L.grid_spacing(d) == pytest.approx(p, abs=0.03)
    assert L.grid_spacing(1e4) == L.MAX_SPACING
    with pytest.raises(ValueError, match="side"):
        L.grid_spacing(0.0)


def test_grid_of_a_work_plane_has_cell_centres_inside_only():
    # A 5 x 4 m plane: d = 5 m (ratio < 2), p = 0.616 m -> 9 x 7 cells, points at their centres.
    plane = np.array([[0, 0, 0.8], [5, 0, 0.8], [5, 4, 0.8], [0, 4, 0.8]], float)
    pts, nrm, w = L.calculation_grid([plane])
    assert pts.shape == (63, 3) and np.allclose(nrm, [0, 0, 1]) and np.allclose(pts[:, 2], 0.8)
    assert w.sum() == pytest.approx(20.0)
    assert pts[:, 0].min() == pytest.approx(5 / 18) and pts[:, 1].min() == pytest.approx(2 / 7)
    # An L-shaped n-gon (a 4 x 4 square less its 2 x 2 corner): no point in the missing corner,
    # and the kept cells add up to its 12 m^2 within one row of cells.
    ell = np.array([[0, 0, 0], [4, 0, 0], [4, 2, 0], [2, 2, 0], [2, 4, 0], [0, 4, 0]], float)
    pts, _, w = L.calculation_grid([ell])
    assert not np.any((pts[:, 0] > 2) & (pts[:, 1] > 2))
    assert abs(w.sum() - 12.0) <= 4 * np.sqrt(w[0]) + 1e-9
    # Two coplanar quads make one grid; a fixed spacing is honoured.
    halves = [plane[[0, 1, 2, 3]] * [0.5, 1, 1], plane * [0.5, 1, 1] + [2.5, 0, 0]]
    pts, _, w = L.calculation_grid(halves, spacing=0.5)
    assert pts.shape[0] == 80 and w.sum() == pytest.approx(20.0)


def test_summary_gives_en_figures():
    s = L.summary([100.0, 200.0, 300.0], [1.0, 1.0, 2.0])
    assert s == dict(points=3, Emin=100.0, Eavg=225.0, Emax=300.0, U0=pytest.approx(100 / 225))
    assert L.summary([0.0, 0.0])["U0"] == 0.0


@pytest.mark.parametrize("mode", ["mesh", "vertices"])
def test_point_light_grid_matches_the_inverse_square_law(mode):
    # A 1000 W white point light 2 m over a grey floor; a work plane at 0.8 m between them sees
    # only the light (the floor is below it): E = 683 x P / (4 pi) x cos / d^2 lx.
    pos = np.array([0.3, 0.2, 2.0])
    lights = make_lights([dict(kind="point", name="P", position=tuple(pos), power=1000.0)])
    result = bake(_floor(lights=lights), BakeSettings(output_mode=mode))
    plane = centred_square(0.0, 0.0, 0.8, 2.0)
    pts, nrm, w = L.calculation_grid([plane])
    d = pos - pts
    r2 = (d * d).sum(axis=1)
    want = LM * 1000.0 / (4 * np.pi) * d[:, 2] / np.sqrt(r2) / r2
    got = L.illuminance_at(result, pts, nrm)
    # The point is lifted 1e-6 of the scene's size off its plane: 1e-5 covers it.
    np.testing.assert_allclose(got, want, rtol=1e-5)
    # The floor's own corners carry the same law (at z = 0), independent of its reflectance;
    # their gather points sit inset by 1e-3 of the face's size (core.gather.INSET): 5.7 mm on
    # the 4 m quad's diagonal, 3.8 m from the light, moves E = h / r^3 by up to 3 x 5.7 / 3800.
    corners = result._state.scene.vertices[result._state.scene.corner_verts]
    d = pos - corners
    r2 = (d * d).sum(axis=1)
    want = LM * 1000.0 / (4 * np.pi) * d[:, 2] / np.sqrt(r2) / r2
    np.testing.assert_allclose(L.lux(result.corner_incident), want, rtol=5e-3)
    if mode == "mesh":
        out = result.output
        d = pos - out.vertices[out.corner_verts]
        r2 = (d * d).sum(axis=1)
        want = LM * 1000.0 / (4 * np.pi) * d[:, 2] / np.sqrt(r2) / r2
        np.testing.assert_allclose(L.lux(out.corner_incident), want, rtol=5e-3)


@pytest.mark.parametrize("exact, rtol", [("all", 2e-3), ("off", 0.03)])
def test_area_light_matches_the_rectangle_form_factor(exact, rtol):
    # A 1 x 1 m panel of radiance 10 facing down 1.5 m over a black floor: the plane at 0.5 m
    # reads E = pi x 10 x F(point -> panel), F by the corner-rectangle closed form (4 corners).
    # Tolerance: exact emitters integrate the panel exactly but sample its visibility; the
    # hemicube at R = 64 is a pixel sum, 2 % at the worst of 36 points here.
    panel = centred_square(0.0, 0.0, 1.5, 1.0, facing_up=False)
    floor = centred_square(0.0, 0.0, 0.0, 4.0)
    V = np.concatenate([floor, panel])
    scene = scene_from_polygons(V, [[0, 1, 2, 3], [4, 5, 6, 7]], [0, 1],
                                reflectance=[[0.0] * 3, [0.0] * 3],
                                emission=[[0.0] * 3, [10.0] * 3])
    result = bake(scene, BakeSettings(exact_direct=exact))
    pts, nrm, _ = L.calculation_grid([centred_square(0.0, 0.0, 0.5, 1.6)])
    x0, x1 = -0.5 - pts[:, 0], 0.5 - pts[:, 0]
    y0, y1 = -0.5 - pts[:, 1], 0.5 - pts[:, 1]
    F = (_signed(x1, y1) - _signed(x0, y1) - _signed(x1, y0) + _signed(x0, y0))
    want = LM * np.pi * 10.0 * F
    np.testing.assert_allclose(L.illuminance_at(result, pts, nrm), want, rtol=rtol)


def _signed(x, y):
    """Corner-rectangle form factor of the rectangle [0, x] x [0, y] (signed by its sides)."""
    return np.sign(x) * np.sign(y) * _corner_rect(np.abs(x), np.abs(y), 1.0)


def test_points_in_a_white_furnace_read_emission_over_one_minus_rho():
    # A closed 3 x 2 x 2.5 m room whose every face emits Le and reflects rho: the radiance is
    # Le / (1 - rho) everywhere and in every direction, so any point facing any way reads
    # E = 683 x pi x Le / (1 - rho) lx (rows of a closed room sum to 1; tolerance the solve's).
    quads, _ = box_quads((3.0, 2.0, 2.5), 0.5)
    n = len(quads)
    V = quads.reshape(-1, 3)
    scene = make_scene(V, np.arange(4 * n), np.arange(0, 4 * n, 4), np.full(n, 4),
                       np.zeros(n, dtype=np.int64), [[0.6, 0.5, 0.4]], [[0.2, 0.2, 0.2]])
    result = bake(scene, BakeSettings(output_mode="vertices", tolerance=1e-9))
    rng = np.random.default_rng(3)
    pts = rng.uniform([0.3, 0.3, 0.3], [2.7, 1.7, 2.2], (40, 3))
    nrm = rng.normal(size=(40, 3))
    want = LM * np.pi * (np.array([0.2, 0.2, 0.2]) / (1 - np.array([0.6, 0.5, 0.4])))
    want = want @ np.array([0.2126, 0.7152, 0.0722])
    np.testing.assert_allclose(L.illuminance_at(result, pts, nrm), want, rtol=1e-4)


def test_bad_points_are_refused():
    lights = make_lights([dict(kind="point", name="P", position=(0, 0, 2), power=10.0)])
    result = bake(_floor(lights=lights))
    with pytest.raises(ValueError, match="normals"):
        L.illuminance_at(result, np.zeros((2, 3)), np.zeros((2, 3)))
    with pytest.raises(TypeError, match="BakeResult"):
        L.illuminance_at(object(), np.zeros((1, 3)), np.ones((1, 3)))
    with pytest.raises(ValueError, match="face"):
        L.calculation_grid([np.zeros((2, 3))])


@pytest.mark.parametrize("mode", ["mesh", "vertices"])
def test_relight_scales_lux_with_the_emission(mode):
    # Light is linear in the emission: a relight at 2.5 x the panel's radiance reads 2.5 x the
    # lux everywhere (corners and free points); rounding only.
    panel = centred_square(0.0, 0.0, 1.5, 1.0, facing_up=False)
    V = np.concatenate([centred_square(0.0, 0.0, 0.0, 4.0), panel])
    scene = scene_from_polygons(V, [[0, 1, 2, 3], [4, 5, 6, 7]], [0, 1],
                                reflectance=[[0.6] * 3, [0.2] * 3],
                                emission=[[0.0] * 3, [4.0] * 3])
    first = bake(scene, BakeSettings(output_mode=mode))
    again = relight(first, emission=[[0.0] * 3, [10.0] * 3])
    np.testing.assert_allclose(L.lux(again.corner_incident), 2.5 * L.lux(first.corner_incident),
                               rtol=1e-9, atol=1e-9)
    pts, nrm, _ = L.calculation_grid([centred_square(0.0, 0.0, 0.7, 2.0)])
    np.testing.assert_allclose(L.illuminance_at(again, pts, nrm),
                               2.5 * L.illuminance_at(first, pts, nrm), rtol=1e-9)
