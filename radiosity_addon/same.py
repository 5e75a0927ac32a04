"""What Relight compares: a value of the re-read scene against the kept bake's, and the kept
lights against the scene's (one factor per colour channel, or a cast again)."""

import numpy as np

#: Two values of a re-read scene are "unchanged" within this relative difference (float32 at the
#: Blender boundary; the lights' factor is one per colour channel for all of them).
SAME_RTOL = 1e-5


def same(a, b):
    """Whether two values of an extraction (arrays, dataclasses, lists, plain values) are
    the same, float arrays within :data:`SAME_RTOL`."""
    if a is None or b is None:
        return a is None and b is None
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        if a.shape != b.shape:
            return False
        if a.dtype.kind in "fc":
            return bool(np.allclose(a, b, rtol=SAME_RTOL, atol=SAME_RTOL * 1e-3))
        return bool(np.array_equal(a, b))
    if hasattr(a, "__dataclass_fields__"):
        return type(a) is type(b) and all(same(getattr(a, f), getattr(b, f))
                                          for f in a.__dataclass_fields__)
    if isinstance(a, (list, tuple)):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b))
    if hasattr(a, "__dict__") and not isinstance(a, type):
        return type(a) is type(b) and same(sorted(vars(a).items()), sorted(vars(b).items()))
    return a == b


def lights_factor(old, new):
    """(3,) factor per colour channel from the lights ``old`` to ``new`` when they differ by
    one common factor per channel (power and colour scaled alike), else None (cast again)."""
    if old is None or not len(old):
        return np.ones(3) if new is None or not len(new) else None
    if new is None or not len(new):
        return np.zeros(3)                    # every light deleted: the old ones at 0
    if len(old) != len(new) or list(old.names) != list(new.names):
        return None
    for f in old.__dataclass_fields__:
        if f not in ("intensity", "sun_irradiance") and not same(getattr(old, f),
                                                                 getattr(new, f)):
            return None
    a = np.concatenate([old.intensity, old.sun_irradiance]).reshape(-1, 3)
    b = np.concatenate([new.intensity, new.sun_irradiance]).reshape(-1, 3)
    factor = np.ones(3)
    for c in range(3):
        on = a[:, c] > 0
        if np.any(b[~on, c] > 0):
            return None
        if on.any():
            ratio = b[on, c] / a[on, c]
            if not np.allclose(ratio, ratio[0], rtol=SAME_RTOL):
                return None
            factor[c] = ratio[0]
    return factor
