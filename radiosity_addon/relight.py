"""Relight and light groups: new light on the last bake's form factors, no new form factors.

After a bake, :func:`keep` holds the core's ``BakeResult`` (its form factors, gather rows and
radiosity mesh) and the extraction that says where its colours go, in this module (``_KEPT``,
keyed by the scene's ``session_uid``): in memory, for this Blender session. Nothing of it is
saved in the .blend (the office sample keeps 248 MB, mostly the radiosity mesh's gather rows);
with Save Relight Data on, saving the .blend writes it beside the file (:mod:`kept_file`) and a
Relight after reopening reads it back (:func:`kept_or_file`). Otherwise, after reopening a
file, or Clear Bake, there is nothing to relight: :func:`relight` says to bake again.

* **Relight** (:func:`relight`): reads the scene again; if anything but the emissive materials'
  strength and colour and the point, spot and sun lights changed, it stops (bake again). Each
  group only scaled (:func:`same.unit_factors`): the groups' weighted sum, no solve. New
  emission goes through ``core.relight`` (a new solve on the kept form factors). The lights'
  direct light is kept summed in the bake: lights scaled alike (one factor per colour channel)
  add the lights' own solution times the factor - 1; lights whose power or colour changed apart
  are relit by ``core.relight(lights=)``, which reads the bake's shadow rays back and keeps the
  gathers and the radiosity mesh (:mod:`core.recolour`: one solve); lights moved, added or
  removed are cast again (shadow rays and gathers again, the form factors kept).
* **Light groups** (:func:`mix`): the solve is linear in the light, so a mix is the light with
  every group at 1 plus each weighted group's own solution times (its weight - 1), no solve
  once that solution is kept. A group is each emissive material (area lights are emissive
  polygons), each point, spot and sun light (named after its object) and the world ("World");
  Blender's light groups (``Object.lightgroup``, ``World.lightgroup``) merge what they hold.
  The groups' own solutions (:mod:`radiosity_addon.relight_solve`) are made every group's at
  once (one ``core.relight_many``, one matrix swept for all): by the panel's bake in its
  worker, after the core bake (:func:`prepared`), so its first Relight or group change solves
  nothing; otherwise when a group is first weighted. A material's emission alone, a light
  alone (the others at power 0: its shadow rays read back), no light for the world. On the
  radiosity mesh too: the mesh is kept. A Relight with groups weighted makes only theirs.

A Relight runs in three steps, as a bake does: :func:`begin` (main thread: the scene read),
:func:`compute` (any thread: the panel's Relight solves in a worker, with progress and Esc, on a
copy of the kept bake, so the group sliders' sums on the kept one stay right while it runs) and
:func:`finish` (main thread: the copy becomes the kept bake, the colours are written by
``job.apply``, exactly as a bake writes them). :func:`relight` runs the three in turn. After
the panel's Relight that solved is written, its run makes every group's own solution in a next
worker (:func:`make_groups`), so a group change after it is a weighted sum, as after the
panel's bake.
"""

import json
import time
import traceback
from contextlib import contextmanager
from dataclasses import dataclass, field, replace

import bpy
import numpy as np

from . import job, kept_file, relight_solve as solving, surfaces
from .light_units import Solution, units as light_units
from .same import BAKE_AGAIN, RelightError, check_baked, read, unit_factors


_KEPT = {}
_TOO_BIG = {}     # session uid -> (MB the last bake would have kept, the memory budget in MB)


