"""Procedural scenes for tests, benchmarks and the README example (not shipped in the extension).

Every builder returns a :class:`~core.scene.Scene`. Rectangles are meshed as grids of quads whose
normals point into the room (walls) or out of the solid (boxes), counter-clockwise about the normal.
"""

import numpy as np

try:  # inside the repository loaded as one package (scripts/make_cornell_box.py)
    from ..core.scene import make_scene
except ImportError:  # the repository root on sys.path (tests, bench, the README example)
    from core.scene import make_scene

#: Cornell box reflectances, RGB = band averages over 600-700, 500-596 and 400-496 nm of the
#: published spectra (shared/reference/cornell_box.md).
CORNELL_WHITE = (0.7339, 0.7358, 0.6978)
CORNELL_RED = (0.5761, 0.0832, 0.0562)
CORNELL_GREEN = (0.1329, 0.3508, 0.1136)


class _Builder:
    """Accumulates polygons with per-face material and object indices."""

    def __init__(self):
        self.vertices = []
        self.polygons = []
        self.materials = []
        self.objects = []
        self.object_names = []
        self._n = 0

    def object(self, name):
        self.object_names.append(name)
        return len(self.object_names) - 1

    def polygon(self, points, material, obj):
        points = np.asarray(points, dtype=np.float64)
        self.vertices.append(points)
        self.polygons.append(list(range(self._n, self._n + len(points))))
        self._n += len(points)
        self.materials.append(material)
        self.objects.append(obj)

    def grid(self, origin, u, v, nu, nv, material, obj):
        """A rectangle origin + s u + t v, s, t in [0, 1], as nu x nv quads; normal along u x v."""
        origin, u, v = (np.asarray(a, dtype=np.float64) for a in (origin, u, v))
        s = np.linspace(0.0, 1.0, nu + 1)
        t = np.linspace(0.0, 1.0, nv + 1)
        pts = origin + s[:, None, None] * u + t[None, :, None] * v  # (nu+1, nv+1, 3)
        base = self._n
        self.vertices.append(pts.reshape(-1, 3))
        self._n += pts.shape[0] * pts.shape[1]
        idx = base + np.arange((nu + 1) * (nv + 1)).reshape(nu + 1, nv + 1)
        quads = np.stack([idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]], axis=-1).reshape(-1, 4)
        self.polygons.extend(quads.tolist())
        self.materials.extend([material] * len(quads))
        self.objects.extend([obj] * len(quads))

    def scene(self, reflectance, emission, material_names=None):
        vertices = np.concatenate(self.vertices, axis=0)
        sizes = np.array([len(p) for p in self.polygons], dtype=np.int64)
        starts = np.cumsum(sizes) - sizes
        corner_verts = np.fromiter((i for p in self.polygons for i in p), dtype=np.int64,
                                   count=int(sizes.sum()))
        return make_scene(vertices, corner_verts, starts, sizes, self.materials, reflectance,
                          emission, face_objects=self.objects, object_names=self.object_names,
                          material_names=material_names)


def _cube_faces(lo, hi, inward):
    """The six faces of an axis-aligned box as (name, origin, u, v), normals in or out."""
    lo = np.asarray(lo, dtype=np.float64)
    hi = np.asarray(hi, dtype=np.float64)
    d = hi - lo
    ex, ey, ez = np.diag(d)
    faces = [
        ("x-", lo, ez, ey), ("x+", lo + ex, ey, ez),
        ("y-", lo, ex, ez), ("y+", lo + ey, ez, ex),
        ("z-", lo, ey, ex), ("z+", lo + ez, ex, ey),
    ]
    # As listed, every normal u x v points out of the box; swap u and v to point inward.
    if inward:
        faces = [(n, o, v, u) for n, o, u, v in faces]
    return faces


def unit_cube(n=1, emitting=("z+",), reflectance=0.5, emission=1.0):
    """Inside of the unit cube [0, 1]^3, each face an object of n x n quads, normals inward.

    Material i belongs to face i in the order x-, x+, y-, y+, z-, z+ (object names the same);
    the faces named in ``emitting`` emit ``emission`` (radiance, grey).
    """
    b = _Builder()
    for i, (name, origin, u, v) in enumerate(_cube_faces((0, 0, 0), (1, 1, 1), inward=True)):
        b.grid(origin, u, v, n, n, material=i, obj=b.object(name))
    names = [f[0] for f in _cube_faces((0, 0, 0), (1, 1, 1), True)]
    rho = np.full((6, 3), float(reflectance))
    le = np.array([[float(emission)] * 3 if nm in emitting else [0.0] * 3 for nm in names])
    return b.scene(rho, le, material_names=names)


