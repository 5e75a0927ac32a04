"""Form-factor rows: how they are computed (per method, in deterministic batches) and kept.

A *row* is what one receiver sees: the fraction of its view (or of its energy, for a patch node)
that lands on each of the 2P nodes. Rows are kept compact in a :class:`RowStore` (per batch, only
the columns it hit, in float32): the node rows of a bake, from which the dense matrix of the
active nodes is assembled, and the point rows of the final gather (vertices, receiver elements).

Discovery (:func:`discover`) computes node rows wave by wave from the emitters: every node an
active row hits becomes active, so only the nodes light can reach are ever solved.
"""

import numpy as np

from .errors import SettingsError
from .exact import exact_rows, hybrid_rows, ray_triangles
from .hemicube import hemicube_rows
from .progress import Monitor, poll
from .raycast import build_bvh
from .nusselt import nusselt_rows
from .raytraced import raytraced_rows
from .settings import METHODS, BY_NAME

#: Form-factor batches are sized for about this much work, so that progress and cancel are
#: polled well within half a second (the first batches are smaller still: 1, 4, 16, ...).
BATCH_SECONDS = 0.15

#: Cost model of one form-factor row (seconds, 2 shared cores), used to size batches. Batch
#: sizes must not depend on measured time: the random draws of a batch (hemicube rotations,
#: visibility rays) depend on its composition, and the bake must be deterministic given
#: ``seed``. Fitted on room_with_boxes at R = 64 (bench/bench_solvers.py): 2.0 ms per row at
#: 1000 triangles, 4.1 ms at 4000, 17.6 ms at 16000; 'exact' 0.18 s per row at 490 patches
#: with 16 rays; 'hybrid' about 3 hemicubes; 'raytraced' 2 x 'exact' per pair and ray
#: (bench/bench_raytraced.py: 0.22 s per row at 490 patches, 16 rays, against exact's 0.10 s).
ROW_SECONDS_PER_PIXEL = 2.5e-7
ROW_SECONDS_PER_TRIANGLE = 1.0e-6
ROW_SECONDS_PER_PAIR_RAY = 2.3e-5
RAYTRACED_COST_FACTOR = 2.0
#: 'nusselt' against the hemicube at the same R (bench/bench_nusselt.py: 1.0-1.9 x, 1.3 typical).
NUSSELT_COST_FACTOR = 1.3
HYBRID_COST_FACTOR = 3.0

#: A batch never holds more than this many float64 row entries (S x 2P): 64 MB.
MAX_BATCH_ENTRIES = 8_000_000

#: Cap on sources per form-factor batch, and growth factor of the first batches.
MAX_BATCH_SOURCES = 1024
BATCH_GROWTH = 4

#: Rows per step of :meth:`RowStore.assemble`: each step scatters a batch's rows into whole dense
#: rows (at most this many x the matrix's columns), then those rows into place. Measured on the
#: kept rows of a 12,767-patch bake (13,899 active nodes, 2,782 batches, float32), nothing
#: else running: 0.73-0.90 s against 2.5-2.6 s for one scatter over the batch's row x column
#: index grid (np.ix_), the same bits.
ASSEMBLE_ROWS = 256

#: A *half* store (:class:`RowStore` ``half=True``) keeps each value in 16 bits: the float32 of
#: value x 2^-HALF_SHIFT, rounded to nearest at its 12th bit and shifted right by 12. With the
#: sign bit 0 and every value from 2^-28 to 4 (a form factor is at most 1) a normal float32
#: below 2^-95, those 16 bits hold 5 exponent bits and 11 mantissa bits: a 12-bit significand,
#: at most 2^-12 (2.4e-4) of the value off; 0 stays 0, and smaller values keep 1e-12 absolute.
#: Read back by an integer shift, as fast as float32 (NumPy's float16 reads 3 times slower).
#: Each row is then scaled by one float64 factor (8 bytes a row) so that it sums to what its
#: values summed to before: the rounding moves weight between a row's columns, but adds or loses
#: no light (a closed white furnace still reads Le / (1 - rho) to float64's rounding).
#: For gather rows (the receiver elements', the radiosity mesh's points'), which weigh one
#: bounce of the solved light and are never solved themselves. Measured on the receiver
#: elements' kept rows of a 12,767-patch bake (bench/bench_relight.py --patches 10000; 685 + 434
#: MB in float32, 251 + 169 MB half): against float32, the light they gather from a radiance
#: drawn as u^4 per node (u uniform in [0, 1)) moved by 2.1e-5 of itself on the mean, 2.4e-4
#: at most, and from a uniform radiance by 1e-16; one pass took 0.18 s against 0.16 s.
HALF_SHIFT = 98

