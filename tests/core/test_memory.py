"""Peak memory per stage (core.memory): the figure of a stage is the peak during that stage."""

import sys

import numpy as np
import pytest

from bench.scenes import room_with_boxes
from core import memory
from core.bake import BakeSettings, bake


def _can_reset():
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
        return True
    except OSError:
        return False


@pytest.mark.skipif(not sys.platform.startswith("linux") or not _can_reset(),
                    reason="the per-stage peak needs Linux's /proc/self/clear_refs")
def test_a_stage_that_held_200_mb_says_so_and_the_next_one_does_not():
    with memory.stages() as peaks:
        big = np.ones(200 * 2**20 // 8)              # 200 MiB, touched
        big += 1.0
        del big
        memory.mark("big")
        small = np.ones(1000)
        small += 1.0
        memory.mark("small")
    assert peaks["big"] - peaks["small"] >= 180, peaks


def test_the_bake_reports_a_peak_for_each_stage():
    result = bake(room_with_boxes(60), BakeSettings(workers=2, output_mode="vertices"))
    peaks = result.report["peak_mb"]
    assert set(peaks) == {"patches", "form_factors", "solve", "colours"}
    assert all(v > 0 for v in peaks.values())
    if result.report["workers"]["shared_calls"]:
        assert result.report["workers"]["peak_mb"] > 0
    # What the form-factor stage ends up holding is within its peak.
    assert peaks["form_factors"] >= result.report["form_factor_bytes"] / 2**20
