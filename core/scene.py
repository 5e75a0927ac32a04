"""A scene as arrays: polygons in Blender's layout, materials, emission.

The layout is Blender's own: a flat corner -> vertex array (``corner_verts``, Blender's loops) and,
per face, its first corner (``face_starts``, ``loop_start``) and its corner count (``face_sizes``,
``loop_total``). So the add-on hands over ``foreach_get`` buffers without reshaping, and every error
can name the object and the face at fault.
"""

from dataclasses import dataclass

import numpy as np

from .constants import MAX_REFLECTANCE_EXCLUSIVE, tol
from .errors import SceneError
from .geometry import ragged
from .light_list import Lights, make_lights
from .sky import Sky


@dataclass(frozen=True, eq=False)
class Scene:
    """Validated scene arrays (read-only) and per-face geometry derived from them.

    Attributes
    ----------
    vertices : (V, 3) float64
    corner_verts : (C,) int64
        Vertex of every corner (Blender loop).
    face_starts, face_sizes : (F,) int64
        First corner and corner count of every face.
    face_materials : (F,) int64
        Index into ``reflectance`` / ``emission``.
    reflectance : (M, 3) float64
        Diffuse albedo per material, in [0, 1).
    emission : (M, 3) float64
        Emitted radiance per material (Blender: strength x colour), >= 0.
    face_objects : (F,) int64
        Index into ``object_names``.
    object_names, material_names : tuple of str
    face_normals : (F, 3) float64
        Unit Newell normals (zero for dropped faces).
    face_areas : (F,) float64
    face_valid : (F,) bool
        False for faces dropped as degenerate (zero area, or fewer than 3 distinct positions).
    back_reflectance, back_emission : (M, 3) float64 or None
        The back side's material (see docs/design.md, "Two sides"); None: the same as the front,
        which is Cycles' behaviour for surfaces and mesh lights. An area light is one-sided: its
        back is black (reflectance 0, emission 0).
    face_duplicate_of : (F,) int64 or None
        Set by :func:`core.duplicates.merge_duplicates`: the kept face each coincident duplicate
        (marked invalid) stands for, -1 for other faces. None: not checked.
    lights : core.light_list.Lights or None
        Point, spot and sun lights (:func:`core.light_list.make_lights`); None: none.
    world : (3,) float64, core.sky.Sky or None
        Radiance of a uniform world (Blender's world colour x strength) seen in every direction
        no surface covers, or a sky whose radiance varies with direction (:mod:`core.sky`, lit
        through the hemicube's empty pixels); None: black.
    """

    vertices: np.ndarray
    corner_verts: np.ndarray
    face_starts: np.ndarray
    face_sizes: np.ndarray
    face_materials: np.ndarray
    reflectance: np.ndarray
    emission: np.ndarray
    face_objects: np.ndarray
    object_names: tuple
    material_names: tuple
    face_normals: np.ndarray
    face_areas: np.ndarray
    face_valid: np.ndarray
    back_reflectance: np.ndarray = None
    back_emission: np.ndarray = None
    face_duplicate_of: np.ndarray = None
    lights: Lights = None
    world: np.ndarray = None

    def back_materials(self):
        """(reflectance, emission) of the back sides, (M, 3) each."""
        rho = self.reflectance if self.back_reflectance is None else self.back_reflectance
        le = self.emission if self.back_emission is None else self.back_emission
        return rho, le

    def emissive_materials(self):
        """(M,) bool: the materials that emit from their front or their back."""
        front = np.asarray(self.emission, dtype=np.float64)
        back = np.asarray(self.back_materials()[1], dtype=np.float64)
        return np.any(front > 0, axis=1) | np.any(back > 0, axis=1)

    @property
    def n_faces(self):
        return int(self.face_starts.shape[0])

    @property
    def n_corners(self):
        return int(self.corner_verts.shape[0])

    @property
    def faces_dropped(self):
        """Number of faces dropped as degenerate."""
        dropped = ~np.asarray(self.face_valid)
        if self.face_duplicate_of is not None:
            dropped &= np.asarray(self.face_duplicate_of) < 0
        return int(np.count_nonzero(dropped))

    def face_corner_indices(self):
        """Corner indices of every face, flattened in face order, and the face of each.

        Returns
        -------
        corners : (sum(face_sizes),) int64
        faces : (sum(face_sizes),) int64
        """
        return _face_corner_indices(self.face_starts, self.face_sizes)

    def face_label(self, face):
        """'face 3 of object "Wall"': names a face the way the user sees it."""
        return _face_label(face, self.face_objects, self.object_names)

    def bounding_diagonal(self):
        """Length of the diagonal of the bounding box of the used vertices (m)."""
        used = self.vertices[np.unique(self.corner_verts)]
        return float(np.linalg.norm(used.max(axis=0) - used.min(axis=0)))


