"""Lux in false colour: the ``Radiosity Lux Colour`` attribute, the viewport's legend, the batch's.

**Show Lux** (:func:`show`) maps the ``Radiosity Lux`` attribute of every mesh in the scene (baked
meshes per corner, calculation surfaces per point) through one ``core.falsecolour`` scale into a
BYTE_COLOR corner attribute :data:`LUX_COLOUR` (sRGB, as the ramp is defined), makes it the active
and render colour, and switches every 3D view to Solid shading, Flat light, Attribute colour (no
shadows, cavity or X-ray) and the scene to the Standard view transform at exposure 0 and gamma 1,
so a pixel's colour is the ramp's colour of its lux. What was there before is remembered: the
colour attributes on the mesh (custom property :data:`PROP_PREVIOUS`), the views and colour
management on the scene (:data:`PROP_DISPLAY`, JSON, which also holds the scale the legend
draws). :func:`hide` puts all of it back exactly and removes the attribute. A draw handler draws
the legend (colour bar, ticks in lux) in every 3D view while the display is on.

The batch's ``--render-lux`` renders the same display with Workbench and adds the legend with
NumPy (``core.legend``), as headless Blender has no text drawing.
"""

import json

import bpy
import numpy as np

from ..core import falsecolour, legend
from .extract import LUX_ATTRIBUTE, LUX_COLOUR_ATTRIBUTE as LUX_COLOUR
from .props import from_blender
from .write import write_corner_colours

#: Mesh custom property: {'active': name, 'default': name} of the colour attributes before.
PROP_PREVIOUS = "radiosity_lux_previous"
#: Scene custom property (JSON): views and colour management before, and the legend's scale.
PROP_DISPLAY = "radiosity_lux_display"
#: 3D view shading settings the display changes, and what it sets them to ('type' last: the
#: others are restored while the view is still Solid).
SHADING = (("light", "FLAT"), ("color_type", "VERTEX"), ("show_shadows", False),
           ("show_cavity", False), ("show_xray", False), ("type", "SOLID"))
#: Colour management the display sets: a byte colour is shown as its sRGB value.
COLOUR = (("view_transform", "Standard"), ("look", "None"), ("exposure", 0.0), ("gamma", 1.0),
          ("use_curve_mapping", False))


class LuxViewError(RuntimeError):
    """The display cannot be shown (no bake, a name clash); the message is for the user."""


def lux_meshes(scene):
    """Local meshes of *scene*'s objects that carry a FLOAT ``Radiosity Lux`` on corners or
    points, each once, as (mesh, an object using it)."""
    found = {}
    for obj in scene.objects:
        mesh = obj.data if obj.type == "MESH" else None
        if mesh is None or mesh.library is not None:
            continue
        attr = mesh.attributes.get(LUX_ATTRIBUTE)
        if attr is not None and attr.data_type == "FLOAT" and attr.domain in ("CORNER", "POINT"):
            found.setdefault(mesh.as_pointer(), (mesh, obj))
    return list(found.values())


def corner_areas(mesh, obj):
    """(C,) float64 area each corner stands for: its face's world area over the face's corners
    (the object's scale taken as uniform, its volume scale to the power 2/3)."""
    area = np.empty(len(mesh.polygons), dtype=np.float32)
    mesh.polygons.foreach_get("area", area)
    sizes = np.empty(len(mesh.polygons), dtype=np.int32)
    mesh.polygons.foreach_get("loop_total", sizes)
    scale = abs(obj.matrix_world.to_3x3().determinant()) ** (2.0 / 3.0)
    return np.repeat(area.astype(np.float64) * scale / np.maximum(sizes, 1), sizes)


def corner_lux(mesh):
    """(C,) float64 illuminance at *mesh*'s corners (a point attribute read at each corner)."""
    attr = mesh.attributes[LUX_ATTRIBUTE]
    values = np.empty(len(attr.data), dtype=np.float32)
    attr.data.foreach_get("value", values)
    values = np.nan_to_num(values.astype(np.float64))
    if attr.domain == "CORNER":
        return values
    verts = np.empty(len(mesh.loops), dtype=np.int32)
    mesh.loops.foreach_get("vertex_index", verts)
    return values[verts]


