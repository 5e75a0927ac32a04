"""Reciprocal form factors: blend each pair's two estimates, then restore the row sums.

A hemicube (or ray) row is a point-source estimate from its own patch: two near patches of
different sizes disagree about their exchange, and the energy balance shows it.
:func:`make_reciprocal` makes ``A_i F_ij = A_j F_ji`` exact while keeping every row's sum
(symmetric Sinkhorn scaling), so a closed scene still passes the white furnace test.

Groups of nodes with no symmetric solution (pieces shut inside or behind furniture) make their
scales diverge: each pass drops them (``SINKHORN_DRIFT``) and balances the rest. Should the
passes run out with rows still off, those rows are scaled back to their own sums
(``Balance.rows``): the energy balance always holds, and reciprocity is exact wherever the
scaling converged and off by at most that row's error elsewhere.

The scaling depends on the form factors and the areas only: :func:`make_reciprocal` returns it
as a :class:`Balance` if asked, and :func:`rebalance` rebuilds the same reciprocal matrix (bit
for bit) from the same ``F`` without the Sinkhorn iterations: a relight with a new emission or
reflectance skips them.

Every block loop polls the monitor, so a cancel is honoured within a poll interval even on a
matrix of thousands of nodes.
"""

from dataclasses import dataclass, field

import numpy as np

from .progress import poll

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
#: A node whose scale has moved further than this factor from its start when a pass stops on
#: a pinned scale belongs to the group that diverges with it, and is dropped with it: the
#: furnace office with shadow lines had a node seeing a strip through 4e-5 of its hemicube,
#: scaled 1,730-fold when the passes ran out, which gave the strip 5 % of its row from it and
#: read it 1 % low. Balanced scales stay within a few percent of their start.
SINKHORN_DRIFT = 1e2
#: Passes of make_reciprocal's Sinkhorn scaling, each dropping the nodes found unbalanceable.
SINKHORN_PASSES = 6
#: Block side of :func:`_blend` and :func:`asymmetry`, which read each pair of blocks once
#: straight and once transposed: at 512 a transposed block (1 MB in float32) stays in cache
#: while it is read. Measured on a random 12,767 x 12,767 float32 matrix (2 cores): the blend
#: 0.60 s against 1.15 s at 1024 (and 0.72 s against 3.3 s on a matrix not yet paged in); the
#: blend's bits are the same at any size (element-wise).
_BLOCK = 512


def asymmetry(F, areas, monitor=None):
    """Area-weighted relative reciprocity error sum|A_i F_ij - A_j F_ji| / sum(A_i F_ij).

    By square blocks (I, J), J >= I, each read once straight and once transposed while in cache
    (``_BLOCK``); a pair of blocks off the diagonal counts twice (the terms are symmetric).
    Measured on the kept matrix of a 12,767-patch bake (13,899 nodes, float32, 2 cores): 0.83 s,
    against 4.3 s by slabs of whole rows and columns in float64 before (the same value to 1e-15).
    """
    n = F.shape[0]
    areas = np.asarray(areas, dtype=np.float64)
    num = 0.0
    den = float(areas @ F.sum(axis=1, dtype=np.float64)) if n else 0.0
    for s in range(0, n, _BLOCK):
        e = min(s + _BLOCK, n)
        ai = areas[s:e, None]
        for s2 in range(s, n, _BLOCK):
            e2 = min(s2 + _BLOCK, n)
            g = ai * F[s:e, s2:e2]
            g -= F[s2:e2, s:e].T * areas[None, s2:e2]
            num += (1.0 if s2 == s else 2.0) * float(np.abs(g).sum())
            poll(monitor, "making form factors reciprocal")
    return num / den if den > 0 else 0.0


