"""Ray-traced form factors from source patches to receiver points (Wallace et al. 1989).

The form factor from a differential area at x (unit normal n_x) to a source patch A_i is estimated
from ``rays`` jittered stratified points y_k on the source, each standing for a disc of area
a_k (their sum is A_i)::

    F(dx -> A_i) ~= sum_k  V(x, y_k) cos(theta_x) cos(theta_y) a_k / (pi r^2 + a_k)

where V is a shadow ray. a / (pi r^2 + a) is the exact form factor of a coaxial disc of area a
facing x from distance r, so each sample is bounded by 1 however near the source is, and the
estimate tends to the area integral as a_k -> 0. It fails where r^2 is comparable with a_k: a
receiver point close to the source (a ceiling just above a luminaire, the near corner of a wall
on a lit floor) sees each sample's disc at its centre's angle, not as the spread-out patch.

:func:`raytraced_point_factors` returns these point values. :func:`raytraced_rows` turns them into
rows by reciprocity: what leaves node i and lands on patch q is

    F_iq = (A_q / A_i) * sum_k w_k F(dx_k -> A_i)

over four receiver points x_k of q (:data:`RECEIVER_RULE`: Gauss points, not Wallace's vertices,
for the reason given there). A sample is counted for column q when it lies in front of q's plane
(cos theta_x > 0) and for q + P when behind, as :func:`core.exact.exact_rows` does.

Accuracy (tests/core/test_raytraced.py): far from the source the estimate is low by
A_i / (pi r^2 rays) (measured to 0.1 %); near it the discs fail (a point 0.1 sizes over a square
source: -33 % with 16 rays, -7 % with 256) and four receiver points cannot follow a steep
gradient (a patch over a luminaire 5 cm below: +45 % with 1024 rays). Cost
(bench/bench_raytraced.py, one core, room_with_boxes(500), 490 patches): 9-10 us per shadow ray,
28-30 us per (source, target patch) pair and ray setting, 0.22 s per row with 16 rays, about
2 x exact_rows (adaptive) and 200 x a R = 64 hemicube; mean L1 row error against exact_rows at
256 rays 0.047 with 16 rays (exact_rows at 16 rays: 0.010; the hemicube: 0.125).
"""

import numpy as np

from .constants import tol
from .exact import RayGeometry, as_points, bilinear, check_common, stratified
from .raycast import any_hit
from .validate import check_sources

#: (source, receiver point, sample) triples evaluated at once: bounds the (triples, 3) arrays to
#: a few MB; rays are then traced in the BVH's own chunks.
SAMPLE_CHUNK = 1 << 16

#: Receiver points of a patch and their weights, for the rows: "gauss" (2 x 2 Gauss-Legendre
#: points of the bilinear map, weighted by its Jacobian) or "corners" (Wallace's vertices, each
#: pulled by RECEIVER_INSET towards the centroid, weights exact for a function linear over the
#: quad). Both take four points per patch and cost the same, but for a row the corners are a
#: trapezoid rule, and a point value is lowest at a patch's corners: opposed unit squares 1
#: apart, one patch each, 1024 rays: corners -30.7 %, Gauss -0.75 %; perpendicular squares
#: sharing an edge: the two corners on the edge lie in the source's plane and see nothing (2 x 2
#: patches each, 256 rays: corners -53 %, Gauss -0.8 %). Vertices pay only when their values
#: are shared by the patches around them (up to 4 x fewer points), which needs a mesh this API
#: does not have and gives one value to both sides of a contact line.
RECEIVER_RULE = "gauss"

#: Receiver corners are moved this fraction of the way to the patch centroid: the point stays on
#: its own patch, so a shadow ray does not start in the plane of a wall or a box side meeting the
#: patch at that corner (its crossing at t = 0 would not count: light would leak under the wall),
#: and a patch on a contact line takes the limit from its own side. Its effect on the value is
#: of the same relative order (1e-6), far below the sampling noise.
RECEIVER_INSET = 1e-6


