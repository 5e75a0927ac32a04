"""Coincident duplicate faces: detected, solved as one surface, reported by name.

A face left twice in an imported file (a floor duplicated in place, or duplicated and flipped)
is two surfaces at the same place. Solved as two, each copy sees the other at zero distance:
the reciprocity step shares the floor's light between the copies and the whole room darkens
(about 15 % for a duplicated floor), while Cycles shows one surface.

Two valid faces are duplicates when they have the same number of corners, lie in the same plane
(normals parallel or opposite), and every corner of one lies within ``DUPLICATE_RTOL`` x the
face size (sqrt of its area) of a corner of the other. Of each group of duplicates the face with
the lowest index is kept; the others are marked invalid (:attr:`Scene.face_valid`) with
:attr:`Scene.face_duplicate_of` naming the kept face, so they make no patches and nothing sees
them; after the solve their corners take the colours of the kept face's corners at the same
places (:func:`fill_duplicate_colours`), and the report warns (:func:`duplicate_warning`).
"""

import dataclasses

import numpy as np

from .constants import tol
from .geometry import box_pairs

#: Corners of two duplicate faces coincide within this fraction of the face size (sqrt area).
DUPLICATE_RTOL = 1e-4

#: Copies of a face (facing the same way, or facing it), farther apart than DUPLICATE_RTOL but
#: within this fraction of its size, are solved as the thin gap between two surfaces (light
#: enters it from the edges) and named in a warning: most often a surface left twice by an
#: import, offset a little. Faces back to back (a pane's or a door's two sides) are not named.
NEAR_DUPLICATE_RTOL = 1e-2

#: Objects named in the warning at most (then "and N more").
MAX_NAMED = 5


def _face_corners(scene, faces):
    """Corner positions (n, k, 3) of faces that all have k corners."""
    k = int(scene.face_sizes[faces[0]])
    idx = scene.face_starts[faces][:, None] + np.arange(k)[None, :]
    return scene.vertices[scene.corner_verts[idx]]


def find_duplicates(scene, *, rtol=DUPLICATE_RTOL):
    """(F,) int64: for every face, the face it duplicates (lowest index of its group), else -1.

    Parameters
    ----------
    scene : core.scene.Scene
    rtol : float
        Corner distance, as a fraction of the face size, within which corners coincide.

    Returns
    -------
    duplicate_of : (F,) int64
        -1 for faces kept (and faces with no duplicate); the kept face's index otherwise.
    """
    F = scene.n_faces
    duplicate_of = np.full(F, -1, dtype=np.int64)
    valid = np.flatnonzero(scene.face_valid)
    if valid.size < 2:
        return duplicate_of
    centroid = _centroids(scene)[valid]
    size = np.sqrt(scene.face_areas[valid])
    reach = rtol * size
    extent = np.ptp(centroid, axis=0).max()
    cell = max(2.0 * float(reach.max()), extent / 2.0**20, np.finfo(float).tiny)
    lo, hi = centroid - reach[:, None], centroid + reach[:, None]
    i, j = box_pairs(lo, hi, lo, hi, cell)
    keep = i < j
    i, j = i[keep], j[keep]
    fi, fj = valid[i], valid[j]
    ok = scene.face_sizes[fi] == scene.face_sizes[fj]
    cos = np.abs(np.einsum("ij,ij->i", scene.face_normals[fi], scene.face_normals[fj]))
    ok &= cos >= tol.parallel_cos
    ok &= np.abs(size[i] - size[j]) <= np.minimum(reach[i], reach[j])
    fi, fj, r = fi[ok], fj[ok], np.minimum(reach[i], reach[j])[ok]
    match = np.zeros(fi.size, dtype=bool)
    for k in np.unique(scene.face_sizes[fi]):       # one pass per corner count, not per pair
        rows = np.flatnonzero(scene.face_sizes[fi] == k)
        a, b = _face_corners(scene, fi[rows]), _face_corners(scene, fj[rows])
        d = np.linalg.norm(a[:, :, None, :] - b[:, None, :, :], axis=3)      # (n, k, k)
        match[rows] = ((d.min(axis=2).max(axis=1) <= r[rows])
                       & (d.min(axis=1).max(axis=1) <= r[rows]))
    fi, fj = fi[match], fj[match]
    root = np.arange(F, dtype=np.int64)
    np.minimum.at(root, fj, fi)
    while True:                                     # point every face at its group's lowest
        nxt = root[root]
        if np.array_equal(nxt, root):
            break
        root = nxt
    dup = root != np.arange(F)
    duplicate_of[dup] = root[dup]
    return duplicate_of


