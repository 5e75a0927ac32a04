"""A bulb modelled as a sphere: a small emitter with many faces (issue 11, class 1, not fixed).

    .venv/bin/python bench/bench_bulb.py          # about 5 minutes on 2 cores

Prints, for UV spheres of radius 5 and 10 cm (12 x 6 and 32 x 16 segments, Blender's default
UV sphere being the second) hanging 0.5 m under the ceiling of the black 4 x 4 x 3 m room of
class 1, the floor's error at its output vertices against the closed form, for the default
(``exact_direct='auto'``) and for the exact emitters with their face cap lifted (``MAX_FACES``
set past the sphere's faces here, not in the product): what each costs and reads.

Oracle: with black walls and ceiling the floor reads ``rho sum_f Le F(x -> f)`` over the
sphere's faces whose emitting side faces x (a convex lamp does not hide itself from outside),
F by the contour integral (core.exact.point_polygon_form_factor).
"""

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.stability.common import corners_of, rel_mean_abs  # noqa: E402
from bench.stability.scenes import LAMP_ROOM, lamp_room  # noqa: E402
import core.emitters  # noqa: E402
from core.bake import bake  # noqa: E402
from core.exact import point_polygon_form_factor  # noqa: E402
from core.settings import BakeSettings  # noqa: E402

RHO = 0.5


def uv_sphere(centre, r, nu, nv):
    """Polygons (outward) of a UV sphere: triangle fans at the poles, quads between."""
    th = np.linspace(0.0, np.pi, nv + 1)
    ph = np.linspace(0.0, 2.0 * np.pi, nu + 1)

    def p(i, j):
        return np.asarray(centre) + r * np.array([np.sin(th[i]) * np.cos(ph[j]),
                                                  np.sin(th[i]) * np.sin(ph[j]), np.cos(th[i])])
    polys = []
    for i in range(nv):
        for j in range(nu):
            if i == 0:
                poly = [p(0, 0), p(1, j + 1), p(1, j)]
            elif i == nv - 1:
                poly = [p(i, j), p(i, j + 1), p(nv, 0)]
            else:
                poly = [p(i, j), p(i, j + 1), p(i + 1, j + 1), p(i + 1, j)]
            poly = np.array(poly)
            n = np.cross(poly[1] - poly[0], poly[2] - poly[0])
            polys.append(poly if n @ (poly.mean(0) - centre) > 0 else poly[::-1])
    return polys


def bulb_room(r, nu, nv):
    """The room with the bulb (radiance 1 / (pi r^2): the same power at every radius); the
    scene, its groups and the bulb's polygons."""
    b = lamp_room()
    polys = uv_sphere(np.array([1.3, 2.1, LAMP_ROOM[2] - 0.5]), r, nu, nv)
    for poly in polys:
        b.add(poly, 2, "lamp")
    em = np.zeros((3, 3))
    em[2] = 1.0 / (np.pi * r * r)
    scene, groups = b.scene(np.array([[RHO] * 3, [0.0] * 3, [0.0] * 3]), em)
    return scene, groups, polys, em[2, 0]


def floor_error(result, groups, polys, le):
    m = result.output
    c = corners_of(m, groups["floor"])
    pts = m.vertices[m.corner_verts[c]]
    up = np.tile([0.0, 0.0, 1.0], (len(pts), 1))
    # Every bulb face has 3 or 4 corners: triangles padded to 4 by repeating a corner.
    stacked = np.stack([np.vstack([q, q[-1:]]) if len(q) == 3 else q for q in polys])
    ff = point_polygon_form_factor(pts, up, stacked)
    normal = np.cross(stacked[:, 1] - stacked[:, 0], stacked[:, 2] - stacked[:, 0])
    facing = np.einsum("pfj,fj->pf", pts[:, None, :] - stacked.mean(1)[None], normal) > 0
    exact = RHO * le * np.where(facing, ff, 0.0).sum(axis=1)
    got = m.corner_colours[c, 0]
    rel = np.abs(got / exact - 1.0)
    return rel_mean_abs(got, exact), rel.max(), np.unique(m.corner_verts[c]).size


def main():
    cap = core.emitters.MAX_FACES
    print("| bulb | faces | exact_direct | floor vertices | mean error | worst vertex | time |")
    print("|---|---|---|---|---|---|---|")
    for r, nu, nv in ((0.05, 12, 6), (0.05, 32, 16), (0.1, 32, 16)):
        scene, groups, polys, le = bulb_room(r, nu, nv)
        for label, lift in (("auto (default)", False), ("exact, cap lifted", True)):
            core.emitters.MAX_FACES = 10 ** 6 if lift else cap
            t = time.perf_counter()
            try:
                result = bake(scene, BakeSettings(exact_direct="all" if lift else "auto"))
            finally:
                core.emitters.MAX_FACES = cap
            seconds = time.perf_counter() - t
            mean, worst, nv_floor = floor_error(result, groups, polys, le)
            taken = result.report.get("lights", {}).get("exact_emitter_faces", 0)
            print(f"| r = {r * 100:g} cm, {nu} x {nv} | {len(polys)} | {label} ({taken} faces "
                  f"exact) | {nv_floor} | {mean * 100:.2f} % | {worst * 100:.1f} % | "
                  f"{seconds:.1f} s |", flush=True)


if __name__ == "__main__":
    main()
