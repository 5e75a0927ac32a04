"""The stages of a bake, each a function that takes values and returns values.

:func:`core.bake.bake` and :func:`core.bake.relight` call them in order::

    nodes = node_arrays(scene, patches, two_sided)              # per-node materials and areas
    ff = form_factors(patches, nodes, settings, monitor, kept)  # discovery: rows of active nodes
    sol = solve(ff, nodes, settings, monitor)                   # radiance of every node
    col = colours(scene, patches, sol.node_radiance, ...)       # corner colours
    warnings, energy, n_dropped = check_result(...)

Energy balance (report ``energy``, watts summed over RGB; power = pi x radiance x area):

* ``emitted``  = pi sum_i A_i Le_i over the solved nodes;
* ``absorbed`` = pi sum_i A_i (1 - rho_i) H_i with ``H_i = sum_j F_ij L_j`` the incident
  radiance-equivalent of node i (``pi A_i H_i`` is the power arriving at i), plus the power that
  lands on black back nodes (``two_sided=False``), ``pi sum_i A_i L_i F_ij`` over black j;
* ``escaped``  = pi sum_i A_i L_i (1 - sum_j F_ij): the part of every row that hits nothing;
* ``balance``  = emitted - absorbed - escaped. It is zero up to the solver residual when the form
  factors are reciprocal (``A_i F_ij = A_j F_ji``); a hemicube's reciprocity error shows here too.
  (Matrix-free progressive: the shooting bookkeeping, where balance = the unshot power.)
"""

import dataclasses
from dataclasses import dataclass

import numpy as np

from .colours import corner_colours
from .covered import covered_fronts
from .creases import find_creases
from .elements import bake_elements
from .gather import corner_groups, gather_rows, gathered_colours
from .orient import BACKLIGHT_RATIO, MIN_LIT
from .progress import SubMonitor
from .reciprocity import asymmetry, make_reciprocal, rebalance
from .rows import (RECIPROCAL_METHODS, Batcher, RowStore, discover, row_function, row_seconds,
                   split_rows)
from .sky import is_directional
from .solvers import (matvec, solve_direct, solve_gauss_seidel_many, solve_jacobi,
                      solve_progressive)

#: 'auto' solves directly (LU, exact) up to this many active nodes, block Gauss-Seidel above.
#: Measured on room_with_boxes (bench/bench_solvers.py, 2 shared cores): 548 nodes direct
#: 0.27 s vs Gauss-Seidel 0.08 s; 2148 nodes direct 1.4 s vs 0.11-0.3 s. Below ~1000 nodes
#: the direct solve costs well under a second and leaves no iteration error.
AUTO_DIRECT_MAX_NODES = 1000

#: Progressive shooters per step are capped here (and by the measured batch speed).
MAX_SHOOT_BATCH = 64

#: The report warns when |emitted - absorbed - escaped| exceeds this fraction of the emitted
#: power. With a converged solve the imbalance is the reciprocity error of the form factors,
#: which a hemicube makes large where surfaces are nearer than about a patch size.
ENERGY_WARN_FRACTION = 0.05

#: Share of the colours stage's progress given to the element gathers (they take about a third
#: of the vertex gather's time on the office sample).
ELEMENT_SHARE = 0.3


