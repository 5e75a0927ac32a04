"""The sidebar panel (3D Viewport > Sidebar > Radiosity) and its sub-panels.

Laid out for the sidebar's default width: quality settings first, the bake button, then the
display of the result; solver and scope settings fold away in "Advanced" (a layout panel), the
last bake's figures in the "Last Bake" sub-panel. Labels are short enough not to be cut off at the
default width (seen in the real-Blender UI tier's screenshots, tests/ui).
"""

import json

import bpy

from . import relight_ops
from .operators import lossy_text
from .extract import ATTRIBUTE, LUX_ATTRIBUTE

#: Stage timings of the report, in the order a user reads them, with their labels (total first).
STAGE_LABELS = (
    ("total", "Total"),
    ("read_scene", "Read scene"),
    ("patches", "Make patches"),
    ("lights", "Direct light"),
    ("form_factors", "Form factors"),
    ("solve", "Solve"),
    ("colours", "Vertex colours"),
    ("light_groups", "Light groups"),
    ("write", "Write"),
)



def _split_row(layout, label):
    """A row with a label on the left and the widget's column on the right (returns the column)."""
    split = layout.split(factor=0.42, align=True)
    split.label(text=label)
    return split.column(align=True)


def has_bake(scene):
    """True when a mesh of *scene* carries the baked colour or lux attribute."""
    return any(o.type == "MESH" and o.data is not None
               and (ATTRIBUTE in o.data.color_attributes or LUX_ATTRIBUTE in o.data.attributes)
               for o in scene.objects)


class VIEW3D_PT_radiosity(bpy.types.Panel):
    bl_label = "Radiosity"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Radiosity"

    def draw(self, context):
        from .operators import RADIOSITY_OT_bake

        layout = self.layout
        layout.use_property_split = False
        layout.use_property_decorate = False
        props = context.scene.radiosity
        _split_row(layout, "Output").prop(props, "output_mode", text="")
        col = layout.column(align=True)
        col.prop(props, "patch_size", text="Patch Size (auto)" if props.patch_size == 0
                 else "Patch Size")
        sub = col.column(align=True)
        sub.active = props.output_mode == "MESH"
        sub.prop(props, "contrast")
        _split_row(layout, "Method").prop(props, "method", text="")
        sub = layout.column()
        sub.active = props.method in ("HEMICUBE", "HYBRID")
        sub.prop(props, "resolution", text="Resolution")
        row = _split_row(layout, "Corners")
        row.active = props.output_mode == "VERTICES"
        row.prop(props, "corners", text="")
        col = layout.column(align=True)
        sub = col.column(align=True)
        sub.active = props.corners == "GATHER"
        sub.prop(props, "element_levels", text="Receiver Levels")
        col.prop(props, "refine_levels", text="Adaptive Levels")

        wm = context.window_manager
        if RADIOSITY_OT_bake.running():
            layout.prop(wm, "radiosity_progress", text=wm.radiosity_status or "Baking",
                        slider=True)
            layout.label(text="Esc cancels", icon="INFO")
        else:
            layout.operator("radiosity.bake", icon="LIGHT_AREA")

        obj = context.active_object
        if obj is not None and obj.type == "MESH":
            layout.prop(obj, "radiosity_calc_surface", text="Calculation Surface (lux)")

        box = layout.box()
        if has_bake(context.scene):
            row = box.row(align=True)
            row.prop(props, "show_bake", text="Show")
            row.operator("radiosity.clear", text="Clear", icon="X")
            box.prop(context.scene.view_settings, "exposure", text="Exposure")
            draw_lux(box, context.scene)
            relight_ops.draw(box, context.scene)
        else:
            box.label(text="No bake in this scene yet")

        # A layout panel, folded by default; its open state is a window-manager property (not
        # saved in the file), so scripts and the UI tier can unfold it too.
        header, body = layout.panel_prop(wm, "radiosity_show_advanced")
        header.label(text="Advanced")
        if body is not None:
            draw_advanced(body, props)


def draw_lux(layout, scene):
    """The false-colour lux display's toggle and scale (radiosity_addon.luxview)."""
    from .luxview import is_shown

    props = scene.radiosity
    col = layout.column(align=True)
    col.operator("radiosity.lux_display", icon="COLOR", depress=is_shown(scene))
    col.prop(props, "lux_scale", text="")
    # A row of its own: beside the scale the label was cut to "Max (au..." at the default width.
    col.prop(props, "lux_max", text="Max lx (auto)" if props.lux_max == 0 else "Max lx")


