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

from .geometry import pairs_by_key, within_crease
from .hemicube import point_rows
from .rows import RowStore

#: The gather point is moved from the vertex towards the centroids of its group's faces by this
#: fraction of the faces' size (sqrt of area): a fraction of a millimetre for 0.2 m faces. It
#: makes a vertex on a concave crease see the adjacent surface as the limit from inside its own
#: face (about half the hemisphere for a right angle) rather than exactly edge-on (nothing).
INSET = 1e-3

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
    pos = scene.vertices[scene.corner_verts[corners]]
    centroid = np.zeros((scene.n_faces, 3))
    np.add.at(centroid, faces, pos)
    centroid /= scene.face_sizes[:, None]

    # All ordered pairs of valid corners at the same vertex (a vertex has few corners).
    i, j = pairs_by_key(v)
    same = (mat[i] == mat[j]) & within_crease(n[i], n[j], crease_angle)
    single = np.zeros(valid_c.size, dtype=bool) if on_contact is None \
        else np.asarray(on_contact)[v]
    same &= ~single[i] | (i == j)
    i, j = i[same], j[same]
    # Smooth normal and inward direction of each corner: area-weighted over its surface's faces.
    # A face counted once per corner it has at the vertex (always one) -- fine.
    sn = np.zeros((valid_c.size, 3))
    np.add.at(sn, i, area[j, None] * n[j])
    sn /= np.linalg.norm(sn, axis=1, keepdims=True)
    inward = np.zeros((valid_c.size, 3))
    size = np.zeros(valid_c.size)
    w = np.zeros(valid_c.size)
    np.add.at(inward, i, centroid[f[j]] - scene.vertices[v[j]])
    np.add.at(size, i, np.sqrt(area[j]))
    np.add.at(w, i, 1.0)
    size /= w

    own = np.where(single, np.arange(valid_c.size), -1).astype(np.float64)
    key = np.concatenate([v[:, None].astype(np.float64), mat[:, None].astype(np.float64),
                          np.round(sn, NORMAL_DECIMALS), own[:, None]], axis=1)
    _, first_of, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    inverse = inverse.reshape(-1)
    direction = inward[first_of]
    # Remove the normal component (a non-planar face's centroid may sit off its plane).
    normal = sn[first_of]
    direction -= np.sum(direction * normal, axis=1, keepdims=True) * normal
    length = np.linalg.norm(direction, axis=1, keepdims=True)
    direction = np.divide(direction, length, out=np.zeros_like(direction), where=length > 0)
    points = scene.vertices[v[first_of]] + INSET * size[first_of, None] * direction
    group = np.full(C, -1, dtype=np.int64)
    group[valid_c] = inverse
    return CornerGroups(group, points, normal, mat[first_of])


def shade(scene, material, incident):
    """Outgoing radiance ``Le + rho * incident`` (n, 3) of receivers of ``material`` (n,)."""
    return np.asarray(scene.emission)[material] + np.asarray(scene.reflectance)[material] * incident


def gather_rows(patches, groups, *, resolution=64, rotate=True, rng=None, monitor=None,
                batch=64):
    """Hemicube rows at every group's gather point, kept compact (:class:`core.rows.RowStore`)."""
    G = groups.points.shape[0]
    store = RowStore(G, 2 * patches.areas.size)
    for s in range(0, G, batch):
        idx = np.arange(s, min(s + batch, G))
        rows = point_rows(patches, groups.points[idx], groups.normals[idx],
                          resolution=resolution, rotate=rotate, rng=rng)
        store.add(idx, rows)
        if monitor is not None:
            monitor.update(min(s + batch, G) / max(G, 1), f"gathering at {G} vertices")
    return store


def gathered_colours(scene, groups, store, node_radiance, fallback, direct=None):
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

    Returns
    -------
    (C, 3) float64
    """
    incident = store.incident(node_radiance)
    if direct is not None:
        incident = incident + direct
    L = shade(scene, groups.material, incident)
    out = np.array(fallback, dtype=np.float64, copy=True)
    ok = groups.group >= 0
    out[ok] = L[groups.group[ok]]
    return out
