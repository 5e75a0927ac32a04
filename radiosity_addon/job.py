"""One bake, in three steps shared by the operator, the modal operator and the batch script.

1. :func:`prepare` (main thread): read the scene into the core's arrays and check that the result
   can be written, so nothing fails after minutes of work.
2. :func:`compute` (any thread): ``core.bake`` on those arrays; touches no Blender data.
3. :func:`apply` (main thread): write the attribute to every baked mesh, show it in the
   viewports, store the summary on the scene.

:class:`BakeJob` runs step 2 in a worker thread with progress and a cancel flag (and then
makes the light groups' own solutions, so the panel's first Relight solves nothing).
"""

import json
import threading
import time
import traceback
from dataclasses import dataclass

from .. import core
from ..core.errors import BakeCancelled, RadiosityError
from ..core.lux import lux
from ..core.settings import EXPOSED, as_dict
from ..core.sky import sky_for
from . import luxview, surfaces
from .extract import extract
from .props import OPTIONS, from_blender
from .write import (WriteError, check_writable, is_baked, show_in_viewports, write_colours,
                    write_mesh)

#: Bake options that come from the panel / the batch command line and go to core.BakeSettings:
#: the exposed rows of the core's settings table.
CORE_OPTIONS = EXPOSED


#: Share of the panel bake's progress bar for the light groups' own solutions (after the core
#: bake: about 6 % of the generated office's bake, more on small scenes).
GROUPS_SHARE = 0.1


class BakeError(RuntimeError):
    """A bake cannot run or its result cannot be written; the message is for the user."""


@dataclass
class BakeInput:
    """Everything the worker needs, and what apply needs afterwards."""

    scene: object            # core.Scene
    settings: object         # core.BakeSettings
    extraction: object       # extract.Extraction
    scene_name: str
    make_single_user: bool
    read_seconds: float
    selected_only: bool = False


def options_from_props(props):
    """Bake options (dict) from the scene's RadiositySettings property group.

    Lengths are converted to metres with the scene's unit scale (the core works in metres).
    """
    scale = float(props.id_data.unit_settings.scale_length) or 1.0
    return {row.name: from_blender(row, getattr(props, row.name), scale) for row in OPTIONS}


def prepare(context, options):
    """Read the scene and validate everything before the bake (main thread).

    Parameters
    ----------
    context : bpy.types.Context
    options : dict
        Keys of :data:`CORE_OPTIONS` plus ``selected_only`` and ``make_single_user``.

    Returns
    -------
    BakeInput

    Raises
    ------
    BakeError
        Edit mode, nothing to bake, no light, bad settings or unwritable meshes.
    """
    t0 = time.perf_counter()
    if context.mode != "OBJECT":
        raise BakeError("Switch to Object Mode to bake radiosity")
    try:
        settings = core.BakeSettings(**{k: options[k] for k in CORE_OPTIONS})
    except (RadiosityError, ValueError, TypeError) as exc:
        raise BakeError(f"Invalid bake setting: {exc}") from exc
    depsgraph = context.evaluated_depsgraph_get()
    try:
        ext = extract(depsgraph, selected_only=options["selected_only"],
                      world=settings.sky == "world")
    except RadiosityError as exc:        # a light core.make_lights refuses (negative power)
        raise BakeError(str(exc)) from exc
    if not ext.parts:
        what = "selected mesh objects" if options["selected_only"] else "visible mesh objects"
        raise BakeError(f"Nothing to bake: no {what} with faces")
    arrays = ext.arrays
    sky = sky_for(settings, arrays.get("world"))      # sky='cie_overcast' replaces the world
    if sky is not arrays.get("world"):
        arrays = dict(arrays, world=sky)
    if not _has_light(arrays):
        unsupported = "; ".join(w for w in ext.warnings if "not supported" in w)
        raise BakeError("No light: add an emissive material or a light"
                        + (f" ({unsupported})" if unsupported else ""))
    try:
        scene = core.make_scene(**arrays)
    except RadiosityError as exc:
        raise BakeError(str(exc)) from exc
    objects = context.scene.objects
    try:
        check_writable([objects[p.object_name] for p in ext.parts],
                       options["make_single_user"], mesh_output=settings.output_mode == "mesh")
    except WriteError as exc:
        raise BakeError(str(exc)) from exc
    for surf in ext.surfaces:
        obj = objects[surf.object_name]
        if obj.data.library is not None or is_baked(obj):
            why = "is linked from a library" if obj.data.library is not None else \
                "shows a baked mesh (Clear Bake on it first)"
            raise BakeError(f"Calculation surface '{obj.name}': its mesh '{obj.data.name}' {why}")
    return BakeInput(scene, settings, ext, context.scene.name, options["make_single_user"],
                     time.perf_counter() - t0, bool(options["selected_only"]))


