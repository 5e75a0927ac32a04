"""Illuminance in lux, as lighting designers read it: at any point after a bake, on the
calculation grids of EN 12464-1, and summed up as Emin, Eavg, Emax and U0 = Emin / Eavg.

Convention. The bake's light is in Blender's radiometric units: a sun of strength 1 gives an
irradiance of 1 W/m² on a surface facing it. A point's illuminance is ``E = pi x incident``, the
incident radiance (irradiance / pi) that the final gather holds before the surface's reflectance is
applied, so it does not depend on the surface's colour; the RGB irradiance becomes lux through its
luminance (Rec. 709 weights, Blender's scene-linear space) times Blender's 683 lm/W, the luminous
efficacy Blender and Cycles use between their watts and lumens. A white (1, 1, 1) irradiance of
1 W/m² is 683 lx.

A *calculation surface* is a mesh that measures light and takes no part in it: it neither blocks
nor reflects (the add-on leaves it out of the scene). Its points are gathered after the solve
exactly as the output mesh's vertices are: a hemicube at the point over the solved patches (or the
receiver elements), plus the lights' direct light, the exact emitters' and the world's share
(:meth:`core.lights.DirectLight.extra`).
"""

import math

import numpy as np

from .geometry import newell_normals_areas, triangulate_polygon
from .hemicube import point_rows
from .refine import LUMINANCE

#: Lumens per (radiometric, Blender) watt.
LUMENS_PER_WATT = 683.0

#: EN 12464-1's largest grid cell (m).
MAX_SPACING = 10.0

#: Faces whose unit normals differ by less than this (and planes by less than COPLANAR x the
#: surface's size) form one plane and get one grid.
COPLANAR = 1e-4

#: Gather points per hemicube batch.
BATCH = 64


def lux(incident):
    """(n,) illuminance in lux of (n, 3) incident radiance (irradiance / pi, RGB)."""
    return LUMENS_PER_WATT * np.pi * (np.asarray(incident, dtype=np.float64) @ LUMINANCE)


def grid_spacing(d):
    """EN 12464-1's largest cell size (m) for a calculation area whose governing side is ``d`` m:
    ``p = 0.2 x 5^log10(d)``, at most :data:`MAX_SPACING` (1 m for 10 m, 0.2 m for 1 m)."""
    if not d > 0:
        raise ValueError(f"the calculation area's side must be > 0 m; got {d!r}")
    return min(0.2 * 5.0 ** math.log10(d), MAX_SPACING)


def _cells(width, height, spacing):
    """Cell counts (nu, nv) of a ``width`` x ``height`` rectangle: the governing side ``d`` is the
    longer one if the sides' ratio is below 2, else the shorter (EN 12464-1); ``p`` from it (or
    ``spacing``), and each side gets the next whole number of cells above side / p."""
    long, short = max(width, height), min(width, height)
    d = long if long < 2.0 * short else short
    p = spacing if spacing is not None else grid_spacing(d)
    return (max(1, math.ceil(width / p - 1e-9)), max(1, math.ceil(height / p - 1e-9)))


def calculation_grid(polygons, spacing=None):
    """Grid points of a calculation surface: cell centres, as EN 12464-1 places them.

    A planar surface (every face in one plane, the usual work plane) gets one grid over its
    extent, aligned with its largest face's longest edge; the cells whose centres fall inside a
    face are kept. A surface that is not planar gets a grid per face (each aligned with that
    face's longest edge).

    Parameters
    ----------
    polygons : sequence of (k, 3) float
        The faces (world metres), counter-clockwise about their front normal.
    spacing : float, optional
        Cell size (m); default EN 12464-1's rule (:func:`grid_spacing`).

    Returns
    -------
    points, normals : (S, 3) float64
    weights : (S,) float64
        Each point's cell area (m²).
    """
    polys = [np.asarray(p, dtype=np.float64) for p in polygons]
    if not polys:
        raise ValueError("a calculation surface needs at least one face")
    if spacing is not None and not spacing > 0:
        raise ValueError(f"spacing must be > 0 m; got {spacing!r}")
    for p in polys:
        if p.ndim != 2 or p.shape[0] < 3 or p.shape[1] != 3 or not np.isfinite(p).all():
            raise ValueError(f"a face must be (k >= 3, 3) finite corners; got {p.shape}")
    K = max(p.shape[0] for p in polys)
    padded = np.stack([np.concatenate([p, np.repeat(p[-1:], K - p.shape[0], axis=0)])
                       for p in polys])
    normals, areas = newell_normals_areas(padded, np.array([p.shape[0] for p in polys]))
    keep = areas > 0
    polys = [p for p, k in zip(polys, keep) if k]
    normals, areas = normals[keep], areas[keep]
    if not polys:
        raise ValueError("a calculation surface's faces all have zero area")
    size = math.sqrt(float(areas.sum()))
    offsets = np.array([n @ p[0] for n, p in zip(normals, polys)])
    planar = (np.abs(normals - normals[0]).max() < COPLANAR
              and np.ptp(offsets) < COPLANAR * size)
    groups = [np.arange(len(polys))] if planar else [np.array([i]) for i in range(len(polys))]
    out = [_grid([polys[i] for i in g], normals[g[0]], spacing) for g in groups]
    return tuple(np.concatenate([o[k] for o in out]) for k in range(3))


