"""Contact cuts: patches split along the lines where other surfaces touch or pierce them.

A box standing on a floor meets the floor along its outline, and the floor under it is in the
dark. A floor patch that straddles the outline carries one radiance for both of its parts, so the
bake errs twice at every contact:

* light leaks into the solid: the patch's part under the box carries the lit part's radiance, the
  box's inner (back) sides see it, and the floor vertices inside the box's footprint, which a path
  tracer reads as black, gather that light back;
* the box's foot and the floor beside it come out too dark, because they see the straddling patch
  at its mean instead of its lit part.

Users avoid this by cutting the floor along the outline themselves. This module does it for them
before the solve: the lines where one surface meets another's plane (a contact edge, or the
section of a face that pierces the plane) cut every patch they cross, exactly along the line, in
the manner of discontinuity meshing (Heckbert 1992; Lischinski, Tampieri & Greenberg 1992), but
only for the contacts, where the radiance jumps from lit to black. Shadow boundaries cast from a
distance are soft and are left to refinement and receiver elements.

A cut splits a convex quad or triangle into two convex polygons of up to five corners; a pentagon
becomes a quad and a triangle, so every patch keeps the 4-corner layout of :class:`Patches`. A
patch crossed by several lines is cut by each in turn (at most :data:`MAX_CUTS`).
"""

import numpy as np

from . import constants
from .geometry import box_pairs, inside_polygons, newell_normals_areas, ragged
from .patches import Patches, assemble_patches, material_table, triangle_mask



#: A patch is cut only if corners of it lie on both sides of the line farther than this fraction
#: of its size (sqrt of area): a line that grazes a corner would leave a sliver that changes
#: nothing but costs a hemicube.
MIN_PIECE = 0.02

#: Corners nearer a cut line than this fraction of the patch size count as on the line:
#: a crossing point computed beside such a corner could round onto it.
SNAP = 1e-9

#: A patch whose size (square root of its area) is below this fraction of its diameter has no
#: area (its corners on one line up to rounding): no line cuts it.
FLAT = 1e-6

#: Most cuts applied to one original patch (a patch under a chair leg meets 4 lines).
MAX_CUTS = 8


def _snapped(h, size):
    """Signed distances h (n, 4) of the corners from the line, 0 where they count as on it."""
    return np.where(np.abs(h) <= SNAP * size[:, None], 0.0, h)


def _unit(v):
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 0, n, 1.0)


