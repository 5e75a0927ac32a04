"""Radiance's view of the lights benchmark's daylight cases: irradiance at the room's ceiling and
walls, ours against ``rtrace -I`` (a second, independent program beside Cycles).

The room and lights of :mod:`bench.compare.lights`, written as a .rad file
(:func:`bench.compare.radiance.to_rad`) plus:

* ``sun``: ``light`` of radiance S / omega on a ``source`` of the sun's angular diameter, omega
  its solid angle (Radiance's sun: irradiance S on a surface facing it);
* ``sky``: a ``glow`` of the world's radiance on a full-sphere ``source`` (what a uniform world
  is);
* ``cie``: the CIE standard overcast sky from Radiance's own ``gensky -c -B E -g 0`` (horizontal
  diffuse irradiance E = ``CIE_IRRADIANCE`` W/m^2, black ground) against ours with
  ``sky='cie_overcast'`` at ``sky_illuminance`` = 683 E lx (core.sky; gensky's zenith radiance
  is ours, 9 E / (7 pi)), both through the window only; 30 more sensors on a work plane 0.85 m
  up, where daylight factors are read (ours: :func:`core.lux.illuminance_at`).

* ``point``: each point light as a Radiance ``light`` sphere of its radius whose radiance gives
  its intensity (``I = L pi r^2``); ours keeps the soft falloff ``1 / (d^2 + r^2)`` (Cycles'),
  Radiance's sphere the exact ``1 / d^2``: 2.7 % apart on the ceiling right above a bulb.
* ``spot``: the spot on the table and the dim fill light of :mod:`bench.compare.lights`. The
  spot is a Radiance ``light`` sphere of its radius, as a point light of its power, whose
  radiance a ``brightfunc`` (:data:`SPOT_CAL`) multiplies by our cone (core.lights.spot_factor,
  measured against Cycles in tests/addon/test_lights.py): ``smoothstep((cos a - cos(size / 2))
  / ((1 - cos(size / 2)) x blend))``, a the angle between the spot's axis and the direction
  leaving the light, so both programs shine the same distribution and the comparison is of the
  light's transport. 40 more
  sensors on the table top and 34 on the floor beside it, through the cone's edge and blend,
  where the direct light alone is compared too (Radiance ``-ab 0``; ours one shadow ray to the
  light's centre, as Radiance's ``-ds 0``).

Sensors: 48 points on the ceiling (facing down) and 60 on two walls (facing in), none of them in
direct light of the sun. Ours: a hemicube (R = 256) at the same points over a uniform 0.25 m
bake's solved patches, plus the lights' direct light and the world's uncovered part
(``DirectLight.extra``).
Radiance: ``-ab 10 -ad 4096 -aa 0`` (no irradiance cache: every sensor sampled).

Run::

    .venv/bin/python -m bench.compare.lights_radiance          # ~1 min
    .venv/bin/python -m bench.compare.lights_radiance --cases spot

Prints, per case and surface, the mean irradiance (RGB) of both and their ratio.
"""

import argparse
import math

import numpy as np

from . import radiance
from .lights import CASES, WORLDS, room_arrays

#: Horizontal diffuse irradiance of the ``cie`` case (W/m^2): 68,300 lx at 683 lm/W.
CIE_IRRADIANCE = 100.0

#: Rec. 709 luminance weights (core.lux's): the ``cie`` case compares luminance, since the
#: room's coloured surfaces tint Radiance's RGB while ours is read as illuminance.
LUMA = np.array([0.2126, 0.7152, 0.0722])

#: The cases, in the order they run by default.
CASE_NAMES = ("point", "spot", "sun", "sky", "cie")

PARAMS = ("-ab", "10", "-ad", "4096", "-as", "0", "-aa", "0", "-lw", "1e-6", "-lr", "-12",
          "-dj", "0", "-ds", "0", "-dt", "0", "-dc", "1", "-dr", "0", "-ss", "0", "-st", "1")

#: rtrace options of the direct light alone (the spot case's cone check).
DIRECT_PARAMS = ("-ab", "0") + PARAMS[2:]

#: Sensors sit this far (m) in front of their surface for our hemicube (Radiance lifts its own).
LIFT = 1e-4

#: The spot's cone as a Radiance brightfunc: A1..A3 its unit axis, A4 cos(size / 2), A5 the
#: blend's width in cosine (1 - A4) x blend > 0. Radiance's (Dx, Dy, Dz) is the ray's direction
#: towards the light: the light leaves it along -D (as in Radiance's own source.cal).
SPOT_CAL = """
spot_cos = -(Dx*A1 + Dy*A2 + Dz*A3);
spot_x = (spot_cos - A4) / A5;
spot_f = if(spot_cos - A4, if(spot_x - 1, 1, spot_x*spot_x*(3 - 2*spot_x)), 0);
"""