def merge_duplicates(scene, *, rtol=DUPLICATE_RTOL):
    """The scene with its duplicate faces marked invalid and ``face_duplicate_of`` set.

    Returns ``scene`` itself when it has no duplicates.
    """
    duplicate_of = find_duplicates(scene, rtol=rtol)
    dup = duplicate_of >= 0
    if not dup.any():
        return scene
    valid = np.asarray(scene.face_valid) & ~dup
    valid.setflags(write=False)
    duplicate_of.setflags(write=False)
    return dataclasses.replace(scene, face_valid=valid, face_duplicate_of=duplicate_of)


def fill_duplicate_colours(scene, corner_colours):
    """Corner colours (C, 3) with every duplicate's corners given the kept face's colours at
    the same places (nearest corner of the kept face)."""
    dup_of = scene.face_duplicate_of
    if dup_of is None or not np.any(dup_of >= 0):
        return corner_colours
    out = np.array(corner_colours, copy=True)
    dups = np.flatnonzero(dup_of >= 0)
    for k in np.unique(scene.face_sizes[dups]):
        f = dups[scene.face_sizes[dups] == k]
        g = dup_of[f]
        a, b = _face_corners(scene, f), _face_corners(scene, g)
        nearest = np.argmin(np.linalg.norm(a[:, :, None, :] - b[:, None, :, :], axis=3), axis=2)
        src = scene.face_starts[g][:, None] + nearest
        dst = scene.face_starts[f][:, None] + np.arange(k)[None, :]
        out[dst.ravel()] = out[src.ravel()]
    return out


def duplicate_warning(scene):
    """The report's warning naming the objects with duplicate faces, or None."""
    dup_of = scene.face_duplicate_of
    if dup_of is None or not np.any(dup_of >= 0):
        return None
    dups = np.flatnonzero(dup_of >= 0)
    objs = np.unique(np.concatenate([scene.face_objects[dups], scene.face_objects[dup_of[dups]]]))
    names = [f'"{scene.object_names[o]}"' for o in objs[:MAX_NAMED]]
    more = f" and {objs.size - MAX_NAMED} more" if objs.size > MAX_NAMED else ""
    return (f"{dups.size} faces coincide with other faces (duplicates, e.g. "
            f"{scene.face_label(dups[0])} = {scene.face_label(dup_of[dups[0]])}) in objects "
            f"{', '.join(names)}{more}: each group was solved as one surface")


