"""Receiver elements: patches split where the solved light changes, for the final gather to see.

The final gather (:mod:`core.gather`) reads each patch's solved radiance as constant over the
patch. Where the light changes steeply across a patch, and the gather point sees only part of it,
that mean is wrong for the part it sees. The typical case: a ceiling patch half over a luminaire
panel hung below the ceiling. Its hidden half, over the panel, is bright, and its visible half is
dark, so the floor sees the patch's mean, which is several times too bright. In the office sample
this made the floor 4 % too bright against both Cycles and Radiance.

Remedy (substructuring, Cohen, Greenberg, Immel & Brock 1986): after the solve, patches whose
light differs from a smooth neighbour's by more than a threshold (:func:`core.refine.refine_mask`)
are split into elements, ``levels`` times (and once more, at a lower threshold, next to
other surfaces: ``near_threshold``). Each new element gets its own radiance, one bounce
gathered at its centre from the solved patches:
``L_e = Le + rho * sum_j F(e -> j) L_j``. F comes from a hemicube at a point, so there is no
proximity error. The vertex gather then sees the elements. The solve keeps the coarse patches,
which carry the energy correctly in aggregate. Only the receivers are refined: a re-solve is not
needed, and each level costs one hemicube per new element.
"""

import numpy as np

from .criteria import near_surfaces
from .farfield import FarField, Seen
from .geometry import spatial_order
from .gather import shade
from .hemicube import point_rows
from .parallel import ahead
from .patches import subdivide_patches
from .refine import lit_mean, refine_mask
from .rows import RowStore, compact_rows

#: Gathered elements next to another surface out of their plane (:func:`near_surfaces`) are
#: gathered once more against the elements themselves, and that gather is swept this many times
#: (Jacobi, on the kept rows): their one-bounce gather from the solved patches reads the coarse
#: patches' means, which next to a concave corner are much brighter than the light there (the
#: light dips steeply into a room's corner). Coarse Cornell box, the ceiling element at a top
#: corner: 0.157 from the patches, 0.131 / 0.125 / 0.123 / 0.123 over four sweeps. Its cost
#: grows with furniture: in bench/bench_scaling.py's rooms 75 % of the gathered elements are
#: near, each such hemicube draws the whole room, and a bake takes twice as long (README,
#: "Scaling, measured again on 2026-12-07"). The last round's new near elements are not
#: gathered over the solved patches first (:attr:`Elements.late`): that gather only started
#: their sweeps, and the Cornell box's error over 12 seeds is the same without it (1.465 %
#: against 1.468 %; docs/benchmark.md).
NEAR_SWEEPS = 3