@dataclass(frozen=True)
class Balance:
    """The scaling :func:`make_reciprocal` found for one matrix: :func:`rebalance` applies it
    again.

    Attributes
    ----------
    scales : (n,) float64
        Sinkhorn scales ``d``: ``F_rec_ij = S_ij d_i d_j / A_i`` (S the blend of the pair's two
        estimates); zero for nodes without a row sum to restore.
    unscaled : (U,) int64
        Nodes that keep their own rows and columns of ``F``.
    rows : (K,) int64
        Scaled nodes whose rows the Sinkhorn passes left off their sums by more than the
        tolerance; :func:`rebalance` multiplies each by its ``row_factors`` last.
    row_factors : (K,) float64
        Each such row's target sum over its sum after the scaling.
    dtype : numpy.dtype
        The matrix's: the blend and the scaling round in it.
    info : dict
        What :func:`make_reciprocal` reports.
    """

    scales: np.ndarray
    unscaled: np.ndarray
    dtype: np.dtype
    info: dict
    rows: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    row_factors: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def nbytes(self):
        """Bytes of the arrays kept (8 per node, per unscaled node, 16 per repaired row)."""
        return int(self.scales.nbytes + self.unscaled.nbytes + self.rows.nbytes
                   + self.row_factors.nbytes)


def make_reciprocal(F, areas, *, tol=RECIPROCITY_TOL, max_iterations=RECIPROCITY_MAX_ITERATIONS,
                    monitor=None, return_balance=False):
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
        ``asymmetry_before`` (see :func:`asymmetry`), ``sinkhorn_iterations`` (of the last
        pass), ``row_sum_error`` (largest relative error the scaling left), ``unscaled`` (nodes
        left with their own rows and columns), ``rows_repaired`` (rows then scaled back to
        their sums; the largest change is ``row_repair``).
    balance : Balance
        Only with ``return_balance=True``: the scaling found, for :func:`rebalance` to rebuild
        ``F_rec`` from the same ``F`` without iterating (a relight).
    """
    F = np.asarray(F)
    areas = np.asarray(areas, dtype=np.float64)
    n = F.shape[0]
    if F.ndim != 2 or F.shape[1] != n:
        raise ValueError(f"F must be square (n, n); got {F.shape}")
    if areas.shape != (n,) or not np.all(areas > 0):
        raise ValueError(f"areas must have shape ({n},) and be > 0; got {areas.shape}")
    info = dict(asymmetry_before=asymmetry(F, areas, monitor))
    row_sum = F.sum(axis=1, dtype=np.float64)
    target = areas * row_sum
    S = _blend(F, areas, None, None, np.empty_like(F), monitor)
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
            poll(monitor, "making form factors reciprocal")
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
    idx = np.flatnonzero(unscaled)
    err = float(np.max(err[live])) if live.any() else 0.0
    info.update(sinkhorn_iterations=it, row_sum_error=err, unscaled=int(idx.size))
    found = Balance(d, idx, F.dtype, dict(info))
    # S holds the blend with the unscaled nodes cut out: the scaled matrix is made again from F,
    # by the very code a relight runs, so the two agree bit for bit.
    S = rebalance(F, areas, found, out=S, monitor=monitor)
    if err > tol:
        # The passes ran out with rows off (a group with no symmetric solution that they did not
        # isolate in SINKHORN_PASSES): each such row is scaled back to its own sum, so no energy
        # is made or lost (before SINKHORN_DRIFT, the furnace office with shadow lines ended
        # with rows 5.7 % off; tests/core/test_reciprocity.py).
        got = S.sum(axis=1, dtype=np.float64)
        scaled = np.ones(n, dtype=bool)
        scaled[idx] = False
        rows = np.flatnonzero(scaled & (got > 0) & (np.abs(got - row_sum) > tol * row_sum))
        factors = row_sum[rows] / got[rows]
        _scale_rows(S, rows, factors)
        info.update(rows_repaired=int(rows.size),
                    row_repair=float(np.abs(factors - 1.0).max(initial=0.0)))
        found = Balance(d, idx, F.dtype, dict(info), rows, factors)
    else:
        info.update(rows_repaired=0, row_repair=0.0)
        found = Balance(d, idx, F.dtype, dict(info))
    return (S, info, found) if return_balance else (S, info)


def _scale_rows(out, rows, factors):
    """``out[rows] *= factors`` in ``out``'s dtype, the factors rounded to it first."""
    if rows.size:
        out[rows] *= factors.astype(out.dtype)[:, None]


