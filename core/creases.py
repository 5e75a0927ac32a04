"""The light at a concave crease: what a gather point on it reads of the surface across it.

A gather point on a concave crease (a floor point at a wall's foot, a room's corner, a point at a
box's foot) stands a tiny inset (:data:`core.gather.INSET`) off the surface across the crease.
The form factor from the point to an area ``dA`` of that surface at distance ``r`` is
``cos t cos t' dA / (pi r^2)`` with ``cos t' = h / r`` (``h`` the point's height over the
surface's plane): it falls as ``h / r^3``, and nearly all of what the point receives from that
surface comes from within a few ``h`` of the crease (the share from beyond a distance ``D`` of
the point's foot on it is of order ``h / D``). Its hemicube,
though, reads the element it sees there at the element's one gathered value, taken at the
element's centre a centimetre or more out. The light dips steeply into a concave corner, so that
value is brighter than the light at the crease: the corners of a plain room read 15-20 % too
bright against Cycles (tests/compare/test_room_corners.py).

Remedy: every (gather point, element) pair where the point lies within :data:`DEPTH` x the
element's size of the element's plane, out of the crease angle, with its foot on the element,
reads that element at the other surface's own value at the foot instead: the inverse-distance
mean of the other surface's two gather points on the crease nearest the foot (points in the
element's plane to the contact tolerance, facing its side, within ``DEPTH`` x its size of the
point's own plane and in front of it; of those at the foot itself, one on the element first).
The two surfaces' crease values depend on each other, so the correction is swept
:data:`SWEEPS` times (Jacobi) from the points' gathered light.

The same rows are read: only the value a row's entry reads changes, so relight applies the same
correction to its own solution (:meth:`Creases.incident`).
"""

import numpy as np

from .constants import tol
from .gather import shade
from .geometry import box_pairs, patch_extents, within_crease

#: A point counts as on the crease of an element when it lies within this fraction of the
#: element's size (longest edge) of the element's plane: the share of its form factor to the
#: element from beyond half the element from its foot is then of order 2 DEPTH. Gather points
#: stand about 1e-3 of their faces' size off the crease (core.gather.INSET).
DEPTH = 0.05

#: Partner points are looked for within this many element sizes of the foot.
REACH = 1.5

#: A partner point faces the element's side within 1 degree.
FACING_COS = float(np.cos(np.radians(1.0)))

#: Grid cell of the pair searches: this quantile of the items' sizes (a large item then covers
#: few cells, a cell few small items).
CELL_QUANTILE = 0.9

#: Jacobi sweeps of the crease values. Two walls meeting at a right angle exchange about half of
#: each crease point's hemisphere, so a sweep shrinks the change by about rho / 2.
SWEEPS = 8


class Creases:
    """The (point, column) entries of gather rows read against a crease value.

    Attributes
    ----------
    point : (n,) int64
        Gather point (row key) of each entry.
    col : (n,) int64
        Column of the row the entry replaces.
    weight : (n,) float64
        The row's form factor there.
    nearest, second : (n,) int64
        The other surface's two gather points on the crease nearest the foot, nearest first
        (equal when only one was found).
    share : (n,) float64
        Weight of ``nearest`` (inverse distance; ``second`` takes ``1 - share``).
    """

    def __init__(self, point, col, weight, nearest, second, share):
        self.point, self.col, self.weight = point, col, weight
        self.nearest, self.second, self.share = nearest, second, share

    def __len__(self):
        return int(self.point.size)

    def incident(self, scene, material, incident, col_radiance):
        """(U, 3) incident light of the gather points with each entry read at its crease value.

        Parameters
        ----------
        scene : core.scene.Scene
            For the points' reflectance and emission (:func:`core.gather.shade`).
        material : (U,) int64
            Material of every gather point.
        incident : (U, 3) float64
            Their light as gathered (rows against ``col_radiance``, plus direct light).
        col_radiance : (n_cols, 3) float64
            What the rows' columns read.
        """
        base = np.asarray(incident, dtype=np.float64)
        if not len(self):
            return base
        f = self.weight[:, None]
        s = self.share[:, None]
        read = f * np.asarray(col_radiance, dtype=np.float64)[self.col]
        out = base
        for _ in range(SWEEPS):
            B = shade(scene, material, out)
            at_foot = s * B[self.nearest] + (1.0 - s) * B[self.second]
            out = base.copy()
            np.add.at(out, self.point, f * at_foot - read)
        return np.maximum(out, 0.0)        # what is taken was added: below 0 only by rounding


