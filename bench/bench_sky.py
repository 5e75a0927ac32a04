"""Cost of a directional sky (core.sky) against the plain hemicube.

1. Kernel: rows of every node of a room with a skylight (4 x 4 x 2 m, a 2 x 2 m opening in the
   ceiling, ``--patch`` m patches), without and with a CIE overcast sky, in one process; CPU
   seconds of ``polygon_rows`` and its ``sky`` stage (the empty pixels' directions, the sky's
   radiance, the sums). Best of ``--repeat``.
2. Bake: the same room baked with a uniform world of the same horizontal illuminance and with
   sky='cie_overcast' (output 'vertices' and 'mesh', one worker): wall seconds.

Run:  .venv/bin/python bench/bench_sky.py [--res 64] [--patch 0.25] [--repeat 3]
"""

import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

from core import BakeSettings, bake, scene_from_polygons  # noqa: E402
from core.hemicube import draw_polygons, polygon_rows  # noqa: E402
from core.hemicube_chunk import Geometry  # noqa: E402
from core.patches import make_patches  # noqa: E402
from core.sky import CIEOvercast, zenith_radiance  # noqa: E402


def skylight_room(world, W=4.0, H=2.0, a=2.0):
    s, o = W / 2, a / 2
    v = [[-s, -s, 0], [s, -s, 0], [s, s, 0], [-s, s, 0], [-s, -s, H], [s, -s, H], [s, s, H],
         [-s, s, H], [-o, -o, H], [o, -o, H], [o, o, H], [-o, o, H]]
    polys = [[0, 1, 2, 3], [0, 4, 5, 1], [1, 5, 6, 2], [2, 6, 7, 3], [3, 7, 4, 0],
             [5, 9, 8, 4], [6, 10, 9, 5], [7, 11, 10, 6], [4, 8, 11, 7]]
    return scene_from_polygons(np.array(v, float), polys, [0] * len(polys), [[0.5] * 3],
                               [[0.0] * 3], world=world)


def kernel(res, patch, repeat):
    lz = zenith_radiance(10_000.0)
    patches = make_patches(skylight_room(CIEOvercast(lz)), patch)
    polys, poly_patch = draw_polygons(patches)
    geometry = Geometry(polys, poly_patch, patches.normals)
    sources = np.arange(2 * patches.areas.size)
    out = {}
    for name, sky in (("plain", None), ("cie_overcast", CIEOvercast(lz))):
        best = None
        for _ in range(repeat):
            timings = {}
            light = None if sky is None else np.zeros((sources.size, 3))
            t0 = time.process_time()
            polygon_rows(polys, poly_patch, patches.centres, patches.normals, patches.corners,
                         sources, resolution=res, rotate=True, rng=1, timings=timings,
                         sky=sky, sky_out=light, _geometry=geometry)
            total = time.process_time() - t0
            if best is None or total < best[0]:
                best = (total, timings.get("sky", 0.0))
        out[name] = best
    n = sources.size
    print(f"kernel: {patches.areas.size} patches, {n} hemicubes at R = {res}")
    for name, (total, sky_s) in out.items():
        print(f"  {name:13s} {total:7.3f} s CPU ({1e3 * total / n:.2f} ms per hemicube), "
              f"sky stage {sky_s:.3f} s")
    # The totals of two runs differ by the machine's noise as much as by the sky: the sky
    # stage's own time is the figure.
    share = out["cie_overcast"][1] / out["plain"][0]
    print(f"  sky stage = {100 * share:.1f} % of the plain rows' CPU")


def bakes():
    lz = zenith_radiance(10_000.0)
    # A uniform world of the same horizontal illuminance: pi L = 7 pi Lz / 9.
    uniform = skylight_room(np.full(3, 7 * lz / 9))
    cie = skylight_room(CIEOvercast(lz))
    for mode in ("vertices", "mesh"):
        for name, scene in (("world", uniform), ("cie_overcast", cie)):
            t0 = time.perf_counter()
            bake(scene, BakeSettings(output_mode=mode, workers=1))
            print(f"bake {mode:8s} {name:13s} {time.perf_counter() - t0:6.2f} s")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--res", type=int, default=64)
    parser.add_argument("--patch", type=float, default=0.25)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--no-bake", action="store_true")
    args = parser.parse_args()
    kernel(args.res, args.patch, args.repeat)
    if not args.no_bake:
        bakes()


if __name__ == "__main__":
    main()
