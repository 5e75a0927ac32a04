"""Bake settings stored in the .blend (Scene.radiosity) and runtime progress (WindowManager)."""

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, StringProperty

from ..core.constants import DEFAULT_MAX_ITERATIONS, DEFAULT_TOLERANCE

METHODS = [
    ("HEMICUBE", "Hemicube", "Cohen-Greenberg hemicube, made reciprocal (default: on the "
                             "speed-accuracy front against Cycles)"),
    ("EXACT", "Exact", "Contour-integral form factors with ray-traced visibility: slow, accurate"),
    ("HYBRID", "Hybrid", "Hemicube, with near patch pairs computed exactly"),
]
CORNERS = [
    ("GATHER", "At Vertex", "Gather the solved light at every vertex: the value there, as Cycles "
     "bakes it (default; about one more hemicube per vertex)"),
    ("AVERAGE", "Patch Average", "Average the patches around each vertex (Gouraud): free, but a "
     "patch mean, off next to lights, in corners and along shadow edges"),
]
SOLVERS = [
    ("AUTO", "Auto", "Pick the solver from the scene size and memory budget"),
    ("DIRECT", "Direct", "Dense linear solve: exact, small scenes only"),
    ("JACOBI", "Jacobi", "Jacobi iterations"),
    ("GAUSS_SEIDEL", "Gauss-Seidel", "Gauss-Seidel sweeps"),
    ("PROGRESSIVE", "Progressive", "Progressive refinement (shooting): no full matrix kept"),
]


def _show_bake_changed(self, context):
    from .write import show_in_viewports

    wm = context.window_manager
    if wm is not None:
        show_in_viewports([w.screen for w in wm.windows], self.show_bake)


class RadiositySettings(bpy.types.PropertyGroup):
    patch_size: FloatProperty(
        name="Patch Size", description="Largest patch edge; smaller is finer and slower",
        default=0.5, min=1e-4, soft_min=0.01, soft_max=5.0, subtype="DISTANCE", unit="LENGTH")
    method: EnumProperty(name="Form Factors", items=METHODS, default="HEMICUBE")
    resolution: IntProperty(name="Hemicube Resolution", description="Pixels across a hemicube face",
                            default=64, min=8, max=1024)
    solver: EnumProperty(name="Solver", items=SOLVERS, default="AUTO")
    corners: EnumProperty(name="Corner Colours", items=CORNERS, default="GATHER")
    refine_levels: IntProperty(
        name="Adaptive Levels", default=0, min=0, max=4,
        description="Split patches where the solved light changes between neighbours and solve "
                    "again, this many times (0: off)")
    element_levels: IntProperty(
        name="Receiver Levels", default=2, min=0, max=3,
        description="After the solve, split patches where the light changes into smaller "
                    "receivers for the vertex colours, this many times (no re-solve; 0: off)")
    contact_cuts: BoolProperty(
        name="Cut at Contacts", default=True,
        description="Cut patches along the lines where objects touch or pierce a surface (a "
                    "box on a floor), so no light leaks under objects and their feet are not "
                    "too dark")
    tolerance: FloatProperty(name="Tolerance", description="Relative residual to stop at",
                             default=DEFAULT_TOLERANCE, min=1e-9, max=0.5, precision=6)
    max_iterations: IntProperty(name="Iteration Cap", default=DEFAULT_MAX_ITERATIONS, min=1)
    selected_only: BoolProperty(name="Selected Only",
                                description="Bake only selected meshes (lights always count)")
    make_single_user: BoolProperty(
        name="Make Single User",
        description="Give objects that share a mesh their own copy, so each gets its own "
                    "lighting (otherwise such a bake stops with a message)")
    show_bake: BoolProperty(name="Show Bake", default=True, update=_show_bake_changed,
                            description="Show the baked colours flat in Solid viewports")
    last_report: StringProperty(name="Last Bake", description="JSON summary of the last bake",
                                options={"HIDDEN"})


CLASSES = (RadiositySettings,)


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.Scene.radiosity = bpy.props.PointerProperty(type=RadiositySettings)
    bpy.types.WindowManager.radiosity_progress = FloatProperty(
        name="Progress", subtype="PERCENTAGE", min=0.0, max=100.0, options={"SKIP_SAVE"})
    bpy.types.WindowManager.radiosity_status = StringProperty(options={"SKIP_SAVE"})


def unregister():
    del bpy.types.WindowManager.radiosity_status
    del bpy.types.WindowManager.radiosity_progress
    del bpy.types.Scene.radiosity
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
