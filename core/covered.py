"""Fronts covered by a face lying on them: the floor under a box, the box's bottom on the floor.

A box standing on a floor touches it face to face: the floor under the box (after the contact
cuts, :mod:`core.contacts`, whole patches) and the box's bottom lie in one plane, facing each
other with no gap. No light reaches either front: a path tracer reads both as black. The
engine's point operations cannot see the contact, because every one starts from a point lifted
off its surface or ignores hits at distance zero:

* a shadow ray from the floor under the box to an emitting box top starts above the bottom it
  should hit, so the top's back lit both the box's bottom (its inner side) and the floor under it
  (measured: a closed room lit by a box's two-sided top absorbed 113 % of the emitted power,
  tests/core/test_fuzz.py);
* a hemicube on the floor under the box has the bottom behind its near plane and sees the box's
  inside.

Here such a front is found geometrically (its whole patch lies inside a face of the opposite
orientation in its plane, within the contact distance) and made a black node: it receives no
direct light, sends nothing and takes no hemicube row; what other rows credit to it is absorbed.

A covered front is still drawn in the hemicubes: seen from inside a box, the floor under it and
the box's bottom lie at one depth and rounding picks which one a pixel sees. The light that
reaches the floor there is absorbed, so the energy balance holds either way; the box's inside
reads a little darker (no one sees it).

Faces that are near-duplicates of each other (a flipped copy of a floor over it,
:func:`core.duplicates.near_duplicate_warning`) are not covers: which of the two shows the light
is the user's model, and both keep it. Emitting fronts are never covered (a lamp face down on a
table still counts its power as emitted, and the exact emitters light from it).
"""

import numpy as np

from . import constants
from .contacts import GRID_CELLS, _box_pairs
from .duplicates import NEAR_DUPLICATE_RTOL, find_duplicates
from .geometry import unit_frames
from .transfer import padded_polygons

#: A patch's corners are tested this fraction of the way in towards its centre: the pieces cut
#: along a box's outline have their corners on it, where the inside test is a tie.
SHRINK = 1e-3


def covered_fronts(scene, patches, *, tol=None):
    """(P,) bool: patches whose front lies face to face on another face (see the module doc).

    Parameters
    ----------
    scene : core.scene.Scene
    patches : core.patches.Patches
    tol : float, optional
        Contact distance in metres (default ``tol.contact`` x the bounding diagonal, as
        :func:`core.contacts.find_contacts`).
    """
    P = len(patches.areas)
    out = np.zeros(P, dtype=bool)
    valid_f = np.flatnonzero(scene.face_valid)
    if P == 0 or valid_f.size < 2:
        return out
    diag = scene.bounding_diagonal()
    if tol is None:
        tol = constants.tol.contact * diag
    emits = np.any(np.asarray(scene.emission, dtype=np.float64)[patches.material] > 0, axis=1)
    corners = np.asarray(patches.corners, dtype=np.float64)
    # A triangle's fourth corner repeats its third: the mean is still inside it.
    centre = corners.mean(axis=1)
    cand = np.flatnonzero(~emits & (patches.areas > 0))
    if cand.size == 0:
        return out
    polys = padded_polygons(scene.vertices, scene.corner_verts, scene.face_starts,
                            scene.face_sizes)
    fmin, fmax = polys.min(axis=1)[valid_f], polys.max(axis=1)[valid_f]
    size = np.sqrt(patches.areas[cand])
    cell = max(float(np.median(size)), diag / GRID_CELLS, tol)
    pi, gi = _box_pairs(centre[cand] - tol, centre[cand] + tol, fmin - tol, fmax + tol, cell)
    pi, gi = cand[pi], valid_f[gi]
    n_p = patches.normals[pi]
    n_g = scene.face_normals[gi]
    first = scene.vertices[scene.corner_verts[scene.face_starts[gi]]]
    ok = (gi != patches.face[pi]) & (np.einsum("ij,ij->i", n_p, n_g) <= -constants.tol.parallel_cos)
    ok &= np.abs(np.einsum("ij,ij->i", centre[pi] - first, n_g)) <= tol
    pi, gi = pi[ok], gi[ok]
    if pi.size == 0:
        return out
    root = find_duplicates(scene, rtol=NEAR_DUPLICATE_RTOL)
    root = np.where(root >= 0, root, np.arange(root.size))
    keep = root[patches.face[pi]] != root[gi]
    pi, gi = pi[keep], gi[keep]
    # Covered only if the whole patch is: its centre and its corners drawn in towards it by
    # SHRINK (a cut piece's corners lie on the footprint's outline).
    points = centre[pi, None] + (1.0 - SHRINK) * (corners[pi] - centre[pi, None])
    points = np.concatenate([centre[pi, None], points], axis=1)           # (K, 5, 3)
    k = points.shape[1]
    inside = _inside(points.reshape(-1, 3), np.repeat(polys[gi], k, axis=0),
                     np.repeat(scene.face_normals[gi], k, axis=0)).reshape(-1, k).all(axis=1)
    out[pi[inside]] = True
    return out


def _inside(points, polys, normals):
    """(K,) bool: ``points`` (K, 3) inside the planar polygons ``polys`` (K, n, 3) of unit
    ``normals``, projected on the polygon's plane (crossing number; a padded polygon's
    repeated corners add zero-length edges, which cross nothing)."""
    u, v = unit_frames(normals)
    rel = polys - points[:, None, :]
    x, y = np.einsum("knj,kj->kn", rel, u), np.einsum("knj,kj->kn", rel, v)
    x1, y1 = np.roll(x, -1, axis=1), np.roll(y, -1, axis=1)
    straddles = (y > 0) != (y1 > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        at = x + (0.0 - y) * (x1 - x) / (y1 - y)
    crossings = (straddles & (at > 0)).sum(axis=1)
    return crossings % 2 == 1
