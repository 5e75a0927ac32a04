"""3. Flipped normals: the same room with more and more faces wound the other way, the lamp
among them.

Oracle (invariance): the room as modelled. Each face's written mean (radiosity mesh) or the
mean of its corners (existing vertices) against the same face in the room as modelled, over
the room's mean.
"""

import re

import numpy as np

from core.scene import scene_from_polygons

from . import scenes
from .common import chart, guard, mesh_mean, pct, secs, table
from .report import Section

NOISE_FACTOR = 2.0

#: Flipped sets, growing: (label, groups whose faces are flipped, or (group, indices of its
#: faces); the box's faces: bottom, top, then its sides, scenes.Builder.box).
SETS = (("none", ()), ("floor", ("floor",)), ("floor, a wall, the box top", ("floor", "wall x1",
                                                                           ("box", (1,)))),
        ("ceiling, 2 walls, a box side, the lamp", ("ceiling", "wall y0", "wall y1",
                                                     ("box", (2,)), "lamp")),
        ("every face", ("floor", "ceiling", "wall y0", "wall x1", "wall y1", "wall x0", "box",
                        "lamp")))


def flip(scene, faces):
    """The scene with ``faces`` wound the other way (normals reversed), as CAD imports do."""
    polys = [list(scene.corner_verts[s:s + k]) for s, k in zip(scene.face_starts,
                                                               scene.face_sizes)]
    for f in faces:
        polys[f] = polys[f][::-1]
    return scene_from_polygons(scene.vertices, polys, scene.face_materials, scene.reflectance,
                               scene.emission, face_objects=scene.face_objects,
                               object_names=scene.object_names)


def faces_of(groups, spec):
    out = []
    for item in spec:
        name, which = item if isinstance(item, tuple) else (item, None)
        out += [groups[name][i] for i in which] if which else list(groups[name])
    return out


def face_means(result, scene, mode):
    """(F,) mean written radiance of every face (mean of the three channels)."""
    if mode == "mesh":
        return np.array([mesh_mean(result.output, [f]) for f in range(scene.n_faces)])
    c = result.corner_colours.mean(axis=1)
    return np.array([c[s:s + k].mean() for s, k in zip(scene.face_starts, scene.face_sizes)])


def error(means, ref, lit):
    return float(np.abs(means[lit] - ref[lit]).max() / ref[lit].mean())


def run(ctx):
    scene0, groups = scenes.room()
    lit = np.ones(scene0.n_faces, dtype=bool)
    lit[groups["lamp"]] = False
    modes = ("mesh", "vertices")
    refs, noise = {}, {}
    for mode in modes:
        means = [face_means(ctx.gate.run(scene0, ctx.settings(seed=s, output_mode=mode))
                            .result, scene0, mode) for s in (0, 1)]
        refs[mode] = means[0]
        noise[mode] = error(means[1], means[0], lit)
    sets = ctx.pick(SETS[1:], SETS[1:2] + SETS[-1:])
    rows, data = [], {}
    for label, spec in sets:
        faces = faces_of(groups, spec)
        scene = flip(scene0, faces)
        for mode in modes:
            r = ctx.gate.run(scene, ctx.settings(output_mode=mode))
            ctx.log(f"orient {label} {mode}: {r.status} {r.seconds:.1f} s")
            if not r.ok:
                rows.append([label, len(faces), mode, r.status, "", "", secs(r.seconds)])
                continue
            err = error(face_means(r.result, scene, mode), refs[mode], lit)
            data[mode, len(faces)] = err
            warn = [w for w in r.result.report["warnings"] if "flipped normals" in w]
            named = re.match(r"(\d+) faces", warn[0]) if warn else None
            rows.append([label, len(faces), f"`{mode}`", pct(err),
                         pct(NOISE_FACTOR * noise[mode]),
                         named.group(1) if named else "0", secs(r.seconds)])

    name = "stability_orient.png"
    counts = [len(faces_of(groups, spec)) for _, spec in sets]
    chart(ctx.images / name, "Flipped normals: each face against the room as modelled",
          "faces flipped (of 13; the lamp among them from 5 on)",
          "worst face |error| / room mean (%)",
          [(f"output_mode='{m}'" + (" (default)" if m == "mesh" else ""), counts,
            [data.get((m, n)) for n in counts]) for m in modes],
          hlines=[(NOISE_FACTOR * noise[m], f"2 x seed noise, {m}") for m in modes],
          percent=True)
    default = [data[k] for k in data if k[0] == "mesh"]
    worst = max(default) if default else float("nan")
    sec = Section(
        key="orient", title="Flipped normals",
        provocation="1 to all 13 faces of a room wound the other way, the lamp included",
        worst=f"{pct(worst)} worst face (2 x seed noise: {pct(NOISE_FACTOR * noise['mesh'])})",
        mitigation="each face baked on the side that receives the light, named in the report "
                   "(`core/orient.py`; no setting)",
        guards=[guard("tests/core/test_orient.py")])
    sec.blocks += [
        "**Scene.** The room of class 2 (no copy); faces reversed in growing sets, the lamp "
        "(two-sided, as in Cycles) in the last two. Default settings, both output modes. "
        "**Oracle.** The room as modelled (seed 0): every face's written mean (the mesh's "
        "area-weighted field, or its corners' mean with existing vertices), the worst face's "
        "difference over the room's mean; the lamp's own faces are left out. **Tolerance**: "
        "twice the seed noise (seeds 0 and 1 of the room as modelled: "
        + ", ".join(f"{m} {pct(noise[m])}" for m in modes) + ").",
    ]
    sec.chart_link(name, "worst face error against the number of flipped faces")
    sec.blocks.append(table(["flipped", "faces", "output", "worst face error", "2 x seed noise",
                             "faces reported", "time"], rows))
    over = [f"{n} faces ({m})" for (m, n), e in data.items() if e > NOISE_FACTOR * noise[m]]
    sec.blocks.append(
        "**What the default does.** "
        + (f"Beyond twice the seed noise: {', '.join(over)}." if over else
           "Every flipped set bakes within twice the seed noise in both output modes.")
        + " 'faces reported': the count in the report's flipped-normals warning.")
    return sec
