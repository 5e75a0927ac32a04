"""Shared pieces of the stability report: the run context, bakes under a time cap, the fields of
the radiosity mesh, charts, and the lookup of the tests that guard each failure class."""

import importlib
import re
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from core import BakeSettings, bake
from core.adaptive import coarse_patch_size, min_element_size
from core.errors import BakeCancelled
from core.patches import make_patches
from core.rows import row_seconds
from core.settings import BY_NAME, METHODS

ROOT = Path(__file__).resolve().parents[2]

#: The engine's default form-factor method (read from the settings table, like every name here).
DEFAULT_METHOD = BY_NAME["method"].default

#: Errors below this are drawn at it on the log-scale charts (bit-identical results are 0).
CHART_FLOOR = 1e-7


def methods():
    """Names of the form-factor methods of core.settings.METHODS, read when called."""
    return tuple(choice.value for choice in METHODS)


#: Quick mode bounds the radiosity mesh (about 1 ms per gathered vertex) to stay near a minute.
QUICK_VERTEX_BUDGET = 600


@dataclass
class Context:
    """What every failure class gets: quick or full, where charts go, the per-run cap (s) of the
    non-default methods, and their cost record (one Gate for the whole run)."""

    quick: bool
    images: Path
    cap: float
    started: float = field(default_factory=time.perf_counter)
    gate: object = None

    def __post_init__(self):
        self.gate = Gate(self.cap)

    def pick(self, full, quick):
        return quick if self.quick else full

    def settings(self, **kw):
        """BakeSettings: the defaults with ``kw`` (quick mode: a smaller vertex budget)."""
        if self.quick:
            kw.setdefault("vertex_budget", QUICK_VERTEX_BUDGET)
        return BakeSettings(**kw)

    def log(self, text):
        print(f"[{time.perf_counter() - self.started:6.1f} s] {text}", flush=True)


@dataclass
class Run:
    """One bake: its result (None unless status is 'ok'), wall seconds and status."""

    result: object
    seconds: float
    status: str

    @property
    def ok(self):
        return self.status == "ok"


def run_bake(scene, settings, cap=None):
    """Bake; past ``cap`` seconds the bake is cancelled. Engine errors are recorded, not raised:
    an exception from the engine is a finding of this report."""
    t0 = time.perf_counter()
    cancel = None if cap is None else (lambda: time.perf_counter() - t0 > cap)
    try:
        result = bake(scene, settings, cancel=cancel)
    except BakeCancelled:
        return Run(None, time.perf_counter() - t0, f"too slow: cancelled after {cap:.0f} s")
    except Exception as exc:  # noqa: BLE001 - reported in the document
        return Run(None, time.perf_counter() - t0, f"error: {type(exc).__name__}: {exc}")
    return Run(result, time.perf_counter() - t0, "ok")


class Gate:
    """Runs of each form-factor method, skipped when predicted to exceed the cap.

    The prediction scales the method's last measured run by the engine's own cost model
    (``core.rows.row_seconds`` x 2P nodes on the bake's patches). The default method always
    runs, uncapped. A run cancelled at the cap counts as taking the cap: larger cases are then
    predicted over it and skipped.
    """

    def __init__(self, cap):
        self.cap = cap
        self.last = {}

    @staticmethod
    def cost(scene, settings):
        size = settings.patch_size
        if size is None:
            size = 0.5 if settings.output_mode == "vertices" else coarse_patch_size(scene)
        patches = make_patches(scene, size)
        # The radiosity mesh splits patches near emitters before the form factors (a private
        # step of core.bake: used when present, else the estimate counts the unsplit patches).
        split = getattr(importlib.import_module("core.bake"), "_split_near", None)
        if split is not None and settings.output_mode == "mesh":
            patches = split(scene, patches, min_element_size(scene, settings.min_element),
                            settings.emitter_levels)
        return row_seconds(patches, settings.method, settings.resolution, settings.rays) \
            * 2 * len(patches.areas)

    def run(self, scene, settings):
        method = settings.method
        if method == DEFAULT_METHOD:
            return run_bake(scene, settings)
        est = self.cost(scene, settings)
        if method in self.last:
            e0, t0 = self.last[method]
            predicted = t0 * est / max(e0, 1e-12)
            if predicted > self.cap:
                return Run(None, 0.0, f"too slow: predicted {predicted:.0f} s > {self.cap:.0f} s")
        run = run_bake(scene, settings, cap=self.cap)
        if run.ok or run.status.startswith("too slow"):
            self.last[method] = (est, run.seconds)
        return run


