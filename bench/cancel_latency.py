"""Largest gap between two polls of the cancel check after the form factors are done.

A cancel is honoured at the next poll, so the largest gap is the worst reaction time to Esc in
the matrix assembly, the reciprocity set-up and the solve (issue 10: within 0.5 s at any size).

Run:  .venv/bin/python bench/cancel_latency.py [--quads 6000] [--resolution 16]
"""

import argparse
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

import numpy as np  # noqa: E402

from bench.scenes import room_with_boxes  # noqa: E402
from core import BakeSettings, bake  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quads", type=int, default=6000)
    ap.add_argument("--resolution", type=int, default=16)
    args = ap.parse_args()
    polls, marks = [], {}

    def progress(fraction, message):
        if message == "form factors done":
            marks["ff_done"] = time.perf_counter()
        if message == "solved":
            marks["solved"] = time.perf_counter()

    def cancel():
        if "ff_done" in marks and "solved" not in marks:
            polls.append(time.perf_counter())
        return False

    res = bake(room_with_boxes(args.quads),
               BakeSettings(patch_size=100.0, resolution=args.resolution, corners="average",
                            element_levels=0, contact_cuts=False),
               progress=progress, cancel=cancel)
    stamps = np.array([marks["ff_done"]] + polls + [marks["solved"]])
    gaps = np.diff(stamps)
    print(f"{res.report['patches']} patches, {res.report['nodes_active']} active nodes, solver "
          f"{res.report['solver']}: form factors {res.report['timings']['form_factors']:.1f} s, "
          f"solve stage {stamps[-1] - stamps[0]:.2f} s with {len(polls)} polls; largest gap "
          f"between polls {gaps.max():.3f} s")


if __name__ == "__main__":
    main()
