"""Benchmark of the solvers and of the whole bake's stage split.

Scene: ``bench.scenes.room_with_boxes(n_quads)`` (closed room, two boxes, emissive panel 5 cm
under the ceiling), one patch per quad. For each size the script

1. bakes once (``solver='auto'``) and prints the stage split (patches, form factors, solve,
   colours), the active node count and the form-factor bytes;
2. takes that bake's form factors of the active nodes (float32, as the bake keeps them) and times
   every solver on them to ``--tol``: seconds, iterations (sweeps / shots), residual, the largest
   relative deviation from the direct solve, and the peak traced memory (tracemalloc: NumPy
   buffers, not LAPACK's internal workspace);
3. optionally (``--free``) bakes again with a memory budget too small for the matrix, i.e.
   matrix-free progressive refinement with rows recomputed on demand.

The process's peak resident size (ru_maxrss) is printed at the end.

Run:  .venv/bin/python bench/bench_solvers.py [--sizes 500 2000 8000] [--res 64] [--tol 1e-4]
                                              [--skip-direct-above 6000] [--free]
                                              [--solvers direct jacobi gauss_seidel progressive]
"""

import argparse
import os
import resource
import sys
import time
import tracemalloc

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

from core.bake import BakeSettings, bake  # noqa: E402
from bench.scenes import room_with_boxes  # noqa: E402
from core.solvers import (solve_direct, solve_gauss_seidel, solve_jacobi,  # noqa: E402
                          solve_progressive)


def active_system(result):
    """Form factors (float32), areas, rho, le of the active nodes of a dense-path bake."""
    st = result._state
    idx = np.flatnonzero(st.active)
    F = st.store.assemble(idx, idx, np.float32)
    mat = np.tile(result.patches.material, 2)[idx]
    rho = st.scene.reflectance[mat]
    le = st.scene.emission[mat]
    areas = np.tile(result.patches.areas, 2)[idx]
    return F, areas, rho, le


def timed(fn):
    tracemalloc.start()
    t0 = time.perf_counter()
    out = fn()
    dt = time.perf_counter() - t0
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return out, dt, peak


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[500, 2000, 8000])
    ap.add_argument("--res", type=int, default=64)
    ap.add_argument("--tol", type=float, default=1e-4)
    ap.add_argument("--skip-direct-above", type=int, default=6000,
                    help="skip the direct solve above this many nodes (memory: 16 N^2 bytes)")
    ap.add_argument("--free", action="store_true", help="also bake matrix-free (slow)")
    ap.add_argument("--solvers", nargs="+", default=None,
                    help="only the solver rows whose name starts with one of these")
    args = ap.parse_args()

    for n_quads in args.sizes:
        scene = room_with_boxes(n_quads)
        settings = BakeSettings(patch_size=100.0, resolution=args.res, tolerance=args.tol,
                                memory_budget=4 << 30)
        res = bake(scene, settings)
        rep = res.report
        t = rep["timings"]
        print(f"\n=== room_with_boxes({n_quads}): {rep['patches']} patches, "
              f"{rep['nodes_active']} active nodes, R = {args.res}")
        print(f"bake (auto -> {rep['solver']}): total {t['total']:.2f} s = patches "
              f"{t['patches']:.3f} + form factors {t['form_factors']:.2f} + solve "
              f"{t['solve']:.3f} + colours {t['colours']:.3f}; form factors kept "
              f"{rep['form_factor_bytes'] / 2**20:.1f} MiB")
        e = rep["energy"]
        print(f"energy: emitted {e['emitted']:.1f} W, absorbed {e['absorbed']:.1f} W, escaped "
              f"{e['escaped']:.2f} W, balance {e['balance']:+.1f} W "
              f"({100 * e['balance'] / e['emitted']:+.1f} %)")
        for w in rep["warnings"]:
            print("warning:", w)

        F, areas, rho, le = active_system(res)
        n = len(F)
        del res
        runs = []
        if n <= args.skip_direct_above:
            runs.append(("direct", lambda: solve_direct(F, rho, le)))
        runs += [
            ("jacobi", lambda: solve_jacobi(F, rho, le, tol=args.tol)),
            ("gauss_seidel block 64", lambda: solve_gauss_seidel(F, rho, le, tol=args.tol)),
            ("gauss_seidel block 256", lambda: solve_gauss_seidel(F, rho, le, tol=args.tol,
                                                                  block=256)),
            ("gauss_seidel point", lambda: solve_gauss_seidel(F, rho, le, tol=args.tol,
                                                              block=1)),
            ("progressive dense F", lambda: solve_progressive(None, areas, rho, le, F=F,
                                                              tol=args.tol)),
            ("progressive rows", lambda: solve_progressive(lambda s: F[s], areas, rho, le,
                                                           tol=args.tol)),
        ]
        if args.solvers:
            runs = [r for r in runs if any(r[0].startswith(p) for p in args.solvers)]
        ref = None
        print(f"{'solver':26s} {'seconds':>8s} {'iters':>7s} {'residual':>9s} "
              f"{'dev/direct':>10s} {'peak MiB':>9s}")
        for name, fn in runs:
            sol, dt, peak = timed(fn)
            if ref is None:
                ref = sol.radiance
            dev = np.abs(sol.radiance - ref).max() / np.abs(ref).max()
            print(f"{name:26s} {dt:8.3f} {sol.iterations:7d} {sol.residual:9.2e} "
                  f"{dev:10.2e} {peak / 2**20:9.1f}")
        del F

        if args.free:
            s2 = BakeSettings(patch_size=100.0, resolution=args.res, tolerance=args.tol,
                              memory_budget=1 << 20)
            r2 = bake(scene, s2)
            t2 = r2.report["timings"]
            print(f"matrix-free bake: total {t2['total']:.2f} s (form factors "
                  f"{t2['form_factors']:.2f}, solve {t2['solve']:.2f}), "
                  f"{r2.report['iterations']} shots, cache "
                  f"{r2.report['matrix_bytes'] / 2**20:.1f} MiB")

    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    print(f"\npeak resident size of the process: {rss / 1024:.0f} MiB")


if __name__ == "__main__":
    main()
