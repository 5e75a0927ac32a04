"""Linear solvers of the radiosity system, RGB at once.

Every solver returns the radiance ``L`` (N, 3) of

    L = Le + rho * (F @ L)

over N nodes, where ``F`` (N, N) holds form factors (row i: the fraction of the energy leaving i
that arrives at each j; rows sum to at most 1), ``rho`` (N, 3) the diffuse reflectance in [0, 1)
and ``Le`` (N, 3) the emitted radiance. ``I - rho F`` is then a non-singular M-matrix, so Jacobi,
Gauss-Seidel and shooting all converge.

Residuals
---------
* Jacobi and Gauss-Seidel: ``max |L_k+1 - L_k| / max |L_k+1|`` of the last sweep (relative change in
  the max norm). For Jacobi this is exactly the relative residual of the iterate before the last;
  the error of the returned iterate is at most ``residual * rho_max / (1 - rho_max)``.
* Progressive refinement: unshot power / emitted power (power = radiance x area, summed over RGB).

Stopping: every iterative solver stops when its residual is at most ``tol x (1 - rho_max)``
(:func:`stopping_threshold`), not ``tol``: the error left by a residual r is up to
``r / (1 - rho_max)`` (the light still to come is a geometric series of ratio rho_max), so a
fixed threshold stops far from the answer when rho -> 1 (0.5 % low at rho = 0.99 with
tol = 1e-4). Scaled, the relative error of the result is at most about ``tol`` at any rho.

Dense ``F`` may be float32 (memory) or float64; products are always accumulated in float64, in
row chunks so that a float32 matrix is never copied whole to float64.
"""

import time
from dataclasses import dataclass, field

import numpy as np

from .constants import DEFAULT_MAX_ITERATIONS, DEFAULT_TOLERANCE, POLL_INTERVAL
from .progress import SILENT

#: Rows per chunk of a dense matrix product: bounds the float64 temporary made from a float32
#: matrix (chunk x N x 8 bytes: 32 MB at N = 8000) and sets how often Jacobi polls the monitor.
MATVEC_CHUNK_ROWS = 512

#: Rows per diagonal block of block Gauss-Seidel. Each block is solved exactly (its inverse is
#: kept: 3 x N x block doubles). Measured on room_with_boxes(2000) (2148 nodes, tol 1e-4):
#: blocks of 1 (point GS), 16, 32, 64, 128 and 256 rows all take 14 sweeps; 64 was the fastest
#: (0.11 s; point GS 5.8 s, 256 rows 1.0 s: the batched block inverses dominate).
GS_BLOCK_ROWS = 64

#: Block Gauss-Seidel on a float32 matrix (every solve past ``AUTO_DIRECT_MAX_NODES``) forms each
#: block's gather from the other blocks in float32 (sgemm on the stored matrix, no float64 copy)
#: while the sweeps' relative change is above this, then in float64. Measured (2 cores): a sweep
#: over a random 12,767 x 12,767 float32 matrix 0.31 s -> 0.14 s, with a relative error of the
#: float32 gather of 2e-7 (accumulation and the rounding of L), 50 times under this floor, so a
#: sweep's change above it is the iteration's, not rounding; bench/bench_solvers.py at 9,069
#: nodes 2.88 s -> 1.25 s, 16 sweeps either way. The usual stopping threshold, tolerance 1e-4 x
#: (1 - rho_max) with rho_max <= 0.9, is above it: such a solve never needs a float64 sweep.
F32_FLOOR = 1e-5

#: Default number of shooters per row request of progressive refinement: enough to amortise the
#: row computation (one hemicube per shooter, computed in one vectorised batch).
DEFAULT_SHOOT_BATCH = 16

#: Default cap on progressive shots, as a multiple of the node count.
SHOTS_PER_NODE = 50


@dataclass
class SolveResult:
    """Outcome of a solve.

    Attributes
    ----------
    radiance : (N, 3) float64
        Outgoing radiance of every node (emission included).
    iterations : int
        Sweeps (Jacobi, Gauss-Seidel), shots (progressive), 1 (direct).
    residual : float
        Relative residual at exit (see module docstring).
    converged : bool
        ``residual <= tol``.
    solver : str
        ``'direct'``, ``'jacobi'``, ``'gauss_seidel'`` or ``'progressive'``.
    stats : dict
        Solver-specific figures. Progressive: ``shot_power`` (3,) power shot (radiance x area),
        ``absorbed`` (3,) and ``escaped`` (3,) of it, ``unshot`` (3,), ``emitted`` (3,),
        ``incident`` (N, 3) power that arrived at each node, ``row_requests`` (number of row_fn
        calls), ``shots``.
    """

    radiance: np.ndarray
    iterations: int
    residual: float
    converged: bool
    solver: str
    stats: dict = field(default_factory=dict)


