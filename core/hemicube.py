"""Hemicube form factors (Cohen & Greenberg 1985), vectorised over sources, polygons and pixels.

One hemicube per source node: a top face of R x R pixels and four side faces of R x R/2 pixels
around an eye at the patch centre (half-width 1, so the top face is the square [-1, 1]^2 at
distance 1 along the viewing normal). Every patch is drawn into a z-buffered item buffer (planar
convex quads whole, other patches as the triangles of ``core.patches.patch_triangles``); each
pixel credits its delta form factor to the node whose polygon is nearest along the pixel's ray:
node q when the polygon is seen from the side its patch normal points to, q + P otherwise.

How the rasteriser works (array operations over a chunk of sources at once; the only Python
loops run over chunks, the five faces and the four edges of a polygon):

1. *Vertices*: every distinct polygon corner is put in each eye frame once per source,
   classified into the face whose viewing pyramid holds it and given homogeneous pixel
   coordinates (J, I, W) on that face, so polygons sharing a corner see identical bits.
2. *Pairs*: (source, polygon) pairs wholly below the near plane, edge-on, or (with
   ``cull_back``) back-facing are dropped.
3. *Items*: a polygon whose corners lie in one face's pyramid (convex) is drawn on that face
   only; the others on every face they reach, cropped by the face's bounds. A polygon that
   straddles a face's near plane gets that plane as one more half-plane ``1/W <= 1/near``:
   homogeneous rasterisation (Olano & Greer 1997), i.e. the near-plane clip done per pixel,
   never a projection through infinity.
4. *Row spans*: with edge functions ``E_k = (v_k x v_k+1) . (j, i, 1)`` the covered columns of
   a row are one interval whose ends are computed exactly; the two polygons of a shared edge
   compute the same bound bit for bit from opposite sides, so a closed mesh leaves no gap.
5. *Z-buffer*: fragments carry a 64-bit key, the float32 bits of 1/W (high) and the item
   (low); ``np.maximum.at`` keeps the nearest per pixel whatever the drawing order. Each
   group's spans are drawn as soon as they are made, a block of spans at a time, _FRAG_SLOTS
   pixels per span in one broadcast (slots past a span get a negative key, which the maximum
   ignores) and the rest of longer spans in one more pass.
6. *Accumulate*: ``np.bincount`` sums the delta form factors of each item's pixels, then
   the items into their (source, node) cells.

float32 is used from the eye-frame coordinates on (pixel positions to ~1e-5 pixel, depth to
~1e-6 relative); the delta form factors and the result are float64.
"""

import sys
import time
import weakref

import numpy as np

from .constants import HEMICUBE_NEAR, SURFACE_OFFSET

#: Face names in pixel-buffer order: the top face, then the sides along +x, -x, +y, -y of the
#: eye frame (x, y tangent, z the viewing normal).
FACE_NAMES = ("top", "+x", "-x", "+y", "-y")

#: For each face, the eye-frame components (and their signs) that give the face's (u, v, w):
#: u, v span the face (|u| <= 1; v in [-1, 1] on top, [0, 1] on a side) and w is the depth
#: along the face's axis. The same map turns an eye-frame covector c into the coefficients of
#: ``c . r`` as ``a u + b v + c`` for the ray ``r`` through face point (u, v) at w = 1.
_FACE_AXES = np.array([[0, 1, 2], [1, 2, 0], [1, 2, 0], [0, 2, 1], [0, 2, 1]])
_FACE_SIGNS = np.array([[1, 1, 1], [1, 1, 1], [-1, 1, -1], [-1, 1, 1], [1, 1, -1]], dtype=float)

#: The z-buffer key of a fragment: the float32 bits of 1/w (positive, so the bits order like the
#: values) in the high 32 bits, item index + 1 in the low 32 bits; the per-pixel maximum is the
#: nearest fragment.
_ITEM_MASK = (1 << 32) - 1

#: Depth ties. The last _DEPTH_DROP mantissa bits of 1/w are cleared, so fragments of two
#: polygons that meet at a pixel (float32 rounding differs by an ulp or two) tie exactly; a tie
#: goes to the larger item in even pixel columns and to the smaller in odd ones (the item is
#: stored complemented there). Where surfaces meet along a line, e.g. the corner edges of a box
#: that fall on the diagonals of the top face, the pixels are then shared alternately instead
#: of all going to one side, which keeps symmetric scenes reciprocal. Depth resolution left:
#: 2^-(23 - 4) = 2e-6 relative.
_DEPTH_DROP = 4
_DEPTH_MASK = np.int32(~((1 << _DEPTH_DROP) - 1))
_TIE_FLIP = np.int32((1 << 31) - 1)

#: Work per internal chunk of sources: (source, polygon) pairs and hemicube pixels. Bounded so
#: that the transient arrays of one chunk stay in the tens of megabytes while still amortising
#: NumPy's per-call overhead over many sources.
_CHUNK_PAIRS = 60_000
_CHUNK_PIXELS = 600_000

#: Slack (in rows) added to bounding rows so that float32 rounding of the projected vertices
#: (relative 1e-7 of up to R rows) never drops a row that the exact span test would fill;
#: extra rows simply get empty spans.
_ROW_SLACK = 1e-3

#: A quad is drawn whole when its 4th corner lies within this fraction of its diagonal from the
#: plane of the first three (else as two triangles): a 1e-6 warp moves its silhouette by far
#: less than a pixel at any resolution allowed.
_PLANAR_TOLERANCE = 1e-6

#: Largest resolution: pixel indices of one chunk are exact in float32 (3 R^2 < 2^24).
_MAX_RESOLUTION = 2048

_LITTLE_ENDIAN = sys.byteorder == "little"

#: Working precision of the rasteriser (see the module docstring).
_F32 = np.float32


# --------------------------------------------------------------------------------------------
# Delta form factors
# --------------------------------------------------------------------------------------------

def _check_resolution(resolution):
    if isinstance(resolution, (bool, np.bool_)) or not isinstance(resolution, (int, np.integer)):
        raise TypeError(f"resolution must be an int; got {type(resolution).__name__}")
    if resolution < 2 or resolution % 2:
        raise ValueError(f"resolution must be an even int >= 2; got {resolution}")
    if resolution > _MAX_RESOLUTION:
        raise ValueError(f"resolution must be at most {_MAX_RESOLUTION}; got {resolution}")
    return int(resolution)


