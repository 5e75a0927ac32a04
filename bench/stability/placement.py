"""6. Offset from the origin and unit scale: the same room moved far away, or scaled mm to km.

Oracle (invariance): radiance does not depend on where a scene is or on its unit (form factors
are dimensionless), so every user corner must read what it reads in the room at the origin at
scale 1. Scaled scenes are baked twice: with the length settings scaled alike (what converting
units once at the boundary gives) and with the defaults in metres.
"""

import numpy as np

from core.adaptive import coarse_patch_size, min_element_size
from core.patches import make_patches
from core.settings import TABLE, BakeSettings

from . import scenes
from .common import DEFAULT_METHOD, chart, guard, methods, pct, secs, table
from .report import Section

NOISE_FACTOR = 2.0
#: Direction of the offsets (m per unit of offset).
DIRECTION = np.array([0.8, -0.6, 0.05])
#: Scaled scenes with default settings are baked only up to this many starting patches (the
#: default patch size is 1 m clamped to the scene's diagonal: a km-sized room has ~10^5).
MAX_PATCHES = 6000


def corner_error(result, ref, keep):
    """(mean |diff| / mean, max |diff| / max) over the kept user corners."""
    a, b = result.corner_colours[keep], ref.corner_colours[keep]
    return float(np.abs(a - b).mean() / np.abs(b).mean()), float(np.abs(a - b).max()
                                                                   / np.abs(b).max())


def scaled_settings(ctx, scene0, scale, **kw):
    """Every length setting (unit 'm') scaled; the auto lengths made explicit first, as the
    bake resolves them for ``scene0``."""
    resolved = BakeSettings()
    lengths = {row.name: getattr(resolved, row.name) for row in TABLE if row.is_length}
    lengths["patch_size"] = coarse_patch_size(scene0)
    lengths["min_element"] = min_element_size(scene0)
    return ctx.settings(**{k: v * scale for k, v in lengths.items()}, **kw)


