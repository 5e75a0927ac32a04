"""Emissive faces as area lights: their direct light computed exactly at points (issue 11).

A hemicube sees an emitter as the pixels it covers. A source smaller than a pixel is hit by a
few gather points and missed by the rest (a 1 cm^2 lamp 3 m above a floor: every floor vertex
read 0), and one a few pixels wide aliases (a 0.3 m panel at 3 m: -25 % to +52 % against the
exact values, only 41 % of the floor within 5 %). Here each emissive face lights a point ``x``
as :mod:`core.lights` lights do::

    E(x) / pi = Le x F(x -> face) x V(x)

``F`` is the contour integral (:func:`core.exact.point_polygon_form_factor`): exact for the whole
face, any size, however near, clipped to ``x``'s horizon. ``V`` is the visible fraction from
shadow rays to points on the face, each weighted by the point-to-area kernel
``cos_x cos_y / r^2`` (a fraction of the form factor, not of the area; Wallace, Elmquist & Haines
1989): first one ray to the face's anchor and one to each of its corners (``RIM``); where all
of them are blocked the face is hidden (a lamp in the next room), else ``FIRST_ROUND`` rays
more and, where they disagree (a penumbra), ``samples`` more. A face narrower than
``min_size`` casts no more where the anchor's and the corners' rays are all clear. The samples
are a rank-1 lattice on the face's patches turned per point (Cranley-Patterson), so
neighbouring points do not share one pattern.

The solve and the gathers then carry only what the emitters *reflect*: their emission enters as
the first bounce, like a point light's (:class:`core.pipeline.Nodes`, ``exact``).

A lamp of several faces (a bulb modelled as a sphere, a meshed panel: faces of one material
that share vertices) is one light, its faces' light summed and one visible fraction for them
all (:mod:`core.lamps`).

Which emitters (``exact_direct``): 'auto' the emissive materials too narrow for the hemicube
(``AUTO_PIXELS``), 'all' every one; in either case fewest faces first, while the lamps taken stay
within ``MAX_LAMPS``, their faces within ``MAX_FACES`` and their area within ``MAX_AREA_SHARE``
of the scene's (a luminous ceiling is left to the hemicube, which sees a large source well; the
shadow rays' cost grows with points x lamps, the unshadowed light's with points x faces).
"""

import copy

import numpy as np

from .exact import bilinear, gauss_square, pair_form_factor
from .lamps import _ALPHA, _ROOT, Lamp, centroids, form_factors, lamp_labels, lamp_reach, \
    lamp_widths
from .progress import checkpoint
from .shadow_memo import PointTable, point_keys
from .transfer import padded_polygons

#: Lamps (lights) lit exactly at most (by material, fewest faces first): one (point, lamp) pair
#: costs FIRST_ROUND + 1 shadow rays and the rim's where the lamp gives more than the culled
#: share (core.lights.CULL).
MAX_LAMPS = 64

#: Emissive faces lit exactly at most: one (point, face) pair costs the contour integral
#: (~1.3 us) near the face, the point-to-area kernel beyond core.lamps.FAR of its diameters.
#: A lamp's own patches are near all its faces, so a closed lamp of n faces costs about n^2
#: integrals for the light inside it (bench/bench_bulb.py, a 5 cm sphere in a 4 m room: 512
#: faces 11.4 s, the hemicube 12.1 s; 2,048 faces 106 s, the hemicube 30 s; under a profiler
#: 77 s of 119 s were the faces' integrals).
#: A UV sphere of Blender's default 32 x 16 has 512 faces, one subdivided once 2,048.
MAX_FACES = 1024

#: Emissive area lit exactly at most, as a share of all the surfaces' area. A lamp is small
#: against its room; a luminous ceiling or a furnace (every wall emits) is an extended source
#: that the hemicube sees well, while the visible fraction of a large face that furniture hides
#: in part needs many shadow rays (a furnace office with every face emitting: up to 12 % off
#: with the first round's rays; mostly the rows' disagreement with the exact light, README
#: "Why that furnace fails").
MAX_AREA_SHARE = 0.1