def contact_segments(scene, faces, plane_n, plane_d, tol):
    """Segments along which faces meet planes, one (face, plane) pair per row.

    A face that is not parallel to the plane meets it along a segment when two of its corners lie
    in the plane (within ``tol``), or when it has corners on both sides (it pierces the plane:
    the segment joins the crossing points). A concave face gives the hull of its crossings.

    Parameters
    ----------
    scene : core.scene.Scene
    faces : (K,) int
        Valid faces of the scene.
    plane_n : (K, 3) float
        Unit normals of the planes.
    plane_d : (K,) float
        Offsets: plane k is ``x . plane_n[k] = plane_d[k]``.
    tol : float or (K,) float
        Distance (m) within which a corner lies in the plane (per plane, or one for all); a
        segment must be longer than it.

    Returns
    -------
    a, b : (K, 3) float64
        Segment ends, in the plane (meaningless where ``ok`` is False).
    ok : (K,) bool
        The face meets the plane along a segment longer than ``tol``.
    """
    faces = np.asarray(faces, dtype=np.int64)
    K = faces.size
    a = np.zeros((K, 3))
    b = np.zeros((K, 3))
    ok = np.zeros(K, dtype=bool)
    if K == 0:
        return a, b, ok
    tol = np.broadcast_to(np.asarray(tol, dtype=np.float64), (K,))
    n_g = scene.face_normals[faces]
    cand = np.abs(np.einsum("ij,ij->i", n_g, plane_n)) <= constants.tol.parallel_cos
    rows = np.flatnonzero(cand)
    if rows.size == 0:
        return a, b, ok
    sizes = scene.face_sizes[faces[rows]]
    owner, local, starts = ragged(sizes)
    first = scene.face_starts[faces[rows]]
    p = scene.vertices[scene.corner_verts[first[owner] + local]]
    q = scene.vertices[scene.corner_verts[first[owner] + (local + 1) % sizes[owner]]]
    n = plane_n[rows][owner]
    d = plane_d[rows][owner]
    hp = np.einsum("ij,ij->i", p, n) - d
    hq = np.einsum("ij,ij->i", q, n) - d
    near = tol[rows][owner]
    sp = np.where(np.abs(hp) <= near, 0.0, np.sign(hp))
    sq = np.where(np.abs(hq) <= near, 0.0, np.sign(hq))
    # Per face: corners on each side and in the plane.
    n_on = np.add.reduceat((sp == 0).astype(np.int64), starts)
    any_pos = np.maximum.reduceat(sp, starts) > 0
    any_neg = np.minimum.reduceat(sp, starts) < 0
    meets = (any_pos & any_neg) | (n_on >= 2)
    # Points where the face meets the plane: corners in it, and strict sign changes along edges.
    cross = sp * sq < 0
    t = np.where(cross, hp / np.where(cross, hp - hq, 1.0), 0.0)
    point_ok = (sp == 0) | cross
    point = np.where((sp == 0)[:, None], p, p + (q - p) * t[:, None])
    direction = _unit(np.cross(plane_n[rows], n_g[rows]))[owner]
    s = np.einsum("ij,ij->i", point, direction)
    s_lo = np.where(point_ok, s, np.inf)
    s_hi = np.where(point_ok, s, -np.inf)
    lo = np.minimum.reduceat(s_lo, starts)
    hi = np.maximum.reduceat(s_hi, starts)
    # The corner slots that attain the extremes (the first one; ties give the same point).
    at_lo = np.flatnonzero(point_ok & (s_lo == lo[owner]))
    at_hi = np.flatnonzero(point_ok & (s_hi == hi[owner]))
    a[rows[owner[at_lo[::-1]]]] = point[at_lo[::-1]]
    b[rows[owner[at_hi[::-1]]]] = point[at_hi[::-1]]
    ok[rows] = meets & (hi - lo > tol[rows])
    # Into the plane exactly (crossing points and corners are within tol of it).
    a -= (np.einsum("ij,ij->i", a, plane_n) - plane_d)[:, None] * plane_n
    b -= (np.einsum("ij,ij->i", b, plane_n) - plane_d)[:, None] * plane_n
    return a, b, ok


def _lines_of(a, b, plane_n):
    """Unit direction u along each segment and unit in-plane normal w = n x u; lengths."""
    d = b - a
    length = np.linalg.norm(d, axis=1)
    u = d / np.where(length > 0, length, 1.0)[:, None]
    w = _unit(np.cross(plane_n, u))
    return u, w, length


def _crossed(corners, k, size, a, u, w, length, tol, along=False):
    """(n,) bool: the segment (a, u, length) crosses the patch (corners, k corners) strictly;
    ``along``: it touches the patch instead (runs inside it or along its edge, within tol).

    Crossing means corners lie on both sides of the line beyond ``MIN_PIECE x size`` and the
    line's chord through the patch overlaps the segment by more than tol: a segment that ends on
    the patch's edge does not cross the patch its line goes on into (a shadow line leaving an
    object's corner that lies inside a patch's edge)."""
    rel = corners - a[:, None, :]
    h = np.einsum("ikj,ij->ik", rel, w)
    t = np.einsum("ikj,ij->ik", rel, u)
    slot_ok = np.arange(4)[None, :] < k[:, None]
    margin = MIN_PIECE * size
    h_max = np.where(slot_ok, h, -np.inf).max(axis=1)
    h_min = np.where(slot_ok, h, np.inf).min(axis=1)
    if along:
        t_max = np.where(slot_ok, t, -np.inf).max(axis=1)
        t_min = np.where(slot_ok, t, np.inf).min(axis=1)
        return (h_max >= -tol) & (h_min <= tol) & (t_max > tol) & (t_min < length - tol)
    nxt, cross, frac = _edge_crossings(h, k)
    tn = np.take_along_axis(t, nxt, axis=1)
    on = slot_ok & (h == 0)
    tc = t + (tn - t) * frac
    t_out = np.maximum(np.where(cross, tc, -np.inf).max(axis=1),
                       np.where(on, t, -np.inf).max(axis=1))
    t_in = np.minimum(np.where(cross, tc, np.inf).min(axis=1), np.where(on, t, np.inf).min(axis=1))
    # A patch with no area (its corners on one line: a sliver of rounding along an ear-clipping
    # diagonal, 58 m from the origin) is never cut: its pieces would have no normal.
    diameter = np.linalg.norm(corners - corners[:, :1], axis=2).max(axis=1)
    return (h_max > margin) & (h_min < -margin) & (t_out > tol) & (t_in < length - tol) \
        & (size > FLAT * diameter)


