"""Carry per-corner values from one polygon mesh onto points of another (NumPy only).

Two jobs of the add-on's writer need the same geometry:

* "Existing Vertices" output: every corner of the user's (original) mesh takes the baked value of
  the evaluated surface where that corner lies (modifiers may have changed the topology):
  :func:`project_corners` finds, for each corner, an evaluated triangle and barycentric weights.
* Mesh output: every corner of the output mesh is a weighted sum of scene corners
  (``core.outmesh.OutputMesh``); :func:`interpolate` evaluates positions, UVs and colours there.

Both answers have the same form, ``(sources (N, 3) int64, weights (N, 3) float64)``, so one
:func:`interpolate` applies them to any per-corner array.

Sizes: V vertices, C corners, F faces of a mesh; N query points.
"""

import numpy as np

from .geometry import newell_normals_areas, ragged
from .raycast import build_bvh, closest_hit

#: Sample points sit this fraction of the way from a corner's vertex to its face's centroid, so the
#: sample falls inside that face (not on an edge shared with a creased neighbour) while staying at
#: the vertex for all practical purposes.
CORNER_INSET = 1e-3

#: Where the evaluated surface has shrunk away from a corner (Catmull-Clark rounds a cube's corners
#: off), the sample moves this far towards the face's centroid and tries again: the nearest part of
#: the same face that survived the modifier.
RETRY_INSETS = (0.25, 0.5)

#: An evaluated triangle may stand for an original face only if their normals are within ~75
#: degrees (cosine above this): subdivision tilts faces near corners, but never flips them.
NORMAL_AGREEMENT = 0.25

#: Query points per chunk of the nearest-corner fallback (bounds memory at ~8 MB per 1000 corners).
NEAREST_CHUNK = 256


def _layout(points, corner_verts, face_starts, face_sizes):
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"points must have shape (V, 3); got {points.shape}")
    cv = np.asarray(corner_verts, dtype=np.int64)
    fs = np.asarray(face_starts, dtype=np.int64)
    fz = np.asarray(face_sizes, dtype=np.int64)
    if fs.shape != fz.shape or fs.ndim != 1:
        raise ValueError(f"face_starts and face_sizes must be (F,) arrays of one length; got "
                         f"{fs.shape} and {fz.shape}")
    if fz.size and (fz.min() < 3 or int(fz.sum()) != cv.size):
        raise ValueError(f"face_sizes must be >= 3 and sum to the {cv.size} corners")
    if cv.size and (cv.min() < 0 or cv.max() >= points.shape[0]):
        raise ValueError(f"corner_verts must index the {points.shape[0]} points")
    return points, cv, fs, fz


def padded_polygons(points, corner_verts, face_starts, face_sizes):
    """(F, K, 3) polygons, K the largest face, short faces padded with their last corner."""
    points, cv, fs, fz = _layout(points, corner_verts, face_starts, face_sizes)
    k = int(fz.max()) if fz.size else 3
    local = np.minimum(np.arange(k)[None, :], fz[:, None] - 1)
    return points[cv[fs[:, None] + local]]


def face_frames(points, corner_verts, face_starts, face_sizes):
    """Unit Newell normals (F, 3) and vertex centroids (F, 3) of ragged polygons."""
    points, cv, fs, fz = _layout(points, corner_verts, face_starts, face_sizes)
    normals, _ = newell_normals_areas(padded_polygons(points, cv, fs, fz), fz)
    face_of = np.repeat(np.arange(fs.size), fz)
    centroids = np.zeros((fs.size, 3))
    np.add.at(centroids, face_of, points[cv])
    return normals, centroids / np.maximum(fz, 1)[:, None]


def fan(face_starts, face_sizes):
    """Fan triangulation of ragged faces: (T, 3) corner indices, T = sum(face_sizes - 2)."""
    fs = np.asarray(face_starts, dtype=np.int64)
    ntri = np.asarray(face_sizes, dtype=np.int64) - 2
    _, local, _ = ragged(ntri)
    first = np.repeat(fs, ntri)
    return np.stack([first, first + local + 1, first + local + 2], axis=1)


def barycentric(p, a, b, c):
    """(N, 3) barycentric weights of points p in triangles abc, clipped to the triangle.

    Parameters
    ----------
    p, a, b, c : (N, 3) float
        Points (projected onto the plane by the least-squares solve) and triangle corners.

    Returns
    -------
    (N, 3) float64
        Non-negative weights summing to one (degenerate triangles: all weight on ``a``).
    """
    v0, v1, v2 = b - a, c - a, p - a
    d00 = np.einsum("ij,ij->i", v0, v0)
    d01 = np.einsum("ij,ij->i", v0, v1)
    d11 = np.einsum("ij,ij->i", v1, v1)
    d20 = np.einsum("ij,ij->i", v2, v0)
    d21 = np.einsum("ij,ij->i", v2, v1)
    den = d00 * d11 - d01 * d01
    ok = np.abs(den) > 0
    den = np.where(ok, den, 1.0)
    v = np.where(ok, (d11 * d20 - d01 * d21) / den, 0.0)
    w = np.where(ok, (d00 * d21 - d01 * d20) / den, 0.0)
    bary = np.clip(np.stack([1.0 - v - w, v, w], axis=1), 0.0, None)
    return bary / np.maximum(bary.sum(axis=1, keepdims=True), 1e-30)


