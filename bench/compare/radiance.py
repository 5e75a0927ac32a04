"""Radiance irradiance at sensor points (``pyradiance``: oconv + ``rtrace -I``).

The scene arrays (``core.scene.make_scene`` layout) become a .rad file: each face a ``polygon``;
a material with rho becomes ``plastic`` with zero specularity and roughness (Radiance's plastic is
then Lambertian with reflectance rho, reflecting on both sides); an emitting material becomes
``light`` with its radiance. A Radiance ``light`` polygon emits from its front only, while Cycles
mesh lights (and our two-sided default) emit from both faces, so every emitting face is written
twice, once reversed (``two_sided_lights=True``). A ``light`` surface reflects nothing: give
emitters rho = 0 in a benchmark scene so that all three programs agree.

Units: rtrace -I returns irradiance E (W/m^2 per RGB channel, Blender's scene-linear units when the
light radiance is Blender's strength x colour). A Lambertian surface with reflectance rho under
irradiance E leaves with radiance L = rho E / pi, so a bake is compared through E = pi L / rho.
"""

import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

#: High-accuracy rtrace settings for a reference: -ab 12 bounces (rho <= 0.8: the missing tail is
#: below 0.8^13 / 0.2 of the total only in a furnace; measured converged by -ab 8 in docs/benchmark.md);
#: -ad 8192 hemisphere samples, -as 0 (measured: -as 2048 with -aa 0 read 4 % low against Cycles in
#: a closed room); -aa 0 turns the irradiance cache off (every sensor sampled, no interpolation);
#: -lw 1e-6 and -lr -16 keep weak paths; -dj 1 -ds 0.01 -dt 0 -dc 1: area lights split finely and
#: jittered (-dj 0 samples sub-sources at their centres: 0.33 % bias under a 1 m square at 1 m).
ACCURATE = ("-ab", "12", "-ad", "8192", "-as", "0", "-aa", "0", "-lw", "1e-6", "-lr", "-16",
            "-dj", "1", "-ds", "0.01", "-dt", "0", "-dc", "1", "-dr", "0", "-ss", "0", "-st", "1")

#: Sensor origins are lifted by this distance (m) along the sensor normal, so that the first
#: ambient rays do not re-hit the surface the sensor lies on (Radiance's own offset is ~1e-6 of
#: the scene size, too small near a coplanar polygon edge).
SENSOR_LIFT = 1e-4


def _fmt(values):
    return " ".join("%.9g" % v for v in values)


