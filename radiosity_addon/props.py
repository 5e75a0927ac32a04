"""Bake settings stored in the .blend (Scene.radiosity) and runtime progress (WindowManager).

The bake's properties are made from the core's settings table (``core.settings.TABLE``, the rows
with ``exposed=True``) and the add-on's own rows (:data:`ADDON_OPTIONS`): one declaration per
option, shared with the batch command line and the report.
"""

import dataclasses

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, StringProperty

from ..core.falsecolour import SETTINGS as LUX_SETTINGS
from ..core.settings import BY_NAME, EXPOSED, Setting
from .write import show_in_viewports

#: Options of the add-on itself (not core.BakeSettings), declared like the core's settings.
ADDON_OPTIONS = (
    Setting("selected_only", "bool", False, "Selected Only",
            "Bake only selected meshes (lights always count)"),
    Setting("make_single_user", "bool", False, "Single User",
            "Give objects that share a mesh their own copy, so each gets its own lighting "
            "(otherwise such a bake stops with a message)"),
    Setting("save_relight", "bool", False, "Save Relight Data",
            "When the .blend is saved, write the kept bake beside it (<name>.radiosity, "
            "as large as the Kept size under Relight), so Relight works after reopening it"),
)

#: Every bake option of the panel and the batch script, in the panel's order.
OPTIONS = tuple(BY_NAME[name] for name in EXPOSED) + ADDON_OPTIONS


def enum_items(row):
    """Blender enum items of a choice row: upper-case identifiers (``'hemicube'`` -> HEMICUBE)."""
    return [(c.value.upper(), c.label, c.help) for c in row.choices]


def from_blender(row, value, unit_scale=1.0):
    """A property's value as the core expects it.

    Enum identifiers go back to lower case; lengths (``row.is_length``) from Blender units to
    metres with the scene's unit scale, as the scene's coordinates are (extract.py): the panel
    shows a length times the unit scale, so what it shows is what the bake uses.
    """
    if row.type == "choice":
        return value.lower()
    if row.auto and value == 0:       # the panel shows "auto" as 0
        return None
    if row.is_length:
        return value * unit_scale
    return value


def _make_even(name):
    def update(self, context):
        value = getattr(self, name)
        if value % 2:      # typed or dragged to an odd value: the next even one
            setattr(self, name, value + 1 if value + 1 <= BY_NAME[name].high else value - 1)
    return update


def make_property(row, update=None):
    """The bpy property of one settings row (label, tooltip, default, bounds, unit); *update*:
    its update callback."""
    common = dict(name=row.label, description=row.help)
    if update is not None:
        common["update"] = update
    default = row.default
    if row.auto:                      # None ("auto") is 0 in the panel
        default = 0 if default is None else default
        row = dataclasses.replace(row, open_low=False)
    if row.type == "bool":
        return BoolProperty(default=row.default, **common)
    if row.type == "choice":
        return EnumProperty(items=enum_items(row), default=row.default.upper(), **common)
    limits = {}
    if row.low is not None:
        limits["min"] = row.low + 1 if row.type == "int" and row.open_low else row.low
    if row.high is not None:
        limits["max"] = row.high - 1 if row.type == "int" and row.open_high else row.high
    if row.soft is not None:
        limits["soft_min"], limits["soft_max"] = row.soft
    if row.type == "int":
        if row.even:
            limits.update(step=2, update=_make_even(row.name))
        return IntProperty(default=default, **limits, **common)
    if row.digits is not None:
        limits["precision"] = row.digits
    if row.is_length:
        limits.update(subtype="DISTANCE", unit="LENGTH")
    return FloatProperty(default=default, **limits, **common)


def _lux_changed(self, context):
    from .luxview import settings_changed
    settings_changed(self, context)


def _show_bake_changed(self, context):
    wm = context.window_manager
    if wm is not None:
        show_in_viewports([w.screen for w in wm.windows], self.show_bake)


class RadiositySettings(bpy.types.PropertyGroup):
    __annotations__ = {row.name: make_property(row) for row in OPTIONS}
    # The false-colour display's scale (core.falsecolour.SETTINGS): not bake options.
    __annotations__.update({row.name: make_property(row, _lux_changed) for row in LUX_SETTINGS})
    __annotations__.update(
        show_bake=BoolProperty(name="Show Bake", default=True, update=_show_bake_changed,
                               description="Show the baked colours flat in Solid viewports"),
        last_report=StringProperty(name="Last Bake", description="JSON summary of the last bake",
                                   options={"HIDDEN"}),
    )


CLASSES = (RadiositySettings,)

#: Blender 5.0 warns on a "//" path in a file path property without this option; 4.2 lacks it.
_RELATIVE = ({"PATH_SUPPORTS_BLEND_RELATIVE"}
             if "is_path_supports_blend_relative" in bpy.types.Property.bl_rna.properties
             else set())

#: Per point and spot light (Light datablock): a measured distribution (core.photometry) and what
#: the light's power means with it (core.light_list.PHOTOMETRY_SCALES, upper case).
LIGHT_PROPERTIES = dict(
    radiosity_ies=StringProperty(
        name="IES / LDT File", subtype="FILE_PATH", default="", options=_RELATIVE,
        description="Measured light distribution (IES LM-63 .ies or EULUMDAT .ldt) used by the "
                    "radiosity bake: the light's -Z is the nadir, its -Y the C0 plane"),
    radiosity_ies_scale=EnumProperty(
        name="Scale", default="POWER",
        items=[("POWER", "Power",
                "The file gives the shape, the light's power the total (as the plain light)"),
               ("CYCLES", "Cycles IES",
                "As Cycles' IES Texture node into the light's Emission strength: a 1 W light "
                "emits the file's candela")],
        description="What the light's power means with the distribution file"),
)


#: Per object: a calculation surface (radiosity_addon.surfaces) measures illuminance and takes
#: no part in the light.
OBJECT_PROPERTIES = dict(
    radiosity_calc_surface=BoolProperty(
        name="Calculation Surface", default=False,
        description="Measure illuminance (lux) on this mesh after the bake: EN 12464-1 grid "
                    "with Emin, Eavg, Emax and U0, and the 'Radiosity Lux' attribute at its "
                    "vertices. It neither blocks nor reflects light"),
)


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.Scene.radiosity = bpy.props.PointerProperty(type=RadiositySettings)
    for name, prop in LIGHT_PROPERTIES.items():
        setattr(bpy.types.Light, name, prop)
    for name, prop in OBJECT_PROPERTIES.items():
        setattr(bpy.types.Object, name, prop)
    bpy.types.WindowManager.radiosity_progress = FloatProperty(
        name="Progress", subtype="PERCENTAGE", min=0.0, max=100.0, options={"SKIP_SAVE"})
    bpy.types.WindowManager.radiosity_status = StringProperty(options={"SKIP_SAVE"})


def unregister():
    for name in OBJECT_PROPERTIES:
        delattr(bpy.types.Object, name)
    for name in LIGHT_PROPERTIES:
        delattr(bpy.types.Light, name)
    del bpy.types.WindowManager.radiosity_status
    del bpy.types.WindowManager.radiosity_progress
    del bpy.types.Scene.radiosity
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