def draw_advanced(layout, props):
    """Solver and scope settings (the folded part of the panel)."""
    _split_row(layout, "Solver").prop(props, "solver", text="")
    col = layout.column(align=True)
    col.active = props.output_mode == "MESH"
    col.prop(props, "min_element", text="Min Element (auto)" if props.min_element == 0
             else "Min Element")
    col.prop(props, "vertex_budget")
    col = layout.column(align=True)
    col.prop(props, "tolerance")
    col.prop(props, "max_iterations", text="Iteration Cap")
    layout.prop(props, "light_samples")
    layout.prop(props, "workers", text="Workers (auto)" if props.workers == 0 else "Workers")
    _split_row(layout, "Emitters").prop(props, "exact_direct", text="")
    _split_row(layout, "Sky").prop(props, "sky", text="")
    layout.prop(props, "sky_illuminance")
    col = layout.column()
    col.prop(props, "contact_cuts")
    sub = col.row()
    sub.active = props.contact_cuts
    sub.prop(props, "shadow_cuts")
    sub = col.row()
    sub.active = props.contact_cuts
    sub.prop(props, "gap_cuts")
    col.prop(props, "selected_only")
    col.prop(props, "make_single_user")
    col.prop(props, "save_relight")


class VIEW3D_PT_radiosity_last(bpy.types.Panel):
    bl_label = "Last Bake"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Radiosity"
    bl_parent_id = "VIEW3D_PT_radiosity"

    @classmethod
    def poll(cls, context):
        scene = context.scene
        return bool(scene is not None and summary_lines(scene.radiosity.last_report))

    def draw(self, context):
        col = self.layout.column(align=True)
        for text, icon in summary_lines(context.scene.radiosity.last_report):
            col.label(text=text, icon=icon)


def summary_lines(text):
    """The Last Bake lines, as (text, icon) pairs, from the JSON report (empty if none).

    The total time comes first, then patches and solver figures, the stages in pipeline order
    with human labels, and the warnings.
    """
    if not text:
        return []
    try:
        report = json.loads(text)
    except ValueError:
        return []
    if not isinstance(report, dict):
        return []
    timings = {k: v for k, v in (report.get("timings") or {}).items()
               if isinstance(v, (int, float)) and not k.startswith("n_")}
    lines = []
    if "total" in timings:
        lines.append((f"Total: {timings['total']:.2f} s", "TIME"))
    lines.append((f"Patches: {report.get('patches', '?')}", "NONE"))
    residual = report.get("residual")
    res_text = f", residual {residual:.2g}" if isinstance(residual, (int, float)) else ""
    lines.append((f"Iterations: {report.get('iterations', '?')}{res_text}", "NONE"))
    workers = report.get("workers")
    if isinstance(workers, dict) and isinstance(workers.get("processes"), int):
        lines.append((f"Workers: {workers['processes']} processes", "NONE"))
    peaks = [v for v in (report.get("peak_mb") or {}).values() if isinstance(v, (int, float))]
    if peaks:
        extra = workers.get("peak_mb") if isinstance(workers, dict) else None
        each = f", workers up to {extra:.0f} MB" if isinstance(extra, (int, float)) else ""
        lines.append((f"Peak memory: {max(peaks):.0f} MB{each}", "NONE"))
    written = report.get("output_objects")
    if written:          # radiosity mesh output: what the user's faces became
        faces_in = sum(o.get("input_faces", 0) for o in written)
        verts = sum(o.get("output_vertices", 0) for o in written)
        faces = sum(o.get("output_faces", 0) for o in written)
        lines.append((f"Mesh: {faces_in} faces -> {faces} ({verts} vertices)", "NONE"))
    lossy = lossy_text(report)
    if lossy:            # Existing Vertices: what one colour per modelled corner cannot show
        lines.append((lossy, "INFO"))
    known = dict(STAGE_LABELS)
    for key, label in STAGE_LABELS[1:]:
        if key in timings:
            lines.append((f"{label}: {timings[key]:.2f} s", "NONE"))
    for key, seconds in timings.items():
        if key not in known:
            lines.append((f"{key.replace('_', ' ').capitalize()}: {seconds:.2f} s", "NONE"))
    for surf in report.get("calculation_surfaces", []):
        try:
            lines.append((f"{surf['object']}: Eavg {surf['Eavg']:.0f} lx, Emin "
                          f"{surf['Emin']:.0f}, Emax {surf['Emax']:.0f}, U0 {surf['U0']:.2f}",
                          "LIGHT"))
        except (KeyError, TypeError, ValueError):
            continue
    for warning in report.get("warnings", []):
        lines.append((str(warning), "ERROR"))
    return lines


class DATA_PT_radiosity_light(bpy.types.Panel):
    """Properties > Light data: the light's measured distribution for the radiosity bake."""

    bl_label = "Radiosity"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "data"
    bl_options = {"DEFAULT_CLOSED"}

    @classmethod
    def poll(cls, context):
        light = getattr(context, "light", None)
        return light is not None and light.type in {"POINT", "SPOT"}

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        light = context.light
        layout.prop(light, "radiosity_ies")
        row = layout.row()
        row.active = bool(light.radiosity_ies)
        row.prop(light, "radiosity_ies_scale")


CLASSES = (VIEW3D_PT_radiosity, VIEW3D_PT_radiosity_last, DATA_PT_radiosity_light)


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.WindowManager.radiosity_show_advanced = bpy.props.BoolProperty(
        name="Advanced", description="Show the solver and scope settings", default=False,
        options={"SKIP_SAVE"})


def unregister():
    del bpy.types.WindowManager.radiosity_show_advanced
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