#: 'auto' lights exactly the emitters narrower than this many hemicube pixels, seen from the
#: surfaces they light: a pixel at the hemicube's centre spans 2/R radians, and a lamp of width
#: w at the typical distance d of what it faces (:func:`lamp_reach`) spans w/d, so it covers
#: w R / (2 d) pixels. A 1 cm^2 lamp 2.95 m over a floor (0.1 px at R = 64) is missed by most
#: gathers; wider ones alias: in a black 4 m room (bench.stability.scenes.emitter_room) the
#: hemicube's mean error at the floor's vertices is 7.8 % at 0.3 m (3.3 px; worst vertex 52 %),
#: 2.7 % at 0.6 m (6.5 px), 1.0 % at 1 m (10.8 px), where the exact light reads 0.005 %; in lit
#: rooms the interreflection averages it out. Taking every lamp of the three samples (tried
#: 2026-12-05) read the Cornell box 1.31 -> 1.18 %, the office 2.65 -> 2.58 % but took 44 ->
#: 56 s, the apartment 3.06 -> 3.12 % and 86 -> 121 s, and the office furnace of
#: tests/core/test_stability.py read up to 1.1 % high (patches beside its 0.6 m panel, whose
#: rows disagree with their exact light: README, "Why that furnace fails"): no lamp as wide as
#: theirs (6.1 to 8.4 px). Under about 4 px the hemicube misses the 5 % goal on the direct
#: light (4.4 % at 4.3 px; at 3.3 px 7.8 % and 6,461 vertices in 3.3 s, exact: 120 in 0.9 s;
#: README "At 4 pixels"): a 20 to 30 cm downlight under a 3 m ceiling. So 4 (2 before).
AUTO_PIXELS = 4.0

#: Shadow rays per (point, emitter) in the first round, cast where the anchor's or a rim ray
#: is clear; where they, the anchor's and the rim's all agree, no more are cast. Where the
#: anchor's and the rim's rays are all blocked, none are: the apartment sample (six lamps in
#: five rooms, all lit exactly) 132 -> 124 s at the same error (2026-12-05); a lamp seen only
#: through a gap that misses its anchor and its corners reads 0 (before, 8 lattice rays might
#: find it; tests/core/test_emitters.py).
FIRST_ROUND = 8

#: The first round also casts one ray to each corner of the face (at most ``RIM_CORNERS``,
#: evenly spaced along an n-gon), moved this fraction of the way to its centre. They only
#: detect a penumbra and are not counted in the visible fraction. A straight shadow edge across
#: a convex lamp leaves a corner on each side, while the lattice's 8 points can all fall on one:
#: of floor points seeing 3-20 % of a lamp, 32-39 % read 0 without them, 1-8 % with them
#: (tests/core/test_emitters.py); the Cornell box's floor lit by its lamp alone (every other
#: surface black) had 104 of 3,004 vertices that see over 2 % of the open floor's light read 0,
#: now 50.
RIM = 0.05
RIM_CORNERS = 8

#: A receiver patch nearer an emitter face than this many times its own diameter takes its
#: unshadowed light from the emitter's side (:meth:`Emitters.near_patch_means`): a few Gauss
#: points on the patch cannot follow a light that falls off over the gap (a 2 m ceiling patch
#: 5 cm over a 0.6 m panel received 1.95 x the panel's power, tests/core/test_fuzz.py).
NEAR_PATCH = 2.0

#: Emitter-side integration: each emitter patch is cut into n x n cells (2 x 2 Gauss points
#: each), n = its size over the gap to the receiver, within these bounds.
NEAR_CELLS = (2, 12)

#: (pair, point) evaluations of the contour integral per vectorised chunk.
NEAR_CHUNK = 1 << 16

#: Bytes of unshadowed light (contour integrals) the emitters keep for a relight: they depend on
#: the geometry alone, so a relight that changes only the emission reads them back instead of
#: integrating again (issue 12; at 6,040 patches they were 1.5 s of a 2.2 s relight). A point
#: takes 64 + 8 x faces bytes: 1.3M points of 4 faces, 230k of 64.
KEEP_BYTES = 128 * 2**20