class Elements:
    """Receiver elements of a bake and what re-lighting needs to recompute their radiance.

    Attributes
    ----------
    patches : core.patches.Patches
        The ``E`` elements (a Patches object: split patches replaced by their children).
    parent : (E,) int64
        Solved patch each element lies in.
    computed : (K,) int64
        Element nodes (front e, back e + E) whose radiance was gathered at their centre (the
        rest copy their patch's side).
    rows : core.rows.RowStore
        Point-to-node form factors (against the solved patches' 2P nodes) of ``computed``, in
        that order; a half store (:data:`core.rows.HALF_SHIFT`), as is ``near_rows``.
    levels : list of dict
        Per level: ``split`` (patches or elements split) and ``elements`` (count after it).
    direct : (K, 3) float64 or None
        Light from beyond the hemicube's surfaces (irradiance / pi,
        :meth:`core.lights.DirectLight.extra`: the lights' direct light and the world's
        share) at the centres of ``computed``.
    near : (N,) int64 or None
        Positions in ``computed`` of the nodes next to another surface, gathered again
        against the elements (:data:`NEAR_SWEEPS`).
    near_rows : core.rows.RowStore or None
        Their point-to-node form factors, in ``near``'s order, against the columns of
        ``far_field`` (every element, far patches drawn whole).
    far_field : core.farfield.FarField or None
    late : (K,) bool or None
        The ``computed`` nodes with no row in :attr:`rows`: the last round's new elements next
        to another surface, gathered only against the elements (their gather over the solved
        patches would only start the sweeps); they start from their patch's radiance.
    """

    late = None                      # kept bakes pickled before it: every node gathered first

    def __init__(self, patches, parent, computed, rows, levels, direct=None, near=None,
                 near_rows=None, far_field=None, late=None):
        self.patches, self.parent, self.computed = patches, parent, computed
        self.rows, self.levels, self.direct = rows, levels, direct
        self.near, self.near_rows, self.far_field = near, near_rows, far_field
        self.late = late

    def points(self):
        """(K, 3) centres and (K, 3) normals of the ``computed`` nodes, each facing the side it
        gathered on (where :attr:`direct` was taken)."""
        E = self.parent.size
        ids = self.computed % E
        sign = np.where(self.computed >= E, -1.0, 1.0)[:, None]
        return self.patches.centres[ids], sign * self.patches.normals[ids]

    def with_direct(self, direct):
        """These elements with ``direct`` (K, 3) in place of :attr:`direct`."""
        return Elements(self.patches, self.parent, self.computed, self.rows, self.levels, direct,
                        self.near, self.near_rows, self.far_field, self.late)

    def node_radiance(self, scene, node_radiance):
        """Radiance of the elements' 2E nodes from the solved patches' (2P, 3) node radiance.

        Gathered for the ``computed`` nodes (but :attr:`late`), the patch's own side's value
        for the others; the ``near`` nodes then gathered from the elements,
        :data:`NEAR_SWEEPS` times.
        """
        L = np.asarray(node_radiance, dtype=np.float64)
        P = L.shape[0] // 2
        E = self.parent.size
        out = np.empty((2 * E, 3))
        out[:E] = L[self.parent]
        out[E:] = L[P + self.parent]
        if self.computed.size:
            incident = self.rows.incident(L)
            if self.direct is not None:
                incident = incident + self.direct
            first = slice(None) if self.late is None else ~self.late
            node = self.computed[first]
            out[node] = shade_side(scene, self.patches.material[node % E], node >= E,
                                   incident[first])
        if self.near is not None and self.near.size:
            node = self.computed[self.near]
            extra = 0.0 if self.direct is None else self.direct[self.near]
            material, back = self.patches.material[node % E], node >= E
            for _ in range(NEAR_SWEEPS):
                incident = self.near_rows.incident(self.far_field.radiance(out))
                out[node] = shade_side(scene, material, back, incident + extra)
        return out


def shade_side(scene, material, back, incident):
    """:func:`core.gather.shade` on either side: ``back`` (n,) bool takes the back materials."""
    back_rho, back_le = (np.asarray(a, dtype=np.float64) for a in scene.back_materials())
    front = shade(scene, material, incident)
    return np.where(np.asarray(back)[:, None], back_le[material] + back_rho[material] * incident,
                    front)


def _survivors(mask, parent):
    """Index in the split set of every unsplit old item (-1 for split ones): (P_old,) int64."""
    new_index = np.full(mask.size, -1, dtype=np.int64)
    kept = np.flatnonzero(~mask[parent])
    new_index[parent[kept]] = kept
    return new_index