def scale_settings(props):
    """(mode, top or None) of the scene's Lux Scale and Lux Max (``Scene.radiosity``)."""
    mode_row, top_row = falsecolour.SETTINGS
    return (from_blender(mode_row, props.lux_scale), from_blender(top_row, props.lux_max))


def is_shown(scene):
    return PROP_DISPLAY in scene


def shown_scale(scene):
    """The legend's scale of the display (``Scale.as_dict()``), or None when it is off."""
    text = scene.get(PROP_DISPLAY)
    if not isinstance(text, str):
        return None
    try:
        return json.loads(text).get("scale")
    except (ValueError, AttributeError):
        return None


def show(scene, settings=None):
    """Show the lux of *scene* in false colour (or refresh it when already shown).

    Parameters
    ----------
    scene : bpy.types.Scene
    settings : (str, float or None), optional
        Scale mode and top (lx, None: auto); default: the scene's Lux Scale and Lux Max.

    Returns
    -------
    core.falsecolour.Scale
    """
    pairs = lux_meshes(scene)
    meshes = [mesh for mesh, _ in pairs]
    if not meshes:
        raise LuxViewError(f"No illuminance to show in scene '{scene.name}': bake first (a "
                           f"bake writes the '{LUX_ATTRIBUTE}' attribute)")
    for mesh in meshes:
        attr = mesh.attributes.get(LUX_COLOUR)
        if attr is not None and PROP_PREVIOUS not in mesh:
            raise LuxViewError(f"Mesh '{mesh.name}' already has an attribute named "
                               f"'{LUX_COLOUR}'; rename it to show lux in false colour")
    mode, top = settings if settings is not None else scale_settings(scene.radiosity)
    values = [corner_lux(m) for m in meshes]
    areas = np.concatenate([corner_areas(m, o) for m, o in pairs])
    scale = falsecolour.make_scale(np.concatenate(values), mode, top,
                                   weights=areas if areas.sum() > 0 else None)
    state = json.loads(scene[PROP_DISPLAY]) if is_shown(scene) else {
        "views": _views_state(), "colour": {k: getattr(scene.view_settings, k)
                                            for k, _ in COLOUR}}
    for mesh, lux in zip(meshes, values):
        _write(mesh, scale.colours(lux))
    for space in _spaces():
        for key, value in SHADING[::-1]:      # Solid first: Flat and Attribute need it
            setattr(space[1].shading, key, value)
    for key, value in COLOUR:
        setattr(scene.view_settings, key, value)
    state["scale"] = scale.as_dict()
    scene[PROP_DISPLAY] = json.dumps(state)
    _redraw()
    return scale


def hide(scene):
    """End the display: attribute removed, colour attributes, views and colour management back
    as they were. Returns True if it was on (or had left an attribute)."""
    found = False
    for mesh in bpy.data.meshes:
        if PROP_PREVIOUS in mesh and mesh.library is None:
            _restore(mesh)
            found = True
    text = scene.get(PROP_DISPLAY)
    if text is not None:
        del scene[PROP_DISPLAY]
        found = True
        state = json.loads(text)
        views = state.get("views", {})
        for key, space in _spaces():
            for name, _ in SHADING:
                if key in views and name in views[key]:
                    setattr(space.shading, name, views[key][name])
        for name, value in state.get("colour", {}).items():
            setattr(scene.view_settings, name, value)
    _redraw()
    return found


def _write(mesh, colours):
    """(C, 3) sRGB colours as the BYTE_COLOR corner attribute, made active and render colour."""
    attrs = mesh.color_attributes
    if PROP_PREVIOUS not in mesh:
        mesh[PROP_PREVIOUS] = {"active": attrs.active_color_name or "",
                               "default": attrs.default_color_name or ""}
    write_corner_colours(mesh, LUX_COLOUR, "BYTE_COLOR", colours)


