"""Refinement rules of the radiosity mesh (core.criteria) on a hand-made field.

A one-quad floor's element tree is split once; its corners then carry a field chosen here, so the
answer of each rule is known without a bake.
"""

import numpy as np
import pytest

from core import BakeSettings, scene_from_polygons
from core.criteria import interpolation_errors, per_leaf_scores
from core.hierarchy import ElementTree
from core.patches import make_patches

SIZE = 4.0


def split_floor():
    # The floor, and a small emitter above it (a scene must have one; its leaves are left out).
    verts = np.array([[0, 0, 0], [SIZE, 0, 0], [SIZE, SIZE, 0], [0, SIZE, 0],
                      [1, 1, 3], [1, 1.1, 3], [1.1, 1.1, 3], [1.1, 1, 3]], float)
    scene = scene_from_polygons(verts, [[0, 1, 2, 3], [4, 5, 6, 7]], [0, 1],
                                [[0.5] * 3, [0.0] * 3], [[0.0] * 3, [1.0] * 3])
    tree = ElementTree.from_patches(scene, make_patches(scene, SIZE))
    tree, _ = tree.split(np.ones(tree.n_leaves, dtype=bool))
    return tree, tree.conforming()


def scores(field, contrast=0.1):
    tree, conf = split_floor()
    pts = conf["corner_verts"]
    y = field(tree.points[pts])
    interp = interpolation_errors(tree, pts, y, floor=1e-9)[pts]
    C, E = pts.size, tree.n_leaves
    args = (tree, conf, y, np.zeros(C, np.int64), np.zeros(C, bool), np.zeros(E, bool), 1e-9,
            BakeSettings(contrast=contrast))
    floor = tree.leaf_face == 0
    floor_corner = np.repeat(floor[conf["face_leaf"]], conf["face_sizes"])
    with_rule, _ = per_leaf_scores(*args, corner_interp=interp)
    without, _ = per_leaf_scores(*args)
    assert floor.sum() == 4
    return interp[floor_corner], with_rule[floor], without[floor]


def test_a_linear_gradient_is_not_split_again():
    # Light rising 1 -> 3 across the floor: every child spans 50 % (> contrast), but each
    # parent-edge midpoint is exactly the mean of its ends, so the output's interpolation already
    # draws it.
    interp, with_rule, without = scores(lambda p: 1.0 + 0.5 * p[:, 0])
    assert np.all(without > 0)
    np.testing.assert_allclose(interp[np.isfinite(interp)], 0.0, atol=1e-12)
    assert np.all(with_rule == 0)


@pytest.mark.parametrize("curvature", [0.5, 2.0])
def test_a_curved_field_is_still_split(curvature):
    # A pool of light in the middle of the floor, not reaching its edges: the edge midpoints
    # agree with their ends, but the centre stands far above the mean of the quad's corners, so
    # every child is split as before.
    def pool(p):
        r2 = ((p[:, :2] - SIZE / 2) ** 2).sum(axis=1)
        return 1.0 + curvature * np.maximum(0.0, SIZE ** 2 / 4 - r2)

    interp, with_rule, without = scores(pool)
    assert np.nanmax(interp) > 0.1
    np.testing.assert_array_equal(with_rule, without)
    assert np.all(with_rule > 0)


def test_the_rule_follows_the_contrast_setting():
    # A steep ramp with a slight bend: every child spans far more than the contrast, but the
    # midpoints are only ~5 % off linear. Not split again at contrast 0.1; at 0.02 the midpoints'
    # error exceeds the setting and the children are split.
    def bent(p):
        x = p[:, 0] / SIZE
        return 1.0 + 2.0 * x + 0.4 * x * (1 - x)

    interp, loose, without = scores(bent, contrast=0.1)
    assert 0.02 < np.nanmax(interp) < 0.1
    assert np.all(without > 0)
    assert np.all(loose == 0)
    _, tight, _ = scores(bent, contrast=0.02)
    assert np.all(tight > 0)
