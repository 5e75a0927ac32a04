"""Relight after a change of power or colour only (core.recolour, core.shadow_memo; issue 12).

Oracles: a fresh bake of the scene with the new lights (the recolour must give what casting them
again gives, with no shadow ray), and superposition (the solve is linear in the lights: the
lights relit one at a time add up to the bake, on the same radiosity mesh).
"""

import dataclasses

import numpy as np
import pytest

from core import emitters as emitters_module
from core import lights as lights_module
from core.bake import bake, relight
from core.light_list import make_lights
from core.settings import BakeSettings
from core.shadow_memo import PointTable, ShadowMemo, point_keys

from test_emitters import _room

#: A soft bulb (shadow rays over its disk: penumbrae of the box), a spot and a sun (outside the
#: closed room: its rays all end on the roof, so it is dark inside but cast).
BULB = dict(kind="point", name="Bulb", position=(2.6, 1.2, 2.4), power=150.0, radius=0.2)
SPOT = dict(kind="spot", name="Spot", position=(1.0, 3.0, 2.6), power=200.0,
            direction=(0.3, -0.4, -1.0), spot_size=1.2, spot_blend=0.3)
SUN = dict(kind="sun", name="Sun", direction=(0.4, 0.1, 1.0), strength=2.0)


def _scene(lights, lamp=1.0):
    """The 4 x 4 x 3 m room of test_emitters with a box under its 1 cm lamp (lit exactly), and
    ``lights``; the lamp's emission times ``lamp`` (3,)."""
    scene, _ = _room(0.01, walls_rho=0.5, box=True)
    emission = np.array(scene.emission) * np.array([[1.0] * 3, [1.0] * 3, np.broadcast_to(lamp, 3)])
    emission.setflags(write=False)
    return dataclasses.replace(scene, lights=make_lights(lights), emission=emission)


def test_new_power_and_colour_give_a_fresh_bake_without_a_shadow_ray():
    s = BakeSettings(output_mode="vertices", element_levels=0, exact_direct="all")
    first = [BULB, SPOT, SUN]
    new = [dict(BULB, power=420.0, color=(1.0, 0.6, 0.3)), dict(SPOT, power=50.0),
           dict(SUN, strength=5.0)]
    lamp = [0.5, 2.0, 1.0]
    base = bake(_scene(first), s)
    assert base.report["lights"]["shadow_rays"] > 0
    assert base.report["lights"]["exact_emitter_faces"] == 1
    fresh = bake(_scene(new, lamp), s)
    again = relight(base, lights=new, emission=np.array(_scene(new, lamp).emission))
    # Only the pairs the bake's culling skipped and the new powers no longer skip are cast.
    assert again.report["lights"]["shadow_rays"] < 0.01 * base.report["lights"]["shadow_rays"]
    np.testing.assert_allclose(again.corner_colours, fresh.corner_colours, rtol=1e-9,
                               atol=1e-15)
    assert not np.allclose(again.corner_colours, base.corner_colours, rtol=0.05)
    # A moved light is cast again (and still equals a fresh bake).
    moved = [dict(BULB, position=(2.0, 1.2, 2.4)), SPOT, SUN]
    recast = relight(base, lights=moved)
    assert recast.report["lights"]["shadow_rays"] > 0
    np.testing.assert_allclose(recast.corner_colours, bake(_scene(moved), s).corner_colours,
                               rtol=1e-9, atol=1e-15)


