"""Write sample_blends/cornell_box.blend: the published Cornell box, ready to bake.

Run from the repository with the bpy module::

    .venv/bin/python scripts/make_cornell_box.py [--output sample_blends/cornell_box.blend]

Geometry, reflectances and the light's colour come from core.samples (one source of truth with the
core's tests), which follows ../shared/reference/cornell_box.md: y and z swapped with handedness
kept (Blender X = x, Y = -z, Z = y), millimetres to metres, the light lowered 1 mm under the
ceiling, the non-planar red wall split into two triangles, reflectances averaged over the bands
R = 600-700, G = 500-596, B = 400-496 nm. The light is a Principled BSDF whose Emission Color is the
band-averaged spectrum (normalised to 1) and whose strength is LIGHT_STRENGTH. The camera is the
published one: at (278, 273, -800) mm looking along +z with +y up, 35 mm lens on a 25 mm film.
"""

import argparse
import importlib.util
import math
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

#: Emission strength of the light (peak channel radiance, W/(m^2 sr)): walls come out around 0.2-1,
#: well exposed in the Standard view transform.
LIGHT_STRENGTH = 50.0

#: Bake settings stored in the file (the batch script's defaults for it): 5 cm patches make
#: ~2000 patches, a bake of seconds.
PATCH_SIZE = 0.05


def _load_package():
    path = os.path.join(ROOT, "radiosity_addon", "bootstrap.py")
    spec = importlib.util.spec_from_file_location("radiosity_bootstrap", path)
    bootstrap = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bootstrap)
    return bootstrap.load_package()


def build(pkg):
    """Build the Cornell box in a fresh empty file."""
    import bpy
    import numpy as np

    samples = importlib.import_module(f"{pkg.__name__}.core.samples")
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    colours = {"white": samples.CORNELL_WHITE, "red": samples.CORNELL_RED,
               "green": samples.CORNELL_GREEN, "light": (0.78, 0.78, 0.78)}
    light_rgb = samples.cornell_light_radiance(peak=1.0)
    mats = {}
    for name, rgb in colours.items():
        mat = bpy.data.materials.new(name)
        if bpy.app.version < (5, 0, 0):
            mat.use_nodes = True  # on by default (and deprecated) from 5.0
        bsdf = mat.node_tree.nodes["Principled BSDF"]
        bsdf.inputs["Base Color"].default_value = (*rgb, 1.0)
        bsdf.inputs["Roughness"].default_value = 1.0
        mat.diffuse_color = (*rgb, 1.0)
        if name == "light":
            bsdf.inputs["Emission Color"].default_value = (*light_rgb, 1.0)
            bsdf.inputs["Emission Strength"].default_value = LIGHT_STRENGTH
        mats[name] = mat

    groups = {}
    for name, pts, mat in samples.cornell_geometry():
        groups.setdefault(name, []).append((np.asarray(pts), mat))
    for name, polys in groups.items():
        verts, faces = [], []
        for pts, _ in polys:
            faces.append(tuple(range(len(verts), len(verts) + len(pts))))
            verts.extend(map(tuple, pts))
        mesh = bpy.data.meshes.new(name)
        mesh.from_pydata(verts, [], faces)
        mesh.update()
        mesh.materials.append(mats[polys[0][1]])
        obj = bpy.data.objects.new(name.title().replace(" ", "_"), mesh)
        scene.collection.objects.link(obj)

    cam_data = bpy.data.cameras.new("Camera")
    cam_data.lens = 35.0
    cam_data.sensor_fit = "HORIZONTAL"
    cam_data.sensor_width = 25.0
    cam_data.sensor_height = 25.0
    cam = bpy.data.objects.new("Camera", cam_data)
    cam.location = (0.278, 0.800, 0.273)          # (278, 273, -800) mm -> (x, -z, y) m
    cam.rotation_euler = (math.pi / 2, 0.0, math.pi)  # look along -Y (= +z), up +Z (= +y)
    scene.collection.objects.link(cam)
    scene.camera = cam
    scene.render.resolution_x = 512
    scene.render.resolution_y = 512
    scene.unit_settings.system = "METRIC"
    scene.radiosity.patch_size = PATCH_SIZE
    return scene


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--output", default=os.path.join(ROOT, "sample_blends", "cornell_box.blend"))
    args = parser.parse_args(argv)
    pkg = _load_package()
    import bpy

    pkg.register()
    try:
        build(pkg)
        out = os.path.abspath(args.output)
        os.makedirs(os.path.dirname(out), exist_ok=True)
        bpy.ops.wm.save_as_mainfile(filepath=out, compress=True, check_existing=False)
    finally:
        pkg.unregister()
    print(f"wrote {out}")


if __name__ == "__main__":
    main(sys.argv[1:])
