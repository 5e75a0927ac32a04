"""A hand-built core.outmesh.OutputMesh for the writer's tests (no adaptive hierarchy needed).

Every scene quad is split into 2 x 2 quads and every scene triangle into 4 triangles (midpoint
subdivision); larger polygons are fanned into triangles over their own corners. Vertices are
shared through keys (scene vertex, scene edge, face centre), so a conforming scene gives a
conforming output. The weights are written down by hand: a corner is (1, 0, 0) on its own scene
corner, an edge midpoint (1/2, 1/2, 0) on the edge's two corners, a quad's centre (1/2, 1/2, 0)
on the diagonal 0-2 (exact for a parallelogram, inside any convex quad).
"""

import importlib

import numpy as np

from conftest import PACKAGE

OutputMesh = importlib.import_module(PACKAGE.__name__ + ".core.outmesh").OutputMesh


def smooth_colour(points):
    """(N, 3) colours in (0, 1): a smooth function of world position (an oracle to interpolate)."""
    points = np.asarray(points, dtype=np.float64)
    return 0.5 + 0.4 * np.sin(np.array([1.3, 0.7, 1.9]) * points + np.array([0.1, 0.5, 0.9]))


def split_output(arrays, colour=smooth_colour):
    """OutputMesh over every face of the scene arrays (extract.Extraction.arrays)."""
    pts = arrays["vertices"]
    cv, fs, fz = arrays["corner_verts"], arrays["face_starts"], arrays["face_sizes"]
    keys, verts = {}, []
    corner_verts, sizes, parents, sources, weights = [], [], [], [], []

    def node(key, src, w):
        pos = sum(wk * pts[cv[s]] for s, wk in zip(src, w))
        if key not in keys:
            keys[key] = len(verts)
            verts.append(pos)
        return keys[key], src, w

    for f in range(fs.size):
        s, n = int(fs[f]), int(fz[f])
        c = list(range(s, s + n))
        vid = [int(v) for v in cv[s:s + n]]
        if n in (3, 4):
            corner = [node(("v", vid[k]), (c[k],) * 3, (1.0, 0.0, 0.0)) for k in range(n)]
            mid = [node(("e",) + tuple(sorted((vid[k], vid[(k + 1) % n]))),
                        (c[k], c[(k + 1) % n], c[k]), (0.5, 0.5, 0.0)) for k in range(n)]
            if n == 4:
                centre = node(("f", f), (c[0], c[2], c[1]), (0.5, 0.5, 0.0))
                pieces = [[corner[k], mid[k], centre, mid[k - 1]] for k in range(4)]
            else:
                pieces = [[corner[k], mid[k], mid[k - 1]] for k in range(3)] + [mid]
        else:
            corner = [node(("v", vid[k]), (c[k],) * 3, (1.0, 0.0, 0.0)) for k in range(n)]
            pieces = [[corner[0], corner[k], corner[k + 1]] for k in range(1, n - 1)]
        for piece in pieces:
            sizes.append(len(piece))
            parents.append(f)
            for vi, src, w in piece:
                corner_verts.append(vi)
                sources.append(src)
                weights.append(w)
    verts = np.array(verts, dtype=np.float64)
    corner_verts = np.array(corner_verts, dtype=np.int64)
    sizes = np.array(sizes, dtype=np.int64)
    return OutputMesh(vertices=verts, corner_verts=corner_verts,
                      face_starts=np.cumsum(sizes) - sizes, face_sizes=sizes,
                      face_parent=np.array(parents, dtype=np.int64),
                      corner_colours=colour(verts[corner_verts]),
                      corner_sources=np.array(sources, dtype=np.int64),
                      corner_weights=np.array(weights, dtype=np.float64))
