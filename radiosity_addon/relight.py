"""Relight and light groups: new light on the last bake's form factors, no new form factors.

After a bake, :func:`keep` holds the core's ``BakeResult`` (its form factors, gather rows and
radiosity mesh) and the extraction that says where its colours go, in this module (``_KEPT``,
keyed by the scene's ``session_uid``): in memory, for this Blender session only. Nothing is
saved with the .blend (the office sample keeps 458 MB, mostly the radiosity mesh's gather rows);
after reopening a file, or Clear Bake, there is nothing to relight: :func:`relight` says to bake
again.

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
  The groups' own solutions are made every group's at once (:func:`_prefetch`: one
  ``core.relight_many``, one matrix swept for all): by the panel's bake in its worker, after the
  core bake (:func:`prepared`), so its first Relight or group change solves nothing; otherwise
  when a group is first weighted. A material's emission alone, a light alone (the others at
  power 0: its shadow rays read back), no light for the world. On the radiosity mesh too: the
  mesh is kept. A Relight with groups weighted makes only theirs.

The colours are written by ``job.apply``, exactly as a bake writes them.
"""

import json
import time
import traceback
from contextlib import contextmanager
from dataclasses import dataclass, field, replace

import bpy
import numpy as np

from .. import core
from ..core.errors import BakeCancelled, RadiosityError
from . import job, surfaces
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
    t0 = time.perf_counter()
    entry.calls = dict(progress=progress, cancel=cancel)
    try:
        _solutions(entry, range(len(units)))
    except RelightError:
        return None
    finally:
        entry.calls = {}
    entry.seconds["prepared in the bake"] = time.perf_counter() - t0
    return entry


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


def _weights(scene, entry):
    return _ops().weights(scene, group_names(entry))


# ----------------------------------------------------------------------------- solving


def _relit(entry, emission, back_emission, lights=None):
    """core.relight of the kept bake with this emission (and these lights: cast again), or
    the one :func:`_prefetch` made."""
    if entry.planning is not None:                  # :func:`_prefetch` plans: a stand-in
        entry.planning.setdefault(_key(emission, back_emission, lights),
                                  (emission, back_emission, lights))
        return entry.template
    made = entry.made.get(_key(emission, back_emission, lights))
    if made is not None:
        return made
    try:
        return core.relight(entry.result, **_change(emission, back_emission, lights),
                            **entry.calls)
    except BakeCancelled:
        raise
    except (RadiosityError, ValueError) as exc:
        raise RelightError(f"Relight failed: {exc}") from exc


def _change(emission, back_emission, lights):
    kw = dict(emission=emission)
    if back_emission is not None:
        kw["back_emission"] = back_emission
    if lights is not None:
        kw["lights"] = lights
    return kw


def _key(emission, back_emission, lights):
    """What tells one relight of the kept bake from another: the emission and the lights'
    power (their places are the kept ones: :func:`_alone`)."""
    parts = [emission, back_emission] + ([] if lights is None else
                                         [lights.intensity, lights.sun_irradiance])
    return tuple(None if a is None else np.asarray(a, np.float64).tobytes() for a in parts)


def _prefetch(entry, ks):
    """Make every relight that the own solutions of units ``ks`` need in one
    ``core.relight_many``: one matrix assembled and swept for all (core.groups), about twice
    as fast as one by one. The plan is :func:`_unit` itself, run with the kept bake standing in
    for every relight (:func:`_relit` records what is asked), then undone; :func:`_relit` hands
    the relights out when :func:`_unit` runs for real."""
    todo, saved = {}, {name: getattr(entry, name) for name in ("basis", "own", "lit", "world",
                                                               "seconds")}
    entry.basis, entry.own, entry.seconds, entry.planning = dict(entry.basis), \
        dict(entry.own), {}, todo
    try:
        for k in ks:
            _unit(entry, k)
    finally:
        entry.planning = None
        vars(entry).update(saved)
    _make(entry, todo)


