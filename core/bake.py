"""The bake pipeline: scene -> patches -> active nodes and form factors -> solve -> corner colours.

Nodes are two-sided (docs/design.md): patch p has a front node p and a back node p + P. Only the
nodes that light can reach are solved: discovery (:func:`core.rows.discover`) starts from the
emitting nodes and adds, wave by wave, every node that an active node's form-factor row hits.
With ``two_sided=False`` back nodes never become active: whatever reaches them is absorbed
(black), and they neither emit nor reflect.

The rows computed during discovery are exactly the rows of the active nodes, so they are kept
(compact, :class:`core.rows.RowStore`) and assembled into the dense matrix of the active nodes. If
they outgrow ``memory_budget`` the bake switches to matrix-free progressive refinement over all
nodes, rows computed on demand (the rows already computed serve as a cache), and the report says
so. The stages themselves, and the energy balance of the report, are in :mod:`core.pipeline`;
the settings in :mod:`core.settings`; reciprocity in :mod:`core.reciprocity`.
"""

import dataclasses
import time
from dataclasses import dataclass, field

import numpy as np

from .adaptive import coarse_patch_size, mesh_colours, min_element_size
from .colours import corner_colours
from .contacts import find_contacts, split_at_contacts
from .covered import Covers
from .criteria import cavity_mask, face_variation, near_emitter_mask, unlit_late_nodes
from .emitters import Emitters, exact_materials
from .footlines import foot_lines, shadow_lines
from .gaplines import gap_lines
from .lights import DirectLight, same_geometry
from .light_list import Lights, make_lights
from .duplicates import (duplicate_warning, fill_duplicate_colours, merge_duplicates,
                         near_duplicate_warning)
from . import blas, memory, parallel
from .orient import orient
from .patches import make_patches, subdivide_patches
from .pipeline import (check_result, colours, form_factors, make_gather,
                       node_arrays, solve, with_world)
from .progress import Monitor, watching
from .reciprocity import make_reciprocal
from .recolour import recoloured, regathered
from .refine import refine_mask
from .rows import form_factor_matrix
from .settings import BakeSettings
from .sky import outdoor_lux, sky_for

__all__ = ["BakeResult", "BakeSettings", "bake", "form_factor_matrix", "make_reciprocal",
           "relight"]

#: Stage boundaries of the overall progress fraction.
_STAGES = dict(patches=(0.0, 0.05), form_factors=(0.05, 0.6), solve=(0.6, 0.7),
               colours=(0.7, 1.0))


@dataclass
class BakeResult:
    """Outcome of :func:`bake` / :func:`relight`.

    Attributes
    ----------
    corner_colours : (C, 3) float64
        Outgoing radiance per scene corner (front side, emission included).
    patch_radiance : (P, 3) float64
        Front-node radiance of every patch.
    node_radiance : (2P, 3) float64
        Radiance of every node (front p, back p + P); zero for nodes never reached.
    patches : core.patches.Patches
    report : dict
        See docs/design.md (keys ``patches``, ``nodes_active``, ``faces_dropped``, ``method``,
        ``solver``, ``iterations``, ``residual``, ``converged``, ``timings``, ``energy``,
        ``form_factor_bytes`` (rows kept for relight; 0 after a matrix-free bake),
        ``matrix_bytes`` (the dense matrix built for the solve, or the row cache of a
        matrix-free solve; freed after it), ``warnings``; ``mesh`` with ``output_mode='mesh'``:
        see :func:`core.adaptive.adaptive_output`; ``face_variation`` with
        ``output_mode='vertices'``: see :func:`core.criteria.face_variation`).
    output : core.outmesh.OutputMesh or None
        The radiosity mesh (``output_mode='mesh'``); None with ``output_mode='vertices'``.
    corner_incident : (C, 3) float64 or None
        Light arriving at every scene corner (irradiance / pi, before the reflectance;
        :func:`core.lux.lux` makes it lux); None with ``corners='average'``.
    """

    corner_colours: np.ndarray
    patch_radiance: np.ndarray
    node_radiance: np.ndarray
    patches: object
    report: dict
    _state: object = field(default=None, repr=False)
    output: object = None
    corner_incident: np.ndarray = None