def interpolate(values, sources, weights):
    """``sum_k weights[:, k] * values[sources[:, k]]``.

    Parameters
    ----------
    values : (C, ...) float
    sources : (N, 3) int
    weights : (N, 3) float

    Returns
    -------
    (N, ...) float64
    """
    values = np.asarray(values, dtype=np.float64)
    sources = np.asarray(sources, dtype=np.int64)
    weights = np.asarray(weights, dtype=np.float64)
    if sources.ndim != 2 or sources.shape != weights.shape:
        raise ValueError(f"sources and weights must have one shape (N, 3); got {sources.shape} "
                         f"and {weights.shape}")
    if sources.size and (sources.min() < 0 or sources.max() >= values.shape[0]):
        raise ValueError(f"sources must index the {values.shape[0]} values")
    picked = values[sources]                               # (N, 3, ...)
    return np.einsum("nk,nk...->n...", weights, picked)


def project_corners(orig, target):
    """Where each corner of one mesh lies on another: evaluated-surface weights per corner.

    Every corner of *orig* is sampled just inside its face and pushed along the face normal onto
    *target* by a ray (started in front of the face at the face's own size, looking back): the
    first surface met from the front is the target's version of this face (shrunk, shifted or
    identical). Corners whose ray finds no compatible triangle (normals within
    :data:`NORMAL_AGREEMENT`) take the nearest compatible target corner.

    Parameters
    ----------
    orig, target : tuple (points (V, 3), corner_verts (C,), face_starts (F,), face_sizes (F,))
        Both in the same (world) space.

    Returns
    -------
    sources : (C_orig, 3) int64
        Target corners.
    weights : (C_orig, 3) float64
        Barycentric weights over them (for :func:`interpolate`).
    """
    p_all, cv, fs, fz = _layout(*orig)
    ev, tcv, tfs, tfz = _layout(*target)
    normals, centroids = face_frames(p_all, cv, fs, fz)
    face_of = np.repeat(np.arange(fs.size), fz)
    p = p_all[cv]
    n = normals[face_of]
    reach = np.linalg.norm(centroids[face_of] - p, axis=1) + 1e-9
    tri_corners = fan(tfs, tfz)
    tri_pts = ev[tcv[tri_corners]]
    tri_n, _ = newell_normals_areas(tri_pts)
    bvh = build_bvh(tri_pts)
    sources = np.zeros((cv.size, 3), dtype=np.int64)
    weights = np.zeros((cv.size, 3))
    todo = np.arange(cv.size)
    for inset in (CORNER_INSET,) + RETRY_INSETS:
        s = p[todo] + inset * (centroids[face_of[todo]] - p[todo])
        nt = n[todo]
        origins = s + nt * reach[todo, None]
        t, tri = closest_hit(bvh, origins, -nt, 2.0 * reach[todo])
        ok = tri >= 0
        ok[ok] = np.einsum("ij,ij->i", tri_n[tri[ok]], nt[ok]) > NORMAL_AGREEMENT
        if np.any(ok):
            hit = origins[ok] - nt[ok] * t[ok, None]
            a, b, c = (tri_pts[tri[ok], k] for k in range(3))
            sources[todo[ok]] = tri_corners[tri[ok]]
            weights[todo[ok]] = barycentric(hit, a, b, c)
        todo = todo[~ok]
        if todo.size == 0:
            return sources, weights
    samples = p[todo] + CORNER_INSET * (centroids[face_of[todo]] - p[todo])
    best = nearest_corners(samples, n[todo], (ev, tcv, tfs, tfz))
    sources[todo] = best[:, None]
    weights[todo, 0] = 1.0
    return sources, weights


def nearest_corners(points, normals, target):
    """(N,) int64: nearest target corner whose face agrees with each normal (else the nearest).

    Parameters
    ----------
    points, normals : (N, 3) float
    target : tuple (points (V, 3), corner_verts (C,), face_starts (F,), face_sizes (F,))
    """
    ev, tcv, tfs, tfz = _layout(*target)
    face_n, centroids = face_frames(ev, tcv, tfs, tfz)
    face_of = np.repeat(np.arange(tfs.size), tfz)
    q = ev[tcv]
    q = q + CORNER_INSET * (centroids[face_of] - q)
    qn = face_n[face_of]
    # Disagreeing corners are pushed beyond any real distance, so they win only if none agrees.
    far = 4.0 * (np.ptp(np.concatenate([ev, points]), axis=0) ** 2).sum() + 1.0
    best = np.empty(points.shape[0], dtype=np.int64)
    for a in range(0, points.shape[0], NEAREST_CHUNK):
        b = a + NEAREST_CHUNK
        d = ((points[a:b, None, :] - q[None]) ** 2).sum(-1)
        d += far * ((normals[a:b] @ qn.T) <= NORMAL_AGREEMENT)
        best[a:b] = d.argmin(axis=1)
    return best
