"""Gap lines: patches cut along the projection of an edge that runs within a small gap of them.

A shelf's bottom board stops 2 cm short of the wall behind it; a sofa stands 3 cm off the
wall. Nothing touches, so :mod:`core.contacts` finds no line, yet the wall under the board sits
in a dark slot and the wall above it is lit: the light changes within a few gap widths of the
line where the board's back edge projects onto the wall. A wall patch that straddles that line
carries one radiance for both sides, and so errs twice, as a contact does: the slot's floor and
the wall inside read the lit part's light (the office's slot under its shelving read 7 to 35 %
too bright against Cycles and Radiance alike), and the wall above reads too dark.

This module finds those lines before the solve: for a patch's plane, a face of another surface
that lies wholly in front of the plane (on its normal's side, or behind it where the bake found
the face lit from behind: a flipped wall, :mod:`core.orient`), clear of it (no contact), but
with an edge (two or more corners) within the gap of it. Those corners, projected onto the
plane, give a segment (:func:`core.contacts.contact_segments` with the gap as its distance),
which cuts every patch it crosses (:func:`core.contacts.split_at_contacts`). Faces parallel to
the plane (a table top above the floor, a panel hung flat on a wall) give none: they shade an
area, not a line.

The light across such a line changes over a few gap widths. A patch is cut where the gap is at
most the bake's smallest element (:func:`core.adaptive.min_element_size`, 5 cm: narrower than
the mesh refines to, so only a cut draws it). A patch much larger than a wider gap still
straddles a steep change: on the cabinet of ``tests/core/test_gaplines.py`` (0.5 m patches; its
inside floor against the same room with the wall cut by hand and 1/8 m patches, 2026-12-05)
the cuts gave 1.10, 1.25, 1.20, 1.18 times that at gaps of 2, 4, 6 and 10 cm, no cuts 4.85,
2.29, 1.55, 1.35; at 20 cm every form reads 1.35 (the rest of the mesh's error), cut or not.
Cutting up to a quarter of the patch's size (``GAP_SHARE``) is not adopted yet (its comment).
"""

import numpy as np

from . import constants
from .contacts import (Contacts, _clear_of_corners, _crossed, _lines_of, contact_segments,
                       face_boxes, no_contacts)
from .geometry import box_pairs, ragged
from .patches import triangle_mask

#: A gap line cuts no patch where it would cross an edge nearer its ends than this fraction of
#: the patch's size: it need not be cut everywhere, and a needle costs a hemicube for nothing
#: (as :data:`core.footlines.NEEDLE`).
NEEDLE = 0.005

#: A patch is also cut by an edge within this fraction of its size (square root of its area),
#: when that is more than the gap. 0: not adopted. At 0.25 the cabinet's 6 and 10 cm slots were
#: nearer the converged light (module doc), but a room of tests/core/test_orient.py, whose
#: wall is 10 cm behind a board's edge, then read its wall 0.2 % darker with its floor flipped
#: than as modelled, on three seeds (seed noise 0.07 %), for a reason not yet traced.
GAP_SHARE = 0.0


