"""The far field's drawings (core.farfield): a batch's mix of far patches and near elements cut
out of one drawing of them all (:class:`core.farfield.Union`).

Oracle: the same mix drawn anew (``draw_polygons`` and its ``Geometry``, as every batch drew it
before), array for array, and the rows a gather reads from either, bit for bit.
"""

import numpy as np
import pytest

from core.farfield import Drawn, FarField, Seen, Union
from core.hemicube import draw_polygons, point_rows
from core.hemicube_chunk import Geometry
from core.patches import make_patches, subdivide_patches
from bench.scenes import room_with_boxes

FIELDS = ("poly_patch", "verts", "poly_v", "plane_n", "plane_c", "diag")


def _parts():
    """The room's patches, and its elements with every 5th one a triangle (its last corner
    repeated) and every 7th one bent out of its plane: drawn as triangles, after the quads."""
    scene = room_with_boxes(24)
    patches = make_patches(scene, 0.5)
    elements, parent = subdivide_patches(patches, np.ones(patches.areas.size, dtype=bool))
    seen = Seen(elements, np.arange(elements.areas.size))
    seen.corners = seen.corners.copy()
    seen.corners[::5, 3] = seen.corners[::5, 2]
    seen.corners[3::7, 2] += 0.05 * seen.normals[3::7]
    return patches, seen, parent


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_mix_cut_from_the_union_is_the_mix_drawn_anew(seed):
    patches, seen, parent = _parts()
    has = np.zeros(patches.areas.size, dtype=bool)
    has[parent] = True
    union = Union(patches, has, seen)
    rng = np.random.default_rng(seed)
    far = has & (rng.uniform(size=has.size) < 0.4)
    whole = np.flatnonzero(far)
    near = np.flatnonzero(~far[parent])
    drawn = Drawn(Seen(patches, whole), Seen(seen, near))
    polys, poly_patch = draw_polygons(drawn)
    assert np.count_nonzero(polys[:, 3] == polys[:, 2]) > 0      # triangles among the quads
    want = Geometry(polys, poly_patch, drawn.normals)
    _, cut_patch, got = union.cut(whole, near)
    np.testing.assert_array_equal(cut_patch, poly_patch)
    for name in FIELDS:
        np.testing.assert_array_equal(getattr(got, name), getattr(want, name), err_msg=name)
    # The rows a gather reads from the cut equal those from the mix drawn anew, bit for bit.
    points = np.column_stack([rng.uniform(1.0, 3.0, 40), rng.uniform(1.0, 3.0, 40),
                              np.full(40, 0.01)])
    normals = np.tile([0.0, 0.0, 1.0], (40, 1))
    kw = dict(resolution=32, rotate=True)
    cut = Drawn(Seen(patches, whole), Seen(seen, near), drawing=union.cut(whole, near))
    np.testing.assert_array_equal(point_rows(cut, points, normals, rng=np.random.default_rng(3),
                                             **kw),
                                  point_rows(drawn, points, normals,
                                             rng=np.random.default_rng(3), **kw))


def test_the_far_field_draws_its_union_once():
    patches, seen, parent = _parts()
    field = FarField(patches, seen, parent)
    rng = np.random.default_rng(4)
    normals = np.tile([0.0, 0.0, 1.0], (16, 1))
    for x in (0.5, 2.0, 3.5):                       # batches with other far sets
        points = np.column_stack([rng.uniform(x, x + 0.3, 16), rng.uniform(0.5, 0.8, 16),
                                  np.full(16, 0.01)])
        field.rows(points, normals, resolution=32)
        assert field._last is not None and field._last[1].drawing is not None
        if x == 0.5:
            union = field._union
        assert field._union is union
    field.release()
    assert field._union is None and field._last is None
