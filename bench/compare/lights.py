"""Point, spot and sun lights (issue 12) against converged Cycles, on a room modelled coarsely.

The room an architect would model: 5 x 4 x 2.7 m, one quad per floor and ceiling, walls as one
quad each except the window wall (four quads around a 1.6 x 1.2 m opening, T-junctions
included), a table and a cabinet as boxes of six quads. Three lightings, each its own case:

* ``point``: two point lights (radius 5 cm, soft falloff) under the ceiling;
* ``spot``: a spot on the table (50 deg, blend 0.2) and a dim point light for the rest;
* ``sun``: the sun through the window (angle 0.53 deg), nothing else (the world is black);
* ``sky``: a uniform blue-white world seen through the window, nothing else.

Reference: the mean of ``--reference-seeds`` Cycles bakes at ``--reference-samples`` of a copy
meshed as a ``--grid`` metre grid (Cycles needs vertices to bake), lights identical. Ours: the
coarse room baked by the core with defaults (radiosity mesh), sampled at the reference's corners
(:mod:`bench.compare.coarse`). Cycles at ``--cycles-samples`` on the same grid gives its time at
equal error. Error: area-weighted relative RMS of per-face luminance (bench/compare/metrics.py).

Run (Blender's Python environment, from the repository root)::

    .venv/bin/python -m bench.compare.lights
    .venv/bin/python -m bench.compare.lights --cases sun --reference-samples 4096

Writes ``bench/results/lights.csv`` and prints one line per case and run.
"""

import argparse
import csv
import time
from pathlib import Path

import numpy as np

from . import coarse, cycles, metrics

ROOT = Path(__file__).resolve().parents[2]

ROOM = (5.0, 4.0, 2.7)
WINDOW = (1.7, 3.3, 0.9, 2.1)         # x from, x to, z from, z to, in the wall y = 4
MATERIALS = dict(wall=(0.7, 0.7, 0.7), floor=(0.45, 0.35, 0.25), ceiling=(0.8, 0.8, 0.8),
                 table=(0.6, 0.2, 0.15), cabinet=(0.3, 0.4, 0.6))

CASES = {
    "point": [dict(kind="point", name="Bulb A", position=(1.5, 1.5, 2.4), power=300.0,
                   radius=0.05, color=(1.0, 0.9, 0.8)),
              dict(kind="point", name="Bulb B", position=(3.6, 2.6, 2.4), power=200.0,
                   radius=0.05)],
    "spot": [dict(kind="spot", name="Spot", position=(2.5, 1.2, 2.6), power=600.0, radius=0.03,
                  direction=(0.0, 0.25, -1.0), spot_size=np.radians(50), spot_blend=0.2),
             dict(kind="point", name="Fill", position=(4.5, 3.5, 2.5), power=40.0, radius=0.05)],
    "sun": [dict(kind="sun", name="Sun", direction=(0.3, -1.0, -0.8), strength=5.0,
                 angle=np.radians(0.53), color=(1.0, 0.95, 0.9))],
    "sky": [],
}

#: Uniform world radiance per case (black where absent).
WORLDS = {"sky": (0.6, 0.7, 0.9)}


def _box(lo, hi):
    """Six outward quads of the box [lo, hi]."""
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    v = [(x0, y0, z0), (x1, y0, z0), (x1, y1, z0), (x0, y1, z0),
         (x0, y0, z1), (x1, y0, z1), (x1, y1, z1), (x0, y1, z1)]
    return v, [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)]


