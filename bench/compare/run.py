"""The speed-against-accuracy sweep: our engine, Cycles and Radiance on the sample scenes.

Run (Blender's Python environment, from the repository root)::

    .venv/bin/python -m bench.compare.run                 # full sweep, every scene
    .venv/bin/python -m bench.compare.run --quick         # CI-sized: small sweep, fewer samples
    .venv/bin/python -m bench.compare.run --scenes office --cycles-samples 16 64 256

Writes ``bench/results/<scene>.csv`` (one row per run) and ``bench/results/<scene>.png`` (error
against wall time, log-log, one curve per method and one for Cycles, Pareto front marked), and
``bench/results/<scene>_radiance.csv`` (illuminance at sensor points: ours, Cycles', Radiance's).

Reference: the mean of ``--reference-seeds`` Cycles seeds (default 2) at the largest sample count
of the run (its own noise is estimated from the seeds' spread and written in the CSV as the
``reference`` row: the error of any run cannot be measured below it). Error: area-weighted
relative RMS of per-face luminance (face = mean of its corners), emitters excluded, and the 95th
percentile (bench/compare/metrics.py).
"""

import argparse
import csv
import resource
import time
import threading
from pathlib import Path

import numpy as np

from . import cycles, metrics, radiance

ROOT = Path(__file__).resolve().parents[2]
SCENES = ("office", "apartment", "cornell_box")

FIELDS = ["scene", "engine", "label", "method", "solver", "patch_size", "resolution", "samples", "seed",
          "patches", "t_patches", "t_form_factors", "t_solve", "t_colours", "t_total", "cpu",
          "peak_mb", "rms", "rms_denoised", "p95", "bias", "faces", "rms_patch", "p95_patch"]


class PeakRSS:
    """Peak resident memory above the starting level during a ``with`` block, in MiB.

    Sampled from /proc/self/statm every 5 ms by a thread. Not tracemalloc: tracing every NumPy
    allocation slowed our bakes about 2x, which would have biased the timing against us.
    """

    def __init__(self, interval=0.005):
        self.interval = interval
        self.peak_mb = float("nan")

    @staticmethod
    def _rss():
        try:
            with open("/proc/self/statm") as f:
                return int(f.read().split()[1]) * 4096
        except OSError:
            return 0

    def __enter__(self):
        self._stop = threading.Event()
        self._base = self._peak = self._rss()

        def watch():
            while not self._stop.wait(self.interval):
                self._peak = max(self._peak, self._rss())
        self._thread = threading.Thread(target=watch, daemon=True)
        self._thread.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        self._thread.join()
        self._peak = max(self._peak, self._rss())
        self.peak_mb = (self._peak - self._base) / 2 ** 20
        return False


def _cpu_seconds():
    """User + system CPU seconds of this process, all threads (Cycles' render threads included):
    on a loaded machine this moves far less than wall time, so both engines are also compared
    by it."""
    use = resource.getrusage(resource.RUSAGE_SELF)
    return use.ru_utime + use.ru_stime


def our_sweep(face_size, args):
    """BakeSettings keyword sets of our engine's runs.

    Patch sizes are given as multiples of the scene's face size (patches never exceed faces:
    ``1`` = one patch per face). Every (patch size, resolution) runs the hemicube with the default
    solver; the first patch size also runs 'hybrid' and 'exact' and every listed solver at R = 64.
    """
    sizes = [face_size * k for k in args.patch_sizes]
    runs = []
    for ps in sizes:
        for R in args.resolutions:
            runs.append(("hemicube, patch %.2f m" % ps,
                         dict(patch_size=ps, method="hemicube", resolution=R)))
    for method in args.methods:
        runs.append(("%s, %d rays" % (method, args.rays),
                     dict(patch_size=sizes[0], method=method, resolution=64, rays=args.rays)))
    for solver in args.solvers:
        runs.append(("hemicube R64, %s" % solver,
                     dict(patch_size=sizes[0], method="hemicube", resolution=64, solver=solver)))
    # Receiver elements (default 2 levels) against fewer.
    for levels in args.element_levels:
        runs.append(("hemicube R64, elements %d" % levels,
                     dict(patch_size=sizes[0], method="hemicube", resolution=64,
                          element_levels=levels)))
    # Contact cuts (default on) against none.
    if not args.no_contact_run:
        runs.append(("hemicube R64, no contact cuts",
                     dict(patch_size=sizes[0], method="hemicube", resolution=64,
                          contact_cuts=False)))
    # Corner colours: the final gather (default) against the patch average it replaced, and
    # adaptive refinement from twice the face size.
    runs.append(("hemicube R64, corners averaged",
                 dict(patch_size=sizes[0], method="hemicube", resolution=64, corners="average")))
    for levels in args.refine_levels:
        runs.append(("hemicube R64, refine %d from 2x" % levels,
                     dict(patch_size=2 * sizes[0], method="hemicube", resolution=64,
                          refine_levels=levels, refine_threshold=0.25)))
    return runs