def furnace_box(rho=0.5, le=1.0, n=4, size=1.0):
    """The white furnace: a closed cube, uniform reflectance and emission everywhere.

    Exact answer: outgoing radiance L = le / (1 - rho) on every surface.
    """
    b = _Builder()
    for name, origin, u, v in _cube_faces((0, 0, 0), (size,) * 3, inward=True):
        b.grid(origin, u, v, n, n, material=0, obj=b.object(name))
    return b.scene(np.full((1, 3), float(rho)), np.full((1, 3), float(le)), material_names=["furnace"])


def opposed_squares(size=1.0, gap=1.0, n=1, rho=0.5, le=1.0):
    """Two directly opposed squares ``size`` wide, ``gap`` apart; the upper one emits downwards.

    Object 0 ("floor") faces +z at z = 0; object 1 ("emitter") faces -z at z = gap.
    """
    b = _Builder()
    s = float(size)
    b.grid((0, 0, 0), (s, 0, 0), (0, s, 0), n, n, material=0, obj=b.object("floor"))
    b.grid((0, 0, gap), (0, s, 0), (s, 0, 0), n, n, material=1, obj=b.object("emitter"))
    rho_arr = np.array([[rho] * 3, [0.0] * 3])
    le_arr = np.array([[0.0] * 3, [le] * 3])
    return b.scene(rho_arr, le_arr, material_names=["floor", "emitter"])


#: Rectangles of the benchmark room, as (name, origin, u, v, material), normals u x v.
def _room_rectangles(w, d, h):
    rects = []
    for name, origin, u, v in _cube_faces((0, 0, 0), (w, d, h), inward=True):
        rects.append(("floor" if name == "z-" else "ceiling" if name == "z+" else "wall " + name,
                      origin, u, v, 1 if name == "z-" else 0))
    boxes = [("box A", (1.0, 1.0, 0.0), (2.2, 1.8, 0.9), 2),
             ("box B", (3.8, 2.2, 0.0), (4.6, 3.0, 1.8), 3)]
    for name, lo, hi, mat in boxes:
        for fname, origin, u, v in _cube_faces(lo, hi, inward=False):
            if fname != "z-":  # resting on the floor: no bottom
                rects.append((f"{name} {fname}", origin, u, v, mat))
    # Luminaire panel 5 cm below the ceiling, facing down (and, two-sided, up).
    pw, pd = 1.2, 0.6
    x0, y0 = 0.5 * (w - pw), 0.5 * (d - pd)
    rects.append(("ceiling panel", (x0, y0, h - 0.05), (0, pd, 0), (pw, 0, 0), 4))
    return rects


def room_with_boxes(n_quads=2000, size=(6.0, 4.0, 3.0), panel_radiance=20.0):
    """A closed room with two boxes on the floor and an emissive ceiling panel.

    The benchmark scene of the core: every rectangle is meshed uniformly so that the total is
    about ``n_quads`` quads (at least one per rectangle). Materials: 0 walls and ceiling (0.7 grey),
    1 floor (0.4 grey), 2 box A (reddish), 3 box B (bluish), 4 panel (emits ``panel_radiance``).
    """
    w, d, h = size
    rects = _room_rectangles(w, d, h)
    areas = [np.linalg.norm(np.cross(u, v)) for _, _, u, v, _ in rects]
    cell = np.sqrt(sum(areas) / float(n_quads))
    b = _Builder()
    for name, origin, u, v, mat in rects:
        nu = max(1, int(round(np.linalg.norm(u) / cell)))
        nv = max(1, int(round(np.linalg.norm(v) / cell)))
        b.grid(origin, u, v, nu, nv, material=mat, obj=b.object(name))
    rho = np.array([[0.7, 0.7, 0.7], [0.4, 0.4, 0.4], [0.6, 0.25, 0.2], [0.2, 0.3, 0.6], [0.8, 0.8, 0.8]])
    le = np.zeros((5, 3))
    le[4] = panel_radiance
    return b.scene(rho, le, material_names=["wall", "floor", "box A", "box B", "panel"])


#: Cornell box geometry in millimetres, +y up (shared/reference/cornell_box.md).
_CORNELL = {
    "floor": ([[552.8, 0, 0], [0, 0, 0], [0, 0, 559.2], [549.6, 0, 559.2]], "white"),
    "light": ([[343.0, 548.8, 227.0], [343.0, 548.8, 332.0], [213.0, 548.8, 332.0],
               [213.0, 548.8, 227.0]], "light"),
    "back wall": ([[549.6, 0, 559.2], [0, 0, 559.2], [0, 548.8, 559.2], [556.0, 548.8, 559.2]], "white"),
    "right wall": ([[0, 0, 559.2], [0, 0, 0], [0, 548.8, 0], [0, 548.8, 559.2]], "green"),
    "left wall": ([[552.8, 0, 0], [549.6, 0, 559.2], [556.0, 548.8, 559.2], [556.0, 548.8, 0]], "red"),
}
_CORNELL_BLOCKS = {
    "short block": [
        [[130, 165, 65], [82, 165, 225], [240, 165, 272], [290, 165, 114]],
        [[290, 0, 114], [290, 165, 114], [240, 165, 272], [240, 0, 272]],
        [[130, 0, 65], [130, 165, 65], [290, 165, 114], [290, 0, 114]],
        [[82, 0, 225], [82, 165, 225], [130, 165, 65], [130, 0, 65]],
        [[240, 0, 272], [240, 165, 272], [82, 165, 225], [82, 0, 225]],
    ],
    "tall block": [
        [[423, 330, 247], [265, 330, 296], [314, 330, 456], [472, 330, 406]],
        [[423, 0, 247], [423, 330, 247], [472, 330, 406], [472, 0, 406]],
        [[472, 0, 406], [472, 330, 406], [314, 330, 456], [314, 0, 456]],
        [[314, 0, 456], [314, 330, 456], [265, 330, 296], [265, 0, 296]],
        [[265, 0, 296], [265, 330, 296], [423, 330, 247], [423, 0, 247]],
    ],
}


