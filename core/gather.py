"""Final gather: the radiance at every mesh vertex, gathered from the solved patches.

Averaging the patches around a vertex (:mod:`core.colours`) gives a patch-mean value, not the
value at the vertex: next to a luminaire, in a room corner or along a shadow edge the two differ by
tens of percent, and Cycles bakes the value at the vertex. So each corner's radiance is gathered at
its vertex: ``L = Le + rho * sum_j F(x -> j) L_j``, with the point-to-node form factors of a hemicube
placed at the vertex (a point receiver: no proximity error) and the nodes' solved radiance ``L_j``.

Corners are grouped first: corners at one vertex whose faces form one smooth surface (same
material, normals within the crease angle) share one gather, with the area-weighted mean normal of
those faces. The eye sits a hair inside the surface (towards the group's faces), so that at a crease
the adjacent wall is seen from the surface's side instead of exactly edge-on.
"""

import numpy as np

from .constants import tol
from .geometry import pairs_by_key, sum_at, unique_rows, within_crease
from .hemicube import point_rows
from .rows import RowStore

#: The gather point is moved from the vertex into its group's faces by this fraction of the
#: faces' size (sqrt of area): a fraction of a millimetre for 0.2 m faces. It makes a vertex on a
#: concave crease see the adjacent surface as the limit from inside its own face (about half the
#: hemisphere for a right angle) rather than exactly edge-on (nothing). The direction is the
#: bisector of the wedge the group's corners cover at the vertex (each corner's angle bisector,
#: weighted by its angle), not the way to the faces' centroids: a sliver's centroid lies almost
#: along its long edge, so a room corner of a CAD fan of slivers was moved along the adjacent wall
#: (microns from it), saw that wall edge-on and read 5-15 % low (tests/core/test_gather.py).
INSET = 1e-3

#: Narrowest wedge (sine of its half angle) whose gather point is moved out to full clearance:
#: a 1.1 deg wedge moves 100 x the inset along its bisector, narrower ones no further.
MIN_HALF_SINE = 0.01

#: A gather point stands at least this many hemicube near planes (``tol.hemicube_near`` x the
#: scene's diagonal) clear of both edges of its wedge. Nearer, the surface across the edge (the
#: floor at a box's foot) lies inside the near plane of the hemicube face looking at it, is
#: clipped away, and the point sees out through it: a box side's foot corner 2.8e-6 m over
#: the floor (a sliver leaf of the radiosity mesh, its inset from sqrt(area) tiny) read 1.87
#: for 2.0 in the white furnace; row sums 0.50 / 0.64 / 0.84 / 1.0 at 0.03 / 0.3 / 0.8 / 3
#: near planes over the floor (tests/core/test_fuzz.py).
NEAR_CLEARANCE = 10.0

#: The wedges of a vertex inside a smooth surface sum to zero up to rounding; a sum shorter than
#: this fraction of the angle they cover is taken as zero (the point stays at the vertex).
WEDGE_ROUNDING = 1e-9

#: Smooth normals are matched after rounding to this many decimals.
NORMAL_DECIMALS = 6


class CornerGroups:
    """Corners sharing a vertex and a smooth surface, with their gather points.

    Attributes
    ----------
    group : (C,) int64
        Group of every corner (-1: corner of a dropped face).
    points, normals : (G, 3) float64
        Gather point and unit normal of every group.
    material : (G,) int64
    """

    def __init__(self, group, points, normals, material):
        self.group, self.points, self.normals, self.material = group, points, normals, material


