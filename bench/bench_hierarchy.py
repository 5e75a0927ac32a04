"""Benchmark of core/hierarchy.py: split, balance and conforming output at ~100k leaves.

    python bench/bench_hierarchy.py

Scene: a 100 x 100 m ground plane (one quad, 1 m patches: 10,000) and a closed 6 x 4 x 3 m room
of one-quad walls. Two refinement patterns, both ending near 100k leaves:

1. uniform-random: every leaf split, then a random half of the leaves again;
2. local: the leaves within a shrinking disc split level after level down to level 8 (a 1 m patch
   down to 4 mm), the case where 2:1 balance has the most work.

Prints CPU seconds (best of a few runs: the machine is shared) per stage.
"""

import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from core.contacts import split_at_contacts  # noqa: E402
from core.hierarchy import ElementTree, output_mesh  # noqa: E402
from core.patches import make_patches  # noqa: E402
from core.scene import scene_from_polygons  # noqa: E402


def scene():
    v = [[-50, -50, 0], [50, -50, 0], [50, 50, 0], [-50, 50, 0]]
    polys = [[0, 1, 2, 3]]
    lo, hi = np.array([0.0, 0.0, 0.0]), np.array([6.0, 4.0, 3.0])
    box = [[lo[0], lo[1], lo[2]], [hi[0], lo[1], lo[2]], [hi[0], hi[1], lo[2]], [lo[0], hi[1], lo[2]],
           [lo[0], lo[1], hi[2]], [hi[0], lo[1], hi[2]], [hi[0], hi[1], hi[2]], [lo[0], hi[1], hi[2]]]
    v += [[x, y, z + 0.01] for x, y, z in box]
    inward = [[0, 1, 2, 3], [4, 7, 6, 5], [0, 4, 5, 1], [1, 5, 6, 2], [2, 6, 7, 3], [3, 7, 4, 0]]
    polys += [[4 + i for i in q] for q in inward]
    mats = [0, 0, 1, 0, 0, 0, 0]
    return scene_from_polygons(np.array(v, float), polys, mats, [[0.5] * 3, [0.7] * 3],
                               [[0.0] * 3, [5.0] * 3], face_objects=[0, 1, 1, 1, 1, 1, 1],
                               object_names=["ground", "room"])


def timed(fn):
    t0 = time.process_time()
    out = fn()
    return out, time.process_time() - t0


def run(name, tree0, masks):
    tree = tree0
    t_split = 0.0
    for make_mask in masks:
        (tree, _), dt = timed(lambda: tree.split(make_mask(tree)))
        t_split += dt
    polys, t_conf = timed(tree.conforming)
    _, t_patch = timed(tree.as_patches)
    C = polys["corner_verts"].size
    _, t_out = timed(lambda: output_mesh(sc, tree, polys, np.zeros((C, 3))))
    print(f"{name:16s} leaves {tree.n_leaves:7d}  points {tree.points.shape[0]:7d}  "
          f"max level {tree.leaf_level.max()}  output faces {polys['face_sizes'].size:7d}")
    print(f"{'':16s} split {t_split:6.2f} s ({len(masks)} calls)  conforming {t_conf:5.2f} s  "
          f"as_patches {t_patch:5.2f} s  output_mesh {t_out:5.2f} s")


if __name__ == "__main__":
    sc = scene()
    (patches, _, _), t_p = timed(lambda: split_at_contacts(sc, make_patches(sc, 1.0)))
    tree0, t_build = timed(lambda: ElementTree.from_patches(sc, patches))
    print(f"patches {patches.n_patches}  make+contacts {t_p:.2f} s  from_patches {t_build:.2f} s")
    rng = np.random.default_rng(0)
    run("uniform-random", tree0, [lambda t: np.ones(t.n_leaves, bool),
                                  lambda t: rng.random(t.n_leaves) < 0.5])

    def disc(radius):
        def mask(t):
            c = t.points[t.leaves].mean(axis=1)
            return np.linalg.norm(c[:, :2] - [20.0, 20.0], axis=1) < radius
        return mask
    run("local, level 8", tree0, [disc(r) for r in (12.0, 8.0, 5.0, 3.0, 2.0, 1.2, 0.8, 0.5)])
