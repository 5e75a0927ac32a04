"""Delta form factors of the hemicube's pixels (Cohen & Greenberg 1985).

A hemicube has a top face of R x R pixels and four side faces of R x R/2 pixels around an eye at
a patch centre (half-width 1). Each pixel's delta form factor is the fraction of the eye's
cosine-weighted view it covers; :mod:`core.hemicube_raster` credits it to the nearest polygon.
"""

import numpy as np

from .constants import MAX_RESOLUTION

#: Face names in pixel-buffer order: the top face, then the sides along +x, -x, +y, -y of the
#: eye frame (x, y tangent, z the viewing normal).
FACE_NAMES = ("top", "+x", "-x", "+y", "-y")

#: Largest resolution (see core.constants).
_MAX_RESOLUTION = MAX_RESOLUTION



def check_resolution(resolution):
    if isinstance(resolution, (bool, np.bool_)) or not isinstance(resolution, (int, np.integer)):
        raise TypeError(f"resolution must be an int; got {type(resolution).__name__}")
    if resolution < 2 or resolution % 2:
        raise ValueError(f"resolution must be an even int >= 2; got {resolution}")
    if resolution > _MAX_RESOLUTION:
        raise ValueError(f"resolution must be at most {_MAX_RESOLUTION}; got {resolution}")
    return int(resolution)


def _raw_delta_form_factors(resolution):
    """Unnormalised delta form factors: (top (R, R), side (R/2, R)), float64."""
    r = resolution
    h = 2.0 / r
    u = -1.0 + h * (np.arange(r) + 0.5)            # column centres, shared by every face
    v_side = h * (np.arange(r // 2) + 0.5)         # row centres of a side face (height above
    da = h * h                                     # the source plane)
    top = da / (np.pi * (u[:, None] ** 2 + u[None, :] ** 2 + 1.0) ** 2)
    side = v_side[:, None] * da / (np.pi * (u[None, :] ** 2 + v_side[:, None] ** 2 + 1.0) ** 2)
    return top, side


def delta_form_factors(resolution, *, normalised=True):
    """Delta form factors of the hemicube pixels (Cohen & Greenberg 1985).

    Top face pixel at (x, y): ``dF = dA / (pi (x^2 + y^2 + 1)^2)``; side face pixel at (y, z):
    ``dF = z dA / (pi (y^2 + z^2 + 1)^2)``, with ``dA = (2/R)^2`` (half-width 1).

    Parameters
    ----------
    resolution : int
        R, even, >= 2: the top face has R x R pixels, each side R/2 x R.
    normalised : bool, optional
        If True (default) all pixels are scaled so that they sum to exactly 1; the raw midpoint
        sums exceed 1 by about 0.54 / R^2.

    Returns
    -------
    dict of str -> ndarray
        ``'top'``: (R, R) indexed [row (y), column (x)]; ``'+x'``, ``'-x'``, ``'+y'``, ``'-y'``:
        (R/2, R) indexed [row (height z, 0 at the horizon), column], float64.
    """
    r = check_resolution(resolution)
    top, side = _raw_delta_form_factors(r)
    scale = 1.0 / (top.sum() + 4.0 * side.sum()) if normalised else 1.0
    out = {"top": top * scale}
    for name in FACE_NAMES[1:]:
        out[name] = side * scale
    return out


def flat_delta_form_factors(resolution):
    """Normalised delta form factors in pixel-buffer order: (3 R^2,) float64."""
    d = delta_form_factors(resolution)
    return np.concatenate([d[name].ravel() for name in FACE_NAMES])


# --------------------------------------------------------------------------------------------
# Input handling
# --------------------------------------------------------------------------------------------