# ----------------------------------------------------------------------------- validation


def _check_system(F, rho, le):
    """Validate F (N, N), rho (N, 3), le (N, 3); return (F, rho, le) with float64 rho, le."""
    if not isinstance(F, np.ndarray) or F.ndim != 2 or F.shape[0] != F.shape[1]:
        shape = getattr(F, "shape", type(F).__name__)
        raise ValueError(f"F must be a square (N, N) array; got {shape}")
    if F.dtype not in (np.float32, np.float64):
        raise TypeError(f"F must be float32 or float64; got {F.dtype}")
    n = F.shape[0]
    rho = _check_rgb("rho", rho, n)
    if np.any(rho < 0.0) or np.any(rho >= 1.0):
        raise ValueError("rho must lie in [0, 1); got values in "
                         f"[{rho.min():.6g}, {rho.max():.6g}]")
    return F, rho, _check_le(le, n)


def _check_le(le, n):
    le = _check_rgb("le", le, n)
    if np.any(le < 0.0):
        raise ValueError(f"le must be >= 0; got minimum {le.min():.6g}")
    return le


def _check_rgb(name, value, n):
    arr = np.asarray(value, dtype=np.float64)
    if arr.shape != (n, 3):
        raise ValueError(f"{name} must have shape (N, 3) = ({n}, 3); got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite; got NaN or inf at row "
                         f"{int(np.argmax(~np.all(np.isfinite(arr), axis=1)))}")
    return arr


def _check_positive_int(name, value):
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise ValueError(f"{name} must be an integer >= 1; got {value!r}")
    return int(value)


def _check_tol(tol):
    tol = float(tol)
    if not (tol > 0.0 and np.isfinite(tol)):
        raise ValueError(f"tol must be a finite number > 0; got {tol!r}")
    return tol


#: Smallest 1 - rho_max the stopping threshold is scaled by (reflectance is < 1 but may be
#: within rounding of it).
MIN_ABSORPTION = 1e-6


def stopping_threshold(tol, rho):
    """Residual at which an iterative solve stops: ``tol x (1 - max(rho))``.

    Parameters
    ----------
    tol : float
        Relative accuracy wanted (the ``tolerance`` setting).
    rho : (N, 3) float
        Reflectance of the nodes.

    Returns
    -------
    float
    """
    rho = np.asarray(rho)
    rho_max = float(rho.max()) if rho.size else 0.0
    return tol * max(1.0 - rho_max, MIN_ABSORPTION)


def _progress_fraction(residual, start, tol):
    """Fraction done, from the decay of the residual on a log scale (start -> tol)."""
    if residual <= tol:
        return 1.0
    if start <= tol or residual >= start:
        return 0.0
    return float(np.log(start / residual) / np.log(start / tol))


# ----------------------------------------------------------------------------- helpers


def _rows_times(F, L, start, stop, out=None):
    """``F[start:stop] @ L`` accumulated in float64. Returns (stop - start, 3)."""
    return np.matmul(F[start:stop].astype(np.float64, copy=False), L, out=out)


def matvec(F, L):
    """``F @ L`` (N, K) accumulated in float64, MATVEC_CHUNK_ROWS rows at a time (a float32 F
    is never copied whole)."""
    out = np.empty((F.shape[0], L.shape[1]))
    for s in range(0, F.shape[0], MATVEC_CHUNK_ROWS):
        e = min(s + MATVEC_CHUNK_ROWS, F.shape[0])
        _rows_times(F, L, s, e, out=out[s:e])
    return out


# ----------------------------------------------------------------------------- direct