def copy_duplicate_faces(scene, mesh):
    """The radiosity mesh with every duplicate face given a copy of its kept face's output faces.

    A duplicate makes no patches, so the output has no faces of its own for it; the object it
    belongs to (often a copy of the floor as an object of its own) would lose them. The copies
    lie where the kept face's output faces lie, wound the duplicate's way (reversed for a
    flipped duplicate), carry the same colours, and take their per-corner values from the
    duplicate's own corners at the same places.

    Returns
    -------
    mesh : core.outmesh.OutputMesh
    source : (C_new,) int64
        Output corner of ``mesh`` (as given) each corner of the result copies (itself for the
        corners that were there).
    """
    C = mesh.corner_verts.size
    source = np.arange(C)
    dup_of = scene.face_duplicate_of
    if dup_of is None or not np.any(dup_of >= 0):
        return mesh, source
    face_of = mesh.face_of_corner()
    to_dup = np.full(scene.n_corners, -1, dtype=np.int64)   # kept face's corner -> duplicate's
    parts = dict(corner_verts=[mesh.corner_verts], face_sizes=[mesh.face_sizes],
                 face_parent=[mesh.face_parent], corner_colours=[mesh.corner_colours],
                 corner_sources=[mesh.corner_sources], corner_weights=[mesh.corner_weights],
                 source=[source])
    for d in np.flatnonzero(dup_of >= 0):             # a few faces: one loop per duplicate
        k = dup_of[d]
        faces = mesh.faces_of(np.array([k]))
        if faces.size == 0:
            continue
        corners = np.flatnonzero(np.isin(face_of, faces))         # in face order
        sizes = mesh.face_sizes[faces]
        if scene.face_normals[d] @ scene.face_normals[k] < 0:     # flipped: reverse each face
            first = np.repeat(mesh.face_starts[faces], sizes)
            local = corners - first
            corners = first + np.repeat(sizes, sizes) - 1 - local
        # each of k's corners -> the duplicate's corner at the nearest place
        ks = scene.face_starts[k] + np.arange(scene.face_sizes[k])
        ds = scene.face_starts[d] + np.arange(scene.face_sizes[d])
        pk = scene.vertices[scene.corner_verts[ks]]
        pd = scene.vertices[scene.corner_verts[ds]]
        to_dup[ks] = ds[np.argmin(np.linalg.norm(pk[:, None] - pd[None], axis=2), axis=1)]
        parts["corner_verts"].append(mesh.corner_verts[corners])
        parts["face_sizes"].append(sizes)
        parts["face_parent"].append(np.full(faces.size, d, dtype=np.int64))
        parts["corner_colours"].append(mesh.corner_colours[corners])
        parts["corner_sources"].append(to_dup[mesh.corner_sources[corners]])
        parts["corner_weights"].append(mesh.corner_weights[corners])
        parts["source"].append(corners)
    sizes = np.concatenate(parts["face_sizes"])
    out = dataclasses.replace(
        mesh, corner_verts=np.concatenate(parts["corner_verts"]), face_sizes=sizes,
        face_starts=np.cumsum(sizes) - sizes, face_parent=np.concatenate(parts["face_parent"]),
        corner_colours=np.concatenate(parts["corner_colours"]),
        corner_sources=np.concatenate(parts["corner_sources"]),
        corner_weights=np.concatenate(parts["corner_weights"]))
    return out, np.concatenate(parts["source"])


def _centroids(scene):
    """(F, 3) corner means of every face (any corner counts), as :func:`find_duplicates` uses."""
    first = np.cumsum(scene.face_sizes) - scene.face_sizes
    corners, _ = scene.face_corner_indices()
    pos = scene.vertices[scene.corner_verts[corners]]
    return np.add.reduceat(pos, first, axis=0) / scene.face_sizes[:, None]


def near_duplicate_warning(scene, *, rtol=NEAR_DUPLICATE_RTOL):
    """The report's warning naming faces with a copy within ``rtol`` x their size, facing the
    same way or facing them, that is not a duplicate (:func:`find_duplicates`), or None."""
    near = find_duplicates(scene, rtol=rtol)
    faces = np.flatnonzero(near >= 0)
    if faces.size == 0:
        return None
    # Kept: copies facing the same way, or facing each other (a flipped copy over the floor);
    # not faces back to back (a pane's two sides, each facing away from the other).
    centroid = _centroids(scene)
    n_f, n_g = scene.face_normals[faces], scene.face_normals[near[faces]]
    c_f, c_g = centroid[faces], centroid[near[faces]]
    same = np.einsum("ij,ij->i", n_f, n_g) > 0
    facing = np.einsum("ij,ij->i", c_g - c_f, n_f) > 0
    faces = faces[same | facing]
    if faces.size == 0:
        return None
    kept = near[faces]
    objs = np.unique(np.concatenate([scene.face_objects[faces], scene.face_objects[kept]]))
    names = [f'"{scene.object_names[o]}"' for o in objs[:MAX_NAMED]]
    more = f" and {objs.size - MAX_NAMED} more" if objs.size > MAX_NAMED else ""
    f, g = int(faces[0]), int(kept[0])
    gap = float(np.linalg.norm(centroid[f] - centroid[g]))
    return (f"{faces.size} faces lie {gap:.3g} m or so from a copy of themselves (e.g. "
            f"{scene.face_label(f)} and {scene.face_label(g)}) in objects "
            f"{', '.join(names)}{more}: solved as the thin gap between two surfaces; if one is "
            f"a leftover copy, delete it")
