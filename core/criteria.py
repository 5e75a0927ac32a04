"""Where the adaptive radiosity mesh refines: the criteria of :mod:`core.adaptive`.

Per leaf of the element tree, from the values gathered at its output corners: the luminance
contrast between them (relative to the brighter, floored at ``DARK_FLOOR`` x the scene's mean),
a change in which emitter points they see (shadow rays), and contact lines running along it.
Also the measures the bake reports about light it cannot show ('vertices' output) or need not
compute (unlit faces).
"""

import numpy as np

from .exact import ray_triangles
from .geometry import patch_extents, spatial_order
from .raycast import any_hit, build_bvh
from .refine import DARK_FLOOR, LUMINANCE

#: Fixed emitter points that the shadow test casts rays to from every element vertex.
SHADOW_SAMPLES = 16

#: A leaf whose vertices see different emitter samples (or lights) is split when its contrast
#: exceeds this fraction of ``contrast``, even where the light across its parent looked linear
#: (the linear rule of :func:`per_leaf_scores` does not hold across a shadow edge). Measured
#: (bench/compare/coarse.py, office modelled coarsely): 0.25 -> 16,430 vertices, 10.00 %;
#: 1.0 -> 13,762, 9.99 %; 2.0 -> 12,118, 10.01 %; the box shadow of bench/bench_adaptive.py
#: 1,118 -> 1,101 vertices at 1.35 -> 1.36 %.
SHADOW_CONTRAST = 1.0

#: Steep leaves may be split below ``2 min_element``, down to this fraction of it
#: (:func:`smallest_split`): leaves along a contact line steeper than ``contrast``, and any leaf
#: whose contrast exceeds ``contrast`` also against the scene's mean luminance (not only against
#: DARK_FLOOR x it: a penumbra on a lit surface, not a dark corner's own level). Measured
#: (bench/compare/coarse.py, Cornell box modelled coarsely): the strip between the short block's
#: foot and its shadow's edge, 7 cm wide, was one element at min_element 0.05 m (+200 % on the
#: worst face); with the contact rule 10.0 % -> 4.8 % RMS, 949 -> 1,072 vertices. The rule
#: away from contacts (2026-11-29, after the shadow lines, the near elements and min_element
#: following a small model): the penumbra beside the short block, 3-6 cm from its corner, was
#: drawn by 2-4 cm leaves (a corner 0.28 for Cycles' 0.18 x the mean; 0.180 with a fine mesh):
#: Cornell box 2.70 % -> 2.40 % (2,286 -> 2,825 vertices), office 3.45 % -> 3.11 % (14,589 ->
#: 19,025 vertices); bakes back to back, 2 workers: office 49.0 -> 50.6 s, apartment 95.1 ->
#: 103.8 s (25,478 -> 30,018 points).
STEEP_FLOOR = 0.25

#: Leaves along a contact line are split down to this many times min_element (0.25 m at the
#: default 0.05 m). A multiple, not metres: with 0.25 m a model in millimetres (min_element
#: scaled with it) was never split along its contacts (tests/core/test_fuzz.py).
CONTACT_ELEMENT = 5.0

#: A leaf is taken as linear from its parent's split-made points (no contrast split; see
#: :func:`per_leaf_scores`) only while its brightest corner is at most this many times its
#: darkest. One midpoint cannot tell a line from an S: an edge of light (a lamp's outline above a
#: ceiling, a penumbra) centred on it passes the test at its inflection: the room of
#: bench/stability with its floor flipped kept 37 coarse faces beside a lamp's outline where the
#: room as modelled made 87, and read 7.5 % too bright there (flipped normals, 2026-11-27).
LINEAR_RATIO = 2.0

#: Alone points lie within the contacts' tolerance of a contact line. Points are tested in
#: chunks of POINT_CHUNK neighbours, each against the lines near it, PAIR_CHUNK (point, line)
#: pairs at a time.
PAIR_CHUNK = 2_000_000
POINT_CHUNK = 512

#: Solve patches near an emitter are split until their size is at most this many times their
#: distance to it (and emitter patches likewise towards the surfaces near them): a hemicube
#: treats its source patch as a point, which is wrong for two surfaces nearer than about a patch
#: size, and near an emitter that error carries most of the energy. Measured on the office
#: modelled coarsely (luminaires hung 5 cm under the ceiling), uniform patches: 0.8 m +24 %,
#: 0.4 m +10.6 %, 0.2 m +0.7 % too bright against converged Cycles (bench/compare/coarse.py).
NEAR_EMITTER_FACTOR = 4.0