def _has_light(arrays):
    """Whether anything emits: an emissive face, a point, spot or sun light of power > 0, a
    world colour or a sky."""
    if (arrays["emission"][arrays["face_materials"]] > 0).any() or arrays.get("world") is not None:
        return True
    lights = arrays.get("lights")
    return lights is not None and lights.shines


def compute(bake_input, progress=None, cancel=None):
    """Run the core bake and measure the calculation surfaces (any thread; they are filled in
    place). Raises core.BakeCancelled when cancelled."""
    try:
        result = core.bake(bake_input.scene, bake_input.settings, progress=progress,
                           cancel=cancel)
        surfaces.measure(result, bake_input.extraction.surfaces, cancel)
        return result
    except BakeCancelled:
        raise
    except RadiosityError as exc:
        raise BakeError(str(exc)) from exc


def make_report(bake_input, result, write_seconds):
    """The bake summary (JSON-serialisable dict): core report + settings + add-on notes."""
    report = json.loads(json.dumps(result.report, default=_jsonable))
    ext = bake_input.extraction
    report["settings"] = as_dict(bake_input.settings)
    report["objects"] = len(ext.parts)
    report["instances"] = ext.instances
    report["area_lights"] = ext.area_lights
    report.setdefault("timings", {})
    report["timings"]["read_scene"] = bake_input.read_seconds
    report["timings"]["write"] = write_seconds
    report["warnings"] = list(ext.warnings) + list(report.get("warnings", []))
    report["notes"] = list(ext.notes)
    if ext.surfaces:
        report["calculation_surfaces"] = [s.summary for s in ext.surfaces]
    return report


def _jsonable(value):
    if hasattr(value, "tolist"):
        return value.tolist()
    return str(value)


def apply(context, bake_input, result, keep=True, ready=None, warnings=()):
    """Write the result (main thread) and store the summary; returns the report dict.

    With ``keep`` the result is kept in memory for Relight and the light groups
    (:func:`radiosity_addon.relight.keep`; ``ready``: the kept bake :class:`BakeJob` made,
    every group's solution with it; ``warnings``: its own); a relight writes through here with
    ``keep=False``.

    The core's radiosity mesh (``result.output``) becomes each object's baked mesh
    (``write.write_mesh``); without one ("Existing Vertices"), the colours go onto the user's own
    corners (``write.write_colours``).
    """
    t0 = time.perf_counter()
    scene = context.scene
    objects = {o.name: o for o in scene.objects}
    output = getattr(result, "output", None)
    outdoor = result.report.get("sky", {}).get("outdoor_lux")     # daylight factors beside lux
    try:
        if output is not None:
            written = write_mesh(objects, bake_input.extraction.parts, output, outdoor=outdoor)
        else:
            incident = getattr(result, "corner_incident", None)
            write_colours(objects, bake_input.extraction.parts, result.corner_colours,
                          make_single_user=bake_input.make_single_user,
                          corner_lux=None if incident is None else lux(incident),
                          outdoor=outdoor)
            written = None
        surfaces.write(objects, bake_input.extraction.surfaces)
    except (WriteError, KeyError) as exc:
        raise BakeError(f"Could not write the result: {exc}") from exc
    report = make_report(bake_input, result, time.perf_counter() - t0)
    if written is not None:
        report["output_objects"] = written
    report["warnings"] += list(warnings)
    if ready is not None:
        report["timings"]["light_groups"] = ready.seconds["prepared in the bake"]
    props = getattr(scene, "radiosity", None)
    if keep and hasattr(scene, "radiosity_groups"):
        from . import relight                     # relight writes through this module
        try:
            relight.keep(scene, bake_input, result, ready)
        except Exception as exc:  # a bug there must not fail a written bake: no relight
            relight.drop(scene)
            report["warnings"].append(f"Relight unavailable for this bake "
                                      f"({type(exc).__name__}: {exc})")
    if props is not None:
        props.last_report = json.dumps(report)
        if props.show_bake:
            show_in_viewports([w.screen for w in context.window_manager.windows], True)
    if luxview.is_shown(scene):          # lux in false colour: the new bake's, on its scale
        try:
            luxview.show(scene)
        except (luxview.LuxViewError, ValueError):
            luxview.hide(scene)
    return report


