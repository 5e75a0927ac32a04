"""Coarse models (issue 9): the adaptive radiosity mesh against uniform subdivision and Cycles.

The question users ask: when I model a room as one polygon per wall, how far is the adaptive bake
from converged Cycles, how many vertices does it spend and how long does it take, against uniform
subdivision and against Cycles itself?

Run (Blender's Python environment, from the repository root)::

    .venv/bin/python -m bench.compare.coarse --scene cornell_box
    .venv/bin/python -m bench.compare.coarse --scene cornell_box --grids 0.2 0.1 0.05 0.025 \\
        --contrasts 0.05 0.2 --min-elements 0.1 --reference-seeds 4 --reference-samples 4096

* Reference: the mean of ``--reference-seeds`` Cycles bakes at ``--reference-samples`` of the
  pre-meshed copy ``bench/blends/<scene>.blend`` (its noise estimated from the seeds' spread:
  :func:`bench.compare.metrics.reference_noise`). Cycles bakes are cached in
  ``bench/results/cache`` under the names bench/compare/run.py uses (kept out of git).
* Adaptive: our bake of the coarse model ``sample_blends/<scene>.blend`` (``output_mode='mesh'``,
  defaults, then ``contrast`` / ``min_element`` variants, ``--exact-direct`` modes and
  ``--methods`` form-factor methods); the output field is sampled at the
  reference's corners (:func:`locate`, :func:`sample_field`).
* Uniform: our bake with ``output_mode='vertices'`` of copies meshed as grids of ``--grids`` metres
  (scripts/make_cornell_box.py, run with .venv-bpy42), patch size = grid; sampled the same way.
* Cycles: the 5 cm copy baked at ``--cycles-samples`` (seed 0), compared per corner directly.

Error: area-weighted relative RMS of per-face luminance over the reference's faces, emitters
excluded (bench/compare/metrics.py). Writes ``bench/results/<scene>_coarse.csv`` and
``bench/results/<scene>_coarse.png`` (error against output vertices and against wall time,
log-log).
"""

import argparse
import csv
import subprocess
import time
from pathlib import Path

import numpy as np

from . import cycles, metrics
from .run import _cpu_seconds

ROOT = Path(__file__).resolve().parents[2]

#: A reference corner is matched only to output triangles whose unit normal has at least this
#: cosine with the reference face's normal (8 degrees): at a crease the two faces through the
#: point differ by 90 degrees, so the right side is picked.
NORMAL_COS = 0.99

#: Largest distance (m) of a reference corner from the plane of the triangle it is matched to.
PLANE_TOL = 1e-3

#: A point is inside a triangle when its smallest barycentric coordinate is >= -BARY_TOL; the
#: points beyond it (none when the geometry is the same) are counted as misses and take the
#: nearest triangle's clamped value. Blender stores float32 coordinates: a grid corner of one
#: copy lies up to ~2e-6 (in barycentric units of a 2.5 cm triangle) off the edge of another's.
BARY_TOL = 1e-4

#: Each reference corner is looked up this fraction of the way from its vertex to its face's
#: centroid: where Cycles bakes a corner (inside its face). It matters only on discontinuities:
#: the office's floor corners at the foot of the shelving's end panels (x = 1.2 and 3.0) read
#: exactly 0 in all three 1024-spp references, in every channel -- Cycles sampled them under the
#: panel, not on the room side of it; sampled at the vertex itself, our field read the lit floor
#: there (those floor faces +104 % and +158 %), and a panel's inner face at the foot of a
#: shelf board took the covered side (-38 % and -41 %).
CORNER_INSET = 1e-3

#: Points x triangles per block of the vectorised search (memory ~ 8 arrays of this many floats).
BLOCK = 2_000_000

FIELDS = ["scene", "method", "label", "contrast", "min_element", "grid", "samples", "seed",
          "vertices", "faces", "t_total", "cpu", "rms", "rms_denoised", "p95", "bias",
          "faces_compared", "rms_rest", "worst_share", "worst_area", "misses"]