def solve_direct(F, rho, le, *, monitor=None):
    """Solve the radiosity system with LU factorisations.

    Channels with the same reflectance column share one factorisation (grey materials: one
    factorisation for RGB); otherwise one per distinct column (at most 3).

    Parameters
    ----------
    F : (N, N) float32 or float64
        Form factors.
    rho : (N, 3) float
        Reflectance in [0, 1).
    le : (N, 3) float
        Emitted radiance >= 0.
    monitor : core.progress.Monitor, optional
        Checked between factorisations (each is uninterruptible: about 0.3 s at N = 3000).

    Returns
    -------
    SolveResult
        ``residual`` is the true relative residual ``max|Le + rho F L - L| / max|L|``.
    """
    F, rho, le = _check_system(F, rho, le)
    monitor = SILENT if monitor is None else monitor
    n = F.shape[0]
    out = np.zeros((n, 3))
    if n == 0:
        return SolveResult(out, 1, 0.0, True, "direct")
    groups = []
    for c in range(3):
        for g in groups:
            if np.array_equal(rho[:, g[0]], rho[:, c]):
                g.append(c)
                break
        else:
            groups.append([c])
    Fd = F.astype(np.float64, copy=True)   # becomes I - rho F in place, channel group by group
    for k, chans in enumerate(groups):
        monitor.update(k / len(groups), "solving (direct)")
        A = Fd if k == len(groups) - 1 else Fd.copy()
        A *= -rho[:, chans[0], None]
        A[np.diag_indices(n)] += 1.0
        out[:, chans] = np.linalg.solve(A, le[:, chans])
    monitor.update(1.0, "solved (direct)")
    residual = _true_residual(F, rho, le, out)
    return SolveResult(out, 1, residual, True, "direct")


def _true_residual(F, rho, le, L):
    n = F.shape[0]
    worst = 0.0
    for s in range(0, n, MATVEC_CHUNK_ROWS):
        e = min(s + MATVEC_CHUNK_ROWS, n)
        r = le[s:e] + rho[s:e] * _rows_times(F, L, s, e) - L[s:e]
        worst = max(worst, float(np.abs(r).max()))
    scale = float(np.abs(L).max())
    return worst / scale if scale > 0 else worst


# ----------------------------------------------------------------------------- Jacobi


def solve_jacobi(F, rho, le, *, tol=DEFAULT_TOLERANCE, max_iterations=DEFAULT_MAX_ITERATIONS,
                 monitor=None):
    """Jacobi iteration ``L <- Le + rho (F @ L)`` from ``L = Le`` (a sum of bounces).

    Parameters
    ----------
    F : (N, N) float32 or float64
    rho, le : (N, 3) float
    tol : float
        Stop when the relative change of a sweep (max norm) is at most
        ``stopping_threshold(tol, rho)`` = ``tol x (1 - rho_max)``.
    max_iterations : int
        Cap on sweeps.
    monitor : core.progress.Monitor, optional
        Polled every ``MATVEC_CHUNK_ROWS`` rows when a poll is due.

    Returns
    -------
    SolveResult
    """
    F, rho, le = _check_system(F, rho, le)
    tol = _check_tol(tol)
    max_iterations = _check_positive_int("max_iterations", max_iterations)
    monitor = SILENT if monitor is None else monitor
    n = F.shape[0]
    L = le.copy()
    new = np.empty_like(L)
    residual, start, best = 1.0, None, 0.0
    it = 0
    if n == 0 or not np.any(le):
        return SolveResult(np.zeros((n, 3)), 0, 0.0, True, "jacobi")
    tol = stopping_threshold(tol, rho)
    while it < max_iterations:
        for s in range(0, n, MATVEC_CHUNK_ROWS):
            e = min(s + MATVEC_CHUNK_ROWS, n)
            _rows_times(F, L, s, e, out=new[s:e])
            if monitor.due():
                monitor.update(best, "solving (Jacobi)")
        new *= rho
        new += le
        it += 1
        residual = float(np.abs(new - L).max() / np.abs(new).max())
        L, new = new, L
        start = residual if start is None else start
        best = max(best, _progress_fraction(residual, start, tol))
        if residual <= tol:
            break
        if monitor.due():
            monitor.update(best, "solving (Jacobi)")
    monitor.update(1.0 if residual <= tol else best, "solved (Jacobi)")
    return SolveResult(L, it, residual, residual <= tol, "jacobi")


# ----------------------------------------------------------------------------- Gauss-Seidel