def _face_corner_indices(face_starts, face_sizes):
    faces, local, _ = ragged(face_sizes)
    return np.repeat(face_starts, face_sizes) + local, faces


def _face_label(face, face_objects, object_names):
    face = int(face)
    obj = int(face_objects[face])
    local = int(np.count_nonzero(face_objects[:face] == obj))
    name = object_names[obj] if obj < len(object_names) else f"#{obj}"
    return f'face {local} of object "{name}"'


def _as_array(name, value, dtype, ndim, width=None):
    try:
        arr = np.array(value, dtype=dtype, copy=True)
    except (TypeError, ValueError) as exc:
        raise SceneError(f"{name} must be convertible to a {np.dtype(dtype).name} array: {exc}") from None
    if arr.ndim != ndim or (width is not None and arr.shape[-1] != width):
        want = "(n, %d)" % width if width is not None else "(n,)"
        raise SceneError(f"{name} must have shape {want}; got {arr.shape}")
    arr.setflags(write=False)
    return arr


def _as_index_array(name, value):
    arr = np.asarray(value)
    if arr.ndim != 1:
        raise SceneError(f"{name} must have shape (n,); got {arr.shape}")
    if arr.size and not np.issubdtype(arr.dtype, np.integer):
        if not np.all(np.isfinite(arr)) or np.any(arr != np.round(arr)):
            bad = int(np.flatnonzero(~np.isfinite(arr) | (arr != np.round(arr)))[0])
            raise SceneError(f"{name} must hold integers; got {arr[bad].item()!r} at index {bad}")
    return _as_array(name, arr, np.int64, 1)


def _first_bad_row(mask):
    return int(np.flatnonzero(mask)[0])


