"""A sky that varies with direction (core.sky, issue 12): the CIE standard overcast sky gathered
through the hemicube's empty pixels, and the daylight factor.

Oracles: closed forms (an unobstructed horizontal plane receives E = 7 pi Lz / 9; the power the
sky puts on a closed shell), numerical quadrature written here (a vertical plane; a floor point
under a skylight: L cos over the opening's solid angle), invariances (a uniform sky through the
new path reproduces the uniform world's ``world x (1 - row sum)``; rotating the scene about Z
changes nothing; two worker processes give the bits of one) and the rasteriser's own pixel
coordinates for the pixel directions.
"""

import numpy as np
import pytest

from builders import centred_square, quad_patches
from core import BakeSettings, bake, parallel, relight, scene_from_polygons
from core import hemicube_chunk
from core.errors import SettingsError
from core.hemicube import hemicube_rows, point_rows
from core.hemicube_raster import pixel_coords
from core.lights import DirectLight
from core.lux import LUMENS_PER_WATT, daylight_factor, illuminance_at, lux, summary
from core.patches import make_patches
from core.sky import (CIEOvercast, Environment, Uniform, from_message, pixel_directions,
                      zenith_radiance)

E_OUT = 10_000.0                        # lx: the settings' default outdoor illuminance
LZ = zenith_radiance(E_OUT)             # W/(m^2 sr), white


def _midpoint_rtol(resolution):
    """The hemicube sums dF x L over pixel centres: a midpoint rule, whose error for a smooth
    integrand is O(1/R^2) (its own sum of dF is off by 0.54 / R^2 before normalising). 2 / R^2
    bounds it with room to spare; measured 4e-5 at R = 64 for the horizontal plane."""
    return 2.0 / resolution ** 2


def _cie(cos_zenith):
    """The CIE overcast sky's shape for Lz = 1, written here from its definition."""
    return np.where(cos_zenith >= 0, (1 + 2 * cos_zenith) / 3, 0.0)


def _sphere_quadrature(normal, n=400):
    """(1/pi) integral of L(d) max(0, d . normal) over the upper hemisphere, L the CIE sky with
    Lz = 1: Gauss-Legendre in cos(zenith) (exact for the polynomial part) x a uniform rule in
    azimuth (periodic, but the kink of max(0, cos) where the plane cuts the sky leaves
    ~1e-5 at n = 400), independent of the hemicube."""
    x, w = np.polynomial.legendre.leggauss(n)
    mu = 0.5 * (x + 1)                                     # cos(zenith) in (0, 1)
    wm = 0.5 * w
    phi = (np.arange(2 * n) + 0.5) * np.pi / n
    wp = np.pi / n
    s = np.sqrt(1 - mu ** 2)
    d = np.stack([s[:, None] * np.cos(phi), s[:, None] * np.sin(phi),
                  np.broadcast_to(mu[:, None], (n, 2 * n))], axis=-1)
    cos_n = np.maximum(d @ np.asarray(normal, float), 0.0)
    return float((_cie(d[..., 2]) * cos_n * wm[:, None] * wp).sum() / np.pi)


def _skylight_room(W=4.0, H=2.0, a=2.0, rho=0.0, turn=0.0, sky=None):
    """A black W x W x H room (inward normals) with an a x a opening in the middle of its
    ceiling, turned by ``turn`` radians about Z; the floor in four quads (a vertex at the
    centre)."""
    s, o = W / 2, a / 2
    v = [[-s, -s, 0], [s, -s, 0], [s, s, 0], [-s, s, 0],
         [-s, -s, H], [s, -s, H], [s, s, H], [-s, s, H],
         [-o, -o, H], [o, -o, H], [o, o, H], [-o, o, H],
         [0, -s, 0], [s, 0, 0], [0, s, 0], [-s, 0, 0], [0, 0, 0]]
    polys = [[0, 12, 16, 15], [12, 1, 13, 16], [16, 13, 2, 14], [15, 16, 14, 3],
             [0, 4, 5, 1], [1, 5, 6, 2], [2, 6, 7, 3], [3, 7, 4, 0],
             [5, 9, 8, 4], [6, 10, 9, 5], [7, 11, 10, 6], [4, 8, 11, 7]]
    c, sn = np.cos(turn), np.sin(turn)
    rot = np.array([[c, -sn, 0], [sn, c, 0], [0, 0, 1]])
    v = np.array(v, float) @ rot.T
    return scene_from_polygons(v, polys, [0] * len(polys), [[rho] * 3], [[0.0] * 3],
                               world=CIEOvercast(LZ) if sky is None else sky), rot