#: A half store splits each added batch into chunks of this many rows, each keeping only the
#: columns it hits: a 64-row batch of receiver elements hits 3.2 times the columns any one of its
#: rows does (corner elements see other walls). Measured on those kept rows: float32 in 64-row
#: batches 1,079 MB; in 16-row chunks 745 MB; half, in 16-row chunks, 420 MB (cols as int32).
HALF_CHUNK = 16

_METHOD_NAMES = tuple(c.value for c in METHODS)

#: Methods that draw every source as a point (rows from its centre): reciprocity='auto' makes
#: their rows reciprocal. The exact, hybrid and ray-traced rows integrate over both patches
#: where it matters and are left as they are.
RECIPROCAL_METHODS = ("hemicube", "nusselt")


def compact_rows(rows):
    """(cols (K,), vals (S, K) float32): the columns of ``rows`` (S, n) that any row hits."""
    cols = np.flatnonzero(np.any(rows > 0, axis=0))
    return cols, rows[:, cols].astype(np.float32)


def encode_half(vals):
    """(S, K) uint16 codes of float values in [0, 4) (:data:`HALF_SHIFT`)."""
    vals = np.asarray(vals, dtype=np.float32)
    if vals.size and not (vals.min() >= 0 and vals.max() < 4):
        raise ValueError("a half row store holds values in [0, 4); got "
                         f"[{vals.min()}, {vals.max()}]")
    bits = (vals * np.float32(2.0 ** -HALF_SHIFT)).view(np.uint32)
    bits = (bits + np.uint32(0x7FF) + ((bits >> 12) & np.uint32(1))) >> 12   # to nearest, even
    return bits.astype(np.uint16)


def decode_half(codes, scaled=True):
    """Float64 values of :func:`encode_half`'s ``codes``; ``scaled=False``: times
    2^-HALF_SHIFT (the caller scales a product once)."""
    bits = codes.astype(np.uint32)
    bits <<= 12
    out = bits.view(np.float32).astype(np.float64)
    if scaled:
        out *= 2.0 ** HALF_SHIFT
    return out


