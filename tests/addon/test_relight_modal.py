"""The Relight button's solve runs in a worker, with progress and Esc (issue 12).

A Relight that is not a weighted sum (a light moved, added, or two lights of one group changed
apart) solves: seconds at 10k patches. From the panel it runs as the bake does
(relight.begin on the main thread, relight.compute in a ``radiosity-relight`` worker on a copy
of the kept bake, relight.finish on the main thread), driven here as the bpy tier drives the
modal bake (the operator's modal on timer events). Oracle: the same Relight run by the
operator's execute (scripts) on the same kept form factors; Esc, a slider moved and the kept
bake cleared while it runs are checked against the scene as it was.
"""

import json
import threading

import bpy
import numpy as np
import pytest

from conftest import PACKAGE
from test_operator import _Event, _modal, _Operator, _snapshot, drive
from test_relight import fixed_cubes  # noqa: F401 (a fixture)
from test_relight import bake, colours_and_lux, lamp_and_two_lights, no_solve, room

relight = PACKAGE.radiosity_addon.relight
relight_ops = PACKAGE.radiosity_addon.relight_ops
operators = PACKAGE.radiosity_addon.operators


def _start_relight():
    """Start the panel's Relight as its invoke does when it must solve: (the stand-in
    operator, the pending Relight)."""
    pending = relight.begin(bpy.context)
    assert not pending.instant
    operators._Running.job = relight_ops.RelightJob(pending).start()
    assert relight_ops.RADIOSITY_OT_relight.running()
    assert not relight_ops.RADIOSITY_OT_relight.poll(bpy.context)
    assert not operators.RADIOSITY_OT_bake.poll(bpy.context)      # one job at a time
    return _Operator(relight_ops.RADIOSITY_OT_relight), pending


def holding(monkeypatch, name):
    """core.<name> (relight or relight_many) holds its first call until ``go`` is set
    (``inside`` is set there): the user acts while a worker runs. Records each call's thread."""
    inside, go, threads, real = threading.Event(), threading.Event(), [], getattr(PACKAGE.core,
                                                                                   name)

    def held(result, *args, **kw):
        threads.append(threading.current_thread().name)
        if len(threads) == 1:
            inside.set()
            assert go.wait(60)
        return real(result, *args, **kw)
    monkeypatch.setattr(PACKAGE.core, name, held)
    return inside, go, threads


@pytest.fixture
def held(monkeypatch):
    return holding(monkeypatch, "relight")


def _colours(objects):
    return [colours_and_lux(o) for o in objects]


def _assert_same(actual, expected):
    # The same computation on the same kept form factors: equal to float32 rounding.
    for (col, lux), (e_col, e_lux) in zip(actual, expected):
        np.testing.assert_allclose(col, e_col, rtol=1e-6, atol=1e-6 * np.abs(e_col).max())
        np.testing.assert_allclose(lux, e_lux, rtol=1e-6, atol=1e-6 * np.abs(e_lux).max())


def test_a_relight_that_solves_runs_in_its_worker_and_writes_what_execute_writes(
        package, fixed_cubes, monkeypatch):
    scene = bpy.context.scene
    objects, lamp, (bulb, spot), baked = lamp_and_two_lights()
    where = tuple(bulb.location)
    bulb.location.x += 0.4                                     # moved: its light cast again
    assert bpy.ops.radiosity.relight() == {"FINISHED"}        # execute: the oracle
    expected = _colours(objects)
    assert not json.loads(scene.radiosity.last_report)["relight"]["summed"]

    bulb.location = where                                      # the same bake again
    bake(shadow_cuts=False)
    _assert_same(_colours(objects), baked)
    kept = relight.kept(scene)
    seen, threads, real, many = [], [], PACKAGE.core.relight, PACKAGE.core.relight_many
    monkeypatch.setattr(relight_ops.RelightJob, "_progress",
                        lambda self, f, m: seen.append((f, m)) or
                        relight_ops.job.Worker._progress(self, f, m))
    monkeypatch.setattr(PACKAGE.core, "relight", lambda result, **kw: threads.append(
        (threading.current_thread().name, "relight", sorted(kw))) or real(result, **kw))
    monkeypatch.setattr(PACKAGE.core, "relight_many", lambda result, changes, **kw:
                        threads.append((threading.current_thread().name, len(changes),
                                        sorted(kw))) or many(result, changes, **kw))
    bulb.location.x += 0.4
    me, pending = _start_relight()
    result, reports = drive(me)
    assert result == {"FINISHED"}, reports
    assert any(text.startswith("Relit in ") for _, text in reports)
    # One cast of the lights in the Relight's worker, which Esc reaches (cancel) and the bar
    # follows; then, written, every group's own solution in one relight_many in the next.
    assert threads == [("radiosity-relight", "relight",
                        ["cancel", "emission", "lights", "progress"]),
                       ("radiosity-groups", 3, ["cancel", "progress"])]
    fractions = [f for f, _ in seen]
    assert fractions and fractions == sorted(fractions)
    assert all(m.startswith("Relight: ") for _, m in seen)
    assert sorted(relight.kept(scene).basis) == [0, 1, 2]
    report = json.loads(scene.radiosity.last_report)["relight"]
    assert report["summed"] is False
    # The kept bake is now the relit one (computed on a copy; the old one was never touched).
    assert relight.kept(scene) is pending.work and pending.work is not kept
    assert kept.lights_ref is not pending.work.lights_ref
    _assert_same(_colours(objects), expected)
    assert not relight_ops.RADIOSITY_OT_relight.running()
    assert relight_ops.RADIOSITY_OT_relight.poll(bpy.context)
    monkeypatch.setattr(PACKAGE.core, "relight", no_solve)        # a group change: a sum
    monkeypatch.setattr(PACKAGE.core, "relight_many", no_solve)
    scene.radiosity_groups[1].strength = 0.5
    assert relight_ops._ERRORS == {}
    assert json.loads(scene.radiosity.last_report)["relight"]["summed"] is True


