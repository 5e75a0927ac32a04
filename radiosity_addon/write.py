"""Bake result -> the ``Radiosity`` colour attribute of each original mesh, and the viewport.

Corner colours are computed on the evaluated geometry (what the user sees). When modifiers keep
the topology, evaluated corners are the original corners one for one. When they change it
(subdivision, array, mirror, ...), every original corner is given the baked lighting of the
evaluated surface where that corner lies: a point just inside the corner's face, pushed along the
face normal onto the evaluated surface by a ray (core.raycast), and interpolated barycentrically
from the hit triangle's corner colours. Corners whose ray finds no compatible surface take the
colour of the nearest evaluated corner.
"""

import numpy as np

from ..core.raycast import build_bvh, closest_hit
from .extract import read_mesh_layout, transform

#: Name of the colour attribute the bake writes (and the only one it touches or clears).
ATTRIBUTE = "Radiosity"

#: Sample points sit this fraction of the way from a corner's vertex to its face's centroid, so the
#: sample falls inside that face (not on an edge shared with a creased neighbour) while staying at
#: the vertex for all practical purposes.
CORNER_INSET = 1e-3

#: Where the evaluated surface has shrunk away from a corner (Catmull-Clark rounds a cube's corners
#: off), the sample moves this far towards the face's centroid and tries again: the nearest part of
#: the same face that survived the modifier.
RETRY_INSETS = (0.25, 0.5)

#: An evaluated triangle may stand for an original face only if their normals are within ~75
#: degrees (cosine above this): subdivision tilts faces near corners, but never flips them.
NORMAL_AGREEMENT = 0.25

#: Evaluated corners per chunk of the nearest-corner fallback (bounds memory at ~8 MB per 1000).
NEAREST_CHUNK = 256


class WriteError(RuntimeError):
    """Writing the result is impossible (shared mesh data, linked data, name clash)."""


def _newell(points, corner_verts, face_starts, face_sizes):
    """Unnormalised Newell normals (F, 3) and centroids (F, 3) of polygons."""
    face_of = np.repeat(np.arange(face_starts.size), face_sizes)
    nxt = np.arange(corner_verts.size) + 1
    ends = face_starts + face_sizes
    nxt[ends - 1] = face_starts
    a = points[corner_verts]
    b = points[corner_verts[nxt]]
    cross = np.stack([(a[:, 1] - b[:, 1]) * (a[:, 2] + b[:, 2]),
                      (a[:, 2] - b[:, 2]) * (a[:, 0] + b[:, 0]),
                      (a[:, 0] - b[:, 0]) * (a[:, 1] + b[:, 1])], axis=1)
    normals = np.zeros((face_starts.size, 3))
    np.add.at(normals, face_of, cross)
    centroids = np.zeros((face_starts.size, 3))
    np.add.at(centroids, face_of, a)
    return normals, centroids / face_sizes[:, None]


def _unit(v):
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return np.divide(v, n, out=np.zeros_like(v), where=n > 0)


def _fan(face_starts, face_sizes):
    """Fan triangulation: (T, 3) corner indices."""
    ntri = face_sizes - 2
    first = np.repeat(face_starts, ntri)
    local = np.arange(ntri.sum()) - np.repeat(np.cumsum(ntri) - ntri, ntri)
    return np.stack([first, first + local + 1, first + local + 2], axis=1)


