"""Hemicube form factors (Cohen & Greenberg 1985), vectorised over sources, polygons and pixels.

One hemicube per source node: a top face of R x R pixels and four side faces of R x R/2 pixels
around an eye at the patch centre (half-width 1, so the top face is the square [-1, 1]^2 at
distance 1 along the viewing normal). Every patch is drawn into a z-buffered item buffer (planar
convex quads whole, other patches as the triangles of ``core.patches.patch_triangles``); each
pixel credits its delta form factor to the node whose polygon is nearest along the pixel's ray:
node q when the polygon is seen from the side its patch normal points to, q + P otherwise.

This module holds the rows (what a source node or a point sees: checks, eye frames, the
per-patches cache); :mod:`core.hemicube_chunk` cuts the sources into chunks and turns each into
rows, :mod:`core.hemicube_raster` rasterises and :mod:`core.hemicube_delta` holds the pixels'
delta form factors.
"""

import weakref

import numpy as np

from .constants import tol
from .hemicube_delta import (FACE_NAMES, check_resolution, delta_form_factors,  # noqa: F401
                             flat_delta_form_factors)
from .hemicube_chunk import Geometry, Scene, rows_in_chunks
from .parallel import Deferred, submit
from .patches import patch_triangles, triangle_mask
from .sky import Sky, gathered
from .validate import check_bool, check_sources, is_int



def patch_geometry(patches):
    """Pull (centres, normals, corners) out of a Patches-like object, validated."""
    for attr in ("centres", "normals", "corners"):
        if not hasattr(patches, attr):
            raise TypeError(f"patches must be a Patches object with '{attr}'; "
                            f"got {type(patches).__name__}")
    centres = np.asarray(patches.centres, dtype=np.float64)
    normals = np.asarray(patches.normals, dtype=np.float64)
    corners = np.asarray(patches.corners, dtype=np.float64)
    if centres.ndim != 2 or centres.shape[1] != 3:
        raise ValueError(f"patches.centres must have shape (P, 3); got {centres.shape}")
    p = centres.shape[0]
    if normals.shape != (p, 3):
        raise ValueError(f"patches.normals must have shape ({p}, 3); got {normals.shape}")
    if corners.shape != (p, 4, 3):
        raise ValueError(f"patches.corners must have shape ({p}, 4, 3); got {corners.shape}")
    if p == 0:
        raise ValueError("patches must hold at least one patch; got 0")
    _check_frames(centres, normals, corners)
    return centres, normals, corners


def _check_frames(centres, normals, corners):
    """Finite geometry and unit normals (a hemicube needs a viewing direction)."""
    for name, a in (("centres", centres), ("normals", normals), ("corners", corners)):
        if not np.isfinite(a).all():
            raise ValueError(f"patches.{name} must be finite; got NaN or inf")
    length = np.linalg.norm(normals, axis=1)
    bad = np.abs(length - 1.0) > 1e-6
    if bad.any():
        i = int(np.argmax(bad))
        raise ValueError(f"patches.normals must be unit vectors; got length {length[i]:.6g} "
                         f"at patch {i}")


def make_rng(rng):
    """``rng`` as a numpy Generator (an int seeds one); TypeError for anything else."""
    if isinstance(rng, np.random.Generator):
        return rng
    if is_int(rng):
        return np.random.default_rng(int(rng))
    raise TypeError("rng must be a numpy.random.Generator (or an int seed) when rotate=True; "
                    f"got {type(rng).__name__}")


def eye_frames(centres, normals, corners, sources, n_patches, diag, angles):
    """Eyes (S, 3) and eye frames (S, 3, 3) (rows x, y, z = viewing normal) of source nodes.

    The unrotated x axis follows the patch's first edge, so a hemicube is aligned with the
    patch (and, in architectural scenes, with the walls); ``angles`` (S,) rotate it about z.
    """
    patch = sources % n_patches
    sign = np.where(sources >= n_patches, -1.0, 1.0)[:, None]
    z = normals[patch] * sign
    eyes = centres[patch] + (tol.surface_offset * diag) * z
    edge = corners[patch, 1] - corners[patch, 0]
    x = edge - np.sum(edge * z, axis=1, keepdims=True) * z
    norm = np.linalg.norm(x, axis=1)
    weak = norm <= 1e-9 * (np.linalg.norm(edge, axis=1) + 1e-300)
    if weak.any():  # degenerate first edge: fall back to the world axis least along z
        axis = np.eye(3)[np.argmin(np.abs(z[weak]), axis=1)]
        x[weak] = axis - np.sum(axis * z[weak], axis=1, keepdims=True) * z[weak]
        norm[weak] = np.linalg.norm(x[weak], axis=1)
    x /= norm[:, None]
    y = np.cross(z, x)
    if angles is not None:
        c, s = np.cos(angles)[:, None], np.sin(angles)[:, None]
        x, y = c * x + s * y, c * y - s * x
    return eyes, np.stack([x, y, z], axis=1)


