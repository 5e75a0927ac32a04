"""Bake result -> Blender data: each object's baked mesh, or colours on the user's own corners.

Two outputs (``job.apply`` picks one):

* **Mesh** (:func:`write_mesh`, the default once the core produces ``BakeResult.output``): each
  baked object's mesh data is swapped for a new mesh holding the radiosity mesh
  (``core.outmesh.OutputMesh``) over that object's faces, with material indices, smooth/flat
  shading, every UV map and the ``Radiosity`` colours. The object keeps its identity (name,
  transform, parent, collections, material slots, custom properties, animation): only
  ``obj.data`` changes. The original mesh is kept with a fake user and remembered on the object
  (custom properties :data:`PROP_ORIGINAL`, :data:`PROP_FAKE_USER`); the modifiers applied into
  the baked mesh (those shown in the viewport) are switched off in viewport and render, their
  flags remembered (:data:`PROP_MODIFIERS`). :func:`clear_bake` restores all of it exactly.
  Extraction always reads the original (:func:`originals_for_reading`), so a re-bake starts from
  the user's mesh and modifiers, and a failed or cancelled bake leaves the scene as it was.
* **Existing Vertices** (:func:`write_colours`): the colours go onto the original mesh's corners.
  Corner colours are computed on the evaluated geometry (what the user sees); when modifiers
  change the topology, every original corner takes the baked lighting of the evaluated surface
  where that corner lies (``core.transfer.project_corners``).
"""

from contextlib import contextmanager

import bpy
import numpy as np

from ..core import transfer
from ..core.geometry import ragged
from ..core.transfer import CORNER_INSET  # noqa: F401  (the tolerance of the corner mapping)
from ..core.lux import daylight_factor, lux
from .extract import (ATTRIBUTE, ATTRIBUTE_TYPES, DF_ATTRIBUTE, LUX_ATTRIBUTE,
                      LUX_COLOUR_ATTRIBUTE, read_mesh_layout, transform)

#: Object custom property: the original mesh (an ID pointer) while the object shows a baked mesh.
PROP_ORIGINAL = "radiosity_original"
#: Object custom property: the original mesh's fake-user flag before the bake (0 or 1).
PROP_FAKE_USER = "radiosity_original_fake_user"
#: Object custom property: {modifier name: [show_viewport, show_render]} before the bake.
PROP_MODIFIERS = "radiosity_modifiers"
#: Custom property on a baked mesh (marks it as ours: Clear Bake may delete it).
PROP_BAKED = "radiosity_baked"
#: Suffix of a baked mesh's name.
BAKED_SUFFIX = ".radiosity"


class WriteError(RuntimeError):
    """Writing the result is impossible (linked data, name clash, a result that does not fit)."""


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
    sources, weights = transfer.project_corners(
        (world, cv, fs, fz),
        (part.world_vertices, part.corner_verts, part.face_starts, part.face_sizes))
    return transfer.interpolate(eval_colours, sources, weights)


# ------------------------------------------------------------------------ baked state of objects


def is_baked(obj):
    """True if *obj* shows a baked mesh (its original is remembered)."""
    return isinstance(obj.get(PROP_ORIGINAL), bpy.types.Mesh)


def original_mesh(obj):
    """The user's mesh of *obj*: the remembered original if baked, else ``obj.data``."""
    return obj[PROP_ORIGINAL] if is_baked(obj) else obj.data


def _show_original(obj):
    """Swap the original mesh and modifier flags back in; return the baked mesh (kept alive).

    Materials the user put into the baked mesh's slots while baked (the material slot list edits
    the object's mesh) go to the original's slots: a re-bake and Clear Bake keep that edit.
    """
    baked = obj.data
    baked.use_fake_user = True            # zero users for a moment must not lose it
    original = obj[PROP_ORIGINAL]
    mats = original.materials
    for i, mat in enumerate(baked.materials):
        if i >= len(mats):
            mats.append(mat)
        elif mats[i] != mat:
            mats[i] = mat
    obj.data = original
    flags = obj.get(PROP_MODIFIERS, {})
    for mod in obj.modifiers:
        if mod.name in flags:
            mod.show_viewport, mod.show_render = (bool(x) for x in flags[mod.name])
    return baked


def _show_baked(obj, baked):
    """Swap a baked mesh in and switch off the modifiers remembered as applied into it."""
    obj.data = baked
    baked.use_fake_user = False
    flags = obj.get(PROP_MODIFIERS, {})
    for mod in obj.modifiers:
        if mod.name in flags:
            mod.show_viewport = mod.show_render = False


