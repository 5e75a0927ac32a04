"""The radiosity mesh handed to the writer: leaf elements of the baked faces, with their colours.

The core builds it (the adaptive hierarchy); the add-on writes it as each object's baked mesh. It
is expressed against the *scene's* faces and corners, never against Blender data: every output
corner says which scene face it lies in and carries interpolation weights over up to three of that
face's corners, so the writer can interpolate anything defined per corner or per vertex of the
user's mesh (object-space positions, every UV map) with no geometry of its own.

Sizes: V output vertices, F output faces, C output corners (Blender's loops).
"""

from dataclasses import dataclass

import numpy as np

from .errors import RadiosityError

#: Interpolation weights must sum to one within this (they are barycentric coordinates).
WEIGHT_SUM_TOL = 1e-6


@dataclass(frozen=True, eq=False)
class OutputMesh:
    """Conforming output polygons (triangles and quads) over the baked scene faces.

    Attributes
    ----------
    vertices : (V, 3) float64
        World positions (scene metres).
    corner_verts : (C,) int64
        Output vertex of every output corner.
    face_starts, face_sizes : (F,) int64
        First corner and corner count (3 or 4) of every output face.
    face_parent : (F,) int64
        Scene face each output face lies in (index into the scene's faces).
    corner_colours : (C, 3) float64
        Outgoing radiance of the front side at every output corner (Cycles' units).
    corner_sources : (C, 3) int64
        Three *scene corners* of the parent face (indices into the scene's corners); an output
        corner's position, UVs and any other per-corner value of the user's mesh is
        ``sum_k corner_weights[c, k] * value[corner_sources[c, k]]``.
    corner_weights : (C, 3) float64
        Barycentric weights over ``corner_sources``, each >= 0, summing to 1.
    corner_incident : (C, 3) float64 or None
        Light arriving at every output corner (irradiance / pi, RGB; before the surface's
        reflectance): ``core.lux.lux`` makes it lux.
    """

    vertices: np.ndarray
    corner_verts: np.ndarray
    face_starts: np.ndarray
    face_sizes: np.ndarray
    face_parent: np.ndarray
    corner_colours: np.ndarray
    corner_sources: np.ndarray
    corner_weights: np.ndarray
    corner_incident: np.ndarray = None

    def __post_init__(self):
        V = _shape("vertices", self.vertices, 2, 3)[0]
        C = _shape("corner_verts", self.corner_verts, 1)[0]
        F = _shape("face_starts", self.face_starts, 1)[0]
        _shape("face_sizes", self.face_sizes, 1, n=F)
        _shape("face_parent", self.face_parent, 1, n=F)
        _shape("corner_colours", self.corner_colours, 2, 3, n=C)
        _shape("corner_sources", self.corner_sources, 2, 3, n=C)
        _shape("corner_weights", self.corner_weights, 2, 3, n=C)
        if self.corner_incident is not None:
            _shape("corner_incident", self.corner_incident, 2, 3, n=C)
        if C and (self.corner_verts.min() < 0 or self.corner_verts.max() >= V):
            raise RadiosityError(f"OutputMesh.corner_verts must index {V} vertices")
        if F and (np.any((self.face_sizes < 3) | (self.face_sizes > 4))
                  or int(self.face_sizes.sum()) != C
                  or not np.array_equal(self.face_starts,
                                        np.cumsum(self.face_sizes) - self.face_sizes)):
            raise RadiosityError("OutputMesh faces must be triangles or quads laid out "
                                 "consecutively over the corners")
        w = self.corner_weights
        if C and (np.any(w < -WEIGHT_SUM_TOL)
                  or np.any(np.abs(w.sum(axis=1) - 1.0) > WEIGHT_SUM_TOL)):
            raise RadiosityError("OutputMesh.corner_weights must be >= 0 and sum to 1 per corner")

    def face_of_corner(self):
        """(C,) int64: output face of every output corner."""
        return np.repeat(np.arange(self.face_starts.size), self.face_sizes)

    def faces_of(self, scene_faces):
        """Output faces whose parent is one of ``scene_faces`` (bool mask over scene faces or
        an index array), in output order: ``(F_sel,) int64``."""
        scene_faces = np.asarray(scene_faces)
        if scene_faces.dtype == bool:
            return np.flatnonzero(scene_faces[self.face_parent])
        return np.flatnonzero(np.isin(self.face_parent, scene_faces))


def _shape(name, value, ndim, width=None, n=None):
    if not isinstance(value, np.ndarray) or value.ndim != ndim \
            or (width is not None and value.shape[1] != width) \
            or (n is not None and value.shape[0] != n):
        want = {1: "(N,)", 2: f"(N, {width})"}[ndim]
        got = value.shape if isinstance(value, np.ndarray) else type(value).__name__
        raise RadiosityError(f"OutputMesh.{name} must be an array of shape {want}"
                             + (f" with N = {n}" if n is not None else "") + f"; got {got}")
    return value.shape
