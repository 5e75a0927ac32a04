"""The sidebar panel (3D Viewport > Sidebar > Radiosity)."""

import json

import bpy


class VIEW3D_PT_radiosity(bpy.types.Panel):
    bl_label = "Radiosity"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Radiosity"

    def draw(self, context):
        from .operators import RADIOSITY_OT_bake

        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        props = context.scene.radiosity
        col = layout.column()
        col.prop(props, "patch_size")
        col.prop(props, "method")
        sub = col.column()
        sub.active = props.method in ("HEMICUBE", "HYBRID")
        sub.prop(props, "resolution")
        col.prop(props, "solver")
        col.prop(props, "corners")
        col.prop(props, "refine_levels")
        sub = col.column()
        sub.active = props.corners == "GATHER"
        sub.prop(props, "element_levels")
        col.prop(props, "contact_cuts")
        col.prop(props, "tolerance")
        col.prop(props, "max_iterations")
        col.prop(props, "selected_only")
        col.prop(props, "make_single_user")
        wm = context.window_manager
        if RADIOSITY_OT_bake.running():
            layout.prop(wm, "radiosity_progress", text=wm.radiosity_status or "Baking",
                        slider=True)
            layout.label(text="Esc cancels", icon="INFO")
        else:
            layout.operator("radiosity.bake", icon="LIGHT_AREA")
        row = layout.row(align=True)
        row.prop(props, "show_bake")
        row.operator("radiosity.clear", text="Clear Bake", icon="X")
        layout.prop(context.scene.view_settings, "exposure", text="Display Exposure")
        _draw_summary(layout, props.last_report)


def _draw_summary(layout, text):
    if not text:
        return
    try:
        report = json.loads(text)
    except ValueError:
        return
    box = layout.box()
    box.label(text="Last bake")
    box.label(text=f"Patches: {report.get('patches', '?')}")
    box.label(text=f"Iterations: {report.get('iterations', '?')}, "
                   f"residual {report.get('residual', float('nan')):.2g}")
    for stage, seconds in report.get("timings", {}).items():
        box.label(text=f"{stage}: {seconds:.2f} s")
    for warning in report.get("warnings", []):
        box.label(text=warning, icon="ERROR")


CLASSES = (VIEW3D_PT_radiosity,)


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)


def unregister():
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
