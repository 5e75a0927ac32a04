"""Refinement rules of the radiosity mesh (core.criteria) on a hand-made field.

A one-quad floor's element tree is split once; its corners then carry a field chosen here, so the
answer of each rule is known without a bake.
"""

import numpy as np
import pytest

from core import BakeSettings, scene_from_polygons
from core.adaptive import MIN_ELEMENT
from core.criteria import (COPLANAR, STEEP_FLOOR, _Lines, cavity_mask, contact_points,
                           interpolation_errors, near_surfaces, per_leaf_scores, smallest_split)
from core.geometry import patch_extents
from core.hierarchy import ElementTree
from core.patches import make_patches
from core.refine import DARK_FLOOR

from builders import box_quads, quad_patches

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
            BakeSettings(contrast=contrast, min_element=MIN_ELEMENT))
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
        return 1.0 + 1.2 * x + 0.3 * x * (1 - x)

    interp, loose, without = scores(bent, contrast=0.1)
    assert 0.02 < np.nanmax(interp) < 0.1
    assert np.all(without > 0)
    assert np.all(loose == 0)
    _, tight, _ = scores(bent, contrast=0.02)
    assert np.all(tight > 0)


def test_an_edge_of_light_centred_on_the_midpoints_is_still_split():
    # A lamp's outline projected across the floor: bright (1) on one side, dark (0.1) on the
    # other, the step 0.3 m wide and centred on the middle. At its inflection the parent's edge
    # midpoints sit exactly on the line between their ends, so the midpoint test alone calls it
    # linear (interpolation error 0). Linear interpolation across the dark-side children is
    # far off (at x = 3 m it draws 0.33 where the light is 0.13): with their corners more
    # than core.criteria.LINEAR_RATIO apart they are split for contrast, as without the rule.
    def edge(p):
        return 0.1 + 0.9 / (1.0 + np.exp((p[:, 0] - SIZE / 2) / 0.3))

    interp, with_rule, without = scores(edge)
    np.testing.assert_allclose(interp[np.isfinite(interp)], 0.0, atol=1e-9)
    assert np.all(without > 0)
    tree, _ = split_floor()
    corners = tree.points[tree.leaves[tree.leaf_face == 0]]       # (4, 4, 3): quads
    dark = corners[:, :, 0].mean(axis=1) > SIZE / 2
    assert dark.sum() == 2
    np.testing.assert_array_equal(with_rule[dark], without[dark])
    assert np.all(with_rule[dark] > 0)
    # The bright side's children (0.55 to 1: within the ratio) keep the rule: that one midpoint
    # cannot see the step there is the rule's known limit.
    assert np.all(with_rule[~dark] == 0)


def test_steep_leaves_split_below_min_element():
    # Leaves 2 m wide, min_element 1.2 m: no leaf may split (2 x min_element = 2.4 m) unless it
    # is steep, along a contact line or against the scene's mean luminance too; there the limit
    # is 2 min_element sqrt(contrast / diff), never below STEEP_FLOOR x 2 min_element.
    tree, conf = split_floor()
    pts = conf["corner_verts"]
    C, E = pts.size, tree.n_leaves
    floor = tree.leaf_face == 0
    y = np.where(tree.points[pts][:, 0] < 1e-9, 0.1, 1.0)       # 90 % contrast across x

    def split(alone, mean, min_element=1.2):
        s, _ = per_leaf_scores(tree, conf, y, np.zeros(C, np.int64), alone, np.zeros(E, bool),
                               DARK_FLOOR * mean, BakeSettings(contrast=0.1,
                                                               min_element=min_element))
        return s[floor] > 0

    steep = np.repeat(floor[conf["face_leaf"]], conf["face_sizes"])
    nowhere = np.zeros(C, bool)
    # In a scene whose mean is 10 the step (0.1 to 1) is 0.18 against the dark floor (5), whose
    # limit is 2.4 m x sqrt(0.1 / 0.18) = 1.8 m, but 0.09 of the mean: it splits only along a
    # contact line.
    assert not split(nowhere, 10.0).any()
    assert split(steep, 10.0).sum() == 2            # the two leaves along x = 0
    # Where the mean is 1 the same step is a penumbra on a lit floor: it splits anywhere.
    assert split(nowhere, 1.0).sum() == 2
    # Over the limit (min_element 4 m: 8 m x sqrt(0.1 / 0.9) = 2.7 m), not even a steep leaf
    # along a contact line splits.
    assert not split(steep, 1.0, min_element=4.0).any()
    settings = BakeSettings(contrast=0.1, min_element=1.5)
    limit = smallest_split(np.array([0.9, 0.1, 100.0]), settings)
    np.testing.assert_allclose(limit, [3.0 / 3.0, 3.0, 3.0 * STEEP_FLOOR])


def board_over_floor(gap, board_width, board_len=2.0):
    """A 4 m floor and a board of ``board_width`` x ``board_len`` facing it ``gap`` above."""
    w, l = board_width, board_len
    verts = np.array([[0, 0, 0], [4, 0, 0], [4, 4, 0], [0, 4, 0],
                      [1, 1, gap], [1, 1 + w, gap], [1 + l, 1 + w, gap], [1 + l, 1, gap],
                      [0, 0, 3], [0, 0.1, 3], [0.1, 0.1, 3], [0.1, 0, 3]], float)
    return scene_from_polygons(verts, [[0, 1, 2, 3], [4, 5, 6, 7], [8, 9, 10, 11]], [0, 0, 1],
                               [[0.5] * 3, [0.0] * 3], [[0.0] * 3, [1.0] * 3])