#: Faces set apart by the concentration measure of every row (``rms_rest``: the RMS without
#: them; ``worst_share``: their share of the mean square; ``worst_area``: their share of the area).
WORST = 20


def triangulate(face_starts, face_sizes):
    """Fan triangles of polygons laid out consecutively over corners.

    Parameters
    ----------
    face_starts, face_sizes : (F,) int
        First corner and corner count (>= 3) of every polygon.

    Returns
    -------
    tris : (T, 3) int64
        Corner indices (0, k+1, k+2 of each polygon: quads split 0-1-2 / 0-2-3).
    face : (T,) int64
        Polygon of every triangle.
    """
    starts = np.asarray(face_starts, dtype=np.int64)
    sizes = np.asarray(face_sizes, dtype=np.int64)
    if starts.shape != sizes.shape or starts.ndim != 1:
        raise ValueError("face_starts and face_sizes must be (F,) of equal length; got %s and %s"
                         % (starts.shape, sizes.shape))
    if np.any(sizes < 3):
        raise ValueError("face_sizes must be >= 3; face %d has %d corners"
                         % (int(np.argmin(sizes)), int(sizes.min())))
    n = sizes - 2
    face = np.repeat(np.arange(starts.size), n)
    k = np.arange(int(n.sum())) - np.repeat(np.cumsum(n) - n, n)
    s = starts[face]
    return np.stack([s, s + k + 1, s + k + 2], axis=1), face