def sources(case):
    """Radiance text of the case's sun or sky."""
    if case == "sun":
        sun = CASES["sun"][0]
        d = np.asarray(sun["direction"], float)
        towards = -d / np.linalg.norm(d)
        deg = math.degrees(sun["angle"])
        omega = 2 * math.pi * (1 - math.cos(math.radians(deg / 2)))
        radiance_ = sun["strength"] * np.asarray(sun["color"], float) / omega
        return ("void light solar 0 0 3 %s\nsolar source sun 0 0 4 %s %.9g\n"
                % (radiance._fmt(radiance_), radiance._fmt(towards), deg))
    if case == "sky":
        return ("void glow skyglow 0 0 4 %s 0\nskyglow source sky 0 0 4 0 0 1 360\n"
                % radiance._fmt(WORLDS["sky"]))
    if case in ("point", "spot"):
        text = ""
        for i, light in enumerate(CASES[case]):
            # Ours and Cycles: I = P colour / (4 pi) W/sr; a Lambertian sphere of radius r and
            # radiance L has I = L pi r^2 in every direction.
            r = light["radius"]
            L = light["power"] * np.asarray(light.get("color", (1, 1, 1)), float) \
                / (4 * math.pi) / (math.pi * r * r)
            modifier = "void"
            if light["kind"] == "spot":
                axis = np.asarray(light["direction"], float)
                axis = axis / np.linalg.norm(axis)
                cos_half = math.cos(light["spot_size"] / 2)
                smooth = (1 - cos_half) * light["spot_blend"]
                if smooth <= 0:
                    raise ValueError("the spot case needs spot_blend > 0")
                cal = _cal_file()
                text += ("void brightfunc cone%d 2 spot_f %s 0 5 %s %.9g %.9g\n"
                         % (i, cal, radiance._fmt(axis), cos_half, smooth))
                modifier = "cone%d" % i
            text += ("%s light bulb%d 0 0 3 %s\nbulb%d sphere bulb%d.s 0 0 4 %s %.9g\n"
                     % (modifier, i, radiance._fmt(L), i, i, radiance._fmt(light["position"]),
                        r))
        return text
    if case == "cie":
        import pyradiance as pr

        sky = pr.gensky(altitude=45.0, azimuth=0.0, cloudy=True, ground_reflectance=0.0,
                        horizontal_brightness=CIE_IRRADIANCE).decode()
        return (sky + "\nskyfunc glow sky_glow 0 0 4 1 1 1 0\n"
                "sky_glow source sky 0 0 4 0 0 1 180\n"
                "sky_glow source ground 0 0 4 0 0 -1 180\n")
    raise ValueError("case must be one of %s; got %r" % (CASE_NAMES, case))


def _cal_file():
    """Path of :data:`SPOT_CAL` written once for this process (Radiance reads .cal files by
    name; an absolute path needs no RAYPATH)."""
    path = getattr(_cal_file, "path", None)
    if path is None:
        import atexit
        import os
        import tempfile

        fd, path = tempfile.mkstemp(prefix="radiosity-spot-", suffix=".cal")
        with os.fdopen(fd, "w") as f:
            f.write(SPOT_CAL)
        atexit.register(os.remove, path)
        _cal_file.path = path
    return path


def spot_sensors():
    """(points, normals, labels): the table top (facing up) and the floor beside the table
    (facing up) on both sides of the spot's cone edge and through its blend."""
    table = [[x, y, 0.75] for x in np.linspace(1.85, 3.15, 8) for y in np.linspace(1.45, 2.25, 5)]
    floor = [[x, 1.85, 0.0] for x in np.concatenate([np.linspace(0.6, 1.7, 12),
                                                     np.linspace(3.3, 4.4, 12)])] + \
        [[2.5, y, 0.0] for y in np.linspace(0.2, 1.3, 10)]
    points = np.array(table + floor, float)
    normals = np.tile([0.0, 0.0, 1.0], (len(points), 1))
    return points, normals, np.array(["table"] * len(table) + ["floor"] * len(floor))


def sensors():
    """(points, normals, labels) on the ceiling and on the walls x = 5 and y = 0."""
    xs, ys, zs = np.linspace(0.3, 4.7, 8), np.linspace(0.3, 3.7, 6), np.linspace(0.3, 2.4, 5)
    ceiling = [[x, y, 2.7] for x in xs for y in ys]
    walls = [[5.0, y, z] for y in ys for z in zs] + \
        [[x, 0.0, z] for x in np.linspace(0.7, 4.7, 6) for z in zs]
    points = np.array(ceiling + walls, float)
    normals = np.array([[0, 0, -1.0]] * len(ceiling) + [[-1.0, 0, 0]] * 30 + [[0, 1.0, 0]] * 30)
    labels = np.array(["ceiling"] * len(ceiling) + ["walls"] * 60)
    return points, normals, labels


