"""Build sample_blends/office.blend: a 6 x 4 x 3 m office, modelled as an architect would.

Run with the oldest supported Blender's bpy (Blender 5 writes files 4.x cannot open)::

    .venv-bpy42/bin/python scripts/make_office.py                 # sample_blends/office.blend
    .venv-bpy42/bin/python scripts/make_office.py --face-size 0.2 --out bench/blends/office.blend

By default every surface is as few polygons as its shape needs: a wall, the floor, the ceiling,
a luminaire, a box side is one quad; the wall with the opening is the eight quads around it (its
floor and ceiling edges meet the whole floor and ceiling quads at T-junctions, as imported models
do). The bake's radiosity mesh subdivides where the light changes. ``--face-size`` splits every
surface into a grid of at most that size instead: the pre-meshed copy the benchmark compares per
face with Cycles (bench/blends/).

Contents: room (normals inward) with an opening 1.2 x 1.5 m in the south wall (no glass: light
escapes, the outside is black), a terracotta accent wall (west), four 0.6 m ceiling luminaire
panels hanging 5 cm below the ceiling (they emit from both faces in Cycles, so they also light the
ceiling above them), a desk and a shelving unit. All materials are Lambertian Principled BSDFs
(Specular IOR Level 0); luminaires have Base Color 0 so that they reflect nothing in every program.

The benchmark's copy has faces of at most ``face_size`` = 0.2 m: per-face comparison with
Cycles needs faces small against the light's variation (the corners are point samples in Cycles
and area averages of patches in our bake); 0.2 m gives ~3,500 faces, so a Cycles bake stays
affordable on 2 cores, and our engine's patch-size sweep (patches <= faces) starts at 0.2 m.
Boxes standing on the floor have no bottom face (it would be an unlit, meaningless error term).
"""

import argparse
import math
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

#: Materials: name -> (reflectance RGB, emission RGB radiance).
MATERIALS = {
    "wall": ((0.70, 0.70, 0.68), (0, 0, 0)),
    "ceiling": ((0.80, 0.80, 0.80), (0, 0, 0)),
    "floor": ((0.35, 0.28, 0.20), (0, 0, 0)),
    "accent": ((0.70, 0.28, 0.15), (0, 0, 0)),
    "desk": ((0.55, 0.45, 0.35), (0, 0, 0)),
    "shelf": ((0.60, 0.60, 0.62), (0, 0, 0)),
    "luminaire": ((0.0, 0.0, 0.0), (12.0, 11.4, 10.2)),
}


class MeshBuilder:
    """Collect grid-subdivided quads for one Blender object."""

    def __init__(self, face_size):
        self.h = float(face_size)
        self.verts, self.faces, self.mats, self._index = [], [], [], {}

    def _v(self, p):
        key = tuple(round(c, 6) for c in p)
        if key not in self._index:
            self._index[key] = len(self.verts)
            self.verts.append(key)
        return self._index[key]

    def rect(self, origin, u, v, mat, hole=None):
        """Quad origin + s u + t v (s, t in [0, 1]) split into a grid; normal = u x v.

        ``hole`` = (s0, s1, t0, t1) in metres along u and v: grid cells inside are left out (the
        grid is aligned to the hole's edges; a cell is inside when its centre is: tested at its
        start, a cell whose start rounded to just below the hole's edge was kept, and the
        apartment's 0.13 m copy had a 13 cm wall strip standing in a doorway).
        """
        lu = math.sqrt(sum(c * c for c in u))
        lv = math.sqrt(sum(c * c for c in v))
        cuts_u = _cuts(lu, self.h, hole[:2] if hole else ())
        cuts_v = _cuts(lv, self.h, hole[2:] if hole else ())
        for i in range(len(cuts_u) - 1):
            for j in range(len(cuts_v) - 1):
                cu, cv = 0.5 * (cuts_u[i] + cuts_u[i + 1]), 0.5 * (cuts_v[j] + cuts_v[j + 1])
                if hole and hole[0] < cu < hole[1] and hole[2] < cv < hole[3]:
                    continue
                quad = [(cuts_u[a], cuts_v[b]) for a, b in ((i, j), (i + 1, j), (i + 1, j + 1),
                                                            (i, j + 1))]
                self.faces.append([self._v([origin[k] + s / lu * u[k] + t / lv * v[k]
                                            for k in range(3)]) for s, t in quad])
                self.mats.append(mat)

    def box(self, lo, hi, mat, bottom=False, inward=False):
        """Axis-aligned box faces (outward normals unless ``inward``)."""
        x0, y0, z0 = lo
        x1, y1, z1 = hi
        dx, dy, dz = x1 - x0, y1 - y0, z1 - z0
        sides = [((x0, y0, z1), (dx, 0, 0), (0, dy, 0)),            # top, +z
                 ((x0, y0, z0), (dx, 0, 0), (0, 0, dz)),            # -y
                 ((x1, y1, z0), (-dx, 0, 0), (0, 0, dz)),           # +y
                 ((x0, y1, z0), (0, -dy, 0), (0, 0, dz)),           # -x
                 ((x1, y0, z0), (0, dy, 0), (0, 0, dz))]            # +x
        if bottom:
            sides.append(((x0, y1, z0), (dx, 0, 0), (0, -dy, 0)))   # -z
        for o, u, v in sides:
            if inward:
                self.rect(o, v, u, mat)
            else:
                self.rect(o, u, v, mat)


def _cuts(length, h, fixed):
    points = sorted({0.0, length, *[f for f in fixed if 0 < f < length]})
    out = [0.0]
    for a, b in zip(points[:-1], points[1:]):
        n = max(1, math.ceil((b - a) / h - 1e-9))
        out += [a + (b - a) * k / n for k in range(1, n + 1)]
    return out