def _clear_of_corners(corners, k, size, a, w, gap):
    """(n,) bool: where the line (a, w) crosses an edge of the patch, the crossing point is at
    least ``gap`` x ``size`` from both ends of that edge (the cut leaves no edge shorter than
    that: a line that meets a patch's edge next to its corner would make a needle)."""
    h = _snapped(np.einsum("ikj,ij->ik", corners - a[:, None, :], w), size)
    nxt, cross, frac = _edge_crossings(h, k)
    edge = np.linalg.norm(np.take_along_axis(corners, nxt[:, :, None], axis=1) - corners, axis=2)
    near = np.minimum(frac, 1.0 - frac) * edge
    return np.all(~cross | (near >= gap * size[:, None]), axis=1)


def _edge_crossings(h, k):
    """Where a line crosses the edges of patches of ``k`` (n,) corners, from the corners'
    signed distances ``h`` (n, 4) to it: each edge's far corner ``nxt`` (n, 4), whether the
    line crosses the edge strictly (n, 4) bool, and the crossing's fraction along it (0 where it
    does not cross)."""
    nxt = (np.arange(4)[None, :] + 1) % k[:, None]
    hn = np.take_along_axis(h, nxt, axis=1)
    cross = (np.arange(4)[None, :] < k[:, None]) & (h * hn < 0)
    return nxt, cross, np.where(cross, h / np.where(cross, h - hn, 1.0), 0.0)


class Contacts:
    """The contact lines of a scene, as they cross its patches and pass through its vertices.

    Attributes
    ----------
    patch : (K,) int64
        Patch crossed by a contact line (one entry per patch-line pair, sorted by patch).
    a, u, w : (K, 3) float64
        A point of the line (its segment's start), its unit direction, and the unit normal to it
        in the patch's plane.
    length : (K,) float64
        Length of the segment.
    vertices : (V,) bool
        Scene vertices on a contact line with faces of that plane on both sides of it: a floor
        vertex on a box's outline, where the floor runs on under the box. The corners there see
        different light on the two sides of the line (a path tracer reads black inside), so the
        final gather treats each corner on its own (:mod:`core.gather`).
    tol : float
        The contact distance (m) they were found with.
    cuts : (K,) bool
        The segment crosses its patch, which :func:`split_at_contacts` cuts along it; the others
        run along the patch's edge (a box whose outline follows patch edges: the office's
        shelving panel standing on a cavity split's edge). Both kinds are contact lines for the
        final gather and the refinement.
    other : (K,) int64 or None
        The face that meets the patch's plane along the segment (:mod:`core.footlines` finds
        objects' corners from it).
    normal : (K, 3) float64 or None
        Unit normal of the patch's plane.
    min_gap : float
        0, or a line cuts no piece where it would cross an edge nearer its ends than this
        fraction of the piece's size (:func:`_clear_of_corners`; shadow lines, which need not
        be cut everywhere, unlike a contact).
    """

    def __init__(self, patch, a, u, w, length, vertices, tol, cuts=None, other=None,
                 normal=None, min_gap=0.0):
        self.patch, self.a, self.u, self.w, self.length = patch, a, u, w, length
        self.vertices, self.tol = vertices, tol
        self.cuts = np.ones(patch.size, dtype=bool) if cuts is None else cuts
        self.other, self.normal, self.min_gap = other, normal, min_gap


#: The grid of the spatial join has at most this many cells along the scene's diagonal.
GRID_CELLS = 1024


