"""Argument checks shared by the core's public functions.

Each check returns the value in the form the caller computes with, or raises ``ValueError`` /
``TypeError`` whose message names the argument, what was expected and what came (house style).
Domain-specific checks (a scene's arrays, a settings row) live with their data
(:mod:`core.scene`, :mod:`core.settings`) and use these.
"""

import numpy as np


def is_int(value):
    """True for Python and NumPy integers, not bools."""
    return isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))


def is_real(value):
    """True for finite Python and NumPy reals, not bools."""
    return isinstance(value, (int, float, np.integer, np.floating)) and \
        not isinstance(value, (bool, np.bool_)) and bool(np.isfinite(value))


def is_bool(value):
    """True for Python and NumPy bools."""
    return isinstance(value, (bool, np.bool_))


def check_bool(name, value):
    """``value`` as a bool; TypeError naming ``name`` if it is not one."""
    if not is_bool(value):
        raise TypeError(f"{name} must be a bool; got {type(value).__name__}")
    return bool(value)


def check_sources(sources, n_nodes):
    """Node ids (S,) int64 in [0, n_nodes), from any 1-D integer array_like.

    Raises
    ------
    ValueError
        Not 1-D, or an id out of range (the first one is named with its index).
    TypeError
        Not integers.
    """
    src = np.asarray(sources)
    if src.ndim != 1:
        raise ValueError(f"sources must be a 1-D array of integer node ids; got shape "
                         f"{src.shape}")
    if src.size == 0:
        return src.astype(np.int64)
    if not np.issubdtype(src.dtype, np.integer):
        raise TypeError(f"sources must hold integer node ids; got dtype {src.dtype}")
    bad = (src < 0) | (src >= n_nodes)
    if bad.any():
        i = int(np.argmax(bad))
        raise ValueError(f"sources must be node ids in [0, {n_nodes}); got {int(src[i])} at "
                         f"index {i}")
    return src.astype(np.int64)