@dataclass(frozen=True)
class Nodes:
    """Per-node arrays of a bake: front node p, back node p + P.

    Attributes
    ----------
    rho, le : (2P, 3) float64
        Reflectance and emitted radiance.
    areas : (2P,) float64
    allowed : (2P,) bool
        Nodes that may become active (back nodes are black when ``two_sided=False``).
    direct : (2P, 3) float64 or None
        Mean irradiance / pi of every node from the point, spot and sun lights
        (:meth:`core.lights.DirectLight.patch_incident`); None: no such lights.
    sky : (2P, 3) float64 or None
        Irradiance / pi of every node from the world or a directional sky (:func:`with_world`);
        None: none.
    exact : (2P, 3) float64 or None
        The part of ``le`` that :mod:`core.emitters` carries as direct light (the exact
        emitters' own emission): the solve transports ``le - exact`` and what the surfaces
        reflect, so a node's solved radiance leaves it out (:meth:`shown` adds it back).
    direct_exact : (2P, 3) float64 or None
        The exact emitters' share of ``direct``.
    """

    rho: np.ndarray
    le: np.ndarray
    areas: np.ndarray
    allowed: np.ndarray
    direct: np.ndarray = None
    sky: np.ndarray = None
    exact: np.ndarray = None
    direct_exact: np.ndarray = None

    @property
    def arriving(self):
        """(2P, 3) irradiance / pi from outside the surfaces' exchange (lights and world), or
        None."""
        if self.sky is None:
            return self.direct
        return self.sky if self.direct is None else self.sky + self.direct

    @property
    def source(self):
        """(2P, 3) what each node sends before any bounce between surfaces: its emission plus
        the direct light it reflects, ``Le + rho E / pi`` (lights shot first)."""
        arriving = self.arriving
        le = self.le if self.exact is None else self.le - self.exact
        if arriving is None:
            return le
        return le + self.rho * arriving

    def shown(self, radiance):
        """(2P, 3) the radiance a viewer sees of every node from the solved (transported)
        ``radiance``: the exact emitters' own emission added back."""
        return radiance if self.exact is None else radiance + self.exact

    def exact_power(self):
        """(emitted, arriving), each (3,): the exact emitters' power and the part of it that
        reaches the nodes (radiance x area, before pi); zeros without exact emitters."""
        if self.exact is None:
            return np.zeros(3), np.zeros(3)
        a = self.areas[:, None]
        return (self.exact * a).sum(axis=0), (self.direct_exact * a).sum(axis=0)

    @property
    def emitting(self):
        """(E,) int64: allowed nodes that emit (or reflect direct light)."""
        return np.flatnonzero(np.any(self.source > 0, axis=1) & self.allowed)


def with_world(nodes, row_sums, world, sky=None):
    """``nodes`` with a uniform world's light as ``sky``: ``world x (1 - row sum)`` for every
    node with a row (the part of its hemicube that no surface covers). A directional ``world``
    (:class:`core.sky.Sky`) takes ``sky`` (2P, 3) instead: what each node's hemicube gathered
    of it (:attr:`core.rows.RowStore.sky`)."""
    if world is None:
        return nodes
    s = np.asarray(row_sums, dtype=np.float64)
    if is_directional(world):
        light = np.zeros((s.size, 3)) if sky is None else np.asarray(sky, dtype=np.float64)
        keep = np.isfinite(s) & nodes.allowed
        return dataclasses.replace(nodes, sky=np.where(keep[:, None], light, 0.0))
    sky = np.where(np.isfinite(s), np.clip(1.0 - s, 0.0, 1.0), 0.0)
    sky = np.where(nodes.allowed, sky, 0.0)
    return dataclasses.replace(nodes,
                               sky=sky[:, None] * np.asarray(world, dtype=np.float64)[None, :])


def node_arrays(scene, patches, two_sided, direct=None):
    """Per-node reflectance, emission, areas and the nodes allowed to be active (:class:`Nodes`).

    ``direct``: a :class:`core.lights.DirectLight` of the scene's lights, or None.
    """
    P = len(patches.areas)
    rho = np.asarray(scene.reflectance, dtype=np.float64)[patches.material]
    le = np.asarray(scene.emission, dtype=np.float64)[patches.material]
    if two_sided:
        back_rho, back_le = scene.back_materials()
        rho_n = np.concatenate([rho, np.asarray(back_rho, dtype=np.float64)[patches.material]])
        le_n = np.concatenate([le, np.asarray(back_le, dtype=np.float64)[patches.material]])
    else:
        rho_n = np.concatenate([rho, np.zeros_like(rho)])
        le_n = np.concatenate([le, np.zeros_like(le)])
    areas = np.concatenate([patches.areas, patches.areas]).astype(np.float64)
    allowed = np.ones(2 * P, dtype=bool)
    if not two_sided:
        allowed[P:] = False
    # Fronts lying face to face on another face (the floor under a box): black, unlit.
    covered = np.concatenate([covered_fronts(scene, patches), np.zeros(P, dtype=bool)])
    allowed[covered] = False
    rho_n[covered] = 0.0
    direct_n = exact = direct_exact = None
    if direct is not None and len(direct):
        direct_n = np.where(covered[:, None], 0.0, direct.patch_incident(patches, two_sided))
        if direct.emitters is not None:
            mine = np.tile(np.isin(patches.face, direct.emitters.faces), 2)
            exact = np.where(mine[:, None], le_n, 0.0)
            direct_exact = np.where(covered[:, None], 0.0,
                                    direct.patch_incident(patches, two_sided, emitters_only=True))
    return Nodes(rho_n, le_n, areas, allowed, direct_n, exact=exact, direct_exact=direct_exact)


