"""9. Near patches: surfaces closer than their size, per form-factor method.

(a) Opposed unit squares, one patch each, at a shrinking gap: ``core.rows.form_factor_matrix``
of every method against Howell's closed form (C-11).
(b) The same squares baked (one emits, the other receives, nothing else): the receiver's written
field against ``rho Le F`` (contour integral at every output vertex; closed form for the mean).
(c) A panel hung under the ceiling of a black box: the ceiling's written field against
``rho Le F(x -> panel)`` (contour integral at every vertex, midpoint quadrature for the mean).
"""

import time

import numpy as np

from core.emitters import MAX_AREA_SHARE
from core.exact import point_polygon_form_factor
from core.patches import make_patches
from core.progress import Monitor
from core.rows import form_factor_matrix
from core.settings import BY_NAME

from . import scenes
from .common import DEFAULT_METHOD, chart, corners_of, guard, mesh_mean, methods, pct, \
    rel_mean_abs, secs, table
from .report import Section

RHO, LE = 0.5, 1.0
PANEL_LE, CEILING_RHO = 10.0, 0.8
#: Midpoints per side of the quadrature of the ceiling's mean form factor.
QUADRATURE = 160
#: Yardstick: the hybrid against the exact method near a hung panel
#: (tests/core/test_reciprocity.py).
YARDSTICK = 0.05


def opposed(a, c):
    """Howell C-11: form factor between opposed squares of side ``a`` at distance ``c``."""
    x = a / c
    p = np.log(np.sqrt((1 + x * x) ** 2 / (1 + 2 * x * x)))
    q = 2 * x * np.sqrt(1 + x * x) * np.arctan(x / np.sqrt(1 + x * x)) - 2 * x * np.arctan(x)
    return 2 / (np.pi * x * x) * (p + q)


def point_ff(points, normal, polygon):
    normals = np.tile(normal, (len(points), 1))
    return np.abs(point_polygon_form_factor(points, normals, polygon[None])[:, 0])


def field_errors(result, parents, normal, polygon, scale, exact_mean):
    """(pointwise mean error at the output vertices, error of the written mean)."""
    m = result.output
    c = corners_of(m, parents)
    pts = m.vertices[m.corner_verts[c]]
    exact = scale * point_ff(pts, normal, polygon)
    return rel_mean_abs(m.corner_colours[c, 0], exact), \
        abs(mesh_mean(m, parents, 0) / exact_mean - 1.0)


def part_a(ctx):
    gaps = ctx.pick([2.0, 1.0, 0.5, 0.2, 0.1, 0.05, 0.02, 0.01], [1.0, 0.1, 0.01])
    out, rows = {}, []
    for method in methods():
        for gap in gaps:
            scene, _ = scenes.opposed_squares(gap)
            patches = make_patches(scene, 1.0)
            t0 = time.perf_counter()
            monitor = Monitor(None, lambda: time.perf_counter() - t0 > ctx.cap)
            try:
                F = form_factor_matrix(patches, method=method, monitor=monitor,
                                       resolution=BY_NAME["resolution"].default,
                                       rays=BY_NAME["rays"].default)
            except Exception as exc:  # noqa: BLE001 - reported in the document
                rows.append([f"`{method}`", f"{gap:g}", f"{type(exc).__name__}", ""])
                continue
            exact = opposed(1.0, gap)
            out[method, gap] = abs(F[0, 1] / exact - 1.0)
            rows.append([f"`{method}`", f"{gap:g}", f"{F[0, 1]:.5f} (exact {exact:.5f})",
                         pct(out[method, gap])])
    return gaps, out, rows


