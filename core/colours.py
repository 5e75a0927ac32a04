"""Corner colours: patch radiance gathered to the scene's corners (Blender loops).

A corner takes the area-weighted mean of the patches at its vertex that lie on one smooth surface
with its face: the same material and a normal within the crease angle of the face's normal (the
face's own patches always count). Room corners and material boundaries thus stay crisp, while a
curved surface tessellated finer than the crease angle shades smoothly.
"""

import numpy as np

from .constants import DEFAULT_CREASE_ANGLE
from .geometry import within_crease
from .patches import Patches, check_scene

def corner_colours(scene, patches, patch_radiance, *, crease_angle=DEFAULT_CREASE_ANGLE):
    """Outgoing radiance at every scene corner.

    Parameters
    ----------
    scene : Scene
        With ``C`` corners and ``F`` faces.
    patches : Patches
        ``P`` patches of that scene (from :func:`core.patches.make_patches`).
    patch_radiance : (P, 3) float
        Outgoing RGB radiance of the front side of every patch.
    crease_angle : float, keyword-only
        Degrees in [0, 180]: a patch at the corner's vertex joins the mean only if its normal is
        within this angle of the corner's face normal (and its material is the face's).

    Returns
    -------
    (C, 3) float64
        Area-weighted mean radiance per corner. Corners of dropped faces (``face_valid`` False)
        take the mean of the same-material patches at their vertex, else 0.
    """
    check_scene(scene)
    if not isinstance(patches, Patches):
        raise TypeError(f"patches must be a Patches; got {type(patches).__name__}")
    n_p = patches.n_patches
    rad = np.asarray(patch_radiance, dtype=np.float64)
    if rad.shape != (n_p, 3):
        raise ValueError(f"patch_radiance must have shape ({n_p}, 3) (one RGB row per patch); "
                         f"got {rad.shape}")
    if not np.all(np.isfinite(rad)):
        bad = int(np.flatnonzero(~np.isfinite(rad).all(axis=1))[0])
        raise ValueError(f"patch_radiance must be finite; row {bad} is {rad[bad].tolist()}")
    try:
        angle = float(crease_angle)
    except (TypeError, ValueError):
        raise ValueError(f"crease_angle must be a number of degrees in [0, 180]; "
                         f"got {crease_angle!r}") from None
    if not (0.0 <= angle <= 180.0):
        raise ValueError(f"crease_angle must be a number of degrees in [0, 180]; got {crease_angle!r}")

    corner_verts = np.asarray(scene.corner_verts, dtype=np.int64)
    face_starts = np.asarray(scene.face_starts, dtype=np.int64)
    n_corners, n_verts = corner_verts.shape[0], np.asarray(scene.vertices).shape[0]
    if patches.face_patch_start.shape[0] != face_starts.shape[0] + 1:
        raise ValueError(f"patches were made for {patches.face_patch_start.shape[0] - 1} faces; "
                         f"the scene has {face_starts.shape[0]}")

    # Face of every corner (corners not used by any face keep -1 and get 0).
    corner_face = np.full(n_corners, -1, dtype=np.int64)
    corners, faces = scene.face_corner_indices()
    corner_face[corners] = faces

    # Join corners with the incidence entries of their vertex: sort entries by vertex, then each
    # corner repeats over its vertex's run.
    inc_v = patches.incidence_vertex
    order = np.argsort(inc_v, kind="stable")
    inc_patch = patches.incidence_patch[order]
    run_start = np.searchsorted(inc_v[order], np.arange(n_verts + 1))
    used = corner_face >= 0
    run_len = np.where(used, run_start[corner_verts + 1] - run_start[corner_verts], 0)
    pair_corner = np.repeat(np.arange(n_corners, dtype=np.int64), run_len)
    pair_entry = (np.arange(pair_corner.shape[0], dtype=np.int64)
                  - np.repeat(np.cumsum(run_len) - run_len, run_len)
                  + run_start[corner_verts[pair_corner]])
    p = inc_patch[pair_entry]
    # A patch touches a vertex at most once per face, but an n-gon's triangles may put several
    # patches of one face at a vertex; each is a distinct patch and counts once.
    f = corner_face[pair_corner]

    valid = np.asarray(scene.face_valid, dtype=bool)[f]
    same_material = patches.material[p] == np.asarray(scene.face_materials, dtype=np.int64)[f]
    smooth = same_material & within_crease(patches.normals[p], np.asarray(scene.face_normals)[f],
                                           angle)
    take = np.where(valid, (patches.face[p] == f) | smooth, same_material)

    w = patches.areas[p] * take
    weight = np.bincount(pair_corner, weights=w, minlength=n_corners)
    out = np.zeros((n_corners, 3))
    for channel in range(3):         # three bincounts: one per colour channel
        out[:, channel] = np.bincount(pair_corner, weights=w * rad[p, channel], minlength=n_corners)
    has = weight > 0
    out[has] /= weight[has, None]
    return out