@contextmanager
def originals_for_reading(scene, depsgraph):
    """Show every baked object of *scene* with its original mesh and modifiers for a while.

    Extraction runs inside: the depsgraph is re-evaluated on entry and on exit, and the baked
    state comes back whatever happens (so a bake that fails or is cancelled changes nothing).
    """
    baked = [(obj, None) for obj in scene.objects if is_baked(obj) and obj.library is None]
    if not baked:
        yield
        return
    baked = [(obj, _show_original(obj)) for obj, _ in baked]
    try:
        depsgraph.update()
        yield
    finally:
        for obj, mesh in baked:
            _show_baked(obj, mesh)
        depsgraph.update()


def clear_bake(objects):
    """Undo the bake on *objects*: baked meshes swapped back, ``Radiosity`` colours removed.

    A baked object gets its original mesh back (the same datablock, untouched), with its former
    fake-user flag and modifier flags; the baked mesh is deleted when nothing else uses it. Any
    other object's mesh loses the ``Radiosity`` attribute (Existing Vertices output) and nothing
    else.

    Parameters
    ----------
    objects : iterable of bpy.types.Object

    Returns
    -------
    int
        Number of objects restored plus meshes whose attribute was removed.
    """
    done = 0
    plain = set()
    memory = _Memory()
    for obj in objects:
        if obj.type != "MESH" or obj.library is not None:
            continue
        if is_baked(obj):
            memory.restore(obj)
            done += 1
        elif obj.data.library is None:
            plain.add(obj.data)
    return done + sum(clear_attribute(m) for m in plain)


class _Memory:
    """The pre-bake fake-user flag of every original mesh, over all baked objects of the file.

    Objects that share an original remember the same flag (the one before the first of them was
    baked), and the flag comes back only when the last of them is restored.
    """

    def __init__(self):
        self.flag, self.count = {}, {}
        for obj in bpy.data.objects:
            if obj.type == "MESH" and is_baked(obj):
                key = obj[PROP_ORIGINAL].as_pointer()
                self.flag.setdefault(key, bool(obj.get(PROP_FAKE_USER, 0)))
                self.count[key] = self.count.get(key, 0) + 1

    def restore(self, obj):
        """Original mesh, fake user and modifier flags back; our properties and mesh gone."""
        original = obj[PROP_ORIGINAL]
        key = original.as_pointer()
        baked = _show_original(obj)
        self.count[key] -= 1
        if self.count[key] == 0:
            original.use_fake_user = self.flag[key]
        for prop in (PROP_ORIGINAL, PROP_FAKE_USER, PROP_MODIFIERS):
            if prop in obj:
                del obj[prop]
        baked.use_fake_user = False
        if baked.users == 0 and baked.get(PROP_BAKED):
            bpy.data.meshes.remove(baked)

    def install(self, obj, baked):
        """Make *baked* the mesh of an unbaked *obj*, remembering the original state."""
        original = obj.data
        key = original.as_pointer()
        self.flag.setdefault(key, original.use_fake_user)
        self.count[key] = self.count.get(key, 0) + 1
        obj[PROP_ORIGINAL] = original
        obj[PROP_FAKE_USER] = int(self.flag[key])
        obj[PROP_MODIFIERS] = {m.name: [int(m.show_viewport), int(m.show_render)]
                               for m in obj.modifiers if m.show_viewport}
        original.use_fake_user = True
        _show_baked(obj, baked)


# ------------------------------------------------------------------------------ checks and writes


def check_writable(objects, make_single_user, *, mesh_output=False):
    """Raise WriteError unless every object can take the result.

    Parameters
    ----------
    objects : list of bpy.types.Object
        The original objects that will receive the result.
    make_single_user : bool
        Shared meshes will be copied (checked here, done by :func:`write_colours`).
    mesh_output : bool
        The result is a baked mesh per object (:func:`write_colours` otherwise): shared meshes
        are fine (each object gets its own baked mesh) and the original mesh is never written.
    """
    for obj in objects:
        if obj.library is not None or (not mesh_output and obj.data.library is not None):
            raise WriteError(f"Object '{obj.name}' uses linked data that cannot be written; "
                             "make it local first")
        if mesh_output:
            continue
        mesh = original_mesh(obj)
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
    write_corner_colours(mesh, ATTRIBUTE, "FLOAT_COLOR", colours)


