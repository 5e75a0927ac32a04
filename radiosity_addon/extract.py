"""Blender scene -> the core's arrays (Blender's own corner layout, world space, metres).

Everything visible and renderable in the evaluated depsgraph takes part: modifiers applied,
collection and geometry-node instances included, world transforms and the scene's unit scale
applied. Only real (non-instance) mesh objects receive the result; instances light and shadow
the scene but share their mesh data with their source, so nothing is written to them.
Area lights become emitting polygons (see :func:`_add_light`); point, spot and sun lights become
``core.light_list.Lights`` (:func:`light_dict`), in ``arrays["lights"]``.
"""

from dataclasses import dataclass, field

import bpy
import numpy as np

from ..core.errors import SceneError
from ..core.light_list import make_lights
from ..core.photometry import read_photometry
from .materials import MaterialReader, area_light_polygon, area_light_radiance
from .surfaces import is_calc_surface, read_surface
from .world_map import read_world

#: An area light is modelled as a one-sided emitting polygon: its front emits the converted
#: radiance, it reflects nothing, and its back side is black (the core's back_reflectance /
#: back_emission), as a Cycles area light emits from its front only. Unlike Cycles' light it
#: still casts a shadow from behind (a polygon in the scene); a light hung in the open is thin
#: enough that this is rarely visible.


@dataclass
class Part:
    """One mesh object's share of the scene arrays, for writing the result back.

    Attributes
    ----------
    object_name : str
        Name of the original object that receives the colours.
    corner_start, corner_stop : int
        Its scene corners are ``corner_start:corner_stop``; they are the evaluated mesh's corners
        in order, except that faces of a mirrored object (negative determinant) are reversed.
    eval_corner_of_scene : (C_part,) int64
        Evaluated-mesh corner of every scene corner of the part.
    world_vertices : (V_eval, 3) float64
        Evaluated vertices in world metres (for mapping onto the original mesh's corners).
    corner_verts, face_starts, face_sizes : int64 arrays
        The evaluated mesh's layout (its own indices).
    matrix_world : (4, 4) float64
        Object to world, unit scale included.
    face_start : int
        Scene index of the part's first face; its faces are the evaluated faces in order.
    object_vertices : (V_eval, 3) float64
        Evaluated vertices in object space (what a baked mesh stores).
    face_materials : (F_eval,) int64
        Material slot index of every evaluated face (the object's own slots).
    face_smooth : (F_eval,) bool
        Smooth shading of every evaluated face.
    uv_maps : list of (str, (C_eval, 2) float64)
        Every UV map of the evaluated mesh, by name, in the mesh's order.
    uv_active, uv_render : int
        Index of the active and of the render UV map (-1 without UV maps).
    attributes : list of (name, domain, data_type, (N, k) array)
        The evaluated mesh's other attributes on points, corners and faces
        (:func:`read_attributes`).
    """

    object_name: str
    corner_start: int
    corner_stop: int
    eval_corner_of_scene: np.ndarray
    world_vertices: np.ndarray
    corner_verts: np.ndarray
    face_starts: np.ndarray
    face_sizes: np.ndarray
    matrix_world: np.ndarray
    face_start: int = 0
    object_vertices: np.ndarray = None
    face_materials: np.ndarray = None
    face_smooth: np.ndarray = None
    uv_maps: list = field(default_factory=list)
    uv_active: int = -1
    uv_render: int = -1
    attributes: list = field(default_factory=list)


@dataclass
class Extraction:
    """What :func:`extract` read: the make_scene arguments, the parts to write, the notes.

    ``lights`` counts every light read (area, point, spot and sun), ``area_lights`` the area
    lights among them; ``surfaces`` are the calculation surfaces (left out of the arrays).
    """

    arrays: dict
    parts: list
    warnings: list = field(default_factory=list)
    notes: list = field(default_factory=list)
    instances: int = 0
    lights: int = 0
    area_lights: int = 0
    surfaces: list = field(default_factory=list)    # surfaces.CalcSurface