@dataclass(frozen=True)
class FormFactors:
    """Outcome of :func:`form_factors`: the kept rows and what discovery found.

    Attributes
    ----------
    store : core.rows.RowStore
        Rows of every active node (a new store: the one handed in is left as it was).
    active : (2P,) bool
    overflow : bool
        The rows outgrew ``memory_budget``: discovery stopped, the solve runs matrix-free.
    rows_fn : callable
        Computes more rows (the matrix-free solve needs them on demand).
    batch : int
        The batch size discovery reached.
    """

    store: RowStore
    active: np.ndarray
    overflow: bool
    rows_fn: object
    batch: int


def form_factors(patches, nodes, settings, monitor, store=None, active=None, *, skip_late=None,
                 all_nodes=False, sky=None):
    """Discovery from the emitters (only from new ones when ``store`` holds a bake's rows).

    ``skip_late(active, late) -> (len(late),) bool``: front nodes that get no late row (the
    radiosity mesh skips unlit surfaces: :func:`core.criteria.unlit_late_nodes`).
    ``all_nodes``: back nodes get late rows too (a world lights every side open to it).
    ``sky``: a directional :class:`core.sky.Sky` whose light the rows gather (the store's
    ``sky``).
    """
    P = len(patches.areas)
    N = 2 * P
    rng = np.random.default_rng(settings.seed)
    if store is not None:
        # Rows for nodes not reached before: a separate stream, so kept rows stay as they were.
        rng = np.random.default_rng([settings.seed, 1])
    rows_fn = row_function(patches, settings.method, settings.resolution,
                           settings.rotate_hemicube, rng, settings.rays, settings.near, sky=sky)
    batcher = Batcher(N, row_seconds(patches, settings.method, settings.resolution,
                                     settings.rays))
    if store is None:
        store = RowStore(N, N)
        active = np.zeros(N, dtype=bool)
    else:
        store = store.copy()
    emitting = nodes.emitting
    frontier = emitting[~active[emitting]]
    active, overflow = discover(store, rows_fn, nodes.allowed, active, frontier, monitor,
                                settings.memory_budget, batcher)
    # Every front node is solved: it is what the user sees and what gets baked, and a small
    # patch can slip between the pixels of every hemicube that looks at it, so "hit by an
    # active row" alone would leave it black. What these late rows hit is not added: a node
    # that only unlit nodes see (the inside of a box, seen from the floor under it) stays out.
    late = np.flatnonzero(~active[:P] & nodes.allowed[:P])   # not covered fronts (black)
    if skip_late is not None and len(late):
        late = late[~skip_late(active, late)]
    if all_nodes:
        late = np.concatenate([late, P + np.flatnonzero(~active[P:] & nodes.allowed[P:])])
    if len(late) and not overflow:
        active, overflow = discover(store, rows_fn, nodes.allowed, active, late, monitor,
                                    settings.memory_budget, batcher, expand=False)
    return FormFactors(store, active, overflow, rows_fn, batcher.size)