def to_rad(arrays, two_sided_lights=True, emitter="glow"):
    """The .rad text of a scene in the ``make_scene`` array layout.

    Parameters
    ----------
    arrays : dict
        ``vertices`` (V, 3), ``corner_verts`` (C,), ``face_starts`` (F,), ``face_sizes`` (F,),
        ``face_materials`` (F,), ``reflectance`` (M, 3), ``emission`` (M, 3).
    two_sided_lights : bool
        Write each emitting face twice (both orientations) so it emits from both sides.
    emitter : {'light', 'glow'}
        ``'light'``: Radiance light sources (direct light by source sampling: fast and smooth, but
        biased low within a few source sizes of an emitter, where Radiance caps the source
        subdivision). ``'glow'`` with radius 0: emitters are never sources and are found only by
        the ambient (indirect) rays: unbiased, noisier. Default ``'glow'``: measured, a light
        panel 0.1 m below a ceiling lit the ceiling above it 5.5 % too weakly as ``'light'``.

    Returns
    -------
    str
    """
    V = np.asarray(arrays["vertices"], np.float64)
    cv = np.asarray(arrays["corner_verts"], np.int64)
    fs = np.asarray(arrays["face_starts"], np.int64)
    fn = np.asarray(arrays["face_sizes"], np.int64)
    fm = np.asarray(arrays["face_materials"], np.int64)
    rho = np.asarray(arrays["reflectance"], np.float64)
    em = np.asarray(arrays["emission"], np.float64)
    if V.ndim != 2 or V.shape[1] != 3:
        raise ValueError("vertices must have shape (V, 3); got %s" % (V.shape,))
    if rho.shape != em.shape or rho.ndim != 2 or rho.shape[1] != 3:
        raise ValueError("reflectance and emission must both be (M, 3); got %s and %s"
                         % (rho.shape, em.shape))
    if fm.size and (fm.min() < 0 or fm.max() >= len(rho)):
        raise ValueError("face_materials must index reflectance (M = %d)" % len(rho))
    if emitter not in ("light", "glow"):
        raise ValueError("emitter must be 'light' or 'glow'; got %r" % (emitter,))
    emitting = np.any(em > 0, axis=1)
    lines = []
    for m in range(len(rho)):
        if emitting[m] and emitter == "glow":
            lines.append("void glow m%d 0 0 4 %s 0" % (m, _fmt(em[m])))
        elif emitting[m]:
            lines.append("void light m%d 0 0 3 %s" % (m, _fmt(em[m])))
        else:
            lines.append("void plastic m%d 0 0 5 %s 0 0" % (m, _fmt(rho[m])))
    for f in range(len(fs)):
        pts = V[cv[fs[f]:fs[f] + fn[f]]]
        lines.append("m%d polygon f%d 0 0 %d %s" % (fm[f], f, 3 * len(pts), _fmt(pts.ravel())))
        if two_sided_lights and emitting[fm[f]]:
            lines.append("m%d polygon b%d 0 0 %d %s"
                         % (fm[f], f, 3 * len(pts), _fmt(pts[::-1].ravel())))
    return "\n".join(lines) + "\n"


def irradiance(arrays, points, normals, *, params=ACCURATE, two_sided_lights=True,
               emitter="glow", nproc=1, workdir=None):
    """Radiance irradiance (RGB, W/m^2) at sensor points facing along ``normals``.

    Parameters
    ----------
    arrays : dict
        Scene arrays (see :func:`to_rad`).
    points : (S, 3) float
        Sensor positions (on a surface or in the air, e.g. a 0.8 m work plane).
    normals : (S, 3) float
        Sensor orientations (need not be unit).
    params : sequence of str
        rtrace options (default :data:`ACCURATE`).
    two_sided_lights, emitter
        See :func:`to_rad`.
    nproc : int
        rtrace processes.

    Returns
    -------
    E : (S, 3) float64
    seconds : float
        Wall time of oconv + rtrace.
    """
    import pyradiance as pr

    p = np.asarray(points, np.float64)
    n = np.asarray(normals, np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError("points must have shape (S, 3); got %s" % (p.shape,))
    if n.shape != p.shape:
        raise ValueError("normals must have the shape of points %s; got %s" % (p.shape, n.shape))
    length = np.linalg.norm(n, axis=1)
    if np.any(length == 0) or not np.all(np.isfinite(p)):
        raise ValueError("normals must be non-zero and points finite")
    n = n / length[:, None]
    origins = p + SENSOR_LIFT * n
    with tempfile.TemporaryDirectory(dir=workdir) as tmp:
        rad = Path(tmp) / "scene.rad"
        rad.write_text(to_rad(arrays, two_sided_lights, emitter))
        t0 = time.perf_counter()
        octree = Path(tmp) / "scene.oct"
        octree.write_bytes(pr.oconv(str(rad)))
        rays = np.hstack([origins, n]).astype(np.float64).tobytes()
        out = pr.rtrace(rays, str(octree), header=False, inform="d", outform="d",
                        irradiance=True, params=list(params), nproc=int(nproc))
        seconds = time.perf_counter() - t0
    E = np.frombuffer(out, dtype=np.float64).reshape(-1, 3)
    if len(E) != len(p):
        raise RuntimeError("rtrace returned %d values for %d sensors" % (len(E), len(p)))
    return E.copy(), seconds