def test_escape_while_relight_solves_leaves_the_colours_and_the_kept_bake(package, held):
    inside, go, threads = held
    walls, lamp, bulb = room()
    bake()
    scene = bpy.context.scene
    kept = relight.kept(scene)
    state = dict(vars(kept))
    before = _snapshot()
    bulb.location.z -= 0.3
    me, _ = _start_relight()
    assert inside.wait(120)                    # the worker solves: the user presses Esc
    assert _modal(me, _Event("ESC", "PRESS")) == {"RUNNING_MODAL"}
    go.set()
    result, reports = drive(me)
    assert result == {"CANCELLED"}, reports
    assert any("Relight cancelled" in text for _, text in reports)
    assert threads == ["radiosity-relight"]
    assert _snapshot() == before
    assert relight.kept(scene) is kept and all(vars(kept)[k] is v for k, v in state.items())
    assert not relight_ops.RADIOSITY_OT_relight.running()
    # Nothing was lost: the same Relight from a script still solves and writes.
    assert bpy.ops.radiosity.relight() == {"FINISHED"}
    assert json.loads(scene.radiosity.last_report)["relight"]["summed"] is False
    assert _snapshot() != before


def test_a_group_slider_moved_while_relight_solves_is_mixed_in_when_it_ends(
        package, fixed_cubes, held):
    inside, go, threads = held
    scene = bpy.context.scene
    objects, lamp, (bulb, spot), baked = lamp_and_two_lights()
    bulb.location.x += 0.4
    me, _ = _start_relight()
    assert inside.wait(120)
    lamp_group = scene.radiosity_groups[0]
    lamp_group.strength = 0.5                  # its update writes nothing while Relight runs
    _assert_same(_colours(objects), baked)
    go.set()
    result, reports = drive(me)
    assert result == {"FINISHED"}, reports
    mixed = _colours(objects)
    # Oracle: the group list's own sums after the Relight, the slider set to 1 and back.
    lamp_group.strength = 1.0
    full = _colours(objects)
    assert not np.allclose(full[0][0], mixed[0][0], rtol=1e-3)
    lamp_group.strength = 0.5
    _assert_same(_colours(objects), mixed)


def test_the_kept_bake_cleared_while_relight_solves_writes_nothing(package, held):
    inside, go, _ = held
    walls, lamp, bulb = room()
    bake()
    before = _snapshot()
    bulb.location.z -= 0.3
    me, _ = _start_relight()
    assert inside.wait(120)
    relight.drop(bpy.context.scene)            # Forget Kept Bake (Clear Bake drops it too)
    go.set()
    result, reports = drive(me)
    assert result == {"CANCELLED"}, reports
    assert any("cleared while it ran" in text for _, text in reports)
    assert _snapshot() == before and relight.kept(bpy.context.scene) is None


def test_escape_while_the_groups_are_made_after_a_relight_keeps_the_relight(
        package, fixed_cubes, monkeypatch):
    # After the Relight is written, its run makes the groups' own solutions in a next worker;
    # Esc there stops only that (the Relight is written and is the run's undo step), and a
    # group slider moved meanwhile is mixed in when the run ends.
    scene = bpy.context.scene
    objects, lamp, (bulb, spot), baked = lamp_and_two_lights()
    inside, escaped, threads = holding(monkeypatch, "relight_many")
    bulb.location.x += 0.4
    me, pending = _start_relight()
    while not inside.wait(0.05):                 # ticks until the groups' worker runs
        assert drive(me, 0.05)[0] in ({"PASS_THROUGH"}, {"RUNNING_MODAL"})
    relit = _colours(objects)
    scene.radiosity_groups[0].strength = 0.5     # deferred while the run goes on
    _assert_same(_colours(objects), relit)
    assert _modal(me, _Event("ESC", "PRESS")) == {"RUNNING_MODAL"}
    escaped.set()
    result, reports = drive(me)
    assert result == {"FINISHED"}, reports
    assert threads[0] == "radiosity-groups"      # (then the slider's group alone, at the end)
    assert any("Light groups not made (cancelled)" in text for _, text in reports)
    assert relight.kept(scene) is pending.work
    # The slider's mix, made at the run's end: the lamp's own solution (solved then) at 0.5.
    mixed = _colours(objects)
    assert not np.allclose(mixed[0][0], relit[0][0], rtol=1e-3)
    scene.radiosity_groups[0].strength = 1.0
    _assert_same(_colours(objects), relit)
