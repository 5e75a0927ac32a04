"""Hemicube form factors (Cohen & Greenberg 1985), vectorised over sources, polygons and pixels.

One hemicube per source node: a top face of R x R pixels and four side faces of R x R/2 pixels
around an eye at the patch centre (half-width 1, so the top face is the square [-1, 1]^2 at
distance 1 along the viewing normal). Every patch is drawn into a z-buffered item buffer (planar
convex quads whole, other patches as the triangles of ``core.patches.patch_triangles``); each
pixel credits its delta form factor to the node whose polygon is nearest along the pixel's ray:
node q when the polygon is seen from the side its patch normal points to, q + P otherwise.

How the rasteriser works (array operations over a chunk of sources at once; the only Python
loops run over chunks, blocks of items or spans, the five faces and the edges of a polygon):

1. *Vertices*: every distinct polygon corner is put in each eye frame once per source,
   classified into the face whose viewing pyramid holds it and given homogeneous pixel
   coordinates (J, I, W) on that face, so polygons sharing a corner see identical bits.
2. *Pairs*: (source, polygon) pairs wholly below the near plane, edge-on, or (with
   ``cull_back``) back-facing are dropped.
3. *Items*: a polygon whose corners lie in one face's pyramid (convex) is drawn on that face
   only; the others on every face they reach, cropped by the face's bounds. A polygon that
   straddles a face's near plane gets that plane as one more half-plane ``1/W <= 1/near``:
   homogeneous rasterisation (Olano & Greer 1997), i.e. the near-plane clip done per pixel,
   never a projection through infinity. Straddling polygons wholly beyond one of the planes
   through the eye and the face's borders are dropped before their clipped extent is computed.
4. *Row spans*: with edge functions ``E_k = (v_k x v_k+1) . (j, i, 1)`` the covered columns of
   a row are one interval whose ends are computed exactly; the two polygons of a shared edge
   compute the same bound bit for bit from opposite sides, so a closed mesh leaves no gap.
   Each edge is one line ``j = K0 + K1 i`` evaluated once per row and used as a lower or an
   upper bound (the other offset pushed out of reach); edges parallel to the rows narrow the
   row interval instead. Items are set up and spanned _ITEM_BLOCK at a time, so that the
   temporaries stay a few hundred kB.
5. *Z-buffer*: fragments carry a 64-bit key, the float32 bits of 1/W (high) and the item
   (low); ``np.maximum.at`` keeps the nearest per pixel whatever the drawing order. Each
   block's spans are drawn as soon as they are made, _FRAG_SLOTS pixels per span in one
   broadcast (slots past a span get a negative key, which the maximum ignores); the rest of
   longer spans is held back and drawn for many blocks at once.
6. *Accumulate*: ``np.bincount`` sums the delta form factors of each item's pixels, then
   the items into their (source, node) cells.

The z-buffer and the tiled delta form factors are kept between chunks and calls (per thread),
and the allocator is primed once (see _ALLOCATOR_PRIME_BYTES): with megabytes mapped afresh
for every chunk, page faults took a fifth of the time.

float32 is used from the eye-frame coordinates on (pixel positions to ~1e-5 pixel, depth to
~1e-6 relative); the delta form factors and the result are float64.
"""

import math
import sys
import threading
import time
import weakref

import numpy as np

from .constants import HEMICUBE_NEAR, MAX_RESOLUTION, SURFACE_OFFSET
from .geometry import ragged

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
#: nearest fragment. An empty cell holds 0.
#:
#: Depth ties. The last _DEPTH_DROP mantissa bits of 1/w are cleared, so fragments of two
#: polygons that meet at a pixel (float32 rounding differs by an ulp or two) tie exactly; a tie
#: goes to the larger item in even pixel columns and to the smaller in odd ones (the item is
#: stored negated there: as an unsigned low word 2^32 - item, which orders the other way, and
#: |low word| is the item in every cell, 0 in an empty one). Where surfaces meet along a line,
#: e.g. the corner edges of a box that fall on the diagonals of the top face, the pixels are then
#: shared alternately instead of all going to one side, which keeps symmetric scenes reciprocal.
#: Depth resolution left: 2^-(23 - 4) = 2e-6 relative.
_DEPTH_DROP = 4
_DEPTH_MASK = np.int32(~((1 << _DEPTH_DROP) - 1))
_LOW_WORD = (1 << 32) - 1

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

