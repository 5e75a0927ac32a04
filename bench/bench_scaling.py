"""Scaling (issue 13 item 4): time per stage and peak memory from 2k to 100k output vertices.

The scenes are :func:`bench.interiors.suite`: rooms in a row joined by doorways, modelled one
quad per surface, with furniture, ceiling panels and point lights; each is baked to the
radiosity mesh (output_mode='mesh') at a vertex budget, so the output has that many vertices.
Three ways to run every size, each bake in a fresh process (its peak memory is its own):

- ``1``: one process;
- ``2``: two worker processes on this machine (``BakeSettings.workers=2``);
- ``dask``: a Dask LocalCluster of two single-threaded worker processes
  (``radiosity_addon/cluster.py``, as ``--scheduler local --workers 2`` in the batch).

The three bakes of a size run back to back and their outputs are compared bit for bit.

Run: ``.venv/bin/python bench/bench_scaling.py [--sizes 1:2000 2:5000 ...] [--modes 1 2 dask]``.
Prints a line per bake, writes ``bench/results/scaling.csv`` and the log-log chart
``bench/results/scaling.png`` (time per stage and peak memory against output vertices).
``--from-csv A.csv B.csv`` writes them from earlier runs' rows instead (a size or a mode run
apart), with no bake.
"""

import argparse
import csv
import hashlib
import importlib.util
import json
import os
import resource
import subprocess
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from bench.interiors import suite  # noqa: E402
from core import BakeSettings, bake, parallel  # noqa: E402

DEFAULT_SIZES = ("1:2000", "2:5000", "3:10000", "6:30000", "12:100000")
STAGES = ("patches", "lights", "form_factors", "solve", "colours")
RESULTS = os.path.join(ROOT, "bench", "results")