def polygon_rows(polys, poly_patch, centres, normals, corners, sources, *, resolution=64,
                 rotate=False, rng=None, cull_back=False, timings=None, sky=None, sky_out=None,
                 _geometry=None):
    """Hemicube rows over explicit polygons; :func:`hemicube_rows` without a Patches object.

    Parameters
    ----------
    polys : (Q, 3, 3) or (Q, 4, 3) float
        Triangles, or planar convex quads (a triangle may repeat its last corner).
    poly_patch : (Q,) int
        Patch of each polygon, in [0, P).
    centres, normals : (P, 3) float
        Patch centres and unit normals.
    corners : (P, 4, 3) float
        Patch corners (the first edge orients an unrotated hemicube).
    sources, resolution, rotate, rng, cull_back
        As :func:`hemicube_rows`.
    timings : dict or None
        If given, CPU seconds per stage and counts (pairs, items, rows, fragments) are added.
    sky, sky_out
        As :func:`hemicube_rows`.
    _geometry : internal
        A prepared ``Geometry`` of these polygons (cached by :func:`hemicube_rows`).

    Returns
    -------
    (S, 2P) float64
    """
    resolution = check_resolution(resolution)
    centres = np.asarray(centres, dtype=np.float64)
    normals = np.asarray(normals, dtype=np.float64)
    corners = np.asarray(corners, dtype=np.float64)
    n_patches = centres.shape[0]
    if centres.shape != (n_patches, 3) or normals.shape != (n_patches, 3) \
            or corners.shape != (n_patches, 4, 3):
        raise ValueError("centres, normals, corners must have shapes (P, 3), (P, 3), (P, 4, 3); "
                         f"got {centres.shape}, {normals.shape}, {corners.shape}")
    _check_frames(centres, normals, corners)
    polys = np.asarray(polys, dtype=np.float64)
    poly_patch = np.asarray(poly_patch)
    if polys.ndim != 3 or polys.shape[1:] not in ((3, 3), (4, 3)):
        raise ValueError(f"polys must have shape (Q, 3, 3) or (Q, 4, 3); got {polys.shape}")
    if poly_patch.shape != (polys.shape[0],):
        raise ValueError(f"poly_patch must have shape ({polys.shape[0]},); "
                         f"got {poly_patch.shape}")
    if poly_patch.size and (poly_patch.min() < 0 or poly_patch.max() >= n_patches):
        raise ValueError(f"poly_patch must hold patch ids in [0, {n_patches}); "
                         f"got range [{poly_patch.min()}, {poly_patch.max()}]")
    if not np.isfinite(polys).all():
        raise ValueError("polys must be finite; got NaN or inf")
    if polys.shape[1] == 3:
        polys = polys[:, [0, 1, 2, 2]]
    src = check_sources(sources, 2 * n_patches)
    check_bool("rotate", rotate)
    check_bool("cull_back", cull_back)
    angles = None
    if rotate:
        angles = make_rng(rng).uniform(0.0, 2.0 * np.pi, size=src.size)
    sky_out = _check_sky(sky, sky_out, src.size)
    out = np.zeros((src.size, 2 * n_patches))
    if src.size == 0:
        return out
    if polys.shape[0] == 0:                 # nothing to draw: the sky fills every pixel
        if sky is not None:
            _, frames = eye_frames(centres, normals, corners, src, n_patches, 1.0, angles)
            sky_out[:] = open_sky(sky, frames, resolution)
        return out
    geometry = _geometry if _geometry is not None else Geometry(polys, poly_patch, normals)
    sc = Scene(geometry, n_patches, resolution, bool(cull_back))
    sc.sky = sky
    eyes, frames = eye_frames(centres, normals, corners, src, n_patches, sc.diag, angles)
    rows_in_chunks(sc, eyes, frames, out, timings, sky_out)
    return out


def open_sky(sky, frames, resolution):
    """(S, 3) what eyes of ``frames`` (S, 3, 3) receive from ``sky`` with nothing in view."""
    dff = flat_delta_form_factors(resolution)
    return gathered(sky, frames, np.ones((frames.shape[0], dff.size), dtype=bool), dff)