def choose_solver(settings, n_active, overflow):
    """(solver name, warnings): 'progressive_free' when the dense matrix would not fit."""
    budget = settings.memory_budget
    mib = budget / 2**20
    if overflow:
        return "progressive_free", [
            f"form factors of the reachable nodes exceed memory_budget ({mib:.0f} MiB): used "
            "matrix-free progressive refinement (rows recomputed on demand, slower)"]
    solver = settings.solver
    if solver == "auto":
        if n_active <= AUTO_DIRECT_MAX_NODES and 8 * n_active * n_active <= budget:
            return "direct", []
        if 4 * n_active * n_active <= budget:
            return "gauss_seidel", []
        return "progressive_free", [
            f"the form factors of {n_active} nodes need {4 * n_active * n_active / 2**20:.0f} "
            f"MiB, over memory_budget ({mib:.0f} MiB): used matrix-free progressive refinement "
            "(rows recomputed on demand, slower)"]
    need = (8 if solver == "direct" else 4) * n_active * n_active
    if need > budget:
        return "progressive_free", [
            f"solver '{solver}' needs {need / 2**20:.0f} MiB of form factors for {n_active} "
            f"nodes, over memory_budget ({mib:.0f} MiB): used matrix-free progressive "
            "refinement instead"]
    return solver, []


@dataclass(frozen=True)
class Solution:
    """Outcome of :func:`solve`.

    Attributes
    ----------
    node_radiance : (2P, 3) float64
        Zero for nodes never reached. Without the exact emitters' own emission
        (:meth:`Nodes.shown` adds it back).
    result : core.solvers.SolveResult
    solver : str
        The solver that ran.
    active : (2P,) bool
        The solved nodes (after a matrix-free solve: those that emit or receive light).
    incident : (2P, 3) float64
        Power arriving at every node / pi (radiance x area).
    energy_rgb : tuple of three (3,) arrays
        Emitted, absorbed, escaped (radiance x area, before the factor pi).
    reciprocity : dict
    matrix_bytes : int
    store : core.rows.RowStore or None
        Rows kept for relight (None after a matrix-free solve).
    warnings : list of str
    balance : KeptBalance or None
        The reciprocity scaling of a dense solve, kept for relight (None without one).
    """

    node_radiance: np.ndarray
    result: object
    solver: str
    active: np.ndarray
    incident: np.ndarray
    energy_rgb: tuple
    reciprocity: dict
    matrix_bytes: int
    store: object
    warnings: list
    balance: object = None


@dataclass(frozen=True)
class KeptBalance:
    """The reciprocity scaling of a dense solve (:class:`core.reciprocity.Balance`) and what
    its matrix was assembled from. It depends on the form factors and areas only, not on the
    emission or the reflectance: a relight with the same solved nodes and the same stored rows
    rebuilds the reciprocal matrix from it (:func:`core.reciprocity.rebalance`) instead of
    iterating again. Holds 8 bytes per solved node (and per unscaled node); ``active`` is the
    solve's own array and ``batches`` the store's own, shared, not copied."""

    balance: object
    active: np.ndarray          # (2P,) bool: the solved nodes, the rows and columns
    batches: tuple              # the RowStore batches the matrix was assembled from

    def fits(self, active, store, dtype):
        """True when the matrix of ``active`` from ``store`` in ``dtype`` is the one balanced:
        same nodes, same rows (a relight that reached new nodes added rows: recompute)."""
        return (self.balance.dtype == np.dtype(dtype)
                and len(store.batches) == len(self.batches)
                and all(a is b for a, b in zip(store.batches, self.batches))
                and np.array_equal(active, self.active))


def solve(ff, nodes, settings, monitor, kept=None):
    """Solve the radiosity system of the active nodes (dense, or matrix-free if too big).

    ``kept``: the :class:`KeptBalance` of an earlier solve on these form factors (relight),
    reused when it :meth:`~KeptBalance.fits`. :func:`solve_many`: several emissions at once.
    """
    return solve_many(ff, [nodes], settings, monitor, kept)[0]


