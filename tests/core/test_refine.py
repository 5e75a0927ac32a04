"""Adaptive refinement: patches are split only where the solved light changes."""

import importlib

import numpy as np
import pytest

from builders import horizontal_square
from core import BakeSettings, SettingsError, bake, scene_from_polygons
from core.patches import make_patches
from core.refine import refine_mask

bake_module = importlib.import_module("core.bake")


def _plane(n=8, size=1.0):
    return horizontal_square(0.0, size, n)


def _plane_patches(n=8):
    verts, quads = _plane(n)
    scene = scene_from_polygons(verts, quads, [0] * len(quads), [[0.5] * 3], [[1.0] * 3])
    return make_patches(scene, max_edge=1.0 / n)


def test_uniform_light_marks_nothing():
    p = _plane_patches()
    L = np.full((p.areas.size, 3), 0.3)
    assert not refine_mask(p, L, np.zeros(p.areas.size, bool)).any()


def test_a_shadow_edge_marks_exactly_the_patches_along_it():
    p = _plane_patches()
    x = p.centres[:, 0]
    L = np.where((x < 0.5)[:, None], 1.0, 0.2) * np.ones((1, 3))      # step at x = 0.5
    mask = refine_mask(p, L, np.zeros(p.areas.size, bool), threshold=0.1)
    # Patches sharing a corner with the other side: the two columns next to x = 0.5.
    want = np.abs(x - 0.5) < 1.0 / 8
    np.testing.assert_array_equal(mask, want)


def test_smooth_gradient_below_threshold_marks_nothing():
    p = _plane_patches()
    L = (1.0 + 0.05 * p.centres[:, 0])[:, None] * np.ones((1, 3))     # < 1 % per patch
    assert not refine_mask(p, L, np.zeros(p.areas.size, bool), threshold=0.1).any()


def test_emitters_and_tiny_patches_are_never_marked():
    p = _plane_patches()
    x = p.centres[:, 0]
    L = np.where((x < 0.5)[:, None], 1.0, 0.2) * np.ones((1, 3))
    assert not refine_mask(p, L, np.ones(p.areas.size, bool)).any()
    assert not refine_mask(p, L, np.zeros(p.areas.size, bool), min_area=1.0).any()


def test_neighbours_across_a_crease_are_not_compared():
    # Floor (normal +z) and wall (normal -x... facing the floor) meeting at x = 1: very
    # different light, but different surfaces: nothing marked.
    verts = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
                      [1, 0, 0], [1, 0, 1], [1, 1, 1], [1, 1, 0]], float)
    scene = scene_from_polygons(verts, [[0, 1, 2, 3], [4, 5, 6, 7]], [0, 0], [[0.5] * 3],
                                [[1.0] * 3])
    p = make_patches(scene, max_edge=0.5)
    L = np.where((p.face == 0)[:, None], 1.0, 0.1) * np.ones((1, 3))
    assert not refine_mask(p, L, np.zeros(p.areas.size, bool)).any()


@pytest.mark.parametrize("kwargs, message", [
    (dict(threshold=0.0), r"threshold must be in \(0, 1\); got 0.0"),
    (dict(threshold=1.5), r"threshold must be in \(0, 1\); got 1.5"),
])
def test_refine_mask_refuses_bad_threshold(kwargs, message):
    p = _plane_patches(2)
    with pytest.raises(ValueError, match=message):
        refine_mask(p, np.ones((p.areas.size, 3)), np.zeros(p.areas.size, bool), **kwargs)


def test_refine_mask_refuses_bad_shapes():
    p = _plane_patches(2)
    with pytest.raises(ValueError, match=r"patch_radiance must have shape \(4, 3\); got \(3, 3\)"):
        refine_mask(p, np.ones((3, 3)), np.zeros(4, bool))
    with pytest.raises(ValueError, match=r"emitting must have shape \(4,\); got \(5,\)"):
        refine_mask(p, np.ones((4, 3)), np.zeros(5, bool))


def _shadowed_floor():
    # A 2 x 2 m floor of 4 faces, a small panel 1 m up facing down, and a blocker plate between
    # them casting a sharp shadow: the light changes strongly only around the shadow.
    fv, fq = _plane(2, 2.0)
    panel = np.array([[0.9, 0.9, 1.0], [0.9, 1.1, 1.0], [1.1, 1.1, 1.0], [1.1, 0.9, 1.0]])
    blocker = np.array([[0.2, 0.2, 0.5], [0.2, 0.8, 0.5], [0.8, 0.8, 0.5], [0.8, 0.2, 0.5]])
    verts = np.vstack([fv, panel, blocker])
    n = len(fv)
    polys = fq + [[n, n + 1, n + 2, n + 3], [n + 4, n + 5, n + 6, n + 7]]
    mats = [0] * len(fq) + [1, 2]
    return scene_from_polygons(verts, polys, mats, [[0.5] * 3, [0.0] * 3, [0.5] * 3],
                               [[0.0] * 3, [20.0] * 3, [0.0] * 3])


def test_refined_bake_spends_patches_at_the_shadow_and_reports_levels():
    scene = _shadowed_floor()
    base = bake(scene, BakeSettings(patch_size=0.25, method="hemicube"))
    ref = bake(scene, BakeSettings(patch_size=0.25, method="hemicube", refine_levels=1,
                                   refine_threshold=0.25))
    steps = ref.report["refinement"]
    assert steps[0]["patches"] == base.report["patches"]
    assert 0 < steps[1]["split"] < base.report["patches"]
    assert steps[1]["patches"] == steps[0]["patches"] + 3 * steps[1]["split"]
    assert ref.report["patches"] == steps[1]["patches"]
    # The blocker's umbra, projected from the panel at (1, 1, 1), covers x, y < 0.6 of the
    # floor: the cell straddling its edge, [0.5, 0.75] x [0, 0.25], is split; a cell deep in
    # the umbra, [0, 0.25]^2, whose neighbours are as dark as itself, is not.
    c = ref.patches.centres
    on_edge = (c[:, 0] > 0.5) & (c[:, 0] < 0.75) & (c[:, 1] < 0.25) & (c[:, 2] < 1e-9)
    in_umbra = (c[:, 0] < 0.25) & (c[:, 1] < 0.25) & (c[:, 2] < 1e-9)
    np.testing.assert_allclose(ref.patches.areas[on_edge], 0.125 ** 2)
    np.testing.assert_allclose(ref.patches.areas[in_umbra], 0.25 ** 2)
    assert ref.report["timings"]["total"] >= ref.report["timings"]["form_factors"]
    assert abs(ref.report["energy"]["balance"]) < 1e-3 * ref.report["energy"]["emitted"]


def test_progress_is_monotone_across_levels():
    seen = []
    bake(_shadowed_floor(), BakeSettings(patch_size=0.5, method="hemicube", refine_levels=2,
                                         refine_threshold=0.25),
         progress=lambda f, m: seen.append(f))
    assert all(b >= a for a, b in zip(seen, seen[1:]))
    assert 0.0 <= seen[0] and seen[-1] <= 1.0


@pytest.mark.parametrize("kwargs, message", [
    (dict(refine_levels=5), r"refine_levels must be an integer in \[0, 4\]; got 5"),
    (dict(refine_levels=-1), r"refine_levels must be an integer in \[0, 4\]; got -1"),
    (dict(refine_threshold=0.0), r"refine_threshold must be a number in \(0, 1\); got 0.0"),
])
def test_refine_settings_are_validated(kwargs, message):
    with pytest.raises(SettingsError, match=message):
        BakeSettings(**kwargs)