def make_scene(vertices, corner_verts, face_starts, face_sizes, face_materials, reflectance,
               emission, *, face_objects=None, object_names=None, material_names=None,
               back_reflectance=None, back_emission=None, lights=None, world=None):
    """Validate scene arrays and derive per-face normals and areas.

    Parameters
    ----------
    vertices : (V, 3) float
    corner_verts : (C,) int
        Vertex index of every corner.
    face_starts : (F,) int
        First corner of every face; corners of face f are ``face_starts[f] : face_starts[f] + face_sizes[f]``.
    face_sizes : (F,) int
        Corner count of every face, >= 3.
    face_materials : (F,) int
        Material index of every face.
    reflectance : (M, 3) float
        RGB diffuse reflectance per material, each in [0, 1).
    emission : (M, 3) float
        RGB emitted radiance per material, >= 0 (Blender: emission strength x colour).
    face_objects : (F,) int, optional
        Object index of every face (default: one object), used to name faces in messages.
    object_names, material_names : sequence of str, optional
    back_reflectance, back_emission : (M, 3) float, optional
        Material of the back sides (default: the same as the front). Same rules as the front.
    lights : core.light_list.Lights or sequence of dict, optional
        Point, spot and sun lights (dicts go through :func:`core.light_list.make_lights`).
    world : (3,) float or core.sky.Sky, optional
        Radiance of a uniform world, RGB, >= 0 (Blender: world colour x strength), or a sky
        that varies with direction (e.g. :class:`core.sky.CIEOvercast`).

    Returns
    -------
    Scene

    Raises
    ------
    SceneError
        Naming the argument and the offending index: wrong shapes, NaN/inf, indices out of range,
        reflectance outside [0, 1), negative emission, an empty scene, or no emitter and no
        light.
    """
    vertices = _as_array("vertices", vertices, np.float64, 2, 3)
    corner_verts = _as_index_array("corner_verts", corner_verts)
    face_starts = _as_index_array("face_starts", face_starts)
    face_sizes = _as_index_array("face_sizes", face_sizes)
    face_materials = _as_index_array("face_materials", face_materials)
    reflectance = _as_array("reflectance", reflectance, np.float64, 2, 3)
    emission = _as_array("emission", emission, np.float64, 2, 3)
    if back_reflectance is not None:
        back_reflectance = _as_array("back_reflectance", back_reflectance, np.float64, 2, 3)
    if back_emission is not None:
        back_emission = _as_array("back_emission", back_emission, np.float64, 2, 3)

    n_faces = face_starts.shape[0]
    if n_faces == 0 or vertices.shape[0] == 0:
        raise SceneError(f"the scene is empty: got {vertices.shape[0]} vertices and {n_faces} faces")
    for name, arr in (("face_sizes", face_sizes), ("face_materials", face_materials)):
        if arr.shape[0] != n_faces:
            raise SceneError(f"{name} must have one entry per face ({n_faces}); got {arr.shape[0]}")
    if face_objects is None:
        face_objects = np.zeros(n_faces, dtype=np.int64)
    face_objects = _as_index_array("face_objects", face_objects)
    if face_objects.shape[0] != n_faces:
        raise SceneError(f"face_objects must have one entry per face ({n_faces}); got {face_objects.shape[0]}")
    n_objects = int(face_objects.max()) + 1 if n_faces else 0
    object_names = tuple(str(n) for n in (object_names if object_names is not None
                                          else [f"object {i}" for i in range(n_objects)]))
    if np.any(face_objects < 0) or np.any(face_objects >= len(object_names)):
        bad = _first_bad_row((face_objects < 0) | (face_objects >= len(object_names)))
        raise SceneError(f"face_objects[{bad}] = {face_objects[bad]} is out of range for "
                         f"{len(object_names)} object names")
    n_materials = reflectance.shape[0]
    material_names = tuple(str(n) for n in (material_names if material_names is not None
                                            else [f"material {i}" for i in range(n_materials)]))

    def label(f):
        return _face_label(f, face_objects, object_names)

    bad = ~np.isfinite(vertices).all(axis=1)
    if bad.any():
        v = _first_bad_row(bad)
        raise SceneError(f"vertices contain NaN or inf: vertex {v} is {vertices[v].tolist()}")
    if emission.shape[0] != n_materials:
        raise SceneError(f"emission must have one row per material ({n_materials}); got {emission.shape[0]}")
    if n_materials == 0:
        raise SceneError("reflectance must have at least one material row; got 0")
    def mname(m):
        return material_names[m] if m < len(material_names) else m

    materials = [("reflectance", reflectance), ("emission", emission),
                 ("back_reflectance", back_reflectance), ("back_emission", back_emission)]
    for name, arr in materials[2:]:
        if arr is not None and arr.shape[0] != n_materials:
            raise SceneError(f"{name} must have one row per material ({n_materials}); "
                             f"got {arr.shape[0]}")
    for name, arr in materials:
        if arr is None:
            continue
        bad = ~np.isfinite(arr).all(axis=1)
        if bad.any():
            m = _first_bad_row(bad)
            raise SceneError(f"{name} contains NaN or inf: material {m} ({mname(m)}) is "
                             f"{arr[m].tolist()}")
        if "reflectance" in name:
            bad = ((arr < 0) | (arr >= MAX_REFLECTANCE_EXCLUSIVE)).any(axis=1)
            if bad.any():
                m = _first_bad_row(bad)
                raise SceneError(f"{name} must lie in [0, 1) (1 or more makes the solve singular "
                                 f"or divergent): material {m} ({mname(m)}) has {arr[m].tolist()}")
        else:
            bad = (arr < 0).any(axis=1)
            if bad.any():
                m = _first_bad_row(bad)
                raise SceneError(f"{name} must be >= 0: material {m} ({mname(m)}) has "
                                 f"{arr[m].tolist()}")

    n_corners = corner_verts.shape[0]
    bad = (corner_verts < 0) | (corner_verts >= vertices.shape[0])
    if bad.any():
        c = _first_bad_row(bad)
        raise SceneError(f"corner_verts[{c}] = {corner_verts[c]} is out of range for "
                         f"{vertices.shape[0]} vertices")
    bad = face_sizes < 3
    if bad.any():
        f = _first_bad_row(bad)
        raise SceneError(f"face_sizes must be >= 3: {label(f)} (face index {f}) has {face_sizes[f]} corners")
    bad = (face_starts < 0) | (face_starts + face_sizes > n_corners)
    if bad.any():
        f = _first_bad_row(bad)
        raise SceneError(f"face_starts[{f}] = {face_starts[f]} with {face_sizes[f]} corners runs past "
                         f"the {n_corners} corners ({label(f)})")
    bad = (face_materials < 0) | (face_materials >= n_materials)
    if bad.any():
        f = _first_bad_row(bad)
        raise SceneError(f"face_materials[{f}] = {face_materials[f]} is out of range for "
                         f"{n_materials} materials ({label(f)})")

    normals, areas = _newell(vertices, corner_verts, face_starts, face_sizes)
    valid = areas > tol.face_area
    normals = np.where(valid[:, None], normals / np.where(valid, areas, 1.0)[:, None], 0.0)
    areas = np.where(valid, areas, 0.0)

    emitting_materials = (emission > 0).any(axis=1)
    if back_emission is not None:
        emitting_materials |= (back_emission > 0).any(axis=1)
    if lights is not None and not isinstance(lights, Lights):
        lights = make_lights(lights)
    if lights is not None and len(lights) == 0:
        lights = None
    if world is not None and not isinstance(world, Sky):
        world = np.array(world, dtype=np.float64).reshape(-1)
        if world.shape != (3,) or not np.all(np.isfinite(world)) or np.any(world < 0):
            raise SceneError(f"world must be 3 finite radiances >= 0 (RGB); got {world.tolist()}")
        world.setflags(write=False)
        if not np.any(world > 0):
            world = None
    has_light = (lights is not None and lights.shines) or world is not None
    if not (emitting_materials[face_materials] & valid).any() and not has_light:
        raise SceneError("the scene has no emitter: no valid face uses a material with emission > 0 "
                         "(add an emissive material, a light or a world colour)")

    for arr in (normals, areas, valid):
        arr.setflags(write=False)
    return Scene(vertices, corner_verts, face_starts, face_sizes, face_materials, reflectance,
                 emission, face_objects, object_names, material_names, normals, areas, valid,
                 back_reflectance, back_emission, lights=lights, world=world)