def read_mesh_layout(mesh):
    """Vertices and face layout of a mesh through float32/int32 foreach_get buffers.

    Returns
    -------
    vertices : (V, 3) float64 (object space)
    corner_verts : (C,) int64
    face_starts, face_sizes, face_materials : (F,) int64
    """
    nv, nc, nf = len(mesh.vertices), len(mesh.loops), len(mesh.polygons)
    co = np.empty(nv * 3, dtype=np.float32)
    mesh.vertices.foreach_get("co", co)
    cv = np.empty(nc, dtype=np.int32)
    mesh.loops.foreach_get("vertex_index", cv)
    starts = np.empty(nf, dtype=np.int32)
    sizes = np.empty(nf, dtype=np.int32)
    mats = np.empty(nf, dtype=np.int32)
    mesh.polygons.foreach_get("loop_start", starts)
    mesh.polygons.foreach_get("loop_total", sizes)
    mesh.polygons.foreach_get("material_index", mats)
    return (co.reshape(nv, 3).astype(np.float64), cv.astype(np.int64), starts.astype(np.int64),
            sizes.astype(np.int64), mats.astype(np.int64))


def read_face_smooth(mesh):
    """(F,) bool: smooth shading of every face."""
    smooth = np.empty(len(mesh.polygons), dtype=bool)
    mesh.polygons.foreach_get("use_smooth", smooth)
    return smooth


def read_uv_maps(mesh):
    """Every UV map as (name, (C, 2) float64), and the active and render map indices."""
    maps, active, render = [], -1, -1
    for i, layer in enumerate(mesh.uv_layers):
        buf = np.empty(len(mesh.loops) * 2, dtype=np.float32)
        layer.uv.foreach_get("vector", buf)
        maps.append((layer.name, buf.reshape(-1, 2).astype(np.float64)))
        if layer.active:
            active = i
        if layer.active_render:
            render = i
    return maps, active, render


#: Attribute data types carried onto a baked mesh: foreach property, width, NumPy dtype.
ATTRIBUTE_TYPES = {"FLOAT": ("value", 1, np.float32), "FLOAT2": ("vector", 2, np.float32),
                   "FLOAT_VECTOR": ("vector", 3, np.float32),
                   "FLOAT_COLOR": ("color", 4, np.float32), "BYTE_COLOR": ("color", 4, np.float32),
                   "INT": ("value", 1, np.int32), "INT8": ("value", 1, np.int32),
                   "BOOLEAN": ("value", 1, bool)}

#: Name of the colour attribute the bake writes.
ATTRIBUTE = "Radiosity"

#: Name of the FLOAT attribute of illuminance (lx) the bake writes: per corner on baked meshes,
#: per point on calculation surfaces. With ATTRIBUTE, the only ones it touches or clears.
LUX_ATTRIBUTE = "Radiosity Lux"

LUX_COLOUR_ATTRIBUTE = "Radiosity Lux Colour"  #: lux in false colour, while shown (luxview.py)
#: Name of the FLOAT attribute of the daylight factor (%), beside the lux after a bake under a
#: sky (``sky='cie_overcast'``).
DF_ATTRIBUTE = "Radiosity Daylight Factor"

#: Attributes a baked mesh gets otherwise (geometry, UV maps, material, shading) or never keeps.
OWN_ATTRIBUTES = {"position", "material_index", "sharp_face", ATTRIBUTE, LUX_ATTRIBUTE,
                  DF_ATTRIBUTE, LUX_COLOUR_ATTRIBUTE}


def read_attributes(mesh):
    """The user's attributes on points, corners and faces, as arrays.

    Internal (``.name``), geometry, UV-map, material-index and shading attributes are left out
    (the baked mesh has its own), as are edge attributes and types not in
    :data:`ATTRIBUTE_TYPES`.

    Returns
    -------
    list of (name, domain, data_type, (N, k) array)
    """
    skip = OWN_ATTRIBUTES | {layer.name for layer in mesh.uv_layers}
    out = []
    for attr in mesh.attributes:
        kind = ATTRIBUTE_TYPES.get(attr.data_type)
        if (kind is None or attr.domain not in ("POINT", "CORNER", "FACE")
                or attr.name.startswith(".") or attr.name in skip):
            continue
        prop, width, dtype = kind
        buf = np.empty(len(attr.data) * width, dtype=dtype)
        attr.data.foreach_get(prop, buf)
        out.append((attr.name, attr.domain, attr.data_type, buf.reshape(-1, width)))
    return out


