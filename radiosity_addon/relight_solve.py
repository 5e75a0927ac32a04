"""The light groups' own solutions of a kept bake (:mod:`radiosity_addon.relight`'s solving).

The solve is linear in the light, so each unit of light (an emissive material, a point, spot or
sun light, the world) has its own solution on the kept form factors, and a mix of the groups is
the light with every group at 1 plus each weighted group's own solution times (its weight - 1)
(:func:`mixed`). The solutions are made at once (:func:`_prefetch`: one ``core.relight_many``).
Any thread: nothing here touches Blender's data.
"""

import time
from dataclasses import replace

import numpy as np

from .. import core
from ..core.errors import BakeCancelled, RadiosityError
from .light_units import Solution
from .same import RelightError


def relit_with(entry, emission, back_emission, lights=None):
    """core.relight of the kept bake with this emission (and these lights: cast again), or
    the one :func:`_prefetch` made."""
    if entry.planning is not None:                  # :func:`_prefetch` plans: a stand-in
        entry.planning.setdefault(key_of(emission, back_emission, lights),
                                  (emission, back_emission, lights))
        return entry.template
    made = entry.made.get(key_of(emission, back_emission, lights))
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


def key_of(emission, back_emission, lights):
    """What tells one relight of the kept bake from another: the emission and the lights'
    power (their places are the kept ones: :func:`alone`)."""
    parts = [emission, back_emission] + ([] if lights is None else
                                         [lights.intensity, lights.sun_irradiance])
    return tuple(None if a is None else np.asarray(a, np.float64).tobytes() for a in parts)


def _prefetch(entry, ks):
    """Make every relight that the own solutions of units ``ks`` need in one
    ``core.relight_many``: one matrix assembled and swept for all (core.groups), about twice
    as fast as one by one. The plan is :func:`_unit` itself, run with the kept bake standing in
    for every relight (:func:`relit_with` records what is asked), then undone;
    :func:`relit_with` hands the relights out when :func:`_unit` runs for real."""
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
    make_together(entry, todo)


def _emission_of(entry, unit):
    """(emission, back emission or None) of a unit of materials alone; (None, None) when it
    is dark."""
    only, back = dark(entry)
    only[unit.materials] = entry.emission[unit.materials]
    if back is not None:
        back[unit.materials] = entry.back_emission[unit.materials]
    if only.any() or (back is not None and back.any()):
        return only, back
    return None, None


def world_change(entry):
    """The relight :func:`_world` asks for, or None (no world, or made)."""
    if entry.bake_input.scene.world is None or entry.world is not None:
        return None
    return (*dark(entry), alone(entry.lights_ref, ()))


def make_together(entry, todo):
    """The relights ``todo`` ({key: (emission, back emission, lights)}) in one
    ``core.relight_many``, for :func:`relit_with` to hand out."""
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
        entry.lit = Solution.of(relit_with(entry, *dark(entry)), surfaces_of(entry))
        entry.seconds["lights_solution"] = time.perf_counter() - t0
    return entry.lit


def dark(entry):
    """(emission, back emission or None) of no emissive material."""
    M = entry.emission.shape[0]
    return np.zeros((M, 3)), None if entry.back_emission is None else np.zeros((M, 3))


def alone(lights, index):
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
    relit = relit_with(entry, *dark(entry), lights=alone(entry.lights_ref, index))
    same_mesh(entry, relit)
    return Solution.of(relit, surfaces_of(entry))


def _world(entry):
    """The world's own solution (a cast with no light; computed once), or None without one."""
    if entry.world is None and entry.bake_input.scene.world is not None:
        t0 = time.perf_counter()
        entry.world = _cast(entry, ())
        entry.seconds["world_solution"] = time.perf_counter() - t0
    return entry.world


def lights_only(entry):
    """The point, spot and sun lights' solution at ``lights_ref``'s power, without the world."""
    world = _world(entry)
    return _lit(entry) if world is None else _lit(entry).combine(world, -1.0)


def surfaces_of(entry):
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
            relit = relit_with(entry, only, back)
            same_mesh(entry, relit)
            sol = Solution.of(relit, surfaces_of(entry))
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
            sol = lights_only(entry)
            for j in others:
                sol = sol.combine(entry.own[j], -1.0)
        else:
            sol, world = _cast(entry, entry.units[k].lights), _world(entry)
            sol = sol if world is None else sol.combine(world, -1.0)
        entry.own[k] = sol
    return entry.own[k]


def solutions(entry, order):
    """Make the own solutions of units ``order`` (:func:`_unit`), at once (:func:`_prefetch`)."""
    try:
        _prefetch(entry, order)
        for k in order:              # in the order _prefetch planned (a light's own solution
            _unit(entry, k)          # may be the rest of the lights': core.lights.CULL)
    finally:
        entry.made = {}


def same_mesh(entry, relit):
    """Group solutions add up only on one radiosity mesh."""
    a, b = entry.template.output, relit.output
    if a is None and b is None:
        return
    if a is None or b is None or a.corner_verts.shape != b.corner_verts.shape \
            or not np.array_equal(a.vertices, b.vertices):
        raise RelightError("Light groups: a group alone re-meshed the radiosity mesh (a new "
                           "emitter, or exact emitters); set its strength back and bake again")


def _weighted(entry, weights):
    """{unit index: (3,) weight} of the units whose weight (times ``entry.scale``) is not 1."""
    w = {k: weights[u.group] * entry.scale.get(k, 1.0) for k, u in enumerate(entry.units)}
    return {k: v for k, v in w.items() if not np.array_equal(v, np.ones(3))}


def summable(entry, weights):
    """Whether :func:`mixed` of ``weights`` solves nothing (every weighted unit's solution is
    made)."""
    return all(k in entry.basis for k in _weighted(entry, weights))


def mixed(entry, weights, every=False):
    """The written Solution: the light with every group at 1, plus each weighted group's own
    solution times (its weight - 1). ``every``: when a group's solution is missing, make every
    group's at once (:func:`_prefetch`), so the next groups' changes solve nothing."""
    w = _weighted(entry, weights)
    order = list(w)
    if every and not summable(entry, weights):
        order = range(len(entry.units))
    solutions(entry, order)
    total = entry.full
    for k, weight in w.items():
        sol = entry.basis[k]
        total = total if sol is None else total.combine(sol, weight - 1.0)
    return total