def _newell(vertices, corner_verts, face_starts, face_sizes):
    """Unnormalised Newell normal (length = polygon area) and area of every face."""
    corners, faces = _face_corner_indices(face_starts, face_sizes)
    first = np.cumsum(face_sizes) - face_sizes
    pos = vertices[corner_verts[corners]]
    # Centre each face first: cross products of far-from-origin coordinates lose digits.
    centroid = np.add.reduceat(pos, first, axis=0) / face_sizes[:, None]
    pos = pos - centroid[faces]
    local = np.arange(corners.shape[0]) - np.repeat(first, face_sizes)
    nxt = np.repeat(first, face_sizes) + (local + 1) % np.repeat(face_sizes, face_sizes)
    cross = np.cross(pos, pos[nxt])
    n = 0.5 * np.add.reduceat(cross, first, axis=0)
    return n, np.linalg.norm(n, axis=1)


def scene_from_polygons(vertices, polygons, face_materials, reflectance, emission, **kwargs):
    """Build a Scene from a list of polygons (each a sequence of vertex indices).

    Parameters
    ----------
    vertices : (V, 3) float
    polygons : sequence of sequences of int
        Vertex indices of each face, counter-clockwise seen from the side its normal points to.
    face_materials, reflectance, emission, **kwargs
        As :func:`make_scene`.
    """
    polygons = [list(p) for p in polygons]
    sizes = np.array([len(p) for p in polygons], dtype=np.int64)
    starts = np.cumsum(sizes) - sizes
    corner_verts = np.array([v for p in polygons for v in p], dtype=np.int64)
    return make_scene(vertices, corner_verts, starts, sizes, face_materials, reflectance, emission,
                      **kwargs)
