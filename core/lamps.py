"""Lamps of many faces lit exactly: a bulb modelled as a sphere, a luminaire as a box, a panel
meshed into a grid (issue 11, class 1).

A lamp is the faces of one emissive material that share vertices (:func:`lamp_labels`), facing
any way. :class:`core.emitters.Emitters` lights a lamp of one face as its own light; a lamp of
many faces is *one* light (:class:`Lamp`): its unshadowed light at a point is its faces' sum
(each counted where its emitting side faces the point), and one visible fraction, from shadow
rays to points on the whole lamp, scales that sum. A 512-face UV sphere lit face by face cast
the penumbra's rounds 512 times per point (153 s for a floor's 1,059 vertices, 149 s of it
shadow rays; ``bench/bench_bulb.py``), and its faces were over the cap (``MAX_FACES``), so the
hemicube took it: a 5 cm bulb at 2.5 m covers 1 to 2 pixels and read 33 % off.

Samples on the faces that turn away from the point weigh 0 (the kernel's ``cos_y``), and their
rays are not cast: seen from outside, a convex lamp never hides itself, a concave one (a ring)
does, as the shadow rays then find. The ray that says whether the lamp's centre is seen (the
lights' centre bits, :mod:`core.criteria`) aims at the anchor of the face that gives the point
most light, and the rim's probes are the faces farthest out along the eight diagonals, each cast
only where that face turns to the point.

Far from a face (:data:`FAR` times its diameter) the contour integral gives way to the
point-to-small-area kernel ``A cos_x cos_y / (pi r^2)``: within 0.1 % of it there summed
over directions (``tests/core/test_lamps.py``), and a sphere's 512 faces cost a floor's points 512 kernels each,
not 512 contour integrals (42 ns a pair against 1.6 us: 1,024k pairs, one run, a /tmp script
over :func:`form_factors` with FAR set past every pair).
"""

import numpy as np

from .exact import bilinear, pair_form_factor
from .geometry import patch_extents, ragged, unit_frames
from .patches import connected_labels
from .transfer import padded_polygons

#: A face farther than this many times its diameter from a point lights it by the
#: point-to-small-area kernel instead of the contour integral. Measured over points in every
#: direction 1 to 3 FAR away, random tilts, a square and a 1 x 3 sliver triangle: 0.03 % of
#: their summed light; at one point at most 0.4 % of the face-on light at that distance (near
#: the point's horizon; tests/core/test_lamps.py).
FAR = 16.0

#: (point, face) pairs per vectorised block.
BLOCK = 1 << 16

#: Generator of the rank-1 (R3) lattice: the powers of the root of x^4 = x + 1 (Roberts 2018).
#: Two coordinates place a sample in its patch, the third picks the patch (by area). With one
#: coordinate doing both (the patch from u's interval, u rescaled in it), a lamp of 2 patches
#: had every sample's u in one of two narrow bands (frac(2 alpha) is near 1/2): floor points
#: seeing a quarter of the Cornell box's lamp read 0.26 +- 0.11 of it with 24 rays.
_ROOT = 1.2207440846057596
_ALPHA = 1.0 / _ROOT ** np.arange(1, 4)


def lamp_labels(scene, faces):
    """(len(faces),) int64: the lamp of each of ``faces`` (scene face indices), numbered 0, 1, ...
    in the order of each lamp's first face: faces of one material that share a vertex (by
    position: :func:`_welded`), any facing, are one lamp."""
    faces = np.asarray(faces, dtype=np.int64)
    if faces.size < 2:
        return np.zeros(faces.size, dtype=np.int64)
    owner, local, _ = ragged(scene.face_sizes[faces])
    verts = _welded(scene, np.asarray(scene.corner_verts, dtype=np.int64)[
        scene.face_starts[faces][owner] + local])
    order = np.lexsort((owner, verts))
    v, f = verts[order], owner[order]
    mat = np.asarray(scene.face_materials)[faces]
    same = (v[1:] == v[:-1]) & (f[1:] != f[:-1]) & (mat[f[1:]] == mat[f[:-1]])
    label = connected_labels(faces.size, f[:-1][same], f[1:][same])
    first = np.unique(label, return_index=True)[1]          # labels are each lamp's least face
    return np.searchsorted(label[np.sort(first)], label)


def _welded(scene, verts):
    """``verts`` (scene vertex indices) renumbered so that vertices at one position share a
    number: an STL or OBJ import, or a mesh never merged, gives every face its own corners (a
    UV sphere bulb as 512 loose faces is still one lamp)."""
    pos = np.asarray(scene.vertices, dtype=np.float64)[verts]
    return np.unique(pos, axis=0, return_inverse=True)[1].reshape(-1)


