"""Operators: bake (modal with a worker thread in the UI, synchronous without one) and clear.

:class:`ModalJob` drives one worker at a time (the bake's, or Relight's in relight_ops): the
bake and Relight are not offered while either runs, and Esc cancels it."""

import traceback

import bpy

from ..core.errors import BakeCancelled
from .job import BakeError, BakeJob, apply, bake_now, options_from_props, prepare
from .luxview import hide as hide_lux
from .relight import drop as drop_kept, units_of
from .write import clear_bake

#: Seconds between modal timer ticks: progress refresh and the latency of Esc (the worker itself
#: polls the cancel flag every core POLL_INTERVAL = 0.2 s, so a cancel lands within ~0.3 s).
TIMER_INTERVAL = 0.1


def lossy_text(report):
    """Existing Vertices: how much the light varies inside the user's faces, from the report's
    ``face_variation`` (core.criteria.face_variation); '' when it varies in none."""
    varying = report.get("face_variation")
    if not isinstance(varying, dict) or not varying.get("faces_varying"):
        return ""
    share = 100.0 * float(varying.get("area_share_varying", 0.0))
    return (f"Lossy: the light varies inside {varying['faces_varying']} faces ({share:.0f} % of "
            f"the area); Output > Radiosity Mesh shows it")


def _summary_line(report):
    lossy = lossy_text(report)
    return (f"Radiosity baked: {report.get('patches', '?')} patches, "
            f"{report.get('iterations', '?')} iterations, "
            f"{report.get('timings', {}).get('total', 0.0):.2f} s" + (f". {lossy}" if lossy
                                                                    else ""))


def panel_job(context, bake_input):
    """The panel's bake in a worker: the core bake, then every light group's own solution (so
    its first Relight or group change is a weighted sum; main thread: the groups are read)."""
    return BakeJob(bake_input, units_of(context.scene, bake_input))


class _Running:
    """The one running modal job (a bake or a Relight), kept outside the operator instance.

    Blender frees an operator's StructRNA when the modal ends, the window closes or the add-on is
    unregistered; touching the instance afterwards raises ReferenceError. Plain module state can
    always be read, so unregister can cancel a bake the operator no longer owns.
    """

    job = None    # job.Worker: BakeJob or RelightJob
    timer = None  # bpy.types.Timer

    @classmethod
    def clear(cls):
        cls.job = cls.timer = None


class ModalJob:
    """A modal operator that drives a :class:`job.Worker` (mixed into the bake's and Relight's
    operators): not offered while either runs (poll), its timer, the progress bar and status,
    Esc. A subclass starts its worker with :meth:`_start`, writes its result in
    ``_finish_job(context, job)`` (main thread) and reports a written one in ``_done``."""

    @staticmethod
    def running():
        return _Running.job is not None

    @classmethod
    def poll(cls, context):
        return context.scene is not None and not ModalJob.running()

    def _start(self, context, worker):
        self._continue(context, worker)
        context.window_manager.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def _continue(self, context, worker):
        """Drive ``worker`` (started here) from this modal operator: its timer, the progress
        bar and status (``_finish_job`` may hand the run on to a next worker with it)."""
        wm = context.window_manager
        _Running.job = worker.start()
        _Running.timer = wm.event_timer_add(TIMER_INTERVAL, window=context.window)
        wm.radiosity_progress = 0.0
        wm.radiosity_status = "Starting"
        wm.progress_begin(0.0, 1.0)
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        job = _Running.job
        if job is None:  # unregistered or finished elsewhere: nothing left to drive
            return {"CANCELLED"}
        try:
            return self._step(context, event, job)
        except Exception as exc:  # a bug: never leave the panel without its button
            traceback.print_exc()
            job.cancel()
            _end_display(context)
            _Running.clear()
            self.report({"ERROR"}, f"{self.failed} ({type(exc).__name__}): {exc}")
            return {"CANCELLED"}

    def _step(self, context, event, job):
        if event.type == "ESC" and event.value == "PRESS":
            job.cancel()
            context.window_manager.radiosity_status = "Cancelling"
            return {"RUNNING_MODAL"}
        # (bpy.types.Event has no 'timer' in 4.2 to 5.0: any TIMER tick refreshes; only ours
        # fires every TIMER_INTERVAL, and an extra refresh costs nothing.)
        if event.type == "TIMER":
            wm = context.window_manager
            if job.done():
                return self._finish(context)
            wm.progress_update(job.fraction)
            wm.radiosity_progress = 100.0 * job.fraction
            wm.radiosity_status = "Cancelling" if job.cancelled else job.message
            if context.workspace is not None:
                context.workspace.status_text_set(
                    f"Radiosity: {100 * job.fraction:.0f} % {job.message}  (Esc to cancel)")
            for area in context.screen.areas if context.screen else ():
                if area.type == "VIEW_3D":
                    area.tag_redraw()
        return {"PASS_THROUGH"}

    def cancel(self, context):
        # Blender calls this when the window closes mid-run: stop the worker, write nothing.
        if _Running.job is not None:
            _Running.job.cancel()
            _Running.job.join(5.0)
        _end_display(context)
        _Running.clear()

    def _ended(self, context, run):
        """Run ``run()`` (the report dict, or None: not ended) and report as the operator ends:
        ``self._done(context, report)``, {'CANCELLED'} (a BakeError: the user's message; a
        bug: its traceback in the console), or None."""
        try:
            report = run()
        except BakeError as exc:           # the user's error, or writing failed
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        except Exception as exc:  # a bug, not a user error: keep the traceback in the console
            traceback.print_exc()
            self.report({"ERROR"}, f"{self.failed} ({type(exc).__name__}): {exc}")
            return {"CANCELLED"}
        return None if report is None else self._done(context, report)

    def _finish(self, context):
        """The one exit of a modal run: timer, progress and status always cleaned up."""
        _end_display(context)
        job = _Running.job
        _Running.clear()
        if job is None:
            return {"CANCELLED"}
        return self._finish_job(context, job)


