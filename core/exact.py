"""Exact (contour-integral) form factors, with ray-cast visibility, and the hemicube hybrid.

The unoccluded form factor from a differential area at x (unit normal n) to a polygon is Lambert's
contour formula (Baum, Rushmeier & Winget 1989)::

    F = 1/(2 pi) | sum_k  beta_k cos(gamma_k) |
      = 1/(2 pi) | sum_k  angle(r_k, r_k+1) * n . (r_k x r_k+1) / |r_k x r_k+1| |,   r_k = c_k - x

after the polygon is clipped to the half-space above x's tangent plane. The absolute value makes
the result independent of the polygon's winding: the form factor from a differential area to a
polygon does not depend on which way the polygon faces. Which *side* of the polygon is seen is
decided separately: x is in front of patch q when (x - centre_q) . n_q > 0 -> node q, else q + P.

:func:`exact_rows` multiplies that form factor by a visible fraction estimated with rays (weighted
by the point-to-area kernel, so that the fraction is a fraction of the form factor, not of the
area). With ``source_order = 1`` the source is its centre point, like a hemicube; a higher order
averages the contour formula over Gauss-Legendre points on the source patch, which removes the
point-source error of near pairs (opposed unit squares one unit apart: +19.8% from the centre,
1e-11 with 8 x 8 source points); "adaptive" raises the order per pair until it converges.
:func:`hybrid_rows` uses that for near pairs only and the hemicube elsewhere.

Cost (bench/bench_exact.py, one core, room_with_boxes(2000), 1966 patches): the contour formula
1.3 us per (point, polygon) pair; a visibility ray ~20 us (BVH traversal dominates);
exact_rows with rays = 16 ~200 us per (source, target) pair overall (60% of the pairs need rays),
i.e. ~50x a R = 64 hemicube row; source_order="adaptive" adds ~60% on a room.
"""

import numpy as np

from .constants import tol
from .hemicube import hemicube_rows
from .raycast import BVH, build_bvh, closest_hit
from .settings import BY_NAME
from .validate import check_bool, check_sources, is_int, is_real


#: Hybrid default: a pair is "near" when its centre distance is below NEAR_DEFAULT times the larger
#: patch size (sqrt of area); the bake's ``near`` setting (core.settings), one default for both.
#: Measured by bench/bench_exact.py (near sweep): the point-source (centre) error of opposed unit
#: squares is +19.8% at distance = 1 size, +7.1% at 2, +3.4% at 3, +2.0% at 4, +1.3% at 5 (about
#: 0.3 / k^2), whatever the hemicube resolution; on room_with_boxes(2000) near = 4 costs 1.5x the
#: plain hemicube (near = 6: 2.5x). Bakes have always used 1.5 (the adjacent and nearest pairs,
#: where the error is largest), so that is the default.
NEAR_DEFAULT = BY_NAME["near"].default

#: Source quadrature of the hybrid's near pairs: Gauss-Legendre n x n points on the source patch,
#: n rising through ADAPTIVE_ORDERS until two successive orders agree to ADAPTIVE_TOL (relative).
#: The order needed grows with source size / gap: opposed unit squares at gap = size settle at
#: n = 8 (error 1e-11), adjacent unit squares too; a 0.67 m ceiling patch over a luminaire 5 cm
#: below it (room_with_boxes) needs n = 24 for 6e-5 (n = 3: -36%, n = 8: -1.2%, n = 16: 8e-4).
#: Successive orders error ratio is >= 10 once converging, so agreement to 1e-3 means ~1e-4.
ADAPTIVE_ORDERS = (4, 8, 16, 32)
ADAPTIVE_TOL = 1e-3


#: (source, target) pairs handled at once; bounds the pair arrays to a few tens of MB.
PAIR_CHUNK = 4096


