"""Adaptive radiosity mesh (issue 9): error against closed forms versus output vertices and time.

Scenes (tests/core/test_adaptive.py builds them; the oracles are the same):

* ``one_quad``: a 4 x 4 m floor as one quad under a 1 m emitter quad; exact field rho Le F.
* ``box``: a black box on a one-quad floor under a 0.6 m light; exact field by quadrature with
  shadow rays.
* ``ground``: a closed 3 m room (one quad per wall, light inside) on a 100 x 100 m ground plane:
  time and vertex counts only.

Run: ``.venv/bin/python bench/bench_adaptive.py [--quick]``. Prints one line per run: scene,
settings, output vertices, mean and max error (of the mean / of the peak), seconds.
"""

import argparse
import os
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.join(ROOT, "tests", "core"))

from core import BakeSettings, bake, scene_from_polygons  # noqa: E402
from core.exact import point_polygon_form_factor  # noqa: E402
from test_adaptive import (LE, RHO, box_scene, floor_points, interpolate,  # noqa: E402
                           one_quad_scene, shadowed_form_factor)


def field_error(result, exact, pts):
    field = interpolate(result.output, pts)[:, 0] if result.output is not None else None
    return (np.mean(np.abs(field - exact)) / np.mean(exact),
            np.max(np.abs(field - exact)) / np.max(exact))


def ground_scene(size=100.0):
    from core.samples import unit_cube
    room = unit_cube(n=1, emitting=("z+",))
    h = size / 2
    v = np.vstack([room.vertices * 3.0, [[-h, -h, -0.01], [h, -h, -0.01], [h, h, -0.01],
                                         [-h, h, -0.01]]])
    V = room.vertices.shape[0]
    polys = [room.corner_verts[s:s + n].tolist()
             for s, n in zip(room.face_starts, room.face_sizes)] + [[V, V + 1, V + 2, V + 3]]
    return scene_from_polygons(v, polys, list(room.face_materials) + [0], room.reflectance,
                               room.emission, face_objects=list(range(6)) + [6],
                               object_names=list(room.object_names) + ["ground"])


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="defaults only")
    args = ap.parse_args()
    runs = [dict()]
    if not args.quick:
        runs += [dict(contrast=0.2), dict(contrast=0.05), dict(min_element=0.02),
                 dict(min_element=0.1), dict(contrast=0.2, min_element=0.05)]
    q = one_quad_scene()
    qp = floor_points(20)
    q_exact = RHO * LE * point_polygon_form_factor(qp, np.tile([0, 0, 1.0], (len(qp), 1)),
                                                   q.vertices[[4, 5, 6, 7]][None])[:, 0]
    b = box_scene()
    bp = floor_points(20)
    b_exact = RHO * LE * shadowed_form_factor(b, bp)
    for name, scene, pts, exact in (("one_quad", q, qp, q_exact), ("box", b, bp, b_exact)):
        for kw in runs:
            t = time.perf_counter()
            r = bake(scene, BakeSettings(**kw))
            dt = time.perf_counter() - t
            mean, peak = field_error(r, exact, pts)
            print(f"{name:9s} {str(kw):40s} vertices {r.output.vertices.shape[0]:6d}  "
                  f"mean {mean:6.2%}  max {peak:6.2%}  {dt:6.1f} s", flush=True)
    for size in (40.0, 100.0):
        scene = ground_scene(size)
        t = time.perf_counter()
        r = bake(scene, BakeSettings())
        dt = time.perf_counter() - t
        ground = r.report["mesh"]["per_object"]["ground"]
        print(f"ground {size:.0f} m: {dt:.1f} s, patches {r.report['patches']}, output vertices "
              f"{r.output.vertices.shape[0]} (ground {ground['output_vertices']}), timings "
              + ", ".join(f"{k} {v:.1f}" for k, v in r.report["timings"].items()), flush=True)


if __name__ == "__main__":
    main()
