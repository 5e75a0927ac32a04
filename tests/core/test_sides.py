"""Back-side materials through the bake: a one-sided emitter (an area light) against a two-sided
one (a Cycles mesh light)."""

import numpy as np

from core import BakeSettings, bake, scene_from_polygons


def _panel_under_ceiling(back_emission):
    # A 1 x 1 ceiling (normal down) at z = 1 and a 1 x 1 panel at z = 0.5 facing down, its back
    # facing the ceiling. Nothing else: the ceiling sees only the panel's back.
    verts = np.array([[0, 0, 1], [0, 1, 1], [1, 1, 1], [1, 0, 1],
                      [0, 0, 0.5], [0, 1, 0.5], [1, 1, 0.5], [1, 0, 0.5]], dtype=float)
    polys = [[0, 1, 2, 3], [4, 5, 6, 7]]
    kw = {}
    if back_emission is not None:
        kw = dict(back_reflectance=[[0.5] * 3, [0.0] * 3], back_emission=back_emission)
    return scene_from_polygons(verts, polys, [0, 1], [[0.5] * 3, [0.0] * 3],
                               [[0.0] * 3, [4.0] * 3], **kw)


def test_one_sided_emitter_leaves_the_ceiling_dark():
    settings = BakeSettings(patch_size=0.25, method="exact")
    two = bake(_panel_under_ceiling(None), settings)
    one = bake(_panel_under_ceiling([[0.0] * 3, [0.0] * 3]), settings)
    ceiling = two.patches.material == 0
    # Two-sided: ceiling lit by the back at rho * F * Le, F of opposed unit squares 0.5 apart
    # (Howell C-11, X = Y = 2: F = 0.4152); the patch mean equals the face's F exactly.
    A = two.patches.areas[ceiling]
    mean = (A[:, None] * two.patch_radiance[ceiling]).sum(0) / A.sum()
    np.testing.assert_allclose(mean, 0.5 * 0.41525 * 4.0, rtol=2e-3)
    # One-sided: nothing reaches the ceiling; the panel's front still emits.
    assert not one.patch_radiance[ceiling].any()
    np.testing.assert_array_equal(one.patch_radiance[~ceiling], 4.0)
    # ... and its back node carries no emission.
    P = one.report["patches"]
    assert not one.node_radiance[P:][~ceiling].any()
