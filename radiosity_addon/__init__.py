"""The Blender layer of Radiosity Baker: properties, operators, panel, scene I/O, batch script.

Data flows one way: Blender scene -> arrays (extract) -> core.bake -> arrays -> colour attribute
(write). Only this package touches bpy; the core never does.
"""

from . import luxview, operators, panels, props, relight_ops

_MODULES = (props, operators, relight_ops, luxview, panels)


def register():
    for module in _MODULES:
        module.register()


def unregister():
    for module in reversed(_MODULES):
        module.unregister()