def _emission_of(entry, unit):
    """(emission, back emission or None) of a unit of materials alone; (None, None) when it
    is dark."""
    only, back = _dark(entry)
    only[unit.materials] = entry.emission[unit.materials]
    if back is not None:
        back[unit.materials] = entry.back_emission[unit.materials]
    if only.any() or (back is not None and back.any()):
        return only, back
    return None, None


def _world_change(entry):
    """The relight :func:`_world` asks for, or None (no world, or made)."""
    if entry.bake_input.scene.world is None or entry.world is not None:
        return None
    return (*_dark(entry), _alone(entry.lights_ref, ()))


def _make(entry, todo):
    """The relights ``todo`` ({key: (emission, back emission, lights)}) in one
    ``core.relight_many``, for :func:`_relit` to hand out."""
    if len(todo) < 2:
        return                   # one relight: core.relight, as it comes
    t0 = time.perf_counter()
    try:
        made = core.relight_many(entry.result, [_change(*c) for c in todo.values()],
                                 **entry.calls)
    except BakeCancelled:
        raise
    except (RadiosityError, ValueError) as exc:
        raise RelightError(f"Relight failed: {exc}") from exc
    entry.made = dict(zip(todo, made))
    entry.seconds[f"{len(made)} relights together"] = time.perf_counter() - t0


def _lit(entry):
    """The lights' and world's solution at ``lights_ref``'s power, no emission (computed once:
    one solve, their direct light is kept in the bake)."""
    if entry.lit is None:
        t0 = time.perf_counter()
        entry.lit = Solution.of(_relit(entry, *_dark(entry)), _surfaces(entry))
        entry.seconds["lights_solution"] = time.perf_counter() - t0
    return entry.lit


def _dark(entry):
    """(emission, back emission or None) of no emissive material."""
    M = entry.emission.shape[0]
    return np.zeros((M, 3)), None if entry.back_emission is None else np.zeros((M, 3))


def _alone(lights, index):
    """Core Lights ``lights`` with every light but ``index`` at power 0 (they then cast no
    shadow ray: core.lights.CULL); None for no lights."""
    if lights is None:
        return None
    on = np.isin(np.arange(len(lights)), index)[:, None]
    n = lights.n_points
    return replace(lights, intensity=np.where(on[:n], lights.intensity, 0.0),
                   sun_irradiance=np.where(on[n:], lights.sun_irradiance, 0.0))


def _cast(entry, index):
    """The solution of the kept lights ``index`` alone with the world (if any), no emission
    (``core.relight(lights=)``: the bake's shadow rays read back, one solve)."""
    relit = _relit(entry, *_dark(entry), lights=_alone(entry.lights_ref, index))
    _same_mesh(entry, relit)
    return Solution.of(relit, _surfaces(entry))


def _world(entry):
    """The world's own solution (a cast with no light; computed once), or None without one."""
    if entry.world is None and entry.bake_input.scene.world is not None:
        t0 = time.perf_counter()
        entry.world = _cast(entry, ())
        entry.seconds["world_solution"] = time.perf_counter() - t0
    return entry.world


def _lights_only(entry):
    """The point, spot and sun lights' solution at ``lights_ref``'s power, without the world."""
    world = _world(entry)
    return _lit(entry) if world is None else _lit(entry).combine(world, -1.0)


def _surfaces(entry):
    return entry.bake_input.extraction.surfaces


def _unit(entry, k):
    """Unit k's own Solution at the current emission and lights factor, or None (dark): made
    when its group is first weighted (a solve for emissive materials, a cast for lights), then
    kept until the next Relight."""
    if k in entry.basis:
        return entry.basis[k]
    t0 = time.perf_counter()
    unit, sol = entry.units[k], None
    if len(entry.units) == 1:
        sol = entry.full                                    # the one unit is all the light
    elif unit.materials is not None:
        only, back = _emission_of(entry, unit)
        if only is not None:
            relit = _relit(entry, only, back)
            _same_mesh(entry, relit)
            sol = Solution.of(relit, _surfaces(entry))
            if any(u.materials is None for u in entry.units):
                sol = sol.combine(_lit(entry), -1.0)        # the lights shine in that solve
    elif [j for j, u in enumerate(entry.units) if u.materials is None] == [k] \
            and np.array_equal(entry.lights_factor, np.ones(3)):
        sol = _lit(entry)                                   # every light and the world
    else:
        if unit.lights:
            sol = _own(entry, k).scaled(entry.lights_factor)
        if unit.world:
            sol = _world(entry) if sol is None else sol.combine(_world(entry))
    entry.basis[k] = sol
    entry.seconds[f"group {unit.group}"] = time.perf_counter() - t0
    return sol


