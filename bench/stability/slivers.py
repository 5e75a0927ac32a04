"""4. Long thin triangles at room corners: walls as fans of slivers from a room corner.

Oracle (invariance): the same room with each wall one quad. Compared: the written field at
points on the floor and on the walls (interpolated linearly over the output triangles, as a
renderer reads it) and each wall's mean. For the default method, both forms at defaults are
also measured against the quad room refined far past the defaults (two forms at defaults
differ by their meshes too, not only by the slivers).
"""

import numpy as np

from core.settings import BakeSettings

from . import scenes
from .concave import REFINED
from .common import DEFAULT_METHOD, chart, guard, interpolate, mesh_mean, methods, pct, \
    rel_mean_abs, secs, table, tests_named
from .report import Section

NOISE_FACTOR = 2.0
WALLS = ("wall y0", "wall x1", "wall y1", "wall x0")
#: Sample grid per surface (points a tenth of a cell in from the edges).
GRID = (10, 8)
#: Floor points this close (m) to the box's outline are not sampled: the light is discontinuous
#: across that contact line (lit floor on one side, the box's dark footprint on the other), and
#: a point on it reads whichever side's output face the lookup meets first. The grid's x = 1.0 m
#: column lies on the box's side: there the fans of 2 read -26 % and the quads +0.9 % against the
#: refined room, by that lookup alone (2026-11-28).
OUTLINE = 0.01


def _grid(origin, u, v, n=GRID):
    s = (np.arange(n[0]) + 0.5) / n[0]
    t = (np.arange(n[1]) + 0.5) / n[1]
    o, u, v = (np.asarray(a, dtype=np.float64) for a in (origin, u, v))
    return np.array([o + a * u + b * v for a in s for b in t])


def samples():
    """{surface: (points (S, 3), normal (3,))} on the floor and the four walls; floor points
    within OUTLINE of the box's outline are left out (see :data:`OUTLINE`)."""
    W, D, H = scenes.ROOM
    floor = _grid((0, 0, 0), (W, 0, 0), (0, D, 0))
    lo, hi = (np.asarray(c[:2]) for c in scenes.BOX)

    def within(margin):            # inside the box's footprint grown by ``margin``
        return np.all((floor[:, :2] > lo - margin) & (floor[:, :2] < hi + margin), axis=1)
    out = {"floor": (floor[~(within(OUTLINE) & ~within(-OUTLINE))], np.array([0, 0, 1.0]))}
    for name, poly in scenes.room_walls(W, D, H):
        n = np.cross(poly[1] - poly[0], poly[3] - poly[0])
        out[name] = (_grid(poly[0], poly[1] - poly[0], poly[3] - poly[0]), n / np.linalg.norm(n))
    return out


def fields(result, groups):
    """{surface: field at its samples}, {wall: mean}."""
    m = result.output
    f = {k: interpolate(m, groups[k], pts, n) for k, (pts, n) in samples().items()}
    return f, {w: mesh_mean(m, groups[w]) for w in WALLS}


def errors(got, ref):
    """(floor field, wall field, worst wall mean) errors of ``got`` against ``ref``."""
    (fa, ma), (fb, mb) = got, ref
    floor = rel_mean_abs(fa["floor"], fb["floor"])
    wa = np.concatenate([fa[w] for w in WALLS])
    wb = np.concatenate([fb[w] for w in WALLS])
    walls = rel_mean_abs(wa, wb)
    mean = max(abs(ma[w] - mb[w]) / mb[w] for w in WALLS)
    return floor, walls, mean


