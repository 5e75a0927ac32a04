"""1. Small, bright emitters: the floor's light under a lamp of shrinking size, black room.

Oracle: with black walls and ceiling the floor reads ``rho Le F(x -> lamp)`` exactly, F by the
contour integral (core.exact.point_polygon_form_factor), at every output vertex of the floor.
"""

import numpy as np

from core.emitters import AUTO_PIXELS, MAX_AREA_SHARE, MAX_FACES, MAX_LAMPS, exact_materials
from core.exact import point_polygon_form_factor
from core.settings import BY_NAME, EXACT_DIRECT

from . import scenes
from .common import DEFAULT_METHOD, chart, corners_of, guard, methods, pct, rel_mean_abs, secs, \
    table
from .report import Section

#: Per-vertex tolerance in the black room: float32 colours' rounding and the exact emitters'
#: quadrature (tests/core/test_emitters.py, BLACK_ROOM_RTOL).
VERTEX_RTOL = 1e-3
#: A vertex counts as right within this (the README's "within 5 %").
NEAR = 0.05
FLOOR_RHO = scenes.FLOOR_RHO


def floor_errors(result, groups, lamp, size):
    """(mean error, worst vertex error, share within NEAR, floor vertices) against rho Le F."""
    m = result.output
    c = corners_of(m, groups["floor"])
    pts = m.vertices[m.corner_verts[c]]
    normals = np.tile([0.0, 0.0, 1.0], (len(pts), 1))
    exact = FLOOR_RHO / size ** 2 * point_polygon_form_factor(pts, normals, lamp[None])[:, 0]
    got = m.corner_colours[c, 0]
    rel = np.abs(got / exact - 1.0)
    return rel_mean_abs(got, exact), float(rel.max()), float(np.mean(rel <= NEAR)), \
        int(np.unique(m.corner_verts[c]).size)


def bulb_form_factor(pts, polys):
    """(n,) sum_f F(x -> f) from floor points ``pts`` (facing up) over a bulb's faces ``polys``
    (outward) whose front faces x: a convex lamp does not hide itself from outside."""
    up = np.tile([0.0, 0.0, 1.0], (len(pts), 1))
    # Every bulb face has 3 or 4 corners: triangles padded to 4 by repeating a corner.
    stacked = np.stack([np.vstack([q, q[-1:]]) if len(q) == 3 else q for q in polys])
    ff = point_polygon_form_factor(pts, up, stacked)
    normal = np.cross(stacked[:, 1] - stacked[:, 0], stacked[:, 2] - stacked[:, 0])
    facing = np.einsum("pfj,fj->pf", pts[:, None, :] - stacked.mean(1)[None], normal) > 0
    return np.where(facing, ff, 0.0).sum(axis=1)


def bulb_errors(result, groups, polys, le):
    """(mean error, worst vertex error, floor vertices) of a bulb room (:func:`scenes.bulb_room`)
    against rho Le :func:`bulb_form_factor`."""
    m = result.output
    c = corners_of(m, groups["floor"])
    pts = m.vertices[m.corner_verts[c]]
    exact = FLOOR_RHO * le * bulb_form_factor(pts, polys)
    got = m.corner_colours[c, 0]
    rel = np.abs(got / exact - 1.0)
    return rel_mean_abs(got, exact), rel.max(), np.unique(m.corner_verts[c]).size


