"""Shadow lines from objects' feet: patches cut where a shadow boundary leaves a contact corner.

A box standing on a floor under a lamp casts a shadow whose sides start at the box's corners on
the floor. There the penumbra is as narrow as the distance to the corner allows: zero at the
corner, a few millimetres a few centimetres away (its width grows with the distance times the
lamp's angular size over the box's height). A mesh whose edges cross that line obliquely draws
it as a smear one element wide, however fine the elements: the Cornell box's worst faces against
Cycles were the floor at the tall block's front corner (0.89 for 0.68).

The lines are known before any light is computed. A corner where two faces of an object meet a
receiver plane (two contact segments ending at one point) has a rising edge ``e``; seen from a
point ``L`` of a light, the edge is a silhouette when both faces lie on one side of the plane
through ``e`` and ``L``, and then the plane meets the receiver along a line from the corner,
away from ``L``: a boundary of the shadow (an EV event of discontinuity meshing; Heckbert 1992,
Lischinski, Tampieri & Greenberg 1992). Per light the two extreme lines over its points (the
corners of an emissive face, a point or spot light's centre moved by its radius across the
plane, a sun's direction turned by its half angle) bound the penumbra; both cut the patches they
cross (:func:`core.contacts.split_at_contacts`), from the corner to the shadow of the edge's top
(at most ``REACH`` times the edge's length, and no farther than where the penumbra between the
two is ``RESOLVED`` minimum elements wide: from there the mesh's refinement draws it).

Each line is checked against the scene before it cuts: its light must give at least
``min_share`` (the bake's ``contrast``) of the corner's direct light, counting only the share
of its points that a ray from just outside the corner sees (a lamp in the next room gives
none), and halfway along the line the light's point must be seen from one side and hidden from
the other. A line that passes both and still is no boundary only costs the pieces it makes.
"""

import numpy as np

from .contacts import Contacts, _clear_of_corners, _crossed, _unit, no_contacts
from .exact import point_polygon_form_factor, ray_triangles
from .geometry import box_pairs, ragged
from .lights import LUMA, spot_factor
from .patches import connected_labels, triangle_mask
from .raycast import any_hit, build_bvh
from .transfer import padded_polygons

#: A line runs from its corner at most this many times the rising edge's length: beyond the
#: shadow of the edge's top the boundary is cast by the top edges, from a distance, and is soft.
REACH = 4.0

#: Lines from one corner within this angle (rad) of each other are one line: a second cut there
#: would make a sliver.
SAME_ANGLE = np.radians(1.0)

#: A rising edge within this cosine of the receiver's plane (about 3 degrees) casts no line.
MIN_RISE = 0.05

#: Emissive faces' corners taken as light points at most; a scene with more (a luminous ceiling
#: of many faces, a large soft source) casts no lines from its emitters.
MAX_EMITTER_POINTS = 512

#: A shadow line cuts no patch where it would cross an edge nearer its ends than this fraction
#: of the patch's size: a needle (tests/core/test_footlines.py, a furnace's wall foot, 0.01 %).
NEEDLE = 0.005

#: A line stops where the wedge between its light's two lines is this many minimum elements
#: wide: from there the radiosity mesh's own refinement draws the penumbra.
RESOLVED = 4.0

#: A light casts lines from a corner only if its direct light there is at least this share of
#: all the lights' (the bake uses its ``contrast`` setting, 0.1 by default).
MIN_SHARE = 0.1

#: (corner, light point) pairs per vectorised chunk.
PAIR_CHUNK = 1 << 16

#: The ray that tests whether a corner sees a light starts this fraction of the rising edge's
#: length out of the object and up from the plane.
OUTSIDE = 0.02

#: The boundary test looks this fraction of the distance from the corner to either side of a
#: line, halfway along it.
PROBE = 0.05

#: A lamp's corner is aimed at this fraction of the way to its face's centre.
AIM_INSET = 0.05

#: Lines at most (a cap on the work: a field of chair legs under many lamps).
MAX_LINES = 4096