class RowStore:
    """Rows computed so far, compact: per batch, its row keys, the columns it hit and the values.

    Parameters
    ----------
    n_rows : int
        Row keys are in [0, n_rows): node ids of a bake's rows, or gather-point ids.
    n_cols : int
        Columns of a full row (2P nodes).

    half : bool
        Keep the values in 16 bits (:data:`HALF_SHIFT`) in chunks of :data:`HALF_CHUNK` rows:
        for gather rows, never for a solve's.

    A bake's node store is never edited once handed on: :meth:`copy` shares the old batches.
    """

    def __init__(self, n_rows, n_cols, half=False):
        self.n_rows, self.n_cols, self.half = n_rows, n_cols, bool(half)
        self.batches = []                          # (keys (S,), cols (K,), vals (S, K) f32)
        self.row_sums = np.full(n_rows, np.nan)    # full row sum of every computed row
        self.where = np.full((n_rows, 2), -1, dtype=np.int64)   # (batch, row) of each key
        self.nbytes = 0
        # A half store's factor per row that keeps its sum (HALF_SHIFT).
        self.scale = np.ones(n_rows) if self.half else None
        # With a directional sky (core.sky): what each row's eye received of it through its
        # empty pixels, (n_rows, 3); None without one.
        self.sky = None

    def copy(self):
        new = RowStore(self.n_rows, self.n_cols, self.half)
        new.batches = list(self.batches)
        new.row_sums = self.row_sums.copy()
        new.sky = None if self.sky is None else self.sky.copy()
        new.where = self.where.copy()
        new.scale = None if self.scale is None else self.scale.copy()
        new.nbytes = self.nbytes
        return new

    def add(self, keys, rows, sky=None):
        """Keep ``rows`` (S, n_cols) of ``keys`` (S,), compacted, and their sky light ``sky``
        (S, 3) if given; returns the columns hit (K,)."""
        cols, vals = compact_rows(rows)
        self.add_compact(keys, cols, vals, rows.sum(axis=1))
        if sky is not None:
            if self.sky is None:
                self.sky = np.zeros((self.n_rows, 3))
            self.sky[keys] = sky
        return cols

    def add_compact(self, keys, cols, vals, row_sums=None):
        """Keep rows already compacted by :func:`compact_rows` (row sums: of ``vals`` if None)."""
        if row_sums is None or self.half:
            sums = vals.sum(axis=1, dtype=np.float64)
        self.row_sums[keys] = sums if row_sums is None else row_sums
        if not self.half:
            self._append(keys, cols, vals)
            return
        keys, cols = np.asarray(keys, dtype=np.int64), np.asarray(cols, dtype=np.int32)
        for s in range(0, len(keys), HALF_CHUNK):
            part = vals[s:s + HALF_CHUNK]
            hit = np.any(part > 0, axis=0)
            codes = encode_half(part[:, hit])
            was, got = sums[s:s + HALF_CHUNK], decode_half(codes).sum(axis=1)
            self.scale[keys[s:s + HALF_CHUNK]] = np.divide(was, got, out=np.ones_like(was),
                                                           where=got > 0)
            self._append(keys[s:s + HALF_CHUNK], cols[hit], codes)

    def _append(self, keys, cols, vals):
        b = len(self.batches)
        self.batches.append((keys, cols, vals))
        self.where[keys, 0] = b
        self.where[keys, 1] = np.arange(len(keys))
        self.nbytes += vals.nbytes + cols.nbytes + keys.nbytes

    def _values(self, vals, keys, dtype=np.float64):
        """A batch's values (of rows ``keys``: (S,) for (S, K) values, or one per value) as
        ``dtype`` (a half store's decoded and scaled)."""
        if not self.half:
            return vals.astype(dtype)
        scale = self.scale[keys]
        return (decode_half(vals) * (scale[:, None] if vals.ndim == 2 else scale)).astype(dtype)

    def n_stored(self):
        """Number of keys with a stored row."""
        return int(np.count_nonzero(self.where[:, 0] >= 0))

    def hit(self):
        """(n_cols,) bool: columns hit by any stored row."""
        out = np.zeros(self.n_cols, dtype=bool)
        for _, cols, _ in self.batches:
            out[cols] = True
        return out

    def has(self, keys):
        return self.where[keys, 0] >= 0

    def rows(self, keys):
        """Dense (len(keys), n_cols) float64 rows of stored keys."""
        out = np.zeros((len(keys), self.n_cols))
        bs = self.where[keys, 0]
        for b in np.unique(bs):
            sel = np.flatnonzero(bs == b)
            _, cols, vals = self.batches[b]
            out[np.ix_(sel, cols)] = self._values(vals[self.where[keys[sel], 1]], keys[sel])
        return out

    def entries(self, keys, cols):
        """(n,) float32: the stored rows' values at (``keys[i]``, ``cols[i]``) (0 where a row
        has no value there or is not stored)."""
        keys, cols = np.asarray(keys, dtype=np.int64), np.asarray(cols, dtype=np.int64)
        out = np.zeros(keys.size, dtype=np.float32)
        bs = self.where[keys, 0] if keys.size else np.zeros(0, dtype=np.int64)
        for b in np.unique(bs[bs >= 0]):
            sel = np.flatnonzero(bs == b)
            _, bcols, vals = self.batches[b]
            if bcols.size == 0:
                continue
            order = np.argsort(bcols, kind="stable")    # ascending as made; not relied on
            at = np.minimum(np.searchsorted(bcols[order], cols[sel]), bcols.size - 1)
            hit = bcols[order[at]] == cols[sel]
            key = keys[sel[hit]]
            out[sel[hit]] = self._values(vals[self.where[key, 1], order[at[hit]]], key,
                                         np.float32)
        return out

    def incident(self, node_radiance):
        """(n_rows, 3): ``sum_j F(key -> j) L_j`` for every stored row (zero elsewhere)."""
        out = np.zeros((self.n_rows, 3))
        L = np.asarray(node_radiance, dtype=np.float64)
        for keys, cols, vals in self.batches:
            v = decode_half(vals, scaled=False) if self.half else vals.astype(np.float64)
            out[keys] = v @ L[cols]
        if self.half:
            out *= (2.0 ** HALF_SHIFT) * self.scale[:, None]
        return out

    def assemble(self, row_keys, col_nodes, dtype, monitor=None):
        """Dense block F[row_keys][:, col_nodes] from the stored rows (all must be stored).

        ``monitor`` is polled between batches (cancel within a poll interval).
        """
        pos_r = np.full(self.n_rows, -1, dtype=np.int64)
        pos_r[row_keys] = np.arange(len(row_keys))
        pos_c = np.full(self.n_cols, -1, dtype=np.int64)
        pos_c[col_nodes] = np.arange(len(col_nodes))
        out = np.zeros((len(row_keys), len(col_nodes)), dtype=dtype)
        for keys, cols, vals in self.batches:
            r = pos_r[keys]
            rk = r >= 0
            c = pos_c[cols]
            ck = c >= 0
            if not (rk.any() and ck.any()):
                continue
            if not (rk.all() and ck.all()):
                vals = vals[np.ix_(rk, ck)]
            if self.half:
                vals = self._values(vals, keys[rk], dtype)
            rows, cols_at = r[rk], c[ck]
            for s in range(0, len(rows), ASSEMBLE_ROWS):
                # Scattered into whole rows first, then the rows into place: two simple
                # scatters instead of one over a row x column grid of indices.
                part = vals[s:s + ASSEMBLE_ROWS]
                block = np.zeros((len(part), len(col_nodes)), dtype=dtype)
                block[:, cols_at] = part
                out[rows[s:s + ASSEMBLE_ROWS]] = block
            poll(monitor, "assembling form factors")
        return out


