"""Adaptive refinement: find the patches across which the solved light changes.

A patch is worth splitting when the radiance of a neighbour on the same smooth surface (sharing a
corner point, same material, normals within the crease angle) differs from its own by more than a
threshold, relative to the brighter of the two: that is where a shadow edge, a light's footprint or
a room corner's fall-off is not resolved at the current patch size. Elsewhere the light is nearly
constant across a patch and splitting it would only cost time.
"""

import numpy as np

from .constants import tol
from .geometry import pairs_by_key, within_crease

#: Luminance weights (Rec. 709 / sRGB primaries, scene-linear) for comparing RGB radiance.
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])

#: Differences are taken relative to the brighter patch of a pair, but never relative to less
#: than this fraction of the scene's mean (area-weighted, non-emitting) luminance: a change that
#: is small against the scene's typical radiance adds little to the area-weighted error, however
#: large it is against a near-black corner's own level. A quarter, not a half: a shadow's
#: inside sits at a tenth of the mean or less, and at a half the changes across it were judged
#: against five times its own level (the floor beside the Cornell box's short block, 0.09 x the
#: mean, read +27 %). Measured (bench/compare/coarse.py's Reference, the samples modelled
#: coarsely, one bake each; floor -> Cornell box, office): 0.5 -> 1.57 % at 2,921 vertices,
#: 2.67 % at 19,079; 0.35 -> 1.30 %, 3,017; 2.66 %, 20,398; 0.25 -> 1.31 %, 3,041; 2.65 %,
#: 21,130; 0.15 -> 1.27 %, 3,064; 2.58 %, 21,601; 0.1 -> 1.42 %, 3,064; 2.60 %, 21,586.
DARK_FLOOR = 0.25



def lit_mean(patches, patch_radiance, emitting):
    """Area-weighted mean luminance of the non-emitting patches (0 when there are none)."""
    y = np.asarray(patch_radiance, dtype=np.float64) @ LUMINANCE
    emitting = np.asarray(emitting, dtype=bool)
    a_lit = patches.areas[~emitting]
    return float((a_lit * y[~emitting]).sum() / a_lit.sum()) if a_lit.sum() > 0 else 0.0


def refine_mask(patches, patch_radiance, emitting, *, threshold=0.1, crease_angle=30.0,
                min_area=0.0, mean=None):
    """Mark patches whose light differs from a smooth neighbour's by more than ``threshold``.

    Parameters
    ----------
    patches : core.patches.Patches
    patch_radiance : (P, 3) float
        Solved front radiance of every patch.
    emitting : (P,) bool
        Emitting patches (never marked: their radiance is dominated by their own emission).
    threshold : float
        Relative luminance difference, in (0, 1), that marks both patches of a pair.
    crease_angle : float
        Degrees: neighbours whose normals differ by more are a different surface (not compared).
    min_area : float
        Patches of this area or less are never marked (the refinement's floor).
    mean : float, optional
        The luminance :data:`DARK_FLOOR` is a fraction of (default: :func:`lit_mean` of
        ``patch_radiance``; a back side's elements pass their scene's, see
        :mod:`core.elements`).

    Returns
    -------
    mask : (P,) bool
    """
    L = np.asarray(patch_radiance, dtype=np.float64)
    P = patches.corners.shape[0]
    if L.shape != (P, 3):
        raise ValueError(f"patch_radiance must have shape ({P}, 3); got {L.shape}")
    emitting = np.asarray(emitting, dtype=bool)
    if emitting.shape != (P,):
        raise ValueError(f"emitting must have shape ({P},); got {emitting.shape}")
    if not 0 < threshold < 1:
        raise ValueError(f"threshold must be in (0, 1); got {threshold!r}")
    if P == 0:
        return np.zeros(0, dtype=bool)
    y = L @ LUMINANCE
    if mean is None:
        mean = lit_mean(patches, L, emitting)
    floor = DARK_FLOOR * mean if mean > 0 else 1e-300

    # Corner points shared by patches: quantised positions -> point ids.
    corners = patches.corners.reshape(-1, 3)
    scale = float(np.ptp(corners, axis=0).max()) or 1.0
    keys = np.round(corners / (tol.point * scale)).astype(np.int64)
    _, point = np.unique(keys, axis=0, return_inverse=True)
    point = point.reshape(-1)
    patch = np.repeat(np.arange(P), 4)
    # One incidence per (point, patch) (a triangle repeats its last corner).
    inc = np.unique(np.stack([point, patch], axis=1), axis=0)
    # All ordered pairs of incidences at each point (degree is small: 4-8 on a grid).
    i, j = pairs_by_key(inc[:, 0])
    a, b = inc[i, 1], inc[j, 1]
    keep = a != b
    a, b = a[keep], b[keep]
    same = (patches.material[a] == patches.material[b]) & \
        within_crease(patches.normals[a], patches.normals[b], crease_angle) & \
        ~emitting[a] & ~emitting[b]
    a, b = a[same], b[same]
    diff = np.abs(y[a] - y[b]) / np.maximum(np.maximum(y[a], y[b]), floor)
    over = diff > threshold
    mask = np.zeros(P, dtype=bool)
    mask[a[over]] = True
    mask &= patches.areas > min_area
    return mask