def _face_size(arrays):
    V = arrays["vertices"]
    cv = arrays["corner_verts"]
    nxt = np.arange(len(cv)) + 1
    ends = arrays["face_starts"] + arrays["face_sizes"]
    nxt[np.isin(nxt, ends)] = np.repeat(arrays["face_starts"], arrays["face_sizes"])[
        np.isin(nxt, ends)]
    return float(np.linalg.norm(V[cv[nxt]] - V[cv], axis=1).max())


#: A sensor face must face up within this cosine (8 degrees): Radiance is asked for the
#: irradiance on a horizontal plane, so a tilted or vertical face must not qualify.
UP_COSINE = 0.99

#: Sensors keep this fraction of the scene's diagonal from every vertex of a surface that does
#: not face up (walls, block sides): 4.7 cm in the Cornell box, 0.39 m in the office.
WALL_CLEARANCE = 0.05


def sensor_points(arrays, count, rng):
    """Floor and desk-top vertices with every face around them horizontal and facing up, at
    least WALL_CLEARANCE x the scene diagonal from any other surface's vertex:
    (S,) vertex ids (emitters and faces above 1 m excluded)."""
    V = arrays["vertices"]
    cv = arrays["corner_verts"]
    face = np.repeat(np.arange(len(arrays["face_starts"])), arrays["face_sizes"])
    Vf = V[cv]
    # Newell normal of each face from its corners (all three components: a wall tilted by a
    # hair has a positive z component too).
    nxt = np.arange(len(cv)) + 1
    ends = arrays["face_starts"] + arrays["face_sizes"]
    wrap = np.isin(nxt, ends)
    nxt[wrap] = np.repeat(arrays["face_starts"], arrays["face_sizes"])[wrap]
    cross = np.cross(Vf, Vf[nxt])
    n = np.stack([np.bincount(face, weights=cross[:, k], minlength=len(arrays["face_starts"]))
                  for k in range(3)], axis=1)
    length = np.linalg.norm(n, axis=1)
    nz = np.divide(n[:, 2], length, out=np.zeros_like(length), where=length > 0)
    emitting = np.any(arrays["emission"] > 0, axis=1)[arrays["face_materials"]]
    up_face = (nz > UP_COSINE) & ~emitting
    ok_vertex = np.zeros(len(V), bool)
    ok_vertex[cv[up_face[face]]] = True
    ok_vertex[cv[~up_face[face]]] = False
    ok_vertex &= V[:, 2] < 1.0
    # Away from other surfaces: a vertex on the edge where the floor meets a wall (separate
    # objects share no vertex) has an irradiance that depends on which side of the crease it is
    # evaluated, and each program evaluates it differently.
    other = np.unique(cv[~up_face[face] & ~emitting[face]])
    diag = float(np.linalg.norm(V[cv].max(0) - V[cv].min(0)))
    cand = np.flatnonzero(ok_vertex)
    if other.size and cand.size:
        near = np.zeros(cand.size, bool)
        for a in range(0, cand.size, 512):
            d = np.linalg.norm(V[cand[a:a + 512], None, :] - V[None, other, :], axis=2)
            near[a:a + 512] = d.min(axis=1) < WALL_CLEARANCE * diag
        cand = cand[~near]
    if len(cand) > count:
        cand = np.sort(rng.choice(cand, count, replace=False))
    return cand