def _own(entry, k):
    """The lights of unit k alone, without the world, at ``lights_ref``'s power (kept until
    they are cast again): cast alone, or, once every other unit of lights has its own, the
    rest of the lights' solution (no cast; it then also carries the difference the core's light
    culling makes, core.lights.CULL: a light culled at a point casts one ray there, not its
    penumbra's rounds)."""
    if k not in entry.own:
        others = [j for j, u in enumerate(entry.units) if u.materials is None and u.lights
                  and j != k]
        if all(j in entry.own for j in others):
            sol = _lights_only(entry)
            for j in others:
                sol = sol.combine(entry.own[j], -1.0)
        else:
            sol, world = _cast(entry, entry.units[k].lights), _world(entry)
            sol = sol if world is None else sol.combine(world, -1.0)
        entry.own[k] = sol
    return entry.own[k]


def _solutions(entry, order):
    """Make the own solutions of units ``order`` (:func:`_unit`), at once (:func:`_prefetch`)."""
    try:
        _prefetch(entry, order)
        for k in order:              # in the order _prefetch planned (a light's own solution
            _unit(entry, k)          # may be the rest of the lights': core.lights.CULL)
    finally:
        entry.made = {}


def _same_mesh(entry, relit):
    """Group solutions add up only on one radiosity mesh."""
    a, b = entry.template.output, relit.output
    if a is None and b is None:
        return
    if a is None or b is None or a.corner_verts.shape != b.corner_verts.shape \
            or not np.array_equal(a.vertices, b.vertices):
        raise RelightError("Light groups: a group alone re-meshed the radiosity mesh (a new "
                           "emitter, or exact emitters); set its strength back and bake again")


def _mixed(entry, weights, every=False):
    """The written Solution: the light with every group at 1, plus each weighted group's own
    solution times (its weight - 1). ``every``: when a group's solution is missing, make every
    group's at once (:func:`_prefetch`), so the next groups' changes solve nothing."""
    w = {k: weights[u.group] * entry.scale.get(k, 1.0) for k, u in enumerate(entry.units)}
    wanted = [k for k in w if not np.array_equal(w[k], np.ones(3))]
    order = wanted
    if every and any(k not in entry.basis for k in wanted):
        order = range(len(entry.units))
    _solutions(entry, order)
    total = entry.full
    for k in wanted:
        sol = entry.basis[k]
        total = total if sol is None else total.combine(sol, w[k] - 1.0)
    return total


def _write(context, entry, solution, seconds, summed=False):
    """Write ``solution`` as a bake writes (job.apply); returns the report (``summed``: the
    groups' weighted sum, no solve of its own: its time, not the kept bake's stages)."""
    result = solution.as_result(entry.template)
    outdoor = entry.template.report.get("sky", {}).get("outdoor_lux")
    for surf, arriving in zip(_surfaces(entry), solution.surfaces):
        surfaces.fill(surf, arriving, outdoor)
    report = job.apply(context, entry.bake_input, result, keep=False)
    if summed:
        report["timings"] = dict(total=seconds, light_groups=seconds,
                                 write=report["timings"]["write"])
    report["relight"] = dict(seconds=round(seconds, 4), groups=group_names(entry),
                             kept_mb=round(kept_bytes(entry) / 2 ** 20, 2), summed=summed)
    context.scene.radiosity.last_report = json.dumps(report, default=str)
    return report


