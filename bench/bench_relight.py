"""Relight and light groups (issue 12) against the bake, on the bundled samples, through the add-on.

For each sample: the bake (radiosity.bake with the file's own settings), then a Relight after
every emissive material's strength x 2 (one new solve on the kept form factors), the first
light-group change (one solve per group, once) and a second one (a weighted sum, no solve), and
the bytes the kept bake holds in memory (radiosity_addon.relight.kept_bytes).

Run: ``.venv/bin/python bench/bench_relight.py [--scenes cornell_box office]``. Prints one JSON
line per scene (seconds per step, the kept MB, the groups).
"""

import argparse
import json
import os
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "radiosity_addon"))

from bootstrap import load_package  # noqa: E402

PACKAGE = load_package()

import bpy  # noqa: E402


def emissive_inputs():
    """The Strength sockets of every emissive node material in the file."""
    out = []
    for mat in bpy.data.materials:
        if mat.node_tree is None:
            continue
        for node in mat.node_tree.nodes:
            for key in ("Strength", "Emission Strength"):
                sock = node.inputs.get(key) if hasattr(node, "inputs") else None
                if sock is not None and not sock.is_linked and sock.default_value > 0:
                    out.append(sock)
    return out


def run(name):
    bpy.ops.wm.open_mainfile(filepath=os.path.join(ROOT, "sample_blends", f"{name}.blend"),
                             load_ui=False)
    relight = PACKAGE.radiosity_addon.relight
    t0 = time.perf_counter()
    assert bpy.ops.radiosity.bake() == {"FINISHED"}
    bake = time.perf_counter() - t0
    report = json.loads(bpy.context.scene.radiosity.last_report)
    for sock in emissive_inputs():
        sock.default_value *= 2.0
    for light in bpy.data.lights:
        light.energy *= 2.0
    t0 = time.perf_counter()
    assert bpy.ops.radiosity.relight() == {"FINISHED"}
    relit = time.perf_counter() - t0
    entry = relight.kept(bpy.context.scene)
    groups = bpy.context.scene.radiosity_groups
    t0 = time.perf_counter()
    groups[0].strength = 0.5
    first = time.perf_counter() - t0
    t0 = time.perf_counter()
    groups[0].strength = 0.25
    second = time.perf_counter() - t0
    return dict(scene=name, bake_s=round(bake, 2),
                bake_core_s=round(report["timings"]["total"], 2),
                relight_s=round(relit, 3), group_first_s=round(first, 3),
                group_next_s=round(second, 3), groups=[g.name for g in groups],
                patches=report["patches"], form_factor_mb=round(
                    report["form_factor_bytes"] / 2 ** 20, 2),
                kept_mb=round(relight.kept_bytes(entry) / 2 ** 20, 2))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", nargs="+", default=["cornell_box", "office"])
    args = parser.parse_args()
    PACKAGE.register()
    for name in args.scenes:
        print(json.dumps(run(name)), flush=True)


if __name__ == "__main__":
    main()