def gap_lines(scene, patches, gap, *, tol=None, back_open=None):
    """The gap lines that cross ``patches``, as :class:`core.contacts.Contacts` rows for
    :func:`core.contacts.split_at_contacts`, and how many (face, plane) segments there are.

    Parameters
    ----------
    scene : core.scene.Scene
    patches : Patches
    gap : float
        Distance (m) of an edge from a patch's plane that makes a line on any patch (a patch
        larger than ``gap / GAP_SHARE`` takes lines from up to ``GAP_SHARE`` x its size).
    tol : float, optional
        Contact distance (m): faces nearer the plane than this touch it (:mod:`core.contacts`
        cuts there). Default ``tol.contact`` x the bounding diagonal.
    back_open : (F,) bool, optional
        Faces whose room side is their back (:mod:`core.orient` found them lit from behind: a
        flipped wall): their lines come from faces behind them instead.

    Returns
    -------
    lines : Contacts
        One row per (patch, segment) pair where the segment crosses the patch.
    count : int
        Distinct (face, plane) segments found.
    """
    if tol is None:
        tol = constants.tol.contact * scene.bounding_diagonal()
    none = no_contacts(scene, tol, min_gap=NEEDLE)
    gap = float(gap)
    if not gap > tol or patches.n_patches == 0:
        return none, 0
    corners = np.asarray(patches.corners, dtype=np.float64)
    normals = np.asarray(patches.normals, dtype=np.float64)
    size = np.sqrt(np.asarray(patches.areas, dtype=np.float64))
    face = np.asarray(patches.face)
    valid_f = np.flatnonzero(scene.face_valid)
    # Lamps are not cut: their light is their emission, which a cut does not change, and the
    # exact direct light integrates each lamp over its own pieces (tests/core/test_fuzz.py: a
    # panel 10 cm over a box, cut along the box's side, let 16 % of its power escape a closed
    # room).
    receives = ~scene.emissive_materials()[np.asarray(patches.material)]
    if valid_f.size == 0 or not receives.any():
        return none, 0
    fmin, fmax = (box[valid_f] for box in face_boxes(scene))
    reach = np.maximum(gap, GAP_SHARE * size)
    cell = max(float(np.median(size)), gap)
    pi, gi = box_pairs(corners.min(axis=1) - reach[:, None], corners.max(axis=1)
                       + reach[:, None], fmin, fmax, cell)
    gi = valid_f[gi]
    keep = (gi != face[pi]) & receives[pi]
    pi, gi = pi[keep], gi[keep]
    # One plane per patch: its normal (turned round on a flipped face) through its first corner.
    plane_n = normals[pi]
    if back_open is not None:
        plane_n = np.where(np.asarray(back_open, dtype=bool)[face[pi]][:, None], -plane_n,
                           plane_n)
    plane_d = np.einsum("ij,ij->i", corners[pi, 0], plane_n)
    clear = _clear_of_plane(scene, gi, plane_n, plane_d, tol)
    pi, gi, plane_n, plane_d = pi[clear], gi[clear], plane_n[clear], plane_d[clear]
    a, b, ok = contact_segments(scene, gi, plane_n, plane_d, reach[pi])
    pi, gi, a, b, plane_n = pi[ok], gi[ok], a[ok], b[ok], plane_n[ok]
    u, w, length = _lines_of(a, b, plane_n)
    k = np.where(triangle_mask(corners[pi]), 3, 4)
    hit = _crossed(corners[pi], k, size[pi], a, u, w, length, tol) \
        & _clear_of_corners(corners[pi], k, size[pi], a, w, NEEDLE)
    count = int(np.unique(np.stack([gi, face[pi]], axis=1), axis=0).shape[0]) if pi.size else 0
    pi, gi, a, u, w, length = pi[hit], gi[hit], a[hit], u[hit], w[hit], length[hit]
    o = np.lexsort((gi, pi))
    return Contacts(pi[o], a[o], u[o], w[o], length[o],
                    np.zeros(scene.vertices.shape[0], dtype=bool), tol, other=gi[o],
                    normal=plane_n[o], min_gap=NEEDLE), count


def _clear_of_plane(scene, faces, plane_n, plane_d, tol):
    """(K,) bool: face k lies wholly in front of plane k (the side its normal points to),
    farther than ``tol`` from it: it neither touches nor pierces it (those are contacts), and
    it is not behind the surface (a shelf board ends 3 cm inside its side panel's outer face,
    on that face's back: hidden there, it casts nothing on it)."""
    owner, local, starts = ragged(scene.face_sizes[faces])
    x = scene.vertices[scene.corner_verts[scene.face_starts[faces][owner] + local]]
    h = np.einsum("ij,ij->i", x, plane_n[owner]) - plane_d[owner]
    if h.size == 0:
        return np.zeros(faces.size, dtype=bool)
    return np.minimum.reduceat(h, starts) > tol
