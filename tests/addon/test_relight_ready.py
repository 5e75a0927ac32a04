"""The panel's bake makes every light group's own solution in its worker (issue 12).

After the core bake, the worker of a bake started from the panel (operators.panel_job) makes the
groups' own solutions (relight.prepared: one core.relight_many), so the first Relight or group
change after it is a weighted sum with no solve. Oracle: the colours the first Relight makes
after a bake that made none (the operator's execute, as scripts call it), on the same kept form
factors. Esc while they are made cancels the bake; a bug there leaves the bake written.
"""

import json
import threading

import bpy
import numpy as np
import pytest

from conftest import PACKAGE
from test_operator import _Event, _modal, _Operator, _snapshot, _start_modal, drive
from test_relight import fixed_cubes  # noqa: F401 (a fixture)
from test_relight import colours_and_lux, lamp_and_two_lights, no_solve, room
from test_relight_modal import holding

relight = PACKAGE.radiosity_addon.relight
job = PACKAGE.radiosity_addon.job


@pytest.fixture
def progress(monkeypatch):
    """Every (fraction, message) the bake's worker reports, in order."""
    seen, real = [], job.BakeJob._progress

    def record(self, fraction, message):
        seen.append((fraction, message))
        real(self, fraction, message)
    monkeypatch.setattr(job.BakeJob, "_progress", record)
    return seen


def test_the_panel_bake_makes_every_group_so_its_first_relight_solves_nothing(
        package, fixed_cubes, monkeypatch, progress):
    scene = bpy.context.scene
    objects, lamp, (bulb, spot), _ = lamp_and_two_lights()       # execute: no group made
    assert relight.kept(scene).basis == {}
    bulb.data.energy *= 2.0
    assert bpy.ops.radiosity.relight() == {"FINISHED"}           # makes them: the oracle
    expected = [colours_and_lux(o) for o in objects]
    bulb.data.energy /= 2.0

    calls, many = [], PACKAGE.core.relight_many
    monkeypatch.setattr(PACKAGE.core, "relight_many", lambda result, changes, **kw: calls.append(
        (threading.current_thread().name, len(changes), sorted(kw))) or many(result, changes,
                                                                             **kw))
    _start_modal()
    result, reports = drive()
    assert result == {"FINISHED"}, reports
    # One relight_many of the lamp alone, the lights and the bulb alone, in the worker, which
    # Esc reaches (cancel) and the progress bar follows.
    assert calls == [("radiosity-bake", 3, ["cancel", "progress"])]
    fractions = [f for f, _ in progress]
    assert fractions == sorted(fractions) and fractions[-1] == 1.0
    groups = [f for f, m in progress if m.startswith("Light groups")]
    assert groups and min(groups) == pytest.approx(1.0 - job.GROUPS_SHARE)
    entry = relight.kept(scene)
    assert sorted(entry.basis) == list(range(len(entry.units))) == [0, 1, 2]
    report = json.loads(scene.radiosity.last_report)
    assert report["timings"]["light_groups"] > 0.0 and report["warnings"] == []

    monkeypatch.setattr(PACKAGE.core, "relight", no_solve)
    monkeypatch.setattr(PACKAGE.core, "relight_many", no_solve)
    bulb.data.energy *= 2.0
    assert bpy.ops.radiosity.relight() == {"FINISHED"}
    assert json.loads(scene.radiosity.last_report)["relight"]["summed"]
    # The same computation on the same form factors (the bake is deterministic with fixed
    # hemicubes): equal to float32 rounding of the written colours.
    for (col, lux), (e_col, e_lux) in zip([colours_and_lux(o) for o in objects], expected):
        np.testing.assert_allclose(col, e_col, rtol=1e-6, atol=1e-6 * np.abs(e_col).max())
        np.testing.assert_allclose(lux, e_lux, rtol=1e-6, atol=1e-6 * np.abs(e_lux).max())


def test_escape_while_the_groups_are_made_cancels_the_bake_and_writes_nothing(package,
                                                                             monkeypatch):
    room()                                                   # a lamp and a bulb: two groups
    bpy.context.scene.radiosity.output_mode = "VERTICES"
    before = _snapshot()
    inside, escaped, threads = holding(monkeypatch, "relight_many")
    _start_modal()
    me = _Operator()
    assert inside.wait(120)                    # the worker makes the groups: the user presses Esc
    assert _modal(me, _Event("ESC", "PRESS")) == {"RUNNING_MODAL"}
    escaped.set()
    result, reports = drive(me)
    assert result == {"CANCELLED"}, reports
    assert threads == ["radiosity-bake"]
    assert any("cancelled" in text for _, text in reports)
    assert _snapshot() == before and relight.kept(bpy.context.scene) is None


def test_a_bug_while_the_groups_are_made_leaves_the_bake_written_and_says_so(package,
                                                                            monkeypatch):
    walls, lamp, bulb = room()
    bpy.context.scene.radiosity.output_mode = "VERTICES"

    def bug(*args, **kw):
        raise ZeroDivisionError("a bug")
    monkeypatch.setattr(relight, "prepared", bug)
    _start_modal()
    result, reports = drive()
    assert result == {"FINISHED"}, reports
    report = json.loads(bpy.context.scene.radiosity.last_report)
    assert any("Light groups not made with the bake (ZeroDivisionError: a bug)" in w
               for w in report["warnings"])
    assert relight.kept(bpy.context.scene).basis == {}      # the first Relight makes them
    bulb.data.energy *= 2.0
    assert bpy.ops.radiosity.relight() == {"FINISHED"}
    assert json.loads(bpy.context.scene.radiosity.last_report)["relight"]["summed"]