def room_arrays():
    """The coarse room as make_scene arrays (objects Floor, Ceiling, Walls, Table, Cabinet)."""
    X, Y, Z = ROOM
    wx0, wx1, wz0, wz1 = WINDOW
    objects = []
    objects.append(("Floor", "floor", [(0, 0, 0), (X, 0, 0), (X, Y, 0), (0, Y, 0)], [(0, 1, 2, 3)]))
    objects.append(("Ceiling", "ceiling", [(0, 0, Z), (0, Y, Z), (X, Y, Z), (X, 0, Z)],
                    [(0, 1, 2, 3)]))
    walls = []

    def quad(a, b, c, d):
        walls.append([a, b, c, d])

    quad((0, 0, 0), (0, 0, Z), (X, 0, Z), (X, 0, 0))          # y = 0, facing +y
    quad((X, 0, 0), (X, 0, Z), (X, Y, Z), (X, Y, 0))          # x = X, facing -x
    quad((0, Y, 0), (0, Y, Z), (0, 0, Z), (0, 0, 0))          # x = 0, facing +x
    # y = Y, facing -y, around the window: below, above, left, right
    quad((X, Y, 0), (X, Y, wz0), (0, Y, wz0), (0, Y, 0))
    quad((X, Y, wz1), (X, Y, Z), (0, Y, Z), (0, Y, wz1))
    quad((wx0, Y, wz0), (wx0, Y, wz1), (0, Y, wz1), (0, Y, wz0))
    quad((X, Y, wz0), (X, Y, wz1), (wx1, Y, wz1), (wx1, Y, wz0))
    wv = [p for q in walls for p in q]
    objects.append(("Walls", "wall", wv, [tuple(range(4 * i, 4 * i + 4))
                                          for i in range(len(walls))]))
    objects.append(("Table", "table", *_box((1.8, 1.4, 0.0), (3.2, 2.3, 0.75))))
    objects.append(("Cabinet", "cabinet", *_box((0.0, 0.3, 0.0), (0.5, 2.0, 1.9))))
    names = list(MATERIALS)
    verts, corners, starts, sizes, fmats, fobjs = [], [], [], [], [], []
    for oi, (name, mat, v, faces) in enumerate(objects):
        base = len(verts)
        verts.extend(v)
        for f in faces:
            starts.append(len(corners))
            sizes.append(len(f))
            corners.extend(base + i for i in f)
            fmats.append(names.index(mat))
            fobjs.append(oi)
    return dict(vertices=np.array(verts, float), corner_verts=np.array(corners),
                face_starts=np.array(starts), face_sizes=np.array(sizes),
                face_materials=np.array(fmats),
                reflectance=np.array([MATERIALS[n] for n in names], float),
                emission=np.zeros((len(names), 3)), face_objects=np.array(fobjs),
                object_names=tuple(o[0] for o in objects), material_names=tuple(names))


def gridded(arrays, grid):
    """The same room as patches of at most ``grid`` metres, one polygon per patch."""
    from core.patches import make_patches
    from core.scene import make_scene

    scene = make_scene(**arrays, lights=CASES["sun"])
    p = make_patches(scene, grid)
    tri = np.all(p.corners[:, 3] == p.corners[:, 2], axis=1)
    sizes = np.where(tri, 3, 4)
    starts = np.cumsum(sizes) - sizes
    corners = np.concatenate([np.arange(4 * i, 4 * i + s) for i, s in enumerate(sizes)])
    return dict(arrays, vertices=p.corners.reshape(-1, 3), corner_verts=corners,
                face_starts=starts, face_sizes=sizes, face_materials=p.material,
                face_objects=scene.face_objects[p.face])


def add_lights(bpy_scene, lights):
    """Blender lights for the dicts of :func:`core.lights.make_lights` (Blender's units)."""
    import bpy
    from mathutils import Vector

    for d in lights:
        kind = d["kind"].upper()
        data = bpy.data.lights.new(d["name"], kind)
        data.color = d.get("color", (1.0, 1.0, 1.0))
        ob = bpy.data.objects.new(d["name"], data)
        bpy_scene.collection.objects.link(ob)
        if kind == "SUN":
            data.energy = d["strength"]
            data.angle = d.get("angle", 0.0)
        else:
            data.energy = d["power"]
            data.shadow_soft_size = d.get("radius", 0.0)
            ob.location = d["position"]
        if kind == "SPOT":
            data.spot_size = d["spot_size"]
            data.spot_blend = d.get("spot_blend", 0.0)
        if kind in ("SUN", "SPOT"):
            ob.rotation_mode = "QUATERNION"
            ob.rotation_quaternion = Vector(d["direction"]).to_track_quat("-Z", "Y")


def reference_blend(case, grid, cache):
    """The gridded room with the case's lights, saved once to the cache (Cycles' input)."""
    import bpy

    path = Path(cache) / ("lights_%s_grid%g.blend" % (case, grid))
    if not path.exists():
        bpy.ops.wm.read_factory_settings(use_empty=True)
        sc = bpy.context.scene
        world = bpy.data.worlds.new("World")
        colour = WORLDS.get(case, (0.0, 0.0, 0.0))
        world.color = colour
        if bpy.app.version < (5, 0, 0):
            world.use_nodes = True
        world.node_tree.nodes["Background"].inputs["Color"].default_value = (*colour, 1.0)
        sc.world = world
        cycles.build(gridded(room_arrays(), grid), sc)
        add_lights(sc, CASES[case])
        bpy.ops.wm.save_as_mainfile(filepath=str(path))
    return path


