"""2. Coincident duplicate faces: a floor left twice, at a growing distance above the floor.

Oracle (invariance): the same room without the copy. The surface a camera sees is the copy (it
lies at or above the floor), so the room with the copy is measured with the copy's faces as its
floor; walls, ceiling and box as they are.
"""

import importlib
from contextlib import contextmanager

from core.duplicates import DUPLICATE_RTOL, NEAR_DUPLICATE_RTOL

from . import scenes
from .common import chart, guard, pct, secs, surface_errors, surface_means, table
from .report import Section

OTHERS = ("ceiling", "wall y0", "wall x1", "wall y1", "wall x0", "box")
#: An invariance holds within this many times the seed noise (tests/core/test_orient.py).
NOISE_FACTOR = 2.0
#: Where offset 0 is drawn on the log axis.
ZERO_AT = 1e-7


@contextmanager
def merge_removed():
    """core.bake without its duplicate merge (to measure what the mechanism buys)."""
    module = importlib.import_module("core.bake")
    old = getattr(module, "merge_duplicates", None)
    if old is None:
        yield False
        return
    module.merge_duplicates = lambda scene, **kw: scene
    try:
        yield True
    finally:
        module.merge_duplicates = old


def run(ctx):
    names = OTHERS + ("floor",)
    refs = []
    for seed in (0, 1):
        scene, groups = scenes.room()
        r = ctx.gate.run(scene, ctx.settings(seed=seed))
        refs.append(surface_means(r.result, scene, groups, names))
    pairs = [(g, g) for g in names]
    noise = surface_errors(refs[1], refs[0], pairs)
    ctx.log(f"duplicates: seed noise room {noise[0]:.2e}, surface {noise[1]:.2e}")

    offsets = ctx.pick([0.0, 1e-6, 1e-5, 1e-3, 1e-2], [0.0, 1e-3])
    variants = ctx.pick([("same", False), ("flipped", True)], [("same", False)])
    rows, data = [], {}
    pairs = [(g, g) for g in OTHERS] + [("copy", "floor")]
    for label, flipped in variants:
        for merged in (True, False):
            for rel in offsets:
                if not merged and rel > DUPLICATE_RTOL:
                    continue            # past the threshold nothing is merged anyway
                scene, groups = scenes.room(copy=(rel, flipped))
                if merged:
                    r = ctx.gate.run(scene, ctx.settings())
                else:
                    with merge_removed() as removed:
                        if not removed:
                            continue
                        r = ctx.gate.run(scene, ctx.settings())
                ctx.log(f"duplicates {label} {rel:g} merged={merged}: {r.status} "
                        f"{r.seconds:.1f} s")
                if not r.ok:
                    rows.append([label, f"{rel:g}", "yes" if merged else "removed", r.status,
                                 "", "", "", secs(r.seconds)])
                    continue
                means = surface_means(r.result, scene, groups, OTHERS + ("copy",))
                err = surface_errors(means, refs[0], pairs)
                data[label, merged, rel] = err
                warned = any("duplicate" in w or "copy of themselves" in w
                             for w in r.result.report["warnings"])
                rows.append([label, f"{rel:g}", "yes" if merged else "removed",
                             r.result.report["patches"], pct(err[0]), pct(err[1]),
                             "yes" if warned else "no", secs(r.seconds)])

    name = "stability_duplicates.png"
    xs = [max(o, ZERO_AT) for o in offsets]
    ticks = sorted({ZERO_AT, *[o for o in offsets if o > 0]})
    panels = []
    for k, ylabel in ((0, "room mean |error| (%)"), (1, "worst surface |error| / room mean (%)")):
        series = [(f"{label}, merge {'(default)' if merged else 'removed'}", xs,
                   [data[label, merged, o][k] if (label, merged, o) in data else None
                    for o in offsets])
                  for label, _ in variants for merged in (True, False)]
        panels.append(dict(xlabel="copy's distance above the floor / floor size", ylabel=ylabel,
                           series=series, logx=True, percent=True,
                           xticks=(ticks, ["0" if t == ZERO_AT else f"{t:g}" for t in ticks]),
                           hlines=[(NOISE_FACTOR * noise[k], "2 x seed noise")],
                           vlines=[(DUPLICATE_RTOL, f"DUPLICATE_RTOL = {DUPLICATE_RTOL:g}")]))
    chart(ctx.images / name, "Duplicate floor: the room against the room without the copy",
          panels=panels)

    default = {o: data[label, True, o] for label, _ in variants for o in offsets
               if (label, True, o) in data}
    worst = max(e[0] for e in default.values())
    worst_surface = max(e[1] for e in default.values())
    within = [o for o in offsets
              if all(data[lb, True, o][0] <= NOISE_FACTOR * noise[0] for lb, _ in variants
                     if (lb, True, o) in data)]
    removed = [data[lb, False, 0.0][0] for lb, _ in variants if (lb, False, 0.0) in data]
    sec = Section(
        key="duplicates", title="Coincident duplicate faces",
        provocation="a copy of the floor, as is or flipped, 0 to "
                    f"{max(offsets):g} x its size above it",
        worst=f"room mean {pct(worst)}, worst surface {pct(worst_surface)} "
              f"(2 x seed noise: {pct(NOISE_FACTOR * noise[0])} / "
              f"{pct(NOISE_FACTOR * noise[1])})",
        mitigation="coincident faces (corners within `DUPLICATE_RTOL` = "
                   f"{DUPLICATE_RTOL:g} x size) solved as one, copies take the kept face's "
                   "colours; copies facing the same way within `NEAR_DUPLICATE_RTOL` = "
                   f"{NEAR_DUPLICATE_RTOL:g} x size named in a warning (`core/duplicates.py`; "
                   "no setting)",
        guards=[guard("tests/core/test_duplicates.py")])
    sec.blocks += [
        "**Scene.** A 4 × 3 × 2.5 m room (walls one quad each), a 1 m box on the floor, a 1 m "
        "lamp 0.3 m under the ceiling; a copy of the floor (as modelled, or wound the other "
        "way) a given fraction of the floor's size (√area) above it. Default settings. "
        "**Oracle.** The same room without the copy (same seed), with the copy's faces read as "
        "the floor. Room mean = area-weighted mean of the written field over floor (copy), "
        "walls, ceiling and box; worst surface = the largest difference of one of them, over "
        "the room mean. **Tolerance**: twice the seed noise (seeds 0 and 1 of the room without "
        f"copy: room {pct(noise[0])}, worst surface {pct(noise[1])}). 'merge removed': the "
        "script replaces `core.bake.merge_duplicates` by the identity, to show what the "
        "mechanism buys.",
    ]
    sec.chart_link(name, "room error against the copy's distance")
    sec.blocks.append(table(["copy", "offset / size", "merge", "patches", "room mean error",
                             "worst surface", "warned", "time"], rows))
    sec.blocks.append(
        f"**What the default does.** Within twice the seed noise at offsets "
        f"{', '.join(f'{o:g}' for o in within) or 'none'}; worst room-mean error "
        f"{pct(worst)}. Without the merge the coincident copy (offset 0) gives "
        + (", ".join(pct(e) for e in removed) or "–")
        + f" on the room mean. Past `DUPLICATE_RTOL` the copy is a surface of its own over a "
          "thin cavity (the patches column shows the cavity split of the radiosity mesh); "
          "within `NEAR_DUPLICATE_RTOL` a copy facing the same way is named in the report "
          "('warned').")
    return sec