def write_corner_colours(mesh, name, data_type, colours):
    """(C, 3) colours as the CORNER colour attribute ``name`` of type ``data_type``
    ('FLOAT_COLOR': linear; 'BYTE_COLOR': the values are sRGB), replacing an attribute of that
    name with another type or domain; made the active and the render colour."""
    attrs = mesh.color_attributes
    attr = attrs.get(name)
    if attr is not None and (attr.data_type != data_type or attr.domain != "CORNER"):
        attrs.remove(attr)
        attr = None
    if attr is None:
        attr = attrs.new(name, data_type, "CORNER")
    rgba = np.ones((colours.shape[0], 4), dtype=np.float32)
    rgba[:, :3] = colours
    attr.data.foreach_set("color" if data_type == "FLOAT_COLOR" else "color_srgb", rgba.ravel())
    attrs.active_color_name = name
    attrs.default_color_name = name
    mesh.update()


def write_lux(mesh, values, domain, outdoor=None):
    """Write illuminance (lx) as the FLOAT attribute :data:`LUX_ATTRIBUTE` of *mesh* on
    ``domain`` ('CORNER' or 'POINT'), replacing ours if it is there; with ``outdoor`` (lx, a
    sky's horizontal illuminance) the daylight factor (%) too, as :data:`DF_ATTRIBUTE` (else
    an old one is removed)."""
    n = len(mesh.loops) if domain == "CORNER" else len(mesh.vertices)
    values = np.asarray(values, dtype=np.float64).reshape(-1)
    if values.shape != (n,):
        raise WriteError(f"illuminance for mesh '{mesh.name}' must have {n} values "
                         f"({domain.lower()}s); got {values.size}")
    for name in (LUX_ATTRIBUTE, DF_ATTRIBUTE):
        attr = mesh.attributes.get(name)
        if attr is not None:
            mesh.attributes.remove(attr)
    mesh.attributes.new(LUX_ATTRIBUTE, "FLOAT", domain).data.foreach_set(
        "value", values.astype(np.float32))
    if outdoor is not None:
        mesh.attributes.new(DF_ATTRIBUTE, "FLOAT", domain).data.foreach_set(
            "value", daylight_factor(values, outdoor).astype(np.float32))


def clear_attribute(mesh):
    """Remove our attributes (colours, lux, daylight factor, lux in false colour) from *mesh*;
    True if there was one."""
    found = False
    for name in (ATTRIBUTE, LUX_COLOUR_ATTRIBUTE):
        attr = mesh.color_attributes.get(name)
        if attr is not None:
            mesh.color_attributes.remove(attr)
            found = True
    for name in (LUX_ATTRIBUTE, DF_ATTRIBUTE):
        attr = mesh.attributes.get(name)
        if attr is not None:
            mesh.attributes.remove(attr)
            found = True
    if found:
        mesh.update()
    return found


def write_colours(objects, parts, corner_colours, *, make_single_user, corner_lux=None,
                  outdoor=None):
    """Write the bake's colours to the original meshes.

    Parameters
    ----------
    objects : dict of str -> bpy.types.Object
        Original objects by name.
    parts : list of extract.Part
    corner_colours : (C, 3) float64
        The core's corner colours in scene corner order.
    make_single_user : bool
    corner_lux : (C,) float64, optional
        Illuminance (lx) at the scene corners, written as :data:`LUX_ATTRIBUTE`.
    outdoor : float, optional
        A sky's outdoor illuminance (lx): the daylight factor is written too (:func:`write_lux`).

    Returns
    -------
    int
        Number of meshes written.
    """
    targets = [objects[p.object_name] for p in parts]
    check_writable(targets, make_single_user)
    clear_bake([o for o in targets if is_baked(o)])   # colours go onto the user's own mesh
    for part in parts:
        obj = objects[part.object_name]
        mesh = obj.data
        if mesh.users - (1 if mesh.use_fake_user else 0) > 1:
            obj.data = mesh.copy()
            mesh = obj.data
        eval_colours = np.empty((part.corner_stop - part.corner_start, 3))
        eval_colours[part.eval_corner_of_scene] = corner_colours[part.corner_start:part.corner_stop]
        layout = read_mesh_layout(mesh)
        write_attribute(mesh, map_to_original(part, eval_colours, layout))
        if corner_lux is not None:
            eval_lux = np.empty((eval_colours.shape[0], 3))
            eval_lux[part.eval_corner_of_scene] = corner_lux[part.corner_start:
                                                             part.corner_stop, None]
            write_lux(mesh, map_to_original(part, eval_lux, layout)[:, 0], "CORNER",
                      outdoor=outdoor)
    return len(parts)