@dataclass(frozen=True)
class _State:
    """What relight needs: the scene, settings, patches, the kept rows and the gather."""

    scene: object
    settings: BakeSettings
    patches: object
    store: object                 # core.rows.RowStore, or None after a matrix-free solve
    active: np.ndarray
    gather: object = None         # core.pipeline.Gather, core.adaptive.AdaptiveState or None
    on_contact: np.ndarray = None  # (V,) bool: vertices on a contact line, gathered per corner
    contact_lines: object = None  # core.contacts.Contacts ('mesh' output), or None
    flipped: np.ndarray = None    # (F,) bool: faces baked on their back side (core.orient)
    direct: object = None         # core.lights.DirectLight of the scene's lights, or None
    solved: np.ndarray = None     # (2P, 3) solved node radiance (exact emitters' light apart)
    balance: object = None        # core.pipeline.KeptBalance: the reciprocity scaling, or None


def bake(scene, settings=None, *, progress=None, cancel=None):
    """Bake radiosity into corner colours.

    Parameters
    ----------
    scene : core.scene.Scene
    settings : BakeSettings, optional
        Default ``BakeSettings()``.
    progress : callable(fraction: float, message: str), optional
        Overall fraction in [0, 1], non-decreasing.
    cancel : callable() -> bool, optional
        Polled at least every ``POLL_INTERVAL`` seconds of work; True raises
        :class:`~core.errors.BakeCancelled` and nothing is returned.

    Returns
    -------
    BakeResult
    """
    settings = BakeSettings() if settings is None else settings
    if not isinstance(settings, BakeSettings):
        raise TypeError(f"settings must be a BakeSettings; got {type(settings).__name__}")
    with parallel.using(settings.workers, cancel) as shared, memory.stages() as peaks, \
            watching(cancel):
        result = _bake(scene, settings, progress, cancel)
    result.report["peak_mb"] = peaks
    result.report["workers"] = dict(processes=shared["processes"], shared_calls=shared["calls"])
    if "backend" in shared:
        result.report["workers"]["backend"] = shared["backend"]
    if shared["calls"]:
        result.report["workers"]["cpu_seconds"] = round(shared["cpu_seconds"], 3)
    if shared["peak_mb"] is not None:
        result.report["workers"]["peak_mb"] = shared["peak_mb"]
    if shared["problem"] is not None:
        result.report["workers"]["problem"] = shared["problem"]
        result.report.setdefault("warnings", []).append(
            f"workers: {shared['problem']}; this process computed the rest (same result)")
    return result


