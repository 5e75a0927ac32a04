"""Generated architectural interiors for the scaling benchmark (issue 13): a suite of rooms.

``suite(rooms)`` is a row of ``rooms`` rooms, each 6 x 4 x 3 m inside, behind 15 cm thick
partition walls with a 0.9 x 2.1 m doorway in each, modelled the way an architect would:

- floor, ceiling and the long walls one quad each; a partition wall face around its doorway
  three quads (two jambs and the lintel: T-junctions at the lintel's ends), the doorway's
  reveals and threshold four quads; the two end walls one quad each;
- furniture as boxes: a desk (1.6 x 0.8 x 0.75 m) in the room, a cabinet (0.8 x 0.4 x 2.0 m)
  standing against the back wall with a 1 cm gap, a sofa block (2.0 x 0.8 x 0.45 m) on the
  floor;
- light: rooms 0, 2, 4, ... an emissive ceiling panel (1.2 x 0.6 m, 5 cm below the ceiling);
  rooms 1, 3, ... a 150 W point light 0.5 m below the ceiling. Light reaches every room from
  its neighbours through the doorways, so the whole suite is one enclosure: a hemicube in one
  room sees into the next.

Materials: 0 walls and ceiling (0.7), 1 floor (0.4), 2 desk (reddish), 3 cabinet (bluish),
4 sofa (greenish), 5 panel (emits 20 W/(m^2 sr)). Deterministic: no random numbers.
"""

import numpy as np

from bench.scenes import _Builder, _cube_faces

W, D, H = 6.0, 4.0, 3.0           # room inside (m)
T = 0.15                          # partition thickness (m)
DOOR_Y, DOOR_W, DOOR_H = 1.0, 0.9, 2.1
PITCH = W + T


def _quad(b, pts, normal, mat, obj):
    """A planar polygon ``pts`` ordered so that its normal points along ``normal``."""
    pts = np.asarray(pts, dtype=float)
    n = np.cross(pts[1] - pts[0], pts[2] - pts[0])
    b.polygon(pts if n @ np.asarray(normal, dtype=float) > 0 else pts[::-1], mat, obj)


def _wall_x(b, x, inward_x, has_door, obj, mat=0):
    """The wall face at ``x`` facing ``+x`` (inward_x=1) or ``-x``: one quad, or three around
    a doorway (jambs full height, lintel above the door)."""
    y_lo, y_hi = DOOR_Y, DOOR_Y + DOOR_W
    pieces = [(0.0, D, 0.0, H)] if not has_door else [
        (0.0, y_lo, 0.0, H), (y_hi, D, 0.0, H), (y_lo, y_hi, DOOR_H, H)]
    for y0, y1, z0, z1 in pieces:
        _quad(b, [(x, y0, z0), (x, y0, z1), (x, y1, z1), (x, y1, z0)], (inward_x, 0, 0), mat,
              obj)


def _reveal(b, x0, obj):
    """A doorway through the partition from ``x0`` to ``x0 + T``: jambs, head and threshold,
    facing into the opening."""
    x1 = x0 + T
    y0, y1 = DOOR_Y, DOOR_Y + DOOR_W
    _quad(b, [(x0, y0, 0), (x1, y0, 0), (x1, y0, DOOR_H), (x0, y0, DOOR_H)], (0, 1, 0), 0, obj)
    _quad(b, [(x0, y1, 0), (x1, y1, 0), (x1, y1, DOOR_H), (x0, y1, DOOR_H)], (0, -1, 0), 0, obj)
    _quad(b, [(x0, y0, DOOR_H), (x1, y0, DOOR_H), (x1, y1, DOOR_H), (x0, y1, DOOR_H)],
          (0, 0, -1), 0, obj)
    _quad(b, [(x0, y0, 0), (x1, y0, 0), (x1, y1, 0), (x0, y1, 0)], (0, 0, 1), 1, obj)


def _box(b, name, lo, hi, mat):
    obj = b.object(name)
    for fname, origin, u, v in _cube_faces(lo, hi, inward=False):
        if fname != "z-":                        # resting on the floor: no bottom
            origin, u, v = (np.asarray(a, dtype=float) for a in (origin, u, v))
            b.polygon([origin, origin + u, origin + u + v, origin + v], mat, obj)


def suite(rooms):
    """The Scene of ``rooms`` rooms in a row (see the module docstring) and its lights."""
    from core import scene_from_polygons

    b = _Builder()
    lights = []
    for k in range(rooms):
        x0 = k * PITCH
        room = b.object(f"room {k}")
        _quad(b, [(x0, 0, 0), (x0 + W, 0, 0), (x0 + W, D, 0), (x0, D, 0)], (0, 0, 1), 1, room)
        _quad(b, [(x0, 0, H), (x0 + W, 0, H), (x0 + W, D, H), (x0, D, H)], (0, 0, -1), 0, room)
        _quad(b, [(x0, 0, 0), (x0 + W, 0, 0), (x0 + W, 0, H), (x0, 0, H)], (0, 1, 0), 0, room)
        _quad(b, [(x0, D, 0), (x0 + W, D, 0), (x0 + W, D, H), (x0, D, H)], (0, -1, 0), 0, room)
        _wall_x(b, x0, +1, k > 0, room)
        _wall_x(b, x0 + W, -1, k < rooms - 1, room)
        if k < rooms - 1:
            _reveal(b, x0 + W, b.object(f"doorway {k}"))
        _box(b, f"desk {k}", (x0 + 1.2, 1.6, 0), (x0 + 2.8, 2.4, 0.75), 2)
        _box(b, f"cabinet {k}", (x0 + 4.2, D - 0.41, 0), (x0 + 5.0, D - 0.01, 2.0), 3)
        _box(b, f"sofa {k}", (x0 + 3.4, 0.3, 0), (x0 + 5.4, 1.1, 0.45), 4)
        if k % 2 == 0:
            px, py, pw, pd = x0 + 0.5 * (W - 1.2), 0.5 * (D - 0.6), 1.2, 0.6
            _quad(b, [(px, py, H - 0.05), (px + pw, py, H - 0.05), (px + pw, py + pd, H - 0.05),
                      (px, py + pd, H - 0.05)], (0, 0, -1), 5, b.object(f"panel {k}"))
        else:
            lights.append(dict(kind="point", name=f"lamp {k}", power=150.0,
                               position=(x0 + 0.5 * W, 0.5 * D, H - 0.5), radius=0.05))
    rho = np.array([[0.7] * 3, [0.4] * 3, [0.6, 0.25, 0.2], [0.2, 0.3, 0.6], [0.3, 0.55, 0.3],
                    [0.8] * 3])
    le = np.zeros((6, 3))
    le[5] = 20.0
    return scene_from_polygons(np.concatenate(b.vertices), b.polygons, b.materials, rho, le,
                               face_objects=b.objects, object_names=b.object_names,
                               material_names=["wall", "floor", "desk", "cabinet", "sofa",
                                               "panel"],
                               lights=lights or None)