def _restore(mesh):
    attrs = mesh.color_attributes
    previous = dict(mesh[PROP_PREVIOUS])
    del mesh[PROP_PREVIOUS]
    attr = attrs.get(LUX_COLOUR)
    if attr is not None:
        attrs.remove(attr)
    for key in ("active", "default"):
        name = str(previous.get(key, ""))
        setattr(attrs, f"{key}_color_name", name if name in attrs else "")
    mesh.update()


def _spaces():
    """(key, space) of every 3D view of every screen; the key names screen, area and space."""
    for screen in bpy.data.screens:
        for i, area in enumerate(screen.areas):
            for j, space in enumerate(area.spaces):
                if space.type == "VIEW_3D":
                    yield f"{screen.name}\t{i}\t{j}", space


def _views_state():
    return {key: {name: getattr(space.shading, name) for name, _ in SHADING}
            for key, space in _spaces()}


def _redraw():
    wm = getattr(bpy.context, "window_manager", None)
    for window in wm.windows if wm is not None else ():
        for area in window.screen.areas:
            if area.type == "VIEW_3D":
                area.tag_redraw()


# ------------------------------------------------------------------------------ batch PNG legend


def add_legend(path, scale):
    """Add the legend of *scale* to the right of the PNG at *path* (rewritten in place)."""
    image = bpy.data.images.load(path, check_existing=False)
    try:
        w, h = image.size
        px = np.empty(w * h * image.channels, dtype=np.float32)
        image.pixels.foreach_get(px)
    finally:
        bpy.data.images.remove(image)
    rgb = px.reshape(h, w, -1)[::-1, :, :3]      # Blender's rows go bottom-up
    out, _ = legend.compose(rgb, scale)
    oh, ow = out.shape[:2]
    rgba = np.ones((oh, ow, 4), dtype=np.float32)
    rgba[:, :, :3] = out[::-1]
    result = bpy.data.images.new("Radiosity Lux Legend", ow, oh, alpha=False)
    try:
        result.pixels.foreach_set(rgba.ravel())
        result.filepath_raw = path
        result.file_format = "PNG"
        result.save()
    finally:
        bpy.data.images.remove(result)


# --------------------------------------------------------------------------- viewport legend


def draw_legend():
    """Draw handler (3D view, POST_PIXEL): the legend in the view's bottom left."""
    context = bpy.context
    scene, region = getattr(context, "scene", None), getattr(context, "region", None)
    data = shown_scale(scene) if scene is not None else None
    if data is None or region is None:
        return
    ui = context.preferences.system.ui_scale
    height = min(220 * ui, region.height - 90 * ui)
    if height >= 60 * ui:
        left, bottom = 16 * ui + _tools_width(context.area), 36 * ui
        if draw_bar(data, left, bottom, height, ui) is not None:
            # Where the bar went, in window pixels (the real-window test reads it back).
            DRAWN.update(left=region.x + left, bottom=region.y + bottom, height=height,
                         width=14 * ui)


#: The colour bar's last position in window pixels (left, bottom, width, height).
DRAWN = {}


