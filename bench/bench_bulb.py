"""A bulb modelled as a sphere: a small emitter with many faces (issue 11, class 1).

    .venv/bin/python bench/bench_bulb.py          # about 8 minutes on 2 cores

Prints, for UV spheres of radius 5 and 10 cm (12 x 6, 32 x 16, 32 x 32 and 64 x 32 segments,
Blender's default UV sphere being the second; the last is over core.emitters.MAX_FACES)
hanging 0.5 m under the ceiling of the black 4 x 4 x 3 m room of class 1, the floor's error at its output vertices against the closed form, for the
default (``exact_direct='auto'``: the sphere is one lamp of many faces, core.lamps) and for the
hemicube alone (``'off'``): what each costs and reads.

Oracle: with black walls and ceiling the floor reads ``rho sum_f Le F(x -> f)`` over the
sphere's faces whose emitting side faces x (a convex lamp does not hide itself from outside),
F by the contour integral (core.exact.point_polygon_form_factor).
"""

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.stability.emitters import bulb_errors  # noqa: E402
from bench.stability.scenes import bulb_room  # noqa: E402
from core.bake import bake  # noqa: E402
from core.settings import BakeSettings  # noqa: E402


def main():
    print("| bulb | faces | exact_direct | floor vertices | mean error | worst vertex | time |")
    print("|---|---|---|---|---|---|---|")
    for r, nu, nv in ((0.05, 12, 6), (0.05, 32, 16), (0.1, 32, 16), (0.05, 32, 32),
                      (0.05, 64, 32)):
        scene, groups, polys, le = bulb_room(r, nu, nv)
        for mode in ("auto", "off"):
            t = time.perf_counter()
            result = bake(scene, BakeSettings(exact_direct=mode))
            seconds = time.perf_counter() - t
            mean, worst, nv_floor = bulb_errors(result, groups, polys, le)
            taken = result.report.get("lights", {}).get("exact_emitter_faces", 0)
            label = "'auto' (default)" if mode == "auto" else "'off' (hemicube)"
            print(f"| r = {r * 100:g} cm, {nu} x {nv} | {len(polys)} | {label} ({taken} faces "
                  f"exact) | {nv_floor} | {mean * 100:.2f} % | {worst * 100:.1f} % | "
                  f"{seconds:.1f} s |", flush=True)


if __name__ == "__main__":
    main()
