"""The provoking scenes of the stability report, built from rectangles and polygons.

Every builder returns the Scene and the face indices the measurement reads (a dict of arrays).
Rooms have inward normals, boxes outward, lamps face down; polygons are counter-clockwise about
their normal. Materials: see each builder.
"""

import numpy as np

from core.scene import scene_from_polygons


def quad(origin, u, v):
    """(4, 3): the parallelogram origin, +u, +u+v, +v (normal along u x v)."""
    o, u, v = (np.asarray(a, dtype=np.float64) for a in (origin, u, v))
    return np.array([o, o + u, o + u + v, o + v])


def fan(poly, n):
    """The convex polygon ``poly`` (k, 3) as a fan of about ``n`` triangles from its corner 0 to
    points spaced evenly along each of its far edges (corner 1 to corner k-1; at least one
    triangle per edge, counts by length): the slivers a CAD triangulation leaves at a room
    corner. Returns a list of (3, 3) triangles."""
    poly = np.asarray(poly, dtype=np.float64)
    far = poly[1:]
    length = np.linalg.norm(np.diff(far, axis=0), axis=1)
    counts = np.maximum(1, np.round(n * length / length.sum())).astype(int)
    pts = [far[0]]
    for a, b, m in zip(far[:-1], far[1:], counts):
        pts += [a + (b - a) * t for t in np.arange(1, m + 1) / m]
    return [np.array([poly[0], pts[i], pts[i + 1]]) for i in range(len(pts) - 1)]


def aspect(tri):
    """Longest edge over the height onto it: 1.15 for an equilateral triangle."""
    e = np.linalg.norm(tri - np.roll(tri, -1, axis=0), axis=1)
    area = 0.5 * np.linalg.norm(np.cross(tri[1] - tri[0], tri[2] - tri[0]))
    return float(e.max() ** 2 / (2.0 * area))


class Builder:
    """Polygons with a material and a named group each."""

    def __init__(self):
        self.verts, self.polys, self.mats, self.groups = [], [], [], {}

    def add(self, points, material, group):
        points = np.asarray(points, dtype=np.float64)
        base = sum(len(v) for v in self.verts)
        self.verts.append(points)
        self.polys.append(list(range(base, base + len(points))))
        self.mats.append(material)
        self.groups.setdefault(group, []).append(len(self.polys) - 1)

    def box(self, lo, hi, material, group):
        (x0, y0, z0), (x1, y1, z1) = lo, hi
        dx, dy, dz = x1 - x0, y1 - y0, z1 - z0
        for o, u, v in (((x0, y0, z0), (0, dy, 0), (dx, 0, 0)), ((x0, y0, z1), (dx, 0, 0),
                                                                (0, dy, 0)),
                        ((x0, y0, z0), (dx, 0, 0), (0, 0, dz)), ((x1, y0, z0), (0, dy, 0),
                                                                (0, 0, dz)),
                        ((x0, y1, z0), (0, 0, dz), (dx, 0, 0)), ((x0, y0, z0), (0, 0, dz),
                                                                (0, dy, 0))):
            self.add(quad(o, u, v), material, group)

    def scene(self, reflectance, emission, **kw):
        names = list(self.groups)
        objects = np.zeros(len(self.polys), dtype=np.int64)
        for i, name in enumerate(names):
            objects[self.groups[name]] = i
        scene = scene_from_polygons(np.concatenate(self.verts), self.polys, self.mats,
                                    reflectance, emission, face_objects=objects,
                                    object_names=names, **kw)
        return scene, {k: np.array(v) for k, v in self.groups.items()}


def room_walls(W, D, H):
    """The four walls of [0, W] x [0, D] x [0, H], inward: (name, polygon) pairs."""
    return [("wall y0", quad((0, 0, 0), (0, 0, H), (W, 0, 0))),
            ("wall x1", quad((W, 0, 0), (0, 0, H), (0, D, 0))),
            ("wall y1", quad((0, D, 0), (W, 0, 0), (0, 0, H))),
            ("wall x0", quad((0, 0, 0), (0, D, 0), (0, 0, H)))]