def _bake(scene, settings, progress, cancel):
    """:func:`bake` with its settings checked, inside its worker pool's context."""
    t_start = time.perf_counter()
    progress = _non_decreasing(progress)   # a second solve (flipped faces) starts over
    if settings.patch_size is None:
        settings = dataclasses.replace(settings, patch_size=0.5 if settings.output_mode == "vertices"
                                       else coarse_patch_size(scene))
    if settings.min_element is None:
        settings = dataclasses.replace(settings, min_element=min_element_size(scene))

    levels = settings.refine_levels
    level_monitor = _LevelMonitor(progress, cancel, 0, levels + 1)
    level_monitor.stage(*_STAGES["patches"])
    level_monitor.update(0.0, "patches")
    t0 = time.perf_counter()
    scene = merge_duplicates(scene)      # stability (issue 11): coincident faces solved as one
    sky = sky_for(settings, scene.world)
    if sky is not scene.world:           # settings.sky names a sky: it replaces the world
        scene = dataclasses.replace(scene, world=sky)
    patches, found, contacts = _solve_patches(scene, settings, level_monitor.check)
    t_patches = time.perf_counter() - t0
    memory.mark("patches")
    level_monitor.update(1.0, f"{len(patches.areas)} patches")

    result = _run(scene, settings, patches, level_monitor, t_start=t_start,
                  timings={"patches": t_patches}, contact_lines=found,
                  on_contact=None if found is None else found.vertices)
    # stability (issue 11): a thin cavity is found on the sides of its faces that face the room,
    # and which side that is, the solve says (core.orient). When the backs of the faces lit from
    # behind bound cavities that the fronts did not (a flipped floor under a shelf), the
    # patches are split there too and solved again (a second solve, in such files only).
    flipped = getattr(result._state, "flipped", None)
    if settings.output_mode == "mesh" and settings.two_sided and flipped is not None \
            and flipped.any():
        t0 = time.perf_counter()
        again, found_again, contacts_again = _solve_patches(scene, settings, level_monitor.check,
                                                            back_open=flipped)
        if again.areas.size != patches.areas.size:
            patches, found, contacts = again, found_again, contacts_again
            first = t0 - t_start
            result = _run(scene, settings, patches, level_monitor, t_start=t_start,
                          timings={"patches": t_patches + time.perf_counter() - t0},
                          contact_lines=found,
                          on_contact=None if found is None else found.vertices)
            result.report["solved_twice"] = (f"flipped faces bound thin cavities: solved again "
                                             f"on {patches.areas.size} patches (the first "
                                             f"solve took {first:.1f} s)")
    on_contact = None if found is None else found.vertices
    if levels:
        result = _refine(scene, settings, patches, result, on_contact, progress, cancel,
                         t_start, found)
    if contacts is not None:
        result.report["contacts"] = contacts
    return result


def _non_decreasing(progress):
    """``progress`` (or None) that never reports a fraction below one it reported."""
    if progress is None:
        return None
    top = [0.0]

    def report(fraction, message):
        top[0] = max(top[0], fraction)
        progress(top[0], message)
    return report


def _solve_patches(scene, settings, check, back_open=None):
    """The solve's patches: the grid, the near-emitter and cavity splits ('mesh' output; the
    backs of ``back_open`` (F,) bool faces bound cavities too), the contact and gap cuts. Returns
    ``(patches, found contacts or None, the contacts' report or None)``. The gap lines
    (:mod:`core.gaplines`) cut after the contacts; like the shadow lines they are not contact
    lines (the light is continuous across them, only steep)."""
    patches = make_patches(scene, settings.patch_size)
    if settings.output_mode == "mesh":
        patches = _split_near(scene, patches, settings.min_element, settings.emitter_levels,
                              check, back_open)
    found = contacts = None
    if settings.contact_cuts:
        found = find_contacts(scene, patches)
        patches, _, contacts = split_at_contacts(scene, patches, found)
        if settings.gap_cuts:
            lines, count = gap_lines(scene, patches, settings.min_element, tol=found.tol,
                                     back_open=back_open)
            patches, _, near = split_at_contacts(scene, patches, lines)
            contacts = dict(contacts, gap_lines=count, gap_cuts=near["cuts"],
                            gap_added=near["added"])
        if settings.shadow_cuts:
            lines, count = foot_lines(scene, patches, found, settings.contrast,
                                      settings.min_element)
            patches, _, more = split_at_contacts(scene, patches, lines)
            contacts = dict(contacts, shadow_lines=count, shadow_cuts=more["cuts"],
                            shadow_added=more["added"])
    return patches, found, contacts


def _split_near(scene, patches, min_size, levels, check=None, back_open=None):
    """Solve patches split where they are too large for their distance to an emitter, or for
    the thin cavity they bound. ``check``: the bake's cancel check; ``back_open``: (F,) bool,
    faces whose back bounds cavities too (:func:`core.criteria.cavity_mask`)."""
    for _ in range(levels):
        emitting = np.any(np.asarray(scene.emission)[patches.material] > 0, axis=1)
        mask = near_emitter_mask(patches, emitting, min_size=min_size) \
            | cavity_mask(patches, min_size=min_size, check=check, emitting=emitting,
                          back_open=None if back_open is None else back_open[patches.face])
        if not mask.any():
            break
        patches, _ = subdivide_patches(patches, mask)
    return patches


