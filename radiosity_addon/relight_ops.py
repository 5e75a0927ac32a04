"""Relight in the panel: the Relight operator, the light groups' properties and their list.

The work is in :mod:`radiosity_addon.relight`; this module is what the user touches. Each group
(``Scene.radiosity_groups``: each emissive material, point, spot and sun light, the world, or a
Blender light group) has a strength and a tint; changing either writes the groups' weighted sum
at once (no solve once the groups' solutions are kept). :func:`set_groups` fills the list,
:func:`weights` reads it. The Relight button's solve runs in a worker (:class:`RelightJob`, with
progress and Esc, as the bake's); a Relight that is a weighted sum is written at once.
"""

import os
import traceback

import bpy
import numpy as np
from bpy.app.handlers import persistent

from ..core.errors import BakeCancelled
from . import job, kept_file, relight
from .operators import ModalJob

#: The last light-group error per scene (an update callback cannot report): the panel shows it.
_ERRORS = {}


def _group_changed(self, context):
    # While a bake or Relight runs, its result replaces the groups' (a Relight mixes the
    # sliders as they are when it ends).
    if relight.is_quiet() or context is None or context.scene is None or ModalJob.running():
        return
    scene = context.scene
    _ERRORS.pop(scene.session_uid, None)
    if relight.kept(scene) is None:
        return
    try:
        relight.mix(context)
    except job.BakeError as exc:
        _ERRORS[scene.session_uid] = str(exc)
    except Exception as exc:  # a bug: keep the traceback in the console, the UI alive
        traceback.print_exc()
        _ERRORS[scene.session_uid] = f"Light groups failed ({type(exc).__name__}): {exc}"


def set_groups(scene, names, keep_values=False):
    """Make the scene's group list ``names`` (strength and tint 1, or as they were). An empty
    list leaves no trace in the scene's data (Clear Bake restores it exactly): the stored
    property is removed."""
    if not names and not keep_values:
        groups = scene.radiosity_groups
        if len(groups):
            with relight.quiet():
                groups.clear()
        if "radiosity_groups" in scene.keys():       # Blender 4.x keeps it as an ID property
            del scene["radiosity_groups"]
        return
    with relight.quiet():
        groups = scene.radiosity_groups
        was = {g.name: (g.strength, tuple(g.tint)) for g in groups} if keep_values else {}
        groups.clear()
        for name in dict.fromkeys(names):
            item = groups.add()
            item.name = name
            if name in was:
                item.strength, item.tint = was[name]


def weights(scene, names):
    """{group name: (3,) float64 strength x tint} for ``names`` (1 where the list has none)."""
    out = {name: np.ones(3) for name in names}
    for item in scene.radiosity_groups:
        if item.name in out:
            out[item.name] = item.strength * np.array(item.tint[:3], dtype=np.float64)
    return out


class RADIOSITY_PG_group(bpy.types.PropertyGroup):
    """A light group of the last bake: its strength and tint multiply its light."""

    strength: bpy.props.FloatProperty(
        name="Strength", description="Multiplies this group's light (1: as baked or relit)",
        default=1.0, min=0.0, soft_max=10.0, update=_group_changed)
    tint: bpy.props.FloatVectorProperty(
        name="Tint", description="Multiplies this group's light per colour channel",
        subtype="COLOR", size=3, default=(1.0, 1.0, 1.0), min=0.0, soft_max=1.0,
        update=_group_changed)


class RelightJob(job.Worker):
    """A begun Relight's solve (``relight.compute``) in a worker thread."""

    name = "radiosity-relight"

    def __init__(self, pending):
        super().__init__()
        self.pending = pending

    def _work(self):
        relight.compute(self.pending, lambda f, m: self._progress(f, f"Relight: {m}"),
                        self._cancel.is_set)


class GroupsJob(job.Worker):
    """Every light group's own solution of the kept bake (``relight.make_groups``) in a worker
    thread, after a Relight that solved was written: the next group change is a weighted sum.
    ``weights``: the group sliders the Relight wrote with (they write nothing while it runs)."""

    name = "radiosity-groups"

    def __init__(self, entry, weights):
        super().__init__()
        self.entry, self.weights = entry, weights

    def _work(self):
        relight.make_groups(
            self.entry, lambda f, m: self._progress(f, f"Light groups: {m}"),
            self._cancel.is_set, "groups made after the relight")


