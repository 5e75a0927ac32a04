"""Scene builders for the add-on tests (real Blender data through bpy)."""

import bpy
import numpy as np


def material(name, colour=(0.5, 0.5, 0.5), emission=None, strength=1.0, kind="principled"):
    """A node material: Principled (default), 'diffuse' or 'emission' shader."""
    mat = bpy.data.materials.new(name)
    if bpy.app.version < (5, 0, 0):
        mat.use_nodes = True  # on by default (and deprecated) from 5.0
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    out = nodes["Material Output"]
    if kind == "principled":
        bsdf = nodes["Principled BSDF"]
        bsdf.inputs["Base Color"].default_value = (*colour, 1.0)
        if emission is not None:
            bsdf.inputs["Emission Color"].default_value = (*emission, 1.0)
            bsdf.inputs["Emission Strength"].default_value = strength
        return mat
    nodes.remove(nodes["Principled BSDF"])
    if kind == "diffuse":
        node = nodes.new("ShaderNodeBsdfDiffuse")
        node.inputs["Color"].default_value = (*colour, 1.0)
    elif kind == "emission":
        node = nodes.new("ShaderNodeEmission")
        node.inputs["Color"].default_value = (*(emission or colour), 1.0)
        node.inputs["Strength"].default_value = strength
    else:
        raise ValueError(f"kind must be principled, diffuse or emission; got {kind!r}")
    links.new(node.outputs[0], out.inputs["Surface"])
    return mat


def mesh_object(name, verts, faces, mat=None, location=(0.0, 0.0, 0.0)):
    """A mesh object linked to the scene collection."""
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata([tuple(v) for v in verts], [], [tuple(f) for f in faces])
    mesh.update()
    obj = bpy.data.objects.new(name, mesh)
    obj.location = location
    bpy.context.scene.collection.objects.link(obj)
    if mat is not None:
        mesh.materials.append(mat)
    return obj


def square(size=1.0, z=0.0, down=False):
    """Vertices and one face of a square centred on the z axis, normal +z (or -z)."""
    h = 0.5 * size
    verts = [(-h, -h, z), (h, -h, z), (h, h, z), (-h, h, z)]
    face = (0, 3, 2, 1) if down else (0, 1, 2, 3)
    return verts, [face]


def box(size=1.0, inward=True):
    """A closed cube of quads centred at the origin, normals inward (or outward)."""
    h = 0.5 * size
    verts = [(x, y, z) for x in (-h, h) for y in (-h, h) for z in (-h, h)]
    faces = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    if inward:
        faces = [tuple(reversed(f)) for f in faces]
    return verts, faces


def read_colours(mesh, name="Radiosity"):
    """(C, 3) float64 colours of a corner colour attribute."""
    attr = mesh.color_attributes[name]
    buf = np.empty(len(attr.data) * 4, dtype=np.float32)
    attr.data.foreach_get("color", buf)
    return buf.reshape(-1, 4)[:, :3].astype(np.float64)


def cycles_corners(obj, samples, indirect=False):
    """Cycles' DIFFUSE bake of *obj*'s corners, (C, 3): direct light x colour, plus the
    indirect light with ``indirect`` (64 bounces, no clamp). Adaptive sampling is off: it would
    stop at its own noise threshold."""
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = samples
    scene.cycles.use_adaptive_sampling = False
    if indirect:
        scene.cycles.max_bounces = scene.cycles.diffuse_bounces = 64
        scene.cycles.sample_clamp_indirect = 0.0
    scene.render.bake.use_pass_direct = True
    scene.render.bake.use_pass_indirect = indirect
    scene.render.bake.use_pass_color = True
    mesh = obj.data
    if "cycles" not in mesh.color_attributes:
        mesh.color_attributes.new("cycles", "FLOAT_COLOR", "CORNER")
    mesh.color_attributes.active_color = mesh.color_attributes["cycles"]
    for other in scene.objects:
        other.select_set(False)
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj
    passes = {"DIRECT", "INDIRECT", "COLOR"} if indirect else {"DIRECT", "COLOR"}
    bpy.ops.object.bake(type="DIFFUSE", pass_filter=passes, target="VERTEX_COLORS")
    return read_colours(mesh, "cycles")


def set_settings(scene, **kw):
    props = scene.radiosity
    for key, value in kw.items():
        setattr(props, key, value)


class Layout:
    """Records what a panel draws (bpy layouts cannot be made outside a UI redraw)."""

    def __init__(self, log):
        self.log = log

    def __getattr__(self, name):
        if name in ("column", "row", "box", "split"):
            return lambda *a, **k: self
        if name == "panel_prop":  # a layout panel: header and (unfolded) body
            return lambda *a, **k: (self, self)
        if name in ("prop", "operator", "label"):
            return lambda *a, **k: self.log.append((name, a, k)) or self
        raise AttributeError(name)


def relight_labels(relight_ops, icon=None):
    """The labels the panel's Relight section draws (only those with ``icon``, when given)."""
    log = []
    relight_ops.draw(Layout(log), bpy.context.scene)
    return [k["text"] for kind, _, k in log
            if kind == "label" and (icon is None or k.get("icon") == icon)]