def find_creases(points, normals, rows, seen, *, crease_angle):
    """The entries of ``rows`` to read at crease values (:class:`Creases`).

    Parameters
    ----------
    points, normals : (U, 3) float64
        The gather points (each facing the side it gathered on).
    rows : core.rows.RowStore
        Their rows (keys 0..U-1); columns ``[0, K)`` are the front nodes of ``seen``'s K items,
        ``[K, 2K)`` their back nodes (columns beyond, far patches, are never crease entries).
    seen : core.farfield.Seen or core.patches.Patches
        The items (receiver elements or patches) the rows' first 2K columns stand for (their
        ``centres``, ``normals``, ``corners`` and ``areas`` are read).
    crease_angle : float
        Degrees: an element within it of the point's normal is the point's own smooth surface.
    """
    P = np.asarray(points, dtype=np.float64)
    N = np.asarray(normals, dtype=np.float64)
    K = seen.areas.size
    none = np.zeros(0, dtype=np.int64)
    empty = Creases(none, none, np.zeros(0), none, none, np.zeros(0))
    if P.shape[0] == 0 or K == 0:
        return empty
    C, n_e, X = seen.centres, seen.normals, seen.corners
    _, size = patch_extents(X, C)
    cell = float(np.quantile(size, CELL_QUANTILE))
    if not cell > 0:                               # every item degenerate: nothing to read
        return empty
    pad = (DEPTH * size)[:, None]
    u, e = box_pairs(P, P, X.min(axis=1) - pad, X.max(axis=1) + pad, cell)
    h = np.einsum("ij,ij->i", P[u] - C[e], n_e[e])
    side = np.where(h >= 0, 1.0, -1.0)
    ok = (np.abs(h) <= DEPTH * size[e]) \
        & ~within_crease(N[u], side[:, None] * n_e[e], crease_angle) \
        & ~within_crease(N[u], -side[:, None] * n_e[e], crease_angle)
    u, e, h, side = u[ok], e[ok], h[ok], side[ok]
    foot = P[u] - h[:, None] * n_e[e]
    ok = _outside(foot, X[e], n_e[e]) <= np.abs(h) + 1e-12 * size[e]
    u, e, side, foot = u[ok], e[ok], side[ok], foot[ok]
    col = np.where(side > 0, e, e + K)
    weight = rows.entries(u, col)
    ok = weight > 0
    u, e, side, foot, col, weight = u[ok], e[ok], side[ok], foot[ok], col[ok], weight[ok]
    if u.size == 0:
        return empty
    # Partners lie in the element's plane: its surface, not a parallel one a board's thickness
    # away (tol.contact of the scene's diagonal, what the contact cuts call touching).
    on_plane = tol.contact * float(np.linalg.norm(np.ptp(X.reshape(-1, 3), axis=0)))
    nearest, second, share = _partners(P, N, u, e, side, foot, C, n_e, X, size, cell,
                                       on_plane)
    ok = nearest >= 0
    return Creases(u[ok], col[ok], weight[ok].astype(np.float64), nearest[ok], second[ok],
                   share[ok])