@dataclass
class Kept:
    """What relight needs from the last bake of a scene (see the module docstring)."""

    bake_input: object           # job.BakeInput of the bake (extraction: where colours go)
    result: object               # core.BakeResult of the bake: the kept form factors
    selected_only: bool
    units: list                  # [Unit]: the sources of light; units of one name, one group
    emission: np.ndarray         # (M, 3) the emission of the written light
    back_emission: np.ndarray    # (M, 3) or None
    lights_ref: object = None    # core Lights that ``result`` was lit by (the bake's, or relit)
    lights_factor: np.ndarray = field(default_factory=lambda: np.ones(3))
    template: object = None      # the last relit core.BakeResult (report, mesh)
    full: Solution = None        # the light written with every group at 1
    lit: Solution = None         # the lights' and world's solution, at ``lights_ref``'s power
    world: Solution = None       # the world's alone (a cast with no light; 'vertices' output)
    own: dict = field(default_factory=dict)    # unit index -> its lights alone, ``lights_ref``
    basis: dict = field(default_factory=dict)  # unit index -> its Solution at ``emission``,
    #                                            ``lights_factor`` (made when first weighted)
    seconds: dict = field(default_factory=dict)
    kept_mb: float = 0.0         # kept_bytes at keep time (the panel shows it)
    made: dict = field(default_factory=dict)   # relights made together (:func:`_prefetch`)
    planning: dict = None                      # the relights :func:`_prefetch` plans
    calls: dict = field(default_factory=dict)  # progress, cancel of its core calls (the worker)
    scale: dict = field(default_factory=dict)  # unit index -> (3,): the scene's unit is the
    #                                            kept one (``full``'s) times this (no solve)


def kept(scene):
    """The scene's kept bake, or None."""
    return _KEPT.get(scene.session_uid)


def kept_or_file(scene, path=None):
    """The scene's kept bake; when none is kept in memory, the one in the kept bake file at
    ``path`` (default: beside the .blend, when there is one: :mod:`kept_file`), which is kept
    from then on; None when neither. Raises kept_file.KeptFileError when the file is not this
    scene's bake."""
    entry = kept(scene)
    if entry is not None:
        return entry
    if path is None:
        path = kept_file.beside_blend(bpy.data.filepath)
        if path is None:
            return None
    entry = kept_file.load(path, scene)
    _KEPT[scene.session_uid] = entry
    _TOO_BIG.pop(scene.session_uid, None)
    if group_names(entry) != [g.name for g in scene.radiosity_groups]:
        _ops().set_groups(scene, group_names(entry), keep_values=True)
    return entry


def not_kept_sizes(scene):
    """(MB the scene's last bake would have kept, the memory budget in MB) when it was not
    kept for being too big, else None."""
    return _TOO_BIG.get(scene.session_uid)


def not_kept_reason(scene):
    """Why the scene's last bake was not kept ("it needs N MB, above the Memory Budget of M
    MB"), or None when nothing was left out."""
    big = not_kept_sizes(scene)
    if big is None:
        return None
    return f"it needs {big[0]:.0f} MB, above the Memory Budget of {big[1]:.0f} MB"


def keep(scene, bake_input, result, ready=None):
    """Keep a bake for relight and list its light groups on the scene (after job.apply).
    ``ready``: the Kept that :func:`prepared` made of this bake in its worker, if any."""
    entry = ready if ready is not None and ready.result is result else _entry(
        bake_input, result, light_units(bake_input, scene))
    _KEPT[scene.session_uid] = entry
    _ops().set_groups(scene, [u.group for u in entry.units])
    size = kept_bytes(entry)
    entry.kept_mb = size / 2 ** 20
    budget = kept_budget(bake_input)
    _TOO_BIG.pop(scene.session_uid, None)
    if size > budget:
        # Kept rows grow with the scene (the office: 458 MB); above the bake's own memory
        # budget they are not kept, and Relight says why.
        drop(scene)
        _TOO_BIG[scene.session_uid] = (size / 2 ** 20, budget / 2 ** 20)


def _entry(bake_input, result, units):
    arrays = bake_input.scene
    return Kept(bake_input, result, bake_input.selected_only, units, np.array(arrays.emission),
                None if arrays.back_emission is None else np.array(arrays.back_emission),
                lights_ref=arrays.lights, template=result,
                full=Solution.of(result, bake_input.extraction.surfaces))


def units_of(scene, bake_input):
    """The light groups' units of a bake about to run (main thread: they read Blender's light
    groups), for :func:`prepared` in its worker; None when the scene lists no groups."""
    if not hasattr(scene, "radiosity_groups"):
        return None
    try:
        return light_units(bake_input, scene)
    except Exception:       # a bug there must not stop the bake: keep() reads them again
        traceback.print_exc()
        return None


