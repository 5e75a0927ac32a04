"""Radiosity Baker core: scene arrays -> patches -> form factors -> RGB radiosity -> corner colours.

Pure NumPy (1.26 and 2.x) and the standard library; never imports Blender. The public entry points
are re-exported here; see README.md for a runnable example and docs/design.md for the contract.
"""

from .bake import BakeResult, bake, form_factor_matrix, relight
from .groups import relight_many
from .errors import BakeCancelled, RadiosityError, SceneError, SettingsError
from .light_list import Lights, make_lights
from .outmesh import OutputMesh
from .photometry import Photometry, read_photometry
from .scene import Scene, make_scene, scene_from_polygons
from .settings import BakeSettings
from .sky import CIEOvercast, Environment, Sky, Uniform, zenith_radiance

__all__ = [
    "BakeCancelled", "RadiosityError", "SceneError", "SettingsError",
    "Lights", "make_lights", "Photometry", "read_photometry",
    "OutputMesh", "Scene", "make_scene", "scene_from_polygons",
    "BakeResult", "BakeSettings", "bake", "form_factor_matrix", "relight", "relight_many",
    "Sky", "CIEOvercast", "Environment", "Uniform", "zenith_radiance",
]