def find_contacts(scene, patches, *, tol=None):
    """The contact lines that cross ``patches`` and the scene vertices on them.

    Candidate (patch, face) pairs come from a spatial join of bounding boxes (grid of about the
    median patch size), so the cost grows with the number of neighbours, not with patches x faces
    or with the number of distinct planes (a finely tessellated sphere costs like a floor).

    Parameters
    ----------
    scene : core.scene.Scene
    patches : Patches
    tol : float, optional
        Contact distance in metres (default ``tol.contact`` x the bounding diagonal).

    Returns
    -------
    Contacts
    """
    diag = scene.bounding_diagonal()
    if tol is None:
        tol = constants.tol.contact * diag
    face = patches.face
    n_f = scene.face_normals[face]
    d_f = np.einsum("ij,ij->i", scene.vertices[scene.corner_verts[scene.face_starts[face]]], n_f)
    # Patches lying in their face's plane (a warped face's patches are not cut).
    dev = np.abs(np.einsum("ikj,ij->ik", patches.corners, n_f) - d_f[:, None]).max(axis=1)
    planar = np.flatnonzero((dev <= tol) & scene.face_valid[face])
    size = np.sqrt(patches.areas)
    fmin, fmax = face_boxes(scene)
    valid_f = np.flatnonzero(scene.face_valid)
    if planar.size == 0 or valid_f.size == 0:
        return no_contacts(scene, tol)
    cell = max(float(np.median(size[planar])), diag / GRID_CELLS, tol)
    pc = patches.corners[planar]
    pi, gi = box_pairs(pc.min(axis=1) - tol, pc.max(axis=1) + tol, fmin[valid_f] - tol,
                       fmax[valid_f] + tol, cell)
    pi, gi = planar[pi], valid_f[gi]
    keep = gi != face[pi]
    pi, gi = pi[keep], gi[keep]
    a, b, ok = contact_segments(scene, gi, n_f[pi], d_f[pi], tol)
    pi, gi, a, b = pi[ok], gi[ok], a[ok], b[ok]
    u, w, length = _lines_of(a, b, n_f[pi])
    on_line = _vertices_on_lines(scene, face[pi], gi, a, u, w, length, tol)
    k = np.where(patches.is_triangle, 3, 4)[pi]
    hit = _crossed(patches.corners[pi], k, size[pi], a, u, w, length, tol)
    along = ~hit & _crossed(patches.corners[pi], k, size[pi], a, u, w, length, tol, along=True)
    edge = np.flatnonzero(along)
    mid = a[edge] + 0.5 * length[edge, None] * u[edge]
    crease = _on_outline(scene, face[pi[edge]], mid, tol)
    crease[crease] = ~_continues(patches, pi[edge[crease]], mid[crease], w[edge[crease]], tol,
                                 cell)
    along[edge] = ~crease
    keep = hit | along
    pi, a, u, w, length, hit = pi[keep], a[keep], u[keep], w[keep], length[keep], hit[keep]
    gi = gi[keep]
    o = np.lexsort((gi, pi))
    return Contacts(pi[o], a[o], u[o], w[o], length[o], on_line, tol, cuts=hit[o], other=gi[o],
                    normal=n_f[pi[o]])


def face_boxes(scene):
    """(F, 3), (F, 3): the lower and upper corners of every face's bounding box
    (``face_corner_indices`` lists the corners face after face)."""
    corners, _ = scene.face_corner_indices()
    pos = scene.vertices[scene.corner_verts[corners]]
    starts = np.cumsum(scene.face_sizes) - scene.face_sizes
    return np.minimum.reduceat(pos, starts, axis=0), np.maximum.reduceat(pos, starts, axis=0)


def _on_outline(scene, f, m, tol):
    """(n,) bool: point m[i] lies within tol of an edge of face f[i] (where another face meets
    it: a crease, not something standing on it)."""
    out = np.zeros(f.size, dtype=bool)
    if f.size == 0:
        return out
    owner, local, _ = ragged(scene.face_sizes[f])
    start = scene.face_starts[f][owner]
    p = scene.vertices[scene.corner_verts[start + local]]
    q = scene.vertices[scene.corner_verts[start + (local + 1) % scene.face_sizes[f][owner]]]
    d = q - p
    t = np.clip(np.einsum("ij,ij->i", m[owner] - p, d)
                / np.maximum(np.einsum("ij,ij->i", d, d), 1e-300), 0.0, 1.0)
    dist = np.linalg.norm(m[owner] - (p + t[:, None] * d), axis=1)
    np.logical_or.at(out, owner, dist <= tol)
    return out