def solve_gauss_seidel(F, rho, le, *, tol=DEFAULT_TOLERANCE, max_iterations=DEFAULT_MAX_ITERATIONS,
                       monitor=None, block=GS_BLOCK_ROWS):
    """Block Gauss-Seidel with exactly solved diagonal blocks.

    Rows are split into consecutive blocks K of ``block`` rows; a sweep sets, block after block,
    ``L_K = (I - rho_K F_KK)^-1 (Le_K + rho_K F_K,~K L)`` with the newest values of the other
    blocks. ``I - rho F`` is an M-matrix, so by Varga's comparison theorem this converges at least
    as fast as point Gauss-Seidel (``block=1``), with vectorised work per block instead of a
    Python step per row. The block inverses (3 x N x block) are computed once. Several
    emissions on one matrix: :func:`solve_gauss_seidel_many`.

    Parameters
    ----------
    F : (N, N) float32 or float64
        A float32 matrix is multiplied in float32 while the sweeps' change is above
        ``F32_FLOOR``, then in float64; a float64 one always in float64.
    rho, le : (N, 3) float
    tol : float
        Stop when the relative change of a sweep (max norm) is at most
        ``stopping_threshold(tol, rho)`` = ``tol x (1 - rho_max)``.
    max_iterations : int
        Cap on sweeps.
    monitor : core.progress.Monitor, optional
        Polled between blocks when a poll is due.
    block : int
        Rows per diagonal block (1 = classic point Gauss-Seidel).

    Returns
    -------
    SolveResult
    """
    return solve_gauss_seidel_many(F, rho, [le], tol=tol, max_iterations=max_iterations,
                                   monitor=monitor, block=block)[0]


def solve_gauss_seidel_many(F, rho, les, *, tol=DEFAULT_TOLERANCE,
                            max_iterations=DEFAULT_MAX_ITERATIONS, monitor=None,
                            block=GS_BLOCK_ROWS):
    """:func:`solve_gauss_seidel` for the emissions ``les`` (a non-empty list of (N, 3)) at once:
    each sweep reads the matrix once for all (a relight of several light groups). They share the
    sweeps until every one is converged; one :class:`SolveResult` each."""
    F, rho, first = _check_system(F, rho, les[0])     # F and rho once; each emission below
    le = np.concatenate([first] + [_check_le(x, F.shape[0]) for x in les[1:]], axis=1)
    G, tol, block = len(les), _check_tol(tol), _check_positive_int("block", block)
    max_iterations = _check_positive_int("max_iterations", max_iterations)
    monitor, n = SILENT if monitor is None else monitor, F.shape[0]
    if n == 0 or not np.any(le):
        return [SolveResult(np.zeros((n, 3)), 0, 0.0, True, "gauss_seidel") for _ in range(G)]
    rho_g = np.tile(rho, G)                                             # (n, 3G)
    bounds, inverses = [(s, min(s + block, n)) for s in range(0, n, block)], []
    for s, e in bounds:
        Fkk = F[s:e, s:e].astype(np.float64)
        # (3, b, b): I - rho_c F_KK for each channel, inverted as one batch.
        A = -rho[s:e].T[:, :, None] * Fkk[None]
        A[:, np.arange(e - s), np.arange(e - s)] += 1.0
        inverses.append(np.linalg.inv(A))
        if monitor.due():
            monitor.update(0.0, "solving (Gauss-Seidel)")
    L, it, tol = le.copy(), 0, stopping_threshold(tol, rho)
    residual, start, best, each = 1.0, None, 0.0, np.ones(G)
    single = F.dtype == np.float32          # float32 gathers until the change reaches F32_FLOOR
    while it < max_iterations:
        change = np.zeros(G)
        single = single and residual > F32_FLOOR
        L32 = L.astype(np.float32) if single else None
        for (s, e), inv in zip(bounds, inverses):
            if single:
                # The other blocks' columns, in two products: subtracting the block's own part
                # from the whole row would leave the whole row's float32 rounding on a
                # difference that can be much smaller (neighbouring patches in one block).
                gathered = (F[s:e, :s] @ L32[:s]).astype(np.float64)
                gathered += F[s:e, e:] @ L32[e:]
            else:
                # One contiguous slab product, then remove the block's own part: F >= 0 and
                # L >= 0, so the subtraction loses no significant digits (no sign cancellation).
                slab = F[s:e].astype(np.float64, copy=False)
                gathered = slab @ L
                gathered -= slab[:, s:e] @ L[s:e]
            rhs = (le[s:e] + rho_g[s:e] * gathered).reshape(e - s, G, 3)     # (b, G, 3)
            new = np.matmul(inv, rhs.transpose(2, 0, 1)).transpose(1, 2, 0).reshape(e - s, -1)
            step = np.abs(new - L[s:e]).reshape(e - s, G, 3)
            change = np.maximum(change, step.max(axis=(0, 2)))
            L[s:e] = new
            if single:
                L32[s:e] = new
            if monitor.due():
                monitor.update(best, "solving (Gauss-Seidel)")
        it += 1
        top = np.abs(L).reshape(n, G, 3).max(axis=(0, 2))
        each = np.divide(change, top, out=np.zeros(G), where=top > 0)
        residual = float(each.max())
        start = residual if start is None else start
        best = max(best, _progress_fraction(residual, start, tol))
        if residual <= tol:
            break
    monitor.update(1.0 if residual <= tol else best, "solved (Gauss-Seidel)")
    return [SolveResult(L[:, 3 * g:3 * g + 3].copy(), it, float(r), bool(r <= tol), "gauss_seidel")
            for g, r in enumerate(each)]


