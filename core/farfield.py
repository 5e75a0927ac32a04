"""The patches a mesh gather draws: the lit ones only, and far ones whole.

:func:`seen_subset` keeps the patches that have light (a dark site plane costs no hemicube
pixels); :class:`FarField` draws a solved patch whole where it lies far from every point of a
gather batch and spreads its form factor over its receiver elements.
"""

import numpy as np

from .geometry import patch_extents
from .hemicube import draw_polygons, point_rows
from .hemicube_chunk import Geometry
from .rows import compact_rows

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
    """A Patches-like concatenation of whole patches and elements (what one batch draws).

    ``drawing``: its (polygons, poly_patch, Geometry) made already (:class:`Union`), which
    :func:`core.hemicube.drawn_polygons` then takes as they are; None: drawn when asked.
    """

    def __init__(self, *parts, drawing=None):
        self.centres = np.concatenate([p.centres for p in parts])
        self.normals = np.concatenate([p.normals for p in parts])
        self.corners = np.concatenate([p.corners for p in parts])
        self.areas = np.concatenate([p.areas for p in parts])
        self.drawing = drawing


class Union:
    """Every solved patch with seen elements drawn whole, then every seen element: drawn once
    (:func:`core.hemicube.draw_polygons` and its :class:`core.hemicube_chunk.Geometry`), so that
    a batch's mix of far patches and near elements is cut out of it instead of drawn anew.

    The cut is what drawing the mix gives, array for array: a polygon and its plane depend on
    its item alone; the items keep their order (whole patches, then elements, each ascending),
    so the polygons do (a quad drawn whole before every triangle); the shared corners are the
    union's, sorted as the mix's own would be. The office sample draws 383 mixes per bake
    (README, Performance: "A batch's far-field mix is cut, not drawn").
    """

    def __init__(self, patches, has, seen):
        self.patch_ids = np.flatnonzero(has)
        self.slot = np.full(has.size, -1, dtype=np.int64)
        self.slot[self.patch_ids] = np.arange(self.patch_ids.size)
        whole = Drawn(Seen(patches, self.patch_ids), seen)
        polys, poly_patch = draw_polygons(whole)
        self.geometry = Geometry(polys, poly_patch, whole.normals)
        self.n_items = self.patch_ids.size + seen.areas.size

    def cut(self, whole, near):
        """(polygons, poly_patch, Geometry) of the mix of patches ``whole`` and elements
        ``near`` (both ascending), numbered as the mix numbers them. The polygons' corners are
        not kept (None): the hemicube reads the Geometry."""
        items = np.concatenate([self.slot[whole], self.patch_ids.size + near])
        local = np.full(self.n_items, -1, dtype=np.int64)
        local[items] = np.arange(items.size)
        item = self.geometry.poly_patch
        sel = np.flatnonzero(local[item] >= 0)
        g = self.geometry.cut(sel, local[item[sel]])
        return None, g.poly_patch, g


