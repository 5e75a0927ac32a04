"""What the Principled BSDF's specular layer does to Cycles' diffuse bake (the bake ignores it).

The add-on reads a Principled BSDF as a Lambertian surface of reflectance Base Color (README,
Materials). Blender's default material has a specular layer (Specular IOR Level 0.5, IOR 1.5,
Roughness 0.5): Cycles takes the layer's reflection out of the diffuse lobe and sends it on as
glossy light. This bakes the Cornell box sample with Cycles three ways, per object the mean of
its corners' DIFFUSE pass (direct, indirect, colour), as a ratio to the Lambertian bake:

* ``lambert``: Specular IOR Level 0, Roughness 1, no glossy bounces (the benchmark's reference);
* ``default``: Blender's defaults (0.5, 0.5) with glossy bounces (128), as a user's file renders;
* ``no_glossy``: the defaults with glossy bounces off (the layer's light lost).

``--dark F`` multiplies every base colour by F first (dark floors and furniture). Two seeds give
the noise of each ratio.

Run: ``.venv/bin/python bench/specular_layer.py [--samples 1024] [--dark 1.0]``
"""

import argparse
import os
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import bpy  # noqa: E402

from bench.compare import cycles  # noqa: E402

CASES = (("lambert", 0.0, 1.0, 0), ("default", 0.5, 0.5, 128), ("no_glossy", 0.5, 0.5, 0))


def principled_nodes():
    return [n for m in bpy.data.materials if m.node_tree for n in m.node_tree.nodes
            if n.type == "BSDF_PRINCIPLED"]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=1024)
    parser.add_argument("--dark", type=float, default=1.0,
                        help="factor on every base colour (default 1: the file's)")
    args = parser.parse_args()
    bpy.ops.wm.open_mainfile(filepath=os.path.join(ROOT, "bench", "blends", "cornell_box.blend"),
                             load_ui=False)
    scene = bpy.context.scene
    for node in principled_nodes():
        colour = node.inputs["Base Color"].default_value
        colour[:3] = [c * args.dark for c in colour[:3]]
    objects = cycles.mesh_objects(scene)
    sizes = [len(ob.data.loops) for ob in objects]
    surfaces = [k for k, ob in enumerate(objects) if "light" not in ob.name.lower()]
    means = {}
    for name, level, roughness, bounces in CASES:
        for node in principled_nodes():
            node.inputs["Specular IOR Level"].default_value = level
            node.inputs["Roughness"].default_value = roughness
        runs = []
        for seed in (0, 1):
            corners, seconds = cycles.bake(scene, args.samples, seed, glossy=bounces)
            parts = np.split(corners, np.cumsum(sizes)[:-1])
            runs.append(np.array([p.mean(axis=0) for p in parts]))
            print(f"{name} seed {seed}: {seconds:.1f} s", flush=True)
        means[name] = np.array(runs)                      # (2, objects, 3)
    base = means["lambert"]
    print(f"\nratio to lambert, RGB (seed spread), {args.samples} samples, dark x{args.dark}")
    for name in ("default", "no_glossy"):
        ratio = means[name] / base
        mid, spread = ratio.mean(axis=0), np.abs(ratio[0] - ratio[1]) / 2
        for k in surfaces:
            print(f"  {name:9s} {objects[k].name:12s} " + " ".join(
                f"{m:.3f}±{s:.3f}" for m, s in zip(mid[k], spread[k])))
        luma = np.array([0.2126, 0.7152, 0.0722])
        lum = (means[name][:, surfaces] @ luma).sum(axis=1) \
            / (base[:, surfaces] @ luma).sum(axis=1)
        print(f"  {name:9s} all surfaces' luminance {lum.mean():.3f}±{abs(lum[0] - lum[1]) / 2:.3f}")


if __name__ == "__main__":
    main()