def _grid(polys, normal, spacing):
    big = polys[int(np.argmax([np.linalg.norm(np.cross(p - p[0], np.roll(p, -1, 0) - p[0]))
                               for p in polys]))]
    edges = np.roll(big, -1, axis=0) - big
    u = edges[int(np.argmax(np.linalg.norm(edges, axis=1)))]
    u = u - (u @ normal) * normal
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)
    origin = big[0]
    flat = [np.stack([(p - origin) @ u, (p - origin) @ v], axis=1) for p in polys]
    both = np.concatenate(flat)
    lo, hi = both.min(axis=0), both.max(axis=0)
    w, h = hi - lo
    nu, nv = _cells(w, h, spacing)
    cu, cv = (np.arange(nu) + 0.5) * (w / nu) + lo[0], (np.arange(nv) + 0.5) * (h / nv) + lo[1]
    xy = np.stack(np.meshgrid(cu, cv, indexing="ij"), axis=-1).reshape(-1, 2)
    inside = np.zeros(xy.shape[0], dtype=bool)
    scale = max(w, h)
    for p2, p3 in zip(flat, polys):
        for tri in triangulate_polygon(p3, normal):
            inside |= _in_triangle(xy, p2[tri], 1e-9 * scale)
    xy = xy[inside]
    points = origin + xy[:, :1] * u + xy[:, 1:] * v
    return (points, np.repeat(normal[None, :], xy.shape[0], axis=0),
            np.full(xy.shape[0], (w / nu) * (h / nv)))


def _in_triangle(xy, tri, eps):
    """(n,) bool: 2-D points inside (or on) the counter-clockwise triangle ``tri`` (3, 2)."""
    a, b, c = tri

    def side(s, t):
        return (t[0] - s[0]) * (xy[:, 1] - s[1]) - (t[1] - s[1]) * (xy[:, 0] - s[0])

    return (side(a, b) >= -eps) & (side(b, c) >= -eps) & (side(c, a) >= -eps)


def summary(E, weights=None, outdoor=None):
    """EN 12464-1's figures of a set of illuminances (lx): ``points``, ``Emin``, ``Eavg`` (the
    ``weights``-weighted mean, cell areas), ``Emax``, ``U0`` = Emin / Eavg (0 in the dark).
    With ``outdoor`` (lx, the unobstructed horizontal illuminance of the sky): the daylight
    factors ``DFmin``, ``DFavg``, ``DFmax`` (%, :func:`daylight_factor`)."""
    E = np.asarray(E, dtype=np.float64).reshape(-1)
    if E.size == 0:
        raise ValueError("no illuminance values to sum up")
    w = np.ones_like(E) if weights is None else np.asarray(weights, dtype=np.float64)
    avg = float((E * w).sum() / w.sum())
    out = dict(points=int(E.size), Emin=float(E.min()), Eavg=avg, Emax=float(E.max()),
               U0=float(E.min() / avg) if avg > 0 else 0.0)
    if outdoor is not None:
        for name in ("min", "avg", "max"):
            out["DF" + name] = float(daylight_factor(out["E" + name], outdoor))
    return out


def daylight_factor(E, outdoor):
    """Daylight factor (%) of illuminances ``E`` (lx) under a sky giving ``outdoor`` lx on an
    unobstructed horizontal plane: ``100 E / outdoor``."""
    if not (np.isfinite(outdoor) and outdoor > 0):
        raise ValueError(f"outdoor must be a finite illuminance > 0 (lx); got {outdoor!r}")
    return 100.0 * np.asarray(E, dtype=np.float64) / float(outdoor)


def incident_at(result, points, normals):
    """(S, 3) incident radiance (irradiance / pi) at arbitrary points after a bake.

    The points take no part in the bake (they neither block nor reflect). Each is gathered as an
    output vertex is: a hemicube at the point, lifted off its own plane by the scene's surface
    offset, over what the bake's own gathers drew (the solved patches, or their receiver
    elements), plus the direct light of the lights, the exact emitters and the world.

    Parameters
    ----------
    result : core.BakeResult
    points, normals : (S, 3) float
        World metres; unit normals of the side that measures.
    """
    state = getattr(result, "_state", None)
    if state is None or getattr(state, "solved", None) is None:
        raise TypeError("result must be a BakeResult from core.bake() or core.relight()")
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    normals = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    if normals.shape != points.shape:
        raise ValueError(f"points and normals must match; got {points.shape} and {normals.shape}")
    length = np.linalg.norm(normals, axis=1)
    if np.any(~np.isfinite(length)) or np.any(length == 0):
        raise ValueError("normals must be finite and non-zero")
    normals = normals / length[:, None]
    scene, settings, gather = state.scene, state.settings, state.gather
    L = state.solved
    drawn = state.patches
    elements = getattr(gather, "elements", None)
    if elements is not None:
        L = elements.node_radiance(scene, L)
        drawn = elements.patches
    seen = getattr(gather, "seen", None)
    if seen is not None:                    # the mesh output's gathers drew the lit subset
        drawn, L = seen, seen.radiance(L)
    rng = np.random.default_rng([settings.seed, 6])
    out = np.zeros((points.shape[0], 3))
    covered = np.zeros(points.shape[0])
    sky = None if state.direct is None else state.direct.sky
    light = None if sky is None else np.zeros((points.shape[0], 3))
    if drawn.areas.size:
        for s in range(0, points.shape[0], BATCH):
            rows = point_rows(drawn, points[s:s + BATCH], normals[s:s + BATCH],
                              resolution=settings.resolution, rotate=settings.rotate_hemicube,
                              rng=rng, sky=sky,
                              sky_out=None if sky is None else light[s:s + BATCH])
            out[s:s + BATCH] = rows @ L
            covered[s:s + BATCH] = rows.sum(axis=1)
    if state.direct is not None:
        out += state.direct.extra(points, normals, covered, sky=light)
    return out


def illuminance_at(result, points, normals):
    """(S,) illuminance (lx) at arbitrary points after a bake (:func:`incident_at`)."""
    return lux(incident_at(result, points, normals))
