"""Benchmark of core/raycast.py and core/exact.py; prints figures, takes ~30 s on one core.

    python bench/bench_exact.py

1. BVH build and ray throughput on the room benchmark scene (closest and any hit).
2. Cost of the contour form factor per (point, polygon) pair, and of exact_rows per pair and
   per visibility ray.
3. The ``near`` sweep behind hybrid_rows' default: relative error of the form factor between
   opposed unit squares (closed form, Howell C-11) at distance = k sizes, for the hemicube
   (R = 64, from the centre), the exact method from the centre (the point-source error, which no
   hemicube resolution removes) and the exact method with 3 x 3 source points; and the same for
   perpendicular squares sharing an edge (closed form C-14, the room-corner case).
"""

import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from core.exact import (  # noqa: E402
    exact_rows, hybrid_rows, point_polygon_form_factor, ray_triangles,
)
from core.hemicube import hemicube_rows  # noqa: E402
from core.patches import make_patches  # noqa: E402
from core.raycast import any_hit, build_bvh, closest_hit  # noqa: E402
from bench.scenes import room_with_boxes  # noqa: E402
from core.scene import scene_from_polygons  # noqa: E402


def best_time(fn, repeat=3):
    """Smallest CPU time of a few runs (the machine is shared: CPU time is steadier than wall)."""
    best = np.inf
    for _ in range(repeat):
        t0 = time.process_time()
        fn()
        best = min(best, time.process_time() - t0)
    return best


def opposed(k):
    """Opposed squares howell C-11 with X = Y = 1/k."""
    x = 1.0 / k
    a = np.log(np.sqrt((1 + x * x) ** 2 / (1 + 2 * x * x)))
    b = 2 * x * np.sqrt(1 + x * x) * np.arctan(x / np.sqrt(1 + x * x)) - 2 * x * np.arctan(x)
    return 2 / (np.pi * x * x) * (a + b)


def two_quads(quad_a, quad_b):
    v = np.concatenate([quad_a, quad_b])
    scene = scene_from_polygons(v, [[0, 1, 2, 3], [4, 5, 6, 7]], [0, 1],
                                [[0.5] * 3, [0.0] * 3], [[0.0] * 3, [1.0] * 3])
    return make_patches(scene, 10.0)