def light_points(scene, lamps=None):
    """Points of the scene's lights.

    Returns
    -------
    q : (k, 3) float64
        A position, or a unit direction towards a sun (``at_infinity``).
    at_infinity : (k,) bool
    group : (k,) int64
        The light each point belongs to: a lamp (emissive faces of one material that share
        vertices: one group per panel, however many share its material), each point or spot
        light, each sun.
    aim : (k, 3) float64
        Where a ray tests whether the point's light is seen: a lamp's corner moved
        ``AIM_INSET`` of the way to its face's centre (not on the ceiling round it), a light's
        centre, a sun's direction.

    Every corner of every emissive face; each point or spot light's centre moved by its radius
    along the 3 axes both ways (the extreme lines come from the two that turn the plane most);
    each sun's direction turned by its half angle the same way. ``lamps``: the scene's
    :func:`_emissive_faces`, when they are at hand.
    """
    pos, inf, group, aim = [], [], [], []
    faces, lamp, g0 = _emissive_faces(scene) if lamps is None else lamps
    if faces.size:
        corners, owner = _corners_of(scene, faces)
        x = scene.vertices[corners]
        centroid = _centroids(scene, faces, x, owner)
        pos.append(x)
        inf.append(np.zeros(corners.size, dtype=bool))
        group.append(lamp[owner])
        aim.append(x + AIM_INSET * (centroid[owner] - x))
    lt = scene.lights
    if lt is not None:
        axes = np.concatenate([np.eye(3), -np.eye(3)])
        n = lt.position.shape[0]
        shines = np.asarray(lt.shadow, dtype=bool)
        for j in np.flatnonzero(shines[:n]):                # per light: a few
            pos.append(lt.position[j] + lt.radius[j] * axes)
            inf.append(np.zeros(6, dtype=bool))
            group.append(np.full(6, g0 + j))
            aim.append(np.repeat(lt.position[j][None], 6, axis=0))
        for k in np.flatnonzero(shines[n:]):
            pos.append(_unit(lt.sun_direction[k] + np.tan(lt.sun_half_angle[k]) * axes))
            inf.append(np.ones(6, dtype=bool))
            group.append(np.full(6, g0 + n + k))
            aim.append(np.repeat(lt.sun_direction[k][None], 6, axis=0))
    if not pos:
        return np.zeros((0, 3)), np.zeros(0, dtype=bool), np.zeros(0, dtype=np.int64), \
            np.zeros((0, 3))
    return np.concatenate(pos), np.concatenate(inf), \
        np.concatenate(group).astype(np.int64), np.concatenate(aim)


def _emissive_faces(scene):
    """The emissive faces whose corners are light points (all of them, or none when they have
    more than MAX_EMITTER_POINTS corners) and the lamp each belongs to (faces of one material
    linked through shared vertices); the number of lamps."""
    emissive = scene.emissive_materials()[scene.face_materials] \
        & np.asarray(scene.face_valid, dtype=bool) & (scene.face_areas > 0)
    faces = np.flatnonzero(emissive)
    if faces.size == 0 or int(scene.face_sizes[faces].sum()) > MAX_EMITTER_POINTS:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64), 0
    corners, owner = _corners_of(scene, faces)
    order = np.lexsort((owner, corners))
    v, f = corners[order], owner[order]
    mat = scene.face_materials[faces]
    same = (v[1:] == v[:-1]) & (mat[f[1:]] == mat[f[:-1]])
    lamp = connected_labels(faces.size, f[:-1][same], f[1:][same])
    _, lamp = np.unique(lamp, return_inverse=True)
    lamp = lamp.reshape(-1)
    return faces, lamp, int(lamp.max()) + 1


def _irradiance(scene, lamps, x, n, G):
    """(k, G): each light's direct luminance irradiance at points ``x`` facing ``n`` before
    shadows (pi F Le for a lamp, its faces summed; I cos / d^2 in a spot's cone; E cos for a
    sun), in the groups of :func:`light_points`; ``lamps``: :func:`_emissive_faces`."""
    out = np.zeros((x.shape[0], G))
    faces, lamp, g0 = lamps
    if faces.size:
        le = np.asarray(scene.emission, dtype=np.float64)
        back = np.asarray(scene.back_materials()[1], dtype=np.float64)
        mat = scene.face_materials[faces]
        lum = np.maximum(le[mat] @ LUMA, back[mat] @ LUMA)
        polys = padded_polygons(scene.vertices, scene.corner_verts, scene.face_starts,
                                scene.face_sizes)[faces]
        f = point_polygon_form_factor(x, n, polys) * (np.pi * lum)[None]
        np.add.at(out.T, lamp, f.T)
    lt = scene.lights
    if lt is None:
        return out
    m = lt.position.shape[0]
    for j in range(m):                                  # per point or spot light: a few
        d = lt.position[j] - x
        r2 = np.maximum(np.einsum("ij,ij->i", d, d), np.finfo(float).tiny)
        cos = np.maximum(np.einsum("ij,ij->i", d, n), 0.0) / np.sqrt(r2)
        cone = 1.0
        if lt.cos_half[j] > -1.0:
            cone = spot_factor(-(d @ lt.axis[j]) / np.sqrt(r2), lt.cos_half[j], lt.smooth[j])
        out[:, g0 + j] = float(lt.intensity[j] @ LUMA) * cos / r2 * cone
    for k in range(lt.sun_direction.shape[0]):
        out[:, g0 + m + k] = float(lt.sun_irradiance[k] @ LUMA) \
            * np.maximum(n @ lt.sun_direction[k], 0.0)
    return out