def receiver_points(corners, rule=None):
    """Receiver points of patches and their area weights.

    Parameters
    ----------
    corners : (P, 4, 3) float64
        Planar quads; a triangle repeats its last corner.
    rule : {"corners", "gauss"} or None
        None: :data:`RECEIVER_RULE`.

    Returns
    -------
    points : (P, 4, 3) float64
    weights : (P, 4) float64
        Non-negative, summing to 1 per patch (a triangle's repeated corner shares its weight).
    """
    rule = RECEIVER_RULE if rule is None else rule
    if rule == "gauss":
        g = (1.0 + np.array([-1.0, 1.0]) / np.sqrt(3.0)) / 2.0
        u = np.broadcast_to(np.repeat(g, 2), (corners.shape[0], 4))
        v = np.broadcast_to(np.tile(g, 2), (corners.shape[0], 4))
        pts, jac = bilinear(corners, u, v)
        total = jac.sum(axis=1, keepdims=True)
        return pts, np.divide(jac, total, out=np.full_like(jac, 0.25), where=total > 0.0)
    if rule != "corners":
        raise ValueError(f"rule must be 'corners' or 'gauss'; got {rule!r}")
    # The mean of the two splits into triangles (c0 c1 c2 + c0 c2 c3, c0 c1 c3 + c1 c2 c3), each
    # triangle's area shared by its corners: corner k gets every corner triangle but the
    # opposite one. A parallelogram gives 1/4 each, a triangle 1/3 each.
    nxt, prv = np.roll(corners, -1, axis=1), np.roll(corners, 1, axis=1)
    a = np.linalg.norm(np.cross(nxt - corners, prv - corners), axis=2)     # corner triangles
    s = a.sum(axis=1, keepdims=True)
    w = np.divide(s - np.roll(a, -2, axis=1), 3.0 * s, out=np.full_like(a, 0.25),
                  where=s > 0.0)
    centroid = corners.mean(axis=1, keepdims=True)
    return corners + RECEIVER_INSET * (centroid - corners), w


def _sample_values(geo, x, nx, src, ns, rays, rng, both):
    """Point-to-source form factors of (point, source) items, by shadow-rayed disc samples.

    x, nx : (M, 3) points and unit normals; src : (M,) source patches; ns : (M, 3) the source
    nodes' unit normals. Returns (front (M,), back (M,)): samples in front of x's tangent plane
    and behind it (back is all zero unless ``both``).
    """
    m = src.size
    su, sv = stratified(rng, m, rays)
    y, jac = bilinear(geo.corners[src], su, sv)
    jsum = jac.sum(axis=1, keepdims=True)
    area = geo.areas[src][:, None] * np.divide(jac, jsum, out=np.full_like(jac, 1.0 / rays),
                                               where=jsum > 0.0)
    d = y - x[:, None, :]
    r2 = np.einsum("mrj,mrj->mr", d, d)
    with np.errstate(invalid="ignore", divide="ignore"):
        inv_r = np.where(r2 > 0.0, 1.0 / np.sqrt(r2), 0.0)
    cos_x = np.einsum("mrj,mj->mr", d, nx) * inv_r
    cos_y = np.maximum(-np.einsum("mrj,mj->mr", d, ns) * inv_r, 0.0)
    if not both:
        cos_x = np.maximum(cos_x, 0.0)
    f = np.abs(cos_x) * cos_y * area / (np.pi * r2 + area)
    live = f > 0.0
    mi, ki = np.nonzero(live)
    if mi.size:
        side = np.sign(cos_x[mi, ki])
        origin = x[mi] + (geo.offset * side)[:, None] * nx[mi]
        blocked = any_hit(geo.bvh, origin, y[mi, ki] - origin, 1.0 - tol.visibility)
        f[mi[blocked], ki[blocked]] = 0.0
    front = np.where(cos_x > 0.0, f, 0.0).sum(axis=1)
    return front, f.sum(axis=1) - front