def transform(points, matrix):
    """Apply a (4, 4) affine matrix to (N, 3) points."""
    return points @ matrix[:3, :3].T + matrix[:3, 3]


def _reverse_faces(face_starts, face_sizes):
    """Corner permutation that reverses every face's winding, keeping its first corner.

    Returns (C,) int64 ``perm``: new corner k of a face reads old corner ``perm[k]``.
    """
    c = int(face_sizes.sum())
    face_of = np.repeat(np.arange(face_starts.size), face_sizes)
    local = np.arange(c) - np.repeat(np.cumsum(face_sizes) - face_sizes, face_sizes)
    rev = np.where(local == 0, 0, face_sizes[face_of] - local)
    return face_starts[face_of] + rev


def _is_visible(inst, view_layer, selected_only):
    obj = inst.object.original
    if obj.hide_render:
        return False
    if inst.is_instance:
        owner = inst.parent.original if inst.parent is not None else obj
        if owner.hide_render:
            return False
        return owner.select_get(view_layer=view_layer) if selected_only else True
    if not obj.visible_get(view_layer=view_layer):
        return False
    return obj.select_get(view_layer=view_layer) if selected_only else True


def extract(depsgraph, *, selected_only=False, world=True):
    """Read the evaluated scene into the core's arrays.

    Objects that show a baked mesh are read with their original mesh and modifiers
    (``write.originals_for_reading``), so a bake always starts from the user's geometry.

    Parameters
    ----------
    depsgraph : bpy.types.Depsgraph
        An evaluated depsgraph (``context.evaluated_depsgraph_get()``).
    selected_only : bool
        Only selected mesh objects (and instances whose instancer is selected) take part and are
        written. Lights always take part.
    world : bool
        Read the scene's world (its light, and its sun disc as a sun light); False when the
        bake's ``sky`` setting replaces it (``sky='cie_overcast'``: an overcast sky has no sun).

    Returns
    -------
    Extraction
        ``arrays`` holds the keyword arguments of ``core.scene.make_scene``.
    """
    from .write import originals_for_reading   # write imports this module

    with originals_for_reading(depsgraph.scene, depsgraph):
        return _extract(depsgraph, selected_only, world)