def main():
    print("== ray casting: room_with_boxes(2000) ==")
    pat = make_patches(room_with_boxes(2000), 10.0)
    tris, _ = ray_triangles(pat)
    t_build = best_time(lambda: build_bvh(tris))
    bvh = build_bvh(tris)
    print(f"triangles {tris.shape[0]}, nodes {bvh.child.size}, depth {bvh.depth}, "
          f"build {t_build * 1e3:.1f} ms")
    rng = np.random.default_rng(0)
    p = pat.centres.shape[0]
    n_rays = 40000
    a, b = rng.integers(0, p, n_rays), rng.integers(0, p, n_rays)
    o = pat.centres[a] + pat.normals[a] * 1e-6
    d = pat.centres[b] - o
    for name, fn in (("closest_hit, t_max = 1 (visibility)", lambda: closest_hit(bvh, o, d, 1.0)),
                     ("closest_hit, t_max = inf", lambda: closest_hit(bvh, o, d)),
                     ("any_hit, t_max = 1", lambda: any_hit(bvh, o, d, 1.0))):
        t = best_time(fn)
        print(f"{name:38s} {n_rays / t / 1e3:6.0f} k rays/s  ({t / n_rays * 1e6:.1f} us/ray)")

    print("\n== contour form factor ==")
    x = pat.centres[:200]
    n = pat.normals[:200]
    t = best_time(lambda: point_polygon_form_factor(x, n, pat.corners), repeat=2)
    pairs = 200 * p
    print(f"point_polygon_form_factor: {pairs} pairs in {t:.2f} s -> {t / pairs * 1e6:.2f} us/pair")

    src = rng.choice(2 * p, 4, replace=False)
    for rays in (4, 16):
        t0 = time.process_time()
        rows = exact_rows(pat, src, rays=rays, bvh=bvh)
        t = time.process_time() - t0
        ff = point_polygon_form_factor(pat.centres[src % p],
                                       pat.normals[src % p] * np.where(src < p, 1, -1)[:, None],
                                       pat.corners)
        traced = int((ff > 0).sum())
        print(f"exact_rows rays={rays:2d}: {len(src)} sources x {p} patches in {t:.2f} s; "
              f"{traced} pairs traced, {traced * rays} rays -> {t / (len(src) * p) * 1e6:.0f} us "
              f"per pair overall, {t / (traced * rays) * 1e6:.1f} us per ray incl. set-up; "
              f"row sums {np.round(rows.sum(axis=1), 4)}")
    t = best_time(lambda: hemicube_rows(pat, src, resolution=64), repeat=1)
    print(f"(hemicube_rows R=64, same sources: {t:.2f} s)")

    print("\n== near sweep: relative error of F(1->2) ==")
    print(f"{'pair':26s} {'dist/size':>9s} {'hemicube R64':>13s} {'exact centre':>13s} "
          f"{'exact 3x3':>10s} {'adaptive':>10s}")
    sq = lambda z, flip: (np.array([[0, 0, z], [0, 1, z], [1, 1, z], [1, 0, z]], float) if flip
                          else np.array([[0, 0, z], [1, 0, z], [1, 1, z], [0, 1, z]], float))
    def compare(label, dist, pt, ref, col=1):
        """One table row: F(1 -> node ``col``) of patch pair ``pt`` by each method against
        ``ref`` (col 1: the second patch's front, 3: its back)."""
        hc = hemicube_rows(pt, [0], resolution=64)[0, col]
        ec = exact_rows(pt, [0])[0, col]
        e3 = exact_rows(pt, [0], source_order=3)[0, col]
        ea = exact_rows(pt, [0], source_order="adaptive")[0, col]
        print(f"{label:26s} {dist:9.2f} {hc / ref - 1:+13.4f} {ec / ref - 1:+13.4f} "
              f"{e3 / ref - 1:+10.2e} {ea / ref - 1:+10.2e}")

    for k in (1, 1.5, 2, 3, 4, 5):
        compare("opposed unit squares", k, two_quads(sq(0.0, False), sq(float(k), True)),
                opposed(k))
    floor = sq(0.0, False)
    wall = np.array([[0, 0, 0], [0, 0, 1], [0, 1, 1], [0, 1, 0]], float)[::-1]     # faces +x
    compare("adjacent unit squares", 0.71, two_quads(floor, wall), 0.200043776075)
    # Luminaire 5 cm under a 0.67 m ceiling patch (room_with_boxes): reference by a 600 x 600
    # midpoint rule over the ceiling patch.
    s_ = 0.6667
    ceil_q = np.array([[2.0, 1.3, 3.0], [2.0, 1.3 + s_, 3.0], [2.0 + s_, 1.3 + s_, 3.0],
                       [2.0 + s_, 1.3, 3.0]])
    panel = np.array([[2.4, 1.7, 2.95], [2.4, 2.3, 2.95], [3.0, 2.3, 2.95], [3.0, 1.7, 2.95]])
    g = (np.arange(600) + 0.5) / 600
    pts = ceil_q[0] + g[:, None, None] * [s_, 0, 0] + g[None, :, None] * [0, s_, 0]
    ref = point_polygon_form_factor(pts.reshape(-1, 3), np.tile([0, 0, -1.0], (360000, 1)),
                                    panel[None]).mean()
    compare("ceiling over panel (back)", 0.81, two_quads(ceil_q, panel), ref, col=3)

    print("\n== hybrid cost on the room (same 4 sources) ==")
    for near in (0.0, 2.0, 4.0, 6.0):
        t = best_time(lambda: hybrid_rows(pat, src, near=near, bvh=bvh), repeat=1)
        print(f"hybrid_rows near={near}: {t:.2f} s")

    print("\n== row accuracy on room_with_boxes(300): L1 row error vs a reference ==")
    # Reference: exact rows averaged over 32 x 32 Gauss source points with 256 rays per pair
    # (the method is checked against closed forms in tests/core/test_exact.py).
    small = make_patches(room_with_boxes(300), 10.0)
    ps = small.centres.shape[0]
    src = np.random.default_rng(3).choice(ps, 6, replace=False)
    ref = exact_rows(small, src, rays=256, source_order=32, rng=np.random.default_rng(4))
    for name, fn in (
            ("hemicube R=64", lambda: hemicube_rows(small, src, resolution=64)),
            ("hemicube R=256", lambda: hemicube_rows(small, src, resolution=256)),
            ("exact centre, rays=16", lambda: exact_rows(small, src)),
            ("exact 3x3 source, rays=16", lambda: exact_rows(small, src, source_order=3)),
            ("exact adaptive, rays=16",
             lambda: exact_rows(small, src, source_order="adaptive")),
            ("hybrid R=64 near=4", lambda: hybrid_rows(small, src)),
            ("hybrid, conserve=False", lambda: hybrid_rows(small, src, conserve=False)),
            ("hybrid R=128 near=4", lambda: hybrid_rows(small, src, resolution=128))):
        t0 = time.process_time()
        rows = fn()
        t = time.process_time() - t0
        err = np.abs(rows - ref).sum(axis=1)
        print(f"{name:28s} mean L1 {err.mean():.4f}  max L1 {err.max():.4f}  "
              f"max |row sum - 1| {np.abs(rows.sum(axis=1) - 1).max():.4f}  ({t:.2f} s)")


if __name__ == "__main__":
    main()