def cornell_light_radiance(peak=50.0):
    """RGB radiance of the Cornell light: band averages of its published spectrum, max = ``peak``.

    The spectrum is linear between 400 nm: 0, 500 nm: 8, 600 nm: 15.6, 700 nm: 18.4; bands are
    R = 600-700, G = 500-596, B = 400-496 nm (the reflectance bands).
    """
    nm = np.arange(400.0, 701.0, 4.0)
    s = np.interp(nm, [400, 500, 600, 700], [0.0, 8.0, 15.6, 18.4])
    r = s[(nm >= 600) & (nm <= 700)].mean()
    g = s[(nm >= 500) & (nm <= 596)].mean()
    bl = s[(nm >= 400) & (nm <= 496)].mean()
    rgb = np.array([r, g, bl])
    return rgb * (peak / rgb.max())


def cornell_geometry():
    """The Cornell box as (name, points (k, 3) metres in Blender axes, material name) polygons.

    Blender axes: X = x, Y = -z, Z = y (a rotation, so handedness is kept: the red wall stays on
    the camera's left). Millimetres become metres. The light sits in an opening of the ceiling,
    as in the real box: the ceiling is the 3 x 3 grid of quads around the light's rectangle minus
    its centre, so nothing coincides with the light and its back side (mesh lights emit from both
    sides in Cycles) emits out of the box. The non-planar red wall is split into two triangles.
    Every normal points into the box (walls) or out of the block (blocks); the light faces down.
    """
    def to_blender(p):
        p = np.asarray(p, dtype=np.float64) / 1000.0
        return np.stack([p[:, 0], -p[:, 2], p[:, 1]], axis=1)

    centre = to_blender([[278.0, 274.4, 279.6]])[0]
    polys = []

    def add(name, pts, mat, outward_from=None):
        n = np.cross(pts[1] - pts[0], pts[2] - pts[0])
        c = pts.mean(axis=0)
        if outward_from is None:  # walls: normal towards the room centre
            flip = np.dot(n, centre - c) < 0
        else:
            flip = np.dot(n, c - outward_from) < 0
        polys.append((name, pts[::-1].copy() if flip else pts, mat))

    for name, (pts, mat) in _CORNELL.items():
        pts = to_blender(pts)
        if name == "light":
            n = np.cross(pts[1] - pts[0], pts[2] - pts[0])
            polys.append((name, pts if n[2] < 0 else pts[::-1].copy(), mat))
        elif name == "left wall":
            add(name, pts[[0, 1, 2]], mat)
            add(name, pts[[0, 2, 3]], mat)
        else:
            add(name, pts, mat)
    xs = [0.0, 213.0, 343.0, 556.0]
    zs = [0.0, 227.0, 332.0, 559.2]
    for i in range(3):
        for k in range(3):
            if i == 1 and k == 1:
                continue  # the light's opening
            cell = [[xs[i], 548.8, zs[k]], [xs[i + 1], 548.8, zs[k]],
                    [xs[i + 1], 548.8, zs[k + 1]], [xs[i], 548.8, zs[k + 1]]]
            add("ceiling", to_blender(cell), "white")
    for name, faces in _CORNELL_BLOCKS.items():
        block = to_blender(np.concatenate(faces))
        mid = 0.5 * (block.min(axis=0) + block.max(axis=0))
        for pts in faces:
            add(name, to_blender(pts), "white", outward_from=mid)
    return polys


def cornell_box(peak_radiance=50.0):
    """The published Cornell box (metres, +z up) as a Scene; materials white, red, green, light."""
    mats = ["white", "red", "green", "light"]
    b = _Builder()
    objs = {}
    for name, pts, mat in cornell_geometry():
        if name not in objs:
            objs[name] = b.object(name)
        b.polygon(pts, mats.index(mat), objs[name])
    rho = np.array([CORNELL_WHITE, CORNELL_RED, CORNELL_GREEN, (0.78, 0.78, 0.78)])
    le = np.zeros((4, 3))
    le[3] = cornell_light_radiance(peak_radiance)
    return b.scene(rho, le, material_names=mats)