def run(ctx):
    scene0, groups = scenes.room()
    keep = np.ones(scene0.n_corners, dtype=bool)
    for f in groups["lamp"]:
        keep[scene0.face_starts[f]:scene0.face_starts[f] + scene0.face_sizes[f]] = False
    refs = {}
    for method in methods():
        if method != DEFAULT_METHOD and ctx.quick:
            continue
        for seed in ((0, 1) if method == DEFAULT_METHOD else (0,)):
            r = ctx.gate.run(scene0, ctx.settings(seed=seed, method=method))
            if r.ok:
                refs[method, seed] = r.result
    noise = corner_error(refs[DEFAULT_METHOD, 1], refs[DEFAULT_METHOD, 0], keep)
    offsets = ctx.pick([1e1, 1e2, 1e3, 1e4, 1e5, 1e6], [1e4])
    scales = ctx.pick([1e-3, 1e-2, 1e-1, 1e1, 1e2, 1e3], [1e-3, 1e3])
    rows, data = [], {}

    def record(kind, x, method, r):
        if not r.ok:
            rows.append([kind, f"{x:g}", f"`{method}`", r.status, "", "", "", secs(r.seconds)])
            return
        err = corner_error(r.result, refs[method, 0], keep)
        data[kind, method, x] = err
        rows.append([kind, f"{x:g}", f"`{method}`", r.result.report["patches"],
                     r.result.output.vertices.shape[0], pct(err[0]), pct(err[1]),
                     secs(r.seconds)])

    for d in offsets:
        scene, _ = scenes.room(offset=d * DIRECTION)
        for method in methods():
            if (method, 0) not in refs or (method != DEFAULT_METHOD and d != offsets[-1]):
                continue
            r = ctx.gate.run(scene, ctx.settings(method=method))
            ctx.log(f"placement offset {d:g} {method}: {r.status} {r.seconds:.1f} s")
            record("offset (m)", d, method, r)
    for s in scales:
        scene, _ = scenes.room(scale=s)
        r = ctx.gate.run(scene, scaled_settings(ctx, scene0, s))
        ctx.log(f"placement scale {s:g} scaled settings: {r.status} {r.seconds:.1f} s")
        record("scale, lengths scaled", s, DEFAULT_METHOD, r)
        n = len(make_patches(scene, coarse_patch_size(scene)).areas)
        if n > ctx.pick(MAX_PATCHES, MAX_PATCHES // 4):
            rows.append(["scale, default lengths", f"{s:g}", f"`{DEFAULT_METHOD}`",
                         f"not baked: {n} starting patches", "", "", "", ""])
            continue
        r = ctx.gate.run(scene, ctx.settings())
        ctx.log(f"placement scale {s:g} default settings: {r.status} {r.seconds:.1f} s")
        record("scale, default lengths", s, DEFAULT_METHOD, r)

    name = "stability_placement.png"
    panels = [
        dict(xlabel="offset from the origin (m)", ylabel="user corners, mean |error| (%)",
             logx=True, percent=True, series=[
                 (m, offsets, [data.get(("offset (m)", m, d), (None,))[0] for d in offsets])
                 for m in methods() if any(("offset (m)", m, d) in data for d in offsets)],
             hlines=[(NOISE_FACTOR * noise[0], "2 x seed noise")]),
        dict(xlabel="scale of the scene (1e-3: a room modelled in mm read as m)",
             ylabel="user corners, mean |error| (%)", logx=True, percent=True, series=[
                 (kind, scales, [data.get((kind, DEFAULT_METHOD, s), (None,))[0]
                                 for s in scales])
                 for kind in ("scale, lengths scaled", "scale, default lengths")],
             hlines=[(NOISE_FACTOR * noise[0], "2 x seed noise")])]
    chart(ctx.images / name, "The room moved from the origin and scaled, against the room at "
          "the origin at scale 1", panels=panels)
    default = [v for (kind, m, _), v in data.items() if m == DEFAULT_METHOD]
    worst_off = max((v[0] for (k, m, _), v in data.items() if k.startswith("offset")
                     and m == DEFAULT_METHOD), default=float("nan"))
    worst_scaled = max((v[0] for (k, m, _), v in data.items() if k == "scale, lengths scaled"),
                       default=float("nan"))
    worst_default = max((v[0] for (k, m, _), v in data.items() if k == "scale, default lengths"),
                        default=float("nan"))
    sec = Section(
        key="placement", title="Offset from the origin and unit scale",
        provocation=f"the room moved {min(offsets):g} to {max(offsets):g} m from the origin; "
                    f"scaled {min(scales):g} to {max(scales):g}",
        worst=f"offset {pct(worst_off)}; scale with lengths scaled {pct(worst_scaled)}, with "
              f"default lengths {pct(worst_default)} (mean over user corners; 2 x seed noise "
              f"{pct(NOISE_FACTOR * noise[0])})",
        mitigation="float64 geometry; length settings in metres, converted once at the "
                   "add-on's boundary with the unit scale (`core/settings.py`)",
        guards=[guard("tests/core/test_stability.py::test_office_furnace_with_contacts"),
                guard("tests/core/test_stability.py::"
                      "test_contact_cuts_never_make_degenerate_pieces")])
    sec.blocks += [
        "**Scene.** The room of class 2, moved along (0.8, −0.6, 0.05) by the offset, or scaled "
        "about the origin. **Oracle.** The room at the origin at scale 1 (seed 0, the same "
        "method): the colours of every user corner but the lamp's, mean |difference| over "
        "mean and largest |difference| over the largest value. **Tolerance**: twice the seed "
        f"noise (seeds 0 and 1: mean {pct(noise[0])}, max {pct(noise[1])}). 'lengths scaled': "
        "every length setting (" + ", ".join(f"`{r.name}`" for r in TABLE if r.is_length)
        + ") times the scale, the automatic patch size made explicit; 'default lengths': the "
          f"defaults in metres (not baked above {ctx.pick(MAX_PATCHES, MAX_PATCHES // 4)} "
          "starting patches). Every method is run at the largest offset (full mode).",
    ]
    sec.chart_link(name, "corner error against offset and scale")
    sec.blocks.append(table(["placement", "value", "method", "patches", "output vertices",
                             "mean error", "max error", "time"], rows))
    over = sorted({f"{k} {x:g}" for (k, m, x), v in data.items() if m == DEFAULT_METHOD
                   and v[0] > NOISE_FACTOR * noise[0]})
    sec.blocks.append(
        "**What the default does.** "
        + (f"Beyond twice the seed noise: {', '.join(over)}." if over else
           "Within twice the seed noise at every placement baked.")
        + (" All default-method runs: " + f"{len(default)} baked." if default else ""))
    return sec