class RADIOSITY_OT_relight(ModalJob, bpy.types.Operator):
    """Solve again with the lights' and emissive materials' current strength and colour, on the
    last bake's form factors (geometry and materials must be unchanged)"""

    bl_idname = "radiosity.relight"
    bl_label = "Relight"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        window = context.window          # a script's Relight that solves blocks
        if window is not None:
            window.cursor_modal_set("WAIT")
        try:
            return self._ended(context, lambda: relight.relight(context))
        finally:
            if window is not None:
                window.cursor_modal_restore()

    def invoke(self, context, event):
        if bpy.app.background or context.window is None:
            return self.execute(context)
        begun = {}

        def begin():          # a weighted sum is written at once; a solve goes to a worker
            begun["pending"] = pending = relight.begin(context)
            return relight.finish(context, relight.compute(pending)) if pending.instant \
                else None

        return self._ended(context, begin) or self._start(context, RelightJob(begun["pending"]))

    def _finish_job(self, context, worker):
        if isinstance(worker, GroupsJob):
            return self._groups_made(context, worker)
        if isinstance(worker.error, BakeCancelled) or worker.cancelled:
            self.report({"INFO"}, "Relight cancelled; the colours are as they were")
            return {"CANCELLED"}

        def finish():
            if worker.error is not None:
                raise worker.error
            return relight.finish(context, worker.pending)

        ended = self._ended(context, finish)
        entry = relight.kept(context.scene)
        if ended != {"FINISHED"} or not relight.needs_groups(entry):
            return ended
        # Written (one undo step when the run ends): every group's own solution next, in a
        # worker, so a group change after this Relight is a weighted sum (Esc stops only that).
        return self._continue(context, GroupsJob(entry, worker.pending.weights))

    def _groups_made(self, context, worker):
        """The run's end after :class:`GroupsJob`: the Relight stays written whatever happened
        there; group sliders moved meanwhile are mixed in now."""
        if isinstance(worker.error, BakeCancelled) or worker.cancelled:
            self.report({"INFO"}, "Light groups not made (cancelled); the first group change "
                                  "makes them")
        elif worker.error is not None:
            traceback.print_exception(worker.error)
            self.report({"WARNING"}, f"Light groups not made ({type(worker.error).__name__}: "
                                     f"{worker.error}); the first group change makes them")
        now = relight.group_weights(context.scene, worker.entry)
        if relight.kept(context.scene) is worker.entry \
                and relight.weights_moved(now, worker.weights):
            try:                      # cancelled: solve only the groups the sliders weight
                relight.mix(context, every=False)
            except job.BakeError as exc:
                _ERRORS[context.scene.session_uid] = str(exc)
        return {"FINISHED"}

    failed = "Relight failed"

    def _done(self, context, report):
        _ERRORS.pop(context.scene.session_uid, None)
        for warning in report.get("warnings", []):
            self.report({"WARNING"}, warning)
        self.report({"INFO"}, f"Relit in {report['relight']['seconds']:.2f} s")
        return {"FINISHED"}


class RADIOSITY_OT_groups_reset(bpy.types.Operator):
    """Set every light group's strength and tint back to 1"""

    bl_idname = "radiosity.groups_reset"
    bl_label = "Reset Groups"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        with relight.quiet():
            for item in context.scene.radiosity_groups:
                item.strength, item.tint = 1.0, (1.0, 1.0, 1.0)
        _group_changed(None, context)
        return {"FINISHED"}


class RADIOSITY_OT_relight_forget(bpy.types.Operator):
    """Free the memory the last bake keeps for Relight and the light groups (bake again to
    relight)"""

    bl_idname = "radiosity.relight_forget"
    bl_label = "Forget Kept Bake"
    bl_options = {"REGISTER"}

    def execute(self, context):
        relight.drop(context.scene)
        return {"FINISHED"}


def draw(layout, scene):
    """The Relight button, and the light groups of the kept bake (in the panel's result box)."""
    entry = relight.kept(scene)
    row = layout.row(align=True)
    row.operator("radiosity.relight", icon="LIGHT")
    if entry is None:
        hint = not_kept_hint(scene)
        if hint:
            layout.label(text=hint, icon="INFO")
        return
    row.operator("radiosity.relight_forget", text=f"{entry.kept_mb:.0f} MB", icon="X")
    groups = scene.radiosity_groups
    if len(groups):
        col = layout.column(align=True)
        header = col.row(align=True)
        header.label(text="Light Groups")
        header.operator("radiosity.groups_reset", text="", icon="LOOP_BACK")
        for item in groups:
            row = col.row(align=True)
            row.prop(item, "strength", text=item.name)
            row.prop(item, "tint", text="")
    error = _ERRORS.get(scene.session_uid)
    if error:
        layout.label(text=error, icon="ERROR")


def not_kept_hint(scene):
    """What the panel says under Relight when no bake is kept in memory: why the last one was
    not kept, or that a kept bake file beside the .blend will be read (after reopening it);
    None when neither."""
    big = relight.not_kept_sizes(scene)         # short: the sidebar is narrow
    if big:
        return f"Not kept: needs {big[0]:.0f} MB (budget {big[1]:.0f})"
    path = kept_file.beside_blend(bpy.data.filepath)
    if path is not None:
        return f"Relight reads {os.path.basename(path)}"
    return None


@persistent
def _forget(*_args):
    """A file is loaded: no kept bake belongs to it."""
    relight.drop()
    _ERRORS.clear()


@persistent
def _save_kept(path="", *_args):
    """The .blend is saved: with Save Relight Data on, or a kept bake file already beside it
    (the two stay one), its scenes' kept bakes go beside it."""
    path = path if isinstance(path, str) and path else bpy.data.filepath
    there = kept_file.beside_blend(path) is not None
    scenes = {}
    for scene in bpy.data.scenes:
        props = getattr(scene, "radiosity", None)
        entry = relight.kept(scene)
        if props is not None and (props.save_relight or there) and entry is not None:
            scenes[scene] = entry
    try:
        written = kept_file.with_blend(path, scenes)
    except kept_file.KeptFileError as exc:
        print(f"Radiosity: {exc}")
        for scene in scenes:
            _ERRORS[scene.session_uid] = str(exc)
        return
    if written:
        print(f"Radiosity: kept bake written beside the .blend -> {written}")


CLASSES = (RADIOSITY_PG_group, RADIOSITY_OT_relight, RADIOSITY_OT_groups_reset,
           RADIOSITY_OT_relight_forget)


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.Scene.radiosity_groups = bpy.props.CollectionProperty(type=RADIOSITY_PG_group)
    bpy.app.handlers.load_pre.append(_forget)
    bpy.app.handlers.save_post.append(_save_kept)


def unregister():
    if _forget in bpy.app.handlers.load_pre:
        bpy.app.handlers.load_pre.remove(_forget)
    if _save_kept in bpy.app.handlers.save_post:
        bpy.app.handlers.save_post.remove(_save_kept)
    relight.drop()
    del bpy.types.Scene.radiosity_groups
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