def part_bc(ctx, which):
    if which == "b":
        gaps = ctx.pick([1.0, 0.3, 0.1, 0.03, 0.01], [0.3])
    else:
        gaps = ctx.pick([0.3, 0.1, 0.03, 0.01], [0.1])
    runs = [(m, None) for m in methods()] + [(DEFAULT_METHOD, "all")]
    if ctx.quick:
        runs = [(DEFAULT_METHOD, None), (DEFAULT_METHOD, "all")]
    out, rows = {}, []
    for method, direct in runs:
        for gap in gaps:
            if which == "b":
                scene, groups = scenes.opposed_squares(gap, le=LE, rho=RHO)
                parents, normal, scale = groups["receiver"], np.array([0, 0, 1.0]), RHO * LE
                polygon = scene.vertices[scene.corner_verts[4:8]]
                exact_mean = scale * opposed(1.0, gap)
            else:
                scene, groups, polygon = scenes.hung_panel(gap, le=PANEL_LE, rho=CEILING_RHO)
                parents, normal = groups["ceiling"], np.array([0, 0, -1.0])
                scale = CEILING_RHO * PANEL_LE
                s = (np.arange(QUADRATURE) + 0.5) / QUADRATURE * 2.0
                q = np.array([[x, y, 2.0] for x in s for y in s])
                exact_mean = scale * point_ff(q, normal, polygon).mean()
            kw = dict(method=method) if direct is None else dict(exact_direct=direct)
            r = ctx.gate.run(scene, ctx.settings(**kw))
            label = f"`{method}`" + (f", exact_direct='{direct}'" if direct else "")
            ctx.log(f"near ({which}) gap {gap:g} {label}: {r.status} {r.seconds:.1f} s")
            if not r.ok:
                rows.append([label, f"{gap:g}", r.status, "", "", "", "", secs(r.seconds)])
                continue
            err = field_errors(r.result, parents, normal, polygon, scale, exact_mean)
            out[method, direct, gap] = err
            e = r.result.report["energy"]
            exact_faces = r.result.report.get("lights", {}).get("exact_emitter_faces", 0)
            rows.append([label, f"{gap:g}", r.result.report["patches"], exact_faces,
                         pct(err[0]), pct(err[1]), pct(e["balance"] / e["emitted"]),
                         secs(r.seconds)])
    return gaps, runs, out, rows