def _extract(depsgraph, selected_only, world):
    scene = depsgraph.scene_eval
    view_layer = depsgraph.view_layer
    scale = float(scene.unit_settings.scale_length) or 1.0
    unit = np.diag([scale, scale, scale, 1.0])
    reader = MaterialReader()
    out = Extraction(arrays={}, parts=[])
    verts, corner_verts, starts, sizes, face_mats, face_objs = [], [], [], [], [], []
    mat_keys, rho, le, object_names = {}, [], [], []
    one_sided = []  # materials whose back side is black (area lights)
    nv = nc = 0
    no_material = []
    ignored = []
    unsupported = {}             # light type -> names of lights we cannot bake
    light_dicts = []             # point, spot and sun lights for core.make_lights
    light_notes = {}             # approximation -> light names
    no_diffuse = []              # lights whose diffuse ray visibility is off

    def material_index(mat):
        key = None if mat is None else mat.original.name_full
        if key not in mat_keys:
            r, e = reader.evaluate(None if mat is None else mat.original)
            mat_keys[key] = len(rho)
            rho.append(r)
            le.append(e)
        return mat_keys[key]

    def add_faces(v_world, cv, fs, fz, fm, obj_index):
        nonlocal nv, nc
        verts.append(v_world)
        corner_verts.append(cv + nv)
        starts.append(fs + nc)
        sizes.append(fz)
        face_mats.append(fm)
        face_objs.append(np.full(fs.size, obj_index, dtype=np.int64))
        nv += v_world.shape[0]
        nc += cv.size

    for inst in depsgraph.object_instances:
        obj = inst.object
        if obj.type not in ("MESH", "LIGHT"):
            if obj.type in ("CURVE", "SURFACE", "FONT", "META", "CURVES", "POINTCLOUD", "VOLUME"):
                ignored.append(obj.name)
            continue
        if obj.type == "LIGHT":
            if obj.original.hide_render:
                continue
            if not getattr(obj, "visible_diffuse", True):
                # Cycles: a light without diffuse ray visibility lights no diffuse surface.
                no_diffuse.append(obj.name)
                continue
            if obj.data.type in LIGHT_KINDS:
                light_dicts.append(light_dict(inst, light_notes))
                out.lights += 1
            elif obj.data.type == "AREA":
                _add_light(inst, unit, out, add_faces, object_names, rho, le, mat_keys, one_sided)
            else:
                unsupported.setdefault(obj.data.type.capitalize(), []).append(obj.name)
            continue
        if is_calc_surface(obj):          # measures the light, takes no part in it
            if not inst.is_instance and obj.original.visible_get(view_layer=view_layer):
                mesh = obj.to_mesh()
                layout = read_mesh_layout(mesh)
                obj.to_mesh_clear()
                if layout[2].size:
                    out.surfaces.append(read_surface(
                        obj, unit @ np.array(inst.matrix_world, dtype=np.float64), layout))
            continue
        if not _is_visible(inst, view_layer, selected_only):
            continue
        mesh = obj.to_mesh()
        try:
            v, cv, fs, fz, fm = read_mesh_layout(mesh)
            slots = [s.material for s in obj.material_slots]
            if not inst.is_instance and fs.size:
                smooth = read_face_smooth(mesh)
                uv_maps, uv_active, uv_render = read_uv_maps(mesh)
                attributes = read_attributes(mesh)
        finally:
            obj.to_mesh_clear()
        if fs.size == 0:
            continue
        matrix = unit @ np.array(inst.matrix_world, dtype=np.float64)
        v_world = transform(v, matrix)
        table = np.array([material_index(m) for m in slots] or [material_index(None)])
        if not slots or any(m is None for m in slots):
            no_material.append(obj.name)
        fm_global = table[np.clip(fm, 0, table.size - 1)]
        # A mirrored transform flips the winding; Cycles keeps the front where the user sees it,
        # so the faces are reversed to keep Newell normals on the side Cycles bakes.
        if np.linalg.det(matrix[:3, :3]) < 0:
            perm = _reverse_faces(fs, fz)
        else:
            perm = np.arange(cv.size, dtype=np.int64)
        obj_index = len(object_names)
        object_names.append(obj.name if not inst.is_instance else f"{obj.name} (instance)")
        if inst.is_instance:
            out.instances += 1
        else:
            out.parts.append(Part(obj.original.name, nc, nc + cv.size, perm, v_world, cv, fs, fz,
                                  matrix, face_start=sum(x.size for x in starts),
                                  object_vertices=v, face_materials=fm, face_smooth=smooth,
                                  uv_maps=uv_maps, uv_active=uv_active, uv_render=uv_render,
                                  attributes=attributes))
        add_faces(v_world, cv[perm], fs, fz, fm_global, obj_index)

    if no_material:
        out.warnings.append(f"No material on {_names(no_material)}: used the default grey "
                            f"reflectance 0.8")
    if ignored:
        out.warnings.append(f"Non-mesh objects ignored: {_names(ignored)}")
    if out.instances:
        out.notes.append(f"{out.instances} instance(s) light and shadow the scene but receive no "
                         "colours (they share their source's mesh)")
    world_radiance, world_sun, world_note = read_world(scene) if world else (None, None, None)
    if world_note:
        out.notes.append(world_note)
    if world_sun is not None:
        light_dicts.append(world_sun)
    out.warnings.extend(f"{kind} lights are not supported yet and were ignored: {_names(names)}"
                        for kind, names in unsupported.items())
    out.warnings.extend(f"{what}: {_names(names)}" for what, names in light_notes.items())
    if no_diffuse:
        out.notes.append(f"Lights with Diffuse ray visibility off light no diffuse surface (as "
                         f"in Cycles) and were left out: {_names(no_diffuse)}")
    out.notes.extend(reader.notes)
    if verts:
        out.arrays = dict(
            vertices=np.concatenate(verts), corner_verts=np.concatenate(corner_verts),
            face_starts=np.concatenate(starts), face_sizes=np.concatenate(sizes),
            face_materials=np.concatenate(face_mats), reflectance=np.array(rho),
            emission=np.array(le), face_objects=np.concatenate(face_objs),
            object_names=tuple(object_names),
            material_names=tuple(_material_name(k) for k in mat_keys))
        if one_sided:
            back_rho = out.arrays["reflectance"].copy()
            back_le = out.arrays["emission"].copy()
            back_rho[one_sided] = 0.0
            back_le[one_sided] = 0.0
            out.arrays.update(back_reflectance=back_rho, back_emission=back_le)
        if light_dicts:
            # Cycles works in Blender units whatever the unit scale: the lights keep their
            # irradiance at Blender-unit distances (positions and radii in metres, intensity
            # times scale^2) -- measured, see tests/addon/test_lights.py.
            out.arrays["lights"] = make_lights(light_dicts).scaled(scale)
        if world_radiance is not None:
            out.arrays["world"] = world_radiance
    return out


