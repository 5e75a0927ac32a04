"""7. Large surfaces with no light: a ground plane of growing size under a closed, lit room.

Oracle: no light leaves the closed room, so the ground reads exactly 0 and the room's corners
read what they read without the ground. Measured: run time, patches and output vertices against
the ground's size.
"""

import numpy as np

from core.adaptive import coarse_patch_size
from core.patches import make_patches

from . import scenes
from .common import chart, corners_of, guard, pct, secs, table
from .report import Section

NOISE_FACTOR = 2.0


def room_error(result, ref, n_corners):
    a, b = result.corner_colours[:n_corners], ref.corner_colours[:n_corners]
    return float(np.abs(a - b).mean() / np.abs(b).mean())


def run(ctx):
    scene0, groups0 = scenes.ground_room(0)
    refs = [ctx.gate.run(scene0, ctx.settings(seed=s)) for s in (0, 1)]
    n0 = scene0.n_corners
    noise = room_error(refs[1].result, refs[0].result, n0)
    sizes = ctx.pick([10.0, 30.0, 100.0], [10.0])
    counted = ctx.pick([300.0, 1000.0, 3000.0], [100.0])
    rows, data = [], {}
    rows.append(["none", refs[0].result.report["patches"], refs[0].result.report["nodes_active"],
                 refs[0].result.output.vertices.shape[0], "", "", "", secs(refs[0].seconds)])
    for size in sizes:
        scene, groups = scenes.ground_room(size)
        r = ctx.gate.run(scene, ctx.settings())
        ctx.log(f"unlit ground {size:g} m: {r.status} {r.seconds:.1f} s")
        if not r.ok:
            rows.append([f"{size:g} m", r.status, "", "", "", "", "", secs(r.seconds)])
            continue
        m = r.result.output
        c = corners_of(m, groups["ground"])
        ground_max = float(m.corner_colours[c].max())
        ground_v = int(np.unique(m.corner_verts[c]).size)
        err = room_error(r.result, refs[0].result, n0)
        data[size] = (r.seconds, r.result.report["patches"], m.vertices.shape[0], ground_v,
                      ground_max, err)
        rows.append([f"{size:g} m", r.result.report["patches"], r.result.report["nodes_active"],
                     m.vertices.shape[0], ground_v, f"{ground_max:g}", pct(err),
                     secs(r.seconds)])
    patches = {}
    for size in sizes + counted:
        scene, _ = scenes.ground_room(size)
        patches[size] = len(make_patches(scene, coarse_patch_size(scene)).areas)
    for size in counted:
        scene, _ = scenes.ground_room(size)
        rows.append([f"{size:g} m", f"{patches[size]} (counted, not baked)", "", "", "", "", "",
                     ""])

    name = "stability_unlit.png"
    all_sizes = sizes + counted
    chart(ctx.images / name, "A ground plane under a closed, lit 3 m room: cost against its "
          "size", panels=[
              dict(xlabel="ground side (m)", ylabel="count", logx=True, series=[
                  ("starting patches (coarse_patch_size)", all_sizes,
                   [patches[s] for s in all_sizes]),
                  ("patches after the bake's splits", sizes,
                   [data[s][1] if s in data else None for s in sizes]),
                  ("output vertices", sizes, [data[s][2] if s in data else None for s in sizes]),
                  ("ground's output vertices", sizes,
                   [data[s][3] if s in data else None for s in sizes])]),
              dict(xlabel="ground side (m)", ylabel="bake time (s)", logx=True, series=[
                  ("default settings", [0.0 + 1.0] + sizes,
                   [refs[0].seconds] + [data[s][0] if s in data else None for s in sizes])],
                  xticks=([1.0] + sizes, ["none"] + [f"{s:g}" for s in sizes]))])
    worst_room = max((d[5] for d in data.values()), default=float("nan"))
    ground_max = max((d[4] for d in data.values()), default=float("nan"))
    big = max(data) if data else None
    sec = Section(
        key="unlit", title="Large surfaces with no light",
        provocation=f"a {min(sizes):g} to {max(sizes):g} m ground plane (counted to "
                    f"{max(counted):g} m) under a closed, lit 3 m room",
        worst=f"ground reads {ground_max:g} (exact: 0); room corners {pct(worst_room)} (2 x seed "
              f"noise {pct(NOISE_FACTOR * noise)}); cost: "
              + (f"{data[big][2]} output vertices and {secs(data[big][0])} at {big:g} m against "
                 f"{refs[0].result.output.vertices.shape[0]} and {secs(refs[0].seconds)} "
                 "without" if big else "–"),
        mitigation="unlit nodes never solved nor gathered, unlit leaves never split "
                   "(`core/criteria.py` `unlit_late_nodes`, `core/adaptive.py`); the coarse "
                   "patch is 1 m clamped to the scene's diagonal / 400",
        guards=[guard("tests/core/test_adaptive.py::"
                      "test_unlit_ground_outside_a_closed_room_costs_no_gathers")])
    sec.blocks += [
        "**Scene.** A closed 3 m cube room (reflectance 0.5, walls one quad each) with a 1 m "
        "lamp 0.3 m under its ceiling, on a square ground plane 1 cm below its floor. Default "
        "settings. **Oracle.** Nothing leaves the room: the ground reads exactly 0, the room's "
        "user corners what they read without the ground (seed 0; mean |difference| over mean). "
        f"**Tolerance**: the ground exactly 0; the room within twice the seed noise "
        f"({pct(noise)}). The cost is the measure: bake time, patches (after the near-emitter "
        "and cavity splits), active nodes, output vertices. Larger grounds are counted "
        "(`make_patches` at `coarse_patch_size`), not baked.",
    ]
    sec.chart_link(name, "patches, vertices and time against the ground's size")
    sec.blocks.append(table(["ground", "patches", "active nodes", "output vertices",
                             "ground's vertices", "ground max", "room corners", "time"], rows))
    sec.blocks.append(
        "**What the default does.** The ground's light: "
        + ("exactly 0 at every size baked" if ground_max == 0 else f"up to {ground_max:g}")
        + f"; the room's corners within {pct(worst_room)} of the room alone. The cost grows "
          "with the ground's patches: "
        + ", ".join(f"{s:g} m: {data[s][1]} patches, {data[s][2]} vertices, {secs(data[s][0])}"
                    for s in sizes if s in data) + ".")
    return sec