class RADIOSITY_OT_bake(ModalJob, bpy.types.Operator):
    """Bake diffuse interreflection into the 'Radiosity' colour attribute of the scene's meshes"""

    bl_idname = "radiosity.bake"
    bl_label = "Bake Radiosity"
    bl_options = {"REGISTER", "UNDO"}

    failed = "Radiosity bake failed"

    def _done(self, context, report):
        for warning in report.get("warnings", []):
            self.report({"WARNING"}, warning)
        self.report({"INFO"}, _summary_line(report))
        return {"FINISHED"}

    def execute(self, context):
        return self._ended(context, lambda: bake_now(context, options_from_props(
            context.scene.radiosity)))

    def invoke(self, context, event):
        if bpy.app.background or context.window is None:
            return self.execute(context)
        try:
            bake_input = prepare(context, options_from_props(context.scene.radiosity))
        except BakeError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        return self._start(context, panel_job(context, bake_input))

    def _finish_job(self, context, job):
        if isinstance(job.error, BakeCancelled) or (job.cancelled and job.result is None):
            self.report({"INFO"}, "Radiosity bake cancelled; the scene is unchanged")
            return {"CANCELLED"}
        if job.error is not None:
            self.report({"ERROR"}, f"Radiosity bake failed: {job.error}")
            return {"CANCELLED"}
        return self._ended(context, lambda: apply(context, job.bake_input, job.result,
                                                  ready=job.ready, warnings=job.warnings))


def _end_display(context):
    """Remove the modal timer and the progress display (safe to call twice)."""
    wm = context.window_manager
    if _Running.timer is not None:
        wm.event_timer_remove(_Running.timer)
        _Running.timer = None
    wm.progress_end()
    if hasattr(wm, "radiosity_status"):
        wm.radiosity_status = ""
        wm.radiosity_progress = 0.0
    if context.workspace is not None:
        context.workspace.status_text_set(None)


class RADIOSITY_OT_clear(bpy.types.Operator):
    """Restore the baked meshes and remove the bake's colour and lux attributes (nothing else)"""

    bl_idname = "radiosity.clear"
    bl_label = "Clear Bake"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        props = context.scene.radiosity
        hide_lux(context.scene)        # the false-colour display's settings come back first
        objs = [o for o in context.scene.objects if o.type == "MESH"]
        if props.selected_only:
            objs = [o for o in objs if o.select_get()]
        removed = clear_bake(objs)
        drop_kept(context.scene)       # Relight has nothing left to relight: bake again
        props.last_report = ""
        self.report({"INFO"}, f"Radiosity cleared from {removed} mesh(es)")
        return {"FINISHED"}


CLASSES = (RADIOSITY_OT_bake, RADIOSITY_OT_clear)


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)


def unregister():
    # A bake or Relight still running (quit or disable mid-run): stop the worker; the modal
    # handler ends itself on its next event. Nothing is written.
    job = _Running.job
    if job is not None:
        job.cancel()
        job.join(5.0)
    if _Running.timer is not None:
        try:
            bpy.context.window_manager.event_timer_remove(_Running.timer)
        except (AttributeError, ReferenceError, RuntimeError):
            pass  # the window manager is already gone at quit
    _Running.clear()
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