def lamp(b, cx, cy, z, size, material, group="lamp"):
    """A square lamp of side ``size`` centred at (cx, cy, z), facing down."""
    s = size
    b.add(quad((cx - s / 2, cy - s / 2, z), (0, s, 0), (s, 0, 0)), material, group)


#: The room of classes 2, 3, 4 and 6: W x D x H (m), floor, ceiling, walls, box, lamp
#: reflectances and the lamp's radiance.
ROOM = (4.0, 3.0, 2.5)
#: The room's box: its lowest and highest corners (m), standing on the floor.
BOX = ((1.0, 1.0, 0.0), (2.0, 2.0, 0.8))
ROOM_RHO = np.array([[0.7] * 3, [0.8] * 3, [0.4, 0.5, 0.6], [0.5] * 3, [0.0] * 3])
ROOM_LE = 20.0


def room(*, drop=0.3, fan_walls=0, copy=None, offset=(0.0, 0.0, 0.0), scale=1.0):
    """A 4 x 3 x 2.5 m room, walls one quad each (or fans of ``fan_walls`` triangles from a room
    corner), a 1 x 1 x 0.8 m box on the floor, a 1 m lamp (radiance 20) ``drop`` m under the
    ceiling. ``copy``: (offset / floor size, flipped) adds a copy of the floor that far above it
    (group 'copy'). The whole scene is scaled by ``scale`` then moved by ``offset``.
    Materials: 0 floor, 1 ceiling, 2 walls, 3 box, 4 lamp."""
    W, D, H = ROOM
    b = Builder()
    floor = quad((0, 0, 0), (W, 0, 0), (0, D, 0))
    b.add(floor, 0, "floor")
    b.add(quad((0, 0, H), (0, D, 0), (W, 0, 0)), 1, "ceiling")
    for name, poly in room_walls(W, D, H):
        for tri in (fan(poly, fan_walls) if fan_walls else [poly]):
            b.add(tri, 2, name)
    b.box(*BOX, 3, "box")
    lamp(b, 2.5, 1.5, H - drop, 1.0, 4)
    if copy is not None:
        rel, flipped = copy
        c = floor + [0.0, 0.0, rel * np.sqrt(W * D)]
        b.add(c[::-1] if flipped else c, 0, "copy")
    for i, v in enumerate(b.verts):
        b.verts[i] = v * scale + np.asarray(offset, dtype=np.float64)
    em = np.zeros((5, 3))
    em[4] = ROOM_LE
    return b.scene(ROOM_RHO, em)


#: The room of class 1 (W, D, H m).
LAMP_ROOM = (4.0, 4.0, 3.0)


def lamp_room():
    """A Builder holding the LAMP_ROOM's floor (material 0), ceiling and walls (1), inward."""
    W, D, H = LAMP_ROOM
    b = Builder()
    b.add(quad((0, 0, 0), (W, 0, 0), (0, D, 0)), 0, "floor")
    b.add(quad((0, 0, H), (0, D, 0), (W, 0, 0)), 1, "ceiling")
    for name, poly in room_walls(W, D, H):
        b.add(poly, 1, name)
    return b


#: Reflectance of the lamp rooms' floors (class 1: :func:`emitter_room`, :func:`bulb_room`).
FLOOR_RHO = 0.5


def emitter_room(size, walls_rho=0.0):
    """The 4 x 4 x 3 m room of tests/core/test_emitters.py: floor (reflectance 0.5, material 0),
    walls and ceiling ``walls_rho`` (1), a square lamp of side ``size`` 5 cm under the ceiling at
    (1.3, 2.1), radiance 1 / size^2 (2): the same power at every size. Returns the scene, the
    groups and the lamp's polygon (4, 3)."""
    b = lamp_room()
    lamp(b, 1.3, 2.1, LAMP_ROOM[2] - 0.05, size, 2)
    em = np.zeros((3, 3))
    em[2] = 1.0 / size ** 2
    scene, groups = b.scene(np.array([[FLOOR_RHO] * 3, [walls_rho] * 3, [0.0] * 3]), em)
    return scene, groups, np.concatenate(b.verts)[-4:]


