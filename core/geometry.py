"""Polygon helpers: Newell normals and areas, convexity of quads, triangulation.

Everything works on padded polygon arrays ``(n, K, 3)`` in scene metres. A polygon with fewer than
``K`` corners repeats its last corner (a repeated corner adds a zero-length edge, which changes
neither the Newell vector nor the shape), or its true corner counts are given as ``sizes``.
"""

import numpy as np

from .constants import tol






def within_crease(na, nb, crease_angle):
    """(n,) bool: unit normals ``na``, ``nb`` (n, 3) differ by at most ``crease_angle`` degrees."""
    return np.einsum("ij,ij->i", na, nb) >= np.cos(np.radians(crease_angle)) - tol.crease_cos


def ragged(counts):
    """Owner, local index and owner start of every item when owner e has ``counts[e]`` items.

    Parameters
    ----------
    counts : (E,) int

    Returns
    -------
    owner, local : (sum(counts),) int64
    starts : (E,) int64
        Index of each owner's first item.
    """
    counts = np.asarray(counts, dtype=np.int64)
    owner = np.repeat(np.arange(counts.shape[0], dtype=np.int64), counts)
    starts = np.cumsum(counts) - counts
    local = np.arange(owner.shape[0], dtype=np.int64) - starts[owner]
    return owner, local, starts


def _as_polygons(name, polygons):
    arr = np.asarray(polygons, dtype=np.float64)
    if arr.ndim != 3 or arr.shape[2] != 3 or arr.shape[1] < 3:
        raise ValueError(f"{name} must have shape (n, K, 3) with K >= 3; got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite; got NaN or inf")
    return arr


def patch_extents(corners, centres):
    """(radius, size) of (P, 4, 3) patch corners: the farthest corner from the centre, and the
    longest edge (a triangle's repeated last corner gives a zero edge)."""
    radius = np.linalg.norm(corners - centres[:, None, :], axis=2).max(axis=1)
    size = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2).max(axis=1)
    return radius, size


def newell_vectors(polygons, sizes=None):
    """Newell vector of every polygon: normal direction, length = area.

    Parameters
    ----------
    polygons : (n, K, 3) float
        Corners in order (counter-clockwise about the normal that comes out).
    sizes : (n,) int, optional
        True corner count of each polygon (3 <= size <= K); the corners beyond are ignored.
        Default: all K corners (pad short polygons by repeating their last corner).

    Returns
    -------
    (n, 3) float64
        ``0.5 * sum_k p_k x p_(k+1)``; exact area vector of a planar polygon, and the area vector
        of the projection onto the best-fit plane of a non-planar one. It is additive: the Newell
        vectors of the pieces of a partition sum to that of the whole.
    """
    poly = _as_polygons("polygons", polygons)
    n, k = poly.shape[:2]
    idx = np.arange(k)
    if sizes is None:
        nxt = np.broadcast_to((idx + 1) % k, (n, k))
        used = np.ones((n, k), dtype=bool)
    else:
        sizes = np.asarray(sizes)
        if sizes.shape != (n,) or not np.issubdtype(sizes.dtype, np.integer):
            raise ValueError(f"sizes must be an integer array of shape ({n},); "
                             f"got {sizes.dtype} {sizes.shape}")
        if n and (sizes.min() < 3 or sizes.max() > k):
            raise ValueError(f"sizes must lie in [3, {k}]; got values in [{sizes.min()}, {sizes.max()}]")
        nxt = np.where(idx[None, :] + 1 < sizes[:, None], idx[None, :] + 1, 0)
        used = idx[None, :] < sizes[:, None]
    # Centre first: cross products of far-from-origin coordinates lose digits.
    centre = poly[:, :1, :]
    p = poly - centre
    q = np.take_along_axis(p, nxt[:, :, None], axis=1)
    cross = np.cross(p, q) * used[:, :, None]
    return 0.5 * cross.sum(axis=1)


def newell_normals_areas(polygons, sizes=None):
    """Unit Newell normals and areas of padded polygons.

    Parameters
    ----------
    polygons : (n, K, 3) float
    sizes : (n,) int, optional
        See :func:`newell_vectors`.

    Returns
    -------
    normals : (n, 3) float64
        Unit normals; zero rows for polygons of zero area.
    areas : (n,) float64
    """
    vec = newell_vectors(polygons, sizes)
    areas = np.linalg.norm(vec, axis=1)
    safe = np.where(areas > 0, areas, 1.0)
    normals = np.where((areas > 0)[:, None], vec / safe[:, None], 0.0)
    return normals, areas