def run(case, args):
    from core.scene import make_scene

    blend = reference_blend(case, args.grid, args.cache)
    world = WORLDS.get(case)
    ref = coarse.Reference("lights_%s" % case, blend, args, lights=CASES[case] or None,
                           world=world)
    rows = []
    arrays = room_arrays()
    # the names bench.compare.cycles.build gave the reference's objects
    arrays["object_names"] = tuple("%03d_%s" % (i, n) for i, n in enumerate(arrays["object_names"]))
    scene = make_scene(**arrays, lights=CASES[case] or None, world=world)
    names = [str(n) for n in arrays["object_names"]]
    runs = [("ours (defaults)", "", {})]
    runs += [("ours (light_samples %d)" % n, n, dict(light_samples=n)) for n in args.light_samples]
    runs += [("ours (no shadow cuts)", "", dict(shadow_cuts=False))] if args.no_shadow_cuts else []
    runs += [("ours (contrast %g)" % c, "", dict(contrast=c)) for c in args.contrasts]
    for label, n, kw in runs:
        res, wall, cpu = coarse.timed_bake(scene, output_mode="mesh", **kw)
        m = res.output
        group = coarse.groups_of(dict(object_names=names, face_objects=scene.face_objects[
            m.face_parent]), ref.names)
        colours, misses = ref.sample(m.vertices, m.corner_verts, m.face_starts, m.face_sizes,
                                     group, m.corner_colours)
        err, fv = ref.measure(colours)
        rows.append(dict(case=case, method=label, samples=n,
                         vertices=len(m.vertices), t_total=wall, cpu=cpu, misses=misses, **err))
        print("%s: %s %.2f %% (bias %+.2f %%, without the worst %d faces %.2f %%), %d vertices, "
              "%.1f s; reference noise %.2f %%" % (case, label, 100 * err["rms"],
                                                   100 * err["bias"], coarse.WORST,
                                                   100 * err["rms_rest"], len(m.vertices), wall,
                                                   100 * ref.noise["rms"]))
        print("   " + ref.worst(fv))
        for line in ref.worst_faces(fv, top=4):
            print("   " + line)
    for spp in args.cycles_samples:
        cc, sec, cyc_cpu = coarse.cycles_cached("lights_%s" % case, blend, ref.sc, spp, 100,
                                                args.cache, args.threads)
        e, _ = ref.measure(cc)
        rows.append(dict(case=case, method="cycles", samples=spp,
                         vertices=len(ref.arrays["vertices"]), t_total=sec, cpu=cyc_cpu,
                         misses=0, **e))
        print("%s: Cycles %d spp %.2f %% in %.1f s" % (case, spp, 100 * e["rms"], sec))
    return rows


FIELDS = ["case", "method", "samples", "vertices", "t_total", "cpu", "rms", "rms_denoised",
          "p95", "bias", "faces_compared", "rms_rest", "worst_share", "worst_area", "misses"]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    ap.add_argument("--grid", type=float, default=0.1)
    ap.add_argument("--reference-samples", type=int, default=1024)
    ap.add_argument("--reference-seeds", type=int, default=2)
    ap.add_argument("--cycles-samples", type=int, nargs="*", default=[16, 64])
    ap.add_argument("--light-samples", type=int, nargs="*", default=[],
                    help="also bake with these light_samples (shadow rays in penumbrae)")
    ap.add_argument("--no-shadow-cuts", action="store_true",
                    help="also bake with shadow_cuts off (the shadow lines at objects' feet)")
    ap.add_argument("--contrasts", type=float, nargs="*", default=[],
                    help="also bake with these contrasts (the radiosity mesh's refinement)")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--cache", default=str(ROOT / "bench" / "results" / "cache"))
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "lights.csv"))
    args = ap.parse_args(argv)
    Path(args.cache).mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    rows = []
    for case in args.cases:
        rows += run(case, args)
    with open(args.out, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=FIELDS, extrasaction="ignore")
        w.writeheader()
        for r in rows:
            w.writerow({k: ("%.6g" % v if isinstance(v, float) else v) for k, v in r.items()})
    print("wrote %s (%.0f s)" % (args.out, time.perf_counter() - t0))


if __name__ == "__main__":
    main()