def run(ctx):
    fans = ctx.pick([2, 8, 32], [4])
    refs = {}
    for method in methods():
        if method != DEFAULT_METHOD and ctx.quick:
            continue
        for seed in ((0, 1) if method == DEFAULT_METHOD else (0,)):
            scene, groups = scenes.room()
            r = ctx.gate.run(scene, ctx.settings(seed=seed, method=method))
            ctx.log(f"slivers quads {method} seed {seed}: {r.status} {r.seconds:.1f} s")
            if r.ok:
                refs[method, seed] = (fields(r.result, groups), r)
    noise = errors(refs[DEFAULT_METHOD, 1][0], refs[DEFAULT_METHOD, 0][0])
    ctx.log(f"slivers: seed noise {noise}")
    scene, groups = scenes.room()
    fine = ctx.gate.run(scene, BakeSettings(**REFINED))
    ctx.log(f"slivers quads refined: {fine.status} {fine.seconds:.1f} s")
    refined = fields(fine.result, groups) if fine.ok else None
    rows, data, aspects, vs_fine = [], {}, {}, {}
    base = refs[DEFAULT_METHOD, 0][1]
    if refined is not None:
        vs_fine[1] = errors(refs[DEFAULT_METHOD, 0][0], refined)
    rows.append(["quads", "1", f"`{DEFAULT_METHOD}`", base.result.report["patches"],
                 base.result.output.vertices.shape[0], "", "", "",
                 " / ".join(pct(e) for e in vs_fine[1]) if 1 in vs_fine else "",
                 secs(base.seconds)])
    for n in fans:
        scene, groups = scenes.room(fan_walls=n)
        tris = [scene.vertices[scene.corner_verts[s:s + 3]]
                for s, k in zip(scene.face_starts, scene.face_sizes) if k == 3]
        aspects[n] = max(scenes.aspect(t) for t in tris)
        for method in methods():
            if (method, 0) not in refs:
                continue
            r = ctx.gate.run(scene, ctx.settings(method=method))
            ctx.log(f"slivers fan {n} {method}: {r.status} {r.seconds:.1f} s")
            if not r.ok:
                rows.append([f"fan of {n}", f"{aspects[n]:.0f}", f"`{method}`", r.status, "", "",
                             "", "", "", secs(r.seconds)])
                continue
            got = fields(r.result, groups)
            err = errors(got, refs[method, 0][0])
            data[method, n] = err
            if method == DEFAULT_METHOD and refined is not None:
                vs_fine[n] = errors(got, refined)
            rows.append([f"fan of {n}", f"{aspects[n]:.0f}", f"`{method}`",
                         r.result.report["patches"], r.result.output.vertices.shape[0],
                         pct(err[0]), pct(err[1]), pct(err[2]),
                         " / ".join(pct(e) for e in vs_fine[n]) if n in vs_fine and
                         method == DEFAULT_METHOD else "", secs(r.seconds)])

    name = "stability_slivers.png"
    xs = [aspects[n] for n in fans]
    labels = ("floor field", "wall field", "worst wall mean")
    panels = [dict(xlabel="largest triangle aspect ratio (longest edge / its height; 1: quads)",
                   ylabel="|error| against the refined quad room (%)", logx=True,
                   percent=True, subtitle=f"{DEFAULT_METHOD} (default), both forms at defaults",
                   series=[(lab, [1.0] + xs, [vs_fine.get(n, (None,) * 3)[k]
                                              for n in [1] + fans])
                           for k, lab in enumerate(labels)])]
    others = [m for m in methods() if any((m, n) in data for n in fans) and m != DEFAULT_METHOD]
    if others:
        panels.append(dict(xlabel="largest triangle aspect ratio", logx=True, percent=True,
                           ylabel="wall field |error| against the method's quad room (%)",
                           subtitle="every method (skipped where too slow)",
                           series=[(m, xs, [data.get((m, n), (None,) * 3)[1] for n in fans])
                                   for m in methods() if any((m, n) in data for n in fans)]))
    chart(ctx.images / name, "Walls as fans of slivers from a room corner, against the same "
          "room with quad walls", panels=panels)

    # The fans' excess over the quad room's own error, both against the refined room.
    excess = [max((vs_fine[n][k] - vs_fine[1][k] for n in fans if n in vs_fine and 1 in vs_fine),
                  default=float("nan")) for k in range(3)]
    guards = tests_named(r"sliver")
    sec = Section(
        key="slivers", title="Long thin triangles at room corners",
        provocation="each wall a fan of 2 to " + f"{max(fans)} triangles from a room corner "
                    f"(aspect up to {max(xs):.0f})",
        worst=f"against the refined room, the fans' error exceeds the quad room's by: floor "
              f"field {pct(excess[0])}, wall field {pct(excess[1])}, wall mean "
              f"{pct(excess[2])} (2 x seed noise: {pct(NOISE_FACTOR * noise[0])}, "
              f"{pct(NOISE_FACTOR * noise[1])}, {pct(NOISE_FACTOR * noise[2])})",
        mitigation="gather points of corners moved along the corner's bisector, clear of "
                   "both walls by the inset, not towards the sliver's centroid "
                   "(`core/gather.py`); patch grids of the triangles as they come "
                   "(`core/patches.py`); no setting",
        guards=[guard(g) for g in guards] or ["none yet"])
    sec.blocks += [
        "**Scene.** The room of class 2; each wall (4 × 2.5 m or 3 × 2.5 m) a fan of about n "
        "triangles from its bottom corner at a room corner to points spaced evenly along its "
        "two far edges, the rest of the room as quads. Default settings. **Oracle.** The same room "
        "with quad walls (same method, seed 0): the written field at a 10 × 8 grid on the "
        "floor and on every wall (mean |difference| over mean), and each wall's mean; floor "
        f"points within {OUTLINE * 100:g} cm of the box's outline are left out (a contact "
        "line, where the light is discontinuous and a point reads either side). "
        "For the default method, both forms at defaults are also measured against the quad "
        "room refined far past the defaults ("
        + ", ".join(f"`{a}={b!r}`" for a, b in REFINED.items()) + "; last column: floor "
        "field / wall field / worst wall mean): two forms at defaults differ by their meshes "
        "too. **Tolerance**: a fan's error against the refined room at most the quad room's "
        "plus twice the seed noise (seeds 0 and 1 of the quad room: floor "
        f"{pct(noise[0])}, walls {pct(noise[1])}, wall mean {pct(noise[2])}).",
    ]
    sec.chart_link(name, "error against the slivers' aspect ratio")
    sec.blocks.append(table(["walls", "aspect", "method", "patches", "output vertices",
                             "floor field", "wall field", "worst wall mean",
                             "against the refined room", "time"], rows))
    over = [f"{n} ({labels[k]})" for n in fans for k in range(3)
            if n in vs_fine and 1 in vs_fine
            and vs_fine[n][k] > vs_fine[1][k] + NOISE_FACTOR * noise[k]]
    sec.blocks.append(
        "**What the default does.** "
        + (f"Against the refined room, beyond the quad room's error plus twice the seed noise "
           f"at fans of {', '.join(over)}." if over else
           "Against the refined room, every fan within the quad room's own error plus twice "
           "the seed noise.")
        + " The patches and output vertices columns give the cost the slivers add. Guarding "
          "tests are looked up by name (`sliver` in a test's name under tests/core).")
    return sec