#: Blender light types read as core.lights kinds (AREA lights are polygons, _add_light).
LIGHT_KINDS = {"POINT": "point", "SPOT": "spot", "SUN": "sun"}

#: Relative spread of a spot light's three world scale factors above which its cone is not round
#: (Cycles scales the cone with the object; the core's cone is round).
SPOT_SCALE_RTOL = 1e-4


def _light_power(light):
    """Power and colour (3,) of a light as Cycles uses them.

    Power: energy x 2^exposure; colour: colour x blackbody colour when ``use_temperature``
    (exposure and temperature exist from Blender 4.5 on). ``diffuse_factor`` is left out: Cycles
    ignores it (an EEVEE setting; measured with bpy 4.2 and 5.0.1, tests/addon/test_lights.py).
    """
    colour = np.array(light.color[:3], dtype=np.float64)
    if getattr(light, "use_temperature", False):
        colour = colour * np.array(light.temperature_color[:3], dtype=np.float64)
    return float(light.energy) * 2.0 ** float(getattr(light, "exposure", 0.0)), colour


def _unnormalized(light, kind, radius):
    """Cycles' factor on the power of a light whose ``normalize`` is off (Blender 4.4 on).

    Measured with bpy 5.0.1 (tests/addon/test_lights.py): a point or spot light of radius r > 0
    is not divided by its area, 4 pi r^2 (x 4 at r = 0); a sun of angle a > 0 is not divided by
    its disk, pi sin^2(a / 2) (x 1 at a = 0).
    """
    if getattr(light, "normalize", True):
        return 1.0
    if kind == "sun":
        half = 0.5 * float(light.angle)
        return float(np.pi * np.sin(half) ** 2) if half > 0 else 1.0
    return 4.0 * np.pi * radius * radius if radius > 0 else 4.0


def _nodes_matter(light):
    """Whether a light's node tree may change its light: anything but the default tree (an
    unlinked white Emission of strength 1 into the Light Output)."""
    tree = light.node_tree if getattr(light, "use_nodes", False) else None
    if tree is None:
        return False
    outs = [n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputLight"
            and getattr(n, "is_active_output", True)]
    if not outs:
        return False
    surface = outs[0].inputs.get("Surface")
    if surface is None or not surface.is_linked:
        return True
    node = surface.links[0].from_node
    if node.bl_idname != "ShaderNodeEmission":
        return True
    colour, strength = node.inputs["Color"], node.inputs["Strength"]
    return (colour.is_linked or strength.is_linked or tuple(colour.default_value[:3]) != (1, 1, 1)
            or strength.default_value != 1.0)