#: How far across a line on a face's outline (in contact distances) the surface is probed for.
PROBE = 4.0


def _continues(patches, p, m, w, tol, cell):
    """(n,) bool: the surface of patch p[i] runs on across the line through m[i] (unit normal
    w[i] in the plane) that lies on its face's outline: a point PROBE x tol beyond the line, away
    from the patch, lies in a patch of the same plane facing the same way. A wall modelled as
    two quads split where a partition butts into it has the partition's foot on both quads'
    outlines: that is a contact line (the wall runs on under the partition), not the crease
    where a floor meets the wall's own edge."""
    out = np.zeros(p.size, dtype=bool)
    if p.size == 0:
        return out
    n = patches.normals[p]
    away = np.sign(np.einsum("ij,ij->i", patches.corners[p].mean(axis=1) - m, w))
    q = m - (away * PROBE * tol)[:, None] * w
    lo, hi = patches.corners.min(axis=1) - tol, patches.corners.max(axis=1) + tol
    i, j = box_pairs(q - tol, q + tol, lo, hi, cell)
    h = np.einsum("ij,ij->i", q[i] - patches.corners[j, 0], n[i])
    same = (np.abs(h) <= tol) & (np.einsum("ij,ij->i", patches.normals[j], n[i])
                                 > constants.tol.parallel_cos)
    i, j = i[same], j[same]
    inside = inside_polygons(q[i], patches.corners[j], patches.normals[j])
    out[i[inside]] = True
    return out