def _refine(scene, settings, patches, result, on_contact, progress, cancel, t_start,
            contact_lines):
    """Adaptive refinement after the first solve: split and re-solve, ``refine_levels`` times."""
    levels = settings.refine_levels
    steps = [dict(level=0, patches=int(len(patches.areas)), split=0)]
    total = dict(result.report["timings"])
    min_area = (settings.patch_size / 2 ** levels) ** 2 / 2
    for level in range(1, levels + 1):
        t0 = time.perf_counter()
        emitting = np.any(np.asarray(scene.emission)[patches.material] > 0, axis=1)
        mask = refine_mask(patches, result.patch_radiance, emitting,
                           threshold=settings.refine_threshold,
                           crease_angle=settings.crease_angle, min_area=min_area)
        if not mask.any():
            break
        patches, _ = subdivide_patches(patches, mask)
        t_split = time.perf_counter() - t0
        steps.append(dict(level=level, patches=int(len(patches.areas)),
                          split=int(np.count_nonzero(mask))))
        level_monitor = _LevelMonitor(progress, cancel, level, levels + 1)
        result = _run(scene, settings, patches, level_monitor, t_start=time.perf_counter(),
                      timings={"patches": t_split}, on_contact=on_contact,
                      contact_lines=contact_lines)
        for key, value in result.report["timings"].items():
            total[key] = total.get(key, 0.0) + value
    total["total"] = time.perf_counter() - t_start
    report = dict(result.report, timings=total, refinement=steps)
    return dataclasses.replace(result, report=report)


class _LevelMonitor(Monitor):
    """A Monitor whose stages map into level ``k`` of ``n`` equal parts of the progress bar."""

    def __init__(self, progress, cancel, k, n):
        super().__init__(progress, cancel)
        self._k, self._n = k, n

    def stage(self, lo, hi):
        super().stage((self._k + lo) / self._n, (self._k + hi) / self._n)


def relight(result, *, reflectance=None, emission=None, back_emission=None, lights=None,
            progress=None, cancel=None):
    """Re-solve a bake with new material reflectance and/or emission, reusing its form factors.

    Nodes that become emitters but were never reached get their rows computed (only those
    rows). The reciprocity scaling of the form factors is kept too and applied again without
    iterating while the solved nodes are the same (new rows: it is computed again). A new
    emission with exact emitters (``exact_direct``, core.emitters) casts their
    shadow rays and gathers again. A matrix-free (progressive) bake kept no form factors: it is
    recomputed from scratch and the report says so.

    Parameters
    ----------
    result : BakeResult
        From :func:`bake` or :func:`relight`.
    reflectance : (M, 3) float, optional
        New per-material reflectance in [0, 1) (default: unchanged).
    emission : (M, 3) float, optional
        New per-material emitted radiance >= 0 (default: unchanged).
    back_emission : (M, 3) float, optional
        New radiance of the back sides, for a scene made with ``back_emission`` (one-sided
        emitters); without it such a scene's back sides keep the bake's.
    lights : core.light_list.Lights or sequence of dict, optional
        New point, spot and sun lights (default: unchanged). Their direct light is kept summed
        at every point, so it is cast again and the gathers that hold it are made again (the
        radiosity mesh too); the form factors are kept.
    progress, cancel : callables, optional
        As in :func:`bake`.

    Returns
    -------
    BakeResult
    """
    with watching(cancel):
        return _relight(result, reflectance=reflectance, emission=emission,
                        back_emission=back_emission, lights=lights, progress=progress,
                        cancel=cancel)


