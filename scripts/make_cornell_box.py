"""Write sample_blends/cornell_box.blend: the published Cornell box, ready to bake.

Run from the repository with the bpy module of the OLDEST supported Blender (4.2 LTS), because
Blender 5 writes .blend files that Blender 4.x cannot read, while 5.x reads 4.2's::

    .venv-bpy42/bin/python scripts/make_cornell_box.py [--output sample_blends/cornell_box.blend]
    .venv-bpy42/bin/python scripts/make_cornell_box.py --grid 0.05 \
        --output bench/blends/cornell_box.blend        # the benchmark's pre-meshed copy

By default every surface is modelled as it is published (a wall is one quad, a block five quads,
the red wall two triangles): the bake's radiosity mesh subdivides where the light changes. The
benchmark (bench/compare) compares per face with Cycles and needs small faces, so its copy is
meshed as grids of ``--grid`` metres (every patch corner a mesh vertex).

Geometry, reflectances and the light's colour come from bench.scenes (one source of truth with the
core's tests), which follows ../shared/reference/cornell_box.md: y and z swapped with handedness
kept (Blender X = x, Y = -z, Z = y), millimetres to metres, the light in an opening of the
ceiling (nothing coincides with it; its back side emits out of the box, as the real box's light
does), the non-planar red wall split into two triangles, reflectances averaged over the bands
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
#: ~1300 patches, a bake of seconds.
PATCH_SIZE = 0.05

#: Grid spacing of the benchmark's pre-meshed copy (``--grid``): the patch size, so every patch
#: corner is a mesh vertex. The light stays one quad.
GRID = PATCH_SIZE


def _load_package():
    path = os.path.join(ROOT, "radiosity_addon", "bootstrap.py")
    spec = importlib.util.spec_from_file_location("radiosity_bootstrap", path)
    bootstrap = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bootstrap)
    return bootstrap.load_package()


def build(pkg, grid=None):
    """Build the Cornell box in a fresh empty file (surfaces split into ``grid``-metre grids, or
    whole with None)."""
    import bpy
    import numpy as np

    samples = importlib.import_module(f"{pkg.__name__}.bench.scenes")
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
        # No specular layer: the published box is Lambertian, and Cycles' DIFFUSE bake would
        # leave out (and the specular layer would take away from) part of the reflected light.
        bsdf.inputs["Specular IOR Level"].default_value = 0.0
        mat.diffuse_color = (*rgb, 1.0)
        if name == "light":
            bsdf.inputs["Emission Color"].default_value = (*light_rgb, 1.0)
            bsdf.inputs["Emission Strength"].default_value = LIGHT_STRENGTH
        mats[name] = mat

    groups = {}
    for name, pts, mat in samples.cornell_geometry():
        groups.setdefault(name, []).append((np.asarray(pts), mat))
    for name, polys in groups.items():
        n = max(_divisions(pts, None if polys[0][1] == "light" else grid) for pts, _ in polys)
        verts, faces = _merge([_grid(pts, n) for pts, _ in polys])
        mesh = bpy.data.meshes.new(name)
        mesh.from_pydata(verts.tolist(), [], faces)
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
    if grid is not None:
        scene.radiosity.patch_size = PATCH_SIZE
    return scene


def _divisions(pts, grid):
    """Grid divisions along the longest edge of a polygon (1: keep it whole)."""
    import numpy as np

    if grid is None:
        return 1
    edges = np.linalg.norm(np.roll(pts, -1, axis=0) - pts, axis=1)
    return max(1, int(np.ceil(edges.max() / grid - 1e-9)))


def _grid(pts, n):
    """Split a quad (bilinear n x n grid) or a triangle (n^2 triangles) keeping its winding.

    Returns (points (k, 3), faces: list of index tuples into points).
    """
    import numpy as np

    t = np.linspace(0.0, 1.0, n + 1)
    if len(pts) == 4:
        u, v = np.meshgrid(t, t, indexing="ij")
        u, v = u.ravel()[:, None], v.ravel()[:, None]
        p = ((1 - u) * (1 - v) * pts[0] + u * (1 - v) * pts[1] + u * v * pts[2]
             + (1 - u) * v * pts[3])
        idx = lambda i, j: i * (n + 1) + j  # noqa: E731
        faces = [(idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1))
                 for i in range(n) for j in range(n)]
        return p, faces
    index, p = {}, []
    for i in range(n + 1):
        for j in range(n + 1 - i):
            index[i, j] = len(p)
            a, b = i / n, j / n
            p.append(pts[0] + a * (pts[1] - pts[0]) + b * (pts[2] - pts[0]))
    faces = []
    for i in range(n):
        for j in range(n - i):
            faces.append((index[i, j], index[i + 1, j], index[i, j + 1]))
            if i + j < n - 1:
                faces.append((index[i + 1, j], index[i + 1, j + 1], index[i, j + 1]))
    return np.array(p), faces


def _merge(pieces):
    """Join grids into one connected mesh: coincident points (to 1 micrometre) become one."""
    import numpy as np

    points = np.concatenate([p for p, _ in pieces])
    offsets = np.cumsum([0] + [len(p) for p, _ in pieces])
    key = np.round(points * 1e6).astype(np.int64)
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    inverse = inverse.ravel()
    faces = [tuple(int(inverse[o + k]) for k in f) for (_, fs), o in zip(pieces, offsets)
             for f in fs]
    return points[first], faces


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--output", default=os.path.join(ROOT, "sample_blends", "cornell_box.blend"))
    parser.add_argument("--grid", type=float, default=None,
                        help=f"mesh the surfaces as grids of this size in metres (the benchmark "
                             f"copy uses {GRID}); default: as published, one polygon per surface")
    args = parser.parse_args(argv)
    if args.grid is not None and not args.grid > 0:
        parser.error(f"--grid must be > 0; got {args.grid}")
    pkg = _load_package()
    import bpy

    pkg.register()
    try:
        build(pkg, args.grid)
        sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
        from make_office import camera_view
        camera_view(bpy.data.screens)
        out = os.path.abspath(args.output)
        os.makedirs(os.path.dirname(out), exist_ok=True)
        bpy.ops.wm.save_as_mainfile(filepath=out, compress=True, check_existing=False)
    finally:
        pkg.unregister()
    print(f"wrote {out}")


if __name__ == "__main__":
    main(sys.argv[1:])
