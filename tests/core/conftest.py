"""Scene builders shared by the core tests (import them: ``from conftest import grid``)."""

import numpy as np


def grid(origin, a, b, n, *, flip=False):
    """An n x n grid of quads spanning ``origin + s a + t b`` (s, t in [0, 1]).

    Returns
    -------
    verts : ((n + 1)^2, 3) float64
        Vertex ``i (n + 1) + j`` at ``origin + (i / n) a + (j / n) b``.
    quads : list of n^2 lists of 4 ints
        Counter-clockwise about ``a x b`` (clockwise with ``flip``), shared vertices.
    """
    origin, a, b = (np.asarray(v, dtype=np.float64) for v in (origin, a, b))
    t = np.linspace(0.0, 1.0, n + 1)
    verts = (origin + t[:, None, None] * a + t[None, :, None] * b).reshape(-1, 3)
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    quads = np.stack([idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]], -1).reshape(-1, 4)
    if flip:
        quads = quads[:, ::-1]
    return verts, quads.tolist()


def horizontal_square(z, size, n, *, down=False, x0=0.0):
    """``grid`` of the square [x0, x0 + size]^2 at height z, normal +z (-z if ``down``)."""
    return grid((x0, x0, z), (size, 0, 0), (0, size, 0), n, flip=down)
