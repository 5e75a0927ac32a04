"""The hemicube rasteriser: polygons into z-buffered item buffers, pixels into form factors.

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
   block's spans are drawn as soon as they are made, FRAG_SLOTS pixels per span in one
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
import time

import numpy as np

from .geometry import ragged

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

#: Slack (in rows) added to bounding rows so that float32 rounding of the projected vertices
#: (relative 1e-7 of up to R rows) never drops a row that the exact span test would fill;
#: extra rows simply get empty spans.
_ROW_SLACK = 1e-3

LITTLE_ENDIAN = sys.byteorder == "little"

#: Working precision of the rasteriser (see the module docstring).
F32 = np.float32


def pixel_coords(x, y, z, face, h):
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
_BIG = F32(1e36)


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
        np.minimum(bound, F32(1e9), out=bound)
        np.maximum(bound, F32(-1e9), out=bound)
        bound[np.isnan(bound)] = 0
        up, down = c1 > 0, c1 < 0
        np.maximum.at(r0, item[up], np.ceil(bound[up]))
        np.minimum.at(r1, item[down], np.floor(bound[down]))
        r1[item[(c1 == 0) & (c0 < 0)]] = -1


#: Rows per work unit: an item's rows are processed as (slots, n) broadcasts, slots = the mean
#: row count of the group rounded up, within [2, _ROW_SLOTS] (items with more rows continue in
#: extra units); a row's fragments as (FRAG_SLOTS, n). Room at R = 64: 2.8 rows per item at
#: 2000 quads, 1.2 at 8000 (where 2 slots instead of 4 saved 25 % of the span time); 3.3
#: fragments per row. FRAG_SLOTS is even, so a fragment's pixel parity (the tie flip) is the
#: parity of its row start plus its slot.
_ROW_SLOTS = 4
FRAG_SLOTS = 4
_ROW_RANGE = np.arange(_ROW_SLOTS, dtype=F32)[:, None]

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
_POISON = F32(1e30)
_SLOT_RANGE = np.arange(FRAG_SLOTS, dtype=F32)[:, None]
_SLOT_POISON = _SLOT_RANGE * _POISON
_SLOT_INT = np.arange(FRAG_SLOTS, dtype=np.int64)[:, None]


def draw_items(zb, verts, face, pair, ps, first_id, sc, *, near_line=False, bbox=None):
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
    zb : ZBuffer
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
    r0 = np.minimum(np.maximum(r0, 0, out=r0), n_rows).astype(F32, copy=False)
    r1 = np.floor(bbox[1] + _ROW_SLACK)
    r1 = np.minimum(np.maximum(r1, -1, out=r1), n_rows - 1).astype(F32, copy=False)
    r1 -= (det == 0) * F32(1e6)                                          # edge-on: empty
    sgn = np.sign(det)
    if near_line:   # -zu j - zv i + (1/near - z0) >= 0
        alpha = np.concatenate([alpha, -zu[None]])
        beta0 = np.concatenate([beta0, (F32(1.0 / sc.near) - z0)[None]])
        beta1 = np.concatenate([beta1, -zv[None]])
        sgn = np.concatenate([np.broadcast_to(sgn, (4, n)), np.ones((1, n), sgn.dtype)])
    tab = np.empty((_ITEM_FIELDS + 3 * alpha.shape[0], n), F32)
    _edge_lines(tab, alpha, beta0, beta1, sgn, r0, r1)
    tab[_R1] = r1
    tab[_BASE] = ps[pair] * sc.npix + sc.face_offset[face]
    tab[_Z0], tab[_ZU], tab[_ZV] = z0, zu, zv
    tab[_ITEM] = np.arange(first_id + 1, first_id + n + 1, dtype=F32)  # 0: empty pixel
    n_rows = np.maximum(r1 - r0 + 1, 0)
    slots = min(max(math.ceil(n_rows.mean()), 2), _ROW_SLOTS)            # adapt to item size
    counts = _row_slots(zb, r0, tab, sc.r, slots)
    extra = np.ceil(n_rows / slots) - 1                                   # further units
    more = np.flatnonzero(extra > 0)
    if more.size:
        owner, rank, _ = ragged(extra[more])
        idx = more[owner]
        r0c = r0[idx] + F32(slots) * (rank + 1).astype(F32)
        more_counts = _row_slots(zb, r0c, np.take(tab, idx, axis=1), sc.r, slots)
        counts = (counts[0] + more_counts[0], counts[1] + more_counts[1])
    return counts


def _row_slots(zb, r0, tab, width, slots):
    """Spans of rows r0 .. r0 + slots - 1 (up to the item's last row), drawn into ``zb``.

    Parameters
    ----------
    zb : ZBuffer
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
    work = np.empty((5,) + row.shape, F32)
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
#: costs page faults. Also the number of long spans whose rest is held back (see ZBuffer).
_FRAG_BLOCK = 16384


class ZBuffer:
    """The z-buffer of a chunk of hemicubes and the fragments still to be drawn into it.

    Parameters
    ----------
    keys : (S 3 R^2 + FRAG_SLOTS,) int64
        Cleared keys (see :meth:`Scene.zbuffer`): high 32 bits the float32 bits of 1/W with
        the low _DEPTH_DROP bits cleared, low 32 bits the item + 1, negated in odd pixel
        columns (see _DEPTH_DROP). ``np.maximum.at`` keeps the nearest per pixel whatever the
        order, so fragments may be drawn in any order.
    timed : bool
        Count the CPU seconds spent drawing in ``seconds``.

    Spans are drawn FRAG_SLOTS pixels at a time, in the (slot, span) layout; slots past a span
    get a negative key (see _POISON). The rest of longer spans (a sixth of them at R = 64) is
    held back and drawn in units of FRAG_SLOTS pixels by :meth:`flush`, for all blocks at
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
            long_ = np.flatnonzero(args[4] > FRAG_SLOTS)
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
            # Units of FRAG_SLOTS pixels after the first (an even step: the same parity).
            units = (np.ceil(span[block] / F32(FRAG_SLOTS)) - 1).astype(np.int64)
            owner, rank, _ = ragged(units)
            idx = owner + start
            step = (rank + 1) * FRAG_SLOTS
            step_f = step.astype(F32)
            dz_u = dz[idx]
            _draw_slots(self.keys, pix_i[idx] + step, z[idx] + dz_u * step_f, dz_u, low[idx],
                        span[idx] - step_f)
        if self.timed:
            self.seconds += time.process_time() - tic


def _draw_slots(keys, pix, z, dz, low, span):
    """Draw the first FRAG_SLOTS pixels of spans into the z-buffer ``keys``.

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
    limit = span - F32(0.5)
    limit *= _POISON
    np.minimum(inv_depth, np.subtract(limit, _SLOT_POISON), out=inv_depth)
    cell = pix + _SLOT_INT
    if LITTLE_ENDIAN:   # assemble the two 32-bit halves in place
        words = np.empty(inv_depth.shape + (2,), dtype=np.int32)
        np.bitwise_and(inv_depth.view(np.int32), _DEPTH_MASK, out=words[..., 1])
        words[0::2, :, 0] = low
        np.negative(low, out=words[1::2, :, 0])
        key = words.view(np.int64)
    else:
        depth = (inv_depth.view(np.int32) & _DEPTH_MASK).astype(np.int64) << 32
        key = depth | (np.where(_SLOT_INT & 1, -low, low).astype(np.int64) & _LOW_WORD)
    np.maximum.at(keys, cell.ravel(), key.ravel())