def map_to_original(part, eval_colours, orig_layout):
    """Colours of the original mesh's corners from the evaluated mesh's.

    Parameters
    ----------
    part : extract.Part
        Evaluated geometry (world metres) of the object.
    eval_colours : (C_eval, 3) float64
        Baked colour of every evaluated-mesh corner.
    orig_layout : tuple
        ``read_mesh_layout`` of the original mesh (object-space vertices).

    Returns
    -------
    (C_orig, 3) float64
    """
    verts, cv, fs, fz, _ = orig_layout
    if (cv.size == part.corner_verts.size and fs.size == part.face_starts.size
            and np.array_equal(cv, part.corner_verts) and np.array_equal(fs, part.face_starts)
            and np.array_equal(fz, part.face_sizes)):
        return eval_colours.copy()
    world = transform(verts, part.matrix_world)
    normals, centroids = _newell(world, cv, fs, fz)
    normals = _unit(normals)
    face_of = np.repeat(np.arange(fs.size), fz)
    p = world[cv]
    samples = p + CORNER_INSET * (centroids[face_of] - p)
    n = normals[face_of]
    reach = np.linalg.norm(centroids[face_of] - p, axis=1) + 1e-9

    ev = part.world_vertices
    tri_corners = _fan(part.face_starts, part.face_sizes)
    tri_pts = ev[part.corner_verts[tri_corners]]
    tri_n = _unit(np.cross(tri_pts[:, 1] - tri_pts[:, 0], tri_pts[:, 2] - tri_pts[:, 0]))
    bvh = build_bvh(tri_pts)
    out = np.empty((cv.size, 3))
    todo = np.arange(cv.size)
    for inset in (CORNER_INSET,) + RETRY_INSETS:
        s = p[todo] + inset * (centroids[face_of[todo]] - p[todo])
        nt = n[todo]
        # Start in front of the face at the face's own size and look back along -n: the first
        # surface met from the front is the evaluated version of this face (shrunk, shifted or
        # identical).
        origins = s + nt * reach[todo, None]
        t, tri = closest_hit(bvh, origins, -nt, 2.0 * reach[todo])
        ok = tri >= 0
        ok[ok] = np.einsum("ij,ij->i", tri_n[tri[ok]], nt[ok]) > NORMAL_AGREEMENT
        if np.any(ok):
            hit = origins[ok] - nt[ok] * t[ok, None]
            a, b, c = (tri_pts[tri[ok], k] for k in range(3))
            w = _barycentric(hit, a, b, c)
            cols = eval_colours[tri_corners[tri[ok]]]           # (K, 3 corners, 3 rgb)
            out[todo[ok]] = np.einsum("kj,kjc->kc", w, cols)
        todo = todo[~ok]
        if todo.size == 0:
            return out
    out[todo] = _nearest_corner_colours(samples[todo], n[todo], part, eval_colours)
    return out


def _barycentric(p, a, b, c):
    """(K, 3) barycentric weights of points p in triangles abc (clipped to the triangle)."""
    v0, v1, v2 = b - a, c - a, p - a
    d00 = np.einsum("ij,ij->i", v0, v0)
    d01 = np.einsum("ij,ij->i", v0, v1)
    d11 = np.einsum("ij,ij->i", v1, v1)
    d20 = np.einsum("ij,ij->i", v2, v0)
    d21 = np.einsum("ij,ij->i", v2, v1)
    den = d00 * d11 - d01 * d01
    den = np.where(np.abs(den) > 0, den, 1.0)
    v = (d11 * d20 - d01 * d21) / den
    w = (d00 * d21 - d01 * d20) / den
    bary = np.clip(np.stack([1.0 - v - w, v, w], axis=1), 0.0, None)
    return bary / np.maximum(bary.sum(axis=1, keepdims=True), 1e-30)


def _nearest_corner_colours(points, normals, part, eval_colours):
    """Colour of the nearest evaluated corner whose face agrees with the normal (else nearest)."""
    ev = part.world_vertices
    face_n, centroids = _newell(ev, part.corner_verts, part.face_starts, part.face_sizes)
    face_of = np.repeat(np.arange(part.face_starts.size), part.face_sizes)
    q = ev[part.corner_verts]
    q = q + CORNER_INSET * (centroids[face_of] - q)
    qn = _unit(face_n)[face_of]
    # Disagreeing corners are pushed beyond any real distance, so they win only if none agrees.
    far = 4.0 * (np.ptp(np.concatenate([ev, points]), axis=0) ** 2).sum() + 1.0
    best = np.empty(points.shape[0], dtype=np.int64)
    for a in range(0, points.shape[0], NEAREST_CHUNK):
        b = a + NEAREST_CHUNK
        d = ((points[a:b, None, :] - q[None]) ** 2).sum(-1)
        d += far * ((normals[a:b] @ qn.T) <= NORMAL_AGREEMENT)
        best[a:b] = d.argmin(axis=1)
    return eval_colours[best]


