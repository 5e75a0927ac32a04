"""The settings table (core.settings) and what is derived from it; cancel during assembly."""

import dataclasses
import time
import traceback

import numpy as np
import pytest

from core import BakeCancelled, SettingsError, bake, progress
from core.exact import NEAR_DEFAULT
from core.hemicube import delta_form_factors
from core.settings import BY_NAME, EXPOSED, MAX_LABEL, TABLE, BakeSettings, Setting, as_dict

from bench.scenes import room_with_boxes


def test_bake_settings_fields_are_the_table():
    fields = dataclasses.fields(BakeSettings)
    assert [f.name for f in fields] == [row.name for row in TABLE]
    assert {f.name: f.default for f in fields} == {row.name: row.default for row in TABLE}
    for row in TABLE:
        assert row.name in BakeSettings.__doc__


@pytest.mark.parametrize("row", TABLE, ids=lambda r: r.name)
def test_every_row_is_consistent(row):
    assert row.valid(row.default), row.describe()
    assert 0 < len(row.label) <= MAX_LABEL
    assert row.help and not row.help.endswith(".")
    if row.type == "choice":
        assert row.default in row.values() and all(c.label and c.help for c in row.choices)
    if row.low is not None and row.high is not None:
        assert row.low < row.high


def test_resolution_range_is_the_hemicubes():
    # One range: the largest resolution the settings accept is one the hemicube computes, and
    # one step above it is refused before any work (it used to fail after building patches).
    row = BY_NAME["resolution"]
    assert delta_form_factors(row.high)["top"].shape == (row.high, row.high)
    with pytest.raises(ValueError):
        delta_form_factors(row.high + 2)
    with pytest.raises(SettingsError, match=r"resolution must be an even integer in \[4, 2048\]"):
        BakeSettings(resolution=row.high + 2)
    with pytest.raises(SettingsError, match="got 3000"):
        BakeSettings(resolution=3000)


def test_near_has_one_default():
    assert BakeSettings().near == NEAR_DEFAULT == 1.5


@pytest.mark.parametrize("row, good, bad", [
    (Setting("x", "float", 0.5, "X", "x", low=0, open_low=True), [1e-9, 3], [0.0, -1, np.nan,
                                                                               True, "1"]),
    (Setting("x", "int", 4, "X", "x", low=2, high=8, even=True), [2, 8, np.int64(6)],
     [3, 10, 0, 4.0, True]),
    (Setting("x", "float", 0.5, "X", "x", low=0, high=1, open_low=True, open_high=True),
     [0.5, np.float32(0.25)], [0.0, 1.0, np.inf]),
    (Setting("x", "bool_or_auto", "auto", "X", "x"), [True, False, np.bool_(True), "auto"],
     [1, 0, "on", None]),
])
def test_setting_check(row, good, bad):
    for value in good:
        assert row.check(value) is value
    for value in bad:
        with pytest.raises(SettingsError) as info:
            row.check(value)
        assert str(info.value) == f"x must be {row.describe()}; got {value!r}"


def test_as_dict_lists_the_exposed_settings():
    s = BakeSettings(patch_size=0.25, corners="average")
    d = as_dict(s)
    assert tuple(d) == EXPOSED and d["patch_size"] == 0.25 and d["corners"] == "average"
    assert set(EXPOSED) >= {"patch_size", "method", "resolution", "solver", "corners"}


def test_bake_settings_are_keyword_only_and_frozen():
    with pytest.raises(TypeError):
        BakeSettings(0.5)
    with pytest.raises(dataclasses.FrozenInstanceError):
        BakeSettings().seed = 2


# ------------------------------------------------------------------- cancel after form factors

@pytest.mark.parametrize("where", ["assemble", "asymmetry", "make_reciprocal", "_sinkhorn"])
def test_cancel_is_polled_while_assembling_and_balancing(monkeypatch, where):
    # Every poll of the cancel check after the form factors are done runs inside one of these
    # functions (or the solver): with the poll interval at 0 each of them must poll at least
    # once, and a cancel seen there must end the bake with BakeCancelled.
    monkeypatch.setattr(progress, "POLL_INTERVAL", 0.0)
    seen = {}

    def cancel():
        names = [frame.name for frame in traceback.extract_stack()]
        seen["polls"] = seen.get("polls", 0) + 1
        if where in names:
            seen["at"] = names
            return True
        return False

    settings = BakeSettings(patch_size=1.0, resolution=16, element_levels=0, solver="direct")
    with pytest.raises(BakeCancelled):
        bake(room_with_boxes(200), settings, cancel=cancel)
    assert where in seen["at"]


def test_cancel_after_form_factors_is_prompt():
    # Measured, not asserted on the clock: the largest gap between two polls of the cancel
    # check after 'form factors done' (assembly, reciprocity, solve, gather), printed with -s.
    stamps, state = [], {}

    def on_progress(fraction, message):
        if message == "form factors done":
            state["after"] = True

    def cancel():
        if state.get("after"):
            stamps.append(time.perf_counter())
        return False

    res = bake(room_with_boxes(2000), BakeSettings(patch_size=1.0, element_levels=0),
               progress=on_progress, cancel=cancel)
    gaps = np.diff(stamps)
    print(f"\n{res.report['nodes_active']} active nodes: {len(stamps)} polls after the form "
          f"factors, largest gap {gaps.max():.3f} s")
    assert len(stamps) > 2