def _raw_delta_form_factors(resolution):
    """Unnormalised delta form factors: (top (R, R), side (R/2, R)), float64."""
    r = resolution
    h = 2.0 / r
    u = -1.0 + h * (np.arange(r) + 0.5)            # column centres, shared by every face
    v_side = h * (np.arange(r // 2) + 0.5)         # row centres of a side face (height above
    da = h * h                                     # the source plane)
    top = da / (np.pi * (u[:, None] ** 2 + u[None, :] ** 2 + 1.0) ** 2)
    side = v_side[:, None] * da / (np.pi * (u[None, :] ** 2 + v_side[:, None] ** 2 + 1.0) ** 2)
    return top, side


def delta_form_factors(resolution, *, normalised=True):
    """Delta form factors of the hemicube pixels (Cohen & Greenberg 1985).

    Top face pixel at (x, y): ``dF = dA / (pi (x^2 + y^2 + 1)^2)``; side face pixel at (y, z):
    ``dF = z dA / (pi (y^2 + z^2 + 1)^2)``, with ``dA = (2/R)^2`` (half-width 1).

    Parameters
    ----------
    resolution : int
        R, even, >= 2: the top face has R x R pixels, each side R/2 x R.
    normalised : bool, optional
        If True (default) all pixels are scaled so that they sum to exactly 1; the raw midpoint
        sums exceed 1 by about 0.54 / R^2.

    Returns
    -------
    dict of str -> ndarray
        ``'top'``: (R, R) indexed [row (y), column (x)]; ``'+x'``, ``'-x'``, ``'+y'``, ``'-y'``:
        (R/2, R) indexed [row (height z, 0 at the horizon), column], float64.
    """
    r = _check_resolution(resolution)
    top, side = _raw_delta_form_factors(r)
    scale = 1.0 / (top.sum() + 4.0 * side.sum()) if normalised else 1.0
    out = {"top": top * scale}
    for name in FACE_NAMES[1:]:
        out[name] = side * scale
    return out


def _flat_delta_form_factors(resolution):
    """Normalised delta form factors in pixel-buffer order: (3 R^2,) float64."""
    d = delta_form_factors(resolution)
    return np.concatenate([d[name].ravel() for name in FACE_NAMES])


# --------------------------------------------------------------------------------------------
# Input handling
# --------------------------------------------------------------------------------------------

def _patch_geometry(patches):
    """Pull (centres, normals, corners) out of a Patches-like object, validated."""
    for attr in ("centres", "normals", "corners"):
        if not hasattr(patches, attr):
            raise TypeError(f"patches must be a Patches object with '{attr}'; "
                            f"got {type(patches).__name__}")
    centres = np.asarray(patches.centres, dtype=np.float64)
    normals = np.asarray(patches.normals, dtype=np.float64)
    corners = np.asarray(patches.corners, dtype=np.float64)
    if centres.ndim != 2 or centres.shape[1] != 3:
        raise ValueError(f"patches.centres must have shape (P, 3); got {centres.shape}")
    p = centres.shape[0]
    if normals.shape != (p, 3):
        raise ValueError(f"patches.normals must have shape ({p}, 3); got {normals.shape}")
    if corners.shape != (p, 4, 3):
        raise ValueError(f"patches.corners must have shape ({p}, 4, 3); got {corners.shape}")
    if p == 0:
        raise ValueError("patches must hold at least one patch; got 0")
    _check_frames(centres, normals, corners)
    return centres, normals, corners


def _check_frames(centres, normals, corners):
    """Finite geometry and unit normals (a hemicube needs a viewing direction)."""
    for name, a in (("centres", centres), ("normals", normals), ("corners", corners)):
        if not np.isfinite(a).all():
            raise ValueError(f"patches.{name} must be finite; got NaN or inf")
    length = np.linalg.norm(normals, axis=1)
    bad = np.abs(length - 1.0) > 1e-6
    if bad.any():
        i = int(np.argmax(bad))
        raise ValueError(f"patches.normals must be unit vectors; got length {length[i]:.6g} "
                         f"at patch {i}")


def _check_sources(sources, n_nodes):
    src = np.asarray(sources)
    if src.ndim != 1:
        raise ValueError(f"sources must be a 1-D array of node ids; got shape {src.shape}")
    if src.size == 0:
        return src.astype(np.int64)
    if not np.issubdtype(src.dtype, np.integer):
        raise TypeError(f"sources must hold integer node ids; got dtype {src.dtype}")
    bad = (src < 0) | (src >= n_nodes)
    if bad.any():
        i = int(np.argmax(bad))
        raise ValueError(f"sources must be node ids in [0, {n_nodes}) (2P); "
                         f"got {int(src[i])} at index {i}")
    return src.astype(np.int64)


def _make_rng(rng):
    if isinstance(rng, np.random.Generator):
        return rng
    if isinstance(rng, (int, np.integer)) and not isinstance(rng, (bool, np.bool_)):
        return np.random.default_rng(int(rng))
    raise TypeError("rng must be a numpy.random.Generator (or an int seed) when rotate=True; "
                    f"got {type(rng).__name__}")


def _eye_frames(centres, normals, corners, sources, n_patches, diag, angles):
    """Eyes (S, 3) and eye frames (S, 3, 3) (rows x, y, z = viewing normal) of source nodes.

    The unrotated x axis follows the patch's first edge, so a hemicube is aligned with the
    patch (and, in architectural scenes, with the walls); ``angles`` (S,) rotate it about z.
    """
    patch = sources % n_patches
    sign = np.where(sources >= n_patches, -1.0, 1.0)[:, None]
    z = normals[patch] * sign
    eyes = centres[patch] + (SURFACE_OFFSET * diag) * z
    edge = corners[patch, 1] - corners[patch, 0]
    x = edge - np.sum(edge * z, axis=1, keepdims=True) * z
    norm = np.linalg.norm(x, axis=1)
    weak = norm <= 1e-9 * (np.linalg.norm(edge, axis=1) + 1e-300)
    if weak.any():  # degenerate first edge: fall back to the world axis least along z
        axis = np.eye(3)[np.argmin(np.abs(z[weak]), axis=1)]
        x[weak] = axis - np.sum(axis * z[weak], axis=1, keepdims=True) * z[weak]
        norm[weak] = np.linalg.norm(x[weak], axis=1)
    x /= norm[:, None]
    y = np.cross(z, x)
    if angles is not None:
        c, s = np.cos(angles)[:, None], np.sin(angles)[:, None]
        x, y = c * x + s * y, c * y - s * x
    return eyes, np.stack([x, y, z], axis=1)


# --------------------------------------------------------------------------------------------
# The rasteriser
# --------------------------------------------------------------------------------------------

class _Geometry:
    """Source-independent data of the polygons: distinct corners, planes, scene scale."""

    def __init__(self, polys, poly_patch, normals):
        polys = np.ascontiguousarray(polys, dtype=np.float64)             # (Q, 4, 3)
        self.poly_patch = np.asarray(poly_patch, dtype=np.int64)          # (Q,)
        self.n_polys = polys.shape[0]
        flat = polys.reshape(-1, 3)
        lo, hi = flat.min(0), flat.max(0)
        self.diag = float(np.linalg.norm(hi - lo)) or 1.0
        # Shared corners are transformed once per source, so every polygon sees bit-identical
        # eye-frame coordinates of a shared vertex (no cracks along shared edges).
        self.verts, inverse = np.unique(flat, axis=0, return_inverse=True)
        self.poly_v = inverse.reshape(-1, 4).astype(np.int64)             # (Q, 4)
        # Planes oriented along the patch normal: eye above the plane = front-facing.
        n = np.cross(polys[:, 1] - polys[:, 0], polys[:, 2] - polys[:, 0]) \
            + np.cross(polys[:, 2] - polys[:, 0], polys[:, 3] - polys[:, 0])
        n[np.sum(n * normals[self.poly_patch], axis=1) < 0] *= -1.0
        length = np.linalg.norm(n, axis=1)
        n /= np.where(length > 0, length, 1.0)[:, None]
        self.plane_n, self.plane_c = n, np.sum(n * polys[:, 0], axis=1)


class _Scene:
    """Per-call constants: the geometry, the resolution's pixel layout, culling."""

    def __init__(self, geometry, n_patches, resolution, cull_back):
        g = geometry
        self.poly_patch, self.verts, self.poly_v = g.poly_patch, g.verts, g.poly_v
        self.plane_n, self.plane_c, self.diag = g.plane_n, g.plane_c, g.diag
        self.near = HEMICUBE_NEAR * g.diag
        self.n_patches = n_patches
        self.r = resolution
        self.npix = 3 * resolution * resolution
        self.cull_back = cull_back
        self.dff = _flat_delta_form_factors(resolution)
        self.h = 2.0 / resolution
        # Pixel-buffer layout of one hemicube: top R x R, then four sides R/2 x R (row-major).
        r = resolution
        self.face_offset = np.array([0] + [r * r + k * r * r // 2 for k in range(4)], np.int64)
        self.face_rows = np.array([r] + [r // 2] * 4, np.int64)
        self.face_rows_f = self.face_rows.astype(_F32)
        self._tiled = {}

    def tiled(self, s_n):
        """The delta form factors of ``s_n`` hemicubes in buffer order, (s_n 3 R^2,)."""
        if s_n not in self._tiled:
            self._tiled[s_n] = np.tile(self.dff, s_n)
        return self._tiled[s_n]

    def tiled_flip(self, s_n):
        """The tie flip of every cell of ``s_n`` hemicubes (odd columns), (s_n 3 R^2,)."""
        key = ("flip", s_n)
        if key not in self._tiled:
            self._tiled[key] = (np.arange(s_n * self.npix, dtype=np.int64) & 1) * _TIE_FLIP
        return self._tiled[key]


def _expand(counts):
    """For items with ``counts`` (n,), return (owner (total,), rank within owner (total,))."""
    owner = np.repeat(np.arange(counts.size), counts)
    starts = np.cumsum(counts) - counts
    rank = np.arange(owner.size) - starts[owner]
    return owner, rank


def _pixel_coords(x, y, z, face, h):
    """Homogeneous pixel coordinates (J, I, W) on ``face`` of eye-frame points (their dtype).

    Pixel (row i, column j) of the face is the ray through (j, i, 1): J = (u - u0 w) / h,
    I = (v - v0 w) / h with (u0, v0) the centre of pixel (0, 0) and W = w the depth along the
    face's axis. ``face`` is an int, or None to use for each point the face whose pyramid
    holds it (then also returned). Both forms give bit-identical values for the same point
    and face (selection is by exact 0/1 blends, never by arithmetic that rounds).
    """
    u0 = -1.0 + 0.5 * h
    if face is not None:
        xyz = (x, y, z)
        (ia, ib, ic), (sa, sb, sc_) = _FACE_AXES[face], _FACE_SIGNS[face].tolist()
        u, v, w = sa * xyz[ia], sb * xyz[ib], sc_ * xyz[ic]      # Python floats keep dtype
        v0 = (-1.0 if face == 0 else 0.0) + 0.5 * h
        return (u - u0 * w) / h, (v - v0 * w) / h, w
    ax, ay = np.abs(x), np.abs(y)
    m = np.maximum(ax, ay)
    top = z >= m
    xbig = ax >= ay
    neg = (xbig & (x < 0)) | (~xbig & (y < 0))
    face = (~top) * (1 + 2 * (~xbig) + neg)                               # 0 top, 1..4 sides
    t = top.astype(x.dtype)
    s = 1 - t
    xb = xbig.astype(x.dtype)
    sign = (1 - 2 * neg).astype(x.dtype)                                  # +x: y, -x: -y,
    u = t * x + s * (xb * (sign * y) + (1 - xb) * (-sign * x))            # +y: -x, -y: x
    v = t * y + s * z
    w = t * z + s * m
    v0 = t * (-1.0 + 0.5 * h) + s * (0.5 * h)
    return (u - u0 * w) / h, (v - v0 * w) / h, w, face


def _setup(*pts):
    """Edge lines and depth plane of planar convex polygons given by (J, I, W) vertex triples.

    A triangle repeats its last vertex: the zero edge has all coefficients 0 and constrains
    nothing.

    Returns
    -------
    alpha, beta0, beta1 : lists of K arrays
        Edge k is ``E_k(j, i) = alpha_k j + beta1_k i + beta0_k`` (from v_k x v_k+1); inside
        means ``sign(D) E_k >= 0`` for all k.
    det : array
        D = n . v0 with n = sum_k v_k x v_k+1, the plane's offset (0 for an edge-on polygon).
    zu, zv, z0 : arrays
        ``1/W = zu j + zv i + z0`` at pixel centres on the polygon's plane.
    """
    k_n = len(pts)
    alpha, beta1, beta0 = [], [], []
    for k in range(k_n):
        a, b = pts[k], pts[(k + 1) % k_n]
        alpha.append(a[1] * b[2] - a[2] * b[1])
        beta1.append(a[2] * b[0] - a[0] * b[2])
        beta0.append(a[0] * b[1] - a[1] * b[0])
    n_j, n_i, n_w = sum(alpha), sum(beta1), sum(beta0)
    det = n_j * pts[0][0] + n_i * pts[0][1] + n_w * pts[0][2]
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
        inv = 1 / (det + (det == 0))
        zu, zv, z0 = n_j * inv, n_i * inv, n_w * inv
    return alpha, beta0, beta1, det, zu, zv, z0


#: Lines excluded from a bound are pushed this far out (float32 max is 3.4e38). Real lines
#: have |K0|, |K1| < 1e30: alpha, a 2 x 2 determinant of float32 pixel coordinates, is either
#: exactly 0 (handled apart) or far above 1e-30 of the betas.
_BIG = _F32(1e36)


def _bounds(alpha, beta0, beta1, sgn, r0, r1):
    """Column bounds of the half-planes ``sgn E >= 0`` over rows (arrays of one group).

    A line with alpha != 0 bounds the columns from below (``sgn alpha > 0``) or above by
    ``j = (beta0 + beta1 i) * -(1/alpha) = K0 + K1 i``; it is returned as a lower line
    (K0, K1) and an upper line, the wrong one pushed out of reach. Both polygons of a shared
    edge hold the negated line, so they compute bit-identical bounds on opposite sides and no
    pixel is left unclaimed. A line with alpha = 0 (parallel to the rows) restricts rows
    only: folded into [r0, r1] exactly (in place).
    """
    nz = alpha != 0
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
        nia = -(1 / (alpha + ~nz))
        nia *= nz
        k0 = beta0 * nia
        k1 = beta1 * nia
    an = alpha * sgn
    low = (an > 0).astype(_F32)
    up = (an < 0).astype(_F32)
    flat = np.flatnonzero(~nz)
    if flat.size:
        c0, c1 = beta0[flat] * sgn[flat], beta1[flat] * sgn[flat]      # c0 + c1 i >= 0
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            bound = np.nan_to_num(c0 * -(1 / c1), nan=0.0, posinf=1e9, neginf=-1e9)
        r0[flat] = np.where(c1 > 0, np.maximum(r0[flat], np.ceil(bound)), r0[flat])
        r1[flat] = np.where(c1 < 0, np.minimum(r1[flat], np.floor(bound)), r1[flat])
        r1[flat] = np.where((c1 == 0) & (c0 < 0), -1, r1[flat])
    return (k0 - _BIG * (1 - low), k1 * low), (k0 + _BIG * (1 - up), k1 * up)


#: Rows per work unit: an item's rows are processed as (slots, n) broadcasts, slots = the mean
#: row count of the group rounded up, within [2, _ROW_SLOTS] (items with more rows continue in
#: extra units); a row's fragments as (_FRAG_SLOTS, n). Room at R = 64: 2.8 rows per item at
#: 2000 quads, 1.2 at 8000 (where 2 slots instead of 4 saved 25 % of the span time); 3.3
#: fragments per row. _FRAG_SLOTS is even, so a fragment's pixel parity (the tie flip) is the
#: parity of its row start plus its slot.
_ROW_SLOTS = 4
_FRAG_SLOTS = 4

#: Fragment slots past a row's span are not masked out: their 1/W is pushed below zero, so
#: their key is negative and ``np.maximum.at`` ignores them (the z-buffer starts at 0). The
#: push is ``(span - 0.5 - slot) * _POISON``: >= 0.5 _POISON (above any real 1/W, at most
#: 1/near) for a real fragment, <= -0.5 _POISON past the span, finite in float32 for any R.
_POISON = _F32(1e30)
_SLOT_RANGE = np.arange(_FRAG_SLOTS, dtype=_F32)[:, None]
_SLOT_POISON = _SLOT_RANGE * _POISON
_SLOT_INT = np.arange(_FRAG_SLOTS, dtype=np.int64)[:, None]


def _item_rows(zbuf, verts, face, pair, ps, first_id, sc, *, near_line=False, bbox=None,
               clock=None):
    """Rasterise a group of polygon items on given faces into the z-buffer.

    Parameters
    ----------
    zbuf : (S 3 R^2 + _FRAG_SLOTS,) int64
        Z-buffer keys (see :func:`_fragments`); updated in place.
    verts : 4 tuples (J, I, W) of (n,) float32
        Polygon vertices in the pixel coordinates of each item's face.
    face, pair : (n,) int
        Face and (source, polygon) pair of each item.
    near_line : bool
        Add the near-plane half-plane ``1/W <= 1/near`` (polygons straddling it).
    bbox : (imin, imax) or None
        Projected row interval (of the near-clipped polygon); default from the vertices.
    clock : dict or None
        If given, CPU seconds spent in the z-buffer are added to ``clock["zbuffer"]``.

    Returns
    -------
    (rows, fragments) : (int, int)
        Non-empty row spans and fragments drawn.
    """
    if pair.size == 0:
        return 0, 0
    alpha, beta0, beta1, det, zu, zv, z0 = _setup(*verts)
    if bbox is None:
        ip = [v[1] / v[2] for v in verts]
        bbox = (np.minimum.reduce(ip), np.maximum.reduce(ip))
    n_rows = sc.face_rows_f[face]
    r0 = np.clip(np.ceil(bbox[0] - _ROW_SLACK), 0, n_rows).astype(_F32)
    r1 = np.clip(np.floor(bbox[1] + _ROW_SLACK), -1, n_rows - 1).astype(_F32)
    r1 -= (det == 0) * _F32(1e6)                                          # edge-on: empty
    sgn = np.sign(det).astype(_F32)
    lines = [_bounds(a, b0, b1, sgn, r0, r1) for a, b0, b1 in zip(alpha, beta0, beta1)]
    if near_line:   # -zu j - zv i + (1/near - z0) >= 0
        ones = np.ones_like(sgn)
        lines.append(_bounds(-zu, _F32(1.0 / sc.near) - z0, -zv, ones, r0, r1))
    lower = [ln[0] for ln in lines]
    upper = [ln[1] for ln in lines]
    item = first_id + 1 + np.arange(pair.size, dtype=np.int32)           # 0: empty pixel
    cols = dict(r1=r1, base=(ps[pair] * sc.npix + sc.face_offset[face]).astype(_F32),
                z0=z0, zu=zu, zv=zv, item=item)
    n_rows = np.maximum(r1 - r0 + 1, 0)
    slots = int(np.clip(np.ceil(n_rows.mean()), 2, _ROW_SLOTS))          # adapt to item size
    counts = _row_slots(zbuf, r0, cols, lower, upper, sc.r, slots, clock)
    extra = np.ceil(n_rows / slots) - 1                                   # further units
    more = np.flatnonzero(extra > 0)
    if more.size:
        owner, rank = _expand(extra[more].astype(np.int64))
        idx = more[owner]
        r0c = r0[idx] + _F32(slots) * (rank + 1).astype(_F32)
        more_counts = _row_slots(zbuf, r0c, {k: v[idx] for k, v in cols.items()},
                                 [(a[idx], b[idx]) for a, b in lower],
                                 [(a[idx], b[idx]) for a, b in upper], sc.r, slots, clock)
        counts = (counts[0] + more_counts[0], counts[1] + more_counts[1])
    return counts


def _row_slots(zbuf, r0, cols, lower, upper, width, slots, clock=None):
    """Spans of rows r0 .. r0 + slots - 1 (up to r1) of each item, drawn into ``zbuf``.

    Returns (non-empty rows, fragments).
    """
    # Layout (slot, item): the long axis is innermost, so every broadcast runs NumPy's inner
    # loop over thousands of items rather than over a handful of slots.
    c = lambda a: a[None, :]                                              # noqa: E731
    row = c(r0) + np.arange(slots, dtype=_F32)[:, None]
    j_lo = None
    b = np.empty(row.shape, _F32)
    for k0, k1 in lower:
        if j_lo is None:
            j_lo = np.multiply(c(k1), row)
            j_lo += c(k0)
        else:
            np.multiply(c(k1), row, out=b)
            b += c(k0)
            np.maximum(j_lo, b, out=j_lo)
    j_hi = None
    for k0, k1 in upper:
        if j_hi is None:
            j_hi = np.multiply(c(k1), row)
            j_hi += c(k0)
        else:
            np.multiply(c(k1), row, out=b)
            b += c(k0)
            np.minimum(j_hi, b, out=j_hi)
    np.ceil(j_lo, out=j_lo)
    np.maximum(j_lo, 0, out=j_lo)
    np.minimum(j_lo, width, out=j_lo)
    np.floor(j_hi, out=j_hi)
    np.minimum(j_hi, width - 1, out=j_hi)
    np.maximum(j_hi, -1, out=j_hi)
    span = j_hi
    span -= j_lo
    span += 1
    span *= row <= c(cols["r1"])
    filled = np.flatnonzero(span.ravel() > 0)                             # NaN-safe
    if filled.size == 0:
        return 0, 0
    pix = row * width
    pix += j_lo
    pix += c(cols["base"])
    z = c(cols["zv"]) * row
    z += c(cols["z0"])
    z += c(cols["zu"]) * j_lo
    span, pix, z = span.ravel()[filled], pix.ravel()[filled], z.ravel()[filled]
    zu = np.tile(cols["zu"], slots)[filled]
    item = np.tile(cols["item"], slots)[filled]
    tic = time.process_time() if clock is not None else 0.0
    n_frag = _fragments(zbuf, pix, z, zu, item, span)
    if clock is not None:
        clock["zbuffer"] = clock.get("zbuffer", 0.0) + time.process_time() - tic
    return filled.size, n_frag


#: Spans per block of :func:`_fragments`: the temporaries of a block (about 16 bytes per
#: fragment slot each) stay in cache and are reused by the allocator instead of being mapped
#: afresh, which costs page faults.
_FRAG_BLOCK = 16384


def _fragments(zbuf, pix, z, dz, item, span):
    """Scatter the fragments of non-empty row spans into the z-buffer, in blocks of spans.

    Arguments as :func:`_fragment_block`. Returns the number of fragments.
    """
    for start in range(0, span.size, _FRAG_BLOCK):
        block = slice(start, start + _FRAG_BLOCK)
        _fragment_block(zbuf, pix[block], z[block], dz[block], item[block], span[block])
    return int(span.sum(dtype=np.float64))


def _fragment_block(zbuf, pix, z, dz, item, span):
    """Scatter the fragments of non-empty row spans into the z-buffer.

    Parameters
    ----------
    zbuf : (S 3 R^2 + _FRAG_SLOTS,) int64
        Keys: high 32 bits the float32 bits of 1/W with the low _DEPTH_DROP bits cleared, low
        32 bits the item + 1, complemented in odd pixel columns (see _TIE_FLIP).
        ``np.maximum.at`` keeps the nearest per pixel whatever the order.
    pix, z, dz, span : (m,) float32
        Buffer cell and 1/W of the first pixel, 1/W step per pixel, length of each span.
    item : (m,) int32
        Item id + 1 of each span.

    Spans are drawn _FRAG_SLOTS pixels at a time, in the (slot, span) layout; slots past a span
    get a negative key (see _POISON).
    """
    pix_i = pix.astype(np.int64)
    low_even = item ^ ((pix_i & 1).astype(np.int32) * _TIE_FLIP)
    low_odd = low_even ^ _TIE_FLIP
    for unit in range(2):
        inv_depth = dz * _SLOT_RANGE
        inv_depth += z
        limit = span - _F32(0.5)
        limit *= _POISON
        np.minimum(inv_depth, np.subtract(limit, _SLOT_POISON), out=inv_depth)
        cell = pix_i + _SLOT_INT
        if _LITTLE_ENDIAN:   # assemble the two 32-bit halves in place
            words = np.empty(inv_depth.shape + (2,), dtype=np.int32)
            np.bitwise_and(inv_depth.view(np.int32), _DEPTH_MASK, out=words[..., 1])
            words[0::2, :, 0] = low_even
            words[1::2, :, 0] = low_odd
            key = words.view(np.int64)
        else:
            depth = (inv_depth.view(np.int32) & _DEPTH_MASK).astype(np.int64) << 32
            key = depth | np.where(_SLOT_INT & 1, low_odd, low_even)
        np.maximum.at(zbuf, cell.ravel(), key.ravel())
        if unit:
            return
        # Spans longer than the slots continue in units of _FRAG_SLOTS pixels (an even step:
        # the same parity), all in one more pass.
        extra = np.ceil(span / _F32(_FRAG_SLOTS)) - 1
        more = np.flatnonzero(extra > 0)
        if more.size == 0:
            return
        owner, rank = _expand(extra[more].astype(np.int64))
        idx = more[owner]
        step = (rank + 1) * _FRAG_SLOTS
        pix_i = pix_i[idx] + step
        step = step.astype(_F32)
        dz, span = dz[idx], span[idx] - step
        z = z[idx] + dz * step
        low_even, low_odd = low_even[idx], low_odd[idx]


def _chunk_rows(sc, eyes, frames, timings):
    """Form-factor rows of one chunk of sources: (S, 2P)."""
    tic = time.process_time()
    s_n = eyes.shape[0]
    near, h = sc.near, sc.h
    n_u = sc.verts.shape[0]
    tv = sc.poly_v

    # 1. Unique vertices in every eye frame (S, U); each vertex is classified once per source
    # into the face whose pyramid holds it (-1: below the horizon or nearer than the near
    # plane) and given pixel coordinates on that face.
    eye_c = np.einsum("sij,sj->si", frames, eyes)
    # float32 from here: relative 6e-8 of the scene size is far below a pixel's footprint.
    vx, vy, vz = (((sc.verts @ frames[:, k].T).T - eye_c[:, k:k + 1]).astype(_F32)
                  for k in range(3))
    pj, pi, pw, face = _pixel_coords(vx, vy, vz, None, h)
    ok = (pw >= near) & (vz >= 0)
    cls = ((face + 1) * ok - 1).astype(np.int8).ravel()
    pj, pi, pw = pj.ravel(), pi.ravel(), pw.ravel()

    # Pairs: not wholly below the near plane, not edge-on, optionally not back-facing.
    top_z = np.maximum.reduce([vz[:, tv[:, k]] for k in range(4)])
    dist = eyes @ sc.plane_n.T - sc.plane_c                               # eye above plane
    keep = (top_z >= near) & (dist != 0.0)
    if sc.cull_back:
        keep &= dist > 0.0
    ps, pt = np.nonzero(keep)
    back = dist[ps, pt] < 0.0
    vid = [ps * n_u + tv[pt, k] for k in range(4)]                        # flat vertex ids
    c0 = cls[vid[0]]
    single = (c0 == cls[vid[1]]) & (c0 == cls[vid[2]]) & (c0 == cls[vid[3]]) & (c0 >= 0)
    q_fast = np.flatnonzero(single)
    q_gen = np.flatnonzero(~single)
    t1 = time.process_time()

    # 2. Items. Polygons inside one face's pyramid (convex) go to that face only. The others
    # are tested against every face: wholly in front of its near plane -> the same rasteriser
    # (the face's bounds crop them), straddling it -> clipped (general items).
    fv = [vid[k][q_fast] for k in range(4)]
    items_v = [[(pj[f], pi[f], pw[f]) for f in fv]]
    items_face = [c0[q_fast].astype(np.int64)]
    items_pair = [q_fast]
    general = _split_general(sc, vid, q_gen, vx.ravel(), vy.ravel(), vz.ravel(),
                             items_v, items_face, items_pair)
    verts = [tuple(np.concatenate([iv[k][c] for iv in items_v]) for c in range(3))
             for k in range(4)]
    face_all = np.concatenate(items_face)
    pair_all = np.concatenate(items_pair)
    t2 = time.process_time()

    # 3. Row spans, drawn into the z-buffer as they are made (4.); the buffer has
    # _FRAG_SLOTS cells of padding for the (negative-key) slots past the last pixel.
    zbuf = np.zeros(s_n * sc.npix + _FRAG_SLOTS, dtype=np.int64)
    clock = {"zbuffer": 0.0}
    n_rows, n_frag = _item_rows(zbuf, verts, face_all, pair_all, ps, 0, sc, clock=clock)
    zb_spans = clock["zbuffer"]
    t3 = time.process_time()
    item_pair = [pair_all]
    n_items = pair_all.size
    for face, pair, verts_g, bbox in general:
        n = _item_rows(zbuf, verts_g, np.full(pair.size, face), pair, ps, n_items, sc,
                       near_line=True, bbox=bbox, clock=clock)
        n_rows, n_frag = n_rows + n[0], n_frag + n[1]
        item_pair.append(pair)
        n_items += pair.size
    item_pair = np.concatenate(item_pair)
    t4 = time.process_time()
    zb = clock["zbuffer"]       # drawn while spans were made: reported apart
    t3, t4 = t3 - zb_spans, t4 - zb
    t5 = t4 + zb

    # 5. Accumulate delta form factors per item, then items into their (source, node) cell.
    n_cols = 2 * sc.n_patches
    zbuf = zbuf[:s_n * sc.npix]
    low = zbuf & _ITEM_MASK
    low ^= sc.tiled_flip(s_n)                                             # undo the tie flip
    low *= zbuf != 0                                                      # empty: item 0
    per_item = np.bincount(low, weights=sc.tiled(s_n),
                           minlength=item_pair.size + 1)[1:]              # item 0: nothing
    cell = ps[item_pair] * n_cols + sc.poly_patch[pt[item_pair]] + sc.n_patches * back[item_pair]
    out = np.bincount(cell, weights=per_item, minlength=s_n * n_cols)
    t6 = time.process_time()
    if timings is not None:
        for name, dt in (("cull", t1 - tic), ("items", t2 - t1), ("spans", t3 - t2),
                         ("general", t4 - t3), ("zbuffer", t5 - t4), ("accumulate", t6 - t5)):
            timings[name] = timings.get(name, 0.0) + dt
        for name, n in (("pairs", ps.size), ("general_pairs", q_gen.size),
                        ("items", item_pair.size), ("rows", n_rows),
                        ("fragments", n_frag)):
            timings["n_" + name] = timings.get("n_" + name, 0) + int(n)
    return out.reshape(s_n, n_cols)


def _split_general(sc, vid, q_gen, vx, vy, vz, items_v, items_face, items_pair):
    """Sort the pairs ``q_gen`` (not inside one pyramid) onto faces.

    Per face: wholly in front of the face's near plane and overlapping the face -> appended to
    the item lists; straddling the near plane and overlapping the face once clipped there ->
    returned as (face, pair, verts, (imin, imax)) general groups.
    """
    near, h, width = sc.near, sc.h, sc.r
    xyz = [(vx[v], vy[v], vz[v]) for v in (vid[k][q_gen] for k in range(4))]
    general = []
    for face in range(5):
        n_rows = sc.face_rows[face]
        jiw = [_pixel_coords(*p, face, h) for p in xyz]
        w = [p[2] for p in jiw]
        wmin, wmax = np.minimum.reduce(w), np.maximum.reduce(w)
        front = np.flatnonzero(wmin >= near)
        with np.errstate(divide="ignore", invalid="ignore"):
            pj = [p[0][front] / p[2][front] for p in jiw]
            pi = [p[1][front] / p[2][front] for p in jiw]
        hit = (np.minimum.reduce(pj) <= width - 0.5) & (np.maximum.reduce(pj) >= -0.5) \
            & (np.minimum.reduce(pi) <= n_rows - 0.5) & (np.maximum.reduce(pi) >= -0.5)
        sel = front[hit]
        items_v.append([tuple(c[sel] for c in p) for p in jiw])
        items_face.append(np.full(sel.size, face, dtype=np.int64))
        items_pair.append(q_gen[sel])
        cut = np.flatnonzero((wmin < near) & (wmax >= near))
        if cut.size:
            sub = [tuple(c[cut] for c in p) for p in jiw]
            lo, hi = _clipped_bbox(sub, near)
            with np.errstate(invalid="ignore"):
                hit = (lo[0] <= width - 0.5) & (hi[0] >= -0.5) \
                    & (lo[1] <= n_rows - 0.5) & (hi[1] >= -0.5)
            keep = np.flatnonzero(hit)
            if keep.size:
                verts = [tuple(c[keep] for c in p) for p in sub]
                general.append((face, q_gen[cut[keep]], verts, (lo[1][keep], hi[1][keep])))
    return general


def _clipped_bbox(verts, near):
    """Projected bounding box (lo (J, I), hi (J, I)) of polygons clipped at W = near.

    ``verts``: K (J, I, W) triples of (n,) arrays, at least one vertex in front.
    The clipped polygon's corners are the front vertices and the crossings of the edges with
    the near plane (at W = near exactly, so projected by dividing by near).
    """
    lo = [np.full(verts[0][0].shape, np.inf) for _ in range(2)]
    hi = [np.full(verts[0][0].shape, -np.inf) for _ in range(2)]
    for k in range(len(verts)):
        a, b = verts[k], verts[(k + 1) % len(verts)]
        front_a, front_b = a[2] >= near, b[2] >= near
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (near - a[2]) / (b[2] - a[2])
            for c in range(2):
                proj = np.where(front_a, a[c] / a[2], np.nan)
                cut = np.where(front_a != front_b, (a[c] + t * (b[c] - a[c])) / near, np.nan)
                lo[c] = np.fmin(lo[c], np.fmin(proj, cut))
                hi[c] = np.fmax(hi[c], np.fmax(proj, cut))
    return lo, hi


def polygon_rows(polys, poly_patch, centres, normals, corners, sources, *, resolution=64,
                 rotate=False, rng=None, cull_back=False, timings=None, _geometry=None):
    """Hemicube rows over explicit polygons; :func:`hemicube_rows` without a Patches object.

    Parameters
    ----------
    polys : (Q, 3, 3) or (Q, 4, 3) float
        Triangles, or planar convex quads (a triangle may repeat its last corner).
    poly_patch : (Q,) int
        Patch of each polygon, in [0, P).
    centres, normals : (P, 3) float
        Patch centres and unit normals.
    corners : (P, 4, 3) float
        Patch corners (the first edge orients an unrotated hemicube).
    sources, resolution, rotate, rng, cull_back
        As :func:`hemicube_rows`.
    timings : dict or None
        If given, CPU seconds per stage and counts (pairs, items, rows, fragments) are added.
    _geometry : internal
        A prepared ``_Geometry`` of these polygons (cached by :func:`hemicube_rows`).

    Returns
    -------
    (S, 2P) float64
    """
    resolution = _check_resolution(resolution)
    centres = np.asarray(centres, dtype=np.float64)
    normals = np.asarray(normals, dtype=np.float64)
    corners = np.asarray(corners, dtype=np.float64)
    n_patches = centres.shape[0]
    if centres.shape != (n_patches, 3) or normals.shape != (n_patches, 3) \
            or corners.shape != (n_patches, 4, 3):
        raise ValueError("centres, normals, corners must have shapes (P, 3), (P, 3), (P, 4, 3); "
                         f"got {centres.shape}, {normals.shape}, {corners.shape}")
    _check_frames(centres, normals, corners)
    polys = np.asarray(polys, dtype=np.float64)
    poly_patch = np.asarray(poly_patch)
    if polys.ndim != 3 or polys.shape[1:] not in ((3, 3), (4, 3)):
        raise ValueError(f"polys must have shape (Q, 3, 3) or (Q, 4, 3); got {polys.shape}")
    if poly_patch.shape != (polys.shape[0],):
        raise ValueError(f"poly_patch must have shape ({polys.shape[0]},); "
                         f"got {poly_patch.shape}")
    if poly_patch.size and (poly_patch.min() < 0 or poly_patch.max() >= n_patches):
        raise ValueError(f"poly_patch must hold patch ids in [0, {n_patches}); "
                         f"got range [{poly_patch.min()}, {poly_patch.max()}]")
    if not np.isfinite(polys).all():
        raise ValueError("polys must be finite; got NaN or inf")
    if polys.shape[1] == 3:
        polys = polys[:, [0, 1, 2, 2]]
    src = _check_sources(sources, 2 * n_patches)
    if not isinstance(rotate, (bool, np.bool_)):
        raise TypeError(f"rotate must be a bool; got {type(rotate).__name__}")
    if not isinstance(cull_back, (bool, np.bool_)):
        raise TypeError(f"cull_back must be a bool; got {type(cull_back).__name__}")
    angles = None
    if rotate:
        angles = _make_rng(rng).uniform(0.0, 2.0 * np.pi, size=src.size)
    out = np.zeros((src.size, 2 * n_patches))
    if src.size == 0 or polys.shape[0] == 0:
        return out
    geometry = _geometry if _geometry is not None else _Geometry(polys, poly_patch, normals)
    sc = _Scene(geometry, n_patches, resolution, bool(cull_back))
    eyes, frames = _eye_frames(centres, normals, corners, src, n_patches, sc.diag, angles)
    _rows_in_chunks(sc, eyes, frames, out, timings)
    return out


def draw_polygons(patches):
    """Polygons to rasterise: planar convex quads whole, every other patch as its triangles.

    A planar convex quad covers exactly the pixels of its two triangles, at half the work.

    Returns
    -------
    polys : (Q, 4, 3) float64
        A triangle repeats its last corner.
    poly_patch : (Q,) int64
    """
    from .patches import patch_triangles  # deferred: keeps this module importable alone

    corners = np.asarray(patches.corners, dtype=np.float64)
    e1, e2, e3 = (corners[:, k] - corners[:, 0] for k in (1, 2, 3))
    n = np.cross(e1, e2)
    other = corners[:, 3] - corners[:, 1]
    diagonal = np.maximum(np.linalg.norm(e2, axis=1), np.linalg.norm(other, axis=1))
    length = np.linalg.norm(n, axis=1)
    off_plane = np.abs(np.sum(e3 * n, axis=1)) / np.where(length > 0, length, 1.0)
    edges = np.roll(corners, -1, axis=1) - corners
    turns = np.einsum("qkj,qj->qk", np.cross(edges, np.roll(edges, -1, axis=1)), n)
    is_quad = ~np.all(corners[:, 3] == corners[:, 2], axis=1)
    whole = is_quad & (length > 0) & (off_plane <= _PLANAR_TOLERANCE * diagonal) \
        & np.all(turns > 0, axis=1)
    rest = np.flatnonzero(~whole)
    tris, tri_local = patch_triangles(_Corners(corners[rest]))
    polys = np.concatenate([corners[whole], tris[:, [0, 1, 2, 2]]])
    poly_patch = np.concatenate([np.flatnonzero(whole), rest[tri_local]]).astype(np.int64)
    return polys, poly_patch


class _Corners:
    """The one attribute of a Patches object that ``patch_triangles`` reads."""

    def __init__(self, corners):
        self.corners = corners


def hemicube_rows(patches, sources, *, resolution=64, rotate=False, rng=None, cull_back=False):
    """Form-factor rows of source nodes by the hemicube method.

    Parameters
    ----------
    patches : Patches
        From :func:`core.patches.make_patches` (uses ``centres``, ``normals``, ``corners``;
        non-planar or concave quads are drawn as :func:`core.patches.patch_triangles`).
    sources : (S,) int
        Node ids in [0, 2P): node p looks along the normal of patch p, node p + P along its
        opposite, both from the patch centre (offset by ``SURFACE_OFFSET`` x scene diagonal
        along the viewing direction so that coplanar neighbours are not seen).
    resolution : int, optional
        R, even, 2 <= R <= 2048 (top face R x R, sides R x R/2). Error falls as 1/R^2 for
        large patches and is aliasing-dominated for small distant ones.
    rotate : bool, optional
        Rotate each hemicube about its normal by a uniform random angle drawn from ``rng``
        (one per source, in order), which turns aliasing into unbiased noise.
    rng : numpy.random.Generator or int, optional
        Required when ``rotate`` is True.
    cull_back : bool, optional
        Skip back-facing polygons entirely (only valid for closed one-sided scenes: light then
        passes through polygons seen from behind).

    Returns
    -------
    (S, 2P) float64
        Row s: fraction of the energy leaving source s that reaches each node (front q, back
        q + P). A row sums to 1 minus the escaped fraction.

    Notes
    -----
    Cost is about linear in S x P + S x R^2 (see ``bench/bench_hemicube.py``); callers that
    poll for progress should pass batches of sources sized to take 0.1-0.2 s.
    """
    centres, normals, corners = _patch_geometry(patches)
    polys, poly_patch, geometry = _drawn(patches, normals)
    return polygon_rows(polys, poly_patch, centres, normals, corners, sources,
                        resolution=resolution, rotate=rotate, rng=rng, cull_back=cull_back,
                        _geometry=geometry)


def point_rows(patches, points, normals, *, resolution=64, rotate=False, rng=None):
    """Hemicube rows from arbitrary points: what each point sees of every node.

    The receiver is a point, so the hemicube has no proximity error here (that error comes from
    treating an area source as its centre); this is what a final gather at mesh vertices needs.

    Parameters
    ----------
    patches : core.patches.Patches
        The scene's patches (``P``); columns are nodes ``q`` (front) and ``q + P`` (back).
    points : (S, 3) float
        Eye points. Each is moved ``SURFACE_OFFSET`` x scene diagonal along its normal, so the
        surface it lies on is not seen.
    normals : (S, 3) float
        Unit viewing normals.
    resolution, rotate, rng
        As :func:`hemicube_rows`.

    Returns
    -------
    (S, 2P) float64
        Point-to-node form factors (differential area to node).
    """
    resolution = _check_resolution(resolution)
    points = np.asarray(points, dtype=np.float64)
    normals = np.asarray(normals, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3 or normals.shape != points.shape:
        raise ValueError(f"points and normals must both have shape (S, 3); got {points.shape} "
                         f"and {normals.shape}")
    if not (np.isfinite(points).all() and np.isfinite(normals).all()):
        raise ValueError("points and normals must be finite; got NaN or inf")
    length = np.linalg.norm(normals, axis=1)
    if points.shape[0] and np.max(np.abs(length - 1.0)) > 1e-6:
        bad = int(np.argmax(np.abs(length - 1.0)))
        raise ValueError(f"normals must be unit vectors; normals[{bad}] has length {length[bad]:.6g}")
    if not isinstance(rotate, (bool, np.bool_)):
        raise TypeError(f"rotate must be a bool; got {type(rotate).__name__}")
    _, n_normals, _ = _patch_geometry(patches)
    n_patches = n_normals.shape[0]
    out = np.zeros((points.shape[0], 2 * n_patches))
    if points.shape[0] == 0 or n_patches == 0:
        return out
    polys, poly_patch, geometry = _drawn(patches, n_normals)
    sc = _Scene(geometry, n_patches, resolution, False)
    z = normals
    axis = np.eye(3)[np.argmin(np.abs(z), axis=1)]
    x = axis - np.sum(axis * z, axis=1, keepdims=True) * z
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    y = np.cross(z, x)
    if rotate:
        ang = _make_rng(rng).uniform(0.0, 2.0 * np.pi, size=points.shape[0])
        c, s_ = np.cos(ang)[:, None], np.sin(ang)[:, None]
        x, y = c * x + s_ * y, c * y - s_ * x
    frames = np.stack([x, y, z], axis=1)
    eyes = points + (SURFACE_OFFSET * sc.diag) * z
    _rows_in_chunks(sc, eyes, frames, out, None)
    return out


def _drawn(patches, normals):
    """(polys, poly_patch, _Geometry) of ``patches``, from the cache when it holds them."""
    cached = _CACHE.get("patches")
    if cached is not None and cached() is patches:
        return _CACHE["data"]
    polys, poly_patch = draw_polygons(patches)
    geometry = _Geometry(polys, poly_patch, normals)
    try:
        ref = weakref.ref(patches, lambda _: _CACHE.clear())              # freed with them
        _CACHE.update(patches=ref, data=(polys, poly_patch, geometry))
    except TypeError:   # not weak-referenceable (a plain namespace): no caching
        _CACHE.clear()
    return polys, poly_patch, geometry


def _rows_in_chunks(sc, eyes, frames, out, timings):
    """Fill ``out`` (S, 2P) with the rows of every eye, in chunks sized for memory."""
    chunk = max(1, min(_CHUNK_PAIRS // sc.poly_v.shape[0], _CHUNK_PIXELS // sc.npix))
    for start in range(0, eyes.shape[0], chunk):
        stop = min(start + chunk, eyes.shape[0])
        out[start:stop] = _chunk_rows(sc, eyes[start:stop], frames[start:stop], timings)


#: The polygons and geometry of the last Patches object seen (by identity, weakly held): a bake
#: asks for rows batch after batch of the same patches, and this setup (draw_polygons, distinct
#: corners, planes) costs as much as several hemicubes. Patches are immutable by contract.
_CACHE = {}
