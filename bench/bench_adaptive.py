"""Adaptive radiosity mesh (issue 9): error against closed forms versus output vertices and time.

Scenes (tests/core/test_adaptive.py builds them; the oracles are the same):

* ``one_quad``: a 4 x 4 m floor as one quad under a 1 m emitter quad; exact field rho Le F.
* ``box``: a black box on a one-quad floor under a 0.6 m light; exact field by quadrature with
  shadow rays.
* ``ground``: a closed 3 m room (one quad per wall, light inside) on a 100 x 100 m ground plane:
  time and vertex counts only.
* ``--room``: bench.scenes.room_with_boxes modelled as an architect would (one quad per
  rectangle) baked with output_mode='mesh' and 'vertices', against the same engine on a pre-meshed
  copy (``--room-quads`` quads, output_mode='vertices', patch_size 0.25 m): area-weighted relative
  RMS of the luminance over the pre-meshed copy's faces (each face: its corners' mean; the coarse
  field interpolated at the same corners).

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
    from bench.scenes import unit_cube
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


def field_at(mesh, scene, points, objects):
    """The OutputMesh's field (linear over triangles 0-1-2, 0-2-3) at points of axis-aligned
    faces; ``objects`` (S,) names each point's object in ``scene``: (S, 3)."""
    out = np.full((points.shape[0], 3), np.nan)
    obj_of_face = scene.face_objects[mesh.face_parent]
    for o in np.unique(objects):
        faces = np.flatnonzero(obj_of_face == o)
        tris = np.concatenate([np.stack([mesh.face_starts[faces], mesh.face_starts[faces] + 1,
                                         mesh.face_starts[faces] + 2], 1)]
                              + [np.stack([s, s + 2, s + 3], 1) for s in
                                 [mesh.face_starts[faces][mesh.face_sizes[faces] == 4]]])
        p3 = mesh.vertices[mesh.corner_verts[tris]]
        n = np.cross(p3[0, 1] - p3[0, 0], p3[0, 2] - p3[0, 0])
        keep = [k for k in range(3) if k != int(np.argmax(np.abs(n)))]
        a, b, c = (p3[:, i][:, keep] for i in range(3))
        det = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])
        for i in np.flatnonzero(objects == o):
            p = points[i, keep]
            u = ((p[0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (p[1] - a[:, 1])) / det
            v = ((b[:, 0] - a[:, 0]) * (p[1] - a[:, 1]) - (p[0] - a[:, 0]) * (b[:, 1] - a[:, 1])) / det
            t = np.flatnonzero((u >= -1e-9) & (v >= -1e-9) & (u + v <= 1 + 1e-9))
            if t.size:
                w = np.array([1 - u[t[0]] - v[t[0]], u[t[0]], v[t[0]]])
                out[i] = w @ mesh.corner_colours[tris[t[0]]]
    return out


RUNS = [dict(), dict(output_mode="vertices"), dict(contrast=0.2), dict(min_element=0.1),
        dict(patch_size=0.5)]


def room(n_quads):
    from bench.scenes import room_with_boxes
    from core.refine import LUMINANCE
    fine = room_with_boxes(n_quads)
    coarse = room_with_boxes(1)
    t = time.perf_counter()
    ref = bake(fine, BakeSettings(output_mode="vertices", patch_size=0.25))
    print(f"room reference: {fine.n_faces} faces, {time.perf_counter() - t:.1f} s", flush=True)
    corners, faces = fine.face_corner_indices()
    emits = np.any(fine.emission[fine.face_materials] > 0, axis=1)
    sel = ~emits[faces]
    pts = fine.vertices[fine.corner_verts[corners[sel]]]
    names = np.array(fine.object_names)[fine.face_objects[faces[sel]]]
    objects = np.array([coarse.object_names.index(n) for n in names])
    y_ref = np.bincount(faces[sel], weights=ref.corner_colours[corners[sel]] @ LUMINANCE,
                        minlength=fine.n_faces) / fine.face_sizes
    area = np.where(emits, 0.0, fine.face_areas)
    for kw in RUNS:
        t = time.perf_counter()
        r = bake(coarse, BakeSettings(**kw))
        dt = time.perf_counter() - t
        if r.output is not None:
            val = field_at(r.output, coarse, pts, objects) @ LUMINANCE
            n_out = r.output.vertices.shape[0]
        else:                                   # the old output: bilinear over the user's quads
            val = np.zeros(len(pts))
            for i, (p, o) in enumerate(zip(pts, objects)):
                f = np.flatnonzero(coarse.face_objects == o)[0]
                c = coarse.vertices[coarse.corner_verts[coarse.face_starts[f]:
                                                        coarse.face_starts[f] + 4]]
                e1, e2 = c[1] - c[0], c[3] - c[0]
                u = np.dot(p - c[0], e1) / np.dot(e1, e1)
                v = np.dot(p - c[0], e2) / np.dot(e2, e2)
                col = r.corner_colours[coarse.face_starts[f]:coarse.face_starts[f] + 4] @ LUMINANCE
                val[i] = (col[0] * (1 - u) * (1 - v) + col[1] * u * (1 - v) + col[2] * u * v
                          + col[3] * (1 - u) * v)
            n_out = coarse.vertices.shape[0]
        y = np.bincount(faces[sel], weights=val, minlength=fine.n_faces) / fine.face_sizes
        rms = np.sqrt(np.sum(area * (y - y_ref) ** 2) / np.sum(area * y_ref ** 2))
        print(f"room coarse {str(kw):32s} output vertices {n_out:6d}  rel RMS {rms:6.2%}  "
              f"{dt:6.1f} s", flush=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="defaults only")
    ap.add_argument("--room", action="store_true", help="only the coarse room comparison")
    ap.add_argument("--room-quads", type=int, default=3000)
    args = ap.parse_args()
    if args.room:
        room(args.room_quads)
        return
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