def _cluster():
    spec = importlib.util.spec_from_file_location(
        "radiosity_cluster", os.path.join(ROOT, "radiosity_addon", "cluster.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _peak_mb():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def one_bake(rooms, budget, mode):
    """Bake one size in this process; a dict of figures."""
    client = None
    if mode == "dask":
        cluster = _cluster()
        client = cluster.connect(workers=2)
        cluster.use(client, parallel)
    scene = suite(rooms)
    t0, c0 = time.perf_counter(), time.process_time()
    result = bake(scene, BakeSettings(workers=1 if mode == "1" else 2, vertex_budget=budget,
                                      min_element=0.02))
    seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
    if client is not None:
        workers_mb = max(client.run(_peak_mb).values())
        client.close()
        client.cluster.close()
    else:
        parallel.close()                   # reap the workers: their peak counts as children's
        workers_mb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    out = result.output
    digest = hashlib.sha256()
    for a in (out.vertices, out.corner_colours, result.corner_colours):
        digest.update(np.ascontiguousarray(a).tobytes())
    return dict(rooms=rooms, budget=budget, mode=mode, vertices=int(out.vertices.shape[0]),
                faces=int(out.face_sizes.size), patches=int(result.report["patches"]),
                seconds=seconds, stages=result.report["timings"], cpu=cpu,
                workers_cpu=result.report["workers"].get("cpu_seconds", 0.0),
                backend=result.report["workers"].get("backend", "local"),
                processes=result.report["workers"]["processes"], peak_mb=_peak_mb(),
                workers_peak_mb=0.0 if mode == "1" else workers_mb, digest=digest.hexdigest())


def chart(rows, path):
    """Log-log: seconds per stage (one process) and total per mode; peak memory."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax, am) = plt.subplots(1, 2, figsize=(12, 5))
    by_mode = {}
    for r in rows:
        by_mode.setdefault(r["mode"], []).append(r)
    styles = {"1": ("k", "1 process"), "2": ("C0", "2 workers"), "dask": ("C3", "Dask, 2 workers")}
    for mode, rs in by_mode.items():
        v = np.array([r["vertices"] for r in rs])
        colour, label = styles[mode]
        ax.loglog(v, [r["seconds"] for r in rs], "o-", color=colour, lw=2,
                  label=f"total, {label}")
        am.loglog(v, [r["peak_mb"] + (2 * r["workers_peak_mb"] if mode != "1" else 0)
                      for r in rs], "o-", color=colour, label=label)
    one = by_mode.get("1", next(iter(by_mode.values())))
    v = np.array([r["vertices"] for r in one])
    for k, stage in enumerate(("lights", "form_factors", "solve", "colours")):
        ax.loglog(v, [max(r["stages"].get(stage, 0.0), 1e-3) for r in one], "s--",
                  color=f"C{k + 4}", ms=4, label=f"{stage}, 1 process")
    t1 = one[-1]["seconds"]
    for power, style, name in ((1, ":", "∝ N"), (2, "-.", "∝ N²")):
        ax.loglog(v, t1 * (v / v[-1]) ** power, style, color="grey", lw=1, label=name)
    ax.axhline(600, color="r", lw=0.8)
    ax.text(v[0], 630, "goal: 10 min", color="r", fontsize=8)
    am.axhline(6144, color="r", lw=0.8)
    am.text(v[0], 6400, "goal: 6 GB", color="r", fontsize=8)
    ax.set(xlabel="output vertices", ylabel="seconds", title="Bake time against output size")
    am.set(xlabel="output vertices", ylabel="peak MB (bake + workers)",
           title="Peak memory against output size")
    ax.legend(fontsize=7)
    am.legend(fontsize=7)
    for a in (ax, am):
        a.grid(True, which="both", alpha=0.3)
    fig.suptitle("Generated suites of rooms (bench/bench_scaling.py), 2-core machine")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", nargs="+", default=list(DEFAULT_SIZES),
                        help="ROOMS:VERTEX_BUDGET pairs")
    parser.add_argument("--modes", nargs="+", default=["1", "2", "dask"],
                        choices=["1", "2", "dask"])
    parser.add_argument("--out", default=os.path.join(RESULTS, "scaling"),
                        help="CSV and PNG path without extension")
    parser.add_argument("--from-csv", nargs="+", metavar="CSV",
                        help="no bakes: write --out's CSV and chart from the rows of these "
                             "(runs of some sizes or modes each)")
    parser.add_argument("--one", nargs=3, metavar=("ROOMS", "BUDGET", "MODE"),
                        help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one:
        print(json.dumps(one_bake(int(args.one[0]), int(args.one[1]), args.one[2])))
        return
    if args.from_csv:
        write(sorted((r for path in args.from_csv for r in read_csv(path)),
                     key=lambda r: (r["vertices"], r["mode"])), args.out)
        return
    print(f"{'rooms':>5} {'mode':>5} {'patches':>7} {'vertices':>8} {'total s':>8} "
          + " ".join(f"{s[:9]:>9}" for s in STAGES)
          + f" {'cpu s':>7} {'wrk cpu s':>9} {'peak MB':>8} {'worker MB':>9}", flush=True)
    rows = []
    for size in args.sizes:
        rooms, budget = size.split(":")
        runs = {}
        for mode in args.modes:
            line = subprocess.run([sys.executable, __file__, "--one", rooms, budget, mode],
                                  check=True, capture_output=True,
                                  text=True).stdout.strip().splitlines()[-1]
            r = runs[mode] = json.loads(line)
            rows.append(r)
            print(f"{r['rooms']:>5} {mode:>5} {r['patches']:>7} {r['vertices']:>8} "
                  f"{r['seconds']:>8.1f} "
                  + " ".join(f"{r['stages'].get(s, 0.0):>9.1f}" for s in STAGES)
                  + f" {r['cpu']:>7.1f} {r['workers_cpu']:>9.1f} {r['peak_mb']:>8.0f} "
                  f"{r['workers_peak_mb']:>9.0f}", flush=True)
        digests = {m: r["digest"] for m, r in runs.items()}
        base = runs[args.modes[0]]["seconds"]
        print(f"      rooms {rooms}: " + ", ".join(f"{base / runs[m]['seconds']:.2f}x ({m})"
                                                   for m in args.modes[1:])
              + f"; outputs bit-identical: {len(set(digests.values())) == 1}", flush=True)
    write(rows, args.out)


def write(rows, out):
    """``out``.csv and ``out``.png of bake rows (one_bake's dicts)."""
    os.makedirs(os.path.dirname(out) or ".", exist_ok=True)
    with open(out + ".csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["rooms", "mode", "patches", "vertices", "faces", "seconds", *STAGES, "cpu",
                    "workers_cpu", "peak_mb", "workers_peak_mb", "digest"])
        for r in rows:
            w.writerow([r["rooms"], r["mode"], r["patches"], r["vertices"], r["faces"],
                        f"{r['seconds']:.2f}", *(f"{r['stages'].get(s, 0.0):.2f}" for s in STAGES),
                        f"{r['cpu']:.1f}", f"{r['workers_cpu']:.1f}", f"{r['peak_mb']:.0f}",
                        f"{r['workers_peak_mb']:.0f}", r["digest"][:16]])
    chart(rows, out + ".png")
    print(f"wrote {out}.csv and {out}.png")


def read_csv(path):
    """The rows of a CSV that :func:`write` wrote, as one_bake's dicts."""
    with open(path, newline="") as f:
        reader = csv.reader(f)
        head = next(reader)
        rows = []
        for line in reader:
            cells = dict(zip(head[:6], line[:6]))
            stages = dict(zip(STAGES, map(float, line[6:6 + len(STAGES)])))
            tail = dict(zip(head[6 + len(STAGES):], line[6 + len(STAGES):]))
            rows.append(dict(rooms=int(cells["rooms"]), mode=cells["mode"],
                             patches=int(cells["patches"]), vertices=int(cells["vertices"]),
                             faces=int(cells["faces"]), seconds=float(cells["seconds"]),
                             stages=stages, cpu=float(tail["cpu"]),
                             workers_cpu=float(tail["workers_cpu"]),
                             peak_mb=float(tail["peak_mb"]),
                             workers_peak_mb=float(tail["workers_peak_mb"]),
                             digest=tail["digest"]))
    return rows


if __name__ == "__main__":
    main()