def _prepare(result, *, reflectance, emission, back_emission, lights, progress, cancel):
    """(the bake's state with the new direct light, the new scene, the relight's start time,
    or None and the result of a new bake when the shadow lines moved) of :func:`relight`."""
    if not isinstance(result, BakeResult) or not isinstance(result._state, _State):
        raise TypeError(f"result must be a BakeResult from bake(); got {type(result).__name__}")
    state = result._state
    scene = state.scene
    M = len(scene.reflectance)
    changes = {}
    for name, value in (("reflectance", reflectance), ("emission", emission),
                        ("back_emission", back_emission)):
        if value is None:
            continue
        arr = np.array(value, dtype=np.float64)
        if arr.shape != (M, 3):
            raise ValueError(f"{name} must have shape (M, 3) = ({M}, 3); got {arr.shape}")
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"{name} must be finite")
        if name == "reflectance" and (np.any(arr < 0) or np.any(arr >= 1)):
            raise ValueError(f"reflectance must lie in [0, 1); got [{arr.min():.6g}, "
                             f"{arr.max():.6g}]")
        if name.endswith("emission") and np.any(arr < 0):
            raise ValueError(f"{name} must be >= 0; got minimum {arr.min():.6g}")
        arr.setflags(write=False)
        changes[name] = arr
    if lights is not None:
        changes["lights"] = lights if isinstance(lights, Lights) else make_lights(lights)
    new_scene = dataclasses.replace(scene, **changes)
    if not np.any(new_scene.emission[state.patches.material] > 0) \
            and new_scene.lights is None and scene.world is None:
        raise ValueError("emission leaves no emitting patch: nothing to light the scene")
    if "lights" in changes and _lines_moved(state, new_scene):
        # The patches were cut along the old lights' shadow lines: keeping them would leave
        # the new shadows' edges smeared and the old ones cut for nothing (a moved bulb read up
        # to 2.6 % off a fresh bake, tests/core/test_recolour.py). Bake the new scene.
        again = bake(new_scene, state.settings, progress=progress, cancel=cancel)
        again.report.setdefault("warnings", []).append(
            "relight: the shadow lines (Cut at Shadows) moved with the new lights, so the "
            "scene was baked again (form factors not reused)")
        return None, new_scene, None, again
    t_start = time.perf_counter()
    st = state.settings
    if "lights" in changes or (("emission" in changes or "back_emission" in changes) and (
            (state.direct is not None and state.direct.emitters is not None)
            or exact_materials(new_scene, st.exact_direct, st.resolution).any())):
        # The exact emitters' and the lights' light is kept summed at every point. Only their
        # power or colour changed: it is recoloured there from the kept shadow rays
        # (core.recolour). Otherwise it is cast again, and the gathers that hold it are made
        # again (the form factors are kept).
        direct = recoloured(state, new_scene)
        gather = None if direct is None else regathered(state.gather, state.direct, direct)
        state = dataclasses.replace(state, direct=direct, gather=gather)
    return state, new_scene, t_start, None


def _relight(result, *, progress, cancel, **changes):
    state, new_scene, t_start, again = _prepare(result, progress=progress, cancel=cancel,
                                                **changes)
    if again is not None:
        return again
    monitor, st = Monitor(progress, cancel), state.settings
    with parallel.using(st.workers, cancel):
        if state.store is None:
            return _recomputed(new_scene, state, monitor, t_start)
        return _run(new_scene, state.settings, state.patches, monitor, t_start=t_start,
                    timings={"patches": 0.0}, kept=state, on_contact=state.on_contact,
                    contact_lines=state.contact_lines)


def _recomputed(new_scene, state, monitor, t_start):
    """The relight of a matrix-free bake, which kept no form factors: computed again."""
    monitor.stage(*_STAGES["patches"])
    monitor.update(1.0, "patches")
    return _run(new_scene, state.settings, state.patches, monitor, t_start=t_start,
                timings={"patches": 0.0}, on_contact=state.on_contact,
                contact_lines=state.contact_lines, warnings=[
                    "relight: the bake kept no form factors (matrix-free progressive): they "
                    "were recomputed"])