#: (patch, emitter patch) pairs measured per chunk.
NEAR_CHUNK = 4_000_000

#: Two patches whose centres lie within this fraction of their radius from each other's plane
#: are coplanar for the near-emitter test.
COPLANAR = 1e-3

#: Thin cavities (a floor under a low shelf, a slot behind a cabinet): two patches facing each
#: other (front normals within 45 degrees of opposite, each in front of the other) across a gap
#: are split until each is at most CAVITY_FACTOR x the gap, when both are at least as wide
#: (area / longest edge) as the gap (a strip narrower than the gap forms no cavity; faces
#: in contact form none). The light in a cavity bounces between its two sides and fades with
#: depth; a patch wider than the gap carries one mean over the whole depth, which a point deep
#: inside then sees. Measured on the office modelled coarsely (bench/compare/coarse.py): the
#: floor under the lowest shelf (10 cm slot) was +130 % against converged Cycles at 1 m and at
#: 0.25 m patches, +24 % at 0.2 m; with this split 10.0 % -> 6.1 % RMS over the whole office.
CAVITY_FACTOR = 2.0
CAVITY_COS = -0.7

#: Patches p per block of the cavity test (each block meets only the patches within its reach).
CAVITY_CHUNK = 256

#: Patches per block of :func:`near_surfaces`, and per outer block whose neighbours its blocks
#: search. The box test is P x P / NEAR_OUTER comparisons and the pair test's blocks are small:
#: at 11,846 elements of one room of bench.interiors, 460-540 ms as one level of 256, 190 ms as
#: 64 in 1,024 (2026-12-07).
NEAR_CHUNK = 64
NEAR_OUTER = 1024


def luminance(rgb):
    """(n,) luminance of (n, 3) scene-linear RGB."""
    return np.asarray(rgb, dtype=np.float64) @ LUMINANCE


def dark_floor(patches, patch_radiance, scene):
    """The contrast test's absolute floor: DARK_FLOOR x the area-weighted mean luminance of the
    non-emitting patches (tiny positive if the scene is black)."""
    emitting = np.any(np.asarray(scene.emission)[patches.material] > 0, axis=1)
    a = patches.areas[~emitting]
    y = luminance(patch_radiance)[~emitting]
    mean = float((a * y).sum() / a.sum()) if a.sum() > 0 else 0.0
    return DARK_FLOOR * mean if mean > 0 else 1e-300


def face_variation(scene, patches, patch_radiance, contrast):
    """How much the light varies inside the user's faces (the 'vertices' output's loss).

    A face varies when the luminance of its patches spans more than ``contrast`` relative to
    its brightest (floored as in the refinement): one colour per user corner cannot show that.

    Returns
    -------
    dict
        ``faces_varying`` (count), ``area_share_varying`` (area fraction of the non-emitting
        faces), ``worst_faces`` (labels of up to 5 faces, largest area first).
    """
    floor = dark_floor(patches, patch_radiance, scene)
    y = luminance(patch_radiance)
    F = scene.n_faces
    hi = np.full(F, -np.inf)
    lo = np.full(F, np.inf)
    np.maximum.at(hi, patches.face, y)
    np.minimum.at(lo, patches.face, y)
    emits = np.any(np.asarray(scene.emission)[scene.face_materials] > 0, axis=1)
    has = np.isfinite(hi) & scene.face_valid & ~emits
    var = np.zeros(F, dtype=bool)
    var[has] = (hi[has] - lo[has]) / np.maximum(hi[has], floor) > contrast
    total = float(scene.face_areas[has].sum())
    share = float(scene.face_areas[var].sum()) / total if total > 0 else 0.0
    worst = np.flatnonzero(var)[np.argsort(-scene.face_areas[var])][:5]
    return dict(faces_varying=int(var.sum()), area_share_varying=share,
                worst_faces=[scene.face_label(f) for f in worst])