def _opening_quadrature(W=4.0, H=2.0, a=2.0, n=48):
    """Irradiance / pi at the floor's centre under the opening, Lz = 1: (1/pi) x integral over
    the opening of L(cos) cos_floor cos_opening / r^2 dA (Gauss-Legendre, both axes)."""
    x, w = np.polynomial.legendre.leggauss(n)
    X, Y = np.meshgrid(0.5 * a * x, 0.5 * a * x)
    wt = np.outer(w, w) * (0.5 * a) ** 2
    r2 = X ** 2 + Y ** 2 + H ** 2
    cos = H / np.sqrt(r2)
    return float((_cie(cos) * cos * cos / r2 * wt).sum() / np.pi)


def test_pixel_directions_are_the_rasterisers_pixel_centres():
    r = 16
    d = pixel_directions(r)
    j, i, w, face = pixel_coords(d[:, 0], d[:, 1], d[:, 2], None, 2.0 / r)
    # Buffer order: top R x R, then four R/2 x R sides, each row-major.
    starts = np.cumsum([0, r * r] + [r * r // 2] * 3)
    want_face = np.searchsorted(starts, np.arange(d.shape[0]), side="right") - 1
    local = np.arange(d.shape[0]) - starts[want_face]
    assert np.array_equal(face, want_face)
    np.testing.assert_allclose(j / w, local % r, atol=1e-9)
    np.testing.assert_allclose(i / w, local // r, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, rtol=1e-15)


@pytest.mark.parametrize("resolution", [16, 64])
def test_hemicube_gathers_the_open_sky_on_a_horizontal_and_a_vertical_plane(resolution):
    # One small patch far below: nothing in view above the horizon.
    far = quad_patches([centred_square(0, 0, -100.0, 1.0)])
    pts = np.zeros((3, 3))
    normals = np.array([[0, 0, 1.0], [1, 0, 0], [0, np.sqrt(0.5), np.sqrt(0.5)]])
    out = np.zeros((3, 3))
    point_rows(far, pts, normals, resolution=resolution, rotate=True, rng=1,
               sky=CIEOvercast(1.0), sky_out=out)
    # Horizontal: the closed form 7 / 9 (E = 7 pi Lz / 9); the others by quadrature.
    want = [7 / 9] + [_sphere_quadrature(n) for n in normals[1:]]
    assert want[1] == pytest.approx(1 / 6 + 4 / (9 * np.pi), rel=1e-5)    # quadrature checked
    np.testing.assert_allclose(out, np.repeat(np.array(want)[:, None], 3, axis=1),
                               rtol=_midpoint_rtol(resolution))


class _AnyDirection(CIEOvercast):
    """The CIE sky through the general path (per empty pixel, float64, radiance(directions))."""

    above_horizon = None


def test_the_above_horizon_shortcut_is_the_general_path():
    # The float32 dense shortcut against the float64 per-pixel sums, on a room whose hemicubes
    # see the sky partly, on every face of the cube and across the horizon (walls, back sides).
    scene, _ = _skylight_room()
    patches = make_patches(scene, 0.5)
    nodes = np.arange(2 * patches.areas.size)
    fast, general = np.zeros((nodes.size, 3)), np.zeros((nodes.size, 3))
    rows = hemicube_rows(patches, nodes, resolution=32, rotate=True, rng=2,
                         sky=CIEOvercast([1.0, 2.0, 3.0]), sky_out=fast)
    same = hemicube_rows(patches, nodes, resolution=32, rotate=True, rng=2,
                         sky=_AnyDirection([1.0, 2.0, 3.0]), sky_out=general)
    plain = hemicube_rows(patches, nodes, resolution=32, rotate=True, rng=2)
    assert np.array_equal(rows, same) and np.array_equal(rows, plain)   # rows: sky or not
    assert general.max() > 0.5 and (general == 0).any()
    # float32 per pixel (relative 6e-8) summed over at most 3 R^2 pixels: 1e-6 of the sky.
    np.testing.assert_allclose(fast, general, rtol=0, atol=1e-6 * 3.0)


def test_unobstructed_black_floor_receives_the_outdoor_illuminance():
    # sky='cie_overcast' replaces the scene's world (here a bright uniform one).
    v = np.array([[-2, -2, 0], [2, -2, 0], [2, 2, 0], [-2, 2, 0]], float)
    floor = scene_from_polygons(v, [[0, 1, 2, 3]], [0], [[0.0] * 3], [[0.0] * 3],
                                world=[5.0, 5.0, 5.0])
    result = bake(floor, BakeSettings(sky="cie_overcast", output_mode="vertices"))
    got = illuminance_at(result, [[0.3, -0.7, 0.0]], [[0, 0, 1.0]])
    assert got[0] == pytest.approx(E_OUT, rel=_midpoint_rtol(64))
    assert lux(result.corner_incident) == pytest.approx(np.full(4, E_OUT),
                                                        rel=_midpoint_rtol(64))
    assert result.report["sky"] == dict(kind="cie_overcast", outdoor_lux=pytest.approx(E_OUT))
    # Facing down, the floor sees below the horizon: no sky (the ground is not modelled).
    assert illuminance_at(result, [[0.0, 0.0, -0.1]], [[0, 0, -1.0]])[0] == 0.0


def test_vertical_wall_receives_the_quadrature_at_every_azimuth():
    v = np.array([[0, -1, 0], [0, 1, 0], [0, 1, 2], [0, -1, 2]], float)    # faces +x
    # A sky given as the scene's world (core API), with the default sky='world'.
    wall = scene_from_polygons(v, [[0, 1, 2, 3]], [0], [[0.0] * 3], [[0.0] * 3],
                               world=CIEOvercast(LZ))
    result = bake(wall, BakeSettings(output_mode="vertices"))
    want = E_OUT * _sphere_quadrature([1, 0, 0]) / (7 / 9)
    for angle in (0.0, 0.4, 2.0):
        n = [np.cos(angle), np.sin(angle), 0.0]
        # Off the wall's own plane by 1 m (so that it does not hide half the sky for angle > 0).
        p = [2 * np.cos(angle), 2 * np.sin(angle), 1.0] if angle else [0.0, 0.0, 1.0]
        assert illuminance_at(result, [p], [n])[0] == pytest.approx(want,
                                                                    rel=_midpoint_rtol(64))


@pytest.mark.parametrize("mode", ["vertices", "mesh"])
def test_floor_under_a_skylight_matches_the_quadrature_over_the_opening(mode):
    scene, _ = _skylight_room()
    result = bake(scene, BakeSettings(sky="cie_overcast", output_mode=mode))
    want = E_OUT * _opening_quadrature() / (7 / 9)
    # The opening's outline is quantised by the pixels: at R = 64 it is 32 px wide (area about
    # 1000 px, outline 128 px), and the rotated hemicubes leave an error of a few px: 2 %.
    got = illuminance_at(result, [[0.0, 0.0, 0.0]], [[0, 0, 1.0]])[0]
    assert got == pytest.approx(want, rel=0.02)
    # The floor's centre corner (the bake's own gather) agrees, and the daylight factor too.
    centre = np.flatnonzero(scene.corner_verts == 16)
    corner = lux(result.corner_incident[centre])
    assert corner == pytest.approx(np.full(centre.size, want), rel=0.02)
    df = summary(corner, outdoor=result.report["sky"]["outdoor_lux"])
    assert df["DFavg"] == pytest.approx(100 * want / E_OUT, rel=0.02)
    assert daylight_factor(want, E_OUT) == pytest.approx(100 * want / E_OUT)


def test_relight_keeps_the_sky():
    """Relight re-shades the kept rows and their sky light: the same reflectance gives the same
    bake, and black walls give the floor the sky through the opening alone (the quadrature)."""
    grey, _ = _skylight_room(rho=0.5)
    result = bake(grey, BakeSettings(sky="cie_overcast", output_mode="vertices"))
    again = relight(result, reflectance=[[0.5] * 3])
    np.testing.assert_allclose(again.corner_colours, result.corner_colours, rtol=1e-12,
                               atol=1e-15)
    black = relight(result, reflectance=[[0.0] * 3])
    centre = illuminance_at(black, [[0.0, 0.0, 0.0]], [[0, 0, 1.0]])[0]
    assert centre == pytest.approx(E_OUT * _opening_quadrature() / (7 / 9), rel=0.02)
    assert illuminance_at(result, [[0.0, 0.0, 0.0]], [[0, 0, 1.0]])[0] > 1.05 * centre


def test_the_sky_puts_its_closed_form_power_on_a_black_shell():
    """Energy: the room's inside receives the opening's share, its outside the unobstructed
    roof (W^2 in all, with the opening) and four walls; the floor's underside nothing. All of
    it is absorbed (black), nothing escapes."""
    W, H = 4.0, 2.0
    scene, _ = _skylight_room(W, H)
    result = bake(scene, BakeSettings(sky="cie_overcast", output_mode="vertices"))
    horizontal = 7 * np.pi / 9 * LZ                                  # W/m^2 per channel
    vertical = np.pi * _sphere_quadrature([1, 0, 0]) * LZ
    want = 3 * (W * W * horizontal + 4 * W * H * vertical)           # RGB summed, W
    e = result.report["energy"]
    # Every node's sky is a hemicube midpoint sum (2 / R^2), and the opening's outline is
    # quantised (its share, a tenth of the total, within 2 %): 0.5 % in all.
    assert e["emitted"] == pytest.approx(want, rel=5e-3)
    assert e["absorbed"] == pytest.approx(e["emitted"], rel=1e-12) and e["escaped"] == 0.0
    # Grey walls: reflected light escapes through the opening; the balance still closes
    # within the hemicube's reciprocity error, as with a uniform world.
    grey, _ = _skylight_room(W, H, rho=0.5)
    e = bake(grey, BakeSettings(sky="cie_overcast", output_mode="vertices")).report["energy"]
    assert e["escaped"] > 0 and abs(e["balance"]) < 0.02 * e["emitted"]


@pytest.mark.parametrize("mode", ["vertices", "mesh"])
def test_a_uniform_sky_through_the_pixels_is_the_uniform_world(mode):
    """The new path with a constant L reproduces ``world x (1 - row sum)``: the empty pixels'
    delta form factors sum to 1 - row sum up to rounding."""
    world = np.array([0.2, 0.3, 0.5])
    old, _ = _skylight_room(rho=0.5, sky=world)
    new, _ = _skylight_room(rho=0.5, sky=Uniform(world))
    settings = BakeSettings(output_mode=mode, workers=1)
    a, b = bake(old, settings), bake(new, settings)
    np.testing.assert_allclose(b.corner_colours, a.corner_colours, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(b.node_radiance, a.node_radiance, rtol=1e-12, atol=1e-15)
    p, n = [[0.5, 0.2, 0.0], [1.9, 0.0, 1.0]], [[0, 0, 1.0], [-1.0, 0, 0]]
    np.testing.assert_allclose(illuminance_at(b, p, n), illuminance_at(a, p, n), rtol=1e-12)


def test_turning_the_scene_about_z_leaves_the_floor_unchanged():
    """The CIE sky depends on the zenith angle only, and the hemicubes turn with the patches
    (their x axis follows each patch's first edge): turned by 90 degrees, the scene's
    coordinates are exact and only the eye frames' rounding differs; by 0.5 rad the patches'
    pixel sampling of the opening changes within its quantisation (2 %, see above)."""
    pts = np.array([[0.0, 0.0, 0.0], [0.8, -0.5, 0.0], [-1.5, 1.2, 0.0]])
    up = np.tile([0.0, 0.0, 1.0], (3, 1))
    scene, _ = _skylight_room()
    base = illuminance_at(bake(scene, BakeSettings(sky="cie_overcast", output_mode="vertices")),
                          pts, up)
    for turn, rtol in ((np.pi / 2, 1e-6), (0.5, 0.02)):
        turned, rot = _skylight_room(turn=turn)
        result = bake(turned, BakeSettings(sky="cie_overcast", output_mode="vertices"))
        np.testing.assert_allclose(illuminance_at(result, pts @ rot.T, up), base, rtol=rtol)


def test_sky_light_does_not_depend_on_the_chunks_or_the_processes(monkeypatch):
    scene, _ = _skylight_room()
    patches = make_patches(scene, 0.5)
    pts = np.random.default_rng(3).uniform([-1.9, -1.9, 0.0], [1.9, 1.9, 0.0], (40, 3))
    up = np.tile([0.0, 0.0, 1.0], (40, 1))
    sky = CIEOvercast(LZ)

    def run():
        out = np.zeros((40, 3))
        rows = point_rows(patches, pts, up, resolution=32, rotate=True, rng=5, sky=sky,
                          sky_out=out)
        return rows, out
    rows, light = run()
    assert light.min() > 0
    for pairs, pixels in ((1, 1), (10**9, 10**9)):
        monkeypatch.setattr(hemicube_chunk, "_CHUNK_PAIRS", pairs)
        monkeypatch.setattr(hemicube_chunk, "_CHUNK_PIXELS", pixels)
        r, s = run()
        assert np.array_equal(r, rows) and np.array_equal(s, light)
    parallel.close()
    try:
        with parallel.using(2) as stats:
            r, s = run()
        assert stats["calls"] == 1 and stats["problem"] is None
        assert np.array_equal(r, rows) and np.array_equal(s, light)
    finally:
        parallel.close()


def test_a_bake_on_two_workers_gives_the_bits_of_one_process():
    scene, _ = _skylight_room(rho=0.5)
    parallel.close()
    try:
        one, two = (bake(scene, BakeSettings(sky="cie_overcast", workers=w, vertex_budget=2000))
                    for w in (1, 2))
    finally:
        parallel.close()
    assert two.report["workers"]["shared_calls"] > 0
    assert "problem" not in two.report["workers"]
    for a, b in ((one.corner_colours, two.corner_colours), (one.node_radiance, two.node_radiance),
                 (one.output.corner_colours, two.output.corner_colours),
                 (one.output.corner_incident, two.output.corner_incident)):
        assert np.array_equal(a, b)


def test_zenith_radiance_follows_the_lux_convention():
    # 9 E / (7 pi 683): white, so its luminance is itself (Rec. 709 weights sum to 1).
    assert LZ == pytest.approx(9 * E_OUT / (7 * np.pi * LUMENS_PER_WATT), rel=1e-15)
    assert lux([CIEOvercast(LZ).horizontal()])[0] == pytest.approx(E_OUT, rel=1e-12)
    sky = from_message(CIEOvercast([1.0, 2.0, 3.0]).message())
    d = np.array([[0, 0, 1.0], [1, 0, 0], [0.6, 0, -0.8]])
    np.testing.assert_allclose(sky.radiance(d), [[1, 2, 3], [1 / 3, 2 / 3, 1], [0, 0, 0]])


def test_settings_and_arguments_that_cannot_carry_a_sky_are_named():
    with pytest.raises(SettingsError, match="method='exact'"):
        BakeSettings(sky="cie_overcast", method="exact")
    with pytest.raises(SettingsError, match="sky_illuminance"):
        BakeSettings(sky="cie_overcast", sky_illuminance=0.0)
    with pytest.raises(SettingsError, match="sky must be one of"):
        BakeSettings(sky="clear")
    far = quad_patches([centred_square(0, 0, -1.0, 1.0)])
    with pytest.raises(ValueError, match=r"sky_out must be a float64 array of shape \(1, 3\)"):
        point_rows(far, [[0, 0, 0.0]], [[0, 0, 1.0]], sky=CIEOvercast(1.0),
                   sky_out=np.zeros((2, 3)))
    with pytest.raises(ValueError, match="zenith_radiance must be 3 finite"):
        CIEOvercast([1.0, -1.0, 0.0])
    with pytest.raises(ValueError, match="illuminance must be"):
        zenith_radiance(-5.0)
    light = DirectLight(None, far, world=CIEOvercast(1.0))
    with pytest.raises(ValueError, match="directional sky needs"):
        light.extra(np.zeros((1, 3)), np.array([[0, 0, 1.0]]), np.zeros(1))


def _texel_means(f, h=32, k=16):
    """(h, 2h, 3): the equirectangular texel means of f(directions) -> (n,) by a k x k rule per
    texel weighted by solid angle (the layout core.sky.Environment documents)."""
    w = 2 * h
    rows = (np.arange(h * k) + 0.5) / (h * k)
    cols = (np.arange(w * k) + 0.5) / (w * k)
    el, lo = np.meshgrid((0.5 - rows) * np.pi, (0.5 - cols) * 2 * np.pi, indexing="ij")
    d = np.stack([np.cos(el) * np.cos(lo), np.cos(el) * np.sin(lo), np.sin(el)], axis=-1)
    wt = np.cos(el)
    v = f(d.reshape(-1, 3)).reshape(el.shape) * wt
    m = v.reshape(h, k, w, k).sum(axis=(1, 3)) / wt.reshape(h, k, w, k).sum(axis=(1, 3))
    return np.repeat(m[..., None], 3, axis=2)


def test_an_environment_map_of_the_cie_sky_lights_a_skylit_floor_like_the_cie_sky():
    """A world that Blender textures reaches the bake as a map (core.sky.Environment). The map
    of the CIE sky, made here by quadrature, lights the floor under a skylight like the CIE sky
    itself: the map's orientation (+Z up) and its lookup, against the closed-form sky."""
    env = Environment(_texel_means(lambda d: _cie(d[:, 2]) * LZ))
    # Horizontal irradiance from the texels' bands: 7/9 Lz, up to each texel's mean being
    # weighted by solid angle where the plane weights its band by cos(zenith) too (O(band^2);
    # measured -9e-4).
    assert env.horizontal() == pytest.approx(np.full(3, LZ * 7 / 9), rel=2e-3)
    scene, _ = _skylight_room(sky=env)
    cie, _ = _skylight_room()
    s = BakeSettings(output_mode="vertices", rotate_hemicube=False)
    got = illuminance_at(bake(scene, s), [[0.0, 0.0, 0.0], [1.5, 0.5, 0.0]], [[0, 0, 1.0]] * 2)
    want = illuminance_at(bake(cie, s), [[0.0, 0.0, 0.0], [1.5, 0.5, 0.0]], [[0, 0, 1.0]] * 2)
    # Bilinear lookup between 5.6 degree texel centres of a smooth sky (measured -0.13 %).
    np.testing.assert_allclose(got, want, rtol=5e-3)


def test_an_environment_map_is_oriented_as_documented():
    """Bright where x > 0, black elsewhere: an unobstructed plane facing +X sees it all (E / pi
    = 1), facing -X nothing but the texels blurred across the seam, facing +Y half."""
    env = Environment(_texel_means(lambda d: (d[:, 0] > 0).astype(float)))
    far = quad_patches([centred_square(0, 0, -100.0, 1.0)])
    normals = np.array([[1.0, 0, 0], [-1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]])
    out = np.zeros((4, 3))
    point_rows(far, np.zeros((4, 3)), normals, resolution=64, sky=env, sky_out=out)
    # The seam (x = 0) falls on texel edges; bilinear reads blur it over half a texel (2.8
    # degrees), where a plane facing +-X has cos < 0.05 (measured 2e-4).
    np.testing.assert_allclose(out[:, 0], [1.0, 0.0, 0.5, 0.5], atol=1e-3)
    assert env.radiance(np.array([[1.0, 0, 0], [-1.0, 0, 0]]))[:, 0] == pytest.approx([1, 0])


def test_an_environment_map_crosses_to_the_workers_and_is_checked():
    env = Environment(np.random.default_rng(0).random((4, 8, 3)))
    back = from_message(env.message())
    d = np.random.default_rng(1).normal(size=(50, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    assert np.array_equal(back.radiance(d), env.radiance(d))
    with pytest.raises(ValueError, match=r"\(H, 2H, 3\)"):
        Environment(np.ones((4, 4, 3)))
    with pytest.raises(ValueError, match="finite"):
        Environment(np.full((2, 4, 3), -1.0))
