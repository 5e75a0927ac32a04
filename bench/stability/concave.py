"""5. Concave n-gons: an L- or comb-shaped room whose floor and ceiling are one polygon each.

Oracle: the same room with floor and ceiling as convex pieces (rectangles), refined far past the
defaults. Both forms at defaults are measured against it: the written field on a grid of the
floor and of the ceiling, every wall's mean and the room mean.
"""

import numpy as np
from matplotlib.path import Path

from core.settings import BakeSettings

from . import scenes
from .common import chart, guard, interpolate, mesh_mean, pct, rel_mean_abs, secs, \
    surface_means, table
from .report import Section

NOISE_FACTOR = 2.0
#: Sample spacing (m); the grid is offset by half of it, so no point lies on an edge.
STEP = 0.2


def samples(outline):
    lo, hi = outline.min(axis=0), outline.max(axis=0)
    xs = np.arange(lo[0] + STEP / 2, hi[0], STEP)
    ys = np.arange(lo[1] + STEP / 2, hi[1], STEP)
    pts = np.array([[x, y] for x in xs for y in ys])
    return pts[Path(outline).contains_points(pts)]


def measure(result, scene, groups, outline):
    pts = samples(outline)
    m = result.output
    floor = interpolate(m, groups["floor"], np.column_stack([pts, np.zeros(len(pts))]),
                        np.array([0, 0, 1.0]))
    ceil = interpolate(m, groups["ceiling"], np.column_stack([pts, np.full(len(pts), 2.5)]),
                       np.array([0, 0, -1.0]))
    walls = np.array([mesh_mean(m, [f]) for f in groups["walls"]])
    room = surface_means(result, scene, groups, ("floor", "ceiling", "walls"))["room"]
    return floor, ceil, walls, room


def errors(got, ref):
    return (rel_mean_abs(got[0], ref[0]), rel_mean_abs(got[1], ref[1]),
            float(np.abs(got[2] - ref[2]).max() / ref[3]), abs(got[3] - ref[3]) / ref[3])


#: The reference: the convex room refined far past the defaults (patches 0.25 m, contrast
#: 0.02, elements down to 2 cm, the emitters' direct light exact at every vertex).
REFINED = dict(patch_size=0.25, contrast=0.02, min_element=0.02, exact_direct="all")

LABELS = ("floor field", "ceiling field", "worst wall mean / room mean", "room mean")


