"""The final gather at vertices against closed forms (shared/reference/form_factors.md)."""

import numpy as np
import pytest

from core import BakeSettings, bake, scene_from_polygons
from core.gather import corner_groups
from core.hemicube import point_rows
from core.patches import make_patches

#: Differential area to a parallel rectangle with one corner above the point, a = b = c = 1.
F_CORNER_UNIT = 0.1385316060


def _floor_and_panel(rho=0.5, le=2.0):
    # Floor [0, 2] x [0, 2] at z = 0 (normal up) as 2 x 2 quads; a 1 x 1 panel over [0, 1]^2 at
    # z = 1 facing down, black (rho 0). The floor vertex (0, 0, 0) sees the panel as a
    # rectangle with one corner straight above it: F = 0.1385316060.
    g = [0.0, 1.0, 2.0]
    verts = [(x, y, 0.0) for y in g for x in g] + [(0, 0, 1), (0, 1, 1), (1, 1, 1), (1, 0, 1)]
    quads = [[0, 1, 4, 3], [1, 2, 5, 4], [3, 4, 7, 6], [4, 5, 8, 7], [9, 10, 11, 12]]
    return scene_from_polygons(np.array(verts, float), quads, [0, 0, 0, 0, 1],
                               [[rho] * 3, [0.0] * 3], [[0.0] * 3, [le] * 3])


@pytest.mark.parametrize("resolution, tol", [(64, 1e-3), (256, 1e-4)])
def test_point_rows_match_the_corner_rectangle_closed_form(resolution, tol):
    # Tolerance: pixel quantisation of the rectangle's edges on the hemicube; the edges here
    # run along pixel rows and columns, so it is far below the general ~1/R (measured 6.8e-5 at
    # R = 64, 4.3e-6 at R = 256).
    scene = _floor_and_panel()
    p = make_patches(scene, max_edge=1.0)
    panel = np.flatnonzero(p.material == 1)
    rows = point_rows(p, [[0.0, 0.0, 0.0]], [[0.0, 0.0, 1.0]], resolution=resolution)
    assert rows[0, panel].sum() == pytest.approx(F_CORNER_UNIT, rel=tol)
    assert rows[0, panel + p.areas.size].sum() == 0.0      # the panel's back faces away


def test_point_rows_refuse_bad_input():
    p = make_patches(_floor_and_panel(), max_edge=1.0)
    with pytest.raises(ValueError, match=r"points and normals must both have shape \(S, 3\)"):
        point_rows(p, [[0.0, 0.0]], [[0.0, 0.0, 1.0]])
    with pytest.raises(ValueError, match=r"normals must be unit vectors; normals\[0\] has length 2"):
        point_rows(p, [[0.0, 0.0, 0.0]], [[0.0, 0.0, 2.0]])


def test_gathered_corner_equals_rho_le_f_at_the_vertex():
    # Only the panel's front lights the floor, and the panel reflects nothing: the radiance at
    # the floor vertex under the panel's corner is exactly rho * Le * F. The patch average gives
    # the mean over the corner patch instead, which is far brighter (the patch lies under the
    # panel). Tolerance 0.2 %: R = 64 pixel quantisation (7e-5 measured) and the eye's inset of
    # 0.1 % of the face size towards the face centre.
    scene = _floor_and_panel(rho=0.5, le=2.0)
    res = bake(scene, BakeSettings(patch_size=1.0, resolution=64, rotate_hemicube=False))
    corner = np.flatnonzero((scene.corner_verts == 0))
    np.testing.assert_allclose(res.corner_colours[corner], 0.5 * 2.0 * F_CORNER_UNIT, rtol=2e-3)
    avg = bake(scene, BakeSettings(patch_size=1.0, resolution=64, rotate_hemicube=False,
                                   corners="average", output_mode="vertices"))
    assert avg.corner_colours[corner].min() > 1.5 * 0.5 * 2.0 * F_CORNER_UNIT


def test_corner_groups_share_a_gather_on_one_smooth_surface_only():
    scene = _floor_and_panel()
    g = corner_groups(scene)
    # The centre floor vertex (4) has 4 corners on one flat surface: one group.
    centre = np.flatnonzero(scene.corner_verts == 4)
    assert len(set(g.group[centre].tolist())) == 1
    # Floor and panel never share a group (different material, opposite normals).
    assert not set(g.group[scene.corner_verts < 9]) & set(g.group[scene.corner_verts >= 9])
    np.testing.assert_allclose(np.linalg.norm(g.normals, axis=1), 1.0)