def draw_bar(data, left, bottom, height, ui=1.0):
    """Draw the legend of *data* (``Scale.as_dict()``) with ``gpu`` and ``blf``: the bar's
    bottom-left corner at (left, bottom) pixels, *height* pixels high; returns its box (x0, y0,
    x1, y1), or None without GPU drawing."""
    try:
        import blf
        import gpu
        from gpu_extras.batch import batch_for_shader
    except ImportError:        # a Blender without GPU drawing: no legend, no error
        return None
    bar, size, pad = 14 * ui, 11 * ui, 6 * ui
    title = "lx" + (" (log)" if data["mode"] == "log" else "")
    blf.size(0, size)
    text_w = max(blf.dimensions(0, s)[0] for s in data["labels"])
    x1 = max(left + bar + 8 * ui + text_w, left + blf.dimensions(0, title)[0]) + pad
    box = (left - pad, bottom - pad, x1, bottom + height + 2 * size + pad)
    quad = [(box[0], box[1]), (box[2], box[1]), (box[2], box[3]), (box[0], box[3])]
    gpu.state.blend_set("ALPHA")
    flat = gpu.shader.from_builtin("UNIFORM_COLOR")
    flat.uniform_float("color", (0.0, 0.0, 0.0, 0.55))
    batch_for_shader(flat, "TRIS", {"pos": quad}, indices=((0, 1, 2), (0, 2, 3))).draw(flat)
    # The ramp is linear between its control points: one quad per interval is exact. Colours are
    # sRGB, as Blender's own 2D drawing takes them.
    n = falsecolour.RAMP.shape[0]
    ys = bottom + np.linspace(0.0, 1.0, n) * height
    pos = [(x, y) for y in ys for x in (left, left + bar)]
    col = [(*falsecolour.RAMP[i], 1.0) for i in range(n) for _ in range(2)]
    tris = [(2 * i + a, 2 * i + b, 2 * i + c) for i in range(n - 1)
            for a, b, c in ((0, 1, 3), (0, 3, 2))]
    smooth = gpu.shader.from_builtin("SMOOTH_COLOR")
    batch_for_shader(smooth, "TRIS", {"pos": pos, "color": col}, indices=tris).draw(smooth)
    scale = falsecolour.Scale(data["mode"], data["top"], data["bottom"], tuple(data["ticks"]))
    blf.color(0, 1.0, 1.0, 1.0, 1.0)
    lines = []
    for t, text in zip(scale.position(np.asarray(scale.ticks, dtype=np.float64)),
                       data["labels"]):
        y = bottom + t * height
        lines += [(left + bar, y), (left + bar + 4 * ui, y)]
        blf.position(0, left + bar + 8 * ui, y - 0.35 * size, 0)
        blf.draw(0, text)
    flat.uniform_float("color", (1.0, 1.0, 1.0, 1.0))
    batch_for_shader(flat, "LINES", {"pos": lines}).draw(flat)
    blf.position(0, left, bottom + height + 0.6 * size, 0)
    blf.draw(0, title)
    gpu.state.blend_set("NONE")
    return box


def _tools_width(area):
    """Width of the toolbar when it overlaps the view (the legend goes beside it)."""
    for region in getattr(area, "regions", ()):
        if region.type == "TOOLS" and region.width > 1:
            return region.width
    return 0


class RADIOSITY_OT_lux_display(bpy.types.Operator):
    """Show the baked illuminance in false colour with a legend in lux, or go back to what the
    viewport showed before"""

    bl_idname = "radiosity.lux_display"
    bl_label = "Show Lux (false colour)"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        scene = context.scene
        if is_shown(scene):
            hide(scene)
            return {"FINISHED"}
        try:
            scale = show(scene)
        except (LuxViewError, ValueError) as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        self.report({"INFO"}, f"Lux in false colour: {scale.mode}, "
                              f"{falsecolour.label(scale.bottom)} to "
                              f"{falsecolour.label(scale.top)} lx")
        return {"FINISHED"}


def settings_changed(self, context):
    """Lux Scale / Lux Max changed: redraw the display with the new scale if it is on."""
    scene = getattr(context, "scene", None)
    if scene is not None and is_shown(scene):
        try:
            show(scene)
        except (LuxViewError, ValueError):
            pass        # nothing to show any more; the operator's toggle still turns it off


_HANDLE = []


def register():
    bpy.utils.register_class(RADIOSITY_OT_lux_display)
    if not bpy.app.background:
        _HANDLE.append(bpy.types.SpaceView3D.draw_handler_add(draw_legend, (), "WINDOW",
                                                              "POST_PIXEL"))


def unregister():
    while _HANDLE:
        bpy.types.SpaceView3D.draw_handler_remove(_HANDLE.pop(), "WINDOW")
    bpy.utils.unregister_class(RADIOSITY_OT_lux_display)