def test_a_thin_cavity_splits_both_sides_down_to_its_gap():
    scene = board_over_floor(0.1, 0.5)
    patches = make_patches(scene, 1.0)
    mask = cavity_mask(patches)
    board, floor = patches.face == 1, patches.face == 0
    assert mask[board].all()                  # 1 m > 2 x 0.1 m
    # The floor under the board; the gap is bounded below by the patches' bounding spheres, so
    # its 1 m neighbours are marked too (their children are measured again the next round).
    c = patches.centres
    under = floor & (c[:, 0] > 1) & (c[:, 0] < 3) & (c[:, 1] > 1) & (c[:, 1] < 1.5 + 1e-9)
    near = floor & (c[:, 0] > 0) & (c[:, 0] < 4) & (c[:, 1] < 3)
    assert under.sum() == 2 and mask[under].all()
    assert not mask[floor & ~near].any()
    # One round later the floor patches far from the board's edge are no longer marked.
    again = make_patches(scene, 0.25)
    m2, c2 = cavity_mask(again), again.centres
    far = (again.face == 0) & ((c2[:, 1] > 2.2) | (c2[:, 0] > 3.7))
    assert m2[(again.face == 0) & (np.abs(c2[:, 0] - 2) < 0.5) & (np.abs(c2[:, 1] - 1.25) < 0.2)].all()
    assert not m2[far].any()
    assert not mask[patches.face == 2].any()  # the emitter faces the floor 3 m away
    # The same board 1 m up: no patch is wider than twice the gap.
    assert not cavity_mask(make_patches(board_over_floor(1.0, 0.5), 1.0)).any()
    # A strip narrower than the gap (an edge 2 cm wide, 5 cm up) forms no cavity.
    strip = make_patches(board_over_floor(0.05, 0.02), 1.0)
    assert not cavity_mask(strip).any()
    # In contact (gap 0), nothing: faces pressed together enclose no light.
    assert not cavity_mask(make_patches(board_over_floor(0.0, 0.5), 1.0)).any()
    # Never below min_size.
    assert not cavity_mask(patches, min_size=2.0).any()


def _boxes_and_a_slab(seed):
    """A room of 0.5 m quads, boxes in it at random, and a 40 m site plane in the floor's
    plane: its bounding sphere reaches every patch (the floor's patches stay not near it)."""
    rng = np.random.default_rng(seed)
    walls, _ = box_quads((4.0, 3.0, 2.5), 0.5)
    parts = [walls]
    for _ in range(4):
        block, _ = box_quads(tuple(rng.uniform(0.3, 1.2, 3)), 0.25)
        parts.append(block[:, ::-1] + rng.uniform([0.0, 0.0, 0.0], [3.0, 2.0, 1.0]))
    slab = np.array([[[-18.0, -18.0, 0.0], [22.0, -18.0, 0.0], [22.0, 21.0, 0.0],
                      [-18.0, 21.0, 0.0]]])
    return quad_patches(np.concatenate(parts + [slab]))


@pytest.mark.parametrize("seed", range(3))
def test_near_surfaces_is_its_definition_over_every_pair(seed):
    """Oracle: the docstring's rule over all pairs, one pair at a time (the function prunes
    pairs by their spheres' boxes, in blocks within outer blocks; it must not drop one that
    qualifies, whatever the block sizes)."""
    patches = _boxes_and_a_slab(seed)
    radius, _ = patch_extents(patches.corners, patches.centres)
    c, n = patches.centres, patches.normals
    want = np.zeros(c.shape[0], dtype=bool)
    for p in range(c.shape[0]):
        d = c - c[p]
        overlap = np.sqrt(np.sum(d * d, axis=1)) < radius[p] + radius
        apart = (np.abs(d @ n[p]) > COPLANAR * radius[p]) \
            & (np.abs(np.sum(d * n, axis=1)) > COPLANAR * radius)
        want[p] = np.any(overlap & apart)
    assert want.any() and not want.all()
    assert c.shape[0] > 64                  # several outer blocks at outer=64 below
    for chunk, outer in ((64, 64), (16, 64), (7, 40), (None, None)):   # None: the defaults
        kw = {} if chunk is None else dict(chunk=chunk, outer=outer)
        assert np.array_equal(near_surfaces(patches, **kw), want), (chunk, outer)


@pytest.mark.parametrize("seed", range(3))
def test_contact_points_is_its_definition_over_every_pair(seed):
    """Oracle: each point against each segment, one at a time (the function tests chunks of
    neighbouring points against the segments whose boxes meet theirs)."""
    rng = np.random.default_rng(seed)
    k = 60
    a = rng.uniform(-5.0, 5.0, (k, 3))
    u = rng.normal(size=(k, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    w = np.cross(u, rng.normal(size=(k, 3)))
    w /= np.linalg.norm(w, axis=1, keepdims=True)
    length = rng.uniform(0.01, 6.0, k)
    tol = 0.05
    lines = _Lines(a, u, w, length, tol)
    # Points on, beside and beyond the segments (about half of them within tol), and at random.
    pick = rng.integers(0, k, 3000)
    t = rng.uniform(-0.2, 1.2, pick.size) * length[pick]
    off = rng.normal(scale=tol, size=(pick.size, 3))
    points = np.concatenate([a[pick] + t[:, None] * u[pick] + off,
                             rng.uniform(-6.0, 6.0, (500, 3))])
    nrm = np.cross(u, w)
    want = np.zeros(points.shape[0], dtype=bool)
    for j in range(k):
        rel = points - a[j]
        s = rel @ u[j]
        want |= (np.abs(rel @ w[j]) <= tol) & (np.abs(rel @ nrm[j]) <= tol) \
            & (s >= -tol) & (s <= length[j] + tol)
    assert 0.1 < want.mean() < 0.9
    assert np.array_equal(contact_points(points, lines, chunk=5000), want)