def corner_groups(scene, *, crease_angle=30.0, on_contact=None):
    """Group the scene's corners for the final gather (vectorised join by vertex).

    Parameters
    ----------
    scene : core.scene.Scene
    crease_angle : float
        Degrees: faces at a vertex whose normals differ by more are separate surfaces.
    on_contact : (V,) bool, optional
        Vertices whose corners are not grouped: each gathers on its own, with its face's normal,
        from a point moved into its own face. For vertices on a contact line
        (:class:`core.contacts.Contacts`): the floor corner of a face under a box must see the
        box's inside, the corner of the face beside it the room.

    Returns
    -------
    CornerGroups
    """
    corners, faces = scene.face_corner_indices()
    C = scene.n_corners
    face_of = np.full(C, -1, dtype=np.int64)
    face_of[corners] = faces
    valid_c = np.flatnonzero((face_of >= 0) & scene.face_valid[np.maximum(face_of, 0)])
    f = face_of[valid_c]
    v = scene.corner_verts[valid_c]
    n = scene.face_normals[f]
    mat = scene.face_materials[f]
    area = scene.face_areas[f]
    wedge = _corner_wedges(scene, corners, faces)[valid_c]

    # All ordered pairs of valid corners at the same vertex (a vertex has few corners).
    i, j = pairs_by_key(v)
    same = (mat[i] == mat[j]) & within_crease(n[i], n[j], crease_angle)
    single = np.zeros(valid_c.size, dtype=bool) if on_contact is None \
        else np.asarray(on_contact)[v]
    same &= ~single[i] | (i == j)
    i, j = i[same], j[same]
    # Smooth normal and inward direction of each corner: area-weighted over its surface's faces.
    # A face counted once per corner it has at the vertex (always one) -- fine.
    m = valid_c.size
    sn = sum_at(i, area[j, None] * n[j], m)
    sn /= np.linalg.norm(sn, axis=1, keepdims=True)
    inward = sum_at(i, wedge[j], m)
    turned = sum_at(i, np.linalg.norm(wedge[j], axis=1), m)  # the angle the group's corners cover
    size = sum_at(i, np.sqrt(area[j]), m) / np.bincount(i, minlength=m)

    own = np.where(single, np.arange(valid_c.size), -1).astype(np.float64)
    key = np.concatenate([v[:, None].astype(np.float64), mat[:, None].astype(np.float64),
                          np.round(sn, NORMAL_DECIMALS), own[:, None]], axis=1)
    first_of, inverse = unique_rows(key)
    direction = inward[first_of]
    # Remove the normal component (a non-planar face's corner may be tilted off its plane).
    normal = sn[first_of]
    direction -= np.sum(direction * normal, axis=1, keepdims=True) * normal
    length = np.linalg.norm(direction, axis=1, keepdims=True)
    # A vertex inside a smooth surface (its corners turn all the way round) stays where it is:
    # what is left of the wedges there is rounding, not a direction.
    moves = length[:, 0] > WEDGE_ROUNDING * turned[first_of]
    direction = np.divide(direction, length, out=np.zeros_like(direction),
                          where=moves[:, None])
    # Along the bisector far enough to stand INSET x size clear of both edges of the wedge
    # (a narrow wedge -- a sliver, a corner of its own at a contact -- would otherwise leave
    # the point next to the edge, seeing the wall on it edge-on), at most 1 / MIN_HALF_SINE
    # times that.
    half_sine = np.sin(0.5 * np.minimum(turned[first_of], np.pi))
    clearance = np.maximum(INSET * size[first_of],
                           NEAR_CLEARANCE * tol.hemicube_near
                           * (scene.bounding_diagonal() if valid_c.size else 0.0))
    reach = clearance / np.maximum(half_sine, MIN_HALF_SINE)
    offset = reach[:, None] * direction
    # Moved within the mean tangent plane, the point of a group across a fold (faces within the
    # crease angle) sits behind the faces of a convex fold, and on the fold line itself (both
    # faces edge-on) where the faces' wedges cancel across it. Lift it along the group's normal
    # until it stands in front of every face of its group by the offset times the face's tilt
    # (|n_face - n_group|): coplanar groups (and contact corners) are not moved off their plane.
    g = inverse[i]
    clear = reach[g] * np.linalg.norm(n[j] - normal[g], axis=1)
    depth = (clear - np.einsum("ij,ij->i", offset[g], n[j])) \
        / np.einsum("ij,ij->i", normal[g], n[j])
    lift = np.zeros(first_of.size)
    np.maximum.at(lift, g, depth)
    points = scene.vertices[v[first_of]] + offset + lift[:, None] * normal
    group = np.full(C, -1, dtype=np.int64)
    group[valid_c] = inverse
    return CornerGroups(group, points, normal, mat[first_of])


def shade(scene, material, incident):
    """Outgoing radiance ``Le + rho * incident`` (n, 3) of receivers of ``material`` (n,)."""
    return np.asarray(scene.emission)[material] + np.asarray(scene.reflectance)[material] * incident


def gather_rows(patches, groups, *, resolution=64, rotate=True, rng=None, monitor=None,
                batch=64, sky=None):
    """Hemicube rows at every group's gather point, kept compact (:class:`core.rows.RowStore`);
    with a directional ``sky`` (:class:`core.sky.Sky`), the store's ``sky`` holds its light at
    every point."""
    G = groups.points.shape[0]
    store = RowStore(G, 2 * patches.areas.size)
    if sky is not None:
        store.sky = np.zeros((G, 3))
    for s in range(0, G, batch):
        idx = np.arange(s, min(s + batch, G))
        light = None if sky is None else np.zeros((idx.size, 3))
        rows = point_rows(patches, groups.points[idx], groups.normals[idx],
                          resolution=resolution, rotate=rotate, rng=rng, sky=sky, sky_out=light)
        store.add(idx, rows, light)
        if monitor is not None:
            monitor.update(min(s + batch, G) / max(G, 1), f"gathering at {G} vertices")
    return store


