"""The bake pipeline: scene -> patches -> active nodes and form factors -> solve -> corner colours.

Nodes are two-sided (docs/design.md): patch p has a front node p and a back node p + P. Only the
nodes that light can reach are solved: discovery starts from the emitting nodes and adds, wave by
wave, every node that an active node's form-factor row hits. With ``two_sided=False`` back nodes
never become active: whatever reaches them is absorbed (black), and they neither emit nor reflect.

The rows computed during discovery are exactly the rows of the active nodes, so they are kept
(compact: per batch, only the columns it hit) and assembled into the dense matrix of the active
nodes. If they outgrow ``memory_budget`` the bake switches to matrix-free progressive refinement
over all nodes, rows computed on demand (the rows already computed serve as a cache), and the
report says so.

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
import time
from dataclasses import dataclass, field

import numpy as np

from .constants import (DEFAULT_CREASE_ANGLE, DEFAULT_MAX_ITERATIONS, DEFAULT_MEMORY_BUDGET,
                        DEFAULT_TOLERANCE)
from .errors import SettingsError
from .gather import compact_rows
from .progress import Monitor, SubMonitor
from .solvers import (matvec, solve_direct, solve_gauss_seidel, solve_jacobi,
                      solve_progressive)

METHODS = ("hemicube", "exact", "hybrid")
SOLVERS = ("auto", "direct", "jacobi", "gauss_seidel", "progressive")

#: 'auto' solves directly (LU, exact) up to this many active nodes, block Gauss-Seidel above.
#: Measured on room_with_boxes (bench/bench_solvers.py, 2 shared cores): 548 nodes direct
#: 0.27 s vs Gauss-Seidel 0.08 s; 2148 nodes direct 1.4 s vs 0.11-0.3 s. Below ~1000 nodes
#: the direct solve costs well under a second and leaves no iteration error.
AUTO_DIRECT_MAX_NODES = 1000

#: Form-factor batches are sized for about this much work, so that progress and cancel are
#: polled well within half a second (the first batches are smaller still: 1, 4, 16, ...).
BATCH_SECONDS = 0.15

#: Cost model of one form-factor row (seconds, 2 shared cores), used to size batches. Batch
#: sizes must not depend on measured time: the random draws of a batch (hemicube rotations,
#: visibility rays) depend on its composition, and the bake must be deterministic given
#: ``seed``. Fitted on room_with_boxes at R = 64 (bench/bench_solvers.py): 2.0 ms per row at
#: 1000 triangles, 4.1 ms at 4000, 17.6 ms at 16000; 'exact' 0.18 s per row at 490 patches
#: with 16 rays; 'hybrid' about 3 hemicubes.
ROW_SECONDS_PER_PIXEL = 2.5e-7
ROW_SECONDS_PER_TRIANGLE = 1.0e-6
ROW_SECONDS_PER_PAIR_RAY = 2.3e-5
HYBRID_COST_FACTOR = 3.0

#: A batch never holds more than this many float64 row entries (S x 2P): 64 MB.
MAX_BATCH_ENTRIES = 8_000_000

#: Cap on sources per form-factor batch, and growth factor of the first batches.
MAX_BATCH_SOURCES = 1024
BATCH_GROWTH = 4

#: Progressive shooters per step are capped here (and by the measured batch speed).
MAX_SHOOT_BATCH = 64

#: A face is reported as lit from behind when its back side receives more than this times the
#: power its front side receives (1: "more light on the back").
BACKLIGHT_RATIO = 1.0

#: Smallest memory_budget accepted (bytes): below this even a small room's rows do not fit.
MIN_MEMORY_BUDGET = 1 << 20

#: The report warns when |emitted - absorbed - escaped| exceeds this fraction of the emitted
#: power. With a converged solve the imbalance is the reciprocity error of the form factors,
#: which a hemicube makes large where surfaces are nearer than about a patch size.
ENERGY_WARN_FRACTION = 0.05

#: Stage boundaries of the overall progress fraction.
_STAGES = dict(patches=(0.0, 0.05), form_factors=(0.05, 0.6), solve=(0.6, 0.7),
               colours=(0.7, 1.0))

CORNERS = ("gather", "average")
OUTPUTS = ("mesh", "vertices")

#: Share of the colours stage's progress given to the element gathers (they take about a third
#: of the vertex gather's time on the office sample).
ELEMENT_SHARE = 0.3


# ----------------------------------------------------------------------------- settings


def _is_int(value):
    return isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))


def _is_real(value):
    return isinstance(value, (int, float, np.integer, np.floating)) and \
        not isinstance(value, (bool, np.bool_)) and np.isfinite(value)


@dataclass(frozen=True)
class BakeSettings:
    """Settings of a bake. Validated on construction (``SettingsError`` names the setting).

    Attributes
    ----------
    patch_size : float or None
        Largest patch edge in scene metres (> 0). None (default): 0.5 m with
        ``output='vertices'``; with ``output='mesh'`` the coarse start of the adaptive mesh,
        1 m clamped to [diagonal / 400, diagonal / 8] of the scene's bounding box
        (:func:`core.adaptive.coarse_patch_size`).
    method : str
        Form factors: ``'hemicube'``, ``'exact'`` (contour formula x ray-traced visibility) or
        ``'hybrid'`` (hemicube with near pairs done exactly).
    resolution : int
        Hemicube resolution R (pixels across the top face), even, 4 to 4096.
    rotate_hemicube : bool
        Random rotation of each hemicube about its normal (breaks up aliasing; drawn from
        ``seed``).
    solver : str
        ``'auto'``, ``'direct'``, ``'jacobi'``, ``'gauss_seidel'`` or ``'progressive'``.
    tolerance : float
        Relative residual at which iterative solvers stop, in (0, 1).
    max_iterations : int
        Sweep cap of Jacobi / Gauss-Seidel (progressive: shots capped at 50 x nodes), >= 1.
    two_sided : bool
        Both sides of every polygon are surfaces (Cycles' behaviour). False: back sides absorb.
    crease_angle : float
        Degrees in [0, 180]; corner colours average patches within it.
    memory_budget : int
        Bytes allowed for kept form factors (>= 1 MiB).
    seed : int
        Seed of every random choice (hemicube rotations, rays), >= 0.
    rays : int
        Visibility rays per patch pair of the 'exact' and 'hybrid' methods, >= 1.
    reciprocity : bool or 'auto'
        Make the kept form factors reciprocal (A_i F_ij = A_j F_ji) with their row sums kept
        (:func:`make_reciprocal`), so that energy is conserved where near surfaces make the
        hemicube's point-source estimates disagree. Dense solves only: matrix-free shooting
        conserves energy by construction. 'auto': on for 'hemicube' (on room_with_boxes(500)
        it cuts the error against the exact method from 85 % to 25 % and the energy imbalance
        from -27 % to 0), off for 'hybrid' and 'exact', whose near pairs are already accurate
        and for which blending in the far hemicube estimates adds ~1 % error.
    near : float
        'hybrid' only: pairs whose centres are nearer than ``near`` x the larger patch size
        (sqrt of area) get exact form factors instead of the hemicube's point-source estimate.
    refine_levels : int
        Adaptive refinement, 0 to 4 levels: after a solve, every patch whose light differs from
        a neighbour on the same smooth surface by more than ``refine_threshold`` (relative
        luminance) is split in four and the scene is solved again (:mod:`core.refine`). Patches
        are spent where the light changes: shadow edges, light footprints, room corners.
    refine_threshold : float
        Relative luminance difference between neighbouring patches that marks both, in (0, 1).
    element_levels : int
        Receiver elements for the final gather, 0 to 3 levels (``corners='gather'`` only):
        after the solve, patches whose light differs from a smooth neighbour's by more than
        ``element_threshold`` are split in four, and each new element's radiance is gathered at
        its centre from the solved patches (:mod:`core.elements`). The vertex gather then sees
        the light's gradient across a patch instead of its mean: without it, a floor sees the
        ceiling patches half over a hung luminaire at their bright mean, while it only sees
        their dark half. Costs one hemicube per new element; no re-solve.
    element_threshold : float
        Relative luminance difference between neighbours that splits them into elements, in
        (0, 1).
    contact_cuts : bool
        Cut patches along the lines where other surfaces touch or pierce them (an object on a
        floor, a shelf in its side panels; :mod:`core.contacts`) before the solve. Without it, a
        patch straddling an object's outline carries one radiance for its lit and its covered
        part: light leaks into the object and its foot comes out too dark.
    corners : str
        How corner colours are made from the solution. ``'gather'`` (default): a final gather
        at every vertex (:mod:`core.gather`), the radiance at the vertex itself, as Cycles bakes
        it; costs about one more hemicube per vertex. ``'average'``: the area-weighted mean of
        the patches around the vertex (:mod:`core.colours`), free but a patch-mean value: off by
        tens of percent next to luminaires, in room corners and along shadow edges.
        ``output='mesh'`` always gathers.

    --- adaptive output mesh (issue 9; :mod:`core.adaptive`) ---
    output : str
        ``'mesh'`` (default): the baked result is the radiosity mesh itself
        (``BakeResult.output``, a :class:`core.outmesh.OutputMesh`): the patches' elements,
        refined where the light changes, conforming, each vertex gathered. ``'vertices'``:
        colours only at the user's own corners (the behaviour before issue 9; the report's
        ``face_variation`` says how much light varies inside the user's faces).
    contrast : float
        Relative luminance contrast between the vertices of one element, in (0, 1), above
        which it is split ('mesh' only). Relative to the brighter vertex, never to less than
        half the scene's mean luminance.
    min_element : float
        Smallest element edge (m, > 0) refinement makes ('mesh' only).
    vertex_budget : int
        Most output vertices (points of the element tree), >= 4 ('mesh' only). The worst
        elements are split first; the report says when the budget stopped refinement.
    """

    patch_size: float = None
    method: str = "hemicube"
    resolution: int = 64
    rotate_hemicube: bool = True
    solver: str = "auto"
    tolerance: float = DEFAULT_TOLERANCE
    max_iterations: int = DEFAULT_MAX_ITERATIONS
    two_sided: bool = True
    crease_angle: float = DEFAULT_CREASE_ANGLE
    memory_budget: int = DEFAULT_MEMORY_BUDGET
    seed: int = 0
    rays: int = 16
    reciprocity: object = "auto"
    near: float = 1.5
    refine_levels: int = 0
    refine_threshold: float = 0.1
    corners: str = "gather"
    element_levels: int = 2
    element_threshold: float = 0.3
    contact_cuts: bool = True
    # --- adaptive output mesh (issue 9): defaults measured in bench/bench_adaptive.py:
    # contrast 0.1 (one-quad floor 0.40 % mean error with 2291 vertices; 0.2: 0.51 %, 964),
    # min_element 0.05 m (box shadow 1.22 % with 2648 vertices; 0.02 m: 1.10 % with 14448),
    # vertex_budget 100k (about 1 ms per gathered vertex: bounds the mesh stage near 2 min)
    output: str = "mesh"
    contrast: float = 0.1
    min_element: float = 0.05
    vertex_budget: int = 100_000

    def __post_init__(self):
        def bad(name, allowed):
            raise SettingsError(f"{name} must be {allowed}; got {getattr(self, name)!r}")

        if self.patch_size is not None and (not _is_real(self.patch_size)
                                            or self.patch_size <= 0):
            bad("patch_size", "a finite number > 0 (metres) or None")
        if self.method not in METHODS:
            bad("method", "one of " + ", ".join(repr(m) for m in METHODS))
        if not _is_int(self.resolution) or not 4 <= self.resolution <= 4096 \
                or self.resolution % 2:
            bad("resolution", "an even integer in [4, 4096]")
        if not isinstance(self.rotate_hemicube, (bool, np.bool_)):
            bad("rotate_hemicube", "True or False")
        if self.solver not in SOLVERS:
            bad("solver", "one of " + ", ".join(repr(s) for s in SOLVERS))
        if not _is_real(self.tolerance) or not 0 < self.tolerance < 1:
            bad("tolerance", "a number in (0, 1)")
        if not _is_int(self.max_iterations) or self.max_iterations < 1:
            bad("max_iterations", "an integer >= 1")
        if not isinstance(self.two_sided, (bool, np.bool_)):
            bad("two_sided", "True or False")
        if not _is_real(self.crease_angle) or not 0 <= self.crease_angle <= 180:
            bad("crease_angle", "a number of degrees in [0, 180]")
        if not _is_int(self.memory_budget) or self.memory_budget < MIN_MEMORY_BUDGET:
            bad("memory_budget", f"an integer number of bytes >= {MIN_MEMORY_BUDGET}")
        if not _is_int(self.seed) or self.seed < 0:
            bad("seed", "an integer >= 0")
        if not _is_int(self.rays) or self.rays < 1:
            bad("rays", "an integer >= 1")
        if not (isinstance(self.reciprocity, (bool, np.bool_)) or self.reciprocity == "auto"):
            bad("reciprocity", "True, False or 'auto'")
        if self.corners not in CORNERS:
            bad("corners", "one of " + ", ".join(repr(c) for c in CORNERS))
        if not _is_int(self.refine_levels) or not 0 <= self.refine_levels <= 4:
            bad("refine_levels", "an integer in [0, 4]")
        if not _is_int(self.element_levels) or not 0 <= self.element_levels <= 3:
            bad("element_levels", "an integer in [0, 3]")
        if not _is_real(self.element_threshold) or not 0 < self.element_threshold < 1:
            bad("element_threshold", "a number in (0, 1)")
        if not _is_real(self.refine_threshold) or not 0 < self.refine_threshold < 1:
            bad("refine_threshold", "a number in (0, 1)")
        if not isinstance(self.contact_cuts, (bool, np.bool_)):
            bad("contact_cuts", "True or False")
        if not _is_real(self.near) or self.near < 0:
            bad("near", "a finite number >= 0 (times the larger patch size)")
        # --- adaptive output mesh (issue 9)
        if self.output not in OUTPUTS:
            bad("output", "one of " + ", ".join(repr(o) for o in OUTPUTS))
        if not _is_real(self.contrast) or not 0 < self.contrast < 1:
            bad("contrast", "a number in (0, 1)")
        if not _is_real(self.min_element) or self.min_element <= 0:
            bad("min_element", "a finite number > 0 (metres)")
        if not _is_int(self.vertex_budget) or self.vertex_budget < 4:
            bad("vertex_budget", "an integer >= 4")


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
        matrix-free solve; freed after it), ``warnings``; ``mesh`` with ``output='mesh'``:
        see :func:`core.adaptive.adaptive_output`; ``face_variation`` with
        ``output='vertices'``: see :func:`core.criteria.face_variation`).
    output : core.outmesh.OutputMesh or None
        The radiosity mesh (``output='mesh'``), None with ``output='vertices'``.
    """

    corner_colours: np.ndarray
    patch_radiance: np.ndarray
    node_radiance: np.ndarray
    patches: object
    report: dict
    _state: object = field(default=None, repr=False)
    output: object = None


# ----------------------------------------------------------------------------- form factor rows


def _row_function(patches, method, resolution, rotate, rng, rays, near=None):
    """Return rows(sources (S,) int64) -> (S, 2P) float64 for the chosen method."""
    if method == "hemicube":
        from .hemicube import hemicube_rows

        def rows(sources):
            return hemicube_rows(patches, sources, resolution=resolution, rotate=rotate, rng=rng)
        return rows
    from .exact import ray_triangles
    from .raycast import build_bvh
    bvh = build_bvh(ray_triangles(patches)[0])
    if method == "exact":
        from .exact import exact_rows

        # The exact method is the reference: integrate over the source patch too (adaptive
        # Gauss order), not just its centre, or it keeps the hemicube's point-source error.
        def rows(sources):
            return exact_rows(patches, sources, rays=rays, rng=rng, bvh=bvh,
                              source_order="adaptive")
        return rows
    if method == "hybrid":
        from .exact import NEAR_DEFAULT, hybrid_rows
        near = NEAR_DEFAULT if near is None else near

        def rows(sources):
            return hybrid_rows(patches, sources, resolution=resolution, rays=rays, rng=rng,
                               bvh=bvh, rotate=rotate, near=near)
        return rows
    raise SettingsError(f"method must be one of {METHODS}; got {method!r}")


def _row_seconds(patches, method, resolution, rays):
    """Estimated seconds for one form-factor row (see ROW_SECONDS_PER_*)."""
    n_tri = 2 * len(patches.areas)                  # quads -> 2 triangles (upper bound)
    hemi = ROW_SECONDS_PER_PIXEL * resolution ** 2 + ROW_SECONDS_PER_TRIANGLE * n_tri
    if method == "hemicube":
        return hemi
    if method == "hybrid":
        return HYBRID_COST_FACTOR * hemi
    return ROW_SECONDS_PER_PAIR_RAY * len(patches.areas) * rays


class _Batcher:
    """Deterministic batch sizes: 1, 4, 16, ... up to about BATCH_SECONDS of estimated work."""

    def __init__(self, n_nodes, row_seconds):
        cap = max(1, min(MAX_BATCH_SOURCES, MAX_BATCH_ENTRIES // max(n_nodes, 1)))
        self.full = int(np.clip(BATCH_SECONDS / max(row_seconds, 1e-9), 1, cap))
        self.size = 1

    def timed(self, fn, sources):
        out = fn(sources)
        self.size = min(self.full, self.size * BATCH_GROWTH)
        return out


def form_factor_matrix(patches, *, method="hemicube", resolution=64, rotate=False, rng=None,
                       rays=16, monitor=None):
    """Dense form factors between all 2P nodes (tests and small scenes).

    Parameters
    ----------
    patches : core.patches.Patches
    method : {'hemicube', 'exact', 'hybrid'}
    resolution : int
        Hemicube resolution.
    rotate : bool
        Random hemicube rotations (from ``rng``).
    rng : numpy.random.Generator, optional
        Default: ``np.random.default_rng(0)``.
    rays : int
        Visibility rays per pair ('exact', 'hybrid').
    monitor : core.progress.Monitor, optional

    Returns
    -------
    (2P, 2P) float64
        Row i: fraction of the energy leaving node i that reaches each node.
    """
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}; got {method!r}")
    if rng is None:
        rng = np.random.default_rng(0)
    elif not isinstance(rng, np.random.Generator):
        raise TypeError(f"rng must be a numpy.random.Generator; got {type(rng).__name__}")
    monitor = Monitor() if monitor is None else monitor
    n = 2 * len(patches.areas)
    fn = _row_function(patches, method, resolution, rotate, rng, rays)
    out = np.zeros((n, n))
    batcher = _Batcher(n, _row_seconds(patches, method, resolution, rays))
    done = 0
    while done < n:
        sources = np.arange(done, min(done + batcher.size, n), dtype=np.int64)
        out[sources] = batcher.timed(fn, sources)
        done = sources[-1] + 1
        monitor.update(done / n, "form factors")
    return out


class _RowStore:
    """Rows computed so far, compact: per batch, its sources, the columns it hit and the values.

    Immutable in use: :meth:`extended` returns a new store sharing the old batches.
    """

    def __init__(self, n_nodes):
        self.n_nodes = n_nodes
        self.batches = []                          # (sources (S,), cols (K,), vals (S, K) f32)
        self.row_sums = np.full(n_nodes, np.nan)   # full row sum of every computed row
        self.where = np.full((n_nodes, 2), -1, dtype=np.int64)   # (batch, row) of each node
        self.nbytes = 0

    def copy(self):
        new = _RowStore(self.n_nodes)
        new.batches = list(self.batches)
        new.row_sums = self.row_sums.copy()
        new.where = self.where.copy()
        new.nbytes = self.nbytes
        return new

    def add(self, sources, rows):
        hit, vals = compact_rows(rows)
        b = len(self.batches)
        self.batches.append((sources, hit, vals))
        self.row_sums[sources] = rows.sum(axis=1)
        self.where[sources, 0] = b
        self.where[sources, 1] = np.arange(len(sources))
        self.nbytes += vals.nbytes + hit.nbytes + sources.nbytes
        return hit

    def hit(self):
        """(n_nodes,) bool: columns hit by any stored row."""
        out = np.zeros(self.n_nodes, dtype=bool)
        for _, cols, _ in self.batches:
            out[cols] = True
        return out

    def has(self, nodes):
        return self.where[nodes, 0] >= 0

    def rows(self, nodes):
        """Dense (len(nodes), n_nodes) float64 rows of stored nodes."""
        out = np.zeros((len(nodes), self.n_nodes))
        bs = self.where[nodes, 0]
        for b in np.unique(bs):
            sel = np.flatnonzero(bs == b)
            _, cols, vals = self.batches[b]
            out[np.ix_(sel, cols)] = vals[self.where[nodes[sel], 1]]
        return out

    def assemble(self, row_nodes, col_nodes, dtype):
        """Dense block F[row_nodes][:, col_nodes] from the stored rows (all must be stored)."""
        pos_r = np.full(self.n_nodes, -1, dtype=np.int64)
        pos_r[row_nodes] = np.arange(len(row_nodes))
        pos_c = np.full(self.n_nodes, -1, dtype=np.int64)
        pos_c[col_nodes] = np.arange(len(col_nodes))
        out = np.zeros((len(row_nodes), len(col_nodes)), dtype=dtype)
        for sources, cols, vals in self.batches:
            r = pos_r[sources]
            rk = r >= 0
            c = pos_c[cols]
            ck = c >= 0
            if rk.any() and ck.any():
                out[np.ix_(r[rk], c[ck])] = vals[np.ix_(rk, ck)]
        return out


def _discover(store, rows_fn, allowed, start_active, frontier, monitor, budget, batcher,
              expand=True):
    """Grow the active set wave by wave from ``frontier``; rows of new active nodes are stored.

    With ``expand=False`` only the rows of ``frontier`` are computed: what they hit is not added.

    Returns (active (2P,) bool, overflow bool). ``overflow``: the store outgrew ``budget``
    and discovery stopped early.
    """
    active = start_active.copy()
    active[frontier] = True
    pending = list(np.sort(frontier))
    pending = np.asarray(pending, dtype=np.int64)
    best = 0.0
    while len(pending):
        pos = 0
        next_wave = np.zeros(store.n_nodes, dtype=bool)
        while pos < len(pending):
            sources = pending[pos:pos + batcher.size]
            rows = batcher.timed(rows_fn, sources)
            hit = store.add(sources, rows)
            pos += len(sources)
            if expand:
                new = hit[allowed[hit] & ~active[hit]]
                active[new] = True
                next_wave[new] = True
            done = int(np.count_nonzero(store.where[:, 0] >= 0))
            left = len(pending) - pos + int(np.count_nonzero(next_wave))
            best = max(best, done / (done + left))
            monitor.update(best, f"form factors: {done} nodes")
            if store.nbytes > budget:
                return active, True
        pending = np.flatnonzero(next_wave)
    return active, False


# ----------------------------------------------------------------------------- bake


def _node_arrays(scene, patches, two_sided):
    """Per-node reflectance, emission (2P, 3), areas (2P,) and the nodes allowed to be active."""
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
    return rho_n, le_n, areas, allowed


class _State:
    """What relight needs: the scene, settings, patches and the kept rows."""

    def __init__(self, scene, settings, patches, store, active, gather=None, alone=None):
        self.gather = gather          # (CornerGroups, GatherRows, Elements or None), or None
        #                               ('mesh' output: a core.adaptive.AdaptiveState)
        self.contact_lines = None     # core.contacts.Contacts ('mesh' output), or None
        self.alone = alone            # vertices gathered per corner (contacts), or None
        self.scene = scene
        self.settings = settings
        self.patches = patches
        self.store = store
        self.active = active


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
    from .patches import make_patches

    settings = BakeSettings() if settings is None else settings
    if not isinstance(settings, BakeSettings):
        raise TypeError(f"settings must be a BakeSettings; got {type(settings).__name__}")
    monitor = Monitor(progress, cancel)
    t_start = time.perf_counter()
    timings = {}
    if settings.patch_size is None:
        from .adaptive import coarse_patch_size
        settings = dataclasses.replace(settings, patch_size=0.5 if settings.output == "vertices"
                                       else coarse_patch_size(scene))

    levels = settings.refine_levels
    level_monitor = _LevelMonitor(progress, cancel, 0, levels + 1)
    level_monitor.stage(*_STAGES["patches"])
    level_monitor.update(0.0, "patches")
    t0 = time.perf_counter()
    patches = make_patches(scene, settings.patch_size)
    contacts = alone = None
    if settings.contact_cuts:
        from .contacts import find_contacts, split_at_contacts
        found = find_contacts(scene, patches)
        patches, _, contacts = split_at_contacts(scene, patches, found)
        alone = found.vertices
    timings["patches"] = time.perf_counter() - t0
    level_monitor.update(1.0, f"{len(patches.areas)} patches")

    result = _run(scene, settings, patches, None, None, level_monitor, timings, t_start, [],
                  alone=alone, contact_lines=found if settings.contact_cuts else None)
    if levels:
        result = _refine(scene, settings, patches, result, alone, progress, cancel, t_start,
                         contact_lines=found if settings.contact_cuts else None)
    if contacts is not None:
        result.report["contacts"] = contacts
    return result


def _refine(scene, settings, patches, result, alone, progress, cancel, t_start,
            contact_lines=None):
    """Adaptive refinement after the first solve: split and re-solve, ``refine_levels`` times."""
    from .patches import subdivide_patches
    from .refine import refine_mask

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
        result = _run(scene, settings, patches, None, None, level_monitor,
                      {"patches": t_split}, time.perf_counter(), [], alone=alone,
                      contact_lines=contact_lines)
        for key, value in result.report["timings"].items():
            total[key] = total.get(key, 0.0) + value
    total["total"] = time.perf_counter() - t_start
    result.report["timings"] = total
    result.report["refinement"] = steps
    return result


class _LevelMonitor(Monitor):
    """A Monitor whose stages map into level ``k`` of ``n`` equal parts of the progress bar."""

    def __init__(self, progress, cancel, k, n):
        super().__init__(progress, cancel)
        self._k, self._n = k, n

    def stage(self, lo, hi):
        super().stage((self._k + lo) / self._n, (self._k + hi) / self._n)


def relight(result, *, reflectance=None, emission=None, progress=None, cancel=None):
    """Re-solve a bake with new material reflectance and/or emission, reusing its form factors.

    Nodes that become emitters but were never reached get their rows computed (only those
    rows). A matrix-free (progressive) bake kept no form factors: it is recomputed from scratch
    and the report says so.

    Parameters
    ----------
    result : BakeResult
        From :func:`bake` or :func:`relight`.
    reflectance : (M, 3) float, optional
        New per-material reflectance in [0, 1) (default: unchanged).
    emission : (M, 3) float, optional
        New per-material emitted radiance >= 0 (default: unchanged).
    progress, cancel : callables, optional
        As in :func:`bake`.

    Returns
    -------
    BakeResult
    """
    if not isinstance(result, BakeResult) or not isinstance(result._state, _State):
        raise TypeError(f"result must be a BakeResult from bake(); got {type(result).__name__}")
    state = result._state
    scene = state.scene
    M = len(scene.reflectance)
    changes = {}
    for name, value in (("reflectance", reflectance), ("emission", emission)):
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
        if name == "emission" and np.any(arr < 0):
            raise ValueError(f"emission must be >= 0; got minimum {arr.min():.6g}")
        arr.setflags(write=False)
        changes[name] = arr
    new_scene = dataclasses.replace(scene, **changes)
    if not np.any(new_scene.emission[state.patches.material] > 0):
        raise ValueError("emission leaves no emitting patch: nothing to light the scene")
    monitor = Monitor(progress, cancel)
    t_start = time.perf_counter()
    warnings = []
    if state.store is None:     # a matrix-free bake kept no form factors
        warnings.append("relight: the bake kept no form factors (matrix-free progressive): "
                        "they were recomputed")
        timings = {}
        monitor.stage(*_STAGES["patches"])
        monitor.update(1.0, "patches")
        timings["patches"] = 0.0
        return _run(new_scene, state.settings, state.patches, None, None, monitor, timings,
                    t_start, warnings, alone=state.alone, contact_lines=state.contact_lines)
    timings = {"patches": 0.0}
    return _run(new_scene, state.settings, state.patches, state.store, state.active, monitor,
                timings, t_start, warnings, gather=state.gather, alone=state.alone,
                contact_lines=state.contact_lines)


def _run(scene, settings, patches, store, active, monitor, timings, t_start, warnings,
         gather=None, alone=None, contact_lines=None):
    """Form factors (discovery, reusing ``store``), solve, colours, report."""
    from .colours import corner_colours

    P = len(patches.areas)
    N = 2 * P
    rho, le, areas, allowed = _node_arrays(scene, patches, settings.two_sided)
    emitting = np.flatnonzero(np.any(le > 0, axis=1) & allowed)

    # --- form factors: discovery from the emitters (only new ones when relighting)
    monitor.stage(*_STAGES["form_factors"])
    monitor.update(0.0, "form factors")
    t0 = time.perf_counter()
    rng = np.random.default_rng(settings.seed)
    if store is not None:
        # Rows for nodes not reached before: a separate stream, so kept rows stay as they were.
        rng = np.random.default_rng([settings.seed, 1])
    rows_fn = _row_function(patches, settings.method, settings.resolution,
                            settings.rotate_hemicube, rng, settings.rays, settings.near)
    batcher = _Batcher(N, _row_seconds(patches, settings.method, settings.resolution,
                                       settings.rays))
    if store is None:
        store = _RowStore(N)
        active = np.zeros(N, dtype=bool)
    else:
        store = store.copy()
    frontier = emitting[~active[emitting]]
    active, overflow = _discover(store, rows_fn, allowed, active, frontier, monitor,
                                 settings.memory_budget, batcher)
    # Every front node is solved: it is what the user sees and what gets baked, and a small
    # patch can slip between the pixels of every hemicube that looks at it, so "hit by an
    # active row" alone would leave it black. What these late rows hit is not added: a node
    # that only unlit nodes see (the inside of a box, seen from the floor under it) stays out.
    late = np.flatnonzero(~active[:P])
    if settings.output == "mesh" and len(late):       # issue 9: unlit surfaces cost nothing
        from .criteria import unlit_late_nodes
        late = late[~unlit_late_nodes(scene, patches, active, late, settings.resolution)]
    if len(late) and not overflow:
        active, overflow = _discover(store, rows_fn, allowed, active, late, monitor,
                                     settings.memory_budget, batcher, expand=False)
    monitor.update(1.0, "form factors done")
    timings["form_factors"] = time.perf_counter() - t0

    # --- solve
    monitor.stage(*_STAGES["solve"])
    monitor.update(0.0, "solving")
    t0 = time.perf_counter()
    idx = np.flatnonzero(active)
    n_a = len(idx)
    solver = settings.solver
    if not overflow:
        if solver == "auto":
            if n_a <= AUTO_DIRECT_MAX_NODES and 8 * n_a * n_a <= settings.memory_budget:
                solver = "direct"
            elif 4 * n_a * n_a <= settings.memory_budget:
                solver = "gauss_seidel"
            else:
                solver = "progressive_free"
                warnings.append(f"the form factors of {n_a} nodes need "
                                f"{4 * n_a * n_a / 2**20:.0f} MiB, over memory_budget "
                                f"({settings.memory_budget / 2**20:.0f} MiB): used matrix-free "
                                "progressive refinement (rows recomputed on demand, slower)")
        else:
            need = (8 if solver == "direct" else 4) * n_a * n_a
            if need > settings.memory_budget:
                warnings.append(f"solver '{solver}' needs {need / 2**20:.0f} MiB of form "
                                f"factors for {n_a} nodes, over memory_budget "
                                f"({settings.memory_budget / 2**20:.0f} MiB): used matrix-free "
                                "progressive refinement instead")
                solver = "progressive_free"
    else:
        solver = "progressive_free"
        warnings.append(f"form factors of the reachable nodes exceed memory_budget "
                        f"({settings.memory_budget / 2**20:.0f} MiB): used matrix-free "
                        "progressive refinement (rows recomputed on demand, slower)")

    node_radiance = np.zeros((N, 3))
    energy_rgb = None
    if solver != "progressive_free":
        dtype = np.float64 if solver == "direct" else np.float32
        F = store.assemble(idx, idx, dtype)
        use_recip = settings.reciprocity
        if use_recip == "auto":
            use_recip = settings.method == "hemicube"
        if use_recip:
            F, recip = make_reciprocal(F, areas[idx], monitor=monitor)
        else:
            recip = dict(asymmetry_before=_asymmetry(F, areas[idx]), sinkhorn_iterations=0)
        black = np.flatnonzero(store.hit() & ~allowed)     # black back nodes that light reaches
        black_block = store.assemble(idx, black, np.float32) if len(black) else None
        matrix_bytes = F.nbytes + (black_block.nbytes if black_block is not None else 0)
        common = dict(tol=settings.tolerance, monitor=monitor)
        if solver == "direct":
            sol = solve_direct(F, rho[idx], le[idx], monitor=monitor)
        elif solver == "jacobi":
            sol = solve_jacobi(F, rho[idx], le[idx], max_iterations=settings.max_iterations,
                               **common)
        elif solver == "gauss_seidel":
            sol = solve_gauss_seidel(F, rho[idx], le[idx],
                                     max_iterations=settings.max_iterations, **common)
        else:
            sol = solve_progressive(None, areas[idx], rho[idx], le[idx], F=F,
                                    max_shots=settings.max_iterations * max(n_a, 1), **common)
        L = sol.radiance
        node_radiance[idx] = L
        # incident power per node (radiance x area), for the energy balance and the warnings
        H = np.zeros((N, 3))
        H[idx] = matvec(F, L)
        incident = H * areas[:, None]
        sent = areas[idx, None] * L                              # (n_a, 3)
        if black_block is not None:
            incident[black] = black_block.T.astype(np.float64) @ sent
        escaped = ((1.0 - store.row_sums[idx])[:, None] * sent).sum(axis=0)
        absorbed = ((1.0 - rho) * incident).sum(axis=0)
        emitted = (le[idx] * areas[idx, None]).sum(axis=0)
        energy_rgb = (emitted, absorbed, escaped)
        del F, black_block
    else:
        cache_store = store

        def rows_on_demand(nodes):
            out = np.empty((len(nodes), N))
            have = cache_store.has(nodes)
            if have.any():
                out[have] = cache_store.rows(nodes[have])
            if (~have).any():
                out[~have] = rows_fn(nodes[~have])
            return out

        recip = dict(asymmetry_before=None, sinkhorn_iterations=0,
                     note="matrix-free shooting conserves energy by construction")
        sol = solve_progressive(rows_on_demand, areas, rho, le, tol=settings.tolerance,
                                max_shots=settings.max_iterations * N,
                                batch=int(np.clip(batcher.size, 1, MAX_SHOOT_BATCH)),
                                monitor=monitor)
        node_radiance = sol.radiance
        st = sol.stats
        incident = st["incident"]
        energy_rgb = (st["emitted"], st["absorbed"], st["escaped"])
        matrix_bytes = cache_store.nbytes
        idx = np.flatnonzero(np.any(incident > 0, axis=1) | np.any(le > 0, axis=1))
        n_a = len(idx)
        solver = "progressive"
        store = None                                    # nothing kept for relight
    monitor.update(1.0, "solved")
    timings["solve"] = time.perf_counter() - t0
    if not sol.converged:
        warnings.append(f"solver '{sol.solver}' stopped after {sol.iterations} iterations at "
                        f"residual {sol.residual:.3g} > tolerance {settings.tolerance:g}")

    # --- colours
    monitor.stage(*_STAGES["colours"])
    monitor.update(0.0, "colours")
    t0 = time.perf_counter()
    patch_radiance = node_radiance[:P].copy()
    element_report = None
    mesh_out = mesh_report = None
    if settings.output == "mesh":                     # issue 9: the adaptive radiosity mesh
        from .adaptive import mesh_colours
        colours, mesh_out, gather, mesh_report = mesh_colours(
            scene, settings, patches, node_radiance, incident, gather, contact_lines, monitor,
            lambda: corner_colours(scene, patches, patch_radiance,
                                   crease_angle=settings.crease_angle))
        element_report = mesh_report.pop("elements", None)
    elif settings.corners == "gather":
        from .gather import corner_groups, gather_rows, gathered_colours
        if gather is None:
            elements = None
            seen = patches
            if settings.element_levels:
                from .elements import make_elements
                elements = make_elements(
                    scene, patches, node_radiance, levels=settings.element_levels,
                    threshold=settings.element_threshold, crease_angle=settings.crease_angle,
                    resolution=settings.resolution, rotate=settings.rotate_hemicube,
                    rng=np.random.default_rng([settings.seed, 3]),
                    monitor=SubMonitor(monitor, 0.0, ELEMENT_SHARE))
                seen = elements.patches
            groups = corner_groups(scene, crease_angle=settings.crease_angle, alone=alone)
            sub = SubMonitor(monitor, ELEMENT_SHARE if elements is not None else 0.0, 1.0)
            store_g = gather_rows(seen, groups, resolution=settings.resolution,
                                  rotate=settings.rotate_hemicube,
                                  rng=np.random.default_rng([settings.seed, 2]),
                                  monitor=sub)
            gather = (groups, store_g, elements)
        groups, store_g, elements = gather
        seen_radiance = node_radiance
        if elements is not None:
            seen_radiance = elements.node_radiance(scene, node_radiance)
            element_report = dict(elements=int(elements.parent.size),
                                   gathered=int(elements.computed.size), levels=elements.levels)
        # The patch average only fills the corners of dropped faces, which have no gather.
        fallback = np.zeros((scene.n_corners, 3))
        if np.any(groups.group < 0):
            fallback = corner_colours(scene, patches, patch_radiance,
                                      crease_angle=settings.crease_angle)
        colours = gathered_colours(scene, groups, store_g, seen_radiance, fallback)
    else:
        colours = corner_colours(scene, patches, patch_radiance,
                                 crease_angle=settings.crease_angle)
    timings["colours"] = time.perf_counter() - t0
    monitor.update(1.0, "done")
    timings["total"] = time.perf_counter() - t_start

    ff_bytes = store.nbytes if store is not None else 0
    n_dropped = int(np.count_nonzero(~np.asarray(scene.face_valid)))
    if n_dropped:
        warnings.append(f"{n_dropped} degenerate faces (zero area) were dropped")
    n_back = _faces_lit_from_behind(patches, incident, scene.emission)
    if n_back:
        warnings.append(f"{n_back} faces receive more light on their back side: check normals")
    emitted, absorbed, escaped = (float(np.pi * x.sum()) for x in energy_rgb)
    balance = emitted - absorbed - escaped
    if emitted > 0 and abs(balance) > ENERGY_WARN_FRACTION * emitted:
        warnings.append(f"energy balance off by {100 * balance / emitted:+.1f} % of the emitted "
                        "power: the form factors are not reciprocal (surfaces nearer than about "
                        "a patch size?); try method='hybrid' or a smaller patch_size")
    report = dict(
        patches=P,
        nodes_active=int(n_a),
        faces_dropped=n_dropped,
        method=settings.method,
        solver=solver,
        iterations=int(sol.iterations),
        residual=float(sol.residual),
        converged=bool(sol.converged),
        timings=timings,
        energy=dict(emitted=emitted, absorbed=absorbed, escaped=escaped,
                    balance=balance),
        form_factor_bytes=int(ff_bytes),
        reciprocity=recip,
        matrix_bytes=int(matrix_bytes),
        warnings=warnings,
    )
    if element_report is not None:
        report["elements"] = element_report
    if mesh_report is not None:
        report["mesh"] = mesh_report
    elif settings.output == "vertices":
        from .criteria import face_variation
        report["face_variation"] = face_variation(scene, patches, patch_radiance,
                                                  settings.contrast)
    state = _State(scene, settings, patches, store, active, gather, alone)
    state.contact_lines = contact_lines
    return BakeResult(colours, patch_radiance, node_radiance, patches, report, state,
                      output=mesh_out)


#: Sinkhorn scaling of make_reciprocal stops when every row sum is within this relative
#: error of its target: ten times below the default solver tolerance, so the energy balance it
#: buys is not lost, and reached in ~100 sweeps on room_with_boxes(2000) (1e-6 took 258).
RECIPROCITY_TOL = 1e-5
RECIPROCITY_MAX_ITERATIONS = 500
#: A node whose row sum is still off by more than this after the Sinkhorn iterations cannot be
#: balanced with the others (see make_reciprocal) and keeps its own row and column.
SINKHORN_FAIL = 1e-3
#: Sinkhorn scales stay within this factor of their starting value.
SINKHORN_RANGE = 1e4
#: Passes of make_reciprocal's Sinkhorn scaling, each dropping the nodes found unbalanceable.
SINKHORN_PASSES = 6
_BLOCK = 1024


def _asymmetry(F, areas):
    """Area-weighted relative reciprocity error sum|A_i F_ij - A_j F_ji| / sum(A_i F_ij)."""
    num = 0.0
    den = 0.0
    for s in range(0, F.shape[0], _BLOCK):
        e = min(s + _BLOCK, F.shape[0])
        g = areas[s:e, None] * F[s:e].astype(np.float64)
        gt = F[:, s:e].T.astype(np.float64) * areas[None, :]
        num += float(np.abs(g - gt).sum())
        den += float(g.sum())
    return num / den if den > 0 else 0.0


def make_reciprocal(F, areas, *, tol=RECIPROCITY_TOL, max_iterations=RECIPROCITY_MAX_ITERATIONS,
                    monitor=None):
    """Reciprocal form factors with the row sums of ``F``.

    Each pair has two estimates of its exchange ``A_i F_ij``: one from i's hemicube (or rays),
    one from j's. A point-source estimate is good when its own patch is small compared with the
    distance, so they are blended with weights favouring the smaller patch:
    ``S_ij = (A_j A_i F_ij + A_i A_j F_ji) / (A_i + A_j)``, symmetric by construction. Then a
    symmetric Sinkhorn scaling ``D S D`` restores every row's own sum (the fraction of i's
    energy that lands on these nodes), so a closed scene keeps rows summing to 1 (white furnace
    exact) and the energy balance holds to solver precision.

    Parameters
    ----------
    F : (n, n) float32 or float64
        Form factors among one set of nodes; row i = what node i sees.
    areas : (n,) float64
        Node areas (> 0).

    Returns
    -------
    F_rec : (n, n), dtype of F
        ``areas[:, None] * F_rec`` is symmetric, ``F_rec.sum(1) == F.sum(1)`` within ``tol``.
    info : dict
        ``asymmetry_before`` (see :func:`_asymmetry`), ``sinkhorn_iterations`` (of the last
        pass), ``row_sum_error`` (largest relative error left), ``unscaled`` (nodes left with
        their own rows and columns).
    """
    F = np.asarray(F)
    areas = np.asarray(areas, dtype=np.float64)
    n = F.shape[0]
    if F.ndim != 2 or F.shape[1] != n:
        raise ValueError(f"F must be square (n, n); got {F.shape}")
    if areas.shape != (n,) or not np.all(areas > 0):
        raise ValueError(f"areas must have shape ({n},) and be > 0; got {areas.shape}")
    info = dict(asymmetry_before=_asymmetry(F, areas))
    row_sum = F.sum(axis=1, dtype=np.float64)
    target = areas * row_sum
    S = np.empty_like(F)
    a = areas.astype(F.dtype)
    for s in range(0, n, _BLOCK):
        e = min(s + _BLOCK, n)
        ai = a[s:e, None]
        S[s:e] = ai * a[None, :] * (F[s:e] + F[:, s:e].T) / (ai + a[None, :])
    # Nodes that cannot be balanced keep their own rows and columns: nodes without a partner
    # (their row hits only nodes that see nothing), and groups whose row sums cannot all be met by
    # a symmetric scaling: two sets of patches shut inside a solid, each seeing mostly through the
    # near walls and the other set only a little, have no solution (their scales diverge). A pass
    # that finds such nodes drops them, and the next balances the rest without them.
    unscaled = np.zeros(n, dtype=bool)
    for attempt in range(1, SINKHORN_PASSES + 1):
        live = (target > 0) & ~unscaled
        while True:
            partnered = live & (S @ live.astype(S.dtype) > 0)
            if np.array_equal(partnered, live):
                break
            live = partnered
        unscaled |= (target > 0) & ~live
        d, it, err, pinned = _sinkhorn(S, target, live, tol, max_iterations, monitor)
        failed = pinned if pinned.any() else live & ~(err <= SINKHORN_FAIL)
        if attempt == SINKHORN_PASSES or not failed.any():
            break
        unscaled |= failed
        idx = np.flatnonzero(unscaled)
        S[idx] = 0
        S[:, idx] = 0
        target = areas * (row_sum - F[:, idx].sum(axis=1, dtype=np.float64))
        target[idx] = 0.0
    for s in range(0, n, _BLOCK):
        e = min(s + _BLOCK, n)
        S[s:e] *= (d[s:e] / areas[s:e])[:, None].astype(S.dtype) * d[None, :].astype(S.dtype)
    idx = np.flatnonzero(unscaled)
    if idx.size:
        S[idx] = F[idx]
        S[:, idx] = F[:, idx]
    err = float(np.max(err[live])) if live.any() else 0.0
    info.update(sinkhorn_iterations=it, row_sum_error=err, unscaled=int(idx.size))
    return S, info


def _sinkhorn(S, target, live, tol, max_iterations, monitor):
    """Symmetric Sinkhorn: d with ``d_i sum_j S_ij d_j = target_i`` over the live nodes.

    Returns (d, iterations, relative row error per node, pinned). Scales are held within
    ``SINKHORN_RANGE`` of their start, so that a group without a solution stays finite instead of
    overflowing into every row through the product; the iteration stops as soon as a scale
    reaches that bound, and ``pinned`` marks the nodes that did.
    """
    n = S.shape[0]
    d = np.zeros(n)
    rs = S.sum(axis=1, dtype=np.float64)
    d[live] = np.sqrt(target[live] / rs[live])
    lo, hi = d / SINKHORN_RANGE, d * SINKHORN_RANGE
    err = np.zeros(n)
    it = 0
    safe = np.where(live, target, 1.0)
    for it in range(1, max_iterations + 1):
        r = d * (S @ d.astype(S.dtype)).astype(np.float64)
        err = np.where(live, np.abs(r - target) / safe, 0.0)
        if float(err.max(initial=0.0)) <= tol:
            break
        ok = live & (r > 0)
        d[ok] = np.clip(d[ok] * np.sqrt(target[ok] / r[ok]), lo[ok], hi[ok])
        pinned = ok & ((d <= lo) | (d >= hi))
        if pinned.any():
            return d, it, err, pinned
        if monitor is not None and monitor.due():
            monitor.update(0.0, "making form factors reciprocal")
    return d, it, err, np.zeros(n, dtype=bool)


def _faces_lit_from_behind(patches, incident, emission):
    """Number of non-emitting faces whose back nodes receive more power than their front nodes."""
    P = len(patches.areas)
    power = incident.sum(axis=1)
    n_faces = len(patches.face_patch_start) - 1
    front = np.bincount(patches.face, weights=power[:P], minlength=n_faces)
    back = np.bincount(patches.face, weights=power[P:], minlength=n_faces)
    emits = np.zeros(n_faces, dtype=bool)
    emits[patches.face[np.any(np.asarray(emission)[patches.material] > 0, axis=1)]] = True
    return int(np.count_nonzero((back > BACKLIGHT_RATIO * front) & (back > 0) & ~emits))