def make_elements(scene, patches, node_radiance, *, levels, threshold, crease_angle,
                  resolution=64, rotate=True, rng=None, monitor=None, batch=64, direct=None,
                  near_threshold=None):
    """Split the solved patches where their light changes and gather the elements' radiance.

    Parameters
    ----------
    scene : core.scene.Scene
    patches : core.patches.Patches
        The solved patches (``P``), made by :func:`core.patches.make_patches`.
    node_radiance : (2P, 3) float
        Solved radiance of every node.
    levels : int
        Splitting rounds, >= 0. Each round splits in four every element whose light differs
        from a smooth neighbour's by more than ``threshold``. Elements are never smaller than
        1/4^levels of their patch.
    threshold : float
        Relative luminance difference, in (0, 1) (:func:`core.refine.refine_mask`).
    crease_angle : float
        Degrees: neighbours across a sharper crease are not compared.
    resolution, rotate, rng
        Hemicube settings of the element gathers (:func:`core.hemicube.point_rows`).
    monitor : core.progress.Monitor, optional
        Progress (over the levels) and cancel.
    batch : int
        Elements per hemicube call.
    direct : core.lights.DirectLight, optional
        The point, spot and sun lights: their direct light is added at the element centres.
    near_threshold : float, optional
        Elements near another surface out of their plane (:func:`core.criteria.near_surfaces`:
        a wall under the ceiling, a floor under furniture) are also split where their light
        differs from a neighbour's by more than this, in every round and in one more round
        after ``levels``: a point gathering next to such an element sees its near part under
        a large solid angle, so the element's mean is wrong there (the office's ceiling along
        the walls read 6 % too bright against Cycles, the wall's top strip being darker than
        its patch).

    Returns
    -------
    Elements
    """
    L = np.asarray(node_radiance, dtype=np.float64)
    P = patches.areas.size
    if L.shape != (2 * P, 3):
        raise ValueError(f"node_radiance must have shape (2P, 3) = ({2 * P}, 3); got {L.shape}")
    if not isinstance(levels, (int, np.integer)) or levels < 0:
        raise ValueError(f"levels must be an int >= 0; got {levels!r}")
    if near_threshold is not None and not 0 < near_threshold < 1:
        raise ValueError(f"near_threshold must be in (0, 1) or None; got {near_threshold!r}")
    # Both sides: a face whose room side is its back (flipped normals, core.orient) or a
    # partition lit on both sides is split where its lit side's light changes. One dark floor
    # for both (the brighter side's mean), so a flipped room splits as the room as modelled.
    side_le = (np.asarray(scene.emission), np.asarray(scene.back_materials()[1]))
    elements = patches
    parent = np.arange(P, dtype=np.int64)          # solved patch of every element
    seen = [L[:P].copy(), L[P:].copy()]            # current radiance of each side of every element
    emits = [np.any(le[patches.material] > 0, axis=1) for le in side_le]
    mean = max(lit_mean(patches, seen[s], emits[s]) for s in (0, 1))
    kept = []                                      # (element ids, side, cols, vals, direct)
    steps = []
    rounds = levels + (near_threshold is not None and levels > 0)
    final_near = None                       # near_surfaces of the final elements, when known
    shares = rounds + (near_threshold is not None)         # the last: the near gather again
    for level in range(rounds):
        emitting = [np.any(side_le[s][elements.material] > 0, axis=1) for s in (0, 1)]
        near = None if near_threshold is None else near_surfaces(elements)
        masks = []
        for s in (0, 1):
            m = np.zeros(elements.areas.size, dtype=bool)
            if level < levels:              # the general step (the last round is near only)
                m = refine_mask(elements, seen[s], emitting[s], threshold=threshold,
                                crease_angle=crease_angle, mean=mean)
            if near is not None:
                m |= near & refine_mask(elements, seen[s], emitting[s], threshold=near_threshold,
                                        crease_angle=crease_angle, mean=mean)
            masks.append(m)
        mask = masks[0] | masks[1]
        if not mask.any():
            break
        elements, split_parent = subdivide_patches(elements, mask)
        last = level == rounds - 1 and level == levels      # the near-only round
        final_near = near_surfaces(elements) if last else None
        remap = _survivors(mask, split_parent)
        remapped = []
        for ids, side, cols, vals, dl in kept:    # per batch of rows, not per element
            ids = remap[ids]
            ok = ids >= 0
            remapped.append((ids[ok], side, cols, vals[ok], dl[ok]))
        kept = remapped
        parent = parent[split_parent]
        seen = [v[split_parent] for v in seen]
        new = np.flatnonzero(mask[split_parent])
        steps.append(dict(split=int(mask.sum()), elements=int(parent.size)))
        todo = [(s, new[masks[s][split_parent[new]]]) for s in (0, 1)]
        if last:
            # Its new elements next to another surface are gathered against the elements
            # (_near_rows); a gather over the solved patches would only start their sweeps.
            for s, t in todo:
                late = t[final_near[t]]
                if late.size:
                    kept.append((late, s, None, None, np.zeros((late.size, 3))))
            todo = [(s, t[~final_near[t]]) for s, t in todo]
        total = max(sum(t.size for _, t in todo), 1)
        done = 0
        sky = None if direct is None else direct.sky
        jobs = [(side, t[b:b + batch]) for side, t in todo for b in range(0, t.size, batch)]

        def begin(job):
            side, ids = job
            normals = (-1.0 if side else 1.0) * elements.normals[ids]
            light = None if sky is None else np.zeros((ids.size, 3))
            rows = point_rows(patches, elements.centres[ids], normals, resolution=resolution,
                              rotate=rotate, rng=rng, sky=sky, sky_out=light, later=True)
            return normals, light, rows

        # Batches start ahead of their use (core.parallel.ahead); none depends on another's
        # result: the rows are against the solved patches.
        for (side, ids), (normals, light, rows) in ahead(jobs, begin):
            rows = rows.result()
            cols, vals = compact_rows(rows)
            dl = np.zeros((ids.size, 3)) if direct is None else \
                direct.extra(elements.centres[ids], normals, rows.sum(axis=1), sky=light)
            kept.append((ids, side, cols, vals, dl))
            seen[side][ids] = shade_side(scene, elements.material[ids],
                                         np.full(ids.size, bool(side)),
                                         vals.astype(np.float64) @ L[cols] + dl)
            done += ids.size
            if monitor is not None:
                monitor.update((level + done / total) / shares,
                               f"elements: level {level + 1}, {parent.size} elements")
    # Rows kept in the order of ``computed`` (the store's row keys are positions in it).
    E = parent.size
    computed = np.concatenate([k[0] + k[1] * E for k in kept]) if kept else np.zeros(0, np.int64)
    store = RowStore(computed.size, 2 * P, half=True)
    start = 0
    for ids, _, cols, vals, _ in kept:
        if cols is not None:
            store.add_compact(np.arange(start, start + ids.size), cols, vals)
        start += ids.size
    late = np.concatenate([np.full(k[0].size, k[2] is None) for k in kept]) if kept else None
    at_centres = None
    if direct is not None:
        at_centres = np.concatenate([k[4] for k in kept]) if kept else np.zeros((0, 3))
    out = Elements(elements, parent, computed, store, steps, at_centres,
                   late=late if late is not None and late.any() else None)
    if near_threshold is not None and computed.size:
        out.far_field = FarField(patches, Seen(elements, np.arange(parent.size)), parent)
        out.near, out.near_rows = _near_rows(out, resolution=resolution, rotate=rotate, rng=rng,
                                             batch=batch, monitor=monitor, start=rounds / shares,
                                             direct=direct, near_mask=final_near)
    return out