def run(ctx):
    ks = ctx.pick([1, 2, 3], [1])
    rows, data, noise = [], {}, None
    for k in ks:
        scene, groups, outline = scenes.comb(k, True)
        ref = ctx.gate.run(scene, BakeSettings(**REFINED))
        ctx.log(f"concave k={k} reference: {ref.status} {ref.seconds:.1f} s")
        if not ref.ok:
            rows.append([k, 2 * k - 1, "reference", ref.status] + [""] * 7)
            continue
        reference = measure(ref.result, scene, groups, outline)
        measured = {}
        for convex, seed in ((True, 0), (True, 1), (False, 0)):
            if seed and k != ks[0]:
                continue
            scene, groups, outline = scenes.comb(k, convex)
            r = ctx.gate.run(scene, ctx.settings(seed=seed))
            ctx.log(f"concave k={k} convex={convex} seed {seed}: {r.status} {r.seconds:.1f} s")
            if not r.ok:
                rows.append([k, 2 * k - 1, "convex" if convex else "one polygon", r.status]
                            + [""] * 7)
                continue
            measured[convex, seed] = measure(r.result, scene, groups, outline)
            if seed:
                noise = errors(measured[True, 1], measured[True, 0])
                continue
            err = errors(measured[convex, seed], reference)
            data[k, convex] = err
            rows.append([k, 2 * k - 1, "convex pieces" if convex else "one polygon",
                         r.result.report["patches"], r.result.output.vertices.shape[0],
                         *(pct(e) for e in err),
                         pct(errors(measured[False, 0], measured[True, 0])[1])
                         if not convex and (True, 0) in measured else "", secs(r.seconds)])
    name = "stability_concave.png"
    reflex = [2 * k - 1 for k in ks]
    series = []
    for convex, form in ((True, "convex pieces"), (False, "one polygon")):
        for i in (0, 1, 3):
            series.append((f"{LABELS[i]}, {form}", reflex,
                           [data[k, convex][i] if (k, convex) in data else None for k in ks]))
    chart(ctx.images / name, "Concave floor and ceiling: one polygon or convex pieces",
          "reflex corners of the floor (1: an L; combs of 2, 3 "
          "teeth: 3, 5)", "|error| against the refined convex room (%)", series, percent=True)
    # The concave form's excess over the convex form's own discretisation error.
    excess = [max(data[k, False][i] - data[k, True][i] for k in ks
                  if (k, False) in data and (k, True) in data) for i in range(4)]
    sec = Section(
        key="concave", title="Concave n-gons",
        provocation="floor and ceiling of an L or comb room as one polygon (1 to "
                    f"{max(reflex)} reflex corners)",
        worst=f"against the refined room, one polygon's error exceeds the convex pieces' by: "
              f"floor field {pct(excess[0])}, ceiling field {pct(excess[1])}, room mean "
              f"{pct(excess[3])} (2 x seed noise: "
              + (", ".join(pct(NOISE_FACTOR * e) for e in (noise[0], noise[1], noise[3]))
                 if noise else "–") + ")",
        mitigation="ear clipping in the face's plane before the patch grids "
                   "(`core/geometry.py` `triangulate_polygon`, `core/patches.py`); no setting",
        guards=[guard("tests/core/test_geometry.py::test_ear_clipping_tiles_the_polygon"),
                guard("tests/core/test_geometry.py::test_split_concave_quad_covers_it")])
    sec.blocks += [
        "**Scene.** A room 2.5 m high on an L (k = 1: a 2.2 × 2 m spine and a 1.2 × 2.5 m "
        "arm) or a comb (k teeth 1.2 m wide, 1 m apart, on a 2 m deep spine); walls one quad "
        "per outline edge, a 1 m lamp 0.3 m under the ceiling over the spine. Floor and ceiling "
        "are one concave polygon each, or the same areas as rectangles. Default settings, "
        "the default method (the polygon's triangulation is shared by every method). "
        "**Oracle.** The convex room refined far past the defaults ("
        + ", ".join(f"`{a}={b!r}`" for a, b in REFINED.items()) + "): the written field on a "
        f"{STEP:g} m grid of the floor and of the ceiling (mean |difference| over mean), every "
        "wall's mean (worst wall over the room mean), and the room mean; both forms at "
        "defaults are measured against it. Comparing the two forms with each other at "
        "defaults measures the mesh, not the polygon: the ceiling's light pool over the lamp "
        "is resolved by elements laid out from different patch grids (last column). "
        "**Tolerance**: one polygon's error at most the convex pieces' error plus twice the "
        "seed noise (seeds 0 and 1 of the convex L room: "
        + (f"floor {pct(noise[0])}, ceiling {pct(noise[1])}, walls {pct(noise[2])}, room "
           f"{pct(noise[3])}" if noise else "not measured") + ").",
    ]
    sec.chart_link(name, "error against the number of reflex corners")
    sec.blocks.append(table(["teeth", "reflex corners", "floor and ceiling", "patches",
                             "output vertices", *LABELS, "ceiling field, one polygon against "
                             "convex pieces", "time"], rows))
    over = [f"{2 * k - 1} reflex corners ({LABELS[i]})" for k in ks
            if (k, False) in data and (k, True) in data and noise for i in (0, 1, 3)
            if data[k, False][i] > data[k, True][i] + NOISE_FACTOR * noise[i]]
    sec.blocks.append(
        "**What the default does.** "
        + (f"One polygon beyond the convex pieces' error plus twice the seed noise: "
           f"{', '.join(over)}." if over else
           "One polygon is within the convex pieces' own error plus twice the seed noise at "
           "every shape.")
        + " The patches column is the cost of the triangulation's fan strips against "
          "rectangles.")
    return sec
