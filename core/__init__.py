"""Radiosity Baker core: scene arrays -> patches -> form factors -> RGB radiosity -> corner colours.

Pure NumPy (1.26 and 2.x) and the standard library; never imports Blender. The public entry points
are re-exported here; see README.md for a runnable example and docs/design.md for the contract.
"""

from .errors import BakeCancelled, RadiosityError, SceneError, SettingsError
from .outmesh import OutputMesh
from .scene import Scene, make_scene, scene_from_polygons

__all__ = [
    "BakeCancelled", "RadiosityError", "SceneError", "SettingsError",
    "OutputMesh", "Scene", "make_scene", "scene_from_polygons",
]

try:  # The pipeline modules are imported when present (they land module by module).
    from .bake import BakeResult, BakeSettings, bake, form_factor_matrix, relight  # noqa: F401
    __all__ += ["BakeResult", "BakeSettings", "bake", "form_factor_matrix", "relight"]
except ImportError:  # pragma: no cover - removed once the pipeline is complete
    pass