def _check_sky(sky, sky_out, n):
    """``sky_out`` checked against ``sky`` (a core.sky.Sky or None) and ``n`` eyes."""
    if sky is None:
        if sky_out is not None:
            raise ValueError("sky_out needs a sky; got sky=None")
        return None
    if not isinstance(sky, Sky):
        raise TypeError(f"sky must be a core.sky.Sky or None; got {type(sky).__name__}")
    if not (isinstance(sky_out, np.ndarray) and sky_out.shape == (n, 3)
            and sky_out.dtype == np.float64):
        got = getattr(sky_out, "shape", type(sky_out).__name__)
        raise ValueError(f"sky_out must be a float64 array of shape ({n}, 3) with a sky; "
                         f"got {got}")
    return sky_out


def draw_polygons(patches):
    """Polygons to rasterise: planar convex quads whole, every other patch as its triangles.

    A planar convex quad covers exactly the pixels of its two triangles, at half the work.

    Returns
    -------
    polys : (Q, 4, 3) float64
        A triangle repeats its last corner.
    poly_patch : (Q,) int64
    """
    corners = np.asarray(patches.corners, dtype=np.float64)
    e1, e2, e3 = (corners[:, k] - corners[:, 0] for k in (1, 2, 3))
    n = np.cross(e1, e2)
    other = corners[:, 3] - corners[:, 1]
    diagonal = np.maximum(np.linalg.norm(e2, axis=1), np.linalg.norm(other, axis=1))
    length = np.linalg.norm(n, axis=1)
    off_plane = np.abs(np.sum(e3 * n, axis=1)) / np.where(length > 0, length, 1.0)
    edges = np.roll(corners, -1, axis=1) - corners
    turns = np.einsum("qkj,qj->qk", np.cross(edges, np.roll(edges, -1, axis=1)), n)
    is_quad = ~triangle_mask(corners)
    whole = is_quad & (length > 0) & (off_plane <= tol.planar * diagonal) \
        & np.all(turns > 0, axis=1)
    rest = np.flatnonzero(~whole)
    tris, tri_local = patch_triangles(_Corners(corners[rest]))
    polys = np.concatenate([corners[whole], tris[:, [0, 1, 2, 2]]])
    poly_patch = np.concatenate([np.flatnonzero(whole), rest[tri_local]]).astype(np.int64)
    return polys, poly_patch


class _Corners:
    """The one attribute of a Patches object that ``patch_triangles`` reads."""

    def __init__(self, corners):
        self.corners = corners


def hemicube_rows(patches, sources, *, resolution=64, rotate=False, rng=None, cull_back=False,
                  sky=None, sky_out=None):
    """Form-factor rows of source nodes by the hemicube method.

    Parameters
    ----------
    patches : Patches
        From :func:`core.patches.make_patches` (uses ``centres``, ``normals``, ``corners``;
        non-planar or concave quads are drawn as :func:`core.patches.patch_triangles`).
    sources : (S,) int
        Node ids in [0, 2P): node p looks along the normal of patch p, node p + P along its
        opposite, both from the patch centre (offset by ``tol.surface_offset`` x scene diagonal
        along the viewing direction so that coplanar neighbours are not seen).
    resolution : int, optional
        R, even, 2 <= R <= 2048 (top face R x R, sides R x R/2). Error falls as 1/R^2 for
        large patches and is aliasing-dominated for small distant ones.
    rotate : bool, optional
        Rotate each hemicube about its normal by a uniform random angle drawn from ``rng``
        (one per source, in order), which turns aliasing into unbiased noise.
    rng : numpy.random.Generator or int, optional
        Required when ``rotate`` is True.
    cull_back : bool, optional
        Skip back-facing polygons entirely (only valid for closed one-sided scenes: light then
        passes through polygons seen from behind).
    sky : core.sky.Sky, optional
        A sky that varies with direction: what each source receives of it through the pixels no
        polygon covers, ``sum dF x L(pixel direction)`` (irradiance / pi), is written into
        ``sky_out`` (S, 3) float64 (required with it).
    sky_out : (S, 3) float64 ndarray, optional

    Returns
    -------
    (S, 2P) float64
        Row s: fraction of the energy leaving source s that reaches each node (front q, back
        q + P). A row sums to 1 minus the escaped fraction.

    Notes
    -----
    Cost is about linear in S x P + S x R^2 (see ``bench/bench_hemicube.py``); callers that
    poll for progress should pass batches of sources sized to take 0.1-0.2 s.
    """
    centres, normals, corners = patch_geometry(patches)
    polys, poly_patch, geometry = drawn_polygons(patches, normals)
    return polygon_rows(polys, poly_patch, centres, normals, corners, sources,
                        resolution=resolution, rotate=rotate, rng=rng, cull_back=cull_back,
                        sky=sky, sky_out=sky_out, _geometry=geometry)


