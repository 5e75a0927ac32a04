"""Benchmark of the hemisphere-base projection (Nusselt analog) against the hemicube.

Part 1, cost: ``bench.scenes.room_with_boxes(n_quads)`` (closed room, two boxes, emissive
ceiling panel), one patch per quad; a random sample of front source nodes is timed in calls of
``--batch`` sources, as the bake makes them, after one warm-up call; the best of ``--repeat``
runs (the machine is shared). Both methods at the same R; note that the Nusselt base counts
about pi R^2 / 4 pixels against the hemicube's 3 R^2, so equal pixel counts are Nusselt at 2R
against the hemicube at R. A least-squares fit ``seconds per row = a R^2 + b P`` is printed for
each method (the batch cost model of core/rows.py).

Part 2, accuracy: a small room (``--small`` quads); rows of ``--error-sources`` sources against
``core.exact.exact_rows`` (point source, 64 visibility rays per pair); the exact method's own
noise is shown by a second run with another seed. RMS over the entries the exact method sees,
and the mean L1 distance of a row.

Run:  .venv/bin/python bench/bench_nusselt.py [--sizes 500 2000] [--res 32 64 128]
                                              [--sources 128] [--batch 64] [--repeat 3]
"""

import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

from bench.scenes import room_with_boxes  # noqa: E402
from core.exact import exact_rows  # noqa: E402
from core.hemicube import hemicube_rows  # noqa: E402
from core.nusselt import nusselt_rows  # noqa: E402
from core.patches import make_patches  # noqa: E402

METHODS = {"nusselt": nusselt_rows, "hemicube": hemicube_rows}


def room_patches(n_quads):
    """Patches of the benchmark room, one per quad (max_edge above every quad's edges)."""
    return make_patches(room_with_boxes(n_quads), max_edge=100.0)


def seconds_per_row(method, patches, sources, resolution, batch, repeat):
    """(wall, CPU) seconds per source row: the best of ``repeat`` runs in batches."""
    method(patches, sources[:batch], resolution=resolution)                       # warm-up
    best = (np.inf, np.inf)
    for _ in range(repeat):
        wall, cpu = time.perf_counter(), time.process_time()
        for start in range(0, sources.size, batch):
            method(patches, sources[start:start + batch], resolution=resolution)
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
        best = (min(best[0], wall / sources.size), min(best[1], cpu / sources.size))
    return best


def cost(args):
    print(f"numpy {np.__version__}, {os.cpu_count()} cpus, load {os.getloadavg()[0]:.2f} "
          "(ms per source row, best of runs: wall and CPU)")
    print(f"{'N':>6} {'P':>6} {'R':>4}  {'nusselt':>15}  {'hemicube':>15}  {'ratio':>5}")
    fits = {name: [] for name in METHODS}
    for n_quads in args.sizes:
        patches = room_patches(n_quads)
        p = patches.centres.shape[0]
        sources = np.random.default_rng(0).choice(p, size=min(args.sources, p), replace=False)
        for res in args.res:
            t = {name: seconds_per_row(f, patches, sources, res, args.batch, args.repeat)
                 for name, f in METHODS.items()}
            for name in METHODS:
                fits[name].append((res * res, p, t[name][1]))
            cells = "  ".join(f"{1e3 * t[m][0]:7.3f} {1e3 * t[m][1]:7.3f}" for m in METHODS)
            ratio = t["nusselt"][1] / t["hemicube"][1]
            print(f"{n_quads:>6} {p:>6} {res:>4}  {cells}  {ratio:5.2f}", flush=True)
    for name, rows in fits.items():
        a = np.array(rows, dtype=float)
        coef, *_ = np.linalg.lstsq(a[:, :2], a[:, 2], rcond=None)
        print(f"fit {name}: CPU seconds per row = {coef[0]:.3g} R^2 + {coef[1]:.3g} P")


def accuracy(args):
    patches = room_patches(args.small)
    p = patches.centres.shape[0]
    sources = np.random.default_rng(1).choice(p, size=min(args.error_sources, p), replace=False)
    tic = time.perf_counter()
    exact = exact_rows(patches, sources, rays=64, rng=np.random.default_rng(0))
    again = exact_rows(patches, sources, rays=64, rng=np.random.default_rng(1))
    seen = exact > 0
    print(f"\naccuracy against exact_rows (point source, 64 rays), room_with_boxes({args.small}): "
          f"P = {p}, {sources.size} sources, exact in {time.perf_counter() - tic:.1f} s")

    def score(rows):
        d = rows - exact
        return np.sqrt(np.mean(d[seen] ** 2)), np.abs(d).sum(axis=1).mean()

    rms, l1 = score(again)
    print(f"{'exact, other seed':>20}: RMS {rms:.2e}  L1/row {l1:.2e}  (the reference's noise)")
    for res in (32, 64, 128, 256):
        for name, f in METHODS.items():
            rms, l1 = score(f(patches, sources, resolution=res))
            print(f"{name + ' R=' + str(res):>20}: RMS {rms:.2e}  L1/row {l1:.2e}", flush=True)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[500, 2000])
    parser.add_argument("--res", type=int, nargs="+", default=[32, 64, 128])
    parser.add_argument("--sources", type=int, default=128)
    parser.add_argument("--batch", type=int, default=64)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--small", type=int, default=150, help="quads of the accuracy scene")
    parser.add_argument("--error-sources", type=int, default=40)
    args = parser.parse_args()
    cost(args)
    accuracy(args)


if __name__ == "__main__":
    main()