def add_object(name, builder, materials, location=(0, 0, 0)):
    import bpy
    me = bpy.data.meshes.new(name)
    me.from_pydata(builder.verts, [], builder.faces)
    used = sorted(set(builder.mats), key=builder.mats.index)
    for m in used:
        me.materials.append(materials[m])
    me.polygons.foreach_set("material_index", [used.index(m) for m in builder.mats])
    me.update()
    ob = bpy.data.objects.new(name, me)
    ob.location = location
    bpy.context.scene.collection.objects.link(ob)
    return ob


def new_file(materials_table):
    """Empty Blender file with Cycles and the materials; returns name -> bpy material."""
    import bpy
    from bench.compare.cycles import principled_material
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.context.scene.render.engine = "CYCLES"
    world = bpy.data.worlds.new("black")
    world.color = (0, 0, 0)
    bpy.context.scene.world = world
    return {k: principled_material(k, rho, em) for k, (rho, em) in materials_table.items()}


def add_camera(location, target, lens=18.0):
    import bpy
    from mathutils import Vector
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.data.lens = lens
    cam.location = location
    cam.rotation_euler = (Vector(target) - Vector(location)).to_track_quat("-Z", "Y").to_euler()
    bpy.context.scene.collection.objects.link(cam)
    bpy.context.scene.camera = cam


def add_room_shell(name, mats, face_size, W, D, H, opening):
    """A W x D x H room, normals inward: floor, ceiling, three walls as object ``name`` (the south
    wall with ``opening`` = (u0, u1, v0, v1) cut out) and the west wall as "AccentWall"."""
    room = MeshBuilder(face_size)
    room.rect((0, 0, 0), (W, 0, 0), (0, D, 0), "floor")                       # floor, +z
    room.rect((0, 0, H), (0, D, 0), (W, 0, 0), "ceiling")                     # ceiling, -z
    # South wall (y = 0, normal +y, into the room) with the opening: u = -x, v = +z.
    room.rect((W, 0, 0), (-W, 0, 0), (0, 0, H), "wall", hole=opening)
    room.rect((0, D, 0), (W, 0, 0), (0, 0, H), "wall")                        # north, -y
    room.rect((W, D, 0), (0, -D, 0), (0, 0, H), "wall")                       # east, -x
    add_object(name, room, mats)
    accent = MeshBuilder(face_size)
    accent.rect((0, 0, 0), (0, D, 0), (0, 0, H), "accent")                    # west, +x
    add_object("AccentWall", accent, mats)


def build_office(face_size=0.2):
    mats = new_file(MATERIALS)
    W, D, H = 6.0, 4.0, 3.0
    add_room_shell("Room", mats, face_size, W, D, H, opening=(2.4, 3.6, 0.9, 2.4))
    lum = MeshBuilder(face_size)
    for cx in (2.0, 4.0):
        for cy in (1.3, 2.7):
            z = H - 0.05
            lum.rect((cx - 0.3, cy - 0.3, z), (0, 0.6, 0), (0.6, 0, 0), "luminaire")   # faces down
    add_object("Luminaires", lum, mats)
    desk = MeshBuilder(face_size)
    desk.box((2.2, 1.2, 0.72), (3.8, 2.0, 0.76), "desk", bottom=True)
    desk.box((2.25, 1.25, 0.0), (2.3, 1.95, 0.72), "desk")
    desk.box((3.7, 1.25, 0.0), (3.75, 1.95, 0.72), "desk")
    add_object("Desk", desk, mats)
    shelf = MeshBuilder(face_size)
    x0, x1, y0, y1 = 1.2, 3.0, D - 0.4, D - 0.02
    shelf.box((x0, y0, 0.0), (x0 + 0.03, y1, 2.0), "shelf")
    shelf.box((x1 - 0.03, y0, 0.0), (x1, y1, 2.0), "shelf")
    for z in (0.1, 0.55, 1.0, 1.45, 1.97):
        shelf.box((x0 + 0.03, y0, z), (x1 - 0.03, y1, z + 0.03), "shelf", bottom=True)
    add_object("Shelving", shelf, mats)
    add_camera((5.6, 0.4, 1.6), (1.5, 3.2, 1.0))


def camera_view(screens):
    """Open the file looking through the scene camera in every 3D view (framed on the room)."""
    for screen in screens:
        for area in screen.areas:
            if area.type == "VIEW_3D":
                for space in area.spaces:
                    if space.type == "VIEW_3D":
                        space.region_3d.view_perspective = "CAMERA"


def main(argv=None, build=build_office, default_out="sample_blends/office.blend", face_size=0.2):
    """Build and save the scene; ``face_size`` is the benchmark copy's (``--face-size``) in help."""
    import bpy
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--face-size", type=float, default=None,
                    help="split surfaces into faces of at most this size in metres (the "
                         "benchmark copy uses %g); default: as modelled" % face_size)
    ap.add_argument("--out", default=str(ROOT / default_out))
    args = ap.parse_args(argv)
    if args.face_size is not None and not args.face_size > 0:
        ap.error("--face-size must be > 0; got %r" % args.face_size)
    build(math.inf if args.face_size is None else args.face_size)
    camera_view(bpy.data.screens)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    bpy.ops.wm.save_as_mainfile(filepath=str(Path(args.out).resolve()), compress=True)
    faces = sum(len(ob.data.polygons) for ob in bpy.context.scene.objects if ob.type == "MESH")
    print("wrote %s: %d faces" % (args.out, faces))


if __name__ == "__main__":
    main()