def point_rows(patches, points, normals, *, resolution=64, rotate=False, rng=None, later=False,
               sky=None, sky_out=None):
    """Hemicube rows from arbitrary points: what each point sees of every node.

    The receiver is a point, so the hemicube has no proximity error here (that error comes from
    treating an area source as its centre); this is what a final gather at mesh vertices needs.

    Parameters
    ----------
    patches : core.patches.Patches
        The scene's patches (``P``); columns are nodes ``q`` (front) and ``q + P`` (back).
    points : (S, 3) float
        Eye points. Each is moved ``tol.surface_offset`` x scene diagonal along its normal, so the
        surface it lies on is not seen.
    normals : (S, 3) float
        Unit viewing normals.
    resolution, rotate, rng
        As :func:`hemicube_rows`.
    later : bool, optional
        Return a :class:`core.parallel.Deferred` of the rows: started now on the bake's worker
        processes, if it uses them, so that the caller can prepare its next call meanwhile
        (the random rotations are drawn now, so the rows do not depend on when they are asked
        for). ``sky_out`` is filled when the rows are.
    sky, sky_out
        As :func:`hemicube_rows`.

    Returns
    -------
    (S, 2P) float64
        Point-to-node form factors (differential area to node).
    """
    resolution = check_resolution(resolution)
    points = np.asarray(points, dtype=np.float64)
    normals = np.asarray(normals, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3 or normals.shape != points.shape:
        raise ValueError(f"points and normals must both have shape (S, 3); got {points.shape} "
                         f"and {normals.shape}")
    if not (np.isfinite(points).all() and np.isfinite(normals).all()):
        raise ValueError("points and normals must be finite; got NaN or inf")
    length = np.linalg.norm(normals, axis=1)
    if points.shape[0] and np.max(np.abs(length - 1.0)) > 1e-6:
        bad = int(np.argmax(np.abs(length - 1.0)))
        raise ValueError(f"normals must be unit vectors; normals[{bad}] has length {length[bad]:.6g}")
    check_bool("rotate", rotate)
    sky_out = _check_sky(sky, sky_out, points.shape[0])
    _, n_normals, _ = patch_geometry(patches)
    n_patches = n_normals.shape[0]
    out = np.zeros((points.shape[0], 2 * n_patches))
    if points.shape[0] == 0:
        return Deferred(lambda: out) if later else out
    polys, poly_patch, geometry = drawn_polygons(patches, n_normals)
    sc = Scene(geometry, n_patches, resolution, False)
    sc.sky = sky
    z = normals
    axis = np.eye(3)[np.argmin(np.abs(z), axis=1)]
    x = axis - np.sum(axis * z, axis=1, keepdims=True) * z
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    y = np.cross(z, x)
    if rotate:
        ang = make_rng(rng).uniform(0.0, 2.0 * np.pi, size=points.shape[0])
        c, s_ = np.cos(ang)[:, None], np.sin(ang)[:, None]
        x, y = c * x + s_ * y, c * y - s_ * x
    frames = np.stack([x, y, z], axis=1)
    eyes = points + (tol.surface_offset * sc.diag) * z
    if later:
        started = submit(sc, eyes, frames, out, sky_out)
        if started is not None:
            return started
        return Deferred(lambda: _filled(sc, eyes, frames, out, sky_out))
    rows_in_chunks(sc, eyes, frames, out, None, sky_out)
    return out


def _filled(sc, eyes, frames, out, sky_out):
    rows_in_chunks(sc, eyes, frames, out, None, sky_out)
    return out


def drawn_polygons(patches, normals):
    """(polys, poly_patch, Geometry) of ``patches``: its own ``drawing`` when it carries one
    (:class:`core.farfield.Drawn`), else from the cache when it holds them."""
    ready = getattr(patches, "drawing", None)
    if ready is not None:
        return ready
    cached = _CACHE.get("patches")
    if cached is not None and cached() is patches:
        return _CACHE["data"]
    polys, poly_patch = draw_polygons(patches)
    geometry = Geometry(polys, poly_patch, normals)
    try:
        ref = weakref.ref(patches, lambda _: _CACHE.clear())              # freed with them
        _CACHE.update(patches=ref, data=(polys, poly_patch, geometry))
    except TypeError:   # not weak-referenceable (a plain namespace): no caching
        _CACHE.clear()
    return polys, poly_patch, geometry


#: The polygons and geometry of the last Patches object seen (by identity, weakly held): a bake
#: asks for rows batch after batch of the same patches, and this setup (draw_polygons, distinct
#: corners, planes) costs as much as several hemicubes. Patches are immutable by contract.
_CACHE = {}