def centroids(polys):
    """(f, 3): the area centroid of each padded planar polygon (f, k, 3) (a triangle fan; a
    repeated corner adds a triangle of no area). Degenerate ones: the corners' mean."""
    a, b, c = polys[:, :1], polys[:, 1:-1], polys[:, 2:]
    cross = np.cross(b - a, c - a)
    n = cross.sum(axis=1)
    w = np.einsum("ftj,fj->ft", cross, n)                  # 2 A_t |n|, signed (concave fans)
    total = w.sum(axis=1)
    mid = (a + b + c) / 3.0
    ok = total > 0
    out = polys.mean(axis=1)
    out[ok] = np.einsum("ft,ftj->fj", w[ok], mid[ok]) / total[ok, None]
    return out


def form_factors(points, normals, polys, centre, normal, area, keep):
    """(m, f) unoccluded form factors from points (unit ``normals``) to planar faces: the contour
    integral (:func:`core.exact.pair_form_factor`) within :data:`FAR` diameters of a face's
    ``centre`` (its area centroid), ``area cos_x cos_y / (pi r^2)`` beyond (``cos_y`` of either
    side). Only the pairs ``keep`` (m, f) bool (the faces that emit towards the point: a bulb's
    own faces see none of its other faces' light); 0 elsewhere."""
    m, f = points.shape[0], polys.shape[0]
    out = np.zeros((m, f))
    if m == 0 or f == 0:
        return out
    normals = normals / np.linalg.norm(normals, axis=1)[:, None]
    reach2 = (2.0 * FAR * np.linalg.norm(polys - centre[:, None], axis=2).max(axis=1)) ** 2
    step = max(1, BLOCK // f)
    for s in range(0, m, step):
        x, n = points[s:s + step], normals[s:s + step]
        d = centre[None] - x[:, None]                                      # (r, f, 3)
        r2 = np.einsum("rfj,rfj->rf", d, d)
        far = r2 > reach2[None]
        cos_x = np.maximum(np.einsum("rfj,rj->rf", d, n), 0.0)
        cos_y = np.abs(np.einsum("rfj,fj->rf", d, normal))
        want = keep[s:s + step]
        block = np.where(far & want, area[None] * cos_x * cos_y
                         / (np.pi * np.maximum(r2, 1e-300) ** 2), 0.0)
        i, q = np.nonzero(~far & want)
        # A face wholly under a point's horizon gives it nothing (a bulb's inside, seen from
        # its faces' fronts): no contour integral.
        up = np.einsum("pkj,pj->pk", polys[q] - x[i][:, None], n[i]).max(axis=1) > 0
        i, q = i[up], q[up]
        if i.size:
            block[i, q] = pair_form_factor(x[i], n[i], polys[q])
        out[s:s + step] = block
    return out


def lamp_widths(scene, faces, labels=False):
    """(F,) float: the width (area / longest extent, m) of the lamp each face belongs to; with
    ``labels``, also (F,) int64: the lamp of each face (faces not in ``faces`` their own).

    A lamp is a sheet of ``faces`` (bool mask) of one material that share vertices (by position)
    and face the same way: a panel meshed into a grid of small faces (an imported or pre-meshed luminaire)
    is one 0.6 m lamp, as wide to the hemicube as the same panel modelled as one quad, not
    sixteen 0.15 m ones. The lamp's extent is the longest side of its bounding box; faces not in
    ``faces`` keep their own width.
    """
    polys = padded_polygons(scene.vertices, scene.corner_verts, scene.face_starts,
                            scene.face_sizes)
    longest = patch_extents(polys, polys.mean(axis=1))[1]
    F = scene.face_areas.size
    width = scene.face_areas / np.maximum(longest, 1e-300)
    faces = np.asarray(faces, dtype=bool)
    if faces.sum() < 2:
        return (width, np.arange(F)) if labels else width
    face_of = np.repeat(np.arange(F), scene.face_sizes)
    verts = np.asarray(scene.corner_verts, dtype=np.int64)
    keep = faces[face_of]
    f, v = face_of[keep], _welded(scene, verts[keep])
    order = np.lexsort((f, v))
    f, v = f[order], v[order]
    same = (v[1:] == v[:-1]) & (f[1:] != f[:-1])           # consecutive faces at one vertex
    a, b = f[:-1][same], f[1:][same]
    mat = np.asarray(scene.face_materials)
    nrm = np.asarray(scene.face_normals)
    link = (mat[a] == mat[b]) & (np.einsum("ij,ij->i", nrm[a], nrm[b]) > 1.0 - 1e-6)
    label = connected_labels(F, a[link], b[link])
    pos = np.asarray(scene.vertices, dtype=np.float64)[verts]
    lo = np.full((F, 3), np.inf)
    hi = np.full((F, 3), -np.inf)
    np.minimum.at(lo, label[face_of], pos)
    np.maximum.at(hi, label[face_of], pos)
    area = np.bincount(label, weights=scene.face_areas, minlength=F)
    lamp = area / np.maximum((hi - lo).max(axis=1), 1e-300)
    multi = faces & (np.bincount(label, minlength=F)[label] > 1)
    width = np.where(multi, lamp[label], width)
    return (width, label) if labels else width


#: Rays per lamp and emitting side that :func:`lamp_reach` casts, cosine-distributed.
REACH_RAYS = 128


def lamp_reach(scene, faces, label):
    """(F,) float: for each face in ``faces`` (bool), the typical distance of the surfaces its
    lamp lights (m); the scene's largest extent elsewhere.

    From the lamp's centre (``label``: :func:`lamp_widths`' lamps), on each side it emits
    from, REACH_RAYS rays in a fixed cosine-weighted pattern (a lamp's light leaves that way)
    find the surfaces in front of it; the median hit distance is that side's, and the lamp's is
    its farthest side's (a panel's back facing the ceiling 1 cm above it does not make it wide).
    A side whose rays all escape (open to the world) lights nothing; a lamp with no side that
    does gets the scene's extent.
    """
    F = scene.face_areas.size
    extent = float(np.ptp(scene.vertices, axis=0).max()) if scene.vertices.size else 0.0
    out = np.full(F, extent)
    faces = np.flatnonzero(faces)
    if not faces.size or extent <= 0.0:
        return out
    from .conforming import _face_triangles
    from .raycast import build_bvh, closest_hit

    tri = _face_triangles(scene, np.flatnonzero(scene.face_areas > 0))[0]
    verts = np.asarray(scene.vertices, dtype=np.float64)
    bvh = build_bvh(verts[np.asarray(scene.corner_verts)[tri]])
    inverse = np.unique(label[faces], return_inverse=True)[1]
    n = int(inverse.max()) + 1
    area = scene.face_areas[faces]
    polys = padded_polygons(scene.vertices, scene.corner_verts, scene.face_starts,
                            scene.face_sizes)[faces]
    centre = np.zeros((n, 3))
    np.add.at(centre, inverse, area[:, None] * polys.mean(axis=1))
    centre /= np.bincount(inverse, weights=area, minlength=n)[:, None]
    first = np.zeros(n, dtype=np.int64)
    first[inverse[::-1]] = faces[::-1]                   # one face of each lamp
    normal = np.asarray(scene.face_normals, dtype=np.float64)[first]
    mat = scene.face_materials[first]
    k = np.arange(REACH_RAYS) + 0.5
    r, phi = np.sqrt(k / REACH_RAYS), k * np.pi * (3.0 - np.sqrt(5.0))
    local = np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(1.0 - r * r)], axis=1)
    reach = np.zeros(n)
    for sign, le in ((1.0, scene.emission), (-1.0, scene.back_materials()[1])):
        side = np.flatnonzero(np.any(np.asarray(le, dtype=np.float64)[mat] > 0, axis=1))
        if not side.size:
            continue
        z = sign * normal[side]
        x, y = unit_frames(z)
        d = (local[None, :, :1] * x[:, None] + local[None, :, 1:2] * y[:, None]
             + local[None, :, 2:] * z[:, None]).reshape(-1, 3)
        o = np.repeat(centre[side] + 1e-6 * extent * z, REACH_RAYS, axis=0)
        t, _ = closest_hit(bvh, o, d)
        t = t.reshape(side.size, REACH_RAYS)
        t = np.where(np.isfinite(t), t, np.nan)
        seen = np.isfinite(t).any(axis=1)
        reach[side[seen]] = np.maximum(reach[side[seen]], np.nanmedian(t[seen], axis=1))
    out[faces] = np.where(reach[inverse] > 0, reach[inverse], extent)
    return out




