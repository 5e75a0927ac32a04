"""Scene builders shared by the core tests: ``from builders import grid``.

A plain module, not conftest.py: test modules cannot import a conftest by name when another
directory's conftest (tests/addon) is collected in the same run (both are module "conftest").
"""

from types import SimpleNamespace

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


def quad_patches(corners):
    """A Patches-like object from (P, 4, 3) corners (a triangle repeats its last corner)."""
    corners = np.asarray(corners, dtype=float)
    v = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]) \
        + np.cross(corners[:, 2] - corners[:, 0], corners[:, 3] - corners[:, 0])
    length = np.linalg.norm(v, axis=1)
    return SimpleNamespace(corners=corners, centres=corners.mean(axis=1),
                           normals=v / length[:, None], areas=0.5 * length)


def centred_square(cx, cy, z, size, facing_up=True):
    """Axis-aligned square in the plane z, normal +z (or -z)."""
    s = 0.5 * size
    c = np.array([[cx - s, cy - s, z], [cx + s, cy - s, z], [cx + s, cy + s, z],
                  [cx - s, cy + s, z]])
    return c if facing_up else c[::-1]


def box_quads(dims, cell):
    """Closed box [0, dims], inward normals, conforming grid of about ``cell`` metres.

    Returns corners (P, 4, 3) and the box face (0..5: x=0, x=max, y=0, y=max, z=0, z=max).
    """
    quads, face = [], []
    for axis in range(3):
        a, b = [k for k in range(3) if k != axis]
        ga = np.linspace(0, dims[a], int(round(dims[a] / cell)) + 1)
        gb = np.linspace(0, dims[b], int(round(dims[b] / cell)) + 1)
        for side in (0, 1):
            for i in range(ga.size - 1):
                for j in range(gb.size - 1):
                    q = np.zeros((4, 3))
                    q[:, axis] = side * dims[axis]
                    q[:, a] = [ga[i], ga[i + 1], ga[i + 1], ga[i]]
                    q[:, b] = [gb[j], gb[j], gb[j + 1], gb[j + 1]]
                    inward = 1 if side == 0 else -1
                    if np.cross(q[1] - q[0], q[2] - q[0])[axis] * inward < 0:
                        q = q[::-1]
                    quads.append(q)
                    face.append(2 * axis + side)
    return np.array(quads), np.array(face)


def floor_field(mesh, points):
    """Linear interpolation of the OutputMesh corner colours at points on z = 0: (S, 3)."""
    tris = []
    for k in (1, 2):                                   # (0, k, k + 1) of every face
        s = mesh.face_starts[mesh.face_sizes >= k + 2]
        tris.append(np.stack([s, s + k, s + k + 1], axis=1))
    tris = np.concatenate(tris)                        # (T, 3) output corners
    xy = mesh.vertices[mesh.corner_verts[tris]][:, :, :2]
    z = mesh.vertices[mesh.corner_verts[tris]][:, :, 2]
    flat = np.all(np.abs(z) < 1e-9, axis=1)
    tris, xy = tris[flat], xy[flat]
    a, b, c = xy[:, 0], xy[:, 1], xy[:, 2]
    det = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])
    out = np.full((points.shape[0], 3), np.nan)
    for i, p in enumerate(points[:, :2]):
        u = ((p[0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (p[1] - a[:, 1])) / det
        v = ((b[:, 0] - a[:, 0]) * (p[1] - a[:, 1]) - (p[0] - a[:, 0]) * (b[:, 1] - a[:, 1])) / det
        inside = np.flatnonzero((u >= -1e-12) & (v >= -1e-12) & (u + v <= 1 + 1e-12))
        t = inside[0]
        w = np.array([1 - u[t] - v[t], u[t], v[t]])
        out[i] = w @ mesh.corner_colours[tris[t]]
    return out