def _vertices_on_lines(scene, f, g, a, u, w, length, tol):
    """(V,) bool: vertices on a contact line with faces of its plane on both sides of it.

    Rows are (face f in the plane, face g whose segment (a, u, w, length) lies in it); per
    distinct (f, g), the corners of f on the segment and the side of the line f's centroid is on.
    """
    on_line = np.zeros(scene.vertices.shape[0], dtype=bool)
    fg = np.unique(np.stack([f, g], axis=1), axis=0, return_index=True)[1]
    f, g = f[fg], g[fg]
    a, u, w, length = a[fg], u[fg], w[fg], length[fg]
    owner, local, _ = ragged(scene.face_sizes[f])
    vert = scene.corner_verts[scene.face_starts[f][owner] + local]
    x = scene.vertices[vert]
    centroid = np.zeros((f.size, 3))
    np.add.at(centroid, owner, x)
    centroid /= scene.face_sizes[f][:, None]
    rel = x - a[owner]
    h = np.einsum("ij,ij->i", rel, w[owner])
    t = np.einsum("ij,ij->i", rel, u[owner])
    on = (np.abs(h) <= tol) & (t >= -tol) & (t <= length[owner] + tol)
    side = np.einsum("ij,ij->i", centroid[owner] - a[owner], w[owner])
    e = np.flatnonzero(on & (np.abs(side) > tol))
    if e.size:
        key, group = np.unique(vert[e] * np.int64(scene.n_faces) + g[owner[e]],
                               return_inverse=True)
        group = group.reshape(-1)
        pos_side = np.zeros(key.size, dtype=bool)
        neg_side = np.zeros(key.size, dtype=bool)
        np.logical_or.at(pos_side, group, side[e] > 0)
        np.logical_or.at(neg_side, group, side[e] < 0)
        on_line[key[pos_side & neg_side] // scene.n_faces] = True
    return on_line


def no_contacts(scene, tol, min_gap=0.0):
    """Contacts with no line (none found, or nowhere to look)."""
    return Contacts(*_no_pairs(), np.zeros(scene.vertices.shape[0], dtype=bool), tol,
                    min_gap=min_gap)


def _no_pairs():
    z3 = np.zeros((0, 3))
    return np.zeros(0, dtype=np.int64), z3, z3, z3, np.zeros(0)


def _canonical_first(p, q):
    """(n,) bool: p precedes q lexicographically (x, then y, then z)."""
    return ((p[:, 0] < q[:, 0]) | ((p[:, 0] == q[:, 0]) & ((p[:, 1] < q[:, 1])
            | ((p[:, 1] == q[:, 1]) & (p[:, 2] < q[:, 2])))))


def _cut(corners, k, a, w, size):
    """Cut patches by lines; returns the pieces' corners (m, 4, 3), their count per patch.

    Every patch gives two convex polygons (one per side), each with 3 to 5 corners; a pentagon
    becomes a quad and a triangle. Crossing points are computed from the edge's endpoints in a
    canonical order, so the two patches sharing an edge place bit-identical points on it.

    Corners within ``SNAP x size`` of the line count as on it (no crossing point is made next to
    them, which rounding could put on the corner itself), and a patch the line does not cross
    by more than ``MIN_PIECE x size`` on both sides is returned whole: no piece can be
    degenerate (every piece has a corner at least ``MIN_PIECE x size`` from the line and two
    distinct points on it).
    """
    n = corners.shape[0]
    h = _snapped(np.einsum("ikj,ij->ik", corners - a[:, None, :], w), size)
    slot_ok = np.arange(4)[None, :] < k[:, None]
    margin = MIN_PIECE * size
    crossed = ((np.where(slot_ok, h, -np.inf).max(axis=1) > margin)
               & (np.where(slot_ok, h, np.inf).min(axis=1) < -margin))
    slot = np.arange(4)[None, :]
    nxt = (slot + 1) % k[:, None]
    v = corners
    vn = np.take_along_axis(corners, nxt[:, :, None], axis=1)
    hn = np.take_along_axis(h, nxt, axis=1)
    valid = slot < k[:, None]
    cross = valid & (h * hn < 0)
    # Crossing point from the canonical endpoint.
    first = _canonical_first(v.reshape(-1, 3), vn.reshape(-1, 3)).reshape(n, 4)
    p0 = np.where(first[:, :, None], v, vn)
    p1 = np.where(first[:, :, None], vn, v)
    h0 = np.where(first, h, hn)
    h1 = np.where(first, hn, h)
    t = np.where(cross, h0 / np.where(cross, h0 - h1, 1.0), 0.0)
    x = p0 + (p1 - p0) * t[:, :, None]
    # Sequence of up to 8 candidate corners per side: (vertex i, crossing on edge i), i = 0..3.
    seq = np.stack([v, x], axis=2).reshape(n, 8, 3)
    pieces, keep = [], []
    for sign in (1.0, -1.0):
        ok = np.stack([valid & (sign * h >= 0), cross], axis=2).reshape(n, 8)
        m = ok.sum(axis=1)
        order = np.argsort(~ok, axis=1, kind="stable")[:, :5]
        poly = np.take_along_axis(seq, order[:, :, None], axis=1)
        # 3 corners -> (0, 1, 2, 2); 4 -> (0, 1, 2, 3); 5 -> (0, 1, 2, 3) and (0, 3, 4, 4).
        main = np.where((m >= 4)[:, None], np.arange(4), np.array([0, 1, 2, 2]))
        pieces += [np.take_along_axis(poly, main[:, :, None], axis=1), poly[:, [0, 3, 4, 4]]]
        keep += [np.ones(n, dtype=bool), m == 5]
    pieces = np.stack(pieces, axis=1)          # (n, 4, 4, 3): +main, +extra, -main, -extra
    keep = np.stack(keep, axis=1)              # (n, 4)
    pieces[~crossed, 0] = corners[~crossed]
    keep[~crossed] = [True, False, False, False]
    return pieces[keep], keep.sum(axis=1)


def split_at_contacts(scene, patches, contacts=None, *, tol=None):
    """Cut the patches along the scene's contact lines.

    Parameters
    ----------
    scene : core.scene.Scene
    patches : Patches
        As made by :func:`core.patches.make_patches` (needs ``incidence_slot``).
    contacts : Contacts, optional
        From :func:`find_contacts` for these patches (found here if not given).
    tol : float, optional
        Contact distance in metres when the contacts are found here (default ``tol.contact`` x
        the scene's bounding diagonal); given contacts carry their own.

    Returns
    -------
    new : Patches
        The pieces replace their patch in place, in order (still contiguous per face).
    parent : (P',) int64
        Index in ``patches`` of the patch each new patch comes from.
    info : dict
        ``lines`` (patch-line pairs found), ``cut`` (patches cut at least once), ``cuts``
        (cuts made), ``added`` (P' - P).
    """
    if not isinstance(patches, Patches):
        raise TypeError(f"patches must be a Patches; got {type(patches).__name__}")
    if patches.incidence_slot is None:
        raise ValueError("patches.incidence_slot is None: split_at_contacts needs Patches made by "
                         "make_patches")
    if contacts is None:
        contacts = find_contacts(scene, patches, tol=tol)
    tol = contacts.tol
    c = contacts.cuts
    pair_p, a, u, w, length = (contacts.patch[c], contacts.a[c], contacts.u[c], contacts.w[c],
                               contacts.length[c])
    P0 = patches.n_patches
    info = dict(lines=int(pair_p.size), cut=int(np.unique(pair_p).size), cuts=0, added=0,
                vertices=int(np.count_nonzero(contacts.vertices)))
    parent = np.arange(P0, dtype=np.int64)
    if pair_p.size == 0:
        return patches, parent, info
    corners = np.asarray(patches.corners)
    face = np.asarray(patches.face)
    inc_v, inc_p = patches.incidence_vertex, patches.incidence_patch
    inc_c, inc_s = patches.incidence_corner, patches.incidence_slot
    for _ in range(MAX_CUTS):
        if pair_p.size == 0:
            break
        P = corners.shape[0]
        # Each patch takes its first pending line this round; the rest wait.
        uniq, first = np.unique(pair_p, return_index=True)
        now = np.zeros(pair_p.size, dtype=bool)
        now[first] = True
        k = np.where(triangle_mask(corners), 3, 4)
        # np.unique's first occurrences are in patch order, which the pending rows need not
        # be (children of different patches interleave): index the lines by ``first``.
        size_u = np.sqrt(newell_normals_areas(corners[uniq])[1])
        pieces, n_pieces = _cut(corners[uniq], k[uniq], a[first], w[first], size_u)
        info["cuts"] += int(uniq.size)
        n_child = np.ones(P, dtype=np.int64)
        n_child[uniq] = n_pieces
        par, local, start = ragged(n_child)
        new_corners = corners[par]
        cut = np.zeros(P, dtype=bool)
        cut[uniq] = True
        piece_start = np.zeros(P, dtype=np.int64)
        piece_start[uniq] = np.cumsum(n_pieces) - n_pieces
        sel = cut[par]
        new_corners[sel] = pieces[piece_start[par[sel]] + local[sel]]
        # Incidence: an original vertex stays a corner of every piece that has it (bit-equal).
        stay = ~cut[inc_p]
        e = np.flatnonzero(~stay)
        pos = corners[inc_p[e], inc_s[e]]
        eo, el, _ = ragged(n_child[inc_p[e]])
        child = start[inc_p[e]][eo] + el
        k_new = np.where(triangle_mask(new_corners), 3, 4)
        match = np.all(new_corners[child] == pos[eo][:, None, :], axis=2)
        match &= np.arange(4)[None, :] < k_new[child][:, None]
        has = match.any(axis=1)
        slot = np.argmax(match, axis=1)
        keep_e = e[eo[has]]
        inc_v = np.concatenate([inc_v[stay], inc_v[keep_e]])
        inc_c = np.concatenate([inc_c[stay], inc_c[keep_e]])
        inc_p, inc_s = (np.concatenate([start[inc_p[stay]], child[has]]),
                        np.concatenate([inc_s[stay], slot[has]]))
        # Pending lines: to every child of their patch that they still cross.
        rest = np.flatnonzero(~now)
        ro, rl, _ = ragged(n_child[pair_p[rest]])
        r = rest[ro]
        rc = start[pair_p[r]] + rl
        size_c = np.sqrt(newell_normals_areas(new_corners[rc])[1])
        hit = _crossed(new_corners[rc], k_new[rc], size_c, a[r], u[r], w[r], length[r], tol)
        if contacts.min_gap > 0:
            hit &= _clear_of_corners(new_corners[rc], k_new[rc], size_c, a[r], w[r],
                                     contacts.min_gap)
        pair_p, a, u, w, length = rc[hit], a[r[hit]], u[r[hit]], w[r[hit]], length[r[hit]]
        parent = parent[par]
        face = face[par]
        corners = new_corners
    info["added"] = int(corners.shape[0] - P0)
    n_faces = patches.face_patch_start.shape[0] - 1
    new = assemble_patches(corners, face, material_table(patches), n_faces, inc_v, inc_p, inc_c,
                           inc_s)
    return new, parent, info