def run(ctx):
    modes = [c.value for c in EXACT_DIRECT]
    default_mode = BY_NAME["exact_direct"].default
    sizes = ctx.pick([0.01, 0.03, 0.1, 0.3, 1.0], [0.01, 0.1])
    others = [m for m in methods() if m != DEFAULT_METHOD]
    rows, data = [], {}
    cases = [(mode, DEFAULT_METHOD, s) for s in sizes for mode in modes]
    if not ctx.quick:
        cases += [(mode, m, s) for m in others for mode, s in
                  ((default_mode, 0.01), ("off", 0.01), (default_mode, 0.3))]
    taken = {}
    for mode, method, size in cases:
        scene, groups, lamp = scenes.emitter_room(size)
        taken[size] = bool(exact_materials(scene, "auto", BY_NAME["resolution"].default)[2])
        r = ctx.gate.run(scene, ctx.settings(exact_direct=mode, method=method))
        ctx.log(f"emitters size {size} {mode} {method}: {r.status} {r.seconds:.1f} s")
        if not r.ok:
            rows.append([f"{size * 100:g} cm", f"`{mode}`", f"`{method}`", r.status, "", "", "",
                         secs(r.seconds)])
            continue
        mean, worst, near, nv = floor_errors(r.result, groups, lamp, size)
        data[mode, method, size] = (mean, worst, near)
        rows.append([f"{size * 100:g} cm", f"`{mode}`", f"`{method}`", nv, pct(mean),
                     pct(worst), pct(near, 3), secs(r.seconds)])

    name = "stability_emitters.png"
    panels = []
    for k, label in ((0, "mean |error| / mean exact (%)"),
                     (1, "worst vertex |error| / exact (%)")):
        panels.append(dict(percent=True,
            xlabel="lamp side (m); power kept (radiance 1 / side²)", ylabel=label, logx=True,
            series=[(f"exact_direct='{mode}'" + (" (default)" if mode == default_mode else ""),
                     sizes, [data.get((mode, DEFAULT_METHOD, s), (None,) * 3)[k]
                             for s in sizes]) for mode in modes],
            hlines=[(VERTEX_RTOL, "0.1 % per-vertex tolerance")] if k else [],
            subtitle=f"{DEFAULT_METHOD}; floor vertices against rho Le F"))
    chart(ctx.images / name, "Small emitters: floor light of a lamp 2.95 m above, black room",
          panels=panels)

    d = [data[default_mode, DEFAULT_METHOD, s] for s in sizes
         if (default_mode, DEFAULT_METHOD, s) in data]
    worst_mean = max(x[0] for x in d)
    worst_vertex = max(x[1] for x in d)
    at = sizes[int(np.argmax([x[1] for x in d]))]
    off = [data.get(("off", DEFAULT_METHOD, s)) for s in sizes]
    sec = Section(
        key="emitters", title="Small, bright emitters",
        provocation="lamp side 1 cm → 1 m at constant power, 2.95 m over a floor, black room",
        worst=f"mean {pct(worst_mean)}, worst vertex {pct(worst_vertex)} (at {at * 100:g} cm;"
              f" tolerance {pct(VERTEX_RTOL, 2)} per vertex)",
        mitigation="`exact_direct` (default `'auto'`): contour integral + shadow rays for "
                   f"emitters under {AUTO_PIXELS:g} hemicube pixels (`core/emitters.py`)",
        guards=[guard("tests/core/test_emitters.py"), guard("tests/core/test_lamps.py")])
    sec.blocks += [
        "**Scene.** A 4 × 4 × 3 m room, walls and ceiling black, floor reflectance 0.5, a "
        "square lamp 5 cm under the ceiling; its radiance is 1 / side², so every size emits "
        "the same power. **Oracle.** The floor reads `rho Le F(x -> lamp)` exactly "
        "(`core.exact.point_polygon_form_factor`), compared at every output vertex of the floor "
        f"(radiosity mesh, default settings). **Tolerance**: {pct(VERTEX_RTOL, 2)} per vertex "
        "(float32 colours; `tests/core/test_emitters.py`).",
        "**Measured.** Mean error = mean |baked − exact| / mean exact over the floor's vertices;"
        f" within {pct(NEAR, 2)} = share of vertices within {pct(NEAR, 2)} of the closed form.",
    ]
    sec.chart_link(name, "floor error against lamp size per exact_direct mode")
    sec.blocks.append(table(["lamp side", "exact_direct", "method", "floor vertices",
                             "mean error", "worst vertex", f"within {pct(NEAR, 2)}", "time"],
                            rows))
    small = [s for s in sizes if taken[s]]
    sec.blocks.append(
        f"**What the default does.** `exact_direct='{default_mode}'` took the lamp exactly at "
        f"{', '.join(f'{s * 100:g} cm' for s in small) or 'no size'} (under "
        f"{AUTO_PIXELS:g} hemicube pixels seen from the floor) and left the wider ones "
        "to the hemicube; its worst floor vertex is off by "
        f"{pct(worst_vertex)} (at {at * 100:g} cm). With `'off'` the hemicube alone reads "
        + ", ".join(f"{s * 100:g} cm: mean {pct(o[0])}" for s, o in zip(sizes, off) if o)
        + ". Other form-factor methods: rows of the table (full mode only).")
    sec.blocks += bulbs(ctx, default_mode)
    sec.blocks.append(
        f"**Mitigation.** `exact_direct='all'` takes every emitter (within {MAX_LAMPS} lamps, "
        f"{MAX_FACES} faces and {pct(MAX_AREA_SHARE, 2)} of the surfaces' area, "
        "`core/emitters.py`); `'auto'` only the narrow ones. A lamp of many faces (faces of one "
        "material that share a vertex position, any facing) is one light (`core/lamps.py`).")
    return sec


def bulbs(ctx, default_mode):
    """The same room with a bulb modelled as a UV sphere 0.5 m under the ceiling (a lamp of
    many faces): blocks of the section."""
    rows = []
    for r, nu, nv in ctx.pick([(0.05, 12, 6), (0.05, 32, 16), (0.1, 32, 16)], [(0.05, 12, 6)]):
        scene, groups, polys, le = scenes.bulb_room(r, nu, nv)
        for mode in (default_mode, "off"):
            run = ctx.gate.run(scene, ctx.settings(exact_direct=mode))
            ctx.log(f"emitters bulb {r} {nu}x{nv} {mode}: {run.status} {run.seconds:.1f} s")
            head = [f"{r * 100:g} cm, {nu} × {nv}", len(polys), f"`{mode}`"]
            if not run.ok:
                rows.append(head + [run.status, "", "", secs(run.seconds)])
                continue
            mean, worst, nv_floor = bulb_errors(run.result, groups, polys, le)
            rows.append(head + [nv_floor, pct(mean), pct(worst), secs(run.seconds)])
    return [
        "**A bulb modelled as a sphere.** The same room, the square lamp replaced by a UV "
        "sphere (loose faces, as an import leaves them) 0.5 m under the ceiling, radiance "
        "1 / (π r²). **Oracle.** `rho sum_f Le F(x -> f)` over the sphere's faces whose "
        "emitting side faces the floor vertex (a convex lamp does not hide itself). "
        "`bench/bench_bulb.py` adds a 2,048-face sphere.",
        table(["bulb", "faces", "exact_direct", "floor vertices", "mean error",
               "worst vertex", "time"], rows)]
