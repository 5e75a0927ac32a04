"""Radiosity Baker: the Blender extension's entry point.

Blender loads this file as the package ``bl_ext.<repository>.radiosity_baker``. It stays free of
bpy at import time so that the standalone core (``core/``) and the tests can import the package
without Blender; the Blender layer lives in ``radiosity_addon/``.
"""


def register():
    from .radiosity_addon import register as _register

    _register()


def unregister():
    from .radiosity_addon import unregister as _unregister

    _unregister()