def row_function(patches, method, resolution, rotate, rng, rays, near=BY_NAME["near"].default,
                 sky=None):
    """Return rows(sources (S,) int64) -> (S, 2P) float64 for the chosen method.

    With a directional ``sky`` (:class:`core.sky.Sky`; the hemicube only) rows returns
    ``(rows, sky light (S, 3))`` (:func:`split_rows` takes them apart).
    """
    if sky is not None and method != "hemicube":
        raise SettingsError(f"method={method!r} cannot carry a sky that varies with direction "
                            "(sky='cie_overcast'): use method='hemicube'")
    if method == "hemicube" and sky is not None:
        def rows(sources):
            light = np.zeros((len(sources), 3))
            out = hemicube_rows(patches, sources, resolution=resolution, rotate=rotate, rng=rng,
                                sky=sky, sky_out=light)
            return out, light
        return rows
    if method == "hemicube":
        def rows(sources):
            return hemicube_rows(patches, sources, resolution=resolution, rotate=rotate, rng=rng)
        return rows
    if method == "nusselt":
        def rows(sources):
            return nusselt_rows(patches, sources, resolution=resolution, rotate=rotate, rng=rng)
        return rows
    if method not in _METHOD_NAMES:
        raise SettingsError(f"method must be one of {_METHOD_NAMES}; got {method!r}")
    bvh = build_bvh(ray_triangles(patches)[0])
    if method == "exact":
        # The exact method is the reference: integrate over the source patch too (adaptive
        # Gauss order), not just its centre, or it keeps the hemicube's point-source error.
        def rows(sources):
            return exact_rows(patches, sources, rays=rays, rng=rng, bvh=bvh,
                              source_order="adaptive")
        return rows
    if method == "raytraced":
        def rows(sources):
            return raytraced_rows(patches, sources, rays=rays, rng=rng, bvh=bvh)
        return rows

    def rows(sources):
        return hybrid_rows(patches, sources, resolution=resolution, rays=rays, rng=rng,
                           bvh=bvh, rotate=rotate, near=near)
    return rows


def split_rows(rows):
    """(rows, sky light or None) of what a :func:`row_function` returned."""
    return rows if isinstance(rows, tuple) else (rows, None)