def ours_cie(points, normals):
    """Irradiance (n, 3) under ``sky='cie_overcast'`` at the gensky case's outdoor level."""
    from core.bake import bake
    from core.lux import LUMENS_PER_WATT, illuminance_at
    from core.scene import make_scene
    from core.settings import BakeSettings
    from core.sky import CIEOvercast, zenith_radiance

    lux = LUMENS_PER_WATT * CIE_IRRADIANCE
    scene = make_scene(**room_arrays(), world=CIEOvercast(zenith_radiance(lux)))
    res = bake(scene, BakeSettings(output_mode="vertices", patch_size=0.25, element_levels=0,
                                   sky="cie_overcast", sky_illuminance=lux))
    E = illuminance_at(res, points + LIFT * normals, normals) / LUMENS_PER_WATT
    return np.repeat(E[:, None], 3, axis=1)


def ours_direct(case, points, normals):
    """The lights' direct irradiance (n, 3) alone, one shadow ray to each light's centre."""
    from core.lights import DirectLight
    from core.patches import make_patches
    from core.scene import make_scene

    scene = make_scene(**room_arrays(), lights=CASES[case])
    direct = DirectLight(scene.lights, make_patches(scene, 0.25), samples=1)
    return np.pi * direct.incident(points + LIFT * normals, normals)


def ours(case, points, normals):
    if case == "cie":
        return ours_cie(points, normals)
    from core.bake import bake
    from core.hemicube import point_rows
    from core.lights import DirectLight
    from core.scene import make_scene
    from core.settings import BakeSettings

    scene = make_scene(**room_arrays(), lights=CASES[case] or None, world=WORLDS.get(case))
    res = bake(scene, BakeSettings(output_mode="vertices", patch_size=0.25, element_levels=0))
    at = points + LIFT * normals
    rows = point_rows(res.patches, at, normals, resolution=256)
    extra = DirectLight(scene.lights, res.patches, world=scene.world).extra(at, normals,
                                                                           rows.sum(axis=1))
    return np.pi * (rows @ res.node_radiance + extra)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", nargs="+", default=list(CASE_NAMES), choices=CASE_NAMES)
    ap.add_argument("--nproc", type=int, default=2)
    args = ap.parse_args(argv)
    plane = np.array([[x, y, 0.85] for x in np.linspace(0.5, 4.5, 6)
                      for y in np.linspace(0.4, 3.6, 5)])
    to_rad = radiance.to_rad
    for case in args.cases:
        points, normals, labels = sensors()
        if case == "cie":
            points = np.concatenate([points, plane])
            normals = np.concatenate([normals, np.tile([0, 0, 1.0], (len(plane), 1))])
            labels = np.concatenate([labels, ["work plane"] * len(plane)])
        if case == "spot":
            more = spot_sensors()
            points, normals, labels = (np.concatenate([a, b]) for a, b in
                                       zip((points, normals, labels), more))
        extra = sources(case)

        def with_source(arrays, two_sided_lights=True, emitter="glow"):
            return to_rad(arrays, two_sided_lights, emitter) + extra

        radiance.to_rad = with_source
        try:
            E_rad, seconds = radiance.irradiance(room_arrays(), points, normals, params=PARAMS,
                                                 nproc=args.nproc)
            if case == "spot":
                D_rad = radiance.irradiance(room_arrays(), points, normals,
                                            params=DIRECT_PARAMS, nproc=args.nproc)[0] @ LUMA
        finally:
            radiance.to_rad = to_rad
        E_ours = ours(case, points, normals)
        if case == "cie":       # ours is illuminance (a luminance); Radiance's RGB to one too
            E_rad = np.repeat((E_rad @ LUMA)[:, None], 3, axis=1)
        for where in ("ceiling", "walls", "work plane", "table", "floor"):
            m = labels == where
            if not m.any():
                continue
            a, b = E_ours[m].mean(axis=0), E_rad[m].mean(axis=0)
            print("%s %-7s ours %s  Radiance %s  ratio %s" % (
                case, where, np.array2string(a, precision=4), np.array2string(b, precision=4),
                np.array2string(a / b, precision=3)))
            if case == "spot":
                r = (E_ours[m] @ LUMA) / (E_rad[m] @ LUMA)
                print("%s %-7s per sensor ratio (luminance) %.3f to %.3f, median %.3f" % (
                    case, where, r.min(), r.max(), np.median(r)))
        if case == "spot":
            D_ours = ours_direct(case, points, normals) @ LUMA
            for where in ("table", "floor"):
                m = (labels == where) & (D_rad > 0.01 * D_rad.max())
                r = D_ours[m] / D_rad[m]
                print("spot %-7s direct light alone, %d lit sensors: ratio %.4f to %.4f, "
                      "mean %.4f" % (where, m.sum(), r.min(), r.max(), r.mean()))
        if case == "cie":
            m = labels == "work plane"
            df_o, df_r = (100 * E[m, 0] / CIE_IRRADIANCE for E in (E_ours, E_rad))
            print("cie work plane daylight factor: ours mean %.3f %% (min %.3f), Radiance %.3f %% "
                  "(min %.3f); per point ratio %.3f to %.3f" % (
                      df_o.mean(), df_o.min(), df_r.mean(), df_r.min(),
                      (df_o / df_r).min(), (df_o / df_r).max()))
        print("%s: Radiance %.1f s" % (case, seconds))


if __name__ == "__main__":
    main()