@pytest.mark.parametrize("shadow_cuts", [False, True])
def test_lights_relit_alone_add_up_to_the_bake_on_its_mesh(monkeypatch, shadow_cuts):
    # No culling (core.lights.CULL): a culled light casts one ray where the bake culled it,
    # not its penumbra's rounds, so the parts would add up only to within CULL. Direct solve
    # (few nodes): exact.
    # With the shadow lines a light at power 0 keeps the bake's lines (and patches): the light
    # groups' parts must share them to add up.
    monkeypatch.setattr(lights_module, "CULL", 0.0)
    s = BakeSettings(exact_direct="all", vertex_budget=1500, shadow_cuts=shadow_cuts)
    first = [BULB, SPOT]
    base = bake(_scene(first), s)
    assert base.report["solver"] == "direct"
    dark = [dict(BULB, power=0.0), dict(SPOT, power=0.0)]
    parts = [relight(base, lights=[BULB, dark[1]], emission=_scene(dark, [0.0] * 3).emission),
             relight(base, lights=[dark[0], SPOT], emission=_scene(dark, [0.0] * 3).emission),
             relight(base, lights=dark)]
    total = np.zeros_like(base.corner_colours)
    direct = np.zeros_like(base.corner_colours)
    for p in parts:
        assert p.report["lights"]["shadow_rays"] == 0
        assert not p.report["mesh"]["rebuilt"]
        np.testing.assert_array_equal(p.output.vertices, base.output.vertices)
        total += p.corner_colours
        direct += p.corner_incident
    np.testing.assert_allclose(total, base.corner_colours, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(direct, base.corner_incident, rtol=1e-9, atol=1e-12)
    # Each part carries its own light (measured: bulb 80 %, spot 9 %, lamp 3 % of the median).
    assert all(np.median(p.corner_incident) > 0.01 * np.median(base.corner_incident)
               for p in parts)


@pytest.mark.parametrize("keep", [True, False])
def test_a_relight_reads_the_emitters_contour_integrals_back(monkeypatch, keep):
    # The exact emitters' unshadowed light (contour integrals at the points, and the near
    # patches' means) depends on the geometry alone: a relight of the lamp's colour reads it
    # back from the bake and still equals a fresh bake. With no bytes to keep it (or counted
    # wrongly) it is integrated again, and the counter shows it.
    if not keep:
        monkeypatch.setattr(emitters_module, "KEEP_BYTES", 0)
    s = BakeSettings(output_mode="vertices", element_levels=0, exact_direct="all")
    base = bake(_scene([BULB]), s)
    calls = []
    for name in ("form_factors", "pair_form_factor"):
        def counted(*args, _f=getattr(emitters_module, name), _name=name):
            calls.append(_name)
            return _f(*args)
        monkeypatch.setattr(emitters_module, name, counted)
    lamp = [2.0, 1.0, 0.25]
    again = relight(base, emission=_scene([BULB], lamp).emission)
    if keep:
        assert calls.count("form_factors") == 0
    else:
        assert calls.count("form_factors") > 0
    assert calls.count("pair_form_factor") == 0      # the near means: kept for the patches
    np.testing.assert_allclose(again.corner_colours, bake(_scene([BULB], lamp), s).corner_colours,
                               rtol=1e-9, atol=1e-15)
    assert not np.allclose(again.corner_colours, base.corner_colours, rtol=0.02)


def test_memo_finds_what_it_kept_and_nothing_else():
    rng = np.random.default_rng(3)
    pts, nrm = rng.normal(size=(50, 3)), rng.normal(size=(50, 3))
    rows, keys = point_keys(pts, nrm, 16)
    memo = ShadowMemo(2)
    frac = rng.uniform(size=(50, 2))
    frac[::5, 1] = np.nan                                 # light 1 not cast at every 5th
    memo.add(rows, keys, 16, frac, frac > 0.5)
    at = memo.find(rows, keys, 16)
    np.testing.assert_array_equal(memo.frac[at], frac)
    np.testing.assert_array_equal(memo.clear[at][:, 0], frac[:, 0] > 0.5)
    # Another ray count, or a point one ulp away, is not found.
    assert np.all(memo.find(*point_keys(pts, nrm, 8), 8) == -1)
    moved = pts.copy()
    moved[:, 2] = np.nextafter(moved[:, 2], np.inf)
    assert np.all(memo.find(*point_keys(moved, nrm, 16), 16) == -1)
    # Pairs cast later fill the gaps; a full memo keeps nothing more.
    later = np.full((10, 2), np.nan)
    later[:, 1] = 0.25
    memo.update(at[::5], later, np.zeros((10, 2), dtype=bool))
    assert np.all(memo.frac[at[::5], 1] == 0.25)
    # Round coordinates (a grid of points on two walls) hash apart.
    grid = np.mgrid[0:20, 0:20, 0:20].reshape(3, -1).T * 0.25
    walls = [point_keys(grid, np.tile(n, (grid.shape[0], 1)), 16)[1] for n in np.eye(3)]
    assert np.unique(np.concatenate(walls)).size == 3 * grid.shape[0]
    small = ShadowMemo(2, budget=1000)
    small.add(rows, keys, 16, frac, frac > 0.5)
    assert small.full and np.all(small.find(rows, keys, 16) == -1)


def test_a_lazy_table_sorts_once_its_new_points_are_as_many_as_the_sorted():
    # A bake asks the emitters' table chunk after chunk of new points: a lazy find sorts the
    # points added since the last sort in only when they are as many as the sorted ones
    # (amortised), and the sort before a relight finds them all.
    rng = np.random.default_rng(5)
    pts, nrm = rng.normal(size=(30, 3)), rng.normal(size=(30, 3))
    rows, keys = point_keys(pts, nrm, 0)
    table = PointTable([(2, np.float64)], budget=1 << 20)
    values = rng.uniform(size=(30, 2))
    table.add(rows[:10], keys[:10], 0, values[:10])
    assert np.all(table.find(rows, keys, 0, lazy=True)[:10] >= 0)      # 10 new, 0 sorted
    table.add(rows[10:15], keys[10:15], 0, values[10:15])
    at = table.find(rows, keys, 0, lazy=True)
    assert np.all(at[:10] >= 0) and np.all(at[10:] == -1)                # 5 new, 10 sorted
    table.sort()
    at = table.find(rows, keys, 0, lazy=True)
    np.testing.assert_array_equal(table.values[0][at[:15]], values[:15])
    assert np.all(at[15:] == -1)


@pytest.mark.parametrize("field, value", [("position", [[2.0, 1.2, 2.4], [1.0, 3.0, 2.6]]),
                                          ("radius", [0.1, 0.0])])
def test_a_light_moved_or_resized_is_not_recoloured(field, value):
    scene = _scene([BULB, SPOT])
    base = bake(scene, BakeSettings(output_mode="vertices", element_levels=0))
    direct = base._state.direct
    other = dataclasses.replace(scene.lights, **{field: np.array(value)})
    assert direct.recoloured(other, direct.emitters) is None
    brighter = dataclasses.replace(scene.lights, intensity=3.0 * scene.lights.intensity)
    assert direct.recoloured(brighter, direct.emitters) is not None


def test_lights_that_move_the_shadow_lines_bake_again():
    # With shadow_cuts the patches are cut along each light's shadow lines from the box's feet:
    # a relight that keeps them after the bulb has moved keeps the old lines (up to 2.6 % off
    # a fresh bake). A change of power keeps the bake's lines and form factors, as it keeps its
    # elements; lights that move the lines bake again, and say so.
    s = BakeSettings(output_mode="vertices", element_levels=0, shadow_cuts=True)
    base = bake(_scene([BULB]), s)
    assert base.report["contacts"]["shadow_lines"] > 0
    brighter = [dict(BULB, power=300.0)]
    again = relight(base, lights=brighter)
    assert not any("baked again" in w for w in again.report.get("warnings", []))
    # A new solve of the same system: within the solver's tolerance of a fresh bake.
    np.testing.assert_allclose(again.corner_colours, bake(_scene(brighter), s).corner_colours,
                               rtol=2 * s.tolerance)
    moved = [dict(BULB, position=(1.2, 2.9, 2.4))]
    fresh = bake(_scene(moved), s)
    assert fresh.report["contacts"]["shadow_cuts"] != base.report["contacts"]["shadow_cuts"] \
        or len(fresh.patches.areas) != len(base.patches.areas)
    recast = relight(base, lights=moved)
    assert any("baked again" in w for w in recast.report["warnings"])
    np.testing.assert_array_equal(recast.patches.areas, fresh.patches.areas)
    np.testing.assert_allclose(recast.corner_colours, fresh.corner_colours, rtol=1e-9,
                               atol=1e-15)