def rebalance(F, areas, found, *, out=None, monitor=None):
    """The reciprocal matrix of ``F`` with the scaling ``found`` (the :class:`Balance` that
    :func:`make_reciprocal` returned for this same ``F`` and ``areas``): what it returned, bit
    for bit, in one pass over the matrix and without iterating.

    ``out`` : (n, n) array of ``F``'s dtype, optional; may be ``F`` itself (made reciprocal in
    place: no second matrix in memory).
    """
    F = np.asarray(F)
    areas = np.asarray(areas, dtype=np.float64)
    n = F.shape[0]
    if not isinstance(found, Balance):
        raise TypeError(f"found must be a Balance; got {type(found).__name__}")
    if F.ndim != 2 or F.shape[1] != n or F.dtype != found.dtype:
        raise ValueError(f"F must be square (n, n) of dtype {found.dtype}; got {F.shape} "
                         f"{F.dtype}")
    if areas.shape != (n,) or found.scales.shape != (n,):
        raise ValueError(f"areas and found.scales must have shape ({n},); got {areas.shape} and "
                         f"{found.scales.shape}")
    if out is None:
        out = np.empty_like(F)
    elif out.shape != F.shape or out.dtype != F.dtype:
        raise ValueError(f"out must have shape {F.shape} and dtype {F.dtype}; got {out.shape} "
                         f"{out.dtype}")
    idx = found.unscaled
    keep = None
    if idx.size:         # their own rows and columns, saved before out (maybe F) is written
        keep = F[idx].copy(), F[:, idx].copy()
    d = found.scales
    _blend(F, areas, d / areas, d, out, monitor)
    if keep is not None:
        out[idx] = keep[0]
        out[:, idx] = keep[1]
    _scale_rows(out, found.rows, found.row_factors)
    return out


def _blend(F, areas, row_scale, col_scale, out, monitor):
    """``out_ij = S_ij w_ij``, the blend ``S_ij = A_i A_j (F_ij + F_ji) / (A_i + A_j)`` scaled
    by ``w_ij = row_scale_i col_scale_j`` (both rounded to F's dtype first; None: unscaled).
    ``out`` may be ``F``: each pair of blocks (I, J), (J, I) is read before either is written,
    S being symmetric bit for bit (IEEE sums and products commute)."""
    n = F.shape[0]
    dt = F.dtype
    a = areas.astype(dt)
    scaled = row_scale is not None
    if scaled:
        r, c = row_scale.astype(dt), col_scale.astype(dt)
    for s in range(0, n, _BLOCK):
        e = min(s + _BLOCK, n)
        ai = a[s:e, None]
        for s2 in range(s, n, _BLOCK):
            e2 = min(s2 + _BLOCK, n)
            aj = a[None, s2:e2]
            S = ai * aj
            S *= F[s:e, s2:e2] + F[s2:e2, s:e].T
            S /= ai + aj
            if not scaled:
                out[s2:e2, s:e] = S.T
                out[s:e, s2:e2] = S
            else:
                if s2 > s:
                    np.multiply(S.T, r[s2:e2, None] * c[None, s:e], out=out[s2:e2, s:e])
                np.multiply(S, r[s:e, None] * c[None, s2:e2], out=out[s:e, s2:e2])
            poll(monitor, "making form factors reciprocal")
    return out


def _sinkhorn(S, target, live, tol, max_iterations, monitor):
    """Symmetric Sinkhorn: d with ``d_i sum_j S_ij d_j = target_i`` over the live nodes.

    Returns (d, iterations, relative row error per node, pinned). Scales are held within
    ``SINKHORN_RANGE`` of their start, so that a group without a solution stays finite instead of
    overflowing into every row through the product; the iteration stops as soon as a scale
    reaches that bound, and ``pinned`` marks the nodes that did and those whose scales have
    drifted more than ``SINKHORN_DRIFT`` from their start with them.
    """
    n = S.shape[0]
    d = np.zeros(n)
    rs = S.sum(axis=1, dtype=np.float64)
    d[live] = np.sqrt(target[live] / rs[live])
    start = d.copy()
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
            drift = ok & ((d * SINKHORN_DRIFT < start) | (d > start * SINKHORN_DRIFT))
            return d, it, err, pinned | drift
        poll(monitor, "making form factors reciprocal")
    return d, it, err, np.zeros(n, dtype=bool)