def _lines_moved(state, new_scene):
    """Whether the point, spot and sun lights of ``new_scene`` moved (or came or went) and so
    moved the shadow lines (``shadow_cuts``) that cut the bake's patches.

    A change of power or colour keeps the bake's lines, as it keeps its elements and radiosity
    mesh (placed where the bake's light changes): the light groups' relights (a group at power
    0) must share the bake's patches to add up. Both sets of lines are drawn on the bake's
    patches, which cover the same surfaces as those the bake drew its lines on.
    """
    st = state.settings
    if not (st.shadow_cuts and st.contact_cuts) or state.contact_lines is None:
        return False
    old = state.scene.lights
    new = new_scene.lights
    if (old is None and new is None) or (old is not None and new is not None
                                         and same_geometry(old, new)):
        return False
    a, b = (shadow_lines(scene, state.patches, state.contact_lines, st.contrast,
                         st.min_element) for scene in (state.scene, new_scene))
    return not all(x.shape == y.shape and np.array_equal(x, y) for x, y in zip(a, b))


def _run(scene, settings, patches, monitor, *, t_start, timings, kept=None, on_contact=None,
         contact_lines=None, warnings=()):
    """Form factors (reusing ``kept``'s rows), solve, colours: :func:`_front`, the solve,
    :func:`_back` (core.groups runs them apart). ``timings`` and ``warnings``: those before
    (patches); the report holds them followed by this run's."""
    direct, nodes, ff, sky, more = _front(scene, settings, patches, monitor, kept)
    timings = dict(timings, **more)
    monitor.stage(*_STAGES["solve"])
    monitor.update(0.0, "solving")
    t0 = time.perf_counter()
    sol = solve(ff, nodes, settings, monitor, kept.balance if kept is not None else None)
    monitor.update(1.0, "solved")
    timings["solve"] = time.perf_counter() - t0
    memory.mark("solve")
    return _back(scene, settings, patches, monitor, t_start, timings, kept, on_contact,
                 contact_lines, warnings, direct, nodes, ff, sky, sol)


def _front(scene, settings, patches, monitor, kept):
    """The lights and the form factors of :func:`_run`: (direct light, Nodes, FormFactors,
    directional sky or None, {stage: seconds})."""
    P = len(patches.areas)
    timings = {}
    t0 = time.perf_counter()
    direct = kept.direct if kept is not None else None
    if direct is None:
        emitters = None
        chosen = exact_materials(scene, settings.exact_direct, settings.resolution)
        if chosen.any():                              # stability (issue 11): small lamps
            emitters = Emitters(scene, patches, chosen)
        if scene.lights is not None or scene.world is not None or emitters is not None:
            direct = DirectLight(scene.lights, patches, settings.light_samples, scene.world,
                                 min_size=settings.min_element, emitters=emitters,
                                 covers=Covers(scene))
    nodes = node_arrays(scene, patches, settings.two_sided, direct)
    if direct is not None:
        timings["lights"] = time.perf_counter() - t0
        memory.mark("lights")

    with blas.one_thread():           # the workers fill the cores (core.blas)
        monitor.stage(*_STAGES["form_factors"])
        monitor.update(0.0, "form factors")
        t0 = time.perf_counter()
        skip_late = None
        if settings.output_mode == "mesh" and scene.world is None:  # unlit surfaces cost nothing
            def skip_late(active, late):
                return unlit_late_nodes(scene, patches, active, late, settings.resolution)
        world = scene.world is not None
        sky = None if direct is None else direct.sky        # a directional sky (core.sky)
        if kept is None:
            ff = form_factors(patches, nodes, settings, monitor, skip_late=skip_late,
                              all_nodes=world, sky=sky)
        else:
            ff = form_factors(patches, nodes, settings, monitor, kept.store, kept.active,
                              skip_late=skip_late, all_nodes=world, sky=sky)
        monitor.update(1.0, "form factors done")
        timings["form_factors"] = time.perf_counter() - t0
        memory.mark("form_factors")
    nodes = with_world(nodes, ff.store.row_sums, scene.world, ff.store.sky)
    return direct, nodes, ff, sky, timings