class FarField:
    """Gather rows with far patches drawn whole (:data:`FAR_FIELD`).

    Dense rows (``compact=False``) are against the seen elements' 2K nodes, a far patch's form
    factor spread over its elements by area. Compact rows (what the mesh stage keeps) are
    against :attr:`n_cols` = 2K + 2P columns instead: the 2K element nodes, then the solved
    patches' 2P nodes, a far patch's form factor in its own column, read against the area
    mean of its seen elements' radiance (:meth:`radiance`). The light gathered is the same
    (``sum_e F w_e L_e = F sum_e w_e L_e``), but a far patch costs one column, not one per
    element: with near receiver elements a gather batch's rows otherwise hold every element of
    every patch it sees from afar.

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
        # What a far patch's column covers of it: its seen elements' share of its area.
        self.cover = np.bincount(parent, weights=self.weight, minlength=P)
        self.radius, self.size = patch_extents(patches.corners, patches.centres)
        self.n_cols = 2 * parent.size + 2 * P
        self.drawn_items = 0
        self._last = None                      # (far mask, Drawn) of the last batch
        self._union = None                     # Union: made at the first batch with far ones

    def radiance(self, seen_radiance):
        """(n_cols, 3) radiance the compact rows read: the seen elements' (2K, 3), then every
        solved patch's area mean of its seen elements' (front nodes, then back nodes)."""
        L = np.asarray(seen_radiance, dtype=np.float64)
        K, P = self.parent.size, self.patches.areas.size
        out = np.zeros((self.n_cols, 3))
        out[:2 * K] = L
        w = self.weight[:, None]
        np.add.at(out, 2 * K + self.parent, w * L[:K])
        np.add.at(out, 2 * K + P + self.parent, w * L[K:])
        return out

    def release(self):
        """Drop the drawings (the last batch's and the union); the rows' reading stays
        usable."""
        self._last = self._union = None

    def rows(self, points, normals, compact=False, **kw):
        """Rows of ``points``: dense (S, 2K) against the seen elements' nodes, or with
        ``compact=True`` the (cols, vals, row sums) of :func:`compact_with_sums` against the
        :attr:`n_cols` columns (made without dense rows); with ``later=True``, a
        :class:`core.parallel.Deferred` of them."""
        lo, hi = points.min(axis=0), points.max(axis=0)
        centres = self.patches.centres
        d = centres - np.clip(centres, lo, hi)
        gap = np.sqrt(np.einsum("ij,ij->i", d, d)) - self.radius
        far = self.has & (gap > FAR_FIELD * self.size)
        if not far.any():
            self.drawn_items += self.parent.size
            rows = point_rows(self.seen, points, normals, **kw)
            if not compact:
                return rows
            return rows.then(compact_with_sums) if kw.get("later") else compact_with_sums(rows)
        whole = np.flatnonzero(far)
        near = np.flatnonzero(~far[self.parent])
        if self._last is None or not np.array_equal(self._last[0], far):
            # Neighbouring batches (Z order) mostly share their far set: one object for them
            # keeps the workers' copy of its polygons (by identity) warm.
            if self._union is None:
                self._union = Union(self.patches, self.has, self.seen)
            self._last = (far, Drawn(Seen(self.patches, whole), Seen(self.seen, near),
                                     drawing=self._union.cut(whole, near)))
        drawn = self._last[1]
        self.drawn_items += whole.size + near.size
        mixed = point_rows(drawn, points, normals, **kw)            # (S, 2D)
        if compact:
            unmix = _unmix_compact
            args = (whole, near, self.parent.size, self.patches.areas.size, self.cover)
        else:
            unmix = _unmix
            args = (far, whole, near, self.parent, self.weight)
        if kw.get("later"):
            return mixed.then(lambda m: unmix(m, *args))
        return unmix(mixed, *args)


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


def compact_with_sums(rows):
    """(cols, vals, row sums) of dense ``rows``: :func:`core.rows.compact_rows` and what each
    row sees in all (summed over the hit columns)."""
    cols, vals = compact_rows(rows)
    return cols, vals, rows[:, cols].sum(axis=1)


def _unmix_compact(mixed, whole, near, K, P, cover):
    """(cols, vals, row sums) of the mixed rows against :attr:`FarField.n_cols` columns: a near
    element's column is its node (e, or K + e on the back), a far patch's is 2K + p (2K + P + p
    on the back); the row sums count a far patch's form factor times the share of it its seen
    elements cover (what the element-space rows summed)."""
    D, W = whole.size + near.size, whole.size
    hit = np.flatnonzero(np.any(mixed > 0, axis=0))             # mixed columns, both sides
    back = hit >= D
    j = hit - D * back                                           # index in [0, D)
    is_near = j >= W
    cols = np.empty(hit.size, dtype=np.int64)
    scale = np.ones(hit.size)
    cols[is_near] = near[j[is_near] - W] + K * back[is_near]
    far_patch = whole[j[~is_near]]
    cols[~is_near] = 2 * K + far_patch + P * back[~is_near]
    scale[~is_near] = cover[far_patch]
    order = np.argsort(cols, kind="stable")
    values = mixed[:, hit[order]]
    return cols[order], values.astype(np.float32), values @ scale[order]


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
