"""Benchmark of core/raytraced.py; prints figures, takes about 15 s on one core.

    python bench/bench_raytraced.py

1. Cost on the room benchmark scene (``room_with_boxes(N)``, N = 200 and 500): seconds per row,
   per (source, target patch) pair and ray setting (the batch cost model of core/rows.py counts
   P x rays per row) and per shadow ray actually traced, beside exact_rows and the hemicube.
2. Row accuracy on ``room_with_boxes(300)``: L1 row error against exact_rows with the adaptive
   source quadrature and 256 rays, beside the hemicube and exact_rows at 16 rays.
3. Where it breaks: the relative error of the point value on the axis of a unit square source at
   height h (the contour formula is the reference), for h from 1 down to 0.05 sizes.
"""

import os
import sys
import time
from types import SimpleNamespace

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

import core.raytraced as rt  # noqa: E402
from bench.scenes import room_with_boxes  # noqa: E402
from core.exact import exact_rows, point_polygon_form_factor, ray_triangles  # noqa: E402
from core.hemicube import hemicube_rows  # noqa: E402
from core.patches import make_patches  # noqa: E402
from core.raycast import build_bvh  # noqa: E402
from core.raytraced import raytraced_point_factors, raytraced_rows  # noqa: E402


def cpu(fn):
    """(result, CPU seconds) of one call (the machine is shared: CPU time is steadier)."""
    t0 = time.process_time()
    out = fn()
    return out, time.process_time() - t0


def count_rays(fn):
    """(result, number of shadow rays traced) of ``fn()``."""
    traced = [0]
    real = rt.any_hit

    def counting(bvh, origins, directions, t_max):
        traced[0] += len(origins)
        return real(bvh, origins, directions, t_max)
    rt.any_hit = counting
    try:
        return fn(), traced[0]
    finally:
        rt.any_hit = real


def cost():
    print("== cost: room_with_boxes(N), 6 front sources, CPU time ==")
    print(f"{'N':>4s} {'P':>4s} {'method':>22s} {'s/row':>7s} {'us/(pair*ray)':>14s} "
          f"{'us/traced ray':>14s} {'rays/row':>9s}")
    for n in (200, 500):
        pat = make_patches(room_with_boxes(n), 10.0)
        p = pat.areas.size
        bvh = build_bvh(ray_triangles(pat)[0])
        src = np.random.default_rng(1).choice(p, 6, replace=False)
        for rays in (4, 16):
            (_, traced), t = cpu(lambda: count_rays(
                lambda: raytraced_rows(pat, src, rays=rays, bvh=bvh)))
            print(f"{n:4d} {p:4d} {'raytraced rays=' + str(rays):>22s} {t / src.size:7.3f} "
                  f"{t / (src.size * p * rays) * 1e6:14.1f} {t / traced * 1e6:14.1f} "
                  f"{traced / src.size:9.0f}")
        for rays in (4, 16):
            _, t = cpu(lambda: exact_rows(pat, src, rays=rays, bvh=bvh, source_order="adaptive"))
            print(f"{n:4d} {p:4d} {'exact adaptive rays=' + str(rays):>22s} {t / src.size:7.3f} "
                  f"{t / (src.size * p * rays) * 1e6:14.1f}")
        _, t = cpu(lambda: hemicube_rows(pat, src, resolution=64))
        print(f"{n:4d} {p:4d} {'hemicube R=64':>22s} {t / src.size:7.3f}")


def accuracy():
    print("\n== row accuracy on room_with_boxes(300): L1 row error against exact_rows "
          "(adaptive, 256 rays) ==")
    pat = make_patches(room_with_boxes(300), 10.0)
    p = pat.areas.size
    src = np.random.default_rng(3).choice(p, 6, replace=False)
    bvh = build_bvh(ray_triangles(pat)[0])
    ref = exact_rows(pat, src, rays=256, source_order="adaptive", bvh=bvh,
                     rng=np.random.default_rng(4))
    runs = [("hemicube R=64", lambda: hemicube_rows(pat, src, resolution=64)),
            ("exact adaptive, rays=16",
             lambda: exact_rows(pat, src, source_order="adaptive", bvh=bvh))]
    runs += [(f"raytraced, rays={r}", lambda r=r: raytraced_rows(pat, src, rays=r, bvh=bvh))
             for r in (4, 16, 64)]
    for name, fn in runs:
        rows, t = cpu(fn)
        err = np.abs(rows - ref).sum(axis=1)
        print(f"{name:26s} mean L1 {err.mean():.4f}  max L1 {err.max():.4f}  "
              f"row sums {rows.sum(axis=1).min():.4f}..{rows.sum(axis=1).max():.4f}  "
              f"({t:.2f} s)")
    print(f"{'(reference row sums)':26s} {ref.sum(axis=1).min():.4f}..{ref.sum(axis=1).max():.4f}")


def breaks():
    print("\n== where it breaks: point on the axis of a unit square at height h, mean relative "
          "error over 8 seeds (sd) ==")
    src = np.array([[-0.5, -0.5, 0], [0.5, -0.5, 0], [0.5, 0.5, 0], [-0.5, 0.5, 0.0]])
    pat = make_patches_stub(src)
    print(f"{'h/size':>7s} {'exact F':>8s}" + "".join(f" {'rays=' + str(r):>17s}"
                                                     for r in (4, 16, 64, 256)))
    for h in (1.0, 0.5, 0.25, 0.1, 0.05):
        x, n = np.array([[0.0, 0.0, h]]), np.array([[0.0, 0.0, -1.0]])
        exact = point_polygon_form_factor(x, n, src[None])[0, 0]
        line = f"{h:7.2f} {exact:8.4f}"
        for rays in (4, 16, 64, 256):
            v = np.array([raytraced_point_factors(x, n, pat, [0], rays=rays,
                                                  rng=np.random.default_rng(k))[0, 0]
                          for k in range(8)]) / exact
            line += f" {v.mean() - 1:+8.3f} ({v.std():.3f})"
        print(line)


def make_patches_stub(corners):
    """One patch from a planar quad (the fields raytraced.py reads)."""
    c = np.asarray(corners, float)[None]
    v = np.cross(c[:, 2] - c[:, 0], c[:, 3] - c[:, 1])
    norm = np.linalg.norm(v, axis=1)
    return SimpleNamespace(corners=c, centres=c.mean(axis=1), normals=v / norm[:, None],
                           areas=norm / 2)


if __name__ == "__main__":
    cost()
    accuracy()
    breaks()
