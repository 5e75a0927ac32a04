"""Bake sample scenes and save every number of the result: a bit-identity check for refactors.

    git worktree add /tmp/base <commit>
    .venv/bin/python bench/fingerprint.py /tmp/base /tmp/base.npz     # the code at <commit>
    .venv/bin/python bench/fingerprint.py . /tmp/new.npz               # this checkout
    .venv/bin/python bench/fingerprint.py --compare /tmp/base.npz /tmp/new.npz

Saved: corner colours, node radiance and every report number (timings aside) of five bakes
(Cornell box with refinement, elements and contact cuts; the room with boxes with the hybrid, with
Gauss-Seidel and patch averages, and matrix-free) and of a relight of each.
"""
import sys

import numpy as np

if sys.argv[1] == "--compare":
    a, b = np.load(sys.argv[2]), np.load(sys.argv[3])
    ka, kb = set(a.files), set(b.files)
    bad = [k for k in sorted(ka & kb) if not np.array_equal(a[k], b[k])]
    print(f"{len(ka & kb)} arrays compared, {len(bad)} differ {bad[:20]}; only in the first: "
          f"{sorted(ka - kb)[:20]}, only in the second: {sorted(kb - ka)[:20]}")
    sys.exit(1 if bad or ka != kb else 0)

sys.path.insert(0, sys.argv[1])

try:
    from bench import scenes as samples  # noqa: E402
except ImportError:  # before the sample scenes moved out of core
    from core import samples  # noqa: E402
from core import BakeSettings, bake, relight  # noqa: E402

CASES = {
    "cornell": (samples.cornell_box, dict(patch_size=0.1, refine_levels=1, element_levels=2,
                                           contact_cuts=True)),
    "room": (lambda: samples.room_with_boxes(600), dict(patch_size=0.5, refine_levels=1,
                                                         element_levels=1, contact_cuts=True)),
    "room_hybrid": (lambda: samples.room_with_boxes(300), dict(patch_size=0.6, method="hybrid",
                                                                element_levels=0, rays=4)),
    "room_gs": (lambda: samples.room_with_boxes(300), dict(patch_size=0.5, solver="gauss_seidel",
                                                            corners="average")),
    "room_free": (lambda: samples.room_with_boxes(300), dict(patch_size=0.5,
                                                              memory_budget=1 << 20)),
}


def numbers(obj, prefix, out):
    if isinstance(obj, dict):
        for k, v in obj.items():
            if k == "timings":
                continue
            numbers(v, f"{prefix}.{k}", out)
    elif isinstance(obj, (list, tuple)):
        for i, v in enumerate(obj):
            numbers(v, f"{prefix}[{i}]", out)
    elif isinstance(obj, (int, float, np.integer, np.floating, bool)):
        out[prefix] = np.asarray(obj)
    else:
        out[prefix] = np.asarray(str(obj))


out = {}
for name, (build, kw) in CASES.items():
    scene = build()
    res = bake(scene, BakeSettings(**kw))
    out[f"{name}/corner_colours"] = res.corner_colours
    out[f"{name}/node_radiance"] = res.node_radiance
    numbers(res.report, f"{name}/report", out)
    rl = relight(res, emission=np.asarray(scene.emission) * 2.0)
    out[f"{name}/relight_corner_colours"] = rl.corner_colours
    numbers(rl.report, f"{name}/relight_report", out)
    print(name, res.report["patches"], res.report["iterations"], res.report["timings"]["total"],
          flush=True)
np.savez(sys.argv[2], **out)