def _corners_of(scene, faces):
    """Scene vertex of every corner of ``faces`` and the index (into ``faces``) of its face."""
    owner, local, _ = ragged(scene.face_sizes[faces])
    return scene.corner_verts[scene.face_starts[faces][owner] + local], owner


def _centroids(scene, faces, x, owner):
    """Mean corner of each of ``faces``, from its corners' points ``x`` (of :func:`_corners_of`)."""
    centroid = np.zeros((faces.size, 3))
    np.add.at(centroid, owner, x)
    return centroid / scene.face_sizes[faces][:, None]


def contact_corners(scene, patches, contacts):
    """Corners where two faces of an object meet a receiver plane.

    Returns
    -------
    c : (C, 3) float64
        The corner, in the plane.
    n : (C, 3) float64
        The receiver plane's unit normal.
    e : (C, 3) float64
        Unit direction of the rising edge (into the plane's front).
    d1, d2 : (C, 3) float64
        Unit directions from the corner into each of the two faces, across the edge.
    h : (C,) float64
        Length of the rising edge (to the lower of the two faces' tops).
    """
    empty = (np.zeros((0, 3)),) * 5 + (np.zeros(0),)
    other = None if contacts is None else contacts.other
    if other is None or contacts.patch.size == 0:
        return empty
    tol = contacts.tol
    n = contacts.normal
    off = np.einsum("ij,ij->i", contacts.a, n)
    # One row per (plane, face, segment end).
    plane = np.concatenate([np.round(n, 6), np.round(off / tol)[:, None]], axis=1)
    b = contacts.a + contacts.length[:, None] * contacts.u
    ends = np.concatenate([contacts.a, b])
    rows = np.concatenate([np.arange(other.size)] * 2)
    key = np.concatenate([plane[rows], np.round(ends / tol), other[rows, None]], axis=1)
    key, first = np.unique(key, axis=0, return_index=True)
    rows, ends = rows[first], ends[first]
    # Ends sharing a (plane, point) with another face: the pairs of faces at one corner.
    _, group = np.unique(key[:, :-1], axis=0, return_inverse=True)
    group = group.reshape(-1)
    order = np.argsort(group, kind="stable")
    group, rows, ends = group[order], rows[order], ends[order]
    count = np.bincount(group)
    first = np.cumsum(count) - count
    i, j = [], []
    for k in range(2, int(count.max(initial=0)) + 1):      # per group size: a handful
        at = first[count == k]
        for p in range(k):
            for q in range(p + 1, k):
                i.append(at + p)
                j.append(at + q)
    if not i:
        return empty
    i, j = np.concatenate(i), np.concatenate(j)
    f1, f2 = other[rows[i]], other[rows[j]]
    c = 0.5 * (ends[i] + ends[j])
    nn = n[rows[i]].copy()
    # The plane's side the object stands on (a floor wound the other way has its normal down).
    mid1 = _centroids(scene, f1, *_points_of(scene, f1))
    nn *= np.where(np.einsum("ij,ij->i", mid1 - c, nn) < 0, -1.0, 1.0)[:, None]
    e = np.cross(scene.face_normals[f1], scene.face_normals[f2])
    norm = np.linalg.norm(e, axis=1)
    e = e / np.where(norm > 0, norm, 1.0)[:, None]
    e *= np.where(np.einsum("ij,ij->i", e, nn) < 0, -1.0, 1.0)[:, None]
    ok = (norm > 0.1) & (np.einsum("ij,ij->i", e, nn) > MIN_RISE)
    h1, d1 = _reach(scene, f1, c, e, nn)
    h2, d2 = _reach(scene, f2, c, e, nn)
    h = np.minimum(h1, h2)
    ok &= h > tol
    return c[ok], nn[ok], e[ok], d1[ok], d2[ok], h[ok]