#: Largest resolution (see core.constants).
_MAX_RESOLUTION = MAX_RESOLUTION

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
        # Corners as (5, Q), the first repeated: edge k runs from corner k to k + 1.
        self.poly_v_t = np.ascontiguousarray(g.poly_v[:, [0, 1, 2, 3, 0]].T)
        self.verts_t = np.ascontiguousarray(g.verts.T)                     # (3, U)
        self.plane_n_t = np.ascontiguousarray(g.plane_n.T)                 # (3, Q)
        self.plane_c, self.diag = g.plane_c, g.diag
        self.near = HEMICUBE_NEAR * g.diag
        self.n_patches = n_patches
        self.r = resolution
        self.npix = 3 * resolution * resolution
        self.cull_back = cull_back
        self.h = 2.0 / resolution
        # Pixel-buffer layout of one hemicube: top R x R, then four sides R/2 x R (row-major).
        r = resolution
        self.face_offset = np.array([0] + [r * r + k * r * r // 2 for k in range(4)], np.int64)
        self.face_rows = np.array([r] + [r // 2] * 4, np.int64)
        self.face_rows_f = self.face_rows.astype(_F32)

    def tiled(self, s_n):
        """The delta form factors of ``s_n`` hemicubes in buffer order, (s_n 3 R^2,)."""
        n = s_n * self.npix
        tiled = _kept("dff", self.r)
        if tiled is None or tiled.size < n:
            tiled = _keep("dff", self.r, np.tile(_flat_delta_form_factors(self.r), s_n))
        return tiled[:n]

    def zbuffer(self, s_n):
        """A cleared z-buffer of ``s_n`` hemicubes plus _FRAG_SLOTS cells of padding."""
        n = s_n * self.npix + _FRAG_SLOTS
        zbuf = _kept("zbuf", None)
        if zbuf is None or zbuf.size < n:
            zbuf = _keep("zbuf", None, np.empty(n, dtype=np.int64))
        zbuf = zbuf[:n]
        zbuf.fill(0)
        return zbuf


#: Buffers kept across chunks and calls (the z-buffer, the delta form factors tiled over a
#: chunk's hemicubes): mapping megabytes afresh for every chunk costs a page fault per 4 kB,
#: more than filling them. One of each per thread (bakes run in worker threads), and only up
#: to _BUFFER_BYTES each (a chunk's z-buffer up to R = 1024).
_BUFFER_STORE = threading.local()
_BUFFER_BYTES = 1 << 25


def _kept(name, tag):
    """This thread's buffer ``name`` if it was kept with ``tag``, else None."""
    tag_array = getattr(_BUFFER_STORE, name, None)
    return tag_array[1] if tag_array is not None and tag_array[0] == tag else None


def _keep(name, tag, array):
    """Keep ``array`` (returned) as this thread's buffer ``name`` with ``tag``, if small enough."""
    setattr(_BUFFER_STORE, name, (tag, array) if array.nbytes <= _BUFFER_BYTES else None)
    return array


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


def _setup(verts):
    """Edge lines and depth plane of planar convex polygons.

    Parameters
    ----------
    verts : (3, 5, n) float32
        J, I, W of the 4 vertices of n polygons and the first again. A triangle repeats its
        last vertex: the zero edge has all coefficients 0 and constrains nothing.

    Returns
    -------
    alpha, beta0, beta1 : (K, n) float32
        Edge k is ``E_k(j, i) = alpha_k j + beta1_k i + beta0_k`` (from v_k x v_k+1); inside
        means ``sign(D) E_k >= 0`` for all k.
    det : (n,) float32
        D = n . v0 with n = sum_k v_k x v_k+1, the plane's offset (0 for an edge-on polygon).
    zu, zv, z0 : (n,) float32
        ``1/W = zu j + zv i + z0`` at pixel centres on the polygon's plane.
    """
    j, i, w = verts[:, :4]
    j1, i1, w1 = verts[:, 1:]                                             # v_k+1
    alpha = i * w1
    alpha -= w * i1
    beta1 = w * j1
    beta1 -= j * w1
    beta0 = j * i1
    beta0 -= i * j1
    n_j, n_i, n_w = (c[0] + c[1] + c[2] + c[3] for c in (alpha, beta1, beta0))
    det = n_j * j[0] + n_i * i[0] + n_w * w[0]
    inv = 1 / (det + (det == 0))
    return alpha, beta0, beta1, det, n_j * inv, n_i * inv, n_w * inv


#: Lines excluded from a bound are pushed this far out (float32 max is 3.4e38). Real lines
#: have |K0|, |K1| < 1e30: alpha, a 2 x 2 determinant of float32 pixel coordinates, is either
#: exactly 0 (handled apart) or far above 1e-30 of the betas.
_BIG = _F32(1e36)


def _edge_lines(tab, alpha, beta0, beta1, sgn, r0, r1):
    """Column bounds of the half-planes ``sgn E >= 0`` over rows, written into ``tab``.

    A line with alpha != 0 bounds the columns from below (``sgn alpha > 0``) or above by
    ``j = (beta0 + beta1 i) * -(1/alpha) = K0 + K1 i``. Each edge gets one slope K1 and two
    offsets, the lower (K0 if the line is a lower bound, else K0 - _BIG: out of reach) and the
    upper (K0, else K0 + _BIG), so that a row evaluates the line once for both bounds. Both
    polygons of a shared edge hold the negated line, so they compute bit-identical bounds on
    opposite sides and no pixel is left unclaimed. A line with alpha = 0 (parallel to the
    rows) restricts rows only: folded into [r0, r1] exactly (in place).

    Parameters
    ----------
    tab : (_ITEM_FIELDS + 3 K, n) float32
        Item table; its rows after _ITEM_FIELDS are filled: the K slopes, the K lower offsets,
        the K upper offsets.
    alpha, beta0, beta1 : (K, n) float32
    sgn : (n,) or (K, n) float32
        Side of each half-plane (sign of D; 1 for the near plane).
    r0, r1 : (n,) float32
        Row interval, narrowed in place.
    """
    k = alpha.shape[0]
    k1, k0_low, k0_high = (tab[_ITEM_FIELDS + m * k:_ITEM_FIELDS + (m + 1) * k]
                           for m in range(3))
    nz = alpha != 0
    nia = np.zeros_like(alpha)
    np.divide(-1, alpha, out=nia, where=nz)     # -(1 / alpha) (negation is exact), 0 if flat
    k0 = beta0 * nia
    np.multiply(beta1, nia, out=k1)
    an = np.multiply(alpha, sgn, out=nia)
    pushed = ~(an > 0)                          # not a lower bound (NaN included)
    np.subtract(k0, np.multiply(pushed, _BIG, out=k0_low), out=k0_low)
    np.logical_not(np.less(an, 0, out=pushed), out=pushed)
    np.add(k0, np.multiply(pushed, _BIG, out=k0_high), out=k0_high)
    np.logical_not(nz, out=nz)
    # Edge by edge: one 2-D nonzero, or a modulo of flat indices, costs several times more.
    n = alpha.shape[1]
    items = [np.flatnonzero(flat_edge) for flat_edge in nz]
    item = np.concatenate(items)
    if item.size:
        flat = np.concatenate([row + e * n for e, row in enumerate(items)])
        s = sgn[item] if sgn.ndim == 1 else sgn.ravel()[flat]
        c0, c1 = beta0.ravel()[flat] * s, beta1.ravel()[flat] * s       # c0 + c1 i >= 0
        # Row bound; beyond +-1e9 (or NaN: 0) the item is empty (or unrestricted) either way.
        bound = c0 * -(1 / c1)
        np.minimum(bound, _F32(1e9), out=bound)
        np.maximum(bound, _F32(-1e9), out=bound)
        bound[np.isnan(bound)] = 0
        up, down = c1 > 0, c1 < 0
        np.maximum.at(r0, item[up], np.ceil(bound[up]))
        np.minimum.at(r1, item[down], np.floor(bound[down]))
        r1[item[(c1 == 0) & (c0 < 0)]] = -1


#: Rows per work unit: an item's rows are processed as (slots, n) broadcasts, slots = the mean
#: row count of the group rounded up, within [2, _ROW_SLOTS] (items with more rows continue in
#: extra units); a row's fragments as (_FRAG_SLOTS, n). Room at R = 64: 2.8 rows per item at
#: 2000 quads, 1.2 at 8000 (where 2 slots instead of 4 saved 25 % of the span time); 3.3
#: fragments per row. _FRAG_SLOTS is even, so a fragment's pixel parity (the tie flip) is the
#: parity of its row start plus its slot.
_ROW_SLOTS = 4
_FRAG_SLOTS = 4
_ROW_RANGE = np.arange(_ROW_SLOTS, dtype=_F32)[:, None]

#: Items per block: each block is set up, spanned and drawn on its own, so that its temporaries
#: (a few hundred kB) are recycled by the allocator; whole chunks of ~50k items made the heap
#: grow and shrink by tens of MB per chunk, one page fault per 4 kB (a quarter of the time).
_ITEM_BLOCK = 16384

#: Rows of the item table (float32, one column per item): the last row, buffer cell of the
#: face's pixel (0, 0), the depth plane, the item id + 1; then per edge line its slope and
#: lower and upper offsets (see :func:`_edge_lines`). Values that are integers stay below 2^24
#: (a chunk's buffer cells and items), so float32 holds them exactly.
_R1, _BASE, _Z0, _ZU, _ZV, _ITEM = range(6)
_ITEM_FIELDS = 6

#: Fragment slots past a row's span are not masked out: their 1/W is pushed below zero, so
#: their key is negative and ``np.maximum.at`` ignores them (the z-buffer starts at 0). The
#: push is ``(span - 0.5 - slot) * _POISON``: >= 0.5 _POISON (above any real 1/W, at most
#: 1/near) for a real fragment, <= -0.5 _POISON past the span, finite in float32 for any R.
_POISON = _F32(1e30)
_SLOT_RANGE = np.arange(_FRAG_SLOTS, dtype=_F32)[:, None]
_SLOT_POISON = _SLOT_RANGE * _POISON
_SLOT_INT = np.arange(_FRAG_SLOTS, dtype=np.int64)[:, None]


def _draw_items(zb, verts, face, pair, ps, first_id, sc, *, near_line=False, bbox=None):
    """Rasterise a group of polygon items into the z-buffer, _ITEM_BLOCK items at a time.

    Arguments as :func:`_item_rows`, ``bbox`` (imin (n,), imax (n,)) or None.
    Returns (rows, fragments).
    """
    n_rows = n_frag = 0
    for start in range(0, pair.size, _ITEM_BLOCK):
        block = slice(start, start + _ITEM_BLOCK)
        counts = _item_rows(zb, verts[:, :, block], face[block], pair[block], ps,
                            first_id + start, sc, near_line=near_line,
                            bbox=None if bbox is None else (bbox[0][block], bbox[1][block]))
        n_rows, n_frag = n_rows + counts[0], n_frag + counts[1]
    return n_rows, n_frag


def _item_rows(zb, verts, face, pair, ps, first_id, sc, *, near_line=False, bbox=None):
    """Rasterise a block of polygon items on given faces into the z-buffer.

    Parameters
    ----------
    zb : _ZBuffer
        Where the items are drawn.
    verts : (3, 5, n) float32
        Polygon vertices (J, I, W) in the pixel coordinates of each item's face, the first
        repeated.
    face, pair : (n,) int
        Face and (source, polygon) pair of each item.
    ps : (pairs,) int
        Source (within the chunk) of each pair.
    first_id : int
        Items are numbered first_id + 1 ... first_id + n in the z-buffer (0: empty).
    near_line : bool
        Add the near-plane half-plane ``1/W <= 1/near`` (polygons straddling it).
    bbox : (imin, imax) or None
        Projected row interval (of the near-clipped polygon); default from the vertices.

    Returns
    -------
    (rows, fragments) : (int, int)
        Non-empty row spans and fragments drawn.
    """
    n = pair.size
    if n == 0:
        return 0, 0
    alpha, beta0, beta1, det, zu, zv, z0 = _setup(verts)
    if bbox is None:
        ip = verts[1, :4] / verts[2, :4]
        bbox = (np.minimum.reduce(ip), np.maximum.reduce(ip))
    n_rows = sc.face_rows_f[face]
    r0 = np.ceil(bbox[0] - _ROW_SLACK)
    r0 = np.minimum(np.maximum(r0, 0, out=r0), n_rows).astype(_F32, copy=False)
    r1 = np.floor(bbox[1] + _ROW_SLACK)
    r1 = np.minimum(np.maximum(r1, -1, out=r1), n_rows - 1).astype(_F32, copy=False)
    r1 -= (det == 0) * _F32(1e6)                                          # edge-on: empty
    sgn = np.sign(det)
    if near_line:   # -zu j - zv i + (1/near - z0) >= 0
        alpha = np.concatenate([alpha, -zu[None]])
        beta0 = np.concatenate([beta0, (_F32(1.0 / sc.near) - z0)[None]])
        beta1 = np.concatenate([beta1, -zv[None]])
        sgn = np.concatenate([np.broadcast_to(sgn, (4, n)), np.ones((1, n), sgn.dtype)])
    tab = np.empty((_ITEM_FIELDS + 3 * alpha.shape[0], n), _F32)
    _edge_lines(tab, alpha, beta0, beta1, sgn, r0, r1)
    tab[_R1] = r1
    tab[_BASE] = ps[pair] * sc.npix + sc.face_offset[face]
    tab[_Z0], tab[_ZU], tab[_ZV] = z0, zu, zv
    tab[_ITEM] = np.arange(first_id + 1, first_id + n + 1, dtype=_F32)  # 0: empty pixel
    n_rows = np.maximum(r1 - r0 + 1, 0)
    slots = min(max(math.ceil(n_rows.mean()), 2), _ROW_SLOTS)            # adapt to item size
    counts = _row_slots(zb, r0, tab, sc.r, slots)
    extra = np.ceil(n_rows / slots) - 1                                   # further units
    more = np.flatnonzero(extra > 0)
    if more.size:
        owner, rank, _ = ragged(extra[more])
        idx = more[owner]
        r0c = r0[idx] + _F32(slots) * (rank + 1).astype(_F32)
        more_counts = _row_slots(zb, r0c, np.take(tab, idx, axis=1), sc.r, slots)
        counts = (counts[0] + more_counts[0], counts[1] + more_counts[1])
    return counts


def _row_slots(zb, r0, tab, width, slots):
    """Spans of rows r0 .. r0 + slots - 1 (up to the item's last row), drawn into ``zb``.

    Parameters
    ----------
    zb : _ZBuffer
        Where the spans are drawn.
    r0 : (n,) float32
        First row of each item's unit.
    tab : (_ITEM_FIELDS + 3 K, n) float32
        Item table (see _ITEM_FIELDS and :func:`_edge_lines`).

    Returns (non-empty rows, fragments).
    """
    # Layout (slot, item): the long axis is innermost, so every broadcast runs NumPy's inner
    # loop over thousands of items rather than over a handful of slots.
    k = (tab.shape[0] - _ITEM_FIELDS) // 3
    k1, k0_low, k0_high = (tab[_ITEM_FIELDS + m * k:_ITEM_FIELDS + (m + 1) * k]
                           for m in range(3))
    row = r0 + _ROW_RANGE[:slots]
    # span, pixel, 1/W, 1/W step and item of each (slot, item), compressed to the filled rows
    # in one take.
    work = np.empty((5,) + row.shape, _F32)
    m = np.multiply(k1[0], row)
    j_lo = m + k0_low[0]
    j_hi = np.add(m, k0_high[0], out=work[0])
    b = np.empty_like(m)
    for e in range(1, k):
        np.multiply(k1[e], row, out=m)
        np.add(m, k0_low[e], out=b)
        np.maximum(j_lo, b, out=j_lo)
        np.add(m, k0_high[e], out=b)
        np.minimum(j_hi, b, out=j_hi)
    # Clipping to the face needs no upper limit on j_lo nor lower on j_hi: such spans are
    # empty either way.
    np.ceil(j_lo, out=j_lo)
    np.maximum(j_lo, 0, out=j_lo)
    np.floor(j_hi, out=j_hi)
    np.minimum(j_hi, width - 1, out=j_hi)
    span = j_hi
    span -= j_lo
    span += 1
    ok = np.greater(span, 0)                                              # NaN-safe
    ok &= row <= tab[_R1]
    filled = np.flatnonzero(ok)
    if filled.size == 0:
        return 0, 0
    pix = np.multiply(row, width, out=work[1])
    pix += j_lo
    pix += tab[_BASE]
    z = np.multiply(tab[_ZV], row, out=work[2])
    z += tab[_Z0]
    z += np.multiply(tab[_ZU], j_lo, out=m)
    work[3] = tab[_ZU]
    work[4] = tab[_ITEM]
    span, pix, z, dz, item = np.take(work.reshape(5, -1), filled, axis=1)
    return filled.size, zb.draw(pix, z, dz, item.astype(np.int32), span)


#: Spans per block of fragments: the temporaries of a block (about 16 bytes per fragment slot
#: each) stay in cache and are reused by the allocator instead of being mapped afresh, which
#: costs page faults. Also the number of long spans whose rest is held back (see _ZBuffer).
_FRAG_BLOCK = 16384


class _ZBuffer:
    """The z-buffer of a chunk of hemicubes and the fragments still to be drawn into it.

    Parameters
    ----------
    keys : (S 3 R^2 + _FRAG_SLOTS,) int64
        Cleared keys (see :meth:`_Scene.zbuffer`): high 32 bits the float32 bits of 1/W with
        the low _DEPTH_DROP bits cleared, low 32 bits the item + 1, negated in odd pixel
        columns (see _DEPTH_DROP). ``np.maximum.at`` keeps the nearest per pixel whatever the
        order, so fragments may be drawn in any order.
    timed : bool
        Count the CPU seconds spent drawing in ``seconds``.

    Spans are drawn _FRAG_SLOTS pixels at a time, in the (slot, span) layout; slots past a span
    get a negative key (see _POISON). The rest of longer spans (a sixth of them at R = 64) is
    held back and drawn in units of _FRAG_SLOTS pixels by :meth:`flush`, for all blocks at
    once: that bookkeeping costs about the same per call whatever the number of spans.
    """

    def __init__(self, keys, timed=False):
        self.keys = keys
        self.timed = timed
        self.seconds = 0.0
        self.rest = []                     # (pix, z, dz, low, span) of long spans
        self.n_rest = 0

    def draw(self, pix, z, dz, item, span):
        """Draw non-empty row spans; returns the number of fragments.

        Parameters
        ----------
        pix, z, dz, span : (m,) float32
            Buffer cell and 1/W of the first pixel, 1/W step per pixel, length of each span.
        item : (m,) int32
            Item id + 1 of each span.
        """
        tic = time.process_time() if self.timed else 0.0
        for start in range(0, span.size, _FRAG_BLOCK):
            block = slice(start, start + _FRAG_BLOCK)
            pix_i = pix[block].astype(np.int64)
            low = item[block]
            low = np.where(pix_i & 1, -low, low)
            args = (pix_i, z[block], dz[block], low, span[block])
            _draw_slots(self.keys, *args)
            long_ = np.flatnonzero(args[4] > _FRAG_SLOTS)
            if long_.size:
                self.rest.append(tuple(a[long_] for a in args))
                self.n_rest += long_.size
        if self.timed:
            self.seconds += time.process_time() - tic
        if self.n_rest >= _FRAG_BLOCK:
            self.flush()
        return int(span.sum(dtype=np.float64))

    def flush(self):
        """Draw the held-back rest of long spans."""
        if not self.rest:
            return
        tic = time.process_time() if self.timed else 0.0
        pix_i, z, dz, low, span = (np.concatenate(part) for part in zip(*self.rest))
        self.rest, self.n_rest = [], 0
        for start in range(0, span.size, _FRAG_BLOCK):
            block = slice(start, start + _FRAG_BLOCK)
            # Units of _FRAG_SLOTS pixels after the first (an even step: the same parity).
            units = (np.ceil(span[block] / _F32(_FRAG_SLOTS)) - 1).astype(np.int64)
            owner, rank, _ = ragged(units)
            idx = owner + start
            step = (rank + 1) * _FRAG_SLOTS
            step_f = step.astype(_F32)
            dz_u = dz[idx]
            _draw_slots(self.keys, pix_i[idx] + step, z[idx] + dz_u * step_f, dz_u, low[idx],
                        span[idx] - step_f)
        if self.timed:
            self.seconds += time.process_time() - tic


def _draw_slots(keys, pix, z, dz, low, span):
    """Draw the first _FRAG_SLOTS pixels of spans into the z-buffer ``keys``.

    Parameters
    ----------
    pix : (m,) int64
        Buffer cell of the first pixel.
    z, dz, span : (m,) float32
        1/W of the first pixel, 1/W step per pixel, pixels left in the span.
    low : (m,) int32
        Low key word of the first pixel: item + 1, negated if its cell is odd.
    """
    inv_depth = dz * _SLOT_RANGE
    inv_depth += z
    limit = span - _F32(0.5)
    limit *= _POISON
    np.minimum(inv_depth, np.subtract(limit, _SLOT_POISON), out=inv_depth)
    cell = pix + _SLOT_INT
    if _LITTLE_ENDIAN:   # assemble the two 32-bit halves in place
        words = np.empty(inv_depth.shape + (2,), dtype=np.int32)
        np.bitwise_and(inv_depth.view(np.int32), _DEPTH_MASK, out=words[..., 1])
        words[0::2, :, 0] = low
        np.negative(low, out=words[1::2, :, 0])
        key = words.view(np.int64)
    else:
        depth = (inv_depth.view(np.int32) & _DEPTH_MASK).astype(np.int64) << 32
        key = depth | (np.where(_SLOT_INT & 1, -low, low).astype(np.int64) & _LOW_WORD)
    np.maximum.at(keys, cell.ravel(), key.ravel())


def _chunk_rows(sc, eyes, frames, timings):
    """Form-factor rows of one chunk of sources: (S, 2P)."""
    # Divisions by zero, overflow and NaN are expected and masked throughout (edge-on
    # polygons, lines parallel to the rows, vertices on the eye plane).
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
        return _chunk_rows_raw(sc, eyes, frames, timings)


def _chunk_rows_raw(sc, eyes, frames, timings):
    """:func:`_chunk_rows` with floating-point warnings already silenced."""
    tic = time.process_time()
    s_n = eyes.shape[0]
    near, h = sc.near, sc.h
    n_u = sc.verts.shape[0]
    tv = sc.poly_v

    # 1. Unique vertices in every eye frame (S, U); each vertex is classified once per source
    # into the face whose pyramid holds it (-1: below the horizon or nearer than the near
    # plane) and given pixel coordinates on that face.
    # einsum, not matmul: BLAS would run these thin products on several threads.
    eye_c = np.einsum("sij,sj->si", frames, eyes)
    # float32 from here: relative 6e-8 of the scene size is far below a pixel's footprint.
    vx, vy, vz = ((np.einsum("sj,ju->su", frames[:, k], sc.verts_t) - eye_c[:, k:k + 1])
                  .astype(_F32) for k in range(3))
    pj, pi, pw, face = _pixel_coords(vx, vy, vz, None, h)
    ok = (pw >= near) & (vz >= 0)
    cls = ((face + 1) * ok - 1).astype(np.int8).ravel()
    pjiw = np.stack([pj.ravel(), pi.ravel(), pw.ravel()])                # (3, S U)

    # Pairs: not wholly below the near plane, not edge-on, optionally not back-facing.
    top_z = np.maximum.reduce([np.take(vz, tv[:, k], axis=1) for k in range(4)])
    dist = np.einsum("sj,jq->sq", eyes, sc.plane_n_t) - sc.plane_c        # eye above plane
    keep = (top_z >= near) & (dist != 0.0)
    if sc.cull_back:
        keep &= dist > 0.0
    ps, pt = np.nonzero(keep)
    back = dist[ps, pt] < 0.0
    # (5, pairs) flat vertex ids; take keeps the result C-ordered (a[:, idx] would not, and
    # reductions over its first axis would then run a 4-long inner loop per pair).
    vid = ps * n_u + np.take(sc.poly_v_t, pt, axis=1)
    c0 = cls[vid[0]]
    single = (c0 == cls[vid[1]]) & (c0 == cls[vid[2]]) & (c0 == cls[vid[3]]) & (c0 >= 0)
    q_fast = np.flatnonzero(single)
    q_gen = np.flatnonzero(~single)
    t1 = time.process_time()

    # 2. Items. Polygons inside one face's pyramid (convex) go to that face only. The others
    # are tested against every face: wholly in front of its near plane -> the same rasteriser
    # (the face's bounds crop them), straddling it -> clipped (general items).
    verts = np.take(pjiw, np.take(vid, q_fast, axis=1), axis=1)           # (3, 5, n)
    face = c0[q_fast].astype(np.int64)
    (face_s, pair_s, verts_s), general = _split_general(
        sc, np.take(vid, q_gen, axis=1), q_gen, vx.ravel(), vy.ravel(), vz.ravel())
    t2 = time.process_time()

    # 3. Row spans, drawn into the z-buffer as they are made (4.). Items are numbered in the
    # order of item_pair (the tie rule depends on it).
    zb = _ZBuffer(sc.zbuffer(s_n), timed=timings is not None)
    n_rows, n_frag = _draw_items(zb, verts, face, q_fast, ps, 0, sc)
    n = _draw_items(zb, verts_s, face_s, pair_s, ps, q_fast.size, sc)
    n_rows, n_frag = n_rows + n[0], n_frag + n[1]
    item_pair = [q_fast, pair_s]
    zb_spans = zb.seconds
    t3 = time.process_time()
    if general is not None:
        face_g, pair_g, verts_g, bbox = general
        n = _draw_items(zb, verts_g, face_g, pair_g, ps, q_fast.size + pair_s.size, sc,
                        near_line=True, bbox=bbox)
        n_rows, n_frag = n_rows + n[0], n_frag + n[1]
        item_pair.append(pair_g)
    item_pair = np.concatenate(item_pair)
    zb.flush()
    t4 = time.process_time()
    # The z-buffer is drawn while spans are made: reported apart.
    t3, t4 = t3 - zb_spans, t4 - zb.seconds
    t5 = t4 + zb.seconds

    # 5. Accumulate delta form factors per item, then items into their (source, node) cell.
    # |low word of a key| is the item (negated in odd cells for the tie rule; 0: empty).
    n_cols = 2 * sc.n_patches
    n_cells = s_n * sc.npix
    low = zb.keys.view(np.int32)[0 if _LITTLE_ENDIAN else 1::2][:n_cells]
    per_item = np.bincount(np.abs(low).astype(np.intp), weights=sc.tiled(s_n),
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


def _split_general(sc, vid, q_gen, vx, vy, vz):
    """Sort the pairs ``q_gen`` (not inside one pyramid) onto faces.

    Parameters
    ----------
    sc : _Scene
    vid : (5, g) int
        Flat vertex ids (source * U + vertex) of the pairs' corners, the first repeated.
    q_gen : (g,) int
        The pairs.
    vx, vy, vz : (S U,) float32
        Eye-frame coordinates of the chunk's vertices.

    Returns
    -------
    items : (face (n,), pair (n,), verts (3, 5, n))
        Items wholly in front of their face's near plane and overlapping the face (the
        rasteriser crops them to the face), face by face.
    general : (face (m,), pair (m,), verts (3, 5, m), (imin (m,), imax (m,))) or None
        Items straddling their face's near plane and overlapping the face once clipped there,
        with the projected row interval of the clipped polygon.
    """
    near, h, width = sc.near, sc.h, sc.r
    xyz = (vx[vid], vy[vid], vz[vid])                                     # (5, g) each
    items, general = [], []
    for face in range(5):
        n_rows = float(sc.face_rows[face])
        jiw = np.stack(_pixel_coords(*xyz, face, h))                      # (3, 5, g)
        w = jiw[2]
        wmin, wmax = np.minimum.reduce(w), np.maximum.reduce(w)
        front = np.flatnonzero(wmin >= near)
        sub = np.take(jiw, front, axis=2)
        pj = sub[0] / sub[2]
        pi = sub[1] / sub[2]
        hit = (np.minimum.reduce(pj) <= width - 0.5) & (np.maximum.reduce(pj) >= -0.5) \
            & (np.minimum.reduce(pi) <= n_rows - 0.5) & (np.maximum.reduce(pi) >= -0.5)
        sel = np.flatnonzero(hit)
        items.append((np.full(sel.size, face, dtype=np.int64), q_gen[front[sel]],
                      np.take(sub, sel, axis=2)))
        cut = np.flatnonzero((wmin < near) & (wmax >= near))
        if cut.size:
            sub = np.take(jiw, cut, axis=2)
            # Most of these (polygons crossing the eye's plane, seen through the sides) lie
            # wholly beyond one of the planes through the eye and the face's borders: dropped
            # before clipping, with a margin far above rounding so that the clipped test
            # below would drop them too.
            j, i, w = sub[:, :4]
            margin = _F32(_PYRAMID_MARGIN) * np.maximum.reduce(np.abs(j) + np.abs(i) + np.abs(w))
            beyond = (np.maximum.reduce(j + 0.5 * w) < -margin) \
                | (np.minimum.reduce(j - (width - 0.5) * w) > margin) \
                | (np.maximum.reduce(i + 0.5 * w) < -margin) \
                | (np.minimum.reduce(i - (n_rows - 0.5) * w) > margin)
            near_cut = np.flatnonzero(~beyond)
            cut, sub = cut[near_cut], np.take(sub, near_cut, axis=2)
            lo, hi = _clipped_bbox(sub, near)
            hit = (lo[0] <= width - 0.5) & (hi[0] >= -0.5) \
                & (lo[1] <= n_rows - 0.5) & (hi[1] >= -0.5)
            keep = np.flatnonzero(hit)
            if keep.size:
                general.append((np.full(keep.size, face, dtype=np.int64), q_gen[cut[keep]],
                                np.take(sub, keep, axis=2), lo[1][keep], hi[1][keep]))
    items = tuple(np.concatenate(part, axis=-1) for part in zip(*items))
    if not general:
        return items, None
    face, pair, verts, lo, hi = (np.concatenate(part, axis=-1) for part in zip(*general))
    return items, (face, pair, verts, (lo, hi))


#: Relative margin (of a polygon's largest |J| + |I| + |W|) by which all its corners must lie
#: beyond a plane of a face's pyramid for it to be dropped from that face unclipped; float32
#: rounding of the clipped bounding box is ~1e-6 of that.
_PYRAMID_MARGIN = 1e-4


def _clipped_bbox(verts, near):
    """Projected bounding box (lo (J, I), hi (J, I)) of polygons clipped at W = near, float64.

    ``verts``: (3, 5, n) (J, I, W) of the corners, the first repeated; at least one corner is
    in front. The clipped polygon's corners are the front corners and the crossings of the
    edges with the near plane (at W = near exactly, so projected by dividing by near).
    """
    a, b = verts[:, :4], verts[:, 1:]                                     # edge k: a -> b
    front_a, front_b = a[2] >= near, b[2] >= near
    crosses = front_a != front_b
    t = (near - a[2]) / (b[2] - a[2])
    lo, hi = [], []
    for c in range(2):
        proj = np.where(front_a, a[c] / a[2], np.nan)
        cut = np.where(crosses, (a[c] + t * (b[c] - a[c])) / near, np.nan)
        lo.append(np.fmin.reduce(np.fmin(proj, cut)).astype(np.float64))
        hi.append(np.fmax.reduce(np.fmax(proj, cut)).astype(np.float64))
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
    # deferred: keeps this module importable alone
    from .patches import patch_triangles, triangle_mask

    corners = np.asarray(patches.corners, dtype=np.float64)
    e1, e2, e3 = (corners[:, k] - corners[:, 0] for k in (1, 2, 3))
    n = np.cross(e1, e2)
    other = corners[:, 3] - corners[:, 1]
    diagonal = np.maximum(np.linalg.norm(e2, axis=1), np.linalg.norm(other, axis=1))
    length = np.linalg.norm(n, axis=1)
    off_plane = np.abs(np.sum(e3 * n, axis=1)) / np.where(length > 0, length, 1.0)
    edges = np.roll(corners, -1, axis=1) - corners
    turns = np.einsum("qkj,qj->qk", np.cross(edges, np.roll(edges, -1, axis=1)), n)
    is_quad = ~triangle_mask(corners)
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
    if points.shape[0] == 0:
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
    _prime_allocator()
    chunk = max(1, min(_CHUNK_PAIRS // sc.poly_v.shape[0], _CHUNK_PIXELS // sc.npix))
    for start in range(0, eyes.shape[0], chunk):
        stop = min(start + chunk, eyes.shape[0])
        out[start:stop] = _chunk_rows(sc, eyes[start:stop], frames[start:stop], timings)


#: A chunk allocates and frees some 20 MB of temporaries. glibc's malloc returns freed memory
#: at the top of its heap to the system once more than its trim threshold (initially 128 kB)
#: is free there, and every chunk then pays a page fault per 4 kB to get it back: a fifth of
#: the run time at R = 64. glibc raises that threshold to twice the size of any freed block
#: it had mapped apart (up to 32 MB, see mallopt(3), M_MMAP_THRESHOLD), so freeing one such
#: block once keeps the chunks' memory in the process. Elsewhere (another malloc) it only
#: costs one allocation.
_ALLOCATOR_PRIME_BYTES = 16 << 20
_PRIMED = []


def _prime_allocator():
    """Allocate and free one _ALLOCATOR_PRIME_BYTES block, once per process."""
    if not _PRIMED:
        np.empty(_ALLOCATOR_PRIME_BYTES, dtype=np.uint8)
        _PRIMED.append(True)


#: The polygons and geometry of the last Patches object seen (by identity, weakly held): a bake
#: asks for rows batch after batch of the same patches, and this setup (draw_polygons, distinct
#: corners, planes) costs as much as several hemicubes. Patches are immutable by contract.
_CACHE = {}