def output_by_part(parts, output):
    """Output faces of every part: list of (F_part,) int64 arrays, in output order.

    Raises WriteError if an output face lies in no part's faces (the result belongs to another
    scene) -- except faces of emitters that are not objects (area lights), which are dropped.
    """
    ends = [p.face_start + p.face_starts.size for p in parts]
    n_scene = max(ends + [int(output.face_parent.max()) + 1 if output.face_parent.size else 0])
    owner = np.full(n_scene, -1, dtype=np.int64)
    for i, part in enumerate(parts):
        owner[part.face_start:part.face_start + part.face_starts.size] = i
    own = owner[output.face_parent]
    order = np.argsort(own, kind="stable")
    counts = np.bincount(own[own >= 0], minlength=len(parts))
    bounds = np.concatenate([[0], np.cumsum(counts)]) + np.count_nonzero(own < 0)
    return [order[bounds[i]:bounds[i + 1]] for i in range(len(parts))]


def part_mesh(part, output, faces):
    """Arrays of the baked mesh of one part (object space, the object's own slots).

    Parameters
    ----------
    part : extract.Part
    output : core.outmesh.OutputMesh
    faces : (F,) int64
        Output faces of this part (:func:`output_by_part`).

    Returns
    -------
    dict
        ``vertices`` (V, 3), ``corner_verts`` (C,), ``face_starts``, ``face_sizes``,
        ``face_materials`` (F,) int64, ``face_smooth`` (F,) bool, ``colours`` (C, 3),
        ``uv_maps`` list of (name, (C, 2)), ``attributes`` list of (name, domain, data_type,
        values per output vertex, corner or face). Faces wind like their parent face of the
        user's mesh.
    """
    sizes = output.face_sizes[faces]
    owner, local, starts = ragged(sizes)
    corners = output.face_starts[faces][owner] + local
    n_part = part.corner_stop - part.corner_start
    src = output.corner_sources[corners] - part.corner_start
    if src.size and (src.min() < 0 or src.max() >= n_part):
        raise WriteError(f"The result for object '{part.object_name}' refers to corners of "
                         "another object; bake again")
    eval_src = part.eval_corner_of_scene[src]                       # (C, 3) evaluated corners
    weights = output.corner_weights[corners]
    parent = output.face_parent[faces] - part.face_start            # evaluated face
    pos = transfer.interpolate(part.object_vertices[part.corner_verts], eval_src, weights)
    # Faces wind like their parent in object space (a mirrored object's scene faces are reversed).
    cv_out = output.corner_verts[corners]
    normals, _ = transfer.face_frames(pos, np.arange(corners.size), starts, sizes)
    pnorm, _ = transfer.face_frames(part.object_vertices, part.corner_verts, part.face_starts,
                                    part.face_sizes)
    flip = np.einsum("ij,ij->i", normals, pnorm[parent]) < 0
    perm = np.where(flip[owner], starts[owner] + (sizes[owner] - local) % sizes[owner],
                    np.arange(corners.size))
    eval_src, weights, pos, cv_out = eval_src[perm], weights[perm], pos[perm], cv_out[perm]
    colours = output.corner_colours[corners][perm]
    corner_lux = None
    if output.corner_incident is not None:
        corner_lux = lux(output.corner_incident[corners][perm])
    verts, inverse = np.unique(cv_out, return_inverse=True)
    inverse = inverse.ravel()
    vpos = np.zeros((verts.size, 3))
    np.add.at(vpos, inverse, pos)
    vpos /= np.bincount(inverse, minlength=verts.size)[:, None]
    attributes = [(name, domain, kind, _carry(values, domain, eval_src, weights, part, parent,
                                              inverse, verts.size))
                  for name, domain, kind, values in part.attributes]
    return dict(vertices=vpos, corner_verts=inverse.astype(np.int64), face_starts=starts,
                attributes=attributes,
                face_sizes=sizes.astype(np.int64), face_materials=part.face_materials[parent],
                face_smooth=part.face_smooth[parent], colours=colours, lux=corner_lux,
                uv_maps=[(name, transfer.interpolate(uv, eval_src, weights))
                         for name, uv in part.uv_maps])