def _near_rows(el, *, resolution, rotate, rng, batch, monitor, start, direct=None,
               near_mask=None):
    """Positions in ``el.computed`` of its nodes next to another surface (in Z order), and their
    rows against ``el.far_field``'s columns (a RowStore keyed by position in that list);
    progress from ``start`` to 1. The :attr:`Elements.late` nodes' :attr:`Elements.direct` is
    taken here, with these rows' sums (and sky). ``near_mask``: :func:`near_surfaces` of
    ``el.patches`` when the caller has it (the last round's)."""
    centres, normals = el.points()
    if near_mask is None:
        near_mask = near_surfaces(el.patches)
    near = np.flatnonzero(near_mask[el.computed % el.parent.size])
    near = near[spatial_order(centres[near])]
    late = np.zeros(el.computed.size, dtype=bool) if el.late is None else el.late
    sky = None if direct is None else direct.sky
    far_field = el.far_field
    store = RowStore(near.size, far_field.n_cols, half=True)
    jobs = [np.arange(b, min(b + batch, near.size)) for b in range(0, near.size, batch)]

    def begin(keys):
        wanted = sky is not None and late[near[keys]].any()     # only the late need the sky
        light = np.zeros((keys.size, 3)) if wanted else None
        rows = far_field.rows(centres[near[keys]], normals[near[keys]], compact=True,
                              resolution=resolution, rotate=rotate, rng=rng, later=True,
                              sky=sky if wanted else None, sky_out=light)
        return light, rows

    for keys, (light, job) in ahead(jobs, begin):
        cols, vals, sums = job.result()
        store.add_compact(keys, cols, vals, sums)
        at = late[near[keys]]
        if direct is not None and at.any():
            pos = near[keys][at]
            el.direct[pos] = direct.extra(centres[pos], normals[pos], sums[at],
                                          sky=None if light is None else light[at])
        if monitor is not None:
            monitor.update(start + (1 - start) * (keys[-1] + 1) / near.size,
                           f"elements: {near.size} next to other surfaces, gathered again")
    far_field.release()
    return near, store


def bake_elements(scene, patches, node_radiance, settings, monitor=None, direct=None):
    """:func:`make_elements` with a bake's settings (``element_levels``, ``element_threshold``,
    ``element_near_threshold`` (0: None), ``crease_angle``, hemicube settings, the seed's
    element stream); None when levels are 0."""
    if not settings.element_levels:
        return None
    return make_elements(scene, patches, node_radiance, levels=settings.element_levels,
                         threshold=settings.element_threshold,
                         crease_angle=settings.crease_angle, resolution=settings.resolution,
                         rotate=settings.rotate_hemicube,
                         rng=np.random.default_rng([settings.seed, 3]), monitor=monitor,
                         direct=direct,
                         near_threshold=settings.element_near_threshold or None)