def locate(vertices, corner_verts, face_starts, face_sizes, face_groups, points, normals, groups):
    """Find, for every query point, the mesh triangle it lies in and its barycentric weights.

    A point is searched only among the triangles of its own group (object) whose normal matches
    the point's normal within ``NORMAL_COS`` and whose plane passes within ``PLANE_TOL``; among
    those the triangle the point is deepest inside (largest smallest barycentric coordinate)
    wins, so a point on a shared edge takes either neighbour and a point on a crease the side
    its normal names.

    Parameters
    ----------
    vertices : (V, 3) float
        Mesh vertex positions (world, m).
    corner_verts : (C,) int
        Vertex of every mesh corner.
    face_starts, face_sizes : (F,) int
        Polygons (convex, fan-triangulated from their first corner).
    face_groups : (F,) int
        Group (object) of every polygon.
    points : (P, 3) float
        Query positions (world, m).
    normals : (P, 3) float
        Unit normal of the surface each point is taken on.
    groups : (P,) int
        Group of every point.

    Returns
    -------
    corners : (P, 3) int64
        Mesh corners of the matched triangle.
    weights : (P, 3) float64
        Barycentric weights over ``corners`` (>= 0, summing to 1; clamped for misses).
    miss : (P,) float64
        How far outside its triangle a point is (minus its smallest barycentric coordinate;
        <= BARY_TOL for a point inside).

    Raises
    ------
    ValueError
        When a point has no triangle of its group with a matching normal and plane.
    """
    V = np.asarray(vertices, dtype=np.float64)
    cv = np.asarray(corner_verts, dtype=np.int64)
    P = np.asarray(points, dtype=np.float64)
    N = np.asarray(normals, dtype=np.float64)
    g = np.asarray(groups, dtype=np.int64)
    fg = np.asarray(face_groups, dtype=np.int64)
    if P.ndim != 2 or P.shape[1] != 3 or N.shape != P.shape or g.shape != (P.shape[0],):
        raise ValueError("points (P, 3), normals (P, 3) and groups (P,) must agree; got %s, %s, %s"
                         % (P.shape, N.shape, g.shape))
    if fg.shape != np.shape(face_starts):
        raise ValueError("face_groups must have shape %s; got %s" % (np.shape(face_starts),
                                                                    fg.shape))
    tris, tface = triangulate(face_starts, face_sizes)
    A, B, C = (V[cv[tris[:, k]]] for k in range(3))
    e1, e2 = B - A, C - A
    n = np.cross(e1, e2)
    length = np.linalg.norm(n, axis=1)
    ok = length > 0
    n = n / np.where(ok, length, 1.0)[:, None]
    d00, d01, d11 = (np.einsum("ij,ij->i", x, y) for x, y in ((e1, e1), (e1, e2), (e2, e2)))
    denom = d00 * d11 - d01 * d01
    ok &= denom > 0
    tgroup = fg[tface]
    corners = np.zeros((P.shape[0], 3), np.int64)
    weights = np.zeros((P.shape[0], 3))
    miss = np.zeros(P.shape[0])
    for grp in np.unique(g):
        t = np.flatnonzero((tgroup == grp) & ok)
        pts = np.flatnonzero(g == grp)
        if t.size == 0:
            raise ValueError("group %d: no mesh triangle for its %d points" % (grp, pts.size))
        # Per-triangle constants of the projection p -> (u, w) = weights of B and C.
        pe1 = np.einsum("ij,ij->i", A[t], e1[t])
        pe2 = np.einsum("ij,ij->i", A[t], e2[t])
        pn = np.einsum("ij,ij->i", A[t], n[t])
        step = max(1, BLOCK // t.size)
        for a in range(0, pts.size, step):
            p = pts[a:a + step]
            d20 = P[p] @ e1[t].T - pe1
            d21 = P[p] @ e2[t].T - pe2
            u = (d11[t] * d20 - d01[t] * d21) / denom[t]
            w = (d00[t] * d21 - d01[t] * d20) / denom[t]
            score = np.minimum(np.minimum(1.0 - u - w, u), w)
            valid = (N[p] @ n[t].T >= NORMAL_COS) & (np.abs(P[p] @ n[t].T - pn) <= PLANE_TOL)
            score = np.where(valid, score, -np.inf)
            best = np.argmax(score, axis=1)
            rows = np.arange(p.size)
            s = score[rows, best]
            if not np.all(np.isfinite(s)):
                bad = p[~np.isfinite(s)][0]
                raise ValueError("group %d: point %d at %s (normal %s) has no triangle with a "
                                 "matching normal and plane" % (grp, bad, P[bad], N[bad]))
            bw = np.stack([1.0 - u[rows, best] - w[rows, best], u[rows, best], w[rows, best]], 1)
            bw = np.clip(bw, 0.0, None)
            weights[p] = bw / bw.sum(axis=1, keepdims=True)
            corners[p] = tris[t[best]]
            miss[p] = -s
    return corners, weights, miss


def sample_field(corner_colours, corners, weights):
    """Interpolated colours: ``sum_k weights[:, k] * corner_colours[corners[:, k]]`` -> (P, 3)."""
    cc = np.asarray(corner_colours, dtype=np.float64)
    return np.einsum("pk,pkc->pc", weights, cc[corners])


def ref_queries(arrays, scene, names):
    """Query points of the reference's corners: positions (C, 3) (:data:`CORNER_INSET` inside
    their faces), normals (C, 3), groups (C,) (index into ``names`` of the corner's object)."""
    face = np.repeat(np.arange(len(arrays["face_starts"])), arrays["face_sizes"])
    obj = groups_of(arrays, names)
    pos = arrays["vertices"][arrays["corner_verts"]]
    centroid = np.stack([np.bincount(face, weights=pos[:, k]) for k in range(3)], axis=1)
    centroid /= np.asarray(arrays["face_sizes"])[:, None]
    pts = pos + CORNER_INSET * (centroid[face] - pos)
    return pts, scene.face_normals[face], obj[face]


def groups_of(arrays, names):
    """(F,) group of every face of ``arrays`` in the numbering of ``names`` (by object name)."""
    index = {name: i for i, name in enumerate(names)}
    missing = sorted(set(map(str, arrays["object_names"])) - set(index))
    if missing:
        raise ValueError("objects %s are not in the reference scene" % missing)
    return np.array([index[str(arrays["object_names"][o])] for o in arrays["face_objects"]])


def cycles_cached(name, blend, sc, spp, seed, cache, threads):
    """Corner colours, seconds and CPU seconds of a Cycles bake, cached as run.py caches them."""
    stamp = "%s_%d" % (name, int(Path(blend).stat().st_mtime))
    f = Path(cache) / ("%s_cycles_%d_%d.npz" % (stamp, spp, seed))
    if f.exists():
        z = np.load(f)
        cpu = float(z["cpu"]) if "cpu" in z.files else float("nan")
        return z["cc"], float(z["seconds"]), cpu
    cpu = _cpu_seconds()
    cc, sec = cycles.bake(sc, spp, seed=seed, threads=threads)
    cpu = _cpu_seconds() - cpu
    np.savez(f, cc=cc, seconds=sec, cpu=cpu)
    return cc, sec, cpu


#: Per scene: the generator's size option, its output option and the grid of the pre-meshed copy
#: in bench/blends (that size is not regenerated: it is the reference's own mesh).
GENERATORS = {"cornell_box": ("--grid", "--output", 0.05),
              "office": ("--face-size", "--out", 0.2),
              "apartment": ("--face-size", "--out", 0.13)}


def on_module(name, grid):
    """Whether a uniform ``grid`` (m) is on the module of the reference's pre-meshed copy: a
    multiple or a whole fraction of its grid. Such a copy's vertices are among the reference's
    corners (coarser) or include them all (finer, or the same), where its own colours are
    sampled with no interpolation; and the office is drawn on its 0.2 m module (every outline
    of its furniture lies on it), so such a copy also has edges along every contact line. A
    grid off the module (the office at 0.15, 0.25, 0.3 m) is what a user's uniform
    subdivision of a model gets."""
    module = GENERATORS[name][2]
    return any(abs(r - round(r)) < 1e-6 for r in (grid / module, module / grid))


#: Scenes whose bench/blends copy predates a fix of their generator (the apartment's: d0184d7
#: turned 7 door reveals to face the doorways): the reference is baked on a copy remade anew.
REMADE = ("apartment",)


def grid_blend(name, grid, cache, remake=False):
    """Path of the ``grid`` m copy (made if missing; bench/blends' at its grid unless remake)."""
    size_opt, out_opt, bench_grid = GENERATORS[name]
    if abs(grid - bench_grid) < 1e-9 and not remake:
        return ROOT / "bench" / "blends" / ("%s.blend" % name)
    path = Path(cache) / ("%s_grid%g.blend" % (name, grid))
    if not path.exists():
        script = ROOT / "scripts" / ("make_%s.py" % name)
        # bpy 4.2 may crash on exit after the file is saved (make_cornell_box.py: SIGSEGV,
        # 2026-11-26): the file is what counts.
        proc = subprocess.run([str(ROOT / ".venv-bpy42" / "bin" / "python"), str(script),
                               size_opt, str(grid), out_opt, str(path)], cwd=ROOT)
        if not path.exists():
            raise RuntimeError("%s did not write %s (exit status %d)" % (script.name, path,
                                                                        proc.returncode))
    return path


class Reference:
    """The converged Cycles reference of a pre-meshed copy and the measure against it."""

    def __init__(self, name, blend, args, lights=None, world=None):
        from core.scene import make_scene

        self.name, self.blend = name, blend
        self.sc = cycles.load(str(blend))
        self.arrays = cycles.extract(self.sc)
        self.scene = make_scene(**self.arrays, lights=lights, world=world)
        self.names = [str(s) for s in self.arrays["object_names"]]
        a = self.arrays
        emitter = np.any(a["emission"] > 0, axis=1)[a["face_materials"]]
        self.keep = ~emitter & self.scene.face_valid
        self.area = self.scene.face_areas
        self.queries = ref_queries(a, self.scene, self.names)
        seeds = [cycles_cached(name, blend, self.sc, args.reference_samples, s, args.cache,
                               args.threads) for s in range(args.reference_seeds)]
        faces = [self.faces(cc) for cc, _, _ in seeds]
        self.ref_faces = np.mean(faces, axis=0)
        self.noise = metrics.reference_noise(faces, self.area, self.keep)
        self.seconds = sum(sec for _, sec, _ in seeds)

    def faces(self, corner_colours):
        return metrics.face_values(corner_colours, self.arrays["face_starts"],
                                   self.arrays["face_sizes"])

    def measure(self, corner_colours):
        """Errors of colours at the reference's corners: rms, rms_denoised, p95, bias, faces."""
        fv = self.faces(corner_colours)
        e = metrics.relative_errors(fv, self.ref_faces, self.area, self.keep)
        c = metrics.concentration(fv, self.ref_faces, self.area, self.keep, top=WORST)
        out = dict(rms=e["rms"], p95=e["p95"], bias=e["bias"], faces_compared=e["faces"],
                   rms_denoised=float(np.sqrt(max(e["rms"] ** 2 - self.noise["rms"] ** 2, 0))),
                   rms_rest=c["rms_rest"], worst_share=c["share"], worst_area=c["area"])
        return out, fv

    def sample(self, vertices, corner_verts, face_starts, face_sizes, face_groups, colours):
        """Colours of a mesh's field at the reference's corners: ((C_ref, 3), misses)."""
        pts, nrm, grp = self.queries
        corners, weights, miss = locate(vertices, corner_verts, face_starts, face_sizes,
                                        face_groups, pts, nrm, grp)
        return sample_field(colours, corners, weights), int(np.sum(miss > BARY_TOL))

    def worst_faces(self, fv, top=8):
        """Lines on the ``top`` faces of largest area-weighted squared error: object, centre,
        reference and test luminance."""
        a = self.arrays
        idx, rel, ww = metrics._face_errors(fv, self.ref_faces, self.area, self.keep)
        face = np.repeat(np.arange(len(a["face_starts"])), a["face_sizes"])
        pos = a["vertices"][a["corner_verts"]]
        centre = np.stack([np.bincount(face, weights=pos[:, k]) for k in range(3)], 1)
        centre /= a["face_sizes"][:, None]
        lr = metrics.luminance(self.ref_faces)
        mean = np.sum(ww * lr[idx])
        lines = []
        for k in np.argsort(-ww * rel ** 2)[:top]:
            f = idx[k]
            lines.append("%s face %d at (%.3f, %.3f, %.3f): reference %.3f x the mean, "
                         "ours %+.0f %%" % (self.names[a["face_objects"][f]], f, *centre[f],
                                            lr[f] / mean, 100 * rel[k]))
        return lines

    def worst(self, fv, top=20):
        """One line on the ``top`` worst faces (metrics.concentration) and their objects."""
        c = metrics.concentration(fv, self.ref_faces, self.area, self.keep, top=top)
        objs = sorted({self.names[self.arrays["face_objects"][f]] for f in c["faces"]})
        return ("the %d worst faces (%.1f %% of the area; objects %s) carry %.0f %% of the mean "
                "square; RMS over the rest %.2f %%" % (top, 100 * c["area"], ", ".join(objs),
                                                        100 * c["share"], 100 * c["rms_rest"]))


def timed_bake(scene, **kw):
    from core.bake import BakeSettings, bake

    settings = BakeSettings(**kw)
    t0, cpu = time.perf_counter(), _cpu_seconds()
    res = bake(scene, settings)
    return res, time.perf_counter() - t0, _cpu_seconds() - cpu


def adaptive_runs(args):
    runs = [("adaptive (defaults)", {})]
    runs += [("adaptive contrast %g" % c, dict(contrast=c)) for c in args.contrasts]
    runs += [("adaptive min_element %g" % m, dict(min_element=m)) for m in args.min_elements]
    runs += [("adaptive emitters %s" % e, dict(exact_direct=e)) for e in args.exact_direct]
    runs += [("adaptive method %s" % m, dict(method=m)) for m in args.methods]
    if args.shadow_cuts:          # the other side of the default
        from core.settings import BakeSettings

        on = not BakeSettings().shadow_cuts
        runs.append(("adaptive %s shadow cuts" % ("with" if on else "without"),
                     dict(shadow_cuts=on)))
    return runs


def run(name, args):
    from core.scene import make_scene

    blend = Path(args.blend_dir) / ("%s.blend" % name)
    if name in REMADE:
        blend = grid_blend(name, GENERATORS[name][2], args.cache, remake=True)
    ref = Reference(name, blend, args)
    rows = [dict(scene=name, method="reference", label="cycles %d seeds" % args.reference_seeds,
                 samples=args.reference_samples, vertices=len(ref.arrays["vertices"]),
                 faces=len(ref.arrays["face_starts"]), t_total=ref.seconds,
                 rms=ref.noise["rms"], p95=ref.noise["p95"], faces_compared=ref.noise["faces"])]
    print("%s: reference noise (%d seeds at %d spp) %.4f rms" % (
        name, args.reference_seeds, args.reference_samples, ref.noise["rms"]), flush=True)
    notes = {}

    def record(row, cc):
        err, fv = ref.measure(cc)
        row.update(err, scene=name)
        rows.append(row)
        print("  %-28s V=%-7d t=%7.2fs rms=%.4f (%.4f without the reference noise; %.4f without "
              "the %d worst faces) misses=%s"
              % (row["label"], row["vertices"], row["t_total"], row["rms"], row["rms_denoised"],
                 row["rms_rest"], WORST, row.get("misses", "")), flush=True)
        return fv

    # Cycles on the pre-meshed copy itself: its corners are the reference's.
    for spp in args.cycles_samples:
        cc, sec, cpu = cycles_cached(name, ref.blend, ref.sc, spp, 0, args.cache, args.threads)
        record(dict(method="cycles", label="cycles %d spp" % spp, samples=spp, seed=0,
                    vertices=len(ref.arrays["vertices"]), faces=len(ref.arrays["face_starts"]),
                    t_total=sec, cpu=cpu), cc)

    # Adaptive: the coarse model.
    sc = cycles.load(str(Path(args.coarse_dir) / ("%s.blend" % name)))
    arrays = cycles.extract(sc)
    scene = make_scene(**arrays)
    fgroups = groups_of(arrays, ref.names)
    for label, kw in adaptive_runs(args):
        res, wall, cpu = timed_bake(scene, output_mode="mesh", **kw)
        m = res.output
        cc, misses = ref.sample(m.vertices, m.corner_verts, m.face_starts, m.face_sizes,
                                fgroups[m.face_parent], m.corner_colours)
        fv = record(dict(method="adaptive", label=label, contrast=kw.get("contrast", ""),
                         min_element=kw.get("min_element", ""), vertices=len(m.vertices),
                         faces=len(m.face_starts), t_total=wall, cpu=cpu, misses=misses), cc)
        worst, faces = ref.worst(fv), ref.worst_faces(fv, top=8 if not kw else 4)
        print("    " + worst)
        for line in faces:
            print("      " + line)
        if not kw:
            notes["worst"], notes["faces"] = worst, faces
            notes["input"] = (len(arrays["face_starts"]), len(arrays["vertices"]))

    # Uniform subdivision: pre-meshed copies, colours at their own corners.
    for grid in args.grids:
        sc = cycles.load(str(grid_blend(name, grid, args.cache)))
        ga = cycles.extract(sc)
        gs = make_scene(**ga)
        res, wall, cpu = timed_bake(gs, output_mode="vertices", patch_size=grid * (1 + 1e-6))
        cc, misses = ref.sample(ga["vertices"], ga["corner_verts"], ga["face_starts"],
                                ga["face_sizes"], groups_of(ga, ref.names), res.corner_colours)
        record(dict(method="uniform", label="uniform %g m" % grid, grid=grid,
                    vertices=len(ga["vertices"]), faces=len(ga["face_starts"]), t_total=wall,
                    cpu=cpu, misses=misses), cc)
    return rows, notes


def at_error(x, err, target):
    """The x (vertices or seconds) of a series at error ``target``, interpolated in log-log.

    Parameters
    ----------
    x, err : (n,) float
        The series' points (n >= 2; error assumed to fall as x grows).
    target : float

    Returns
    -------
    (value, how)
        ``how`` is 'interpolated' when two consecutive points (sorted by x) bracket the target,
        'extrapolated' when the line through the two nearest ends is used, 'none' (value nan)
        with fewer than two points or a non-falling end.
    """
    x = np.asarray(x, dtype=np.float64)
    e = np.asarray(err, dtype=np.float64)
    if x.size < 2:
        return float("nan"), "none"
    order = np.argsort(x)
    lx, le, lt = np.log(x[order]), np.log(e[order]), np.log(target)
    for i in range(lx.size - 1):
        lo, hi = sorted((le[i], le[i + 1]))
        if lo <= lt <= hi and le[i] != le[i + 1]:
            f = (lt - le[i]) / (le[i + 1] - le[i])
            return float(np.exp(lx[i] + f * (lx[i + 1] - lx[i]))), "interpolated"
    i = 0 if lt > le.max() else lx.size - 2
    if le[i + 1] >= le[i]:
        return float("nan"), "none"
    f = (lt - le[i]) / (le[i + 1] - le[i])
    return float(np.exp(lx[i] + f * (lx[i + 1] - lx[i]))), "extrapolated"


def summary(rows, key="rms"):
    """Figures of the README on error ``key`` ('rms', or 'rms_rest': without each run's WORST
    faces): error at defaults, uniform vertices and Cycles time at that error."""
    d = next(r for r in rows if r["label"] == "adaptive (defaults)")
    uni = [r for r in rows if r["method"] == "uniform"]
    off = [r for r in uni if not on_module(r["scene"], r["grid"])]
    cyc = [r for r in rows if r["method"] == "cycles"]
    vu, how_v = at_error([r["vertices"] for r in uni], [r[key] for r in uni], d[key])
    vo, how_o = at_error([r["vertices"] for r in off], [r[key] for r in off], d[key])
    tu, how_tu = at_error([r["t_total"] for r in uni], [r[key] for r in uni], d[key])
    tc, how_c = at_error([r["t_total"] for r in cyc], [r[key] for r in cyc], d[key])
    return dict(rms=d[key], rms_denoised=d["rms_denoised"], p95=d["p95"],
                vertices=d["vertices"], seconds=d["t_total"], uniform_vertices=vu,
                uniform_how=how_v, ratio=d["vertices"] / vu, uniform_seconds=tu,
                uniform_time_how=how_tu, off_vertices=vo, off_how=how_o,
                off_ratio=d["vertices"] / vo, cycles_seconds=tc, cycles_how=how_c,
                speedup=tc / d["t_total"])


def write_csv(rows, path):
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=FIELDS, extrasaction="ignore")
        w.writeheader()
        for r in rows:
            w.writerow({k: ("%.6g" % v if isinstance(v, float) else v) for k, v in r.items()})