def prepared(bake_input, result, units, progress=None, cancel=None):
    """The Kept of a bake with every light group's own solution made (any thread: the panel's
    bake makes them in its worker, so its first Relight or group change is a weighted sum with
    no solve); None when there is nothing to make (one group), it would not be kept (above
    the memory budget) or a group alone re-meshes (the first Relight then solves, as before).
    ``progress``, ``cancel``: as core.relight_many's (core.BakeCancelled when cancelled)."""
    entry = _entry(bake_input, result, units)
    if len(units) < 2 or kept_bytes(entry) > kept_budget(bake_input):
        return None
    if not make_groups(entry, progress, cancel, "prepared in the bake"):
        return None
    return entry


def _all_made(entry):
    """Whether every group's own solution of a kept bake is made."""
    return all(k in entry.basis for k in range(len(entry.units)))


def needs_groups(entry):
    """Whether a kept bake has two groups or more and not every group's own solution."""
    return entry is not None and len(entry.units) > 1 and not _all_made(entry)


def weights_moved(now, before):
    """Whether a group slider moved: ``now`` ({group: (3,)}) against ``before``."""
    return any(not np.array_equal(w, before[g]) for g, w in now.items())


def _calls(progress, cancel):
    """The progress and cancel keywords core calls take, those given."""
    return {k: f for k, f in dict(progress=progress, cancel=cancel).items() if f is not None}


def make_groups(entry, progress=None, cancel=None, label="groups made"):
    """Make every light group's own solution of a kept bake (any thread: the panel's bake
    before writing, its Relight that solved after writing, each in its worker), so the next
    group change is a weighted sum; False when a group alone re-meshes (nothing made: the first
    change solves, as before). Its seconds go to ``entry.seconds[label]``."""
    t0 = time.perf_counter()
    entry.calls = _calls(progress, cancel)
    try:
        solving.solutions(entry, range(len(entry.units)))
    except RelightError:
        return False
    finally:
        entry.calls = {}
    entry.seconds[label] = time.perf_counter() - t0
    return True


def kept_budget(bake_input):
    """Bytes a bake may keep for relight: the bake's own memory budget (1 GiB by default)."""
    return bake_input.settings.memory_budget


def drop(scene=None):
    """Forget the kept bake of ``scene`` (every scene's without one) and its group list."""
    if scene is None:
        _KEPT.clear()
        return
    _KEPT.pop(scene.session_uid, None)
    if hasattr(scene, "radiosity_groups"):
        _ops().set_groups(scene, [])


def kept_bytes(entry):
    """Bytes of the NumPy arrays a kept bake holds (form factors, gather rows, meshes, bases)."""
    seen, buffers, total, stack = set(), set(), 0, [entry]
    while stack:
        obj = stack.pop()
        if id(obj) in seen or obj is None or isinstance(obj, (str, bytes, int, float, bool)):
            continue
        seen.add(id(obj))
        if isinstance(obj, np.ndarray):      # a view counts its base's memory, once
            while isinstance(obj.base, np.ndarray):
                obj = obj.base
            if obj.base is None and id(obj) not in buffers:
                buffers.add(id(obj))
                total += obj.nbytes
            continue
        if isinstance(obj, dict):
            stack.extend(obj.values())
        elif isinstance(obj, (list, tuple, set)):
            stack.extend(obj)
        elif isinstance(obj, bpy.types.bpy_struct):   # Blender's own data: not ours
            continue
        elif hasattr(obj, "__dict__"):
            stack.extend(vars(obj).values())
        elif hasattr(obj, "__slots__"):
            stack.extend(getattr(obj, s, None) for s in obj.__slots__)
    return total


# ----------------------------------------------------------------------------- groups


def group_names(entry):
    """Group names in order, each once."""
    return list(dict.fromkeys(u.group for u in entry.units))


_QUIET = [False]


@contextmanager
def quiet():
    """Group properties set inside write nothing (filling, resetting or scripting the list)."""
    was, _QUIET[0] = _QUIET[0], True
    try:
        yield
    finally:
        _QUIET[0] = was


def is_quiet():
    return _QUIET[0]


def _ops():
    """radiosity_addon.relight_ops, which holds the scene's group list (and imports us)."""
    from . import relight_ops
    return relight_ops


def group_weights(scene, entry):
    """{group name: (3,) strength x tint} of the scene's group list for a kept bake."""
    return _ops().weights(scene, group_names(entry))