def relight(context):
    """Relight the scene's kept bake with the scene's current light (main thread).

    When each group's light was only scaled (strength, power, colour: ``same.unit_factors``),
    this is the groups' weighted sum with no solve (every group's solution is made at once
    when one is missing, as :func:`mix` makes them).
    Returns the report dict; raises RelightError (nothing written) when there is no kept bake or
    the scene changed otherwise."""
    scene = context.scene
    entry = kept(scene)
    if entry is None:
        big = _TOO_BIG.get(scene.session_uid)
        if big is not None:
            raise RelightError(f"Relight: the last bake was not kept in memory (it needs "
                               f"{big[0]:.0f} MB, above the Memory Budget of {big[1]:.0f} MB); "
                               f"{BAKE_AGAIN}")
        raise RelightError(f"Relight: no bake is kept in memory for this scene (bakes are not "
                           f"kept in the saved file); {BAKE_AGAIN}")
    if context.mode != "OBJECT":
        raise RelightError("Switch to Object Mode to relight")
    check_baked(scene, entry)
    t0 = time.perf_counter()
    emission, back, lights, factor = read(context, entry)
    if lights is None:             # every light deleted: the kept ones at no power (factor 0)
        lights = _alone(entry.lights_ref, ())
    if factor is not None and not np.array_equal(factor, np.ones(3)) \
            and entry.bake_input.scene.world is not None \
            and entry.bake_input.settings.output_mode == "mesh":
        factor = None              # the world cannot leave the lights' solution on this mesh
    before = dict(vars(entry))     # ``lights``: the scene's, as _reference(entry) holds them
    scale = unit_factors(entry.units, (entry.emission, entry.back_emission, _reference(entry)),
                         (emission, back, lights))
    if scale is not None:
        try:
            entry.scale = scale
            return _write(context, entry, _mixed(entry, _weights(scene, entry), True),
                          time.perf_counter() - t0, summed=True)
        except RelightError:       # a group alone re-meshed: solve the scene's light below
            vars(entry).update(before)
    try:
        if factor is None:         # lights moved, added or changed apart: cast them again
            relit = _relit(entry, emission, back, lights)
            entry.result = entry.template = relit
            entry.lights_ref, entry.lit, entry.world, factor = lights, None, None, np.ones(3)
            entry.own, solution = {}, Solution.of(relit, _surfaces(entry))
            entry.units = light_units(entry.bake_input, scene, lights)
        else:                      # one solve: the scene's light as it is now
            scaled = not np.array_equal(factor, np.ones(3))
            if scaled:             # and the lights' own solution, solved with it
                todo = [(emission, back, None), (*_dark(entry), None) if entry.lit is None
                        else None, _world_change(entry)]
                _make(entry, {_key(*c): c for c in todo if c is not None})
            relit = _relit(entry, emission, back)
            _same_mesh_or_new(entry, relit, scaled)
            solution = Solution.of(relit, _surfaces(entry))
            if scaled:
                solution = solution.combine(_lights_only(entry), factor - 1.0)
            entry.template = relit
        entry.emission, entry.back_emission, entry.lights_factor = emission, back, factor
        entry.full, entry.basis, entry.scale = solution, {}, {}
        solution = _mixed(entry, _weights(scene, entry))  # a group new since a cast is at 1
        report = _write(context, entry, solution, time.perf_counter() - t0)
    except BaseException:          # nothing was written: the kept bake stays as it was
        vars(entry).update(before)
        raise
    if group_names(entry) != [g.name for g in scene.radiosity_groups]:
        _ops().set_groups(scene, group_names(entry), keep_values=True)
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
        _same_mesh(entry, relit)
    except RelightError:
        if scaled:
            raise RelightError("Relight: the emitters were meshed again (exact emitters), so "
                               f"the lights' power cannot be scaled with them; {BAKE_AGAIN}")
        entry.lit, entry.world, entry.own = None, None, {}


def mix(context, every=True):
    """Write the light groups' weighted sum (no solve once the groups' solutions are kept).
    ``every``: a missing solution makes every group's (the panel: the next change is a sum);
    False: only the weighted groups' (the batch)."""
    entry = kept(context.scene)
    if entry is None:
        raise RelightError(f"Light groups: no bake is kept in memory; {BAKE_AGAIN}")
    t0 = time.perf_counter()
    solution = _mixed(entry, _weights(context.scene, entry), every=every)
    return _write(context, entry, solution, time.perf_counter() - t0, summed=True)
