"""Operators: bake (modal with a worker thread in the UI, synchronous without one) and clear."""

import traceback

import bpy

from ..core.errors import BakeCancelled
from .job import BakeError, BakeJob, apply, bake_now, options_from_props, prepare
from .write import clear_bake

#: Seconds between modal timer ticks: progress refresh and the latency of Esc (the worker itself
#: polls the cancel flag every core POLL_INTERVAL = 0.2 s, so a cancel lands within ~0.3 s).
TIMER_INTERVAL = 0.1


def _summary_line(report):
    return (f"Radiosity baked: {report.get('patches', '?')} patches, "
            f"{report.get('iterations', '?')} iterations, "
            f"{report.get('timings', {}).get('total', 0.0):.2f} s")


class RADIOSITY_OT_bake(bpy.types.Operator):
    """Bake diffuse interreflection into the 'Radiosity' colour attribute of the scene's meshes"""

    bl_idname = "radiosity.bake"
    bl_label = "Bake Radiosity"
    bl_options = {"REGISTER", "UNDO"}

    _job = None
    _timer = None

    @classmethod
    def poll(cls, context):
        return context.scene is not None and not RADIOSITY_OT_bake.running()

    @staticmethod
    def running():
        return RADIOSITY_OT_bake._active is not None

    _active = None  # the operator instance whose bake is running (one at a time)

    def _report_result(self, report):
        for warning in report.get("warnings", []):
            self.report({"WARNING"}, warning)
        self.report({"INFO"}, _summary_line(report))

    def execute(self, context):
        try:
            report = bake_now(context, options_from_props(context.scene.radiosity))
        except BakeError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        except Exception as exc:  # a bug, not a user error: keep the traceback in the console
            traceback.print_exc()
            self.report({"ERROR"}, f"Radiosity bake failed ({type(exc).__name__}): {exc}")
            return {"CANCELLED"}
        self._report_result(report)
        return {"FINISHED"}

    def invoke(self, context, event):
        if bpy.app.background or context.window is None:
            return self.execute(context)
        try:
            bake_input = prepare(context, options_from_props(context.scene.radiosity))
        except BakeError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        wm = context.window_manager
        self._job = BakeJob(bake_input).start()
        self._timer = wm.event_timer_add(TIMER_INTERVAL, window=context.window)
        RADIOSITY_OT_bake._active = self
        wm.radiosity_progress = 0.0
        wm.radiosity_status = "Starting"
        wm.progress_begin(0.0, 1.0)
        wm.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        if event.type == "ESC" and event.value == "PRESS":
            self._job.cancel()
            context.window_manager.radiosity_status = "Cancelling"
            return {"RUNNING_MODAL"}
        if event.type == "TIMER" and event.timer is self._timer:
            job, wm = self._job, context.window_manager
            if job.done():
                return self._finish(context)
            wm.progress_update(job.fraction)
            wm.radiosity_progress = 100.0 * job.fraction
            wm.radiosity_status = job.message
            if context.workspace is not None:
                context.workspace.status_text_set(
                    f"Radiosity: {100 * job.fraction:.0f} % {job.message}  (Esc to cancel)")
            for area in context.screen.areas if context.screen else ():
                if area.type == "VIEW_3D":
                    area.tag_redraw()
        return {"PASS_THROUGH"}

    def cancel(self, context):
        # Blender calls this when the window closes mid-bake: stop the worker, write nothing.
        if self._job is not None:
            self._job.cancel()
            self._job.join(5.0)
        self._finish(context)

    def _finish(self, context):
        """The one exit of a modal bake: timer, progress and status always cleaned up."""
        wm = context.window_manager
        if self._timer is not None:
            wm.event_timer_remove(self._timer)
            self._timer = None
        wm.progress_end()
        wm.radiosity_status = ""
        wm.radiosity_progress = 0.0
        if context.workspace is not None:
            context.workspace.status_text_set(None)
        RADIOSITY_OT_bake._active = None
        job, self._job = self._job, None
        if job is None:
            return {"CANCELLED"}
        if isinstance(job.error, BakeCancelled) or (job.cancelled and job.result is None):
            self.report({"INFO"}, "Radiosity bake cancelled; the scene is unchanged")
            return {"CANCELLED"}
        if job.error is not None:
            self.report({"ERROR"}, f"Radiosity bake failed: {job.error}")
            return {"CANCELLED"}
        try:
            report = apply(context, job.bake_input, job.result)
        except BakeError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        self._report_result(report)
        return {"FINISHED"}


class RADIOSITY_OT_clear(bpy.types.Operator):
    """Remove the 'Radiosity' colour attribute (and nothing else) from the scene's meshes"""

    bl_idname = "radiosity.clear"
    bl_label = "Clear Bake"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        props = context.scene.radiosity
        objs = [o for o in context.scene.objects if o.type == "MESH"]
        if props.selected_only:
            objs = [o for o in objs if o.select_get()]
        removed = clear_bake(objs)
        props.last_report = ""
        self.report({"INFO"}, f"Radiosity cleared from {removed} mesh(es)")
        return {"FINISHED"}


CLASSES = (RADIOSITY_OT_bake, RADIOSITY_OT_clear)


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)


def unregister():
    if RADIOSITY_OT_bake._active is not None and RADIOSITY_OT_bake._active._job is not None:
        RADIOSITY_OT_bake._active._job.cancel()
    RADIOSITY_OT_bake._active = None
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