def run(ctx):
    gaps_a, a, rows_a = part_a(ctx)
    ctx.log("near (a) done")
    gaps_b, runs_b, b, rows_b = part_bc(ctx, "b")
    gaps_c, runs_c, c, rows_c = part_bc(ctx, "c")

    def lab(m, d):
        return m + (f" + exact_direct='{d}'" if d else "")

    name = "stability_near.png"
    panels = [
        dict(xlabel="gap / square side", ylabel="|F / F_exact − 1| (%)", logx=True,
             percent=True, subtitle="(a) opposed squares, one patch each",
             series=[(m, gaps_a, [a.get((m, g)) for g in gaps_a]) for m in methods()],
             hlines=[(YARDSTICK, "5 %")]),
        dict(xlabel="gap / square side", ylabel="receiver's written mean |error| (%)",
             logx=True, percent=True, subtitle="(b) opposed squares baked (defaults)",
             series=[(lab(m, d), gaps_b, [b.get((m, d, g), (None, None))[1] for g in gaps_b])
                     for m, d in runs_b], hlines=[(YARDSTICK, "5 %")]),
        dict(xlabel="panel's gap under the ceiling (m; panel 0.6 m)",
             ylabel="ceiling's written mean |error| (%)", logx=True, percent=True,
             subtitle="(c) hung panel baked (defaults)",
             series=[(lab(m, d), gaps_c, [c.get((m, d, g), (None, None))[1] for g in gaps_c])
                     for m, d in runs_c], hlines=[(YARDSTICK, "5 %")])]
    chart(ctx.images / name, "Near patches: each form-factor method against closed forms",
          panels=panels)

    def worst(data, k, gaps):
        v = [data[DEFAULT_METHOD, None, g][k] for g in gaps if (DEFAULT_METHOD, None, g) in data]
        return max(v) if v else float("nan")

    worst_a = max(a.get((DEFAULT_METHOD, g), np.nan) for g in gaps_a)
    skipped = sorted({r[0] for r in rows_b + rows_c if str(r[2]).startswith("too slow")})
    sec = Section(
        key="near", title="Near patches",
        provocation=f"opposed squares at gap/side {min(gaps_b):g}–{max(gaps_b):g}; a 0.6 m panel "
                    f"{min(gaps_c) * 100:g}–{max(gaps_c) * 100:g} cm under a ceiling",
        worst=f"squares: mean {pct(worst(b, 1, gaps_b))}, vertices {pct(worst(b, 0, gaps_b))};"
              f" panel: ceiling mean {pct(worst(c, 1, gaps_c))}, vertices "
              f"{pct(worst(c, 0, gaps_c))} (one-patch form factor {pct(worst_a)}; yardstick "
              f"{pct(YARDSTICK, 2)})",
        mitigation="`reciprocity='auto'`, near-emitter and cavity splits (`emitter_levels`), "
                   "vertex gathers; `method='hybrid'` / `'exact'`; `exact_direct='all'`",
        guards=[guard("tests/core/test_reciprocity.py"), guard("tests/core/test_exact.py"),
                guard("tests/core/test_elements.py::"
                      "test_near_emitter_split_alone_brings_the_floor_to_the_oracle")])
    sec.blocks += [
        "**Scenes.** (a) Two opposed 1 m squares, one patch each (`make_patches(scene, 1.0)`), "
        "`core.rows.form_factor_matrix` of every method at its default resolution and rays, "
        "F from the receiver's front to the emitter's front. (b) The same squares baked with "
        f"default settings, the upper emitting Le = {LE:g} (reflectance 0), the lower "
        f"reflecting {RHO:g}, nothing else. (c) A closed 2 m box, black but for its ceiling "
        f"(reflectance {CEILING_RHO:g}), a 0.6 m panel (radiance {PANEL_LE:g}, both sides) hung "
        "under the ceiling at the gap. **Oracles.** (a) Howell's closed form C-11; (b) "
        "`rho Le F(x -> emitter)` at every output vertex of the receiver "
        "(`core.exact.point_polygon_form_factor`) and C-11 for its mean; (c) "
        "`rho Le F(x -> panel)` at every output vertex of the ceiling, its mean by a "
        f"{QUADRATURE} × {QUADRATURE} midpoint rule of the same contour integral. Pointwise "
        "error = mean |baked − exact| / mean exact over the vertices; mean error = the written "
        "field's area-weighted mean against the exact mean. **Yardstick**: "
        f"{pct(YARDSTICK, 2)} (the hybrid against the exact method near a hung panel, "
        "`tests/core/test_reciprocity.py`); no engine tolerance is stated for these cases.",
    ]
    sec.chart_link(name, "form factor and written-field error against the gap, per method")
    sec.blocks += ["**(a) One patch each, form factor alone.**",
                   table(["method", "gap / side", "F", "error"], rows_a),
                   "**(b) Opposed squares baked.**",
                   table(["method", "gap / side", "patches", "exact emitter faces",
                          "vertices (pointwise)", "written mean", "energy balance / emitted",
                          "time"], rows_b),
                   "**(c) Panel under a ceiling baked.**",
                   table(["method", "gap (m)", "patches", "exact emitter faces",
                          "vertices (pointwise)", "written mean", "energy balance / emitted",
                          "time"], rows_c),
                   "'exact emitter faces': emissive faces lit by `core/emitters.py` (the report's "
                   "`lights.exact_emitter_faces`)."
                   + (" `'all'` takes none in (b): the emitter is half the scene's area, over "
                      f"`core.emitters.MAX_AREA_SHARE` = {MAX_AREA_SHARE:g}." if not any(
                          r[3] for r in rows_b if "'all'" in r[0] and r[3] != "") else "")]
    sec.blocks.append(
        f"**What the default does.** `{DEFAULT_METHOD}` (a point-source form factor) on one "
        f"patch each is off by up to {pct(worst_a)} on (a); baked with the defaults, which "
        "split patches near emitters and gather at the vertices, the receiver's mean is off "
        f"by up to {pct(worst(b, 1, gaps_b))} (b) and the ceiling's by up to "
        f"{pct(worst(c, 1, gaps_c))} (c). "
        + (f"Too slow under the {ctx.cap:.0f} s cap (skipped): "
           + ", ".join(skipped) + ". " if skipped else ""))
    return sec
