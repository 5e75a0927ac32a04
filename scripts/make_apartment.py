"""Build sample_blends/apartment.blend: a 12 x 8 x 2.8 m apartment/gallery, modelled coarse.

Run with the oldest supported Blender's bpy (Blender 5 writes files 4.x cannot open)::

    .venv-bpy42/bin/python scripts/make_apartment.py              # sample_blends/apartment.blend
    .venv-bpy42/bin/python scripts/make_apartment.py --face-size 0.13 \
        --out bench/blends/apartment.blend                         # the benchmark's copy

By default surfaces are modelled as an architect would (see make_office.py): one quad per wall
side, floor, ceiling, plinth side and luminaire, doorways and the window as the few quads around
them. ``--face-size`` meshes them as grids instead: the benchmark's pre-meshed copy
(bench/blends/), > 20,000 faces at 0.13 m.

Three rooms: two 6 x 4 m rooms on the west side (separated by a 0.1 m thick wall with a doorway)
and a 6 x 8 m gallery on the east, joined through two doorways in a 0.1 m thick wall; a window
opening (no glass) in the gallery's south wall; six plinths in the gallery; one luminaire panel in
each small room and four in the gallery (5 cm below the ceiling, emitting from both faces in
Cycles). In the benchmark's copy, faces <= 0.13 m give ~25,000 faces: at the default 0.5 m
patch size our engine needs one patch per face, i.e. well over 20,000 patches. Same materials and
conventions as make_office.py.
"""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from make_office import (MATERIALS, MeshBuilder, add_camera, add_object, add_room_shell,  # noqa: E402
                         main, new_file)

APARTMENT_MATERIALS = dict(MATERIALS, plinth=((0.75, 0.74, 0.72), (0, 0, 0)),
                           luminaire=((0.0, 0.0, 0.0), (15.0, 14.4, 13.2)))


def _wall(b, axis, at, lo, hi, H, doors, mat="wall", t=0.1):
    """A wall of thickness t centred on ``axis`` = ``at`` spanning [lo, hi] along the other
    horizontal axis, with doorways (d0, d1, height): two faces (one per side) + door reveals."""
    a0, a1 = at - t / 2, at + t / 2
    # Face each side split per doorway segment so each rect carries at most one hole.
    cuts = [lo] + [0.5 * (doors[k][1] + doors[k + 1][0]) for k in range(len(doors) - 1)] + [hi]
    for k in range(len(cuts) - 1):
        s0, s1 = cuts[k], cuts[k + 1]
        hole = None
        if doors:
            d0, d1, dh = doors[k]
            hole = (d0 - s0, d1 - s0, 0.0, dh)
        L = s1 - s0
        if axis == "x":   # wall plane x = at, running along y
            b.rect((a0, s1, 0), (0, -L, 0), (0, 0, H), mat,
                   hole=(L - hole[1], L - hole[0], 0, hole[3]) if hole else None)      # -x side
            b.rect((a1, s0, 0), (0, L, 0), (0, 0, H), mat, hole=hole)                 # +x side
        else:             # wall plane y = at, running along x
            b.rect((s0, a0, 0), (L, 0, 0), (0, 0, H), mat, hole=hole)                 # -y side
            b.rect((s1, a1, 0), (-L, 0, 0), (0, 0, H), mat,
                   hole=(L - hole[1], L - hole[0], 0, hole[3]) if hole else None)      # +y side
    for d0, d1, dh in doors:   # reveals: jambs face into the doorway, head faces down
        # (normal = u x v). The benchmark's copy in bench/blends/ was made before this was
        # put right (7 reveal faces there face into the wall); its figures stand for that file.
        if axis == "x":
            b.rect((a0, d0, 0), (0, 0, dh), (t, 0, 0), mat)                            # +y
            b.rect((a1, d1, 0), (0, 0, dh), (-t, 0, 0), mat)                           # -y
            b.rect((a0, d0, dh), (0, d1 - d0, 0), (t, 0, 0), mat)                      # -z
        else:
            b.rect((d0, a1, 0), (0, 0, dh), (0, -t, 0), mat)                           # +x
            b.rect((d1, a0, 0), (0, 0, dh), (0, t, 0), mat)                            # -x
            b.rect((d0, a0, dh), (0, t, 0), (d1 - d0, 0, 0), mat)                      # -z


def build_apartment(face_size=0.13):
    mats = new_file(APARTMENT_MATERIALS)
    W, D, H = 12.0, 8.0, 2.8
    add_room_shell("Shell", mats, face_size, W, D, H, opening=(2.0, 4.0, 0.8, 2.2))
    walls = MeshBuilder(face_size)
    _wall(walls, "x", 6.0, 0.0, D, H, [(1.5, 2.4, 2.1), (5.5, 6.4, 2.1)])
    _wall(walls, "y", 4.0, 0.0, 5.95, H, [(2.5, 3.4, 2.1)])
    add_object("InteriorWalls", walls, mats)
    plinths = MeshBuilder(face_size)
    for cx in (7.5, 9.0, 10.5):
        for cy in (2.5, 5.5):
            plinths.box((cx - 0.4, cy - 0.4, 0.0), (cx + 0.4, cy + 0.4, 1.0), "plinth")
    add_object("Plinths", plinths, mats)
    lum = MeshBuilder(face_size)
    z = H - 0.05
    for cx, cy in ((3.0, 2.0), (3.0, 6.0), (7.5, 2.5), (10.5, 2.5), (7.5, 5.5), (10.5, 5.5)):
        lum.rect((cx - 0.4, cy - 0.4, z), (0, 0.8, 0), (0.8, 0, 0), "luminaire")    # faces down
    add_object("Luminaires", lum, mats)
    add_camera((11.6, 0.4, 1.6), (6.0, 5.0, 1.0))


if __name__ == "__main__":
    main(build=build_apartment, default_out="sample_blends/apartment.blend", face_size=0.13)
