"""Several relights of one bake solved on one matrix (core.groups.relight_many; issue 12).

Oracles: core.relight of each change on its own (the same light, bit for bit when a change is
alone; to the solver's tolerance when several share the sweeps), and superposition (the solve
is linear in the light: the groups relit apart add up to the bake).
"""

import numpy as np
import pytest

from core import lights as lights_module
from core.bake import bake, relight
from core.groups import relight_many
from core.settings import BakeSettings

from test_recolour import BULB, SPOT, _scene

#: The solver's tolerance here (relative change of a sweep). Changes solved together are swept
#: until every one is converged, so each is at least as converged as alone: they agree with
#: core.relight to the error a converged sweep leaves, tol x rho / (1 - rho) (rho <= 0.5 here,
#: so about tol), with a margin of 10.
TOL = 1e-6
AGREE = 10 * TOL


def _dark(scene):
    return np.zeros_like(np.asarray(scene.emission))


@pytest.fixture(scope="module")
def baked():
    # Gauss-Seidel (the solver past AUTO_DIRECT_MAX_NODES), on the radiosity mesh: a bulb, a
    # spot and an exactly lit lamp.
    s = BakeSettings(exact_direct="all", vertex_budget=1500, solver="gauss_seidel",
                     tolerance=TOL)
    scene = _scene([BULB, SPOT])
    return scene, bake(scene, s)


def test_one_change_is_core_relight_bit_for_bit(baked):
    scene, base = baked
    change = dict(emission=_scene([BULB, SPOT], [2.0, 1.0, 0.5]).emission,
                  lights=[dict(BULB, power=40.0), SPOT])
    [many] = relight_many(base, [change])
    one = relight(base, **change)
    np.testing.assert_array_equal(many.corner_colours, one.corner_colours)
    np.testing.assert_array_equal(many.output.corner_colours, one.output.corner_colours)
    np.testing.assert_array_equal(many.node_radiance, one.node_radiance)
    assert "shared_solve" not in many.report


def test_groups_solved_together_equal_their_relights_and_add_up(baked, monkeypatch):
    # No light culling (core.lights.CULL): a light culled where it is weak casts one ray there,
    # so lights relit alone add up to the bake only to within CULL (test_recolour).
    monkeypatch.setattr(lights_module, "CULL", 0.0)
    scene, _ = baked
    s = BakeSettings(exact_direct="all", vertex_budget=1500, solver="gauss_seidel",
                     tolerance=TOL)
    base = bake(scene, s)
    dark = [dict(BULB, power=0.0), dict(SPOT, power=0.0)]
    changes = [dict(emission=_dark(scene), lights=[BULB, dark[1]]),       # the bulb alone
               dict(emission=_dark(scene), lights=[dark[0], SPOT]),       # the spot alone
               dict(lights=dark),                                         # the lamp alone
               dict(reflectance=np.asarray(scene.reflectance) * 0.5)]     # another matrix
    many = relight_many(base, changes)
    for res, change in zip(many, changes):
        one = relight(base, **change)
        assert res.report["iterations"] >= one.report["iterations"]
        err = np.abs(res.corner_colours - one.corner_colours).max()
        assert err <= AGREE * np.abs(one.corner_colours).max(), err
        np.testing.assert_array_equal(res.output.vertices, base.output.vertices)
    assert [m.report.get("shared_solve", {}).get("relights") for m in many] == [3, 3, 3, None]
    # Superposition: the three lights apart are the bake.
    total = sum(m.corner_colours for m in many[:3])
    err = np.abs(total - base.corner_colours).max()
    assert err <= AGREE * np.abs(base.corner_colours).max(), err
    # Each part carries light of its own (not one part and two copies of the dark).
    assert all(np.median(m.corner_incident) > 0.01 * np.median(base.corner_incident)
               for m in many[:3])


def test_a_wrong_change_is_named_before_any_work(baked):
    _, base = baked
    with pytest.raises(TypeError, match="unknown change 'emmision'"):
        relight_many(base, [dict(emission=None), dict(emmision=np.zeros((3, 3)))])
    with pytest.raises(ValueError, match="emission must have shape"):
        relight_many(base, [dict(emission=np.zeros((2, 3)))])


@pytest.mark.parametrize("solver", ["gauss_seidel", "direct"])
def test_the_progress_bar_of_relights_together_only_moves_on(baked, solver):
    # Every relight's lights and form factors run first, then the shared solve (one per
    # emission with the direct solver), then every relight's colours: each phase is split
    # among the relights, so the bar never moves back (the add-on's bake shows it, issue 12).
    scene, base = baked
    if solver == "direct":
        base = bake(scene, BakeSettings(exact_direct="all", vertex_budget=1500, solver=solver))
    dark = [dict(BULB, power=0.0), dict(SPOT, power=0.0)]
    seen = []
    relight_many(base, [dict(emission=_dark(scene), lights=[BULB, dark[1]]),
                        dict(emission=_dark(scene), lights=[dark[0], SPOT]),
                        dict(lights=dark)],
                 progress=lambda fraction, message: seen.append((fraction, message)))
    fractions = [f for f, _ in seen]
    assert fractions == sorted(fractions) and fractions[-1] == 1.0
    assert [m for _, m in seen].count("colours") == 3           # each relight's own part
