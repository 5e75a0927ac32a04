"""Radiance harness against closed forms and against the Cycles harness (needs pyradiance)."""

import numpy as np
import pytest

pytest.importorskip("pyradiance")

from bench.compare import radiance  # noqa: E402


def _corner_ff(a, b, c):
    """Point to parallel rectangle with a corner above the point (Howell; form_factors.md)."""
    A, B = a / c, b / c
    return (A / np.sqrt(1 + A * A) * np.arctan(B / np.sqrt(1 + A * A))
            + B / np.sqrt(1 + B * B) * np.arctan(A / np.sqrt(1 + B * B))) / (2 * np.pi)


def _panel(z, facing_down, L):
    quad = [0, 3, 2, 1] if facing_down else [0, 1, 2, 3]
    return dict(vertices=[(0, 0, z), (1, 0, z), (1, 1, z), (0, 1, z)], corner_verts=quad,
                face_starts=[0], face_sizes=[4], face_materials=[0],
                reflectance=[[0.0, 0.0, 0.0]], emission=[[L, 0.5 * L, 0.25 * L]])


def test_irradiance_under_uniform_square_emitter():
    # Sensor 1 m below the centre of a 1 m square of radiance L: E = pi L F, F = 4 F_corner(.5, .5, 1).
    L = 2.0
    E, seconds = radiance.irradiance(_panel(1.0, True, L), [(0.5, 0.5, 0.0)] * 40,
                                     [(0, 0, 1)] * 40, two_sided_lights=False, emitter="light")
    expected = np.pi * np.array([L, 0.5 * L, 0.25 * L]) * 4 * _corner_ff(0.5, 0.5, 1.0)
    # 0.5 %: jittered source sampling has ~0.5 % noise per sensor; 40 sensors average it to ~0.1 %.
    np.testing.assert_allclose(E.mean(axis=0), expected, rtol=5e-3)
    assert seconds > 0


def test_lights_emit_from_both_sides_only_when_asked():
    # The panel faces UP, away from the sensor: a Radiance light is one-sided, so the sensor sees
    # nothing unless the reversed polygon is added (which matches Cycles' two-sided mesh lights).
    arrays = _panel(1.0, False, 1.0)
    one, _ = radiance.irradiance(arrays, [(0.5, 0.5, 0.0)], [(0, 0, 1)], two_sided_lights=False,
                                 emitter="light")
    two, _ = radiance.irradiance(arrays, [(0.5, 0.5, 0.0)] * 20, [(0, 0, 1)] * 20,
                                 emitter="light")
    assert np.all(one == 0.0)
    np.testing.assert_allclose(two.mean(axis=0), np.pi * np.array([1, .5, .25])
                               * 4 * _corner_ff(0.5, 0.5, 1.0), rtol=5e-3)
    assert radiance.to_rad(arrays).count("polygon") == 2
    # As glow (emitters found by ambient rays only) the reversed copy matters in the same way.
    glow_one, _ = radiance.irradiance(arrays, [(0.5, 0.5, 0.0)], [(0, 0, 1)],
                                      two_sided_lights=False, emitter="glow")
    assert np.all(glow_one == 0.0)
    assert radiance.to_rad(arrays, two_sided_lights=False).count("polygon") == 1