def _carry(values, domain, eval_src, weights, part, parent, inverse, n_verts):
    """An attribute of the evaluated mesh on the baked mesh's points, corners or faces.

    Real values are interpolated; integer and boolean ones take the value of the heaviest source.
    A point value is the mean over the output vertex's corners (they agree on a shared vertex).
    """
    if domain == "FACE":
        return values[parent]
    src = part.corner_verts[eval_src] if domain == "POINT" else eval_src
    if values.dtype.kind == "f":
        per_corner = transfer.interpolate(values, src, weights)
    else:
        per_corner = values[src[np.arange(src.shape[0]), weights.argmax(axis=1)]]
    if domain == "CORNER":
        return per_corner
    if per_corner.dtype.kind == "f":
        out = np.zeros((n_verts, per_corner.shape[1]))
        np.add.at(out, inverse, per_corner)
        return out / np.bincount(inverse, minlength=n_verts)[:, None]
    out = np.empty((n_verts, per_corner.shape[1]), dtype=per_corner.dtype)
    out[inverse] = per_corner
    return out


def new_mesh(name, arrays, part, materials):
    """A new mesh datablock from :func:`part_mesh` arrays."""
    mesh = bpy.data.meshes.new(name)
    nv, nc, nf = len(arrays["vertices"]), len(arrays["corner_verts"]), len(arrays["face_starts"])
    mesh.vertices.add(nv)
    mesh.loops.add(nc)
    mesh.polygons.add(nf)
    mesh.vertices.foreach_set("co", arrays["vertices"].astype(np.float32).ravel())
    mesh.loops.foreach_set("vertex_index", arrays["corner_verts"].astype(np.int32))
    mesh.polygons.foreach_set("loop_start", arrays["face_starts"].astype(np.int32))
    mesh.polygons.foreach_set("material_index", arrays["face_materials"].astype(np.int32))
    mesh.polygons.foreach_set("use_smooth", arrays["face_smooth"].astype(bool))
    mesh.update(calc_edges=True)
    for i, (uv_name, uv) in enumerate(arrays["uv_maps"]):
        layer = mesh.uv_layers.new(name=uv_name, do_init=False)
        layer.uv.foreach_set("vector", uv.astype(np.float32).ravel())
        if i == part.uv_active:
            mesh.uv_layers.active = layer
        if i == part.uv_render:
            layer.active_render = True
    for name, domain, kind, values in arrays["attributes"]:
        prop, _, dtype = ATTRIBUTE_TYPES[kind]
        mesh.attributes.new(name, kind, domain).data.foreach_set(prop, values.astype(dtype).ravel())
    for mat in materials:
        mesh.materials.append(mat)
    mesh[PROP_BAKED] = 1
    write_attribute(mesh, arrays["colours"])
    if arrays.get("lux") is not None:
        write_lux(mesh, arrays["lux"], "CORNER", outdoor=arrays.get("outdoor"))
    return mesh


def write_mesh(objects, parts, output, outdoor=None):
    """Give every baked object its baked mesh (the radiosity mesh over its faces).

    Parameters
    ----------
    objects : dict of str -> bpy.types.Object
        Original objects by name.
    parts : list of extract.Part
    output : core.outmesh.OutputMesh
    outdoor : float, optional
        A sky's outdoor illuminance (lx): the daylight factor is written beside the lux.

    Returns
    -------
    list of dict
        Per object: ``object``, ``input_faces`` (evaluated faces), ``output_vertices``,
        ``output_faces``.
    """
    targets = [objects[p.object_name] for p in parts]
    check_writable(targets, False, mesh_output=True)
    per_part = output_by_part(parts, output)
    # Everything is computed before the first object changes: an error leaves the scene as is.
    built = []
    for part, faces in zip(parts, per_part):
        built.append(dict(part_mesh(part, output, faces), outdoor=outdoor))
    summary = []
    memory = _Memory()
    for obj, part, arrays in zip(targets, parts, built):
        if is_baked(obj):
            memory.restore(obj)
        original = obj.data
        mesh = new_mesh(original.name + BAKED_SUFFIX, arrays, part, list(original.materials))
        memory.install(obj, mesh)
        summary.append(dict(object=obj.name, input_faces=int(part.face_starts.size),
                            output_vertices=len(mesh.vertices),
                            output_faces=len(mesh.polygons)))
    return summary


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
