"""Calculation surfaces: meshes that measure illuminance (lux) and take no part in the light.

An object marked **Calculation Surface** (``Object.radiosity_calc_surface``) is left out of the
scene the bake solves, so it neither blocks nor reflects. After the solve the core gathers the
light at its points (:mod:`core.lux`): on EN 12464-1's grid over it (cell centres, the cell size
from the surface's governing side), for Emin, Eavg, Emax and U0 = Emin / Eavg; and at each of
its own vertices, written to its mesh as the POINT attribute ``Radiosity Lux`` (removed by Clear
Bake). The front side measures: the side the face normals point to (a work plane faces up).
"""

from dataclasses import dataclass, field

import numpy as np

from ..core import lux as corelux
from ..core.errors import BakeCancelled
from ..core.geometry import ragged

#: Object property that marks a calculation surface.
PROP = "radiosity_calc_surface"


@dataclass
class CalcSurface:
    """One calculation surface: what :func:`read_surface` read, and what :func:`measure` found.

    Attributes
    ----------
    object_name : str
    polygons : list of (k, 3) float64
        Its evaluated faces, world metres.
    vertex_points, vertex_normals : (V, 3) float64
        The original mesh's vertices (world metres) and unit normals (area-weighted over their
        faces); the attribute goes on those.
    grid, grid_normals : (S, 3) float64; weights : (S,) float64
        The EN 12464-1 grid (after :func:`measure`).
    grid_lux, vertex_lux : float64 arrays
        Illuminance (lx) at the grid points and the vertices.
    summary : dict
        ``core.lux.summary`` of the grid, plus ``object`` and ``cell_area`` (m²); with a sky
        (``sky='cie_overcast'``) also the daylight factors ``DFmin``, ``DFavg``, ``DFmax`` (%).
    outdoor : float or None
        The sky's outdoor horizontal illuminance (lx) the daylight factors divide by.
    """

    object_name: str
    polygons: list
    vertex_points: np.ndarray
    vertex_normals: np.ndarray
    grid: np.ndarray = None
    grid_normals: np.ndarray = None
    weights: np.ndarray = None
    grid_lux: np.ndarray = None
    vertex_lux: np.ndarray = None
    summary: dict = field(default_factory=dict)
    outdoor: float = None


def is_calc_surface(obj):
    """True if the (original) object is marked as a calculation surface."""
    return bool(getattr(obj.original, PROP, False))


def read_surface(obj, matrix, layout):
    """A :class:`CalcSurface` from an object's evaluated mesh ``layout`` (``read_mesh_layout``)
    and its original mesh's vertices, both under ``matrix`` (object to world metres)."""
    from .extract import read_mesh_layout, transform

    v, cv, fs, fz, _ = layout
    world = transform(v, matrix)
    polygons = [world[cv[s:s + k]] for s, k in zip(fs, fz)]
    if np.linalg.det(matrix[:3, :3]) < 0:                 # mirrored: keep the front side
        polygons = [p[::-1] for p in polygons]
    ov, ocv, ofs, ofz, _ = read_mesh_layout(obj.original.data)
    opoints = transform(ov, matrix)
    owner, local, _ = ragged(ofz)                          # Newell vector of every face
    nxt = ofs[owner] + (local + 1) % ofz[owner]
    ring = opoints[ocv] - opoints[ocv[ofs]][owner]
    area_vec = np.zeros((ofs.size, 3))
    np.add.at(area_vec, owner, 0.5 * np.cross(ring, ring[nxt]))
    normals = np.zeros_like(opoints)
    np.add.at(normals, ocv, area_vec[owner])
    if np.linalg.det(matrix[:3, :3]) < 0:
        normals = -normals
    length = np.linalg.norm(normals, axis=1)
    lone = length == 0                                   # loose vertices measure facing up
    normals[lone] = (0.0, 0.0, 1.0)
    normals[~lone] /= length[~lone, None]
    return CalcSurface(obj.original.name, polygons, opoints, normals)


def measure(result, surfaces, cancel=None):
    """Gather every surface's grid and vertices after the bake (fills them in place)."""
    outdoor = result.report.get("sky", {}).get("outdoor_lux")
    for surf in surfaces:
        if cancel is not None and cancel():
            raise BakeCancelled("cancelled while measuring calculation surfaces")
        fill(surf, incident(result, surf), outdoor)


def incident(result, surf):
    """(S, 3) light arriving (irradiance / pi) at the surface's grid points, then vertices."""
    pts, nrm, _ = corelux.calculation_grid(surf.polygons)
    return corelux.incident_at(result, np.concatenate([pts, surf.vertex_points]),
                               np.concatenate([nrm, surf.vertex_normals]))


def fill(surf, arriving, outdoor):
    """Set the surface's grid, lux and summary from :func:`incident`'s (S, 3) (linear in the
    light: the relight's light groups mix it)."""
    pts, nrm, w = corelux.calculation_grid(surf.polygons)
    both = corelux.lux(arriving)
    surf.grid, surf.grid_normals, surf.weights = pts, nrm, w
    surf.grid_lux, surf.vertex_lux = both[:pts.shape[0]], both[pts.shape[0]:]
    surf.outdoor = outdoor
    surf.summary = dict(object=surf.object_name, cell_area=float(w[0]),
                        **corelux.summary(surf.grid_lux, w, outdoor=outdoor))


def write(objects, surfaces):
    """The vertex illuminance of every measured surface, as its mesh's ``Radiosity Lux`` (and,
    under a sky, ``Radiosity Daylight Factor``)."""
    from .write import write_lux

    for surf in surfaces:
        mesh = objects[surf.object_name].data
        write_lux(mesh, surf.vertex_lux, "POINT", outdoor=surf.outdoor)
        mesh.update()


def rows(surfaces):
    """Every grid point as a CSV row: object, x, y, z (m), lux."""
    out = [("object", "x", "y", "z", "lux")]
    for surf in surfaces:
        out += [(surf.object_name, *map(float, p), float(e))
                for p, e in zip(surf.grid, surf.grid_lux)]
    return out