def _outside(q, corners, normal):
    """(n,) float: how far the in-plane points ``q`` lie outside the convex polygons ``corners``
    (n, 4, 3) (counter-clockwise about ``normal``; 0 inside): the largest distance beyond an
    edge's line."""
    out = np.zeros(q.shape[0])
    for k in range(4):
        edge = corners[:, (k + 1) % 4] - corners[:, k]
        inward = np.cross(normal, edge)
        length = np.linalg.norm(inward, axis=1)
        real = length > 0                  # a triangle's repeated corner gives a zero edge
        s = np.einsum("ij,ij->i", q - corners[:, k], inward) / np.where(real, length, 1.0)
        out = np.maximum(out, np.where(real, -s, 0.0))
    return out


def _partners(P, N, u, e, side, foot, C, n_e, X, size, cell, on_plane):
    """For every crease entry, the two gather points of the element's surface on the crease
    nearest its foot (one at the foot and on the element first), and the nearer one's
    inverse-distance weight (-1: none; one found: both that one). A partner lies within
    ``on_plane`` (m) of the element's plane.

    Not within ``DEPTH`` x the element's size, which the entries' points are: inside a shelf's
    3 cm top board, flush against the side panel, the panel's points on the board's top edge
    stand 3 cm over the board's long underside (within 5 % of its 1.7 m), see its back, and
    read the board's lit top, 3 cm further on and facing the same way, as its crease value: a
    strip of the panel hidden in the board read 0.45 x the top's light, and the office
    sample's reference faces over it +73 % (exact emitters 'all'; bench/compare/coarse.py).
    """
    # The partners lie along the crease: search the segment foot +- REACH x size along it.
    line = np.cross(N[u], side[:, None] * n_e[e])
    line /= np.maximum(np.linalg.norm(line, axis=1, keepdims=True), 1e-300)
    reach = (REACH * size[e])[:, None] * np.abs(line) + (DEPTH * size[e])[:, None]
    c, v = box_pairs(foot - reach, foot + reach, P, P, cell)
    n_side = side[c, None] * n_e[e[c]]
    off_own = np.einsum("ij,ij->i", P[v] - P[u[c]], N[u[c]])
    depth = DEPTH * size[e[c]]
    ok = (np.einsum("ij,ij->i", N[v], n_side) >= FACING_COS) \
        & (np.abs(np.einsum("ij,ij->i", P[v] - C[e[c]], n_e[e[c]]))
           <= np.minimum(depth, on_plane)) \
        & (off_own > 0) & (off_own <= depth) & (v != u[c])
    c, v = c[ok], v[ok]
    d = np.linalg.norm(P[v] - foot[c], axis=1)
    # Of the points at the foot itself (within DEPTH x the element's size: one vertex's
    # groups), one on the element comes first: where the other surface's light is
    # discontinuous there (a box's corner on a floor, its per-corner groups either side of a
    # shadow line), each element takes the light of its own side. The rest by distance.
    off = (d > DEPTH * size[e[c]]) | (_outside(P[v], X[e[c]], n_e[e[c]]) > 1e-9 * size[e[c]])
    order = np.lexsort((v, d, off, c))            # nearest first per entry (ties: lower id)
    c, v, d, off = c[order], v[order], d[order], off[order]
    n = u.size
    if c.size == 0:
        return np.full(n, -1, dtype=np.int64), np.full(n, -1, dtype=np.int64), np.ones(n)
    first = np.flatnonzero(np.r_[True, c[1:] != c[:-1]])
    second = first + 1
    two = second < c.size
    two[two] = (c[second[two]] == c[first[two]]) & (off[second[two]] == off[first[two]])
    near, other = np.full(n, -1, dtype=np.int64), np.full(n, -1, dtype=np.int64)
    share = np.ones(n)
    near[c[first]] = v[first]
    other[c[first]] = v[first]
    d1, d2 = d[first[two]], d[second[two]]
    other[c[first[two]]] = v[second[two]]
    total = d1 + d2
    share[c[first[two]]] = np.where(total > 0, d2 / np.where(total > 0, total, 1.0), 0.5)
    return near, other, share