def _room():
    """2 m cube room (normals inward, rho 0.6), floor split 4 x 4, a 0.5 m panel at z = 1.9
    facing up (it lights the room from its back face only)."""
    g = np.linspace(0, 2, 5)
    floor_v = [(x, y, 0.0) for y in g for x in g]
    V = floor_v + [(x, y, 2.0) for y in (0, 2) for x in (0, 2)]
    quads = [[j * 5 + i, j * 5 + i + 1, (j + 1) * 5 + i + 1, (j + 1) * 5 + i]
             for j in range(4) for i in range(4)]
    c = {(x, y, z): k for k, (x, y, z) in enumerate(V)}
    ids = lambda pts: [c[p] for p in pts]  # noqa: E731
    quads += [ids([(0, 0, 2.0), (0, 2, 2.0), (2, 2, 2.0), (2, 0, 2.0)]),      # ceiling, down
              ids([(0, 0, 0.0), (2, 0, 0.0), (2, 0, 2.0), (0, 0, 2.0)]),      # y = 0, +y
              ids([(2, 2, 0.0), (0, 2, 0.0), (0, 2, 2.0), (2, 2, 2.0)]),      # y = 2, -y
              ids([(0, 2, 0.0), (0, 0, 0.0), (0, 0, 2.0), (0, 2, 2.0)]),      # x = 0, +x
              ids([(2, 0, 0.0), (2, 2, 0.0), (2, 2, 2.0), (2, 0, 2.0)])]      # x = 2, -x
    n = len(V)
    V += [(0.75, 0.75, 1.9), (1.25, 0.75, 1.9), (1.25, 1.25, 1.9), (0.75, 1.25, 1.9)]
    quads.append([n, n + 1, n + 2, n + 3])
    F = len(quads)
    return dict(vertices=np.array(V, float), corner_verts=np.concatenate(quads),
                face_starts=np.arange(F) * 4, face_sizes=np.full(F, 4),
                face_materials=np.array([0] * (F - 1) + [1]),
                reflectance=np.array([[0.6, 0.5, 0.4], [0.0, 0.0, 0.0]]),
                emission=np.array([[0.0] * 3, [5.0] * 3]),
                face_objects=np.array([0] * 16 + [1] * 5 + [2]),
                object_names=("floor", "walls", "panel"), material_names=("wall", "panel"))


def test_glow_near_a_panel_matches_the_closed_form():
    # Ceiling point 0.1 m above the centre of a 0.5 m panel (radiance 5, facing up): E = pi L F
    # with F = 4 F_corner(0.25, 0.25, 0.1) = 0.885. As 'light', Radiance read 5.5 % low here.
    arrays = _room()
    E, _ = radiance.irradiance(arrays, [(1.0, 1.0, 2.0)] * 4, [(0, 0, -1)] * 4, nproc=2)
    direct = np.pi * 5.0 * 4 * _corner_ff(0.25, 0.25, 0.1)
    # Plus interreflection from the rest of the room, which is < 1 % of the direct part here
    # (the panel covers 88 % of the hemisphere): 1.5 % band above, 0.5 % noise below.
    assert direct * 0.995 < E[:, 0].mean() < direct * 1.015


def test_radiance_agrees_with_cycles_in_a_closed_room():
    # Two independent programs on a room with interreflection (rho 0.6 / 0.5 / 0.4 by channel).
    bpy = pytest.importorskip("bpy")
    from bench.compare import cycles

    arrays = _room()
    sensors = np.array([6, 8, 12, 16, 18])           # interior floor vertices (x, y in {.5, 1, 1.5})
    E_rad, _ = radiance.irradiance(arrays, arrays["vertices"][sensors], [(0, 0, 1)] * 5, nproc=2)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    try:
        sc = cycles.build(arrays)
        cc = sum(cycles.bake(sc, samples=4096, seed=s)[0] for s in (0, 1)) / 2
    finally:
        bpy.ops.wm.read_factory_settings(use_empty=True)
    # Floor corners -> vertex values (floor is object 0: its corners come first in corner order).
    floor_corners = np.arange(64)
    L = np.zeros((25, 3))
    cnt = np.zeros(25)
    np.add.at(L, arrays["corner_verts"][floor_corners], cc[floor_corners])
    np.add.at(cnt, arrays["corner_verts"][floor_corners], 1)
    E_cyc = np.pi * (L[sensors] / cnt[sensors, None]) / arrays["reflectance"][0]
    # Measured noise: Cycles 4096 samples ~2 % per vertex (a vertex's corners share one sample
    # pattern), two seeds ~1.5 %; Radiance -ad 8192 ~0.3 %. The sum of five sensors: 3 %.
    np.testing.assert_allclose(E_cyc.sum(axis=0), E_rad.sum(axis=0), rtol=0.03)
    np.testing.assert_allclose(E_cyc, E_rad, rtol=0.06)


@pytest.mark.parametrize("kw, match", [
    (dict(points=np.zeros((2, 2)), normals=np.zeros((2, 2))), "points"),
    (dict(points=np.zeros((2, 3)), normals=np.zeros((3, 3))), "normals"),
    (dict(points=np.zeros((1, 3)), normals=np.zeros((1, 3))), "non-zero"),
])
def test_irradiance_rejects_bad_sensors(kw, match):
    with pytest.raises(ValueError, match=match):
        radiance.irradiance(_panel(1.0, True, 1.0), **kw)