def comb(k, convex):
    """An L (k = 1) or comb-shaped room, 2.5 m high: a 2 m deep spine along x with ``k`` teeth,
    1.2 m wide and 2.5 m long, 1 m apart; the spine runs 1 m past the last tooth. Floor and
    ceiling are one concave polygon each, or (``convex``) the same area as rectangles. A 1 m lamp
    (radiance 20) hangs 0.3 m under the ceiling over the spine's middle. Materials: 0 floor,
    1 ceiling, 2 walls, 3 lamp. Returns the scene, the groups and the floor outline (n, 2)."""
    s, t, g, L, H = 2.0, 1.2, 1.0, 2.5, 2.5
    W = k * (t + g)
    outline = [(0.0, 0.0), (W, 0.0), (W, s)]
    for i in reversed(range(k)):
        x0 = i * (t + g)
        outline += [(x0 + t, s), (x0 + t, s + L), (x0, s + L), (x0, s)]
    outline = np.array(outline)
    b = Builder()
    if convex:
        xs = sorted({0.0, W, *[i * (t + g) for i in range(k)],
                     *[i * (t + g) + t for i in range(k)]})
        for x0, x1 in zip(xs[:-1], xs[1:]):
            b.add(quad((x0, 0, 0), (x1 - x0, 0, 0), (0, s, 0)), 0, "floor")
            b.add(quad((x0, 0, H), (0, s, 0), (x1 - x0, 0, 0)), 1, "ceiling")
        for i in range(k):
            x0 = i * (t + g)
            b.add(quad((x0, s, 0), (t, 0, 0), (0, L, 0)), 0, "floor")
            b.add(quad((x0, s, H), (0, L, 0), (t, 0, 0)), 1, "ceiling")
    else:
        pts = np.column_stack([outline, np.zeros(len(outline))])
        b.add(pts, 0, "floor")
        b.add((pts + [0, 0, H])[::-1], 1, "ceiling")
    for a, c in zip(outline, np.roll(outline, -1, axis=0)):
        d = np.append(c - a, 0.0)
        b.add(quad((*a, 0.0), (0, 0, H), d), 2, "walls")
    lamp(b, W / 2, s / 2, H - 0.3, 1.0, 3)
    em = np.zeros((4, 3))
    em[3] = 20.0
    rho = np.array([[0.7] * 3, [0.8] * 3, [0.5] * 3, [0.0] * 3])
    scene, groups = b.scene(rho, em)
    return scene, groups, outline


def ground_room(size):
    """A closed 3 m cube room (inward, reflectance 0.5) with a 1 m lamp (radiance 10) 0.3 m under
    its ceiling, standing on a ``size`` x ``size`` m ground plane 1 cm below its floor (size 0:
    no ground). Materials: 0 room and ground, 1 lamp."""
    b = Builder()
    S = 3.0
    b.add(quad((0, 0, 0), (S, 0, 0), (0, S, 0)), 0, "floor")
    b.add(quad((0, 0, S), (0, S, 0), (S, 0, 0)), 0, "ceiling")
    for name, poly in room_walls(S, S, S):
        b.add(poly, 0, name)
    lamp(b, S / 2, S / 2, S - 0.3, 1.0, 1)
    if size:
        h = size / 2
        b.add(quad((S / 2 - h, S / 2 - h, -0.01), (size, 0, 0), (0, size, 0)), 0, "ground")
    return b.scene(np.array([[0.5] * 3, [0.0] * 3]), np.array([[0.0] * 3, [10.0] * 3]))