def corner_turns(polygons, normals):
    """Turn at every corner: (e_in x e_out) . normal / (|e_in| |e_out|).

    Parameters
    ----------
    polygons : (n, K, 3) float
    normals : (n, 3) float
        Unit normal of each polygon (its counter-clockwise side).

    Returns
    -------
    (n, K) float64
        Sine of the turning angle at each corner: > 0 convex, < 0 reflex, 0 straight (or a
        zero-length edge).
    """
    poly = _as_polygons("polygons", polygons)
    normals = np.asarray(normals, dtype=np.float64)
    if normals.shape != (poly.shape[0], 3):
        raise ValueError(f"normals must have shape ({poly.shape[0]}, 3); got {normals.shape}")
    e_out = np.roll(poly, -1, axis=1) - poly
    e_in = poly - np.roll(poly, 1, axis=1)
    cross = np.einsum("nkj,nj->nk", np.cross(e_in, e_out), normals)
    scale = np.linalg.norm(e_in, axis=2) * np.linalg.norm(e_out, axis=2)
    return np.where(scale > 0, cross / np.where(scale > 0, scale, 1.0), 0.0)


def quads_convex(quads, normals):
    """Whether each quad has no reflex corner, seen along its normal.

    Parameters
    ----------
    quads : (n, 4, 3) float
    normals : (n, 3) float
        Unit normal of each quad.

    Returns
    -------
    (n,) bool
        True where every corner turn is >= ``tol.convex_turn`` (straight corners count
        as convex: a bilinear grid on such a quad does not fold).
    """
    quads = _as_polygons("quads", quads)
    if quads.shape[1] != 4:
        raise ValueError(f"quads must have shape (n, 4, 3); got {quads.shape}")
    return np.all(corner_turns(quads, normals) >= tol.convex_turn, axis=1)


def split_concave_quads(quads, normals):
    """Split quads with one reflex corner into two triangles along the diagonal from it.

    Parameters
    ----------
    quads : (n, 4, 3) float
    normals : (n, 3) float
        Unit normal of each quad.

    Returns
    -------
    (n, 2, 3) int64
        Local corner indices (0..3) of the two triangles of each quad, counter-clockwise. The
        diagonal runs from the most reflex corner r to r + 2, which keeps both triangles inside
        the quad (a simple quad has at most one reflex corner).
    """
    turns = corner_turns(quads, normals)
    r = np.argmin(turns, axis=1)
    local = (r[:, None] + np.arange(4)[None, :]) % 4
    return np.stack([local[:, [0, 1, 2]], local[:, [0, 2, 3]]], axis=1).astype(np.int64)


def plane_basis(normal):
    """Two unit vectors (u, v) with (u, v, normal) right-handed.

    Parameters
    ----------
    normal : (3,) float
        Unit vector.

    Returns
    -------
    u, v : (3,) float64
    """
    normal = np.asarray(normal, dtype=np.float64)
    helper = np.eye(3)[int(np.argmin(np.abs(normal)))]
    u = np.cross(helper, normal)
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)
    return u, v