def vertex_values(arrays, corner_colours, vertices):
    """Mean corner colour at each given vertex: (S, 3)."""
    cv = arrays["corner_verts"]
    sums = np.zeros((len(arrays["vertices"]), 3))
    np.add.at(sums, cv, corner_colours)
    cnt = np.bincount(cv, minlength=len(arrays["vertices"]))
    return sums[vertices] / cnt[vertices, None]


def run_scene(name, blend, args, rng):
    from core.bake import BakeSettings, bake
    from core.scene import make_scene

    sc = cycles.load(blend)
    arrays = cycles.extract(sc)
    scene = make_scene(**arrays)
    F = len(arrays["face_starts"])
    emitter = np.any(arrays["emission"] > 0, axis=1)[arrays["face_materials"]]
    keep = ~emitter & scene.face_valid
    area = scene.face_areas
    rows = []

    def record(row, cc):
        """Measure ``cc`` against the reference, keep and print the row; returns face values."""
        fv = metrics.face_values(cc, arrays["face_starts"], arrays["face_sizes"])
        row.update(metrics.relative_errors(fv, ref_faces, area, keep))
        # The reference's own noise adds in quadrature to a run's error (independent of it);
        # this is the run's error with it taken out (not for the seeds inside the reference).
        row["rms_denoised"] = float(np.sqrt(max(row["rms"] ** 2 - noise["rms"] ** 2, 0.0)))
        row["scene"] = name
        rows.append(row)
        print("  %-8s %-12s %-8s R=%-4s ps=%-5s spp=%-5s t=%8.2fs rms=%s" % (
            row["engine"], row.get("method", ""), row.get("solver", ""),
            row.get("resolution", ""), row.get("patch_size", ""), row.get("samples", ""),
            row["t_total"], "%.4f (%.4f without the reference noise)" % (
                row["rms"], row["rms_denoised"])), flush=True)
        return fv

    # Cycles: every sample count, two seeds; the reference is the mean of the top count's seeds.
    samples = sorted(args.cycles_samples)
    cyc = {}
    cache = Path(args.out) / "cache"
    cache.mkdir(exist_ok=True)
    stamp = "%s_%d" % (name, int(Path(blend).stat().st_mtime))
    top = samples[-1]
    n_ref = args.reference_seeds
    for spp in samples:
        for seed in range(n_ref if spp == top else 2):
            # Cycles bakes are cached per (.blend mtime, samples, seed): a rerun of the sweep
            # (e.g. after a core change) does not pay for the reference again. Delete the
            # cache folder to re-time Cycles.
            f = cache / ("%s_cycles_%d_%d.npz" % (stamp, spp, seed))
            if f.exists() and not args.no_cache:
                z = np.load(f)
                cpu = float(z["cpu"]) if "cpu" in z.files else float("nan")
                cyc[spp, seed] = (z["cc"], float(z["seconds"]), cpu)
                continue
            cpu = _cpu_seconds()
            cc, sec = cycles.bake(sc, spp, seed=seed, threads=args.threads)
            cpu = _cpu_seconds() - cpu
            np.savez(f, cc=cc, seconds=sec, cpu=cpu)
            cyc[spp, seed] = (cc, sec, cpu)
    # The reference: the mean of the top count's seeds; its noise from their spread.
    ref_cc = np.mean([cyc[top, seed][0] for seed in range(n_ref)], axis=0)
    seed_faces = [metrics.face_values(cyc[top, seed][0], arrays["face_starts"],
                                      arrays["face_sizes"]) for seed in range(n_ref)]
    ref_faces = np.mean(seed_faces, axis=0)     # face values are linear in the corners
    noise = metrics.reference_noise(seed_faces, area, keep)
    rows.append(dict(scene=name, engine="reference", method="cycles-%dseeds" % n_ref,
                     samples=top, t_total=sum(cyc[top, s][1] for s in range(n_ref)),
                     rms=noise["rms"], p95=noise["p95"], bias=0.0, faces=noise["faces"]))
    print("  reference noise (%d seeds at %d spp): %.4f rms" % (n_ref, top, noise["rms"]))
    # Only seeds 0 and 1 are runs of the sweep; the others only sharpen the reference.
    cyc = {key: value for key, value in cyc.items() if key[1] < 2}
    for (spp, seed), (cc, sec, cpu) in sorted(cyc.items()):
        record(dict(engine="cycles", method="path", samples=spp, seed=seed, t_total=sec,
                    cpu=cpu, patches=F), cc)

    face_size = _face_size(arrays) * (1 + 1e-6)
    best = None
    for label, kw in our_sweep(face_size, args):
        if args.memory_budget_gb is not None:
            kw = dict(kw, memory_budget=int(args.memory_budget_gb * 2 ** 30))
        settings = BakeSettings(**kw)
        with PeakRSS() as mem:
            t0, cpu = time.perf_counter(), _cpu_seconds()
            res = bake(scene, settings)
            wall, cpu = time.perf_counter() - t0, _cpu_seconds() - cpu
        peak = mem.peak_mb
        tm = res.report["timings"]
        row = dict(engine="ours", label=label, method=kw["method"], solver=res.report["solver"],
                   patch_size=kw["patch_size"], resolution=kw.get("resolution", ""),
                   patches=res.report["patches"], t_patches=tm.get("patches"),
                   t_form_factors=tm.get("form_factors"), t_solve=tm.get("solve"),
                   t_colours=tm.get("colours"), t_total=wall, cpu=cpu, peak_mb=peak)
        # Diagnostic: the same error with our per-face value taken from the patches (area mean of
        # the face's patches) instead of the mean of corner colours, which average patches of
        # neighbouring faces: separates solver/form-factor error from corner interpolation.
        pf = res.patches.face
        pa = res.patches.areas
        fm = np.stack([np.bincount(pf, weights=pa * res.patch_radiance[:, k], minlength=F)
                       for k in range(3)], axis=1)
        fa = np.bincount(pf, weights=pa, minlength=F)
        fm = fm / np.where(fa > 0, fa, 1.0)[:, None]
        e = metrics.relative_errors(fm, ref_faces, area, keep & (fa > 0))
        row.update(rms_patch=e["rms"], p95_patch=e["p95"])
        fv = record(row, res.corner_colours)
        if label.startswith("hemicube, ") and kw.get("resolution") == 64:
            c = metrics.concentration(fv, ref_faces, area, keep)
            names = sorted({str(arrays["object_names"][arrays["face_objects"][f]])
                            for f in c["faces"]}) if "object_names" in arrays else []
            print("    the 20 worst faces (%.1f %% of the area; objects %s) carry %.0f %% of the "
                  "mean square; RMS over the rest %.2f %%"
                  % (100 * c["area"], ", ".join(names), 100 * c["share"], 100 * c["rms_rest"]))
        if best is None or row["rms"] < best[0]["rms"]:
            best = (row, res.corner_colours)

    # Radiance: illuminance at floor / desk-top sensor points.
    sensors = sensor_points(arrays, args.sensors, rng)
    normals = np.tile([0.0, 0.0, 1.0], (len(sensors), 1))
    params = list(radiance.ACCURATE)
    if args.quick:
        params[params.index("-ad") + 1] = "2048"
    E_rad, t_rad = radiance.irradiance(arrays, arrays["vertices"][sensors], normals,
                                       params=params, nproc=args.threads)
    face_of_corner = np.repeat(np.arange(F), arrays["face_sizes"])
    rho_v = np.zeros((len(arrays["vertices"]), 3))
    rho_v[arrays["corner_verts"]] = arrays["reflectance"][arrays["face_materials"][face_of_corner]]
    rho_s = rho_v[sensors]
    E_ours = np.pi * vertex_values(arrays, best[1], sensors) / rho_s
    E_cyc = np.pi * vertex_values(arrays, ref_cc, sensors) / rho_s
    lum = metrics.luminance
    with open(Path(args.out) / ("%s_radiance.csv" % name), "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["x", "y", "z", "E_radiance", "E_ours", "E_cycles"])
        for k, v in enumerate(sensors):
            w.writerow(["%.3f" % c for c in arrays["vertices"][v]]
                       + ["%.5f" % lum(x[k:k + 1])[0] for x in (E_rad, E_ours, E_cyc)])
    # A sensor Radiance sees in the dark (inside a block's footprint) has no relative error.
    lit = lum(E_rad) > 1e-3 * np.median(lum(E_rad))
    ratio_ours = lum(E_ours[lit]) / lum(E_rad[lit]) - 1
    ratio_cyc = lum(E_cyc[lit]) / lum(E_rad[lit]) - 1
    rad_row = dict(scene=name, engine="radiance", method="rtrace -I", samples=len(sensors),
                   t_total=t_rad, rms=float(np.sqrt(np.mean(ratio_ours ** 2))),
                   bias=float(np.mean(ratio_ours)),
                   p95=float(np.percentile(np.abs(ratio_ours), 95)), faces=len(sensors))
    rows.append(rad_row)
    rows.append(dict(scene=name, engine="radiance-vs-cycles", method="rtrace -I",
                     samples=len(sensors), t_total=t_rad,
                     rms=float(np.sqrt(np.mean(ratio_cyc ** 2))), bias=float(np.mean(ratio_cyc)),
                     p95=float(np.percentile(np.abs(ratio_cyc), 95)), faces=len(sensors)))
    print("  Radiance (%d lit sensors, %.0f s): ours %+.2f %% mean, %.2f %% rms; Cycles ref %+.2f %% "
          "mean, %.2f %% rms" % (int(lit.sum()), t_rad, 100 * np.mean(ratio_ours),
                                 100 * np.sqrt(np.mean(ratio_ours ** 2)),
                                 100 * np.mean(ratio_cyc), 100 * np.sqrt(np.mean(ratio_cyc ** 2))))
    return rows


def write_csv(rows, path):
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=FIELDS, extrasaction="ignore")
        w.writeheader()
        for r in rows:
            w.writerow({k: ("%.6g" % v if isinstance(v, float) else v)
                        for k, v in r.items() if k in FIELDS})