def _clip_halfspace(r, h):
    """Sutherland-Hodgman clip of padded polygons to h >= 0.

    Parameters
    ----------
    r : (M, K, 3) float64
        Polygon corners.
    h : (M, K) float64
        Signed height of each corner above the clipping plane.

    Returns
    -------
    poly : (M, L, 3) float64
        Clipped polygons, L = the largest corner count over M (<= K + 1 for convex input); a
        polygon with fewer corners repeats its last one (degenerate edges, which add nothing).
    count : (M,) int64
        Corners of each clipped polygon (0 if it lies wholly below).
    """
    m, k = h.shape
    inside = h >= 0.0
    b = np.roll(r, -1, axis=1)
    hb = np.roll(h, -1, axis=1)
    inside_b = np.roll(inside, -1, axis=1)
    crosses = inside != inside_b
    with np.errstate(invalid="ignore", divide="ignore"):
        s = np.where(crosses, h / np.where(crosses, h - hb, 1.0), 0.0)
    hit = r + (b - r) * s[..., None]
    # Each edge emits its start corner (if inside) then its crossing point (if any).
    slots = np.stack([r, hit], axis=2).reshape(m, 2 * k, 3)
    valid = np.stack([inside, crosses], axis=2).reshape(m, 2 * k)
    count = valid.sum(axis=1)
    length = max(int(count.max()), 1)
    order = np.argsort(~valid, axis=1, kind="stable")[:, :length]
    pos = np.minimum(np.arange(length), np.maximum(count - 1, 0)[:, None])
    idx = np.take_along_axis(order, pos, axis=1)
    return np.take_along_axis(slots, idx[..., None], axis=1), count


def pair_form_factor(x, n, polys):
    """Contour form factor for paired points and polygons.

    x : (M, 3) points; n : (M, 3) unit normals; polys : (M, K, 3). Returns (M,) float64.
    """
    r = polys - x[:, None, :]
    h = np.einsum("mkj,mj->mk", r, n)
    reach = np.sqrt(np.einsum("mkj,mkj->mk", r, r)).max(axis=1)
    above = h.max(axis=1) > tol.coplanar * reach
    # A point in the polygon's own plane sees it edge-on: F = 0. (On its boundary the contour
    # sum would otherwise give a partial winding angle, e.g. 0.088 at a wall's corner.)
    area_vec = np.cross(r, np.roll(r, -1, axis=1)).sum(axis=1)        # Newell: 2 x area x normal
    edge_on = np.abs(np.einsum("mj,mj->m", area_vec, r.mean(axis=1))) <= \
        tol.coplanar * reach * np.sqrt(np.einsum("mj,mj->m", area_vec, area_vec))
    poly, count = _clip_halfspace(r, h)
    a, b = poly, np.roll(poly, -1, axis=1)
    c = np.cross(a, b)
    cn = np.sqrt(np.einsum("mkj,mkj->mk", c, c))
    dot = np.einsum("mkj,mkj->mk", a, b)
    angle = np.arctan2(cn, dot)
    # angle / |c| -> 1 / dot as the edge shrinks to nothing (degenerate or padding edges).
    g = np.divide(angle, cn, out=np.zeros_like(cn), where=cn > 0.0)
    g = np.where(cn > 0.0, g, np.divide(1.0, dot, out=np.zeros_like(dot), where=dot > 0.0))
    total = np.einsum("mkj,mj->mk", c, n) * g
    f = np.abs(total.sum(axis=1)) / (2.0 * np.pi)
    return np.where(above & ~edge_on & (count >= 3), f, 0.0)


def as_points(name, value):
    """``value`` as a float64 (S, 3) array; ValueError naming ``name`` otherwise."""
    a = np.asarray(value, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"{name} must have shape (S, 3); got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be finite; got NaN or inf")
    return a