def unit_frames(d):
    """Two unit vectors (n, 3) each perpendicular to the unit rows of ``d`` (n, 3) and to each
    other (``d``, e1, e2 right-handed)."""
    helper = np.where(np.abs(d[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    e1 = np.cross(d, helper)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    return e1, np.cross(d, e1)


def inside_polygons(points, polys, normals, margin=0.0):
    """(K,) bool: ``points`` (K, 3) inside the planar polygons ``polys`` (K, n, 3) of unit
    ``normals``, projected on the polygon's plane (crossing number; a padded polygon's
    repeated corners add zero-length edges, which cross nothing), and farther than ``margin``
    from every edge."""
    u, v = unit_frames(normals)
    rel = polys - points[:, None, :]
    x, y = np.einsum("knj,kj->kn", rel, u), np.einsum("knj,kj->kn", rel, v)
    x1, y1 = np.roll(x, -1, axis=1), np.roll(y, -1, axis=1)
    straddles = (y > 0) != (y1 > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        at = x + (0.0 - y) * (x1 - x) / (y1 - y)
    crossings = (straddles & (at > 0)).sum(axis=1)
    inside = crossings % 2 == 1
    if margin > 0.0:
        dx, dy = x1 - x, y1 - y
        length2 = dx * dx + dy * dy
        t = np.clip(-(x * dx + y * dy) / np.where(length2 > 0, length2, 1.0), 0.0, 1.0)
        near = ((x + t * dx) ** 2 + (y + t * dy) ** 2).min(axis=1) <= margin * margin
        inside &= ~near
    return inside


def triangulate_polygon(points, normal):
    """Ear-clipping triangulation of one simple polygon in its plane.

    Set-up code (one call per n-gon face); each step tests every candidate ear at once and clips
    the best-shaped one (largest smallest angle), which avoids some needless slivers (greedy: not
    an optimal triangulation).

    Parameters
    ----------
    points : (k, 3) float
        Corners, counter-clockwise about ``normal``; k >= 3.
    normal : (3,) float
        Unit normal of the polygon (e.g. its Newell normal).

    Returns
    -------
    (t, 3) int64
        Local corner indices of the triangles, counter-clockwise about ``normal``. ``t = k - 2``
        for a polygon without degenerate (collinear) corner runs; triangles of zero area are left
        out, so ``t`` may be smaller.
    """
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3 or pts.shape[0] < 3:
        raise ValueError(f"points must have shape (k, 3) with k >= 3; got {pts.shape}")
    normal = np.asarray(normal, dtype=np.float64)
    if normal.shape != (3,) or not np.isfinite(normal).all() or np.linalg.norm(normal) == 0:
        raise ValueError(f"normal must be a non-zero finite (3,) vector; got {normal!r}")
    u, v = plane_basis(normal / np.linalg.norm(normal))
    rel = pts - pts.mean(axis=0)
    xy = np.stack([rel @ u, rel @ v], axis=1)
    extent = float(np.ptp(xy, axis=0).max()) if len(xy) else 0.0
    tiny = tol.ear_area * max(extent, np.finfo(float).tiny) ** 2

    remaining = list(range(pts.shape[0]))
    triangles = []
    while len(remaining) > 3:
        ring = np.array(remaining)
        a, b, c = xy[np.roll(ring, 1)], xy[ring], xy[np.roll(ring, -1)]
        cross = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
        convex = cross > tiny
        cand = np.flatnonzero(convex)
        if cand.size:
            # Any other ring corner inside or on a candidate ear (not at its own corners) blocks it.
            p = xy[ring][None, :, :]
            ca, cb, cc = a[cand][:, None, :], b[cand][:, None, :], c[cand][:, None, :]

            def side(s, t):
                return (t[..., 0] - s[..., 0]) * (p[..., 1] - s[..., 1]) - \
                       (t[..., 1] - s[..., 1]) * (p[..., 0] - s[..., 0])

            inside = (side(ca, cb) >= -tiny) & (side(cb, cc) >= -tiny) & (side(cc, ca) >= -tiny)
            at_corner = (np.all(p == ca, axis=2) | np.all(p == cb, axis=2) | np.all(p == cc, axis=2))
            blocked = np.any(inside & ~at_corner, axis=1)
            ok = cand[~blocked]
        else:
            ok = cand
        if ok.size:
            pa, pb, pc = a[ok], b[ok], c[ok]
            angles = np.stack([_angle(pa, pb, pc), _angle(pb, pc, pa), _angle(pc, pa, pb)], axis=1)
            smallest = angles.min(axis=1)
            pick = int(ok[np.argmax(smallest >= smallest.max() - tol.ear_angle)])
        else:
            # No clean ear (numerically degenerate or self-touching input): clip the most convex
            # corner so the loop always ends; a zero-area triangle is dropped below.
            pick = int(np.argmax(cross))
        n = len(remaining)
        triangles.append((remaining[(pick - 1) % n], remaining[pick], remaining[(pick + 1) % n]))
        del remaining[pick]
    triangles.append(tuple(remaining))
    tris = np.array(triangles, dtype=np.int64)
    t2 = xy[tris]
    area2 = ((t2[:, 1, 0] - t2[:, 0, 0]) * (t2[:, 2, 1] - t2[:, 0, 1])
             - (t2[:, 1, 1] - t2[:, 0, 1]) * (t2[:, 2, 0] - t2[:, 0, 0]))
    return tris[area2 > tiny]


def _angle(a, b, c):
    """Angle at a of the 2-D triangles (a, b, c); arrays (n, 2)."""
    e1, e2 = b - a, c - a
    cos = np.sum(e1 * e2, axis=1) / np.maximum(np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1),
                                              np.finfo(float).tiny)
    return np.arccos(np.clip(cos, -1.0, 1.0))


def pairs_by_key(keys):
    """All ordered pairs (i, j) of positions whose keys are equal, i == j included.

    Vectorised join for small groups (corners at a vertex, patches at a point): the output has
    sum over groups of size^2 pairs.

    Parameters
    ----------
    keys : (n,) int
        Group key of each position.

    Returns
    -------
    i, j : (m,) int64
        Positions into ``keys``, grouped by key.
    """
    keys = np.asarray(keys)
    if keys.ndim != 1:
        raise ValueError(f"keys must have shape (n,); got {keys.shape}")
    order = np.argsort(keys, kind="stable")
    ks = keys[order]
    start = np.flatnonzero(np.r_[True, ks[1:] != ks[:-1]]) if ks.size else np.zeros(0, np.int64)
    count = np.diff(np.r_[start, ks.size])
    deg = np.repeat(count, count)
    first = np.repeat(start, count)
    i = np.repeat(np.arange(ks.size), deg)
    j = np.repeat(first, deg) + (np.arange(deg.sum()) - np.repeat(np.cumsum(deg) - deg, deg))
    return order[i].astype(np.int64), order[j].astype(np.int64)


def spatial_order(points):
    """Indices that put ``points`` (n, 3) in Z order (batches of neighbours stay compact)."""
    if points.shape[0] < 2:
        return np.arange(points.shape[0])
    lo = points.min(axis=0)
    span = max(float(np.max(points.max(axis=0) - lo)), 1e-300)
    q = np.minimum((points - lo) / span * 1024, 1023).astype(np.int64)
    code = np.zeros(points.shape[0], dtype=np.int64)
    for bit in range(10):
        for axis in range(3):
            code |= ((q[:, axis] >> bit) & 1) << (3 * bit + axis)
    return np.argsort(code, kind="stable")


def sum_at(index, values, n):
    """``out[index[k]] += values[k]`` into zeros of length ``n`` (values (m,) or (m, d)).

    ``np.add.at``'s sum, in the same order, so bit-identical to it; ``np.bincount`` computes it
    a column at a time, 3x faster (NumPy 1.26, 300,000 rows of 3 into 100,000; the colours'
    corner groups did seven such sums per mesh level over every corner)."""
    values = np.asarray(values, dtype=np.float64)
    if values.ndim == 1:
        return np.bincount(index, weights=values, minlength=n)
    out = np.empty((n, values.shape[1]))
    for d in range(values.shape[1]):
        out[:, d] = np.bincount(index, weights=values[:, d], minlength=n)
    return out


def unique_rows(keys):
    """(first, inverse) of the distinct rows of ``keys`` (m, d), sorted as ``np.unique(keys,
    axis=0, return_index=True, return_inverse=True)`` sorts them (lexicographically, the first
    column first; equal rows by first occurrence), with the same answers: ``np.unique`` with an
    axis sorts rows as records, several times slower than a lexsort of the columns."""
    m = keys.shape[0]
    if m == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    order = np.lexsort(keys.T[::-1])
    s = keys[order]
    new = np.empty(m, dtype=bool)
    new[0] = True
    np.any(s[1:] != s[:-1], axis=1, out=new[1:])
    inverse = np.empty(m, dtype=np.int64)
    inverse[order] = np.cumsum(new) - 1
    return order[new].astype(np.int64), inverse


def box_pairs(lo_a, hi_a, lo_b, hi_b, cell):
    """Pairs (i, j) of boxes a_i, b_j (any dimension) that overlap, found through a uniform grid.

    Each box is entered in the cells of side ``cell`` it covers; pairs sharing a cell are
    candidates, kept once, and checked for overlap. Cost ~ the number of (box, cell) entries,
    not len(a) x len(b).
    """
    if lo_a.shape[0] == 0 or lo_b.shape[0] == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    origin = np.minimum(lo_a.min(axis=0), lo_b.min(axis=0))
    dim = lo_a.shape[1]

    def cells(lo, hi):
        c0 = np.floor((lo - origin) / cell).astype(np.int64)
        c1 = np.floor((hi - origin) / cell).astype(np.int64)
        extent = c1 - c0 + 1
        owner, local, _ = ragged(np.prod(extent, axis=1))
        key = np.zeros(owner.size, dtype=np.int64)
        rest = local
        for axis in range(dim - 1, -1, -1):
            e = extent[owner, axis]
            key = key + (c0[owner, axis] + rest % e) * (np.int64(1) << (21 * axis))
            rest = rest // e
        return owner, key

    oa, ka = cells(lo_a, hi_a)
    ob, kb = cells(lo_b, hi_b)
    order = np.argsort(ka, kind="stable")
    ka, oa = ka[order], oa[order]
    first = np.searchsorted(ka, kb, side="left")
    count = np.searchsorted(ka, kb, side="right") - first
    jb, local, _ = ragged(count)
    ia = oa[first[jb] + local]
    jb = ob[jb]
    key = np.unique(ia * np.int64(lo_b.shape[0]) + jb)
    ia, jb = key // lo_b.shape[0], key % lo_b.shape[0]
    ok = np.all((lo_a[ia] <= hi_b[jb]) & (hi_a[ia] >= lo_b[jb]), axis=1)
    return ia[ok], jb[ok]
