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

A patch only partly under a cover (one the contact cuts left overhanging the outline by a
sliver, or any patch with the cuts off) is not black; its points under the cover get no direct
light instead (:class:`Covers`, used by :class:`core.lights.DirectLight` at the patches' Gauss
points).

Faces that are near-duplicates of each other (a flipped copy of a floor over it,
:func:`core.duplicates.near_duplicate_warning`) are not covers: which of the two shows the light
is the user's model, and both keep it. Emitting fronts are never covered (a lamp face down on a
table still counts its power as emitted, and the exact emitters light from it).
"""

import numpy as np

from . import constants
from .contacts import GRID_CELLS
from .duplicates import NEAR_DUPLICATE_RTOL, find_duplicates
from .geometry import box_pairs, inside_polygons
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
    pi, gi = box_pairs(centre[cand] - tol, centre[cand] + tol, fmin - tol, fmax + tol, cell)
    pi, gi = cand[pi], valid_f[gi]
    n_p = patches.normals[pi]
    n_g = scene.face_normals[gi]
    first = scene.vertices[scene.corner_verts[scene.face_starts[gi]]]
    ok = (gi != patches.face[pi]) & (np.einsum("ij,ij->i", n_p, n_g) <= -constants.tol.parallel_cos)
    ok &= np.abs(np.einsum("ij,ij->i", centre[pi] - first, n_g)) <= tol
    pi, gi = pi[ok], gi[ok]
    if pi.size == 0:
        return out
    root = _roots(scene)
    keep = root[patches.face[pi]] != root[gi]
    pi, gi = pi[keep], gi[keep]
    # Covered only if the whole patch is: its centre and its corners drawn in towards it by
    # SHRINK (a cut piece's corners lie on the footprint's outline).
    points = centre[pi, None] + (1.0 - SHRINK) * (corners[pi] - centre[pi, None])
    points = np.concatenate([centre[pi, None], points], axis=1)           # (K, 5, 3)
    k = points.shape[1]
    inside = inside_polygons(points.reshape(-1, 3), np.repeat(polys[gi], k, axis=0),
                             np.repeat(scene.face_normals[gi], k, axis=0))
    inside = inside.reshape(-1, k).all(axis=1)
    out[pi[inside]] = True
    return out


def _roots(scene):
    """(F,) int64: each face's root among its near-duplicates (:func:`core.duplicates.
    find_duplicates`), itself if it has none."""
    root = find_duplicates(scene, rtol=NEAR_DUPLICATE_RTOL)
    return np.where(root >= 0, root, np.arange(root.size))


class Covers:
    """Faces lying face to face on another face (a box's bottom and the floor under it), to
    find the points they cover (:meth:`points`).

    :func:`covered_fronts` blacks out a patch only if the whole of it is covered. A patch that
    overhangs its cover by a sliver, which the contact cuts leave uncut (``MIN_PIECE``), or any
    patch with ``contact_cuts`` off, has points under the cover and points beside it: the points
    under it are lifted into the box by the shadow rays' offset, where an emitting box top's
    inner side lit them (the floor under a glowing box read 1 % of the box's power,
    tests/core/test_fuzz.py). The direct light treats each such point as covered: no light at
    all, whatever the rays say.

    Parameters
    ----------
    scene : core.scene.Scene
    tol : float, optional
        Contact distance in metres (default ``tol.contact`` x the bounding diagonal, as
        :func:`covered_fronts`); a point must also lie this far inside a cover's outline (on
        the outline, at a box's foot, it is lit from outside).
    """

    def __init__(self, scene, *, tol=None):
        diag = scene.bounding_diagonal()
        self.tol = float(constants.tol.contact * diag if tol is None else tol)
        valid = np.flatnonzero(scene.face_valid)
        polys = padded_polygons(scene.vertices, scene.corner_verts, scene.face_starts,
                                scene.face_sizes)[valid]
        normals = np.asarray(scene.face_normals, dtype=np.float64)[valid]
        first = polys[:, 0]
        lo, hi = polys.min(axis=1) - self.tol, polys.max(axis=1) + self.tol
        size = np.sqrt(np.asarray(scene.face_areas, dtype=np.float64)[valid])
        self.cell = max(float(np.median(size)) if size.size else 0.0, diag / GRID_CELLS,
                        self.tol, np.finfo(float).tiny)
        a, b = box_pairs(lo, hi, lo, hi, self.cell)
        ok = (a < b) & (np.einsum("ij,ij->i", normals[a], normals[b])
                        <= -constants.tol.parallel_cos)
        a, b = a[ok], b[ok]
        ok = np.abs(np.einsum("ikj,ij->ik", polys[b] - first[a][:, None], normals[a])).max(
            axis=1) <= self.tol
        a, b = a[ok], b[ok]
        #: (F,) int64: each face's root among its near-duplicates (itself if it has none).
        self.root = np.arange(scene.face_areas.size)
        if a.size:
            # A flipped copy of a face is not its cover (core.duplicates; as covered_fronts).
            self.root = _roots(scene)
            keep = self.root[valid[a]] != self.root[valid[b]]
            a, b = a[keep], b[keep]
        mine = np.unique(np.concatenate([a, b]))
        self.polys, self.normals, self.first = polys[mine], normals[mine], first[mine]
        self.face = valid[mine]
        self.lo, self.hi = lo[mine], hi[mine]

    def __len__(self):
        return self.polys.shape[0]

    def points(self, points, normals, faces):
        """(n,) bool: ``points`` (n, 3) of scene faces ``faces`` (n,) facing ``normals`` (n, 3)
        that lie in another face's plane (within ``tol``), face it, and lie inside its outline
        by more than ``tol``. (The face a point belongs to is needed: the floor under a box and
        the box bottom's inner side are the same points facing the same way; a face's flipped
        copy does not cover it either.)"""
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        out = np.zeros(points.shape[0], dtype=bool)
        if not len(self) or points.shape[0] == 0:
            return out
        normals = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
        pi, ci = box_pairs(points, points, self.lo, self.hi, self.cell)
        ok = self.root[np.asarray(faces)[pi]] != self.root[self.face[ci]]
        ok &= np.einsum("ij,ij->i", normals[pi], self.normals[ci]) <= -constants.tol.parallel_cos
        ok &= np.abs(np.einsum("ij,ij->i", points[pi] - self.first[ci], self.normals[ci])) \
            <= self.tol
        pi, ci = pi[ok], ci[ok]
        if pi.size:
            hit = inside_polygons(points[pi], self.polys[ci], self.normals[ci], margin=self.tol)
            out[pi[hit]] = True
        return out