def gathered_colours(scene, groups, store, node_radiance, fallback, direct=None, creases=None):
    """Corner colours from the kept gather rows: ``Le + rho * incident`` of each corner's group.

    Parameters
    ----------
    scene : core.scene.Scene
    groups : CornerGroups
    store : core.rows.RowStore
    node_radiance : (2P, 3) float
    fallback : (C, 3) float
        Colours for corners of dropped faces (group -1).
    direct : (G, 3) float, optional
        Light from beyond the hemicube's surfaces (irradiance / pi,
        :meth:`core.lights.DirectLight.extra`: the lights' direct light and the world's
        share) at every group.
    creases : core.creases.Creases, optional
        Row entries read at the light of a concave crease (:mod:`core.creases`).

    Returns
    -------
    (C, 3) float64, and the light arriving at every group (G, 3) float64 (irradiance / pi)
    """
    incident = store.incident(node_radiance)
    if direct is not None:
        incident = incident + direct
    if creases is not None:
        incident = creases.incident(scene, groups.material, incident, node_radiance)
    L = shade(scene, groups.material, incident)
    out = np.array(fallback, dtype=np.float64, copy=True)
    ok = groups.group >= 0
    out[ok] = L[groups.group[ok]]
    return out, incident


def corner_values(scene, corner_verts, groups, incident):
    """(C, 3) outgoing radiance and (C, 3) incident light of the corners of ``groups`` from
    the ``incident`` light (G, 3) of the groups (corners of no group borrow at their vertex,
    :func:`borrow_at_vertex`); ``corner_verts`` (C,) the corners' vertices."""
    ok = groups.group >= 0
    value = np.zeros((corner_verts.size, 3))
    value[ok] = shade(scene, groups.material, incident)[groups.group[ok]]
    inc = np.zeros((corner_verts.size, 3))
    inc[ok] = incident[groups.group[ok]]
    return borrow_at_vertex(corner_verts, ok, value), borrow_at_vertex(corner_verts, ok, inc)


def borrow_at_vertex(corner_verts, valid, values):
    """``values`` (C, 3) with every corner that is not ``valid`` (C,) given the mean of the
    valid corners at its vertex (unchanged where its vertex has none).

    A face too thin to have a normal (a sliver that float64 rounding leaves in the conforming
    mesh of a model far from the origin) gathers nothing; its corners would read black in the
    written mesh, and a viewer draws that black along the sliver.
    """
    valid = np.asarray(valid, dtype=bool)
    if valid.all():
        return values
    n_v = int(corner_verts.max()) + 1 if corner_verts.size else 0
    total = np.zeros((n_v, values.shape[1]))
    count = np.zeros(n_v)
    np.add.at(total, corner_verts[valid], values[valid])
    np.add.at(count, corner_verts[valid], 1.0)
    out = values.copy()
    bad = np.flatnonzero(~valid)
    has = count[corner_verts[bad]] > 0
    out[bad[has]] = total[corner_verts[bad[has]]] / count[corner_verts[bad[has]], None]
    return out


def _corner_wedges(scene, corners, faces):
    """(C, 3): every corner's angle bisector, inside its face, times the corner's angle (rad).

    Reflex corners of concave n-gons point into the face too (the bisector of the two edges,
    turned round, with the angle 2 pi minus the edges' angle). Zero for a corner whose edges have
    no length.
    """
    C = scene.n_corners
    out = np.zeros((C, 3))
    if corners.size == 0:
        return out
    start = scene.face_starts[faces]
    size = scene.face_sizes[faces]
    k = corners - start
    here = scene.vertices[scene.corner_verts[corners]]
    e_prev = scene.vertices[scene.corner_verts[start + (k - 1) % size]] - here
    e_next = scene.vertices[scene.corner_verts[start + (k + 1) % size]] - here
    lp = np.linalg.norm(e_prev, axis=1, keepdims=True)
    ln = np.linalg.norm(e_next, axis=1, keepdims=True)
    ok = (lp[:, 0] > 0) & (ln[:, 0] > 0)
    up = np.divide(e_prev, lp, out=np.zeros_like(e_prev), where=lp > 0)
    un = np.divide(e_next, ln, out=np.zeros_like(e_next), where=ln > 0)
    cosang = np.clip(np.einsum("ij,ij->i", up, un), -1.0, 1.0)
    angle = np.arccos(cosang)
    # The winding's own normal (Newell), not face_normals: a face turned to the room by
    # core.orient keeps its winding, and its convex corners would all look reflex.
    origin = scene.vertices[scene.corner_verts[start]]
    winding = np.zeros((scene.n_faces, 3))
    np.add.at(winding, faces, np.cross(here - origin, e_next + here - origin))
    # Counter-clockwise about the winding normal: at a convex corner next x prev points along it.
    reflex = np.einsum("ij,ij->i", np.cross(un, up), winding[faces]) < 0
    bis = up + un
    lb = np.linalg.norm(bis, axis=1, keepdims=True)
    # Edges turning back on themselves (angle pi): the bisector is the in-plane perpendicular.
    flat = lb[:, 0] < 1e-9
    perp = np.cross(winding[faces], un)
    perp /= np.maximum(np.linalg.norm(perp, axis=1, keepdims=True), np.finfo(float).tiny)
    bis = np.where(flat[:, None], perp, np.divide(bis, lb, out=np.zeros_like(bis), where=lb > 0))
    bis = np.where(reflex[:, None] & ~flat[:, None], -bis, bis)
    angle = np.where(reflex, 2.0 * np.pi - angle, angle)
    out[corners] = np.where(ok[:, None], bis * angle[:, None], 0.0)
    return out