# ----------------------------------------------------------------------- fields of the mesh
def polygon_areas(mesh, faces):
    """(n,) areas of output faces ``faces`` (Newell's formula over their corners)."""
    out = np.zeros(len(faces))
    for k in np.unique(mesh.face_sizes[faces]):
        sel = np.flatnonzero(mesh.face_sizes[faces] == k)
        idx = mesh.face_starts[faces[sel]][:, None] + np.arange(k)[None]
        p = mesh.vertices[mesh.corner_verts[idx]]
        out[sel] = 0.5 * np.linalg.norm(np.cross(p, np.roll(p, -1, axis=1)).sum(axis=1), axis=1)
    return out


def corners_of(mesh, parents):
    """Output corners of the output faces lying in scene faces ``parents``."""
    faces = mesh.faces_of(np.asarray(parents))
    return np.concatenate([np.arange(s, s + n) for s, n in
                           zip(mesh.face_starts[faces], mesh.face_sizes[faces])]).astype(int)


def mesh_mean(mesh, parents, channel=None):
    """Area-weighted mean over scene faces ``parents`` of the written field (each output
    face: the mean of its corners, which is exact for a linear field on a triangle); one
    channel, or (None) the mean of the three."""
    faces = mesh.faces_of(np.asarray(parents))
    areas = polygon_areas(mesh, faces)
    col = mesh.corner_colours.mean(axis=1) if channel is None else mesh.corner_colours[:, channel]
    means = np.array([col[s:s + n].mean()
                      for s, n in zip(mesh.face_starts[faces], mesh.face_sizes[faces])])
    return float((areas * means).sum() / areas.sum())


def surface_means(result, scene, groups, names):
    """{name: written mean} over the named groups, and their area-weighted mean ('room')."""
    means = {g: mesh_mean(result.output, groups[g]) for g in names}
    areas = {g: float(scene.face_areas[groups[g]].sum()) for g in names}
    means["room"] = sum(means[g] * areas[g] for g in names) / sum(areas.values())
    return means


def surface_errors(means, ref, pairs):
    """(room error, worst surface error): |mean - ref| / ref's room mean, surfaces paired as
    (name in means, name in ref)."""
    room = abs(means["room"] - ref["room"]) / ref["room"]
    worst = max(abs(means[a] - ref[b]) for a, b in pairs) / ref["room"]
    return room, worst