# ----------------------------------------------------------------------------- progressive


def ambient_radiance(areas, rho, unshot, mask=None):
    """Ambient term of Cohen, Chen, Wallace & Greenberg (1988) for early display.

    The unshot power is spread uniformly over the surfaces and bounced with the area-mean
    reflectance: ``ambient = sum(A dL) / sum(A) / (1 - rho_avg)``, and each node displays
    ``L + rho * ambient``.

    Parameters
    ----------
    areas : (N,) float
    rho : (N, 3) float
    unshot : (N, 3) float
        Unshot radiance.
    mask : (N,) bool, optional
        Nodes over which the averages are taken (default: all).

    Returns
    -------
    (N, 3) float64
        ``rho * ambient``: add it to the current radiance estimate.
    """
    areas = np.asarray(areas, dtype=np.float64)
    n = areas.shape[0]
    rho, unshot = _check_rgb("rho", rho, n), _check_rgb("unshot", unshot, n)
    m = np.ones(n, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
    a = areas[m]
    total = a.sum()
    if total <= 0:
        return np.zeros((n, 3))
    rho_avg = (rho[m] * a[:, None]).sum(axis=0) / total
    ambient = (unshot[m] * a[:, None]).sum(axis=0) / total / (1.0 - rho_avg)
    return rho * ambient


def solve_progressive(row_fn, areas, rho, le, *, tol=DEFAULT_TOLERANCE, max_shots=None,
                      batch=DEFAULT_SHOOT_BATCH, monitor=None, F=None, ambient=False,
                      preview=None):
    """Progressive refinement by shooting (Cohen, Chen, Wallace & Greenberg 1988).

    Each step takes the ``batch`` nodes with the largest unshot power ``A_s * sum_c dL_s,c``,
    fetches their form-factor rows in one call and shoots: for every receiver j,
    ``dL_j += rho_j * F_sj * dL_s * A_s / A_j`` (reciprocity: ``A_j F_js = A_s F_sj``), and the
    shooters' unshot radiance becomes zero. No N x N matrix is needed.

    With a dense ``F`` the shooters' *columns* are used instead (``dL_j += rho_j F_js dL_s``),
    so the answer is that of the gathering system solved by the other solvers even when ``F``
    is not reciprocal. From rows only (``row_fn``), non-reciprocal rows (a hemicube's) give the
    answer of the reciprocal system ``A_j F_js := A_s F_sj``: the two differ by the
    discretisation's reciprocity error, not by a solver error.

    Parameters
    ----------
    row_fn : callable((S,) int64) -> (S, N) float, or None
        Form-factor rows of the given nodes (one hemicube per shooter). Ignored when ``F`` is
        given. Rows are fetched again when a node shoots again.
    areas : (N,) float
        Node areas (> 0).
    rho, le : (N, 3) float
    tol : float
        Stop when unshot power / emitted power <= ``tol x (1 - rho_max)``
        (:func:`stopping_threshold`).
    max_shots : int, optional
        Cap on shots (node shootings); default ``SHOTS_PER_NODE * N``.
    batch : int
        Shooters per step.
    monitor : core.progress.Monitor, optional
        Polled after every step when a poll is due.
    F : (N, N) float32 or float64, optional
        Dense form factors; its rows are used instead of ``row_fn``.
    ambient : bool
        Add the ambient term to the returned radiance (display only: it is an estimate of the
        light not shot yet; it vanishes as the solve converges).
    preview : callable((N, 3) ndarray), optional
        Called with the display radiance (ambient term included when ``ambient``) at every
        monitor poll, for interactive display. It receives a fresh array.

    Returns
    -------
    SolveResult
        ``stats`` holds the shooting energy bookkeeping in radiance x area units per channel:
        ``emitted = absorbed + escaped + unshot`` holds to rounding.
    """
    areas = np.asarray(areas, dtype=np.float64)
    if areas.ndim != 1:
        raise ValueError(f"areas must have shape (N,); got {areas.shape}")
    n = areas.shape[0]
    if not np.all(np.isfinite(areas)) or np.any(areas <= 0):
        raise ValueError("areas must be finite and > 0")
    if F is not None:
        F, rho, le = _check_system(F, rho, le)
        if F.shape[0] != n:
            raise ValueError(f"F must have shape ({n}, {n}) to match areas; got {F.shape}")
    else:
        if not callable(row_fn):
            raise TypeError(f"row_fn must be callable when F is None; got {type(row_fn).__name__}")
        rho = _check_rgb("rho", rho, n)
        le = _check_rgb("le", le, n)
        if np.any(rho < 0.0) or np.any(rho >= 1.0):
            raise ValueError("rho must lie in [0, 1)")
        if np.any(le < 0.0):
            raise ValueError("le must be >= 0")
    tol = _check_tol(tol)
    batch = _check_positive_int("batch", batch)
    max_shots = SHOTS_PER_NODE * max(n, 1) if max_shots is None else \
        _check_positive_int("max_shots", max_shots)
    monitor = SILENT if monitor is None else monitor

    L = le.copy()
    dL = le.copy()
    emitted = (le * areas[:, None]).sum(axis=0)             # (3,) radiance x area
    absorbed = np.zeros(3)
    escaped = np.zeros(3)
    shot_power = np.zeros(3)
    total_emitted = float(emitted.sum())
    stats = dict(emitted=emitted, absorbed=absorbed, escaped=escaped, shot_power=shot_power,
                 unshot=np.zeros(3), incident=np.zeros((n, 3)), row_requests=0, shots=0)
    if n == 0 or total_emitted <= 0:
        return SolveResult(np.zeros((n, 3)), 0, 0.0, True, "progressive", stats)

    shots = 0
    residual = 1.0
    best = 0.0
    tol = stopping_threshold(tol, rho)
    last_preview = time.perf_counter()
    while True:
        power = areas * dL.sum(axis=1)
        unshot_total = float(power.sum())
        residual = unshot_total / total_emitted
        if residual <= tol or shots >= max_shots:
            break
        k = min(batch, max_shots - shots, int(np.count_nonzero(power > 0)))
        if k == 0:
            break
        if k < n:
            shooters = np.argpartition(power, n - k)[n - k:]
        else:
            shooters = np.arange(n)
        shooters = np.sort(shooters[power[shooters] > 0]).astype(np.int64)
        sent = dL[shooters] * areas[shooters, None]          # (S, 3) power shot
        if F is not None:
            # Gathering-consistent: node j receives rho_j F_js dL_s, exactly the system the
            # other solvers solve even when F is not reciprocal (hemicube rows).
            cols = F[:, shooters].astype(np.float64, copy=False)        # (N, S)
            arriving = areas[:, None] * (cols @ dL[shooters])
            lost = sent.sum(axis=0) - arriving.sum(axis=0)
        else:
            rows = np.asarray(row_fn(shooters), dtype=np.float64)
            stats["row_requests"] += 1
            if rows.shape != (len(shooters), n):
                raise ValueError(f"row_fn must return shape ({len(shooters)}, {n}); "
                                 f"got {rows.shape}")
            arriving = rows.T @ sent                         # (N, 3) power arriving at each node
            lost = ((1.0 - rows.sum(axis=1))[:, None] * sent).sum(axis=0)
        dL[shooters] = 0.0
        received = rho * arriving / areas[:, None]           # reflected radiance
        L += received
        dL += received
        shot_power += sent.sum(axis=0)
        stats["incident"] += arriving
        absorbed += ((1.0 - rho) * arriving).sum(axis=0)
        escaped += lost
        shots += len(shooters)
        if monitor.due() or time.perf_counter() - last_preview >= POLL_INTERVAL:
            best = max(best, _progress_fraction(residual, 1.0, tol))
            monitor.update(best, "shooting")
            if preview is not None:
                preview(_display(L, dL, areas, rho, ambient))
            last_preview = time.perf_counter()
    stats["unshot"] = (dL * areas[:, None]).sum(axis=0)
    stats["shots"] = shots
    converged = residual <= tol
    monitor.update(1.0 if converged else best, "solved (progressive)")
    return SolveResult(_display(L, dL, areas, rho, ambient), shots, residual, converged,
                       "progressive", stats)


def _display(L, dL, areas, rho, ambient):
    if not ambient:
        return L.copy()
    reached = np.any(L > 0, axis=1)
    return L + ambient_radiance(areas, rho, dL, mask=reached)
