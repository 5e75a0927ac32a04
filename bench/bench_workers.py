"""Worker processes (issue 13): bake time with 1 and 2 workers on generated interiors.

Each interior is ``--rooms`` closed rooms in a row (bench.scenes.room_with_boxes modelled as an
architect would: one quad per wall, floor, ceiling and box face; a ceiling panel lights each
room), baked to the radiosity mesh (output_mode='mesh') with the vertex budget scaled so that the
output has from a few thousand to ~100k vertices. Every bake runs in a fresh process (so its peak
memory is its own): the parent's and the workers' peak resident sets are reported apart. The two
bakes of one size run back to back, and their outputs are compared bit for bit.

Run: ``.venv/bin/python bench/bench_workers.py [--sizes 1:3000 2:10000 ...]``. Prints one line per
bake (rooms, workers, output vertices, seconds per stage, the bake process's and the workers' CPU
seconds, peak MB) and the 1-worker / 2-worker time ratio per size.
"""

import argparse
import hashlib
import json
import os
import resource
import subprocess
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from bench.scenes import room_with_boxes  # noqa: E402
from core import BakeSettings, bake, scene_from_polygons  # noqa: E402
from core import parallel  # noqa: E402

DEFAULT_SIZES = ("1:3000", "2:10000", "4:30000", "8:100000")


def interior(rooms):
    """``rooms`` copies of the coarse room_with_boxes, 7 m apart along x: one Scene."""
    one = room_with_boxes(24)
    verts, polys, faces_mat, objects = [], [], [], []
    per = [one.corner_verts[s:s + n] for s, n in zip(one.face_starts, one.face_sizes)]
    for k in range(rooms):
        base = k * one.vertices.shape[0]
        verts.append(one.vertices + [7.0 * k, 0.0, 0.0])
        polys += [(p + base).tolist() for p in per]
        faces_mat += list(one.face_materials)
        objects += [k] * len(per)
    return scene_from_polygons(np.vstack(verts), polys, faces_mat, one.reflectance, one.emission,
                               face_objects=objects,
                               object_names=[f"room {k}" for k in range(rooms)])


def one_bake(rooms, budget, workers):
    """Bake one size in this process; a dict of figures."""
    scene = interior(rooms)
    t0, c0 = time.perf_counter(), time.process_time()
    result = bake(scene, BakeSettings(workers=workers, vertex_budget=budget, min_element=0.02))
    seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
    parallel.close()                       # reap the workers: their peak counts as children's
    out = result.output
    digest = hashlib.sha256()
    for a in (out.vertices, out.corner_colours, result.corner_colours):
        digest.update(np.ascontiguousarray(a).tobytes())
    return dict(rooms=rooms, budget=budget, workers=workers, vertices=int(out.vertices.shape[0]),
                seconds=seconds, stages=result.report["timings"], cpu=cpu,
                workers_cpu=result.report["workers"].get("cpu_seconds", 0.0),
                processes=result.report["workers"]["processes"],
                peak_mb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                workers_peak_mb=resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024,
                digest=digest.hexdigest())


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", nargs="+", default=list(DEFAULT_SIZES),
                        help="ROOMS:VERTEX_BUDGET pairs")
    parser.add_argument("--one", nargs=3, type=int, metavar=("ROOMS", "BUDGET", "WORKERS"),
                        help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one:
        print(json.dumps(one_bake(*args.one)))
        return
    print(f"{'rooms':>5} {'workers':>7} {'vertices':>8} {'total s':>8} {'colours s':>9} "
          f"{'form f. s':>9} {'cpu s':>7} {'wrk cpu s':>9} {'peak MB':>8} {'workers MB':>10}")
    for size in args.sizes:
        rooms, budget = (int(x) for x in size.split(":"))
        runs = {}
        for workers in (1, 2):
            line = subprocess.run([sys.executable, __file__, "--one", str(rooms), str(budget),
                                   str(workers)], check=True, capture_output=True,
                                  text=True).stdout.strip().splitlines()[-1]
            r = runs[workers] = json.loads(line)
            print(f"{rooms:>5} {r['processes']:>7} {r['vertices']:>8} {r['seconds']:>8.1f} "
                  f"{r['stages'].get('colours', 0):>9.1f} "
                  f"{r['stages'].get('form_factors', 0):>9.1f} {r['cpu']:>7.1f} "
                  f"{r['workers_cpu']:>9.1f} {r['peak_mb']:>8.0f} "
                  f"{r['workers_peak_mb']:>10.0f}", flush=True)
        same = runs[1]["digest"] == runs[2]["digest"]
        print(f"      rooms {rooms}: 1 worker / 2 workers = "
              f"{runs[1]['seconds'] / runs[2]['seconds']:.2f}x; outputs bit-identical: {same}",
              flush=True)


if __name__ == "__main__":
    main()