def interpolate(mesh, parents, points, normal, channel=None):
    """The written field at ``points`` (S, 3) on the plane of scene faces ``parents`` (whose
    normal is ``normal``): linear over the triangles (0, k, k + 1) of their output faces, as a
    renderer reads it (one channel, or None: the mean of the three). NaN where no triangle
    holds the point."""
    col = mesh.corner_colours.mean(axis=1) if channel is None else mesh.corner_colours[:, channel]
    faces = mesh.faces_of(np.asarray(parents))
    tris = []
    for k in (1, 2):
        f = faces[mesh.face_sizes[faces] >= k + 2]
        s = mesh.face_starts[f]
        tris.append(np.stack([s, s + k, s + k + 1], axis=1))
    tris = np.concatenate(tris)
    keep = [a for a in range(3) if a != int(np.argmax(np.abs(normal)))]
    xy = mesh.vertices[mesh.corner_verts[tris]][:, :, keep]
    a, b, c = xy[:, 0], xy[:, 1], xy[:, 2]
    det = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])
    ok = np.abs(det) > 0
    a, b, c, det, tris = a[ok], b[ok], c[ok], det[ok], tris[ok]
    out = np.full(len(points), np.nan)
    for i, p in enumerate(np.asarray(points)[:, keep]):
        u = ((p[0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (p[1] - a[:, 1])) / det
        v = ((b[:, 0] - a[:, 0]) * (p[1] - a[:, 1]) - (p[0] - a[:, 0]) * (b[:, 1] - a[:, 1])) / det
        hit = np.flatnonzero((u >= -1e-9) & (v >= -1e-9) & (u + v <= 1 + 1e-9))
        if hit.size:
            t = hit[0]
            w = np.array([1 - u[t] - v[t], u[t], v[t]])
            out[i] = w @ col[tris[t]]
    return out


def rel_mean_abs(got, want):
    """mean |got - want| / mean |want|."""
    got, want = np.asarray(got, float), np.asarray(want, float)
    return float(np.mean(np.abs(got - want)) / np.mean(np.abs(want)))


# ----------------------------------------------------------------------- words and numbers
def pct(x, digits=3):
    """A fraction as a percentage with ``digits`` significant digits; '–' for None / NaN."""
    if x is None or not np.isfinite(x):
        return "–"
    if x == 0:
        return "0 %"
    return f"{100 * x:.{digits}g} %"


def secs(x):
    return "–" if x is None else f"{x:.1f} s" if x >= 1 else f"{x:.2f} s"


def table(header, rows):
    """A Markdown table."""
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def guard(spec):
    """'tests/core/test_x.py::test_y' (or a file) as Markdown code, '(not found)' if absent."""
    path, _, name = spec.partition("::")
    file = ROOT / path
    found = file.is_file() and (not name or re.search(rf"def {re.escape(name)}\b",
                                                      file.read_text()))
    return f"`{spec}`" + ("" if found else " (not found)")


def tests_named(pattern):
    """'file::test' of every test under tests/core whose name matches ``pattern`` (regex)."""
    out = []
    for file in sorted((ROOT / "tests" / "core").glob("test_*.py")):
        for name in re.findall(r"^def (test_\w+)", file.read_text(), flags=re.M):
            if re.search(pattern, name):
                out.append(f"{file.relative_to(ROOT)}::{name}")
    return out


# ----------------------------------------------------------------------- charts
def chart(path, title, xlabel=None, ylabel=None, series=(), *, ncols=1, panels=None, **kw):
    """Line chart(s) with markers, saved to ``path``.

    ``series``: (label, xs, ys) with ys None where not measured. ``kw``: logx, logy (default
    True), hlines / vlines ((value, label) pairs), percent (fractions drawn as %), xticks
    ((values, labels)), subtitle. ``panels``: a list of dicts of those keys (with xlabel,
    ylabel, series) for side-by-side charts under one title. Values below CHART_FLOOR on a
    log axis are drawn at it.
    """
    import matplotlib
    import matplotlib.ticker
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if panels is None:
        panels = [dict(xlabel=xlabel, ylabel=ylabel, series=series, **kw)]
    fig, axes = plt.subplots(1, len(panels), figsize=(6.4 * len(panels), 4.4), squeeze=False)
    for ax, p in zip(axes[0], panels):
        floored = False
        for i, (label, xs, ys) in enumerate(p["series"]):
            pts = [(x, y) for x, y in zip(xs, ys) if y is not None and np.isfinite(y)]
            if not pts:
                continue
            x, y = map(np.array, zip(*pts))
            y = y * (100.0 if p.get("percent") else 1.0)
            if p.get("logy", True):
                floored |= bool(np.any(y < CHART_FLOOR))
                y = np.maximum(y, CHART_FLOOR)
            # Later series drawn thinner and hollow: equal series stay visible.
            ax.plot(x, y, marker="os^vD<>ph*"[i % 10], linestyle=("-", "--", ":", "-.")[i % 4],
                    markersize=max(9 - 1.2 * i, 3), fillstyle="full" if i == 0 else "none",
                    label=label)
        for value, label in p.get("hlines", ()):
            value = value * (100.0 if p.get("percent") else 1.0)
            ax.axhline(value, color="grey", linestyle="--", linewidth=1)
            ax.annotate(label, (0.01, value), xycoords=("axes fraction", "data"),
                        fontsize=8, color="dimgrey", va="bottom")
        for value, label in p.get("vlines", ()):
            ax.axvline(value, color="grey", linestyle=":", linewidth=1)
            ax.annotate(label, (value, 0.98), xycoords=("data", "axes fraction"),
                        fontsize=8, color="dimgrey", ha="right", va="top", rotation=90)
        if p.get("logx"):
            ax.set_xscale("log")
        if p.get("logy", True):
            ax.set_yscale("log")
            if floored:
                ax.axhline(CHART_FLOOR, color="lightgrey", linewidth=4, zorder=0)
                ax.annotate(f"0 and values < {CHART_FLOOR:g} drawn at {CHART_FLOOR:g}",
                            (0.99, CHART_FLOOR), xycoords=("axes fraction", "data"),
                            fontsize=7, color="dimgrey", ha="right", va="bottom")
        if p.get("xticks"):
            ax.set_xticks(*p["xticks"])
            ax.xaxis.set_minor_locator(matplotlib.ticker.NullLocator())
        ax.set_xlabel(p["xlabel"])
        ax.set_ylabel(p["ylabel"])
        if p.get("subtitle"):
            ax.set_title(p["subtitle"], fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=8, ncols=ncols)
    fig.suptitle(title, fontsize=11)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path
