"""Shadow-ray results kept per point and light, so that a relight that only changes the lights'
power or colour (or the exact emitters' strength) casts no shadow ray again (issue 12).

What a light's shadow rays find at a point (the visible fraction of the light, and whether the ray
to its centre is clear) depends on the point, its normal, the number of rays and the scene's
geometry, never on the light's power or colour. :class:`core.lights.DirectLight` records every
result of a bake here; a copy of it lit by the same lights at another power
(:meth:`core.lights.DirectLight.recoloured`) reads them back and casts only the (point, light)
pairs the bake did not cast (a light the culling skipped at a point, or a dark light), so it gives
what a fresh cast would, bit for bit.

Points are found by a hash of their coordinates, normal and ray count, checked against the stored
values (a collision is a miss: the pair is cast again). The table itself (:class:`PointTable`)
also keeps the exact emitters' unshadowed light per point (:mod:`core.emitters`).
"""

import numpy as np

#: Bytes the record may hold. Beyond them nothing more is kept: a relight then casts what it
#: lacks, as a bake does. 150k points and 20 lights take about 35 MB.
BUDGET = 256 * 2**20

#: ``frac`` of a pair that cast only the ray to the light's centre (a light culled at the point,
#: core.lights.CULL); ``clear`` holds that ray. A pair cast in full holds its centre ray too.
ONE_RAY = -1.0

#: Odd 64-bit multipliers of the six coordinates' bit patterns (wrapping arithmetic).
_MIX = np.array([0x9E3779B97F4A7C15, 0xC2B2AE3D27D4EB4F, 0x165667B19E3779F9,
                 0xD6E8FEB86659FD93, 0xFF51AFD7ED558CCD, 0xC4CEB9FE1A85EC53], dtype=np.uint64)


def point_keys(points, normals, samples):
    """(n, 6) float64 rows (point, normal) and their (n,) uint64 hash keys for ``samples``."""
    rows = np.ascontiguousarray(np.concatenate([points, normals], axis=1), dtype=np.float64)
    # Each coordinate's bits mixed first (round numbers' bits are all high: multiplied alone,
    # they collide), then combined by column.
    h = (_mix(rows.view(np.uint64)) * _MIX).sum(axis=1, dtype=np.uint64)
    return rows, _mix(h ^ np.uint64(int(samples)))


def _mix(x):
    """SplitMix64's finaliser, elementwise on uint64 (wrapping)."""
    x = x ^ (x >> np.uint64(30))
    x = x * np.uint64(0xBF58476D1CE4E5B9)
    x = x ^ (x >> np.uint64(27))
    x = x * np.uint64(0x94D049BB133111EB)
    return x ^ (x >> np.uint64(31))


class PointTable:
    """Rows of values kept per point (and ray count), found by :func:`point_keys`.

    ``columns``: (width, dtype) of each value array; :attr:`values` holds them, (N, width) each,
    one row per point kept. Beyond ``budget`` bytes nothing more is added (:attr:`full`).
    """

    def __init__(self, columns, budget):
        self.budget = int(budget)
        self.keys = np.zeros(0, dtype=np.uint64)
        self.rows = np.zeros((0, 6))
        self.samples = np.zeros(0, dtype=np.int64)
        self.values = [np.zeros((0, int(w)), dtype=dt) for w, dt in columns]
        self._pending = []
        self._added = 0                     # rows in _pending
        self.full = False
        #: Bytes held (the table and the points added since it was last sorted).
        self.nbytes = 0

    def find(self, rows, keys, samples, lazy=False):
        """(n,) int64: the entry of each point (-1: none). ``lazy``: the points added since the
        table was last sorted are found only once they are as many as the sorted ones (a bake
        asks chunk after chunk of new points: sorting the whole table at each would cost
        O(n log n) per chunk; its bake took 1.23x as long)."""
        if not lazy or self._added >= self.keys.size:
            self.sort()
        n = keys.size
        if not self.keys.size or not n:
            return np.full(n, -1, dtype=np.int64)
        at = np.minimum(np.searchsorted(self.keys, keys), self.keys.size - 1)
        ok = (self.keys[at] == keys) & (self.samples[at] == int(samples)) \
            & np.all(self.rows[at] == rows, axis=1)
        return np.where(ok, at, -1)

    def add(self, rows, keys, samples, *values):
        """Keep new points' rows of values (nothing once :attr:`full`)."""
        if not keys.size or self.full:
            return
        part = (keys, rows, np.full(keys.size, int(samples), dtype=np.int64)) + values
        size = sum(a.nbytes for a in part)
        if self.nbytes + size > self.budget:
            self.full = True
            return
        self._pending.append(part)
        self._added += keys.size
        self.nbytes += size

    def sort(self):
        """Sort the points added since the last sort into the table (find finds them all)."""
        if not self._pending:
            return
        parts = list(zip(*self._pending))
        self._pending, self._added = [], 0
        keys = np.concatenate([self.keys, *parts[0]])
        order = np.argsort(keys, kind="stable")
        keys = keys[order]
        first = np.ones(keys.size, dtype=bool)            # one entry per key (the oldest)
        first[1:] = keys[1:] != keys[:-1]
        order = order[first]
        self.keys = keys[first]
        self.rows = np.concatenate([self.rows, *parts[1]])[order]
        self.samples = np.concatenate([self.samples, *parts[2]])[order]
        self.values = [np.concatenate([v, *p])[order] for v, p in zip(self.values, parts[3:])]
        self.nbytes = sum(a.nbytes for a in (self.keys, self.rows, self.samples, *self.values))


class ShadowMemo(PointTable):
    """Visible fractions and centre rays per (point, light) of a set of ``m`` lights.

    Attributes
    ----------
    frac : (N, m) float64
        Visible fraction of light j at point i (NaN: not cast there; ``ONE_RAY``: only the
        ray to its centre).
    clear : (N, m) bool
        The ray to light j's centre from point i is clear (where ``frac`` is set).
    """

    def __init__(self, m, budget=BUDGET):
        self.m = int(m)
        super().__init__([(self.m, np.float64), (self.m, bool)], budget)

    @property
    def frac(self):
        return self.values[0]

    @property
    def clear(self):
        return self.values[1]

    def add(self, rows, keys, samples, frac, clear):
        """Keep new points' results (rows with nothing cast are not kept)."""
        keep = ~np.all(np.isnan(frac), axis=1)
        if keep.any():
            super().add(rows[keep], keys[keep], samples, frac[keep], clear[keep])

    def update(self, entries, frac, clear):
        """Fill in the pairs newly cast at points already kept (``entries``: their index)."""
        new = ~np.isnan(frac)
        i, j = np.nonzero(new)
        self.frac[entries[i], j] = frac[i, j]
        self.clear[entries[i], j] = clear[i, j]
