"""Benchmark of the hemicube rasteriser: seconds per source patch, peak memory, per-stage split.

Scene: ``bench.scenes.room_with_boxes(n_quads)`` (closed room, two boxes, emissive ceiling
panel), one patch per quad. A random sample of source nodes (front sides) is timed, in calls of
``--batch`` sources as the bake makes them, after one warm-up call. Stages (CPU time): cull,
items, spans (main group), general (near-plane-clipped groups) and accumulate exclude the
z-buffer, which is drawn from inside the span stages as spans are made and timed apart.

Run:  .venv/bin/python bench/bench_hemicube.py [--sizes 500 2000 8000] [--res 32 64 128]
                                               [--sources 200] [--batch 64] [--profile]
"""

import argparse
import cProfile
import os
import pstats
import resource
import sys
import time
import tracemalloc

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

from core.hemicube import draw_polygons, polygon_rows
from core.hemicube_chunk import Geometry  # noqa: E402
from core.patches import make_patches  # noqa: E402
from bench.scenes import room_with_boxes  # noqa: E402

STAGES = ("cull", "items", "spans", "general", "zbuffer", "accumulate")


def room_patches(n_quads):
    """Patches of the benchmark room, one per quad (max_edge above every quad's edges)."""
    scene = room_with_boxes(n_quads)
    return make_patches(scene, max_edge=100.0)


def setup(patches):
    """(polys, poly_patch, Geometry): the per-scene setup, made once per scene as
    hemicube_rows caches it across a bake's calls."""
    polys, poly_patch = draw_polygons(patches)
    return polys, poly_patch, Geometry(polys, poly_patch, patches.normals)


def run(patches, drawn, sources, resolution, batch, *, rotate=False):
    """(wall s, CPU s) per source and per-stage CPU timings (dict) for ``sources`` in batches."""
    polys, poly_patch, geometry = drawn
    args = (polys, poly_patch, patches.centres, patches.normals, patches.corners)
    rng = np.random.default_rng(1)
    kw = dict(resolution=resolution, rotate=rotate, rng=rng, _geometry=geometry)
    polygon_rows(*args, sources[:batch], **kw)                                     # warm-up
    timings = {}
    wall, cpu = time.perf_counter(), time.process_time()
    for start in range(0, sources.size, batch):
        polygon_rows(*args, sources[start:start + batch], timings=timings, **kw)
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    return wall / sources.size, cpu / sources.size, timings


def peak_memory(patches, drawn, sources, resolution, batch):
    """Peak traced memory (bytes) of one call with ``batch`` sources."""
    polys, poly_patch, _ = drawn
    tracemalloc.start()
    polygon_rows(polys, poly_patch, patches.centres, patches.normals, patches.corners,
                 sources[:batch], resolution=resolution)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return peak


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[500, 2000, 8000])
    parser.add_argument("--res", type=int, nargs="+", default=[32, 64, 128])
    parser.add_argument("--sources", type=int, default=200)
    parser.add_argument("--batch", type=int, default=64)
    parser.add_argument("--profile", action="store_true", help="cProfile the N=2000, R=64 case")
    args = parser.parse_args()

    print(f"numpy {np.__version__}, {os.cpu_count()} cpus, load {os.getloadavg()[0]:.2f} "
          "(ms per source: wall and CPU; stage split of CPU time)")
    print(f"{'N':>6} {'P':>6} {'Q':>6} {'R':>4} {'wall':>6} {'cpu':>6} {'call s':>6} "
          f"{'peak MB':>7} {'pairs':>6} {'rows':>6} {'frags':>6}  "
          + " ".join(f"{s[:7]:>7}" for s in STAGES))
    for n_quads in args.sizes:
        patches = room_patches(n_quads)
        p = patches.centres.shape[0]
        drawn = setup(patches)
        t = drawn[0].shape[0]
        rng = np.random.default_rng(0)
        sources = rng.choice(p, size=min(args.sources, p), replace=False)
        for res in args.res:
            wall, cpu, tm = run(patches, drawn, sources, res, args.batch)
            peak = peak_memory(patches, drawn, sources, res, args.batch)
            stage_total = sum(tm[s] for s in STAGES)
            split = " ".join(f"{100 * tm[s] / stage_total:6.1f}%" for s in STAGES)
            ns = sources.size
            print(f"{n_quads:>6} {p:>6} {t:>6} {res:>4} {1e3 * wall:6.2f} {1e3 * cpu:6.2f} "
                  f"{wall * args.batch:6.3f} {peak / 2**20:7.1f} {tm['n_pairs'] // ns:>6} "
                  f"{tm['n_rows'] // ns:>6} {tm['n_fragments'] // ns:>6}  {split}", flush=True)
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"max RSS of the whole run: {rss:.0f} MB")

    if args.profile:
        patches = room_patches(2000)
        sources = np.random.default_rng(0).choice(patches.centres.shape[0], 200, replace=False)
        prof = cProfile.Profile()
        prof.enable()
        run(patches, setup(patches), sources, 64, args.batch)
        prof.disable()
        pstats.Stats(prof).sort_stats("tottime").print_stats(15)


if __name__ == "__main__":
    main()
