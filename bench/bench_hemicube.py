"""Benchmark of the hemicube rasteriser: seconds per source patch, peak memory, per-stage split.

Scene: ``core.samples.room_with_boxes(n_quads)`` (closed room, two boxes, emissive ceiling
panel), one patch per quad. A random sample of source nodes (front sides) is timed, in calls of
``--batch`` sources as the bake makes them, after one warm-up call.

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

from core.hemicube import triangle_rows  # noqa: E402
from core.patches import make_patches, patch_triangles  # noqa: E402
from core.samples import room_with_boxes  # noqa: E402

STAGES = ("cull", "setup", "spans", "general", "zbuffer", "accumulate")


def room_patches(n_quads):
    """Patches of the benchmark room, one per quad (max_edge above every quad's edges)."""
    scene = room_with_boxes(n_quads)
    return make_patches(scene, max_edge=100.0)


def run(patches, sources, resolution, batch, *, rotate=False):
    """Seconds per source and the per-stage timings (dict) for ``sources`` in batches."""
    tris, tri_patch = patch_triangles(patches)
    args = (tris, tri_patch, patches.centres, patches.normals, patches.corners)
    rng = np.random.default_rng(1)
    triangle_rows(*args, sources[:batch], resolution=resolution, rotate=rotate, rng=rng)  # warm
    timings = {}
    tic = time.perf_counter()
    for start in range(0, sources.size, batch):
        triangle_rows(*args, sources[start:start + batch], resolution=resolution,
                      rotate=rotate, rng=rng, timings=timings)
    return (time.perf_counter() - tic) / sources.size, timings


def peak_memory(patches, sources, resolution, batch):
    """Peak traced memory (bytes) of one call with ``batch`` sources."""
    tris, tri_patch = patch_triangles(patches)
    tracemalloc.start()
    triangle_rows(tris, tri_patch, patches.centres, patches.normals, patches.corners,
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

    print(f"numpy {np.__version__}, {os.cpu_count()} cpus, load {os.getloadavg()[0]:.2f}")
    print(f"{'N':>6} {'P':>6} {'T':>6} {'R':>4} {'ms/src':>7} {'call s':>7} {'peak MB':>8} "
          f"{'pairs':>6} {'rows':>6} {'frags':>6}  " + " ".join(f"{s[:6]:>6}" for s in STAGES))
    for n_quads in args.sizes:
        patches = room_patches(n_quads)
        p = patches.centres.shape[0]
        t = patch_triangles(patches)[0].shape[0]
        rng = np.random.default_rng(0)
        sources = rng.choice(p, size=min(args.sources, p), replace=False)
        for res in args.res:
            per_src, tm = run(patches, sources, res, args.batch)
            peak = peak_memory(patches, sources, res, args.batch)
            stage_total = sum(tm[s] for s in STAGES)
            split = " ".join(f"{100 * tm[s] / stage_total:5.1f}%" for s in STAGES)
            ns = sources.size
            print(f"{n_quads:>6} {p:>6} {t:>6} {res:>4} {1e3 * per_src:7.3f} "
                  f"{per_src * args.batch:7.3f} {peak / 2**20:8.1f} {tm['n_pairs'] // ns:>6} "
                  f"{tm['n_rows'] // ns:>6} {tm['n_fragments'] // ns:>6}  {split}", flush=True)
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"max RSS of the whole run: {rss:.0f} MB")

    if args.profile:
        patches = room_patches(2000)
        sources = np.random.default_rng(0).choice(patches.centres.shape[0], 200, replace=False)
        prof = cProfile.Profile()
        prof.enable()
        run(patches, sources, 64, args.batch)
        prof.disable()
        pstats.Stats(prof).sort_stats("tottime").print_stats(15)


if __name__ == "__main__":
    main()
