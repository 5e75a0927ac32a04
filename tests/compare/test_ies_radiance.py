"""Measured light distributions (IES LM-63) against Radiance's own reader (needs pyradiance).

Radiance's ``ies2rad`` turns a published IES file into a luminaire (its luminous opening with a
``brightdata`` distribution, candela / 179 lm/W), an independent parser, interpolator and unit
convention; ``rtrace -I -ab 0`` gives the direct irradiance at floor points 2 m under it. Ours
is core.photometry's reader on a point light (core.lights.DirectLight) of power 177.83 / 179 W
with ``photometry_scale='cycles'`` (candela x 4 pi / 177.83 W, Cycles' IES node), which is then
Radiance's candela / 179 W/sr.

Tolerance 1 %: Radiance's luminous opening is a disk or box of a few centimetres (at 2 m its
near field is below 0.1 %) and the two programs interpolate differently between the table's
angles where the candela curve bends (measured 0.53 % at worst, at the BEGA flood's cut-off).
Where it breaks: the C-planes' orientation. Radiance's C = 0 runs along +X; ours is the light's
``c0`` (Blender's -Y of the light object by default), so the same file with ``c0`` along +Y
reads up to 40 % apart on the Lithonia head (quadrant symmetry).
"""

import os
import subprocess
import tempfile
from pathlib import Path

import numpy as np
import pytest

pr = pytest.importorskip("pyradiance")

from core.lights import DirectLight  # noqa: E402
from core.patches import make_patches  # noqa: E402
from core.photometry import read_ies  # noqa: E402
from core.scene import scene_from_polygons  # noqa: E402

DATA = Path(__file__).resolve().parents[1] / "core" / "data"
BIN = Path(pr.__file__).parent / "bin"
HEIGHT = 2.0
RTOL = 0.01


def _floor_points():
    """60 floor points on a spiral out to 4 m: every C-plane and gamma from 0 to 63 degrees."""
    r, phi = np.sqrt(np.linspace(0.0, 16.0, 60)), np.linspace(0.0, 14.0 * np.pi, 60)
    return np.stack([r * np.cos(phi), r * np.sin(phi), np.zeros_like(r)], axis=1)


def _radiance(ies, points):
    """Radiance's direct irradiance (W/m^2) at ``points`` facing up, the file's luminaire at
    (0, 0, HEIGHT) pointing down (ies2rad's own orientation), a white lamp (``-t default``)."""
    with tempfile.TemporaryDirectory() as tmp:
        run = dict(cwd=tmp, check=True, capture_output=True)
        subprocess.run([str(BIN / "ies2rad"), "-dm", "-t", "default", "-o", "lum", str(ies)], **run)
        Path(tmp, "scene.rad").write_text(f"!xform -t 0 0 {HEIGHT} lum.rad\n")
        Path(tmp, "scene.oct").write_bytes(
            subprocess.run([str(BIN / "oconv"), "scene.rad"], **run).stdout)
        up = np.tile([0.0, 0.0, 1.0], (len(points), 1))
        rays = np.hstack([points + 1e-4 * up, up]).astype(np.float64).tobytes()
        out = subprocess.run([str(BIN / "rtrace"), "-h", "-fdd", "-I", "-ab", "0", "-dj", "0",
                              "-ds", "0", "scene.oct"], input=rays, **run).stdout
    return np.frombuffer(out, np.float64).reshape(-1, 3)


def _ours(ies, points, c0):
    light = dict(kind="point", name="Luminaire", position=(0.0, 0.0, HEIGHT),
                 power=177.83 / 179.0, photometry=read_ies(str(ies)),
                 photometry_scale="cycles", c0=c0)
    ground = [[-9, -9, -1], [9, -9, -1], [9, 9, -1], [-9, 9, -1]]     # nothing in the way
    scene = scene_from_polygons(np.array(ground, float), [[0, 1, 2, 3]], [0], [[0.5] * 3],
                                [[0, 0, 0]], lights=[light])
    direct = DirectLight(scene.lights, make_patches(scene, 5.0), samples=1)
    return np.pi * direct.incident(points, np.tile([0.0, 0.0, 1.0], (len(points), 1)))


@pytest.mark.parametrize("name", ["bega_8701", "lithonia_ela_cds"])
def test_an_ies_light_matches_radiances_ies2rad(name):
    """Ours against Radiance per floor point, per colour channel, where the light is at least
    0.1 % of its peak (the BEGA flood is a narrow beam)."""
    ies, points = DATA / f"{name}.ies", _floor_points()
    theirs = _radiance(ies, points)
    ours = _ours(ies, points, c0=(1.0, 0.0, 0.0))
    lit = theirs[:, 0] > 1e-3 * theirs[:, 0].max()
    assert lit.sum() >= 10
    np.testing.assert_allclose(ours[lit], theirs[lit], rtol=RTOL)
    assert np.all(ours[~lit] < 2e-3 * theirs[:, 0].max())


def test_the_c_planes_orientation_is_what_breaks_it():
    """The Lithonia head's C-planes differ (quadrant symmetry): turned a quarter (c0 along +Y
    instead of Radiance's +X), the same file reads far from Radiance."""
    ies, points = DATA / "lithonia_ela_cds.ies", _floor_points()
    theirs = _radiance(ies, points)[:, 0]
    turned = _ours(ies, points, c0=(0.0, 1.0, 0.0))[:, 0]
    assert np.abs(turned / theirs - 1.0).max() > 0.2