def _write(context, entry, solution, seconds, summed=False):
    """Write ``solution`` as a bake writes (job.apply); returns the report (``summed``: the
    groups' weighted sum, no solve of its own: its time, not the kept bake's stages)."""
    result = solution.as_result(entry.template)
    outdoor = entry.template.report.get("sky", {}).get("outdoor_lux")
    for surf, arriving in zip(solving.surfaces_of(entry), solution.surfaces):
        surfaces.fill(surf, arriving, outdoor)
    report = job.apply(context, entry.bake_input, result, keep=False)
    if summed:
        report["timings"] = dict(total=seconds, light_groups=seconds,
                                 write=report["timings"]["write"])
    report["relight"] = dict(seconds=round(seconds, 4), groups=group_names(entry),
                             kept_mb=round(kept_bytes(entry) / 2 ** 20, 2), summed=summed)
    context.scene.radiosity.last_report = json.dumps(report, default=str)
    return report


@dataclass
class Pending:
    """A Relight begun (:func:`begin`): the scene's light as read, and what :func:`compute` makes
    of it on ``work``, a copy of the kept bake ``entry``."""

    entry: Kept
    work: Kept
    light: tuple             # (emission, back emission, core Lights, lights factor or None)
    scale: dict              # same.unit_factors: each group only scaled, or None
    units: list              # the scene's units, when the lights are cast again (else None)
    weights: dict            # group name -> (3,): the sliders at begin
    t0: float
    solution: Solution = None
    summed: bool = False

    @property
    def instant(self):
        """A weighted sum of solutions already made: no solve, no need for a worker."""
        return self.scale is not None and _all_made(self.entry)


def _copy(entry):
    """A Kept to compute on: its own dicts, the arrays shared (nothing changes them in place)."""
    return replace(entry, basis=dict(entry.basis), own=dict(entry.own), made={}, calls={},
                   seconds=dict(entry.seconds), scale=dict(entry.scale))


def relight(context):
    """Relight the scene's kept bake with the scene's current light (main thread):
    :func:`begin`, :func:`compute`, :func:`finish`.

    When each group's light was only scaled (strength, power, colour: ``same.unit_factors``),
    this is the groups' weighted sum with no solve (every group's solution is made at once
    when one is missing, as :func:`mix` makes them).
    Returns the report dict; raises RelightError (nothing written) when there is no kept bake or
    the scene changed otherwise."""
    return finish(context, compute(begin(context)))


def begin(context):
    """Read the scene's light for a Relight of its kept bake (main thread); a :class:`Pending`.
    Raises RelightError when there is no kept bake or the scene changed otherwise."""
    scene = context.scene
    entry = kept_or_file(scene)
    if entry is None:
        reason = not_kept_reason(scene)
        if reason is not None:
            raise RelightError(f"Relight: the last bake was not kept in memory ({reason}); "
                               f"{BAKE_AGAIN}")
        raise RelightError(f"Relight: no bake is kept in memory for this scene (the .blend "
                           f"holds none; Save Relight Data writes it beside the file); "
                           f"{BAKE_AGAIN}")
    if context.mode != "OBJECT":
        raise RelightError("Switch to Object Mode to relight")
    check_baked(scene, entry)
    t0 = time.perf_counter()
    emission, back, lights, factor = read(context, entry)
    if lights is None:             # every light deleted: the kept ones at no power (factor 0)
        lights = solving.alone(entry.lights_ref, ())
    if factor is not None and not np.array_equal(factor, np.ones(3)) \
            and entry.bake_input.scene.world is not None \
            and entry.bake_input.settings.output_mode == "mesh":
        factor = None              # the world cannot leave the lights' solution on this mesh
    # ``lights``: the scene's, as _reference(entry) holds them
    scale = unit_factors(entry.units, (entry.emission, entry.back_emission, _reference(entry)),
                         (emission, back, lights))
    units = light_units(entry.bake_input, scene, lights) if factor is None else None
    names = [u.group for u in entry.units + (units or [])]
    return Pending(entry, _copy(entry), (emission, back, lights, factor), scale, units,
                   _ops().weights(scene, names), t0)