def _values(geo, x, nx, src, ns, rays, rng, both):
    """:func:`_sample_values` over all items, culled and in chunks of SAMPLE_CHUNK triples."""
    m = src.size
    front, back = np.zeros(m), np.zeros(m)
    # Cull: a point on or behind the source's plane, or a source in the point's plane (seen
    # edge-on from either side), receives nothing.
    above = np.einsum("mj,mj->m", x - geo.centres[src], ns)
    h = np.einsum("mkj,mj->mk", geo.corners[src] - x[:, None, :], nx)
    reach = np.abs(geo.corners[src] - x[:, None, :]).max(axis=(1, 2))
    seen = h.max(axis=1) if not both else np.abs(h).max(axis=1)
    live = np.flatnonzero((above > tol.coplanar * reach) & (seen > tol.coplanar * reach))
    step = max(1, SAMPLE_CHUNK // rays)
    for a in range(0, live.size, step):
        sel = live[a:a + step]
        front[sel], back[sel] = _sample_values(geo, x[sel], nx[sel], src[sel], ns[sel], rays,
                                               rng, both)
    return front, back


def raytraced_point_factors(points, normals, patches, sources, *, rays=16, rng=None, bvh=None):
    """Form factors from receiver points to source nodes, by ray-traced disc samples.

    Parameters
    ----------
    points : (M, 3) array_like of float
        Receiver points (a vertex should be nudged onto its own face by the caller: a shadow
        ray starting in the plane of another surface does not see it).
    normals : (M, 3) array_like of float
        Their normals (normalised here; must be non-zero); only light from in front counts.
    patches : Patches
        Uses ``corners (P, 4, 3)``, ``centres (P, 3)``, ``normals (P, 3)``, ``areas (P,)``.
    sources : (S,) array_like of int
        Source node ids: p (front of patch p) or p + P (its back).
    rays : int, optional
        Stratified samples (and shadow rays) on the source per (point, source) pair.
    rng : numpy.random.Generator or None
        Jitter of the samples; None uses a generator seeded with 0 (reproducible).
    bvh : BVH or None
        ``build_bvh(ray_triangles(patches)[0])``, to share between calls; built if None.

    Returns
    -------
    (M, S) float64
        F(dx_m -> A_i) of what leaves the point that lands on source node i, visibility
        included: the fraction of the point's view (its sum over a closed scene's front nodes
        is about 1).
    """
    geo = RayGeometry(patches, bvh)
    p = geo.n_patches
    nodes = check_sources(sources, 2 * p)
    rays, rng = check_common(rays, rng)
    x = as_points("points", points)
    n = as_points("normals", normals)
    if n.shape != x.shape:
        raise ValueError(f"normals must have shape {x.shape} like points; got {n.shape}")
    nn = np.linalg.norm(n, axis=1)
    if np.any(nn == 0.0):
        bad = int(np.flatnonzero(nn == 0)[0])
        raise ValueError(f"normals must be non-zero; row {bad} is zero")
    n = n / nn[:, None]
    m, s = x.shape[0], nodes.size
    out = np.zeros((m, s))
    if m == 0 or s == 0:
        return out
    src_patch, src_normal = geo.node_frames(nodes)
    rows = max(1, SAMPLE_CHUNK // (rays * s))
    for a in range(0, m, rows):
        b = min(a + rows, m)
        i = np.repeat(np.arange(a, b), s)
        j = np.tile(np.arange(s), b - a)
        front, _ = _values(geo, x[i], n[i], src_patch[j], src_normal[j], rays, rng, False)
        out[a:b] = front.reshape(b - a, s)
    return out


def raytraced_rows(patches, sources, *, rays=16, rng=None, bvh=None):
    """Form-factor rows from ray-traced point values at the receivers, by reciprocity.

    Parameters
    ----------
    patches : Patches
        Uses ``corners (P, 4, 3)``, ``centres (P, 3)``, ``normals (P, 3)``, ``areas (P,)``.
    sources : (S,) array_like of int
        Node ids: p (front of patch p) or p + P (its back: same centre, normal flipped).
    rays : int, optional
        Stratified samples on the source, each a shadow ray, per receiver point (four points
        per receiver patch: :data:`RECEIVER_RULE`).
    rng : numpy.random.Generator or None
        Jitter of the samples; None uses a generator seeded with 0 (reproducible).
    bvh : BVH or None
        ``build_bvh(ray_triangles(patches)[0])``, to share between calls; built if None.

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
    pts, w = receiver_points(geo.corners)
    k = pts.shape[1]
    out = np.zeros((nodes.size, 2 * p))
    src_patch, src_normal = geo.node_frames(nodes)
    rows = max(1, SAMPLE_CHUNK // (rays * k * p))
    for a in range(0, nodes.size, rows):
        b = min(a + rows, nodes.size)
        i = np.repeat(np.arange(a, b), p)
        q = np.tile(np.arange(p), b - a)
        keep = src_patch[i] != q
        i, q = np.repeat(i[keep], k), np.repeat(q[keep], k)
        c = np.tile(np.arange(k), i.size // k)
        front, back = _values(geo, pts[q, c], geo.normals[q], src_patch[i], src_normal[i],
                              rays, rng, True)
        scale = w[q, c] * geo.areas[q] / geo.areas[src_patch[i]]
        flat = (i - a) * 2 * p + q
        block = np.bincount(flat, scale * front, minlength=(b - a) * 2 * p) \
            + np.bincount(flat + p, scale * back, minlength=(b - a) * 2 * p)
        out[a:b] = block.reshape(b - a, 2 * p)
    return out
