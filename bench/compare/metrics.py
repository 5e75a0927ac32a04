"""Error metrics between two bakes of the same mesh.

Per-face value = the plain mean of the face's corner colours (both Cycles and our engine write one
colour per corner; the mean of a face's corners is what a viewer sees on average over the face for
a bilinear/flat interpolation and is the same statistic for both bakes). Error = area-weighted
relative RMS over faces, emitters excluded, and the area-weighted 95th percentile of the per-face
relative error. Relative error of a face = |test - ref| / ref on the face's luminance, so a face's
error is not dominated by a dark channel.
"""

import numpy as np

#: Rec. 709 / sRGB luminance weights of linear RGB (Blender's scene-linear default).
LUMINANCE_WEIGHTS = np.array([0.2126, 0.7152, 0.0722])

#: Faces whose reference luminance is below this fraction of the area-weighted mean reference
#: luminance are left out of the relative error: a relative error of ~0 / ~0 (e.g. a face in a
#: closed cupboard) says nothing about accuracy and would dominate the RMS. 1e-3 of the mean is far
#: below any lit architectural surface (indirect-only areas of a room are > 1e-2 of the mean).
DARK_FRACTION = 1e-3


def _as_array(name, value, ndim, last=None):
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim != ndim or (last is not None and arr.shape[-1] != last):
        want = "(n, %d)" % last if last is not None else "%d-D" % ndim
        raise ValueError("%s must have shape %s; got %s" % (name, want, arr.shape))
    if not np.all(np.isfinite(arr)):
        raise ValueError("%s must be finite; got NaN or inf" % name)
    return arr


def face_values(corner_colours, face_starts, face_sizes):
    """Mean of each face's corner colours.

    Parameters
    ----------
    corner_colours : (C, 3) float
        One colour per corner (Blender loop).
    face_starts, face_sizes : (F,) int
        First corner and corner count of each face (Blender ``loop_start``, ``loop_total``).

    Returns
    -------
    (F, 3) float64
    """
    cc = _as_array("corner_colours", corner_colours, 2, 3)
    starts = np.asarray(face_starts, dtype=np.int64)
    sizes = np.asarray(face_sizes, dtype=np.int64)
    if starts.ndim != 1 or sizes.shape != starts.shape:
        raise ValueError("face_starts and face_sizes must be (F,) of equal length; got %s and %s"
                         % (starts.shape, sizes.shape))
    if starts.size == 0:
        raise ValueError("face_starts must not be empty")
    if np.any(sizes < 1) or np.any(starts < 0) or np.any(starts + sizes > len(cc)):
        raise ValueError("face_starts/face_sizes must index into corner_colours of length %d"
                         % len(cc))
    face = np.repeat(np.arange(len(starts)), sizes)
    within = np.arange(len(face)) - np.repeat(np.cumsum(sizes) - sizes, sizes)
    corner = np.repeat(starts, sizes) + within
    out = np.stack([np.bincount(face, weights=cc[corner, k], minlength=len(starts))
                    for k in range(3)], axis=1)
    return out / sizes[:, None]


def luminance(rgb):
    """Luminance of linear RGB rows: (n, 3) -> (n,)."""
    return _as_array("rgb", rgb, 2, 3) @ LUMINANCE_WEIGHTS