def compute(pending, progress=None, cancel=None):
    """Solve a begun Relight on its copy of the kept bake (any thread; ``progress``,
    ``cancel``: as core.relight's, core.BakeCancelled when cancelled); returns ``pending``."""
    emission, back, lights, factor = pending.light
    calls = _calls(progress, cancel)
    work = pending.work
    work.calls = calls
    try:
        if pending.scale is not None:
            try:
                work.scale = pending.scale
                pending.solution = solving.mixed(work, pending.weights, True)
                pending.summed = True
                return pending
            except RelightError:   # a group alone re-meshed: solve the scene's light below
                pending.work = work = _copy(pending.entry)
                work.calls = calls
        if factor is None:         # lights moved, added or changed apart: cast them again
            relit = solving.relit_with(work, emission, back, lights)
            work.result = work.template = relit
            work.lights_ref, work.lit, work.world, factor = lights, None, None, np.ones(3)
            work.own, solution = {}, Solution.of(relit, solving.surfaces_of(work))
            work.units = pending.units
        else:                      # one solve: the scene's light as it is now
            scaled = not np.array_equal(factor, np.ones(3))
            if scaled:             # and the lights' own solution, solved with it
                todo = [(emission, back, None), (*solving.dark(work), None) if work.lit is None
                        else None, solving.world_change(work)]
                solving.make_together(work, {solving.key_of(*c): c for c in todo
                                             if c is not None})
            relit = solving.relit_with(work, emission, back)
            _same_mesh_or_new(work, relit, scaled)
            solution = Solution.of(relit, solving.surfaces_of(work))
            if scaled:
                solution = solution.combine(solving.lights_only(work), factor - 1.0)
            work.template = relit
        work.emission, work.back_emission, work.lights_factor = emission, back, factor
        work.full, work.basis, work.scale = solution, {}, {}
        # a group new since a cast is at 1
        pending.solution = solving.mixed(work, pending.weights)
        return pending
    finally:
        work.calls = {}


def finish(context, pending):
    """Write a computed Relight and keep its bake (main thread); returns the report dict.
    Group sliders moved while it ran are mixed in when that solves nothing (otherwise the
    panel's run mixes them once its groups are made; ``pending.weights``: those written).
    Raises RelightError (nothing written) when the kept bake went meanwhile (Clear Bake,
    Forget, a new bake)."""
    scene = context.scene
    if kept(scene) is not pending.entry:
        raise RelightError(f"Relight: the kept bake was cleared while it ran; {BAKE_AGAIN}")
    work, solution = pending.work, pending.solution
    now = group_weights(scene, work)
    if weights_moved(now, pending.weights) and solving.summable(work, now):
        solution = solving.mixed(work, now)     # a slider moved while it ran: no solve
        pending.weights = dict(pending.weights, **now)
    report = _write(context, work, solution, time.perf_counter() - pending.t0,
                    summed=pending.summed)
    _KEPT[scene.session_uid] = work
    if group_names(work) != [g.name for g in scene.radiosity_groups]:
        _ops().set_groups(scene, group_names(work), keep_values=True)
    return report


def _reference(entry):
    """The kept lights at the power ``full`` holds: ``lights_ref`` times ``lights_factor``."""
    ref, f = entry.lights_ref, entry.lights_factor
    if ref is None or not len(ref):
        return ref
    return replace(ref, intensity=ref.intensity * f, sun_irradiance=ref.sun_irradiance * f)


def _same_mesh_or_new(entry, relit, scaled):
    """A relight that re-meshed (exact emitters gather again) writes its own mesh from now on;
    the lights' solution on the old mesh no longer adds to it."""
    if relit.output is None:
        return
    try:
        solving.same_mesh(entry, relit)
    except RelightError:
        if scaled:
            raise RelightError("Relight: the emitters were meshed again (exact emitters), so "
                               f"the lights' power cannot be scaled with them; {BAKE_AGAIN}")
        entry.lit, entry.world, entry.own = None, None, {}


def mix(context, every=True):
    """Write the light groups' weighted sum (no solve once the groups' solutions are kept).
    ``every``: a missing solution makes every group's (the panel: the next change is a sum);
    False: only the weighted groups' (the batch)."""
    entry = kept_or_file(context.scene)
    if entry is None:
        raise RelightError(f"Light groups: no bake is kept in memory; {BAKE_AGAIN}")
    t0 = time.perf_counter()
    solution = solving.mixed(entry, group_weights(context.scene, entry), every=every)
    return _write(context, entry, solution, time.perf_counter() - t0, summed=True)