def read_csv(path):
    """Rows of a CSV written by :func:`write_csv` (numbers as float, empty cells dropped)."""
    rows = []
    with open(path, newline="") as fh:
        for r in csv.DictReader(fh):
            row = {}
            for k, v in r.items():
                if v == "":
                    continue
                try:
                    row[k] = float(v)
                except ValueError:
                    row[k] = v
            rows.append(row)
    return rows


def main(argv=None):
    from .coarse_chart import chart

    ap = argparse.ArgumentParser(description="Coarse models: adaptive mesh vs uniform vs Cycles.")
    ap.add_argument("--scene", default="cornell_box", choices=sorted(GENERATORS))
    ap.add_argument("--blend-dir", default=str(ROOT / "bench" / "blends"),
                    help="folder of the pre-meshed <scene>.blend (the reference's mesh)")
    ap.add_argument("--coarse-dir", default=str(ROOT / "sample_blends"),
                    help="folder of the coarse <scene>.blend (one polygon per wall)")
    ap.add_argument("--reference-seeds", type=int, default=4)
    ap.add_argument("--reference-samples", type=int, default=4096)
    ap.add_argument("--cycles-samples", nargs="*", type=int, default=[64, 256, 1024])
    ap.add_argument("--grids", nargs="*", type=float, default=None,
                    help="uniform grid sizes (m); default Cornell box 0.2 0.1 0.05 0.025 (0.05 is "
                         "the reference's own mesh), office 0.8 0.4 0.2 (0.2 is)")
    ap.add_argument("--contrasts", nargs="*", type=float, default=[0.05, 0.2])
    ap.add_argument("--min-elements", nargs="*", type=float, default=[0.1, 0.025])
    ap.add_argument("--exact-direct", nargs="*", default=[], choices=["all", "off"],
                    help="also run these exact_direct modes (the default 'auto' always runs)")
    ap.add_argument("--methods", nargs="*", default=[],
                    help="also run these form-factor methods (core.settings.METHODS)")
    ap.add_argument("--shadow-cuts", action="store_true",
                    help="also bake with shadow_cuts the other way from its default "
                         "(core.footlines)")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--cache", default=str(ROOT / "bench" / "results" / "cache"))
    ap.add_argument("--out", default=str(ROOT / "bench" / "results"))
    ap.add_argument("--chart-only", action="store_true",
                    help="redraw the chart from the CSV of a previous run (no bake)")
    args = ap.parse_args(argv)
    base = Path(args.out) / ("%s_coarse" % args.scene)
    title = "%s, coarse model: error against vertices and time" % args.scene
    if args.chart_only:
        chart(read_csv(base.with_suffix(".csv")), base.with_suffix(".png"), title)
        return
    if args.grids is None:
        # The apartment's uniform copies cost ~1,000 s at 0.13 m: none unless --grids asks.
        args.grids = dict(cornell_box=[0.2, 0.15, 0.1, 0.075, 0.05, 0.035, 0.025],
                          office=[0.8, 0.4, 0.3, 0.25, 0.2, 0.15, 0.12, 0.1],
                          apartment=[])[args.scene]
    if args.reference_seeds < 2:
        ap.error("--reference-seeds must be >= 2 (the reference's noise comes from their spread)")
    if args.reference_samples in args.cycles_samples:
        ap.error("--cycles-samples must not contain --reference-samples (seed 0 of it is in "
                 "the reference)")
    for flag, path in (("--blend-dir", args.blend_dir), ("--coarse-dir", args.coarse_dir)):
        if not (Path(path) / ("%s.blend" % args.scene)).exists():
            ap.error("%s: %s/%s.blend does not exist" % (flag, path, args.scene))
    Path(args.cache).mkdir(parents=True, exist_ok=True)
    Path(args.out).mkdir(parents=True, exist_ok=True)
    rows, notes = run(args.scene, args)
    write_csv(rows, base.with_suffix(".csv"))
    chart(rows, base.with_suffix(".png"), title)
    for key, what in (("rms", "all faces"), ("rms_rest", "without each run's %d worst faces"
                                                 % WORST)):
        s = summary(rows, key)
        print("%s:" % what)
        print("  error at defaults: %.2f %% (%d vertices; input %d faces, %d vertices; %.1f s)"
              % (100 * s["rms"], s["vertices"], notes["input"][0], notes["input"][1],
                 s["seconds"]))
        print("  uniform at equal error: %.0f vertices (%s), %.1f s; adaptive/uniform vertices "
              "%.0f %%" % (s["uniform_vertices"], s["uniform_how"], s["uniform_seconds"],
                           100 * s["ratio"]))
        print("  uniform off the design module at equal error: %.0f vertices (%s); "
              "adaptive/uniform vertices %.0f %%" % (s["off_vertices"], s["off_how"],
                                                     100 * s["off_ratio"]))
        print("  Cycles (pre-meshed copy) at equal error: %.1f s (%s); adaptive time / Cycles "
              "time %.2f" % (s["cycles_seconds"], s["cycles_how"], 1.0 / s["speedup"]))
    print("worst faces at defaults: " + notes["worst"])
    for line in notes["faces"]:
        print("  " + line)


if __name__ == "__main__":
    main()