def solve_many(ff, nodes_list, settings, monitor, kept=None):
    """:func:`solve` for each :class:`Nodes` of ``nodes_list`` (the same nodes and reflectance,
    lit apart: a relight of several light groups): the dense matrix is assembled and balanced
    once, and Gauss-Seidel sweeps every emission together."""
    idx = np.flatnonzero(ff.active)
    solver, warnings = choose_solver(settings, len(idx), ff.overflow)
    if solver == "progressive_free":
        sols = [_solve_matrix_free(ff, nodes, settings, monitor) for nodes in nodes_list]
    else:
        sols = _solve_dense(ff, nodes_list, settings, solver, monitor, kept)
    out = []
    for sol in sols:
        more = []
        if not sol.result.converged:
            r = sol.result
            more.append(f"solver '{r.solver}' stopped after {r.iterations} iterations at "
                        f"residual {r.residual:.3g} > tolerance {settings.tolerance:g} x (1 - "
                        "max reflectance)")
        out.append(dataclasses.replace(sol, warnings=warnings + more + sol.warnings))
    return out


def _solve_dense(ff, nodes_list, settings, solver, monitor, kept=None):
    store, nodes = ff.store, nodes_list[0]
    rho, areas = nodes.rho, nodes.areas
    N = len(areas)
    idx = np.flatnonzero(ff.active)
    n_a = len(idx)
    dtype = np.float64 if solver == "direct" else np.float32
    F = store.assemble(idx, idx, dtype, monitor)
    use_recip = settings.reciprocity
    if use_recip == "auto":
        use_recip = settings.method in RECIPROCAL_METHODS
    balanced = None
    if use_recip and kept is not None and kept.fits(ff.active, store, dtype):
        # Same matrix as the kept solve's: its scaling, in place, without the Sinkhorn sweeps.
        F = rebalance(F, areas[idx], kept.balance, out=F, monitor=monitor)
        recip, balanced = dict(kept.balance.info, reused=True), kept
    elif use_recip:
        F, recip, found = make_reciprocal(F, areas[idx], monitor=monitor, return_balance=True)
        balanced = KeptBalance(found, ff.active, tuple(store.batches))
    else:
        recip = dict(asymmetry_before=asymmetry(F, areas[idx], monitor), sinkhorn_iterations=0)
    black = np.flatnonzero(store.hit() & ~nodes.allowed)   # black back nodes that light reaches
    black_block = store.assemble(idx, black, np.float32, monitor) if len(black) else None
    matrix_bytes = F.nbytes + (black_block.nbytes if black_block is not None else 0)
    common = dict(tol=settings.tolerance, monitor=monitor)
    les = [n.source[idx] for n in nodes_list]
    if solver == "gauss_seidel":
        results = solve_gauss_seidel_many(F, rho[idx], les,
                                          max_iterations=settings.max_iterations, **common)
    else:                                   # one solve per emission, each its part of the bar
        results = []
        for g, le in enumerate(les):
            with monitor.part(g, len(les)):
                if solver == "direct":
                    results.append(solve_direct(F, rho[idx], le, monitor=monitor))
                elif solver == "jacobi":
                    results.append(solve_jacobi(F, rho[idx], le, max_iterations=settings.
                                                max_iterations, **common))
                else:
                    results.append(solve_progressive(
                        None, areas[idx], rho[idx], le, F=F,
                        max_shots=settings.max_iterations * max(n_a, 1), **common))
    # incident power per node (radiance x area), for the energy balance and the warnings
    H = np.zeros((N, 3 * len(les)))
    H[idx] = matvec(F, np.concatenate([res.radiance for res in results], axis=1))
    out = []
    for g, (nodes, res) in enumerate(zip(nodes_list, results)):
        L = res.radiance
        node_radiance = np.zeros((N, 3))
        node_radiance[idx] = L
        incident = H[:, 3 * g:3 * g + 3] * areas[:, None]
        if nodes.arriving is not None:      # the lights' and the world's light arrives too
            incident += nodes.arriving * areas[:, None]
        sent = areas[idx, None] * L                              # (n_a, 3)
        if black_block is not None:
            incident[black] = black_block.T.astype(np.float64) @ sent
        escaped = ((1.0 - store.row_sums[idx])[:, None] * sent).sum(axis=0)
        absorbed = ((1.0 - rho) * incident).sum(axis=0)
        # The exact emitters' power counts as emitted, what of it reaches no node as escaped.
        exact_out, exact_in = nodes.exact_power()
        transported = nodes.le if nodes.exact is None else nodes.le - nodes.exact
        emitted = (transported[idx] * areas[idx, None]).sum(axis=0) + _direct_power(nodes) \
            + exact_out - exact_in
        escaped = escaped + exact_out - exact_in
        out.append(Solution(node_radiance, res, solver, ff.active, incident,
                            (emitted, absorbed, escaped), recip, int(matrix_bytes), store, [],
                            balanced))
    return out