def light_dict(inst, notes=None):
    """A point, spot or sun light instance as a :func:`core.light_list.make_lights` dict.

    In Blender units (``Lights.scaled`` converts to metres). The light's radius is not scaled
    by the object's scale, as in Cycles (measured). A light node tree is ignored and a spot's
    non-uniform scale is read as a round cone; both are added to *notes* (dict: approximation ->
    light names). A point or spot light's ``radiosity_ies`` file (:func:`_photometry`) gives it
    a measured distribution.

    Parameters
    ----------
    inst : bpy.types.DepsgraphObjectInstance
        An instance of a light object of type POINT, SPOT or SUN.
    notes : dict or None

    Returns
    -------
    dict
    """
    obj, light = inst.object, inst.object.data
    kind = LIGHT_KINDS[light.type]
    matrix = np.array(inst.matrix_world, dtype=np.float64)
    axis = -matrix[:3, 2]
    norm = np.linalg.norm(axis)
    direction = axis / norm if norm > 0 else np.array([0.0, 0.0, -1.0])
    power, colour = _light_power(light)
    out = dict(kind=kind, name=obj.name, color=colour,
               shadow=bool(getattr(light, "use_shadow", True)))
    if notes is not None and _nodes_matter(light):
        notes.setdefault("Light node trees are not supported yet and were ignored (colour and "
                         "power used)", []).append(obj.name)
    if kind == "sun":
        out.update(direction=direction, strength=power * _unnormalized(light, kind, 0.0),
                   angle=float(light.angle))
        return out
    radius = float(light.shadow_soft_size)
    out.update(position=matrix[:3, 3].copy(), radius=radius,
               power=power * _unnormalized(light, kind, radius),
               soft_falloff=bool(getattr(light, "use_soft_falloff", True)))
    out.update(_photometry(obj, light, direction, matrix))
    if kind == "spot":
        out.update(direction=direction, spot_size=float(light.spot_size),
                   spot_blend=float(light.spot_blend))
        scales = np.linalg.norm(matrix[:3, :3], axis=0)
        if notes is not None and scales.max() > scales.min() * (1.0 + SPOT_SCALE_RTOL):
            notes.setdefault("Spot lights with non-uniform scale are not supported yet and were "
                             "baked with a round cone", []).append(obj.name)
    return out


def _photometry(obj, light, direction, matrix):
    """The light's measured distribution (its ``radiosity_ies`` file) as make_lights keys: {}
    without one. The light's -Z is the nadir, its -Y the C0 plane, as Cycles' IES Texture node
    reads a file on a light. An unreadable or malformed file stops the bake here, before any long
    work, naming the light and the file."""
    # The original datablock: the evaluated copy keeps a property's value from the last
    # depsgraph evaluation.
    original = getattr(light, "original", None) or light
    path = getattr(original, "radiosity_ies", "")
    if not path:
        return {}
    full = bpy.path.abspath(path, library=original.library)
    try:
        photometry = read_photometry(full)
    except SceneError as exc:
        raise SceneError(f'light "{obj.name}": its IES / LDT file {path!r} cannot be used: '
                         f"{exc}") from None
    return dict(photometry=photometry, photometry_scale=original.radiosity_ies_scale.lower(),
                direction=direction, c0=-matrix[:3, 1])


def _add_light(inst, unit, out, add_faces, object_names, rho, le, mat_keys, one_sided):
    light = inst.object.data
    local, local_area = area_light_polygon(light)
    raw = np.array(inst.matrix_world, dtype=np.float64)
    pts = transform(local, unit @ raw)
    # Cycles divides the power by the light's area in Blender units (object scale included, unit
    # scale not: it only relabels lengths) -- measured, see tests/addon/test_lights.py.
    stretch = np.linalg.norm(np.cross(raw[:3, 0], raw[:3, 1]))
    radiance = area_light_radiance(light, local_area * stretch)
    k = local.shape[0]
    name = inst.object.name
    emit_key = ("light", name, len(rho))
    mat_keys[emit_key] = len(rho)
    one_sided.append(len(rho))
    rho.append(np.zeros(3))
    le.append(radiance)
    obj_index = len(object_names)
    object_names.append(f"{name} (area light)")
    add_faces(pts, np.arange(k, dtype=np.int64), np.array([0]), np.array([k]),
              np.array([mat_keys[emit_key]]), obj_index)
    out.lights += 1
    out.area_lights += 1


def _material_name(key):
    if key is None:
        return "(no material)"
    if isinstance(key, tuple):  # ("light", object name, n)
        return f"{key[0]}: {key[1]}"
    return key


def _names(names, limit=5):
    uniq = list(dict.fromkeys(names))
    text = ", ".join(f"'{n}'" for n in uniq[:limit])
    return text + (f" and {len(uniq) - limit} more" if len(uniq) > limit else "")