def check_writable(objects, make_single_user):
    """Raise WriteError unless every object's mesh can take its own colours.

    Parameters
    ----------
    objects : list of bpy.types.Object
        The original objects that will receive colours.
    make_single_user : bool
        Shared meshes will be copied (checked here, done by :func:`write_colours`).
    """
    for obj in objects:
        mesh = obj.data
        if mesh.library is not None or obj.library is not None:
            raise WriteError(f"Object '{obj.name}' uses linked data that cannot be written; "
                             "make it local first")
        users = mesh.users - (1 if mesh.use_fake_user else 0)
        if users > 1 and not make_single_user:
            raise WriteError(f"Mesh '{mesh.name}' is shared by {users} objects (one is "
                             f"'{obj.name}'), which would get each other's lighting; enable "
                             "'Make Single User' or give them their own mesh data")
        existing = mesh.attributes.get(ATTRIBUTE)
        if existing is not None and existing.data_type not in ("FLOAT_COLOR", "BYTE_COLOR"):
            raise WriteError(f"Mesh '{mesh.name}' already has a non-colour attribute named "
                             f"'{ATTRIBUTE}'; rename it to bake")


def write_attribute(mesh, colours):
    """Write (C, 3) colours as the FLOAT_COLOR CORNER attribute ``Radiosity`` of *mesh*.

    The attribute becomes the active and the render colour; no other attribute is changed.

    Parameters
    ----------
    mesh : bpy.types.Mesh
    colours : (C, 3) array_like of float, C = len(mesh.loops)
    """
    colours = np.asarray(colours, dtype=np.float64)
    if colours.shape != (len(mesh.loops), 3):
        raise WriteError(f"colours for mesh '{mesh.name}' must have shape "
                         f"({len(mesh.loops)}, 3); got {colours.shape}")
    attrs = mesh.color_attributes
    attr = attrs.get(ATTRIBUTE)
    if attr is not None and (attr.data_type != "FLOAT_COLOR" or attr.domain != "CORNER"):
        attrs.remove(attr)
        attr = None
    if attr is None:
        attr = attrs.new(ATTRIBUTE, "FLOAT_COLOR", "CORNER")
    rgba = np.ones((colours.shape[0], 4), dtype=np.float32)
    rgba[:, :3] = colours
    attr.data.foreach_set("color", rgba.ravel())
    attrs.active_color = attr
    attrs.render_color_index = attrs.find(ATTRIBUTE)
    mesh.update()


def clear_attribute(mesh):
    """Remove our attribute from *mesh*; True if there was one."""
    attr = mesh.color_attributes.get(ATTRIBUTE)
    if attr is None:
        return False
    mesh.color_attributes.remove(attr)
    mesh.update()
    return True


def write_colours(objects, parts, corner_colours, *, make_single_user):
    """Write the bake's colours to the original meshes.

    Parameters
    ----------
    objects : dict of str -> bpy.types.Object
        Original objects by name.
    parts : list of extract.Part
    corner_colours : (C, 3) float64
        The core's corner colours in scene corner order.
    make_single_user : bool

    Returns
    -------
    int
        Number of meshes written.
    """
    check_writable([objects[p.object_name] for p in parts], make_single_user)
    for part in parts:
        obj = objects[part.object_name]
        mesh = obj.data
        if mesh.users - (1 if mesh.use_fake_user else 0) > 1:
            obj.data = mesh.copy()
            mesh = obj.data
        eval_colours = np.empty((part.corner_stop - part.corner_start, 3))
        eval_colours[part.eval_corner_of_scene] = corner_colours[part.corner_start:part.corner_stop]
        write_attribute(mesh, map_to_original(part, eval_colours, read_mesh_layout(mesh)))
    return len(parts)


def show_in_viewports(screens, show=True):
    """Make Solid-mode 3D viewports show the baked colours flat (or restore material colours)."""
    for screen in screens:
        for area in screen.areas:
            if area.type != "VIEW_3D":
                continue
            for space in area.spaces:
                if space.type == "VIEW_3D":
                    shading = space.shading
                    shading.color_type = "VERTEX" if show else "MATERIAL"
                    shading.light = "FLAT" if show else "STUDIO"
            area.tag_redraw()