def _solve_matrix_free(ff, nodes, settings, monitor):
    store, rows_fn = ff.store, ff.rows_fn
    N = len(nodes.areas)

    def rows_on_demand(keys):
        out = np.empty((len(keys), N))
        have = store.has(keys)
        if have.any():
            out[have] = store.rows(keys[have])
        if (~have).any():
            out[~have] = split_rows(rows_fn(keys[~have]))[0]
        return out

    recip = dict(asymmetry_before=None, sinkhorn_iterations=0,
                 note="matrix-free shooting conserves energy by construction")
    res = solve_progressive(rows_on_demand, nodes.areas, nodes.rho, nodes.source,
                            tol=settings.tolerance, max_shots=settings.max_iterations * N,
                            batch=int(np.clip(ff.batch, 1, MAX_SHOOT_BATCH)), monitor=monitor)
    st = res.stats
    incident = st["incident"]
    emitted, absorbed = st["emitted"], st["absorbed"]
    if nodes.arriving is not None:   # shooting counted rho E / pi as emission: count E instead
        direct = nodes.arriving * nodes.areas[:, None]
        incident = incident + direct
        emitted = emitted - (nodes.rho * direct).sum(axis=0) + direct.sum(axis=0)
        absorbed = absorbed + ((1.0 - nodes.rho) * direct).sum(axis=0)
    exact_out, exact_in = nodes.exact_power()
    active = np.any(incident > 0, axis=1) | np.any(nodes.source > 0, axis=1)
    return Solution(res.radiance, res, "progressive", active, incident,
                    (emitted + exact_out - exact_in, absorbed,
                     st["escaped"] + exact_out - exact_in), recip, int(store.nbytes), None, [])


def _direct_power(nodes):
    """(3,) the lights' and the world's light arriving at the nodes (radiance x area, before
    pi)."""
    if nodes.arriving is None:
        return np.zeros(3)
    return (nodes.arriving * nodes.areas[:, None]).sum(axis=0)


@dataclass(frozen=True)
class Gather:
    """What the final gather keeps for relight: corner groups, their rows, receiver elements,
    and the light from beyond their surfaces at the groups (lights and world,
    :meth:`core.lights.DirectLight.extra`; or None)."""

    groups: object
    rows: RowStore
    elements: object
    direct: np.ndarray = None
    creases: object = None        # core.creases.Creases: entries read at a crease's light


def make_gather(scene, patches, node_radiance, settings, monitor, on_contact=None, direct=None):
    """Receiver elements (if ``element_levels``) and the gather rows at every corner group.

    ``direct``: a :class:`core.lights.DirectLight`, evaluated at the groups' points.
    """
    elements = bake_elements(scene, patches, node_radiance, settings,
                             SubMonitor(monitor, 0.0, ELEMENT_SHARE), direct)
    seen = patches if elements is None else elements.patches
    groups = corner_groups(scene, crease_angle=settings.crease_angle, on_contact=on_contact)
    sub = SubMonitor(monitor, ELEMENT_SHARE if elements is not None else 0.0, 1.0)
    rows = gather_rows(seen, groups, resolution=settings.resolution,
                       rotate=settings.rotate_hemicube,
                       rng=np.random.default_rng([settings.seed, 2]), monitor=sub,
                       sky=None if direct is None else direct.sky)
    at_points = None
    if direct is not None:
        at_points = direct.extra(groups.points, groups.normals, rows.row_sums, sky=rows.sky)
    creases = find_creases(groups.points, groups.normals, rows, seen,
                           crease_angle=settings.crease_angle)
    return Gather(groups, rows, elements, at_points, creases)