def chart(rows, path, title):
    """Error vs wall time, log-log: a curve per method (ours) and Cycles; Pareto front marked."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    runs = [r for r in rows if r["engine"] in ("ours", "cycles") and r.get("rms", 0) > 0]
    fig, ax = plt.subplots(figsize=(7.5, 5.2))
    groups = {}
    for r in runs:
        key = "Cycles (seed %d)" % r["seed"] if r["engine"] == "cycles" else r["label"]
        groups.setdefault(key, []).append(r)
    for key, rs in sorted(groups.items()):
        rs = sorted(rs, key=lambda r: r["t_total"])
        style = "o-" if "Cycles" in key else "s--" if key.startswith("hemicube, ") else "D"
        ax.plot([r["t_total"] for r in rs], [100 * r["rms"] for r in rs], style, label=key, ms=5)
        for r in rs:
            tag = ("%d spp" % r["samples"]) if r["engine"] == "cycles" else (
                "R%s" % r["resolution"] if r["label"].startswith("hemicube, ") else "")
            if "seed 1" not in key:
                ax.annotate(tag, (r["t_total"], 100 * r["rms"]), fontsize=6,
                            xytext=(3, 3), textcoords="offset points")
    t = np.array([r["t_total"] for r in runs])
    e = np.array([r["rms"] for r in runs])
    front = metrics.pareto_front(t, e)
    ax.plot(t[front], 100 * e[front], "-", color="k", lw=2.5, alpha=0.25, label="Pareto front")
    ref = [r for r in rows if r["engine"] == "reference"]
    if ref:
        ax.axhline(100 * ref[0]["rms"], color="grey", ls=":", label="reference noise")
    for level in (5, 2):
        ax.axhline(level, color="r", lw=0.6, ls="-.")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("wall time (s, 2 cores)")
    ax.set_ylabel("area-weighted relative RMS error (%)")
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, loc="lower left")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def summary(rows):
    """At 5 % and 2 %: least time of ours and of Cycles (seed 0 and 1 pooled) and the speed-up."""
    out = {}
    ours = [r for r in rows if r["engine"] == "ours"]
    cyc = [r for r in rows if r["engine"] == "cycles"]
    for level in (0.05, 0.02):
        to = metrics.time_to_reach([r["t_total"] for r in ours], [r["rms"] for r in ours], level)
        tc = metrics.time_to_reach([r["t_total"] for r in cyc], [r["rms"] for r in cyc], level)
        out[level] = (to, tc, tc / to if np.isfinite(to) and np.isfinite(tc) else float("nan"))
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description="Speed against accuracy: ours, Cycles, Radiance.")
    ap.add_argument("--scenes", nargs="+", default=["office", "apartment"], choices=SCENES)
    ap.add_argument("--blend-dir", default=str(ROOT / "bench" / "blends"),
                    help="folder of <scene>.blend files (the pre-meshed copies: per-face "
                         "comparison with Cycles needs small faces)")
    ap.add_argument("--quick", action="store_true", help="CI-sized sweep (minutes)")
    ap.add_argument("--cycles-samples", nargs="+", type=int, default=None)
    ap.add_argument("--resolutions", nargs="+", type=int, default=None)
    ap.add_argument("--patch-sizes", nargs="+", type=float, default=None,
                    help="patch sizes as multiples of the face size (1 = one patch per face)")
    ap.add_argument("--methods", nargs="*", default=None, help="besides hemicube: exact, hybrid")
    ap.add_argument("--solvers", nargs="*", default=None,
                    help="solvers to run at R = 64 besides 'auto'")
    ap.add_argument("--refine-levels", nargs="*", type=int, default=None,
                    help="adaptive refinement levels to run (from twice the face size)")
    ap.add_argument("--element-levels", nargs="*", type=int, default=None,
                    help="receiver element levels to run besides the default (R = 64)")
    ap.add_argument("--sensors", type=int, default=40, help="Radiance sensor points per scene")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--memory-budget-gb", type=float, default=None,
                    help="memory_budget of our bakes in GiB (default: BakeSettings' 1 GiB; the "
                         "apartment needs ~4 for a dense solve instead of matrix-free shooting)")
    ap.add_argument("--rays", type=int, default=16,
                    help="visibility rays per patch pair of the exact and hybrid runs")
    ap.add_argument("--no-contact-run", action="store_true",
                    help="skip the run without contact cuts")
    ap.add_argument("--reference-seeds", type=int, default=2,
                    help="Cycles seeds at the top sample count averaged into the reference "
                         "(>= 2; the noise of their mean is estimated from their spread)")
    ap.add_argument("--no-cache", action="store_true", help="re-bake Cycles even if cached")
    ap.add_argument("--out", default=str(ROOT / "bench" / "results"))
    ap.add_argument("--seed", type=int, default=0, help="seed of the sensor choice")
    args = ap.parse_args(argv)
    if args.cycles_samples is None:
        args.cycles_samples = [16, 64, 256] if args.quick else [16, 64, 256, 1024, 4096]
    full = not args.quick
    if args.resolutions is None:
        args.resolutions = [32, 64, 128, 256] if full else [32, 64]
    if args.patch_sizes is None:
        args.patch_sizes = [1.0, 0.5] if full else [1.0]
    if args.methods is None:
        args.methods = ["hybrid", "exact"] if full else []
    if args.solvers is None:
        args.solvers = ["jacobi", "gauss_seidel", "progressive"] if full else []
    if args.refine_levels is None:
        args.refine_levels = [1, 2] if full else []
    if args.element_levels is None:
        args.element_levels = [0, 1] if full else [0]
    if any(s < 1 for s in args.cycles_samples):
        ap.error("--cycles-samples must be >= 1")
    if args.reference_seeds < 2:
        ap.error("--reference-seeds must be >= 2 (the reference's noise comes from their spread)")
    Path(args.out).mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(args.seed)
    t_start = time.perf_counter()
    for name in args.scenes:
        blend = Path(args.blend_dir) / ("%s.blend" % name)
        if not blend.exists():
            print("%s: %s missing (run scripts/make_%s.py with --face-size/--grid and --out/"
                  "--output %s); skipped" % (name, blend, name, blend))
            continue
        print("%s:" % name, flush=True)
        rows = run_scene(name, blend, args, rng)
        write_csv(rows, Path(args.out) / ("%s.csv" % name))
        chart(rows, Path(args.out) / ("%s.png" % name), "%s: error against wall time" % name)
        for level, (to, tc, x) in summary(rows).items():
            print("  at %.0f %%: ours %.1f s, Cycles %.1f s, speed-up %.1fx"
                  % (100 * level, to, tc, x))
    print("total %.0f s" % (time.perf_counter() - t_start))


if __name__ == "__main__":
    main()