def _back(scene, settings, patches, monitor, t_start, timings, kept, on_contact, contact_lines,
          warnings, direct, nodes, ff, sky, sol):
    """The colours and the report of :func:`_run`: the BakeResult."""
    P = len(patches.areas)
    with blas.one_thread():           # the gathers: as the form factors
        monitor.stage(*_STAGES["colours"])
        monitor.update(0.0, "colours")
        t0 = time.perf_counter()
        # stability (issue 11): each face is baked on the side that receives the light
        # (core.orient). The world lights every side open to it alike: which side faces the room
        # is decided by the rest of the light.
        oriented = sol
        if nodes.sky is not None:
            oriented = dataclasses.replace(sol,
                                           incident=sol.incident - nodes.sky * nodes.areas[:, None])
        side = orient(scene, patches, oriented.incident, settings.two_sided,
                      kept.flipped if kept is not None else None, ff.store.row_sums)
        shown = nodes.shown(sol.node_radiance)       # the transported radiance + exact emission
        room_side = side.room_side(shown)
        gather = kept.gather if kept is not None else None
        mesh = mesh_report = incident = None
        if settings.output_mode == "mesh":
            corner, mesh, gather, mesh_report = mesh_colours(
                scene, settings, patches, sol.node_radiance, sol.incident, gather, contact_lines,
                monitor, direct, lambda: corner_colours(scene, patches, room_side,
                                                        crease_angle=settings.crease_angle),
                flipped=side.flipped)
            element_report = mesh_report.pop("elements", None)
        elif settings.corners == "gather":
            if gather is None:
                gather = make_gather(side.scene, patches, sol.node_radiance, settings, monitor,
                                     on_contact, direct)
            corner, incident, element_report = colours(side.scene, patches, sol.node_radiance,
                                                       settings, gather)
        else:
            corner, incident, element_report = colours(side.scene, side.patches,
                                                       np.concatenate([room_side, shown[P:]]),
                                                       settings, gather)
        corner = fill_duplicate_colours(scene, corner)       # stability (issue 11)
        if mesh is not None:
            incident = np.zeros((scene.n_corners, 3))
            has = gather.user >= 0
            incident[has] = mesh.corner_incident[gather.user[has]]
        if incident is not None:
            incident = fill_duplicate_colours(scene, incident)
        timings["colours"] = time.perf_counter() - t0
        memory.mark("colours")
    monitor.update(1.0, "done")
    timings["total"] = time.perf_counter() - t_start

    checks, energy, n_dropped = check_result(scene, patches, oriented, side.open_back)
    if side.flipped.any():   # stability (issue 11): the flipped faces are baked on the lit side
        checks = [w for w in checks if not w.endswith("on their back side: check normals")]
    checks += [w for w in [duplicate_warning(scene), near_duplicate_warning(scene),
                           side.warning()] if w]
    report = dict(
        patches=P,
        nodes_active=int(np.count_nonzero(sol.active)),
        faces_dropped=n_dropped,
        method=settings.method,
        solver=sol.solver,
        iterations=int(sol.result.iterations),
        residual=float(sol.result.residual),
        converged=bool(sol.result.converged),
        timings=timings,
        energy=energy,
        form_factor_bytes=int(sol.store.nbytes if sol.store is not None else 0),
        reciprocity=sol.reciprocity,
        matrix_bytes=sol.matrix_bytes,
        warnings=list(warnings) + sol.warnings + checks,
    )
    if element_report is not None:
        report["elements"] = element_report
    patch_radiance = room_side
    if mesh_report is not None:
        report["mesh"] = mesh_report
    else:
        report["face_variation"] = face_variation(scene, patches, patch_radiance,
                                                  settings.contrast)
    if sky is not None:              # what a daylight factor divides by (core.lux.summary)
        report["sky"] = dict(kind=sky.kind, outdoor_lux=outdoor_lux(sky))
    if direct is not None and len(direct):
        n_lights = len(direct.lights)
        report["lights"] = dict(count=n_lights, names=list(direct.lights.names),
                                shadow_rays=int(direct.rays))
        if direct.emitters is not None:
            report["lights"]["exact_emitter_faces"] = int(direct.emitters.faces.size)
    state = _State(scene, settings, patches, sol.store, ff.active, gather, on_contact,
                   contact_lines, side.flipped, direct, sol.node_radiance, sol.balance)
    return BakeResult(corner, patch_radiance, shown, patches, report, state, output=mesh,
                      corner_incident=incident)