def _points_of(scene, faces):
    """The points of ``faces``' corners and the index (into ``faces``) of each one's face."""
    corners, owner = _corners_of(scene, faces)
    return scene.vertices[corners], owner


def _reach(scene, faces, c, e, n):
    """Per row: the length along ``e`` from ``c`` to the top of face ``faces`` (its highest
    corner over the plane of normal ``n`` through ``c``), and the unit direction into the face
    from the edge (its centroid's offset, perpendicular to ``e``)."""
    x, owner = _points_of(scene, faces)
    up = np.einsum("ij,ij->i", x - c[owner], n[owner])
    top = np.full(faces.size, -np.inf)
    np.maximum.at(top, owner, up)
    d = _centroids(scene, faces, x, owner) - c
    d -= np.einsum("ij,ij->i", d, e)[:, None] * e
    rise = np.einsum("ij,ij->i", e, n)
    return top / np.where(rise > MIN_RISE, rise, 1.0), _unit(d)


def shadow_lines(scene, patches, contacts, min_share=MIN_SHARE, min_element=None):
    """The shadow lines leaving contact corners.

    Parameters
    ----------
    scene : core.scene.Scene
    patches : core.patches.Patches
        Patches of the scene (shadow rays test which lights a corner sees against them).
    contacts : core.contacts.Contacts
        The contact lines (:func:`core.contacts.find_contacts`), found on any patches of the
        scene: only their segments, faces and planes are read.
    min_share : float
        A light casts lines from a corner only if it gives at least this share of the corner's
        direct light (the bake passes its ``contrast``).
    min_element : float, optional
        The mesh's smallest element: a line stops where the wedge between its light's two
        lines is ``RESOLVED`` of them wide (None: at the shadow of its edge's top).

    Returns
    -------
    a, u : (k, 3) float64
        The line's corner and its unit direction, in the receiver's plane.
    length : (k,) float64
    n : (k, 3) float64
        The receiver plane's unit normal (on the side the object stands).
    """
    none = np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), np.zeros((0, 3))
    tol = contacts.tol
    c, n, e, d1, d2, h = contact_corners(scene, patches, contacts)
    lamps = _emissive_faces(scene)
    q, at_inf, group, aim = light_points(scene, lamps)
    if c.shape[0] == 0 or q.shape[0] == 0:
        return none
    r1 = _outward(n, d1, d2)
    step = max(1, PAIR_CHUNK // q.shape[0])
    found = [_candidates(c[s:s + step], n[s:s + step], e[s:s + step], d1[s:s + step],
                         d2[s:s + step], h[s:s + step], r1[s:s + step], q, at_inf, group, tol,
                         min_element)
             for s in range(0, c.shape[0], step)]
    ci = np.concatenate([f[0] + s for f, s in zip(found, range(0, c.shape[0], step))])
    qi, u, length, ang = (np.concatenate([f[k] for f in found]) for k in range(1, 5))
    if ci.size == 0:
        return none
    # Which lights matter at the corner: each light's direct light there (unshadowed, times
    # the share of its points seen from just outside the corner: a lamp in the next room,
    # behind a wall, is out), against all of them. A light giving less than ``min_share`` of
    # it draws a shadow edge of less contrast than the mesh refines for: no line.
    G = lamps[2] + (0 if scene.lights is None else len(scene.lights))
    x = c + OUTSIDE * h[:, None] * (r1 + n)
    light = _irradiance(scene, lamps, x, n, G)                                # (C, G)
    # The share of each light's points the corner sees, one ray each; only for the lights that
    # could matter: unshadowed, at least min_share of the brightest one there (a long ray to a
    # lamp rooms away costs like hundreds of short ones).
    light *= light >= min_share * light.max(axis=1, keepdims=True)
    cc, qq = np.nonzero(light[:, group] > 0)
    far = 2.0 * scene.bounding_diagonal()
    direction = np.where(at_inf[qq, None], far * aim[qq], aim[qq] - x[cc])
    bvh = build_bvh(ray_triangles(patches)[0])
    clear = ~any_hit(bvh, x[cc], direction, t_max=1.0 - 1e-9)
    seen = np.zeros((c.shape[0], G))
    np.add.at(seen, (cc, group[qq]), clear)
    light *= seen / np.maximum(np.bincount(group, minlength=G), 1)[None]
    total = light.sum(axis=1)
    keep = light[ci, group[qi]] >= np.maximum(min_share * total[ci], np.finfo(float).tiny)
    ci, qi, u, length, ang = ci[keep], qi[keep], u[keep], length[keep], ang[keep]
    if ci.size == 0:
        return none
    # A line is a shadow boundary only if, halfway along it, its light point is seen from one
    # side and hidden from the other (two rays): this drops lines that the corner's geometry
    # allows but the scene does not (a room's floor and wall meeting a partition's plane).
    mid = c[ci] + 0.5 * length[:, None] * u
    side = PROBE * 0.5 * length[:, None] * _unit(np.cross(n[ci], u))
    lift = OUTSIDE * np.minimum(h[ci], length)[:, None] * n[ci]
    seen = []
    for sign in (1.0, -1.0):
        probe = mid + sign * side + lift
        direction = np.where(at_inf[qi, None], far * q[qi], q[qi] - probe)
        seen.append(~any_hit(bvh, probe, direction, t_max=1.0 - 1e-9))
    keep = seen[0] != seen[1]
    ci, u, length, ang = ci[keep], u[keep], length[keep], ang[keep]
    if ci.size == 0:
        return none
    # One line per corner and direction.
    order = np.lexsort((ang, ci))
    ci, u, length, ang = ci[order], u[order], length[order], ang[order]
    keep = np.r_[True, (ci[1:] != ci[:-1]) | (np.diff(ang) > SAME_ANGLE)]
    ci, u, length = ci[keep][:MAX_LINES], u[keep][:MAX_LINES], length[keep][:MAX_LINES]
    return c[ci], u, length, n[ci]


def foot_lines(scene, patches, contacts, min_share=MIN_SHARE, min_element=None):
    """The shadow lines leaving contact corners (:func:`shadow_lines`) as
    :class:`core.contacts.Contacts` rows, one per patch a line crosses, for
    :func:`core.contacts.split_at_contacts`; and how many lines.

    A line cuts no patch where it would cross an edge nearer its ends than ``NEEDLE`` of
    the patch's size (``Contacts.min_gap``): unlike a contact, a shadow line need not be cut
    everywhere, and two lines meeting a wall's foot a hair apart made needles whose gather
    points stood behind the wall (tests/core/test_footlines.py).
    """
    tol = contacts.tol
    a, u, length, nl = shadow_lines(scene, patches, contacts, min_share, min_element)
    if a.shape[0] == 0:
        return no_contacts(scene, tol), 0
    w = _unit(np.cross(nl, u))
    # The patches each line crosses: same plane, boxes overlapping, crossed strictly.
    corners = np.asarray(patches.corners, dtype=np.float64)
    b = a + length[:, None] * u
    li, pi = box_pairs(np.minimum(a, b) - tol, np.maximum(a, b) + tol,
                       corners.min(axis=1) - tol, corners.max(axis=1) + tol,
                       max(float(np.median(np.sqrt(patches.areas))), tol))
    pn = np.asarray(patches.normals)[pi]
    same = (np.einsum("ij,ij->i", pn, nl[li]) > 1.0 - 1e-9) \
        & (np.abs(np.einsum("ij,ij->i", corners[pi, 0] - a[li], nl[li])) <= tol)
    li, pi = li[same], pi[same]
    k = np.where(triangle_mask(corners[pi]), 3, 4)
    size = np.sqrt(np.asarray(patches.areas, dtype=np.float64)[pi])
    hit = _crossed(corners[pi], k, size, a[li], u[li], w[li], length[li], tol) \
        & _clear_of_corners(corners[pi], k, size, a[li], w[li], NEEDLE)
    li, pi = li[hit], pi[hit]
    o = np.lexsort((li, pi))
    li, pi = li[o], pi[o]
    return Contacts(pi, a[li], u[li], w[li], length[li],
                    np.zeros(scene.vertices.shape[0], dtype=bool), tol,
                    min_gap=NEEDLE), int(a.shape[0])


def _outward(n, d1, d2):
    """Unit direction in the plane out of the object at each corner (the faces' bisector,
    reversed): the corner's lines lie within less than pi of it."""
    r1 = -(d1 + d2)
    return _unit(r1 - np.einsum("ij,ij->i", r1, n)[:, None] * n)


def _candidates(c, n, e, d1, d2, h, r1, q, at_inf, group, tol, min_element=None):
    """For corners (C,) and light points (Q,): per (corner, light) the two extreme shadow lines
    as (corner, point, unit direction, length, angle about the corner), each (k,); ``r1`` is
    each corner's :func:`_outward` direction."""
    # Every (corner, light point) pair: the plane through the edge and the point.
    to_l = np.where(at_inf[None, :, None], q[None], q[None] - c[:, None])     # (C, Q, 3)
    height = np.einsum("cqj,cj->cq", to_l, n)
    m = np.cross(e[:, None], to_l)
    s1 = np.einsum("cqj,cj->cq", m, d1)
    s2 = np.einsum("cqj,cj->cq", m, d2)
    # A point in the plane of one face sees that face edge-on: the limit of a silhouette.
    mm = np.linalg.norm(m, axis=2)
    s1 = np.where(np.abs(s1) <= 1e-9 * mm, 0.0, s1)
    s2 = np.where(np.abs(s2) <= 1e-9 * mm, 0.0, s2)
    ok = (height > 0) & (s1 * s2 >= 0) & (np.abs(s1) + np.abs(s2) > 0) & (mm > 0)
    # The shadow of the edge's top (kept under the light) on the plane.
    rise = np.einsum("cj,cj->c", e, n)
    top_h = np.minimum(h[:, None] * rise[:, None], np.where(at_inf[None], np.inf, 0.9 * height))
    top = c[:, None] + (top_h / rise[:, None])[..., None] * e[:, None]
    ray = np.where(at_inf[None, :, None], -q[None], top - q[None])              # light -> top
    down = -np.einsum("cqj,cj->cq", ray, n)
    ok &= down > 0
    s = top_h / np.where(ok, down, 1.0)
    t = top + s[..., None] * ray - c[:, None]
    t -= np.einsum("cqj,cj->cq", t, n)[..., None] * n[:, None]
    span = np.linalg.norm(t, axis=2)
    ok &= span > tol
    # The faces lie on one side of the plane through the edge and a point: which side tells
    # where the line falls. A light with points on both (a corner under a wide lamp, which
    # lights both faces) fans its lines out on both sides of the corner, and the two extremes
    # bound no penumbra: such a (corner, light) casts no line.
    G = int(group.max()) + 1
    side = np.where(s1 != 0, s1, s2) > 0
    pos = np.zeros((c.shape[0], G), dtype=bool)
    neg = np.zeros((c.shape[0], G), dtype=bool)
    cc, qq = np.nonzero(ok)
    np.logical_or.at(pos, (cc, group[qq]), side[cc, qq])
    np.logical_or.at(neg, (cc, group[qq]), ~side[cc, qq])
    ok &= ~(pos & neg)[:, group]
    ci, qi = np.nonzero(ok)
    if ci.size == 0:
        return ci, qi, np.zeros((0, 3)), np.zeros(0), np.zeros(0)
    u = t[ci, qi] / span[ci, qi, None]
    length = np.minimum(span[ci, qi], REACH * h[ci])
    r2 = np.cross(n, r1)
    ang = np.arctan2(np.einsum("kj,kj->k", u, r2[ci]), np.einsum("kj,kj->k", u, r1[ci]))
    # Per (corner, light): the two extreme lines, by angle about the corner.
    key = ci * np.int64(G) + group[qi]
    order = np.lexsort((ang, key))
    key = key[order]
    first = np.r_[True, key[1:] != key[:-1]]
    last = np.r_[key[1:] != key[:-1], True]
    pick = order[np.flatnonzero(first | last)]
    # Where the wedge between the two is RESOLVED minimum elements wide, the mesh draws the
    # penumbra by itself: the lines stop there (a point light's shadow edge stays sharp).
    if min_element is not None:
        sorted_ang = ang[order]
        spread = sorted_ang[last] - sorted_ang[first]           # per (corner, light)
        run = np.cumsum(first) - 1                              # of each sorted row
        wide = spread[run] > 0
        cap = np.full(run.size, np.inf)
        cap[wide] = RESOLVED * min_element / spread[run][wide]
        length[order] = np.minimum(length[order], cap)
    return ci[pick], qi[pick], u[pick], length[pick], ang[pick]