class Lamp:
    """One emitting side of a lamp of several faces, as one light of :class:`Emitters`.

    Parameters
    ----------
    sign : float
        +1: the faces' fronts emit; -1: their backs.
    corners, areas : (p, 4, 3), (p,) float
        The lamp's patches (shadow rays aim at points on them, by area).
    patch_normal : (p, 3) float
        Their faces' normals.
    anchor, centre, normal, area : (f, 3), (f, 3), (f, 3), (f,) float
        Per face: a point inside it (:class:`Emitters`' anchors), its area centroid, normal and
        area.
    """

    def __init__(self, sign, corners, areas, patch_normal, anchor, centre, normal, area):
        self.sign = float(sign)
        self.corners, self.patch_normal = corners, patch_normal
        self.cum = np.cumsum(areas)
        self.anchor, self.centre, self.normal, self.area = anchor, centre, normal, area
        mid = (area[:, None] * centre).sum(axis=0) / max(float(area.sum()), 1e-300)
        diag = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
        out = np.unique(np.argmax((centre - mid) @ diag.T, axis=0))
        self.rim, self.rim_normal = anchor[out], normal[out]

    def _toward(self, d, n_x, n_y):
        """cos_x cos_y / r^4 (r^2 times the kernel) of offsets ``d`` (..., 3) from points of
        normals ``n_x`` to points of the lamp of normals ``n_y``: 0 where the lamp's emitting
        side turns away (or the point's horizon hides it)."""
        r2 = np.einsum("...j,...j->...", d, d)
        return np.maximum(np.einsum("...j,...j->...", d, n_x), 0.0) \
            * np.maximum(-self.sign * np.einsum("...j,...j->...", d, n_y), 0.0) \
            / np.maximum(r2, 1e-300) ** 2

    def best(self, origin, normals):
        """(g,) int: the face whose light (by the kernel) is largest at each point."""
        out = np.zeros(origin.shape[0], dtype=np.int64)
        step = max(1, BLOCK // self.area.size)
        for s in range(0, origin.shape[0], step):
            d = self.centre[None] - origin[s:s + step, None]
            w = self.area[None] * self._toward(d, normals[s:s + step, None], self.normal[None])
            out[s:s + step] = np.argmax(w, axis=1)
        return out

    def samples(self, shift, index):
        """Points (g, m, 3) on the lamp and their faces' normals: lattice points ``index``
        (m,) turned by ``shift`` (g, 3), patches picked by area."""
        uvw = (0.5 + index[None, :, None] * _ALPHA[None, None, :] + shift[:, None, :]) % 1.0
        if not self.cum.size:
            return np.broadcast_to(self.anchor[0], uvw.shape[:2] + (3,)), \
                np.broadcast_to(self.normal[0], uvw.shape[:2] + (3,))
        k = np.clip(np.searchsorted(self.cum, uvw[..., 2] * self.cum[-1], side="right"), 0,
                    self.cum.size - 1)
        pts, _ = bilinear(self.corners[k.ravel()], uvw[..., 0].reshape(-1, 1),
                          uvw[..., 1].reshape(-1, 1))
        return pts.reshape(uvw.shape[:2] + (3,)), self.patch_normal[k]

    def visible(self, origin, normals, k, turn, blocked, small, first_round):
        """As :meth:`core.emitters.Emitters.visible`, for the whole lamp: the visible fraction
        (g,) of its light, kernel-weighted over the faces that turn to each point, and whether
        the ray to the anchor of the face giving it most light is clear (g,) bool."""
        g = origin.shape[0]
        centre = ~blocked(origin, self.anchor[self.best(origin, normals)] - origin)
        if k <= 1:
            return centre.astype(np.float64), centre
        shift = turn[:, None] * _ROOT ** np.arange(3)[None, :] / (2.0 * np.pi)

        def cast(rows, index):
            y, n_y = self.samples(shift[rows], index)
            d = y - origin[rows, None, :]
            w = self._toward(d, normals[rows, None, :], n_y)
            clear = np.zeros(w.shape, dtype=bool)
            i, j = np.nonzero(w > 0)                     # the rays that can carry light
            clear[i, j] = ~blocked(origin[rows[i]], d[i, j])
            return clear, w

        to = self.rim[None] - origin[:, None]                               # (g, r, 3)
        facing = self._toward(to, normals[:, None], self.rim_normal[None]) > 0
        i, j = np.nonzero(facing)
        probe = centre + np.bincount(i, weights=~blocked(origin[i], to[i, j]), minlength=g)
        probes = 1 + facing.sum(axis=1)
        # As Emitters.visible: hidden where every probe is blocked, seen whole where a lamp
        # narrower than an element has every probe clear; the others cast the rounds.
        whole = small & (probe == probes)
        frac = whole.astype(np.float64)
        seen = np.flatnonzero((probe > 0) & ~whole)
        if not seen.size:
            return frac, centre
        first, w1 = cast(seen, np.arange(first_round))
        frac[seen] = _fraction(first, w1, centre[seen])
        part = np.flatnonzero(first.sum(axis=1) + probe[seen]
                              < (w1 > 0).sum(axis=1) + probes[seen])
        if part.size:
            mixed = seen[part]
            more, w2 = cast(mixed, first_round + np.arange(k))
            frac[mixed] = _fraction(np.concatenate([first[part], more], axis=1),
                                    np.concatenate([w1[part], w2], axis=1), centre[mixed])
        return frac, centre


def _fraction(clear, w, fallback):
    """(g,) share of the weight ``w`` (g, m) on clear rays; ``fallback`` (g,) bool where no ray
    carries any (every sample on a face turned away)."""
    total = w.sum(axis=1)
    return np.where(total > 0, (clear * w).sum(axis=1) / np.where(total > 0, total, 1.0),
                    fallback.astype(np.float64))