class _Kept:
    """The unshadowed light of the emitters' faces, kept per point (:class:`PointTable`, found by
    a hash of its coordinates and normal) within :data:`KEEP_BYTES`, and the near patches' means
    for the last patches asked (a few pairs per lamp); one object shared by an
    :class:`Emitters` and its recoloured copies. Full: no more points are kept (they are
    integrated as before)."""

    def __init__(self, m, budget=None):
        self.table = PointTable([(m, np.float64)], KEEP_BYTES if budget is None else budget)
        self.near = None                    # (patches, two_sided, near_patch_means' arrays)

    def unshadowed(self, origin, normals, integrate):
        """(m, n): the kept values at the points, ``integrate(origin, normals)`` (m, k) for
        the points not kept."""
        rows, keys = point_keys(origin, normals, 0)
        at = self.table.find(rows, keys, 0, lazy=True)
        miss = at < 0
        out = np.empty((self.table.values[0].shape[1], keys.size))
        out[:, ~miss] = self.table.values[0][at[~miss]].T
        if miss.any():
            new = integrate(origin[miss], normals[miss])
            out[:, miss] = new
            self.table.add(rows[miss], keys[miss], 0, np.ascontiguousarray(new.T))
        return out


def exact_materials(scene, mode="all", resolution=64):
    """(M,) bool: the emissive materials whose faces are lit exactly (see the module doc).

    ``mode``: 'all', 'off', or 'auto': only materials whose every face is narrower than
    ``AUTO_PIXELS`` pixels of a hemicube of ``resolution`` seen from what the face's lamp
    lights (width w = area / longest extent of the lamp, :func:`lamp_widths`, at the distance
    d of :func:`lamp_reach`: w R / (2 d) pixels). Materials with more than ``MAX_FACES`` faces
    or ``MAX_LAMPS`` lamps (:func:`core.lamps.lamp_labels`) are not judged: none is taken.
    """
    emissive = scene.emissive_materials()
    real = scene.face_areas > 0
    faces = np.bincount(scene.face_materials[real], minlength=emissive.size)
    if mode == "off":
        return np.zeros(emissive.size, dtype=bool)
    if mode == "auto":
        emissive &= faces <= MAX_FACES
        lamp = real & emissive[scene.face_materials]
        width, label = lamp_widths(scene, lamp, labels=True)
        reach = lamp_reach(scene, lamp, label)
        wide = lamp & (width * resolution > 2.0 * AUTO_PIXELS * reach)
        emissive &= np.bincount(scene.face_materials[wide], minlength=emissive.size) == 0
    area = np.bincount(scene.face_materials[real], weights=scene.face_areas[real],
                       minlength=emissive.size)
    lit = np.flatnonzero(real & emissive[scene.face_materials])
    first = np.unique(lamp_labels(scene, lit), return_index=True)[1]
    lamps = np.bincount(scene.face_materials[lit[first]], minlength=emissive.size)
    out = np.zeros(emissive.size, dtype=bool)
    total, count, total_area, limit = 0, 0, 0.0, MAX_AREA_SHARE * float(area.sum())
    for m in np.argsort(np.where(emissive, faces, np.iinfo(np.int64).max), kind="stable"):
        if not emissive[m] or total + faces[m] > MAX_FACES or count + lamps[m] > MAX_LAMPS \
                or total_area + area[m] > limit:
            break
        out[m] = True
        total += int(faces[m])
        count += int(lamps[m])
        total_area += float(area[m])
    return out