def point_polygon_form_factor(points, normals, polygons):
    """Unoccluded form factor from differential areas to polygons (contour integral).

    Parameters
    ----------
    points : (S, 3) array_like of float
        Positions of the differential areas.
    normals : (S, 3) array_like of float
        Their normals (normalised here; must be non-zero).
    polygons : (Q, K, 3) array_like of float
        Planar polygons, K >= 3 corners, either winding; repeat a corner to pad a smaller polygon.

    Returns
    -------
    (S, Q) float64
        F >= 0, the part of each polygon above each point's tangent plane; 0 for a polygon in
        (or under) the tangent plane. Visibility is not considered.
    """
    x = as_points("points", points)
    n = as_points("normals", normals)
    if n.shape != x.shape:
        raise ValueError(f"normals must have shape {x.shape} like points; got {n.shape}")
    nn = np.linalg.norm(n, axis=1)
    if np.any(nn == 0.0):
        raise ValueError(f"normals must be non-zero; row {int(np.flatnonzero(nn == 0)[0])} is zero")
    n = n / nn[:, None]
    polys = np.asarray(polygons, dtype=np.float64)
    if polys.ndim != 3 or polys.shape[2] != 3 or polys.shape[1] < 3:
        raise ValueError(f"polygons must have shape (Q, K, 3) with K >= 3; got {polys.shape}")
    if not np.all(np.isfinite(polys)):
        raise ValueError("polygons must be finite; got NaN or inf")
    s_count, q_count = x.shape[0], polys.shape[0]
    out = np.zeros((s_count, q_count))
    if s_count == 0 or q_count == 0:
        return out
    rows = max(1, PAIR_CHUNK // q_count)
    for a in range(0, s_count, rows):
        b = min(a + rows, s_count)
        i = np.repeat(np.arange(a, b), q_count)
        q = np.tile(np.arange(q_count), b - a)
        out[a:b] = pair_form_factor(x[i], n[i], polys[q]).reshape(b - a, q_count)
    return out


def ray_triangles(patches):
    """Triangles that :func:`exact_rows` casts rays against.

    Parameters
    ----------
    patches : Patches

    Returns
    -------
    tris : (2P, 3, 3) float64
        Patch p is split into (c0, c1, c2) = triangle 2p and (c0, c2, c3) = triangle 2p + 1 (zero
        area for a triangular patch, never hit).
    tri_patch : (2P,) int64
    """
    c = np.asarray(patches.corners, dtype=np.float64)
    tris = np.stack([c[:, [0, 1, 2]], c[:, [0, 2, 3]]], axis=1).reshape(-1, 3, 3)
    return tris, np.repeat(np.arange(c.shape[0]), 2)


def bilinear(corners, u, v):
    """Points and area Jacobians of the bilinear map of quads at (u, v).

    corners : (M, 4, 3); u, v : (M, R). Returns points (M, R, 3) and jacobian (M, R).
    """
    c0, c1, c2, c3 = (corners[:, None, i] for i in range(4))
    uu, vv = u[..., None], v[..., None]
    p = (1 - uu) * (1 - vv) * c0 + uu * (1 - vv) * c1 + uu * vv * c2 + (1 - uu) * vv * c3
    du = (1 - vv) * (c1 - c0) + vv * (c2 - c3)
    dv = (1 - uu) * (c3 - c0) + uu * (c2 - c1)
    return p, np.linalg.norm(np.cross(du, dv), axis=-1)


def stratified(rng, m, rays):
    """Jittered nx x ny strata in the unit square for m pairs: u, v of shape (m, rays)."""
    nx = max(d for d in range(1, int(np.sqrt(rays)) + 1) if rays % d == 0)
    ny = rays // nx
    cell = np.arange(rays)
    j = rng.random((m, rays, 2))
    return (cell % nx + j[..., 0]) / nx, (cell // nx + j[..., 1]) / ny


def gauss_square(order):
    """Gauss-Legendre nodes and weights on [0, 1]^2: u, v, w of shape (order^2,), sum w = 1."""
    g, w = np.polynomial.legendre.leggauss(order)
    g, w = (g + 1) / 2, w / 2
    return np.repeat(g, order), np.tile(g, order), np.outer(w, w).ravel()


class RayGeometry:
    """Patch arrays validated once, plus the ray-casting set-up."""

    def __init__(self, patches, bvh):
        for attr in ("corners", "centres", "normals", "areas"):
            if not hasattr(patches, attr):
                raise TypeError(f"patches must be a Patches (needs .{attr}); "
                                f"got {type(patches).__name__}")
        self.corners = np.asarray(patches.corners, dtype=np.float64)
        if self.corners.ndim != 3 or self.corners.shape[1:] != (4, 3) or self.corners.shape[0] == 0:
            raise ValueError(f"patches.corners must have shape (P, 4, 3), P >= 1; "
                             f"got {self.corners.shape}")
        p = self.corners.shape[0]
        self.centres = np.asarray(patches.centres, dtype=np.float64)
        self.normals = np.asarray(patches.normals, dtype=np.float64)
        self.areas = np.asarray(patches.areas, dtype=np.float64)
        if self.centres.shape != (p, 3) or self.normals.shape != (p, 3) or self.areas.shape != (p,):
            raise ValueError(f"patches.centres/normals/areas must have shapes ({p}, 3)/({p}, 3)/"
                             f"({p},); got {self.centres.shape}/{self.normals.shape}/"
                             f"{self.areas.shape}")
        self.n_patches = p
        tris, self.tri_patch = ray_triangles(patches)
        if bvh is None:
            bvh = build_bvh(tris)
        elif not isinstance(bvh, BVH):
            raise TypeError(f"bvh must be a BVH or None; got {type(bvh).__name__}")
        elif bvh.n_triangles != tris.shape[0] or not _same_triangles(bvh, tris):
            # Same count is not enough: another split of the patches would map hits to the wrong
            # patches silently.
            raise ValueError(f"bvh must be built over ray_triangles(patches) ({tris.shape[0]} "
                             f"triangles); got one over {bvh.n_triangles} other triangles")
        self.bvh = bvh
        lo, hi = self.corners.min(axis=(0, 1)), self.corners.max(axis=(0, 1))
        self.offset = tol.surface_offset * max(float(np.linalg.norm(hi - lo)), 1e-300)

    def node_frames(self, nodes):
        patch = nodes % self.n_patches
        side = np.where(nodes < self.n_patches, 1.0, -1.0)
        return patch, self.normals[patch] * side[:, None]


def _same_triangles(bvh, tris):
    t = tris[bvh.order]
    return (np.array_equal(bvh.v0, t[:, 0]) and np.array_equal(bvh.e1, t[:, 1] - t[:, 0])
            and np.array_equal(bvh.e2, t[:, 2] - t[:, 0]))


def check_common(rays, rng):
    """Validated (rays, rng) of the ray-traced methods: rng None -> a generator seeded with 0."""
    if not is_int(rays) or rays < 1:
        raise ValueError(f"rays must be an integer >= 1; got {rays!r}")
    if rng is None:
        rng = np.random.default_rng(0)
    elif not isinstance(rng, np.random.Generator):
        raise TypeError(f"rng must be a numpy.random.Generator or None; got {type(rng).__name__}")
    return int(rays), rng


def _source_average(geo, patch, n, targets, order):
    """Unoccluded form factor of pairs, averaged over order x order Gauss points of the source.

    Returns (front (M,), back (M,)): each source point's value goes to the side of the target it
    is on. Chunked so that pairs x points stays bounded.
    """
    m = patch.size
    front, back = np.zeros(m), np.zeros(m)
    if order == 1:
        gu = gv = np.array([0.5])
        gw = np.array([1.0])
    else:
        gu, gv, gw = gauss_square(order)
    k = gu.size
    step = max(1, PAIR_CHUNK * 8 // k)
    for a in range(0, m, step):
        pa, na, ta = patch[a:a + step], n[a:a + step], targets[a:a + step]
        mm = pa.size
        if order == 1:
            xs = geo.centres[pa][:, None, :]
            ws = np.ones((mm, 1))
        else:
            xs, jac = bilinear(geo.corners[pa], np.broadcast_to(gu, (mm, k)),
                                np.broadcast_to(gv, (mm, k)))
            ws = gw * jac
            ws = ws / ws.sum(axis=1, keepdims=True)
        xf = xs.reshape(-1, 3)
        tf = np.repeat(ta, k)
        f = pair_form_factor(xf, np.repeat(na, k, axis=0), geo.corners[tf]).reshape(mm, k)
        in_front = (np.einsum("mj,mj->m", xf - geo.centres[tf], geo.normals[tf]) > 0.0)
        in_front = in_front.reshape(mm, k)
        front[a:a + step] = (ws * f * in_front).sum(axis=1)
        back[a:a + step] = (ws * f * ~in_front).sum(axis=1)
    return front, back


def _adaptive_average(geo, patch, n, targets):
    """:func:`_source_average` at rising orders until two successive orders agree."""
    front, back = _source_average(geo, patch, n, targets, ADAPTIVE_ORDERS[0])
    todo = np.arange(patch.size)
    for order in ADAPTIVE_ORDERS[1:]:
        f2, b2 = _source_average(geo, patch[todo], n[todo], targets[todo], order)
        settled = np.abs((f2 + b2) - (front[todo] + back[todo])) <= ADAPTIVE_TOL * (f2 + b2)
        front[todo], back[todo] = f2, b2
        todo = todo[~settled]
        if not todo.size:
            break
    return front, back


def _pair_values(geo, nodes, targets, rays, rng, order):
    """Exact form factors of (source node, target patch) pairs: (front (M,), back (M,)).

    ``front`` goes to column target, ``back`` to column target + P. ``order`` is the source
    quadrature: 1 (centre), n (n x n Gauss points) or "adaptive".
    """
    patch, n = geo.node_frames(nodes)
    front, back = np.zeros(nodes.size), np.zeros(nodes.size)
    # A target wholly in or under the source's plane is invisible from every source point.
    h = np.einsum("mkj,mj->mk", geo.corners[targets] - geo.centres[patch][:, None, :], n)
    reach = np.abs(geo.corners[targets] - geo.centres[patch][:, None, :]).max(axis=(1, 2))
    live = np.flatnonzero(h.max(axis=1) > tol.coplanar * reach)
    if order == "adaptive":
        f, b = _adaptive_average(geo, patch[live], n[live], targets[live])
    else:
        f, b = _source_average(geo, patch[live], n[live], targets[live], order)
    front[live], back[live] = f, b

    need = np.flatnonzero((front + back) > 0.0)
    step = max(1, PAIR_CHUNK * 4 // rays)          # bounds the (pairs, rays, 3) ray arrays
    for a in range(0, need.size, step):
        sel = need[a:a + step]
        vis = _visible_fraction(geo, patch[sel], n[sel], targets[sel], rays, rng, order != 1)
        front[sel] *= vis
        back[sel] *= vis
    return front, back


def _visible_fraction(geo, src, n, tgt, rays, rng, area_source):
    """Kernel-weighted fraction of ``rays`` rays from the source to the target that arrive."""
    m = src.size
    if area_source:
        su, sv = stratified(rng, m, rays)
        xs, _ = bilinear(geo.corners[src], su, sv)
    else:
        xs = np.broadcast_to(geo.centres[src][:, None, :], (m, rays, 3))
    tu, tv = stratified(rng, m, rays)
    y, jac = bilinear(geo.corners[tgt], tu, tv)
    origin = xs + geo.offset * n[:, None, :]
    d = y - origin
    dist2 = np.einsum("mrj,mrj->mr", d, d)
    cos_s = np.maximum(np.einsum("mrj,mj->mr", d, n), 0.0)
    cos_t = np.abs(np.einsum("mrj,mj->mr", d, geo.normals[tgt]))
    with np.errstate(invalid="ignore", divide="ignore"):
        w = np.where(dist2 > 0.0, jac * cos_s * cos_t / (dist2 * dist2), 0.0)
    # Pairs whose kernel vanishes at every sample (a sliver above the horizon) fall back to area.
    flat = w.sum(axis=1) <= 0.0
    w[flat] = jac[flat]
    t, tri = closest_hit(geo.bvh, origin.reshape(-1, 3), d.reshape(-1, 3), 1.0 + tol.visibility)
    tri = tri.reshape(m, rays)
    hit_patch = np.where(tri >= 0, geo.tri_patch[np.maximum(tri, 0)], -1)
    clear = (tri < 0) | (hit_patch == tgt[:, None]) | (t.reshape(m, rays) >= 1.0 - tol.visibility)
    total = w.sum(axis=1)
    return np.divide((w * clear).sum(axis=1), total, out=np.ones(m), where=total > 0.0)


def exact_rows(patches, sources, *, rays=16, rng=None, bvh=None, source_order=1):
    """Form-factor rows by the contour formula times ray-cast visibility.

    Parameters
    ----------
    patches : Patches
        Uses ``corners (P, 4, 3)``, ``centres (P, 3)``, ``normals (P, 3)``, ``areas (P,)``.
    sources : (S,) array_like of int
        Node ids: p (front of patch p) or p + P (its back: same centre, normal flipped).
    rays : int, optional
        Visibility rays per (source, target) pair with a non-zero unoccluded form factor, to
        jittered stratified points on the target.
    rng : numpy.random.Generator or None
        Jitter of the ray targets; None uses a generator seeded with 0 (reproducible).
    bvh : BVH or None
        ``build_bvh(ray_triangles(patches)[0])``, to share between calls; built if None.
    source_order : int or "adaptive", optional
        1: the source is its centre point (the hemicube's assumption). n > 1: the contour formula
        is averaged over n x n Gauss-Legendre points of the source patch, and rays start from
        stratified points on it (area-to-area form factor). "adaptive": n rises through
        :data:`ADAPTIVE_ORDERS` per pair until two orders agree to :data:`ADAPTIVE_TOL`.

    Returns
    -------
    (S, 2P) float64
        Row i: fraction of what leaves node ``sources[i]`` that lands on each node; column q when
        q is hit from its front, q + P from its back. A source never sees its own patch.
    """
    geo = RayGeometry(patches, bvh)
    p = geo.n_patches
    nodes = check_sources(sources, 2 * p)
    rays, rng = check_common(rays, rng)
    order = _check_order(source_order)
    out = np.zeros((nodes.size, 2 * p))
    rows = max(1, PAIR_CHUNK // p)
    for a in range(0, nodes.size, rows):
        b = min(a + rows, nodes.size)
        i = np.repeat(np.arange(a, b), p)
        q = np.tile(np.arange(p), b - a)
        keep = (nodes[i] % p) != q
        i, q = i[keep], q[keep]
        front, back = _pair_values(geo, nodes[i], q, rays, rng, order)
        out[i, q] = front
        out[i, q + p] = back
    return out


def _check_order(order):
    if isinstance(order, str) and order == "adaptive":
        return order
    if not is_int(order) or order < 1:
        raise ValueError(f"source_order must be an integer >= 1 or 'adaptive'; got {order!r}")
    return int(order)


def near_pairs(patches, sources, near):
    """(row, target patch) pairs closer than ``near`` x the larger patch size.

    Parameters
    ----------
    patches : Patches
    sources : (S,) int node ids
    near : float

    Returns
    -------
    rows, targets : (M,) int64
        Indices into ``sources`` and target patches, excluding a source's own patch.
    """
    centres = np.asarray(patches.centres, dtype=np.float64)
    size = np.sqrt(np.asarray(patches.areas, dtype=np.float64))
    p = centres.shape[0]
    src = np.asarray(sources, dtype=np.int64) % p
    rows_out, tgt_out = [], []
    chunk = max(1, PAIR_CHUNK * 4 // p)
    for a in range(0, src.size, chunk):
        s = src[a:a + chunk]
        dist = np.linalg.norm(centres[s][:, None, :] - centres[None, :, :], axis=2)
        lim = near * np.maximum(size[s][:, None], size[None, :])
        close = dist < lim
        close[np.arange(s.size), s] = False
        r, t = np.nonzero(close)
        rows_out.append(r + a)
        tgt_out.append(t)
    return np.concatenate(rows_out), np.concatenate(tgt_out)


def hybrid_rows(patches, sources, *, resolution=64, near=NEAR_DEFAULT, rays=16, rng=None,
                bvh=None, rotate=False, source_order="adaptive", conserve=True):
    """Hemicube rows with near pairs replaced by the exact area-averaged form factor.

    The hemicube treats the source as a point at its centre; for a pair closer than a few patch
    sizes that errs by tens of % whatever the resolution (opposed squares at gap = size: +19.8%).
    Near pairs are recomputed by :func:`exact_rows`' method with the contour formula averaged
    over the source patch (adaptive Gauss-Legendre) and ray-cast visibility.

    Parameters
    ----------
    patches : Patches
    sources : (S,) array_like of int
        Node ids (p or p + P).
    resolution : int
        Hemicube resolution R (passed to :func:`core.hemicube.hemicube_rows`).
    near : float
        A (source, target) pair is near when the distance between centres is below ``near`` times
        the larger of the two patch sizes (sqrt of area): there the hemicube's point source errs by
        more than about 2% (see :data:`NEAR_DEFAULT`). 0 gives the plain hemicube.
    rays, rng, bvh, source_order
        As in :func:`exact_rows`, for the near pairs; ``rng`` also drives the hemicube rotation.
    rotate : bool
        Random hemicube rotation per source (passed on).
    conserve : bool
        Rescale each row's far (hemicube) entries so that the row keeps the hemicube's row sum
        (1 minus the escaped fraction). Without it, exact near values next to point-source far
        values break the sum rule: a ceiling patch over a luminaire 5 cm below sees the floor
        past the luminaire from its centre, though the luminaire shadows most of its area (row
        sum 1.13 in room_with_boxes(300)), and a row sum above 1 lets the solver create energy.

    Returns
    -------
    (S, 2P) float64
        Both columns (q and q + P) of every near pair come from the exact method.
    """
    geo = RayGeometry(patches, bvh)
    p = geo.n_patches
    nodes = check_sources(sources, 2 * p)
    rays, rng = check_common(rays, rng)
    order = _check_order(source_order)
    if not is_real(near) or near < 0:
        raise ValueError(f"near must be a finite number >= 0; got {near!r}")
    check_bool("conserve", conserve)
    rows = np.array(hemicube_rows(patches, nodes, resolution=resolution, rotate=rotate, rng=rng),
                    dtype=np.float64)
    hemi_total = rows.sum(axis=1)
    r, q = near_pairs(patches, nodes, float(near))
    is_near = np.zeros(rows.shape, dtype=bool)
    is_near[r, q] = is_near[r, q + p] = True
    for a in range(0, r.size, PAIR_CHUNK):
        b = a + PAIR_CHUNK
        front, back = _pair_values(geo, nodes[r[a:b]], q[a:b], rays, rng, order)
        rows[r[a:b], q[a:b]] = front
        rows[r[a:b], q[a:b] + p] = back
    if conserve:
        near_sum = np.where(is_near, rows, 0.0).sum(axis=1)
        far_sum = np.where(is_near, 0.0, rows).sum(axis=1)
        scale = np.divide(np.maximum(hemi_total - near_sum, 0.0), far_sum,
                          out=np.ones_like(far_sum), where=far_sum > 0.0)
        rows = np.where(is_near, rows, rows * scale[:, None])
    return rows