def _face_errors(test, reference, weights, mask):
    """The faces compared and their errors: (indices (k,), relative errors (k,), weights (k,)
    summing to 1). Faces outside ``mask``, of zero area, or darker than ``DARK_FRACTION`` x the
    mean reference luminance are left out."""
    t = luminance(test)
    r = luminance(reference)
    w = _as_array("weights", weights, 1)
    if len(t) != len(r) or len(w) != len(r):
        raise ValueError("test, reference and weights must have the same length; got %d, %d, %d"
                         % (len(t), len(r), len(w)))
    if np.any(w < 0):
        raise ValueError("weights must be >= 0")
    keep = np.ones(len(r), dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
    if keep.shape != r.shape:
        raise ValueError("mask must have shape (%d,); got %s" % (len(r), keep.shape))
    keep = keep & (w > 0)
    if not np.any(keep):
        raise ValueError("no face left to compare (mask and weights exclude every face)")
    mean_ref = np.sum(w[keep] * r[keep]) / np.sum(w[keep])
    keep &= r > DARK_FRACTION * mean_ref
    idx = np.flatnonzero(keep)
    return idx, (t[idx] - r[idx]) / r[idx], w[idx] / np.sum(w[idx])


def relative_errors(test, reference, weights, mask=None):
    """Area-weighted relative RMS and 95th percentile of per-face luminance errors.

    Parameters
    ----------
    test, reference : (F, 3) float
        Per-face colours of the bake under test and of the reference.
    weights : (F,) float
        Face areas (m^2), the weights of the RMS and of the percentile.
    mask : (F,) bool, optional
        Faces to include (e.g. not emitters). Default: all. Faces darker than
        ``DARK_FRACTION`` x the mean reference luminance are also left out.

    Returns
    -------
    dict
        ``rms`` (relative, 0.01 = 1 %), ``p95`` (relative), ``bias`` (area-weighted mean of the
        signed relative error), ``faces`` (number of faces used).
    """
    idx, rel, ww = _face_errors(test, reference, weights, mask)
    rms = float(np.sqrt(np.sum(ww * rel ** 2)))
    return {"rms": rms, "p95": weighted_quantile(np.abs(rel), ww, 0.95),
            "bias": float(np.sum(ww * rel)), "faces": int(idx.size)}


def reference_noise(seeds, weights, mask=None):
    """Noise of the mean of independent bakes (seeds), as the relative RMS error it carries.

    Per face: the sample variance of the seeds' luminance over N - 1, divided by N (the variance
    of their mean), relative to the mean's luminance; then area-weighted like
    :func:`relative_errors`. For two seeds this is |a - b| / 2 per face.

    Parameters
    ----------
    seeds : (N, F, 3) float
        Per-face colours of N >= 2 bakes that differ only in their seed.
    weights : (F,) float
    mask : (F,) bool, optional

    Returns
    -------
    dict
        ``rms``, ``p95`` (relative noise of the mean), ``faces``, ``seeds``.
    """
    x = np.asarray(seeds, dtype=np.float64)
    if x.ndim != 3 or x.shape[0] < 2 or x.shape[2] != 3:
        raise ValueError("seeds must have shape (N >= 2, F, 3); got %s" % (x.shape,))
    n = x.shape[0]
    mean = x.mean(axis=0)
    lum = np.stack([luminance(s) for s in x])
    sd_mean = np.sqrt(lum.var(axis=0, ddof=1) / n)
    idx, _, ww = _face_errors(mean, mean, weights, mask)
    rel = sd_mean[idx] / luminance(mean)[idx]
    return {"rms": float(np.sqrt(np.sum(ww * rel ** 2))),
            "p95": weighted_quantile(rel, ww, 0.95), "faces": int(idx.size), "seeds": n}


def concentration(test, reference, weights, mask=None, top=20):
    """How much of the squared error a few faces carry.

    Parameters as :func:`relative_errors`; ``top`` faces with the largest area-weighted squared
    relative error are set apart.

    Returns
    -------
    dict
        ``share`` (their fraction of the mean square), ``area`` (their fraction of the area
        compared), ``rms_rest`` (the RMS over the other faces), ``faces`` (their indices).
    """
    idx, rel, ww = _face_errors(test, reference, weights, mask)
    ms = ww * rel ** 2
    order = np.argsort(-ms, kind="stable")
    k = min(int(top), idx.size)
    head, rest = order[:k], order[k:]
    share = float(ms[head].sum() / ms.sum()) if ms.sum() > 0 else 0.0
    rest_w = ww[rest].sum()
    rms_rest = float(np.sqrt(ms[rest].sum() / rest_w)) if rest_w > 0 else 0.0
    return {"share": share, "area": float(ww[head].sum()), "rms_rest": rms_rest,
            "faces": idx[head]}


def weighted_quantile(values, weights, q):
    """Quantile of ``values`` (n,) under ``weights`` (n,): smallest v with weight(<= v) >= q."""
    v = _as_array("values", values, 1)
    w = _as_array("weights", weights, 1)
    if not 0.0 <= q <= 1.0:
        raise ValueError("q must be in [0, 1]; got %r" % q)
    order = np.argsort(v, kind="stable")
    cw = np.cumsum(w[order])
    i = int(np.searchsorted(cw, q * cw[-1] * (1 - 1e-12)))
    return float(v[order][min(i, len(v) - 1)])


def pareto_front(times, errors):
    """Indices of the runs that no other run beats on both time and error.

    Parameters
    ----------
    times, errors : (n,) float

    Returns
    -------
    (k,) int64
        Indices on the front, in order of increasing time.
    """
    t = _as_array("times", times, 1)
    e = _as_array("errors", errors, 1)
    if t.shape != e.shape:
        raise ValueError("times and errors must have the same shape; got %s and %s"
                         % (t.shape, e.shape))
    order = np.lexsort((e, t))
    best = np.minimum.accumulate(e[order])
    # A run is on the front if its error is strictly below every faster (or equally fast) run.
    prev = np.concatenate([[np.inf], best[:-1]])
    return order[e[order] < prev].astype(np.int64)


def time_to_reach(times, errors, target):
    """Least wall time among runs with error <= target, or inf when none reaches it."""
    t = _as_array("times", times, 1)
    e = _as_array("errors", errors, 1)
    ok = e <= target
    return float(t[ok].min()) if np.any(ok) else float("inf")