def unlit_late_nodes(scene, patches, active, late, resolution):
    """Which of the late front nodes (never reached by discovery) need no hemicube row.

    ``bake._run`` computes a row for every unreached front node, because a small patch can slip
    between the pixels of every hemicube that looks at it. A whole face none of whose patches
    was reached, and which is large enough to cover several pixels of a hemicube at the far
    end of the scene, did not slip: no light reaches it. Its patches stay black without rows.
    (A 100 x 100 m ground plane outside a closed room: 10,000 rows saved.)

    Returns
    -------
    (len(late),) bool
    """
    P = patches.areas.size
    face_reached = np.zeros(scene.n_faces, dtype=bool)
    face_reached[patches.face[np.flatnonzero(active[:P])]] = True
    diag = scene.bounding_diagonal()
    pixel = (2.0 / resolution) ** 2          # solid angle of a pixel at the top face's centre
    big = scene.face_areas >= 4.0 * pixel * diag * diag
    f = patches.face[late]
    return ~face_reached[f] & big[f]


class _Lines:
    """Segments (a, u unit, w unit in-plane normal, length) with a distance tolerance."""

    def __init__(self, a, u, w, length, tol):
        self.a, self.u, self.w, self.length, self.tol = a, u, w, length, tol


def contact_points(points, lines, chunk=PAIR_CHUNK):
    """(V,) bool: points within the lines' tolerance of one of their segments.

    Parameters
    ----------
    points : (V, 3) float64
    lines : core.contacts.Contacts, _Lines or None
    """
    out = np.zeros(points.shape[0], dtype=bool)
    if lines is None or lines.a.shape[0] == 0 or points.shape[0] == 0:
        return out
    key = np.round(np.concatenate([lines.a, lines.u, lines.length[:, None]], axis=1), 9)
    _, first = np.unique(key, axis=0, return_index=True)
    a, u, w, length = lines.a[first], lines.u[first], lines.w[first], lines.length[first]
    n = np.cross(u, w)
    tol = lines.tol
    # A point within tol of a segment lies within sqrt(3) tol of its bounding box: each chunk
    # of neighbouring points is tested against the segments whose box, grown by 2 tol, meets
    # the chunk's box (the same answers as testing every segment).
    end = a + length[:, None] * u
    seg_lo, seg_hi = np.minimum(a, end) - 2.0 * tol, np.maximum(a, end) + 2.0 * tol
    order = spatial_order(points)
    for s in range(0, points.shape[0], POINT_CHUNK):
        idx = order[s:s + POINT_CHUNK]
        pts = points[idx]
        near = np.flatnonzero(np.all((seg_hi >= pts.min(axis=0)) & (seg_lo <= pts.max(axis=0)),
                                     axis=1))
        step = max(1, chunk // idx.size)
        for k0 in range(0, near.size, step):
            k = near[k0:k0 + step]
            rel = pts[:, None, :] - a[None, k]
            t = np.einsum("pkj,kj->pk", rel, u[k])
            on = (np.abs(np.einsum("pkj,kj->pk", rel, w[k])) <= tol) \
                & (np.abs(np.einsum("pkj,kj->pk", rel, n[k])) <= tol) \
                & (t >= -tol) & (t <= length[None, k] + tol)
            out[idx] |= on.any(axis=1)
    return out


def contact_edges(scene, tree, contacts):
    """The level-0 edges of ``tree`` that run along a contact line, as :class:`_Lines`.

    A box whose outline follows the patch edges crosses no patch, so its lines are not among
    ``contacts``' segments; its outline vertices are (``contacts.vertices``). An edge between two
    such points (or points on a crossing line) is taken as part of the outline, so the points
    later put on it gather per corner too. (An edge across a footprint between two outline
    points is taken too: its points then gather per corner, which is only slower.)
    """
    if contacts is None:
        return None
    P = tree.points
    flagged = scene.vertices[np.flatnonzero(contacts.vertices)]
    on = contact_points(P, contacts)
    if flagged.shape[0]:
        both = np.concatenate([flagged, P])
        _, inv = np.unique(both, axis=0, return_inverse=True)
        inv = inv.reshape(-1)
        on |= np.isin(inv[flagged.shape[0]:], inv[:flagged.shape[0]])
    a = tree.leaves
    b = np.roll(a, -1, axis=1)
    edge = (a != b) & on[a] & on[b]
    leaf = np.nonzero(edge)[0]
    pa, pb = P[a[edge]], P[b[edge]]
    d = pb - pa
    length = np.linalg.norm(d, axis=1)
    ok = length > 0
    u = d[ok] / length[ok, None]
    w = np.cross(np.asarray(tree.normals)[leaf[ok]], u)
    w /= np.maximum(np.linalg.norm(w, axis=1, keepdims=True), 1e-300)
    return _Lines(pa[ok], u, w, length[ok], contacts.tol)


class EmitterSamples:
    """Fixed sample points on the emitters and the shadow rays to them."""

    def __init__(self, scene, patches, rng):

        le = luminance(np.asarray(scene.emission)[patches.material])
        emitting = np.flatnonzero(le > 0)
        self.n = 0
        if emitting.size == 0:
            return
        weight = patches.areas[emitting] * le[emitting]
        pick = emitting[rng.choice(emitting.size, size=SHADOW_SAMPLES, p=weight / weight.sum())]
        c = patches.corners[pick]
        u, v = rng.random(SHADOW_SAMPLES), rng.random(SHADOW_SAMPLES)
        # A point inside the patch (triangles repeat their last corner: the map still lands
        # inside them).
        self.points = ((1 - u) * (1 - v))[:, None] * c[:, 0] + (u * (1 - v))[:, None] * c[:, 1] \
            + (u * v)[:, None] * c[:, 2] + ((1 - u) * v)[:, None] * c[:, 3]
        self.normals = patches.normals[pick]
        self.bvh = build_bvh(ray_triangles(patches)[0])
        self.offset = 1e-6 * max(float(np.ptp(patches.corners.reshape(-1, 3), axis=0).max()), 1.0)
        self.n = SHADOW_SAMPLES

    def visibility(self, points, normals):
        """(S,) int64 bit masks: bit k set when emitter sample k is visible from the point."""

        S = points.shape[0]
        out = np.zeros(S, dtype=np.int64)
        if self.n == 0 or S == 0:
            return out
        o = points + self.offset * normals
        d = self.points[None, :, :] - o[:, None, :]                 # (S, K, 3)
        facing = (np.einsum("skj,sj->sk", d, normals) > 0) \
            & (np.einsum("skj,kj->sk", d, self.normals) < 0)
        s, k = np.nonzero(facing)
        vis = np.zeros((S, self.n), dtype=bool)
        if s.size:
            vis[s, k] = ~any_hit(self.bvh, o[s], d[s, k], t_max=1.0 - 1e-6)
        return (vis.astype(np.int64) << np.arange(self.n, dtype=np.int64)).sum(axis=1)


def _per_leaf(conf, values, n_leaves, fn, fill):
    """Reduce per-corner ``values`` over the leaf of each corner's output face."""
    face_of = np.repeat(np.arange(conf["face_sizes"].size), conf["face_sizes"])
    out = np.full(n_leaves, fill, dtype=values.dtype)
    fn.at(out, conf["face_leaf"][face_of], values)
    return out


def interpolation_errors(tree, corner_points, corner_y, floor):
    """(V,) float: at each point a split made, how far its value is from the mean of the points
    it was made from (an edge's two ends, a quad's four corners), relative to the brightest of
    them (floored at ``floor``); NaN at the level-0 points and where a value is missing.

    The output interpolates linearly: where a parent's new points agree with its corners, the
    light across it is linear and splitting its children further buys nothing.
    """
    V = tree.points.shape[0]
    y = np.full(V, np.nan)
    y[corner_points] = -np.inf
    np.maximum.at(y, corner_points, corner_y)
    par = tree.point_parents
    made = np.flatnonzero(par[:, 0] >= 0)
    par = par[made]
    have = par >= 0
    yp = np.where(have, y[np.maximum(par, 0)], 0.0)
    mean = yp.sum(axis=1) / have.sum(axis=1)
    top = np.maximum(np.where(have, yp, -np.inf).max(axis=1), np.maximum(y[made], floor))
    err = np.full(V, np.nan)
    err[made] = np.abs(y[made] - mean) / top        # NaN where a value is missing
    return err


def per_leaf_scores(tree, conf, corner_y, corner_vis, corner_alone, emitting_leaf, floor, settings,
                    corner_interp=None):
    """(E,) float: how badly each leaf needs splitting (0: not at all).

    ``corner_interp`` (C,) float, optional: :func:`interpolation_errors` at each corner (NaN
    where unknown). A leaf with a split-made point among its corners and no interpolation error
    above ``contrast`` there is not split for contrast: the light across its parent was linear,
    which the output's interpolation already draws. Not beyond :data:`LINEAR_RATIO` between
    its corners, where one midpoint cannot vouch for a line. ``floor``: :func:`dark_floor`.
    """
    E = tree.leaves.shape[0]
    hi = _per_leaf(conf, corner_y, E, np.maximum, -np.inf)
    lo = _per_leaf(conf, corner_y, E, np.minimum, np.inf)
    has = np.isfinite(hi)
    diff = _contrast(hi, lo, has, floor)
    area = np.asarray(tree.areas, dtype=np.float64)
    steep = diff
    if corner_interp is not None:
        known = np.isfinite(corner_interp)
        interp = _per_leaf(conf, np.where(known, corner_interp, -1.0), E, np.maximum, -1.0)
        linear = (interp >= 0) & (interp <= settings.contrast) \
            & (diff <= 1.0 - 1.0 / LINEAR_RATIO)
        steep = np.where(linear, 0.0, diff)
    score = np.where(steep > settings.contrast, area * steep / settings.contrast, 0.0)
    vmax = _per_leaf(conf, corner_vis, E, np.maximum, np.int64(-1))
    vmin = _per_leaf(conf, corner_vis, E, np.minimum, np.int64(np.iinfo(np.int64).max))
    # A visibility change alone does not split: inside a wide penumbra every leaf sees a
    # different part of the light, and the light there changes smoothly (contrast's business).
    shadow = has & (vmax != vmin) & (diff > SHADOW_CONTRAST * settings.contrast)
    score = np.maximum(score, np.where(shadow, area, 0.0))
    touches = _per_leaf(conf, corner_alone.astype(np.int64), E, np.maximum, np.int64(0)) > 0
    size = np.asarray(tree.sizes, dtype=np.float64)
    contact = touches & (size > CONTACT_ELEMENT * settings.min_element)
    score = np.maximum(score, np.where(contact, 0.5 * area, 0.0))
    score[emitting_leaf] = 0.0
    # Below 2 min_element only where the light changes on the scene's scale (STEEP_FLOOR).
    vs_mean = _contrast(hi, lo, has, floor / DARK_FLOOR)     # floor / DARK_FLOOR: the mean
    steep_here = touches | (vs_mean > settings.contrast)
    limit = np.where(steep_here, smallest_split(diff, settings), 2.0 * settings.min_element)
    score[size < limit] = 0.0
    return score, dict(contrast=int(np.count_nonzero(steep > settings.contrast)),
                       shadow=int(np.count_nonzero(shadow)), contact=int(np.count_nonzero(contact)))


def _contrast(hi, lo, has, floor):
    """(E,) float: ``(hi - lo) / max(hi, floor)`` where ``has``, else 0."""
    out = np.zeros(hi.shape[0])
    out[has] = (hi[has] - lo[has]) / np.maximum(hi[has], floor)
    return out


def smallest_split(diff, settings):
    """(E,) float: the smallest leaf size (m) that may still be split, per leaf contrast ``diff``.

    ``2 min_element`` where the contrast is at most ``contrast``; where it is steeper (the
    foot of an object, a penumbra: :func:`per_leaf_scores` applies it to leaves along a
    contact line and to leaves steep against the scene's mean)
    down to ``2 min_element sqrt(contrast / diff)``, never below
    ``STEEP_FLOOR x 2 min_element``: linear interpolation across a leaf errs by about a quarter
    of its contrast at its middle, so a leaf ten times over the threshold is worth halving once
    or twice more, and the floor bounds what a hard shadow edge costs.
    """
    ratio = settings.contrast / np.maximum(diff, 1e-300)
    return 2.0 * settings.min_element * np.clip(np.sqrt(ratio), STEEP_FLOOR, 1.0)


def _pair_gaps(centres, radius, normals, a, b):
    """Lower bounds of the gaps between patches ``a`` (rows) and ``b`` (columns).

    The gap is at least the distance between their bounding spheres and the distance of each
    centre from the other's plane. Returns ``(d, gap, plane_a, plane_b)``: ``d`` (A, B, 3) the
    vectors from a's centres to b's, ``plane_a`` b's centres from a's planes, ``plane_b`` a's
    from b's.
    """
    d = centres[None, b, :] - centres[a, None, :]
    sphere = np.linalg.norm(d, axis=2) - radius[None, b] - radius[a, None]
    plane_a = np.abs(np.einsum("abk,ak->ab", d, normals[a]))
    plane_b = np.abs(np.einsum("abk,bk->ab", d, normals[b]))
    return d, np.maximum(sphere, np.maximum(plane_a, plane_b)), plane_a, plane_b


def near_emitter_mask(patches, emitting, *, factor=NEAR_EMITTER_FACTOR, min_size=0.0):
    """Patches too large for their distance to an emitter, and emitters too large for theirs.

    The distance between two patches is bounded below by the gap between their bounding
    spheres and by the distance of each centre from the other's plane; patch p (size s_p, the
    longest edge) is marked when ``s_p > factor * d`` for some pair (p, e) with e emitting
    (and e when ``s_e > factor * d``), never below ``min_size``.

    Parameters
    ----------
    patches : core.patches.Patches
    emitting : (P,) bool
    factor : float
    min_size : float
        Patches no larger than this are never marked (m).

    Returns
    -------
    (P,) bool
    """
    emitting = np.asarray(emitting, dtype=bool)
    P = patches.areas.size
    mask = np.zeros(P, dtype=bool)
    src = np.flatnonzero(emitting)
    if src.size == 0 or P == 0:
        return mask
    corners = patches.corners
    centres, normals = patches.centres, patches.normals
    radius, size = patch_extents(corners, centres)
    step = max(1, NEAR_CHUNK // P)
    for lo in range(0, src.size, step):
        e = src[lo:lo + step]
        _, gap, plane_e, plane_p = _pair_gaps(centres, radius, normals, e, slice(None))
        # Coplanar patches exchange nothing (a ceiling around a flush panel); emitters are
        # measured against the surfaces around them, not against each other.
        flat = (plane_e <= COPLANAR * radius[e, None]) & (plane_p <= COPLANAR * radius[None, :])
        gap[flat] = np.inf
        gap[:, emitting] = np.inf
        near = gap * factor
        mask |= np.any(size[None, :] > near, axis=0)
        mask[e] |= np.any((size[e, None] > near) & ~emitting[None, :], axis=1)
    return mask & (size > min_size)


def cavity_mask(patches, *, factor=CAVITY_FACTOR, min_size=0.0, check=None, emitting=None,
                back_open=None):
    """Patches too wide for the thin cavity they bound (:data:`CAVITY_FACTOR`).

    Pairs (p, q) whose front normals are within 45 degrees of opposite, whose centres lie in
    front of each other and off each other's plane (faces in contact enclose nothing), neither
    of them ``emitting``; their
    gap is bounded below as in :func:`near_emitter_mask`. Patch p is marked when its size
    (longest edge) exceeds ``factor * gap`` and both are at least as wide (area / longest edge)
    as the gap, never when its size is at or below ``min_size``: a strip narrower than the gap
    forms no cavity with what faces it.

    Parameters
    ----------
    patches : core.patches.Patches
    check : callable, optional
        Called between chunks (a bake's cancel check: 3,000 boxes take seconds here).
    emitting : (P,) bool, optional
        Emitters bound no cavity: a two-sided lamp's back is its front, so which of its sides
        faces a surface says nothing (:func:`near_emitter_mask` splits by distance, whatever
        the sides). Measured on the office (bench/compare/coarse.py): counting a panel's back
        and the ceiling above it as a cavity cost 30 % more patches and 8 % more vertices and
        took the error from 5.75 % to 5.94 %.
    back_open : (P,) bool, optional
        Patches whose back side bounds cavities too (the faces a solve found lit from behind,
        :mod:`core.orient`); every front does.

    Returns
    -------
    (P,) bool
    """
    P = patches.areas.size
    mask = np.zeros(P, dtype=bool)
    if P < 2:
        return mask
    if emitting is not None:
        emitting = np.asarray(emitting, dtype=bool)
    centres, normals = patches.centres, patches.normals
    # The sides that may bound a cavity: (sign, (P,) bool) -- fronts, and the open backs.
    sides = [(1.0, np.ones(P, dtype=bool))]
    if back_open is not None and np.any(back_open):
        sides.append((-1.0, np.asarray(back_open, dtype=bool)))
    radius, size = patch_extents(patches.corners, centres)
    width = patches.areas / np.maximum(size, 1e-300)
    cand = np.flatnonzero((size > min_size) if emitting is None else
                          (size > min_size) & ~emitting)
    cand = cand[spatial_order(centres[cand])]
    # Chunks of neighbouring p; q is looked at only within reach of the chunk's bounding box
    # (a pair farther apart than the larger radius plus size / factor cannot qualify).
    for lo in range(0, cand.size, CAVITY_CHUNK):
        if check is not None:
            check()
        p = cand[lo:lo + CAVITY_CHUNK]
        reach = radius[p].max() + radius.max() + size[p].max() / factor
        box_lo, box_hi = centres[p].min(axis=0) - reach, centres[p].max(axis=0) + reach
        q = np.flatnonzero(np.all((centres >= box_lo) & (centres <= box_hi), axis=1))
        d, gap, plane_p, plane_q = _pair_gaps(centres, radius, normals, p, q)
        cos = normals[p] @ normals[q].T
        ahead_q = np.einsum("pqk,pk->pq", d, normals[p])        # q along p's normal
        ahead_p = np.einsum("pqk,qk->pq", d, normals[q])        # minus p along q's normal
        front = np.zeros(cos.shape, dtype=bool)
        for sp, open_p in sides:
            for sq, open_q in sides:
                front |= (sp * sq * cos < CAVITY_COS) & (sp * ahead_q > 0) \
                    & (sq * ahead_p < 0) & open_p[p, None] & open_q[None, q]
        if emitting is not None:
            front &= ~emitting[q][None, :]
        apart = (plane_p > COPLANAR * radius[p, None]) & (plane_q > COPLANAR * radius[None, q])
        cavity = front & apart & (width[None, q] >= gap) & (width[p, None] >= gap)
        mask[p] = np.any(cavity & (size[p, None] > factor * gap), axis=1)
    return mask


def near_surfaces(patches, *, chunk=NEAR_CHUNK, outer=NEAR_OUTER):
    """(P,) bool: patches within reach of another surface that is not in their plane.

    Patch p is near q when their bounding spheres overlap and each centre lies off the other's
    plane: a concave corner (a wall under the ceiling), an object standing on or against p.
    There a point gathering close to the corner sees the near part of p under a large solid
    angle, so p's mean radiance is not what it sees (:mod:`core.elements` splits such patches
    at a lower contrast). Coplanar neighbours, and patches farther apart than their extents,
    are not near.

    Patches are taken in blocks of ``chunk`` in spatial order; each block meets the patches
    whose bounding box meets its own, found among those of its ``outer`` block (so the boxes
    are compared P x P / outer times, not P x P / chunk).
    """
    P = patches.areas.size
    mask = np.zeros(P, dtype=bool)
    if P < 2:
        return mask
    centres, normals = patches.centres, patches.normals
    radius, _ = patch_extents(patches.corners, centres)
    order = spatial_order(centres)
    # q's own sphere must reach the box of the block's spheres: one large patch (a floor left
    # whole) does not widen every block's reach to its radius.
    lo_q, hi_q = centres - radius[:, None], centres + radius[:, None]

    def meeting(p, among):
        box_lo, box_hi = lo_q[p].min(axis=0), hi_q[p].max(axis=0)
        return among[np.all((hi_q[among] >= box_lo) & (lo_q[among] <= box_hi), axis=1)]

    everything = np.arange(P)
    for top in range(0, P, max(outer, chunk)):
        block = order[top:top + max(outer, chunk)]
        reach = meeting(block, everything)
        for lo in range(0, block.size, chunk):
            p = block[lo:lo + chunk]
            q = meeting(p, reach)
            d = centres[None, q, :] - centres[p, None, :]
            a, b = np.nonzero(np.sqrt(np.einsum("pqk,pqk->pq", d, d))
                              < radius[p, None] + radius[None, q])
            a, b, d = p[a], q[b], d[a, b]                   # the overlapping pairs alone
            plane_p = np.abs(np.einsum("ik,ik->i", d, normals[a]))
            plane_q = np.abs(np.einsum("ik,ik->i", d, normals[b]))
            mask[a[(plane_p > COPLANAR * radius[a]) & (plane_q > COPLANAR * radius[b])]] = True
    return mask
