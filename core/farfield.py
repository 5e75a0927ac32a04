"""The patches a mesh gather draws: the lit ones only, and far ones whole.

:func:`seen_subset` keeps the patches that have light (a dark site plane costs no hemicube
pixels); :class:`FarField` draws a solved patch whole where it lies far from every point of a
gather batch and spreads its form factor over its receiver elements.
"""

import numpy as np

from .geometry import patch_extents
from .hemicube import point_rows

#: A gather batch draws a solved patch whole, instead of its receiver elements, when it lies
#: farther than this many times its size from every point of the batch: there it covers a few
#: hemicube pixels, and its form factor is spread over its elements by area (exact for the
#: gathered light when the form-factor kernel is flat across the patch; the kernel varies by
#: (1 + 1/FAR_FIELD)^2 across it at worst).
FAR_FIELD = 4.0

class Seen:
    """The patches a gather draws (what :func:`core.hemicube.point_rows` reads), a subset."""

    def __init__(self, patches, keep):
        self.keep = keep
        self.centres = patches.centres[keep]
        self.normals = patches.normals[keep]
        self.corners = patches.corners[keep]
        self.areas = patches.areas[keep]

    def radiance(self, node_radiance):
        """(2K, 3) radiance of the kept nodes from the full (2P, 3)."""
        P = node_radiance.shape[0] // 2
        return np.concatenate([node_radiance[self.keep], node_radiance[P + self.keep]])


class Drawn:
    """A Patches-like concatenation of whole patches and elements (what one batch draws)."""

    def __init__(self, *parts):
        self.centres = np.concatenate([p.centres for p in parts])
        self.normals = np.concatenate([p.normals for p in parts])
        self.corners = np.concatenate([p.corners for p in parts])
        self.areas = np.concatenate([p.areas for p in parts])


class FarField:
    """Gather rows with far patches drawn whole (:data:`FAR_FIELD`), returned against the seen
    elements' columns.

    Parameters
    ----------
    patches : core.patches.Patches
        The solved patches (P).
    seen : Seen
        The drawn elements (K of them, a subset of the receiver elements).
    parent : (K,) int64
        Patch of each seen element.
    """

    def __init__(self, patches, seen, parent):
        self.patches, self.seen, self.parent = patches, seen, parent
        P = patches.areas.size
        self.has = np.zeros(P, dtype=bool)
        self.has[parent] = True
        self.weight = seen.areas / patches.areas[parent]
        self.radius, self.size = patch_extents(patches.corners, patches.centres)
        self.drawn_items = 0
        self._last = None                      # (far mask, Drawn) of the last batch

    def rows(self, points, normals, **kw):
        """(S, 2K) rows of ``points`` against the seen elements' nodes (with ``later=True``, a
        :class:`core.parallel.Deferred` of them)."""
        lo, hi = points.min(axis=0), points.max(axis=0)
        centres = self.patches.centres
        gap = np.linalg.norm(centres - np.clip(centres, lo, hi), axis=1) - self.radius
        far = self.has & (gap > FAR_FIELD * self.size)
        if not far.any():
            self.drawn_items += self.parent.size
            return point_rows(self.seen, points, normals, **kw)
        whole = np.flatnonzero(far)
        near = np.flatnonzero(~far[self.parent])
        if self._last is None or not np.array_equal(self._last[0], far):
            # Neighbouring batches (Z order) mostly share their far set: one object for them
            # keeps point_rows' set-up cache (by identity) warm.
            self._last = (far, Drawn(Seen(self.patches, whole), Seen(self.seen, near)))
        drawn = self._last[1]
        self.drawn_items += whole.size + near.size
        mixed = point_rows(drawn, points, normals, **kw)            # (S, 2D)
        weight = self.weight
        if kw.get("later"):
            return mixed.then(lambda m: _unmix(m, far, whole, near, self.parent, weight))
        return _unmix(mixed, far, whole, near, self.parent, weight)


def _unmix(mixed, far, whole, near, parent, weight):
    """:meth:`FarField.rows` from the rows of its mixed drawing: a far patch's columns spread
    over its elements by their weights."""
    D, K, W = whole.size + near.size, parent.size, whole.size
    out = np.zeros((mixed.shape[0], 2 * K))
    out[:, near] = mixed[:, W:D]
    out[:, K + near] = mixed[:, D + W:]
    slot = np.full(far.size, -1, dtype=np.int64)
    slot[whole] = np.arange(W)
    child = np.flatnonzero(far[parent])
    col = slot[parent[child]]
    out[:, child] = mixed[:, col] * weight[child]
    out[:, K + child] = mixed[:, D + col] * weight[child]
    return out


def seen_subset(patches, radiance, power):
    """The patches the gathers draw: those whose front or back node has light.

    A patch that light never reaches on either side cannot stand between a lit point and a lit
    patch (the lit patch would light it), so leaving it out changes no row that matters, and
    a 100 x 100 m ground plane outside a closed room no longer slows every hemicube.
    """
    P = patches.areas.size
    has = np.any(radiance[:P] > 0, axis=1) | np.any(radiance[P:] > 0, axis=1) \
        | np.any(power[:P] > 0, axis=1) | np.any(power[P:] > 0, axis=1)
    return Seen(patches, np.flatnonzero(has))