class Emitters:
    """The exact emitters of a scene as lights: one per emitting side of every lamp (a face, or
    faces of one material that share vertices: :mod:`core.lamps`).

    Parameters
    ----------
    scene : core.scene.Scene
    patches : core.patches.Patches
        The solve's patches: shadow rays aim at points on the emitters' patches.
    materials : (M,) bool
        Materials lit exactly (:func:`exact_materials`).

    Attributes
    ----------
    face : (n,) int64
        Scene face of every light (a lamp's first; a face emitting from both sides is two
        lights).
    sign : (n,) float64
        +1: the faces' fronts emit; -1: their backs.
    colour : (n, 3) float64
        Emitted radiance of that side.
    size : (n,) float64
        sqrt(area) of a lamp's one face; a lamp of several, its longest extent (m).
    faces : (f,) int64
        The faces lit exactly (both their sides: a side that does not emit is no light).
    """

    def __init__(self, scene, patches, materials):
        materials = np.asarray(materials, dtype=bool)
        faces = np.flatnonzero(materials[scene.face_materials] & (scene.face_areas > 0))
        le = np.asarray(scene.emission, dtype=np.float64)[scene.face_materials[faces]]
        back = np.asarray(scene.back_materials()[1], dtype=np.float64)[
            scene.face_materials[faces]]
        front_on, back_on = np.any(le > 0, axis=1), np.any(back > 0, axis=1)
        # Sides: every emitting side of every face, fronts first.
        local = np.concatenate([np.flatnonzero(front_on), np.flatnonzero(back_on)])
        side_sign = np.concatenate([np.ones(front_on.sum()), -np.ones(back_on.sum())])
        self.faces = faces
        self._slot = local                          # each side's face: column in the F matrix
        self._side_sign = side_sign
        self._kept = _Kept(local.size)                # shared with the recoloured copies
        # Lights: the sides of a lamp's faces (core.lamps), fronts first; a lamp of one face
        # is its sides' lights, in their order.
        lamp = lamp_labels(scene, faces)
        key = (side_sign < 0) * (faces.size + 1) + lamp[local]
        _, first, self._light_of_side = np.unique(key, return_index=True, return_inverse=True)
        self._light_of_side = self._light_of_side.reshape(-1)
        self._first = first
        order = np.argsort(self._light_of_side, kind="stable")      # sides grouped by light
        self._by_light = (order, np.searchsorted(self._light_of_side[order],
                                                 np.arange(first.size)))
        self.face = faces[local[first]]
        self.sign = side_sign[first]
        self.colour = np.concatenate([le[front_on], back[back_on]]).reshape(-1, 3)[first]
        polys = padded_polygons(scene.vertices, scene.corner_verts, scene.face_starts,
                                scene.face_sizes)
        self._polys = polys[faces] if faces.size else np.zeros((0, 3, 3))
        self._normal = scene.face_normals[faces]
        self._centre = self._polys.mean(axis=1) if faces.size else np.zeros((0, 3))
        self._mid = centroids(self._polys)                  # area centroids (core.lamps.FAR)
        self._face_area = scene.face_areas[faces]
        self._emits = (front_on, back_on)                   # per face: which sides emit
        sides = np.bincount(self._light_of_side, minlength=first.size)
        self._q = np.where(sides == 1, local[first], -1)    # a one-face light's face slot
        self.size = np.sqrt(scene.face_areas[self.face])
        # The rim's points per face (a few per lamp face: a list).
        self._rim = []
        for i, n in enumerate(scene.face_sizes[faces]):
            m = min(n, RIM_CORNERS)
            corners = self._polys[i, np.arange(m) * n // m]
            self._rim.append(corners + RIM * (self._centre[i] - corners))
        # The faces' patches, as cumulative area per face (sampling by inverse CDF).
        mine = np.isin(patches.face, faces)
        pid = np.flatnonzero(mine)
        order = np.lexsort((pid, patches.face[pid]))
        self._pid = pid[order]
        self._corners = np.asarray(patches.corners, dtype=np.float64)[self._pid]
        self._pface = np.searchsorted(faces, patches.face[self._pid])
        areas = np.asarray(patches.areas, dtype=np.float64)[self._pid]
        self._start = np.searchsorted(self._pface, np.arange(faces.size))
        self._stop = np.searchsorted(self._pface, np.arange(faces.size), side="right")
        self._cum = np.cumsum(areas)
        self._areas = areas
        # Anchor: the centre of each face's largest patch (inside the face, concave or not).
        self._anchor = np.zeros((faces.size, 3))
        for i in range(faces.size):                         # per emitter face: a few
            s, e = self._start[i], self._stop[i]
            if e > s:
                best = s + int(np.argmax(areas[s:e]))
                self._anchor[i] = self._corners[best].mean(axis=0)
            else:
                self._anchor[i] = self._centre[i]
        self._lamps = {e: self._lamp(e) for e in np.flatnonzero(self._q < 0)}
        for e, lamp in self._lamps.items():
            self.size[e] = float(np.ptp(lamp.corners.reshape(-1, 3), axis=0).max()) \
                if lamp.corners.size else 0.0

    def _lamp(self, e):
        """:class:`core.lamps.Lamp` of light ``e`` (a lamp of several faces)."""
        slots = self._slot[self._light_of_side == e]
        rows = np.concatenate([np.arange(self._start[q], self._stop[q]) for q in slots])
        return Lamp(self.sign[e], self._corners[rows], self._areas[rows],
                    self._normal[self._pface[rows]], self._anchor[slots], self._mid[slots],
                    self._normal[slots], self._face_area[slots])

    def __len__(self):
        return int(self.face.size)

    def recoloured(self, scene, materials):
        """These emitters at the emission of ``scene`` (the same geometry), or None.

        ``materials``: the new scene's exact materials (:func:`exact_materials`). None when a
        face would be lit exactly that is not one of these lights, or a face among them would
        emit from a side it did not (new lights), or keep emitting without being lit exactly.
        """
        materials = np.asarray(materials, dtype=bool)
        mat = scene.face_materials[self.faces]
        front = np.any(np.asarray(scene.emission)[mat] > 0, axis=1)
        back = np.any(np.asarray(scene.back_materials()[1])[mat] > 0, axis=1)
        chosen = np.flatnonzero(materials[scene.face_materials] & (scene.face_areas > 0))
        had_front = np.isin(self.faces, self.faces[self._slot[self._side_sign > 0]])
        had_back = np.isin(self.faces, self.faces[self._slot[self._side_sign < 0]])
        if not np.all(np.isin(chosen, self.faces)) or np.any(front & ~had_front) \
                or np.any(back & ~had_back) or np.any((front | back) & ~materials[mat]):
            return None
        slot = self._slot[self._first]
        le = np.asarray(scene.emission, dtype=np.float64)[mat[slot]]
        be = np.asarray(scene.back_materials()[1], dtype=np.float64)[mat[slot]]
        new = copy.copy(self)
        new.colour = np.where(self.sign[:, None] > 0, le, be)
        self._kept.table.sort()             # a relight asks every point again
        return new

    def unshadowed(self, origin, normals):
        """Per light: (n,) ``pi F`` from the points ``origin`` facing ``normals`` to the side of
        its face that emits (0 where the point sees the other side): the light's factor in the
        irradiance before shadows. Kept per point for a relight (:data:`KEEP_BYTES`)."""
        if not len(self):
            return []
        lit = self._kept.unshadowed(origin, normals, self._unshadowed)      # per side
        if not self._lamps:
            return list(lit)                                   # per light
        order, starts = self._by_light
        return list(np.add.reduceat(lit[order], starts, axis=0))

    def _unshadowed(self, origin, normals):
        """(sides, m): :meth:`unshadowed` integrated, per emitting side of a face."""
        side = np.einsum("nqj,qj->nq", origin[:, None, :] - self._centre[None], self._normal)
        front, back = self._emits
        ff = form_factors(origin, normals, self._polys, self._mid, self._normal,
                          self._face_area, ((side > 0) & front) | ((side < 0) & back))
        q = self._slot
        return np.where(self._side_sign[:, None] * side[:, q].T > 0, np.pi * ff[:, q].T, 0.0)

    def near_patch_means(self, patches, two_sided=True):
        """Unshadowed ``pi F`` averaged over the receiver patches near each emitter, integrated
        from the emitter's side.

        The mean over a patch ``p`` of ``F(x -> E)`` is ``(1 / A_p) int_E F(dy -> p) dy``
        (reciprocity of the point-to-area form factor). The inner ``F`` is the contour integral
        over the whole patch, exact; the outer integral runs over the emitter's patches in cells
        no larger than the gap (``NEAR_CELLS``). Whatever the outer rule, each point of the
        emitter hands its light out over the receivers' polygons, which tile what it sees: near
        the emitter its power is conserved by construction, where Gauss points on a receiver
        overrate a light that falls off across it.

        Parameters
        ----------
        patches : core.patches.Patches
        two_sided : bool
            Also the patches' back nodes (a point of the emitter behind a patch's plane lights
            its back).

        Returns
        -------
        light : (k,) int64
            The light (index into this object's lights) of each near pair.
        patch : (k,) int64
        mean : (k, 2) float64
            ``pi`` x the mean form factor over the patch from its front (column 0) and back
            (column 1) node to the light's emitting side (column 1 is 0 without
            ``two_sided``).

        Kept for the last ``patches`` asked (read-only arrays): a relight asks again.
        """
        near = self._kept.near
        if near is not None and near[0] is patches and near[1] == two_sided:
            return near[2]
        out = self._near_patch_means(patches, two_sided)
        for a in out:
            a.setflags(write=False)
        self._kept.near = (patches, two_sided, out)
        return out

    def _near_patch_means(self, patches, two_sided):
        out_l, out_p, out_m = [], [], []
        corners = np.asarray(patches.corners, dtype=np.float64)
        P = corners.shape[0]
        if not len(self) or self._pid.size == 0 or P == 0:
            return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros((0, 2))
        centres = corners.mean(axis=1)
        radius = np.linalg.norm(corners - centres[:, None], axis=2).max(axis=1)
        e_centre = self._corners.mean(axis=1)
        e_radius = np.linalg.norm(self._corners - e_centre[:, None], axis=2).max(axis=1)
        receives = np.ones(P, dtype=bool)
        receives[self._pid] = False                 # an emitter's own patches: coplanar, F = 0
        gu, gv, gw = gauss_square(2)
        lo, hi = NEAR_CELLS
        for e in range(self._slot.size):            # per side: at most 2 x MAX_FACES
            q = self._slot[e]
            kk, pp, gap = self._near_pairs(q, centres, radius, e_centre, e_radius, receives)
            if kk.size == 0:
                continue
            hit = np.unique(pp)
            normal = self._side_sign[e] * self._normal[q]
            # A receiver wholly behind the emitting side (the ceiling over a downlight) reads 0
            # from every point of it: kept, not integrated.
            ahead = (corners[pp] @ normal).max(axis=1) > (self._corners[kk] @ normal).min(axis=1)
            kk, pp, gap = kk[ahead], pp[ahead], gap[ahead]
            with np.errstate(divide="ignore"):
                cells = np.ceil(2.0 * e_radius[kk] / gap)
            cells = np.clip(np.nan_to_num(cells, nan=hi, posinf=hi), lo, hi).astype(np.int64)
            acc = np.zeros((P, 2))
            for n in np.unique(cells):
                rows = np.flatnonzero(cells == n)
                i, j = np.divmod(np.arange(n * n), n)
                u = ((i[:, None] + gu[None]) / n).ravel()
                v = ((j[:, None] + gv[None]) / n).ravel()
                w = np.tile(gw, n * n) / (n * n)
                m = u.size
                step = max(1, NEAR_CHUNK // m)
                for a in range(0, rows.size, step):
                    checkpoint()
                    r = rows[a:a + step]
                    y, jac = bilinear(self._corners[kk[r]], np.broadcast_to(u, (r.size, m)),
                                      np.broadcast_to(v, (r.size, m)))
                    p = np.repeat(pp[r], m)
                    y = y.reshape(-1, 3)
                    f = pair_form_factor(y, np.broadcast_to(normal, y.shape), corners[p]) \
                        * (jac * w[None]).reshape(-1)
                    back = np.einsum("ij,ij->i", y - centres[p], patches.normals[p]) < 0
                    np.add.at(acc, (p, back.astype(np.int64)), f)
            mean = np.pi * acc[hit] / np.asarray(patches.areas, dtype=np.float64)[hit, None]
            if not two_sided:
                mean[:, 1] = 0.0
            out_l.append(np.full(hit.size, self._light_of_side[e]))
            out_p.append(hit)
            out_m.append(mean)
        if not out_l:
            return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros((0, 2))
        light, patch, mean = (np.concatenate(a) for a in (out_l, out_p, out_m))
        if self._lamps:                             # a lamp's faces' shares of one patch
            key, at = np.unique(light * P + patch, return_inverse=True)
            total = np.zeros((key.size, 2))
            np.add.at(total, at.reshape(-1), mean)
            light, patch, mean = key // P, key % P, total
        return light, patch, mean

    def _near_pairs(self, q, centres, radius, e_centre, e_radius, receives):
        """(emitter patch, receiver patch, gap) of face slot ``q``: every receiver within
        ``NEAR_PATCH`` of its diameter of one of the face's patches (bounding spheres), paired
        with *every* patch of the face, so that its mean integrates the whole emitter (a receiver
        near one patch of a lamp split in four also sees the other three). Blocks of emitter
        patches keep a large emitter's (K, P) distances out of memory at once."""
        block = max(1, NEAR_CHUNK // max(centres.shape[0], 1))
        spans = [np.arange(a, min(a + block, self._stop[q]))
                 for a in range(self._start[q], self._stop[q], block)]

        def gaps(ks, p):
            d = centres[p][None] - e_centre[ks, None]
            return np.sqrt(np.einsum("kpj,kpj->kp", d, d)) - radius[p][None] \
                - e_radius[ks, None]

        everyone = np.arange(centres.shape[0])
        near = np.zeros(centres.shape[0], dtype=bool)
        for ks in spans:
            near |= np.any(gaps(ks, everyone) < NEAR_PATCH * 2.0 * radius[None], axis=0)
        p = np.flatnonzero(near & receives)
        if p.size == 0:
            return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros(0)
        out = []
        for ks in spans:
            g = gaps(ks, p)
            out.append((np.repeat(ks, p.size), np.tile(p, ks.size),
                        np.maximum(g, 0.0).ravel()))
        return tuple(np.concatenate(a) for a in zip(*out))

    def _samples(self, q, shift, index):
        """Points (g, m, 3) on face slot ``q``: lattice points ``index`` (m,) turned by
        ``shift`` (g, 3)."""
        uvw = (0.5 + index[None, :, None] * _ALPHA[None, None, :] + shift[:, None, :]) % 1.0
        s, e = self._start[q], self._stop[q]
        if e <= s:
            return np.broadcast_to(self._anchor[q], uvw.shape[:2] + (3,))
        base = self._cum[s] - self._areas[s]
        total = self._cum[e - 1] - base
        a = base + uvw[..., 2] * total
        k = np.clip(np.searchsorted(self._cum[s:e], a, side="right"), 0, e - s - 1) + s
        pts, _ = bilinear(self._corners[k.ravel()], uvw[..., 0].reshape(-1, 1),
                          uvw[..., 1].reshape(-1, 1))
        return pts.reshape(uvw.shape[:2] + (3,))

    def visible(self, e, origin, normals, k, turn, blocked, small=False):
        """Visible fraction (g,) of light ``e`` from ``origin`` (g, 3), kernel-weighted, and
        whether the ray to its anchor is clear (g,) bool.

        ``k``: rays where the first round disagrees (1: the anchor's ray only); ``turn``: (g,)
        angles per point; ``blocked(origin, direction)``: shadow rays ending at
        origin + direction. ``small``: a face narrower than the smallest element; where the
        anchor's and the corners' rays are all clear it is seen whole, no more rays
        (:data:`core.lights.SMALL_ROUND`). A lamp of several faces: :meth:`core.lamps.Lamp.visible`.
        """
        q = self._q[e]
        if q < 0:
            return self._lamps[e].visible(origin, normals, k, turn, blocked, small, FIRST_ROUND)
        g = origin.shape[0]
        centre = ~blocked(origin, self._anchor[q] - origin)
        if k <= 1:
            return centre.astype(np.float64), centre
        shift = turn[:, None] * _ROOT ** np.arange(3)[None, :] / (2.0 * np.pi)

        def cast(rows, index):
            y = self._samples(q, shift[rows], index)                      # (r, m, 3)
            d = y - origin[rows, None, :]
            r2 = np.einsum("rmj,rmj->rm", d, d)
            w = np.maximum(np.einsum("rmj,rj->rm", d, normals[rows]), 0.0) \
                * np.abs(d @ self._normal[q]) / np.maximum(r2, 1e-300) ** 2
            clear = ~blocked(np.repeat(origin[rows], index.size, axis=0),
                             d.reshape(-1, 3)).reshape(rows.size, index.size)
            return clear, w

        rim = self._rim[q]
        edge = ~blocked(np.repeat(origin, rim.shape[0], axis=0),
                        (rim[None, :, :] - origin[:, None, :]).reshape(-1, 3)
                        ).reshape(g, rim.shape[0])
        probe = centre + edge.sum(axis=1)
        # Hidden where every probe is blocked; narrower than an element and every probe clear:
        # seen whole. The others cast the rounds.
        whole = small & (probe == 1 + rim.shape[0])
        frac = whole.astype(np.float64)
        seen = np.flatnonzero((probe > 0) & ~whole)
        if not seen.size:
            return frac, centre
        first, w1 = cast(seen, np.arange(FIRST_ROUND))
        frac[seen] = _weighted(first, w1)
        lit = first.sum(axis=1) + probe[seen]
        part = np.flatnonzero(lit < FIRST_ROUND + 1 + rim.shape[0])
        if part.size:
            mixed = seen[part]
            more, w2 = cast(mixed, FIRST_ROUND + np.arange(k))
            frac[mixed] = _weighted(np.concatenate([first[part], more], axis=1),
                                    np.concatenate([w1[part], w2], axis=1))
        return frac, centre


def _weighted(clear, w):
    """(g,) fraction of the weight ``w`` (g, m) on clear rays (the plain fraction where every
    weight is 0: a point grazing the face)."""
    total = w.sum(axis=1)
    plain = clear.mean(axis=1)
    return np.where(total > 0, (clear * w).sum(axis=1) / np.where(total > 0, total, 1.0), plain)