def row_seconds(patches, method, resolution, rays):
    """Estimated seconds for one form-factor row (see ROW_SECONDS_PER_*)."""
    n_tri = 2 * len(patches.areas)                  # quads -> 2 triangles (upper bound)
    hemi = ROW_SECONDS_PER_PIXEL * resolution ** 2 + ROW_SECONDS_PER_TRIANGLE * n_tri
    if method == "hemicube":
        return hemi
    if method == "hybrid":
        return HYBRID_COST_FACTOR * hemi
    if method == "nusselt":
        return NUSSELT_COST_FACTOR * hemi
    pair_ray = ROW_SECONDS_PER_PAIR_RAY * len(patches.areas) * rays
    return RAYTRACED_COST_FACTOR * pair_ray if method == "raytraced" else pair_ray


class Batcher:
    """Deterministic batch sizes: 1, 4, 16, ... up to about BATCH_SECONDS of estimated work."""

    def __init__(self, n_nodes, row_seconds):
        cap = max(1, min(MAX_BATCH_SOURCES, MAX_BATCH_ENTRIES // max(n_nodes, 1)))
        self.full = int(np.clip(BATCH_SECONDS / max(row_seconds, 1e-9), 1, cap))
        self.size = 1

    def rows(self, fn, sources):
        """``fn(sources)``, then grow the next batch (up to ``full``)."""
        out = fn(sources)
        self.size = min(self.full, self.size * BATCH_GROWTH)
        return out


def form_factor_matrix(patches, *, method="hemicube", resolution=64, rotate=False, rng=None,
                       rays=16, monitor=None):
    """Dense form factors between all 2P nodes (tests and small scenes).

    Parameters
    ----------
    patches : core.patches.Patches
    method : str
        One of core.settings.METHODS ('hemicube', 'exact', 'hybrid', 'raytraced', ...).
    resolution : int
        Hemicube resolution.
    rotate : bool
        Random hemicube rotations (from ``rng``).
    rng : numpy.random.Generator, optional
        Default: ``np.random.default_rng(0)``.
    rays : int
        Visibility rays per pair ('exact', 'hybrid'), source samples ('raytraced').
    monitor : core.progress.Monitor, optional

    Returns
    -------
    (2P, 2P) float64
        Row i: fraction of the energy leaving node i that reaches each node.
    """
    if method not in _METHOD_NAMES:
        raise ValueError(f"method must be one of {_METHOD_NAMES}; got {method!r}")
    if rng is None:
        rng = np.random.default_rng(0)
    elif not isinstance(rng, np.random.Generator):
        raise TypeError(f"rng must be a numpy.random.Generator; got {type(rng).__name__}")
    monitor = Monitor() if monitor is None else monitor
    n = 2 * len(patches.areas)
    fn = row_function(patches, method, resolution, rotate, rng, rays)
    out = np.zeros((n, n))
    batcher = Batcher(n, row_seconds(patches, method, resolution, rays))
    done = 0
    while done < n:
        sources = np.arange(done, min(done + batcher.size, n), dtype=np.int64)
        out[sources] = split_rows(batcher.rows(fn, sources))[0]
        done = sources[-1] + 1
        monitor.update(done / n, "form factors")
    return out


def discover(store, rows_fn, allowed, start_active, frontier, monitor, budget, batcher,
             expand=True):
    """Grow the active set wave by wave from ``frontier``; rows of new active nodes are stored.

    With ``expand=False`` only the rows of ``frontier`` are computed: what they hit is not added.

    Returns (active (2P,) bool, overflow bool). ``overflow``: the store outgrew ``budget``
    and discovery stopped early.
    """
    active = start_active.copy()
    active[frontier] = True
    pending = np.asarray(np.sort(frontier), dtype=np.int64)
    best = 0.0
    while len(pending):
        pos = 0
        next_wave = np.zeros(store.n_cols, dtype=bool)
        while pos < len(pending):
            sources = pending[pos:pos + batcher.size]
            rows, sky = split_rows(batcher.rows(rows_fn, sources))
            hit = store.add(sources, rows, sky)
            pos += len(sources)
            if expand:
                new = hit[allowed[hit] & ~active[hit]]
                active[new] = True
                next_wave[new] = True
            done = store.n_stored()
            left = len(pending) - pos + int(np.count_nonzero(next_wave))
            best = max(best, done / (done + left))
            monitor.update(best, f"form factors: {done} nodes")
            if store.nbytes > budget:
                return active, True
        pending = np.flatnonzero(next_wave)
    return active, False