def bake_now(context, options, progress=None, cancel=None):
    """prepare + compute + apply on the calling thread; returns the report dict."""
    bake_input = prepare(context, options)
    result = compute(bake_input, progress, cancel)
    return apply(context, bake_input, result)


class Worker:
    """Work in a thread with progress and a cancel flag, driven by a modal operator's timer
    (the bake's :class:`BakeJob`, Relight's ``relight_ops.RelightJob``).

    Attributes
    ----------
    fraction : float
        Progress in [0, 1], updated by the worker.
    message : str
    error : BaseException or None
        What stopped the worker (``core.BakeCancelled`` after :meth:`cancel`).
    """

    name = "radiosity-worker"

    def __init__(self):
        self.fraction = 0.0
        self.message = "Starting"
        self.error = None
        self._cancel = threading.Event()
        self._thread = threading.Thread(target=self._run, name=self.name, daemon=True)

    def start(self):
        self._thread.start()
        return self

    def cancel(self):
        self._cancel.set()

    @property
    def cancelled(self):
        return self._cancel.is_set()

    def done(self):
        return not self._thread.is_alive()

    def join(self, timeout=None):
        self._thread.join(timeout)
        return self.done()

    def _progress(self, fraction, message):
        self.fraction, self.message = float(fraction), str(message)

    def _run(self):
        try:
            self._work()
        except BaseException as exc:  # handed to the main thread, never lost in the thread
            self.error = exc

    def _work(self):
        raise NotImplementedError


class BakeJob(Worker):
    """The core bake of a prepared input, in a worker thread (:class:`Worker`).

    Attributes
    ----------
    result : core.BakeResult or None
    units : list or None
        ``relight.units_of``: with two groups or more, every group's own solution is made after
        the core bake (:data:`GROUPS_SHARE` of the progress bar; Esc cancels the bake there too).
    ready : relight.Kept or None
        What ``relight.prepared`` made, for :func:`apply` to keep.
    warnings : list of str
        What the worker could not do, for the report.
    """

    name = "radiosity-bake"

    def __init__(self, bake_input, units=None):
        super().__init__()
        self.bake_input = bake_input
        self.result = None
        self.units = units
        self.ready = None
        self.warnings = []

    def _work(self):
        groups = self.units is not None and len(self.units) > 1
        share = 1.0 - GROUPS_SHARE if groups else 1.0
        self.result = compute(self.bake_input, lambda f, m: self._progress(share * f, m),
                              self._cancel.is_set)
        if groups:
            self._groups(share)

    def _groups(self, share):
        """Every light group's own solution (relight.prepared), after the core bake."""
        from . import relight
        self._progress(share, "Light groups")
        try:
            self.ready = relight.prepared(
                self.bake_input, self.result, self.units,
                lambda f, m: self._progress(share + (1.0 - share) * f, f"Light groups: {m}"),
                self._cancel.is_set)
        except BakeCancelled:
            raise
        except Exception as exc:  # a bug there must not fail the bake: Relight makes them
            traceback.print_exc()
            self.warnings.append(f"Light groups not made with the bake ({type(exc).__name__}: "
                                 f"{exc}); the first Relight makes them")
        if self.cancelled:        # Esc after the last poll: still a cancel, nothing written
            raise BakeCancelled("cancelled while the light groups were made")
        self._progress(1.0, "Done")