def furnace_cube(rho, le=1.0, size=2.0):
    """A closed cube, one quad per face (inward), every face reflecting ``rho`` and emitting
    ``le``: the radiance is le / (1 - rho) everywhere inside."""
    b = Builder()
    S = size
    b.add(quad((0, 0, 0), (S, 0, 0), (0, S, 0)), 0, "floor")
    b.add(quad((0, 0, S), (0, S, 0), (S, 0, 0)), 0, "ceiling")
    for name, poly in room_walls(S, S, S):
        b.add(poly, 0, name)
    return b.scene(np.full((1, 3), rho), np.full((1, 3), le))


def opposed_squares(gap, size=1.0, le=1.0, rho=0.5):
    """A receiver square (reflectance ``rho``, facing up) under an emitting square (radiance
    ``le``, reflectance 0, facing down) ``gap`` above it, nothing else. Materials: 0, 1."""
    b = Builder()
    b.add(quad((0, 0, 0), (size, 0, 0), (0, size, 0)), 0, "receiver")
    b.add(quad((0, 0, gap), (0, size, 0), (size, 0, 0)), 1, "emitter")
    return b.scene(np.array([[rho] * 3, [0.0] * 3]), np.array([[0.0] * 3, [le] * 3]))


def hung_panel(gap, size=2.0, panel=0.6, le=10.0, rho=0.8):
    """A closed ``size`` m cube, black but for its ceiling (reflectance ``rho``), with a square
    panel of side ``panel`` (radiance ``le`` from both sides, reflectance 0) ``gap`` under the
    ceiling: the ceiling reads rho Le F(x -> panel) exactly. Materials: 0 black, 1 ceiling,
    2 panel. Returns the scene, the groups and the panel polygon (4, 3)."""
    b = Builder()
    S = size
    b.add(quad((0, 0, 0), (S, 0, 0), (0, S, 0)), 0, "floor")
    b.add(quad((0, 0, S), (0, S, 0), (S, 0, 0)), 1, "ceiling")
    for name, poly in room_walls(S, S, S):
        b.add(poly, 0, name)
    lamp(b, S / 2, S / 2, S - gap, panel, 2)
    scene, groups = b.scene(np.array([[0.0] * 3, [rho] * 3, [0.0] * 3]),
                            np.array([[0.0] * 3, [0.0] * 3, [le] * 3]))
    return scene, groups, np.concatenate(b.verts)[-4:]


def uv_sphere(centre, r, nu, nv):
    """Polygons (outward) of a UV sphere: triangle fans at the poles, quads between."""
    th = np.linspace(0.0, np.pi, nv + 1)
    ph = np.linspace(0.0, 2.0 * np.pi, nu + 1)

    def p(i, j):
        return np.asarray(centre) + r * np.array([np.sin(th[i]) * np.cos(ph[j]),
                                                  np.sin(th[i]) * np.sin(ph[j]), np.cos(th[i])])
    polys = []
    for i in range(nv):
        for j in range(nu):
            if i == 0:
                poly = [p(0, 0), p(1, j + 1), p(1, j)]
            elif i == nv - 1:
                poly = [p(i, j), p(i, j + 1), p(nv, 0)]
            else:
                poly = [p(i, j), p(i, j + 1), p(i + 1, j + 1), p(i + 1, j)]
            poly = np.array(poly)
            n = np.cross(poly[1] - poly[0], poly[2] - poly[0])
            polys.append(poly if n @ (poly.mean(0) - centre) > 0 else poly[::-1])
    return polys


def bulb_room(r, nu, nv):
    """The room with the bulb (radiance 1 / (pi r^2): the same power at every radius); the
    scene, its groups and the bulb's polygons."""
    b = lamp_room()
    polys = uv_sphere(np.array([1.3, 2.1, LAMP_ROOM[2] - 0.5]), r, nu, nv)
    for poly in polys:
        b.add(poly, 2, "lamp")
    em = np.zeros((3, 3))
    em[2] = 1.0 / (np.pi * r * r)
    scene, groups = b.scene(np.array([[FLOOR_RHO] * 3, [0.0] * 3, [0.0] * 3]), em)
    return scene, groups, polys, em[2, 0]