def colours(scene, patches, node_radiance, settings, gather):
    """Corner colours (C, 3), the light arriving at every corner (C, 3: irradiance / pi, zero
    at the corners of dropped faces; None for ``corners='average'``) and the elements' report
    (or None).

    ``gather`` (:class:`Gather`) is needed for ``corners='gather'``; ignored for 'average'. The
    elements' radiance and the gather rows' products are computed once for both.
    """
    P = len(patches.areas)
    patch_radiance = node_radiance[:P]
    if settings.corners != "gather":
        return corner_colours(scene, patches, patch_radiance,
                              crease_angle=settings.crease_angle), None, None
    element_report = None
    seen_radiance = node_radiance
    if gather.elements is not None:
        elements = gather.elements
        seen_radiance = elements.node_radiance(scene, node_radiance)
        element_report = dict(elements=int(elements.parent.size),
                              gathered=int(elements.computed.size), levels=elements.levels)
    # The patch average only fills the corners of dropped faces, which have no gather.
    fallback = np.zeros((scene.n_corners, 3))
    if np.any(gather.groups.group < 0):
        fallback = corner_colours(scene, patches, patch_radiance,
                                  crease_angle=settings.crease_angle)
    corner, inc = gathered_colours(scene, gather.groups, gather.rows, seen_radiance, fallback,
                                   gather.direct, gather.creases)
    incident = np.zeros((scene.n_corners, 3))
    ok = gather.groups.group >= 0
    incident[ok] = inc[gather.groups.group[ok]]
    return corner, incident, element_report


def check_result(scene, patches, sol, open_back=None):
    """Warnings about the scene and the energy balance, and the balance in watts (dict)."""
    warnings = []
    n_dropped = scene.faces_dropped           # degenerate only (duplicates: core.duplicates)
    if n_dropped:
        warnings.append(f"{n_dropped} degenerate faces (zero area) were dropped")
    n_back = faces_lit_from_behind(patches, sol.incident, scene.emission, open_back)
    if n_back:
        warnings.append(f"{n_back} faces receive more light on their back side: check normals")
    emitted, absorbed, escaped = (float(np.pi * x.sum()) for x in sol.energy_rgb)
    balance = emitted - absorbed - escaped
    if emitted > 0 and abs(balance) > ENERGY_WARN_FRACTION * emitted:
        warnings.append(f"energy balance off by {100 * balance / emitted:+.1f} % of the emitted "
                        "power: the form factors are not reciprocal (surfaces nearer than about "
                        "a patch size?); try method='hybrid' or a smaller patch_size")
    energy = dict(emitted=emitted, absorbed=absorbed, escaped=escaped, balance=balance)
    return warnings, energy, n_dropped


def faces_lit_from_behind(patches, incident, emission, open_back=None):
    """Number of non-emitting faces whose back nodes receive more power than their front nodes,
    and more than ``MIN_LIT`` x the scene's mean irradiance (a leak into a closed box is no sign
    of a flipped normal), not counting ``open_back`` faces ((F,) bool: lit from the outside by
    design)."""
    P = len(patches.areas)
    power = incident.sum(axis=1)
    n_faces = len(patches.face_patch_start) - 1
    front = np.bincount(patches.face, weights=power[:P], minlength=n_faces)
    back = np.bincount(patches.face, weights=power[P:], minlength=n_faces)
    area = np.bincount(patches.face, weights=patches.areas, minlength=n_faces)
    mean_irradiance = power.sum() / max(2.0 * float(area.sum()), np.finfo(float).tiny)
    emits = np.zeros(n_faces, dtype=bool)
    emits[patches.face[np.any(np.asarray(emission)[patches.material] > 0, axis=1)]] = True
    if open_back is not None:
        emits |= open_back
    lit = (back > 0) & (back > MIN_LIT * mean_irradiance * area)
    return int(np.count_nonzero((back > BACKLIGHT_RATIO * front) & lit & ~emits))
