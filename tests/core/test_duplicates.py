"""Coincident duplicate faces (issue 11): solved as one surface, reported by object name.

Oracle: the same room with and without the duplicate gives the same corner colours (same
seed), since the duplicate makes no patch and takes the kept face's colours.
"""

import numpy as np
import pytest

from core.bake import bake
from core.duplicates import (DUPLICATE_RTOL, NEAR_DUPLICATE_RTOL, find_duplicates,
                             near_duplicate_warning)
from core.scene import scene_from_polygons
from core.settings import BakeSettings

#: Same patches, same seed: the bakes agree up to rounding.
SAME_RTOL = 1e-9


def _room(extra=()):
    """A 4 x 3 x 2.5 m room (walls one quad each, inward), a box on the floor, a ceiling lamp;
    ``extra``: (vertices (4, 3), object name) quads appended after the room."""
    W, D, H = 4.0, 3.0, 2.5
    v = [[0, 0, 0], [W, 0, 0], [W, D, 0], [0, D, 0], [0, 0, H], [W, 0, H], [W, D, H], [0, D, H]]
    polys = [[0, 1, 2, 3], [4, 7, 6, 5], [0, 4, 5, 1], [1, 5, 6, 2], [2, 6, 7, 3], [3, 7, 4, 0]]
    mats, objs = [0, 0, 0, 0, 1, 0], [0, 1, 2, 2, 2, 2]
    b = len(v)
    v += [[1, 1, 0], [2, 1, 0], [2, 2, 0], [1, 2, 0], [1, 1, 0.8], [2, 1, 0.8], [2, 2, 0.8],
          [1, 2, 0.8]]
    box = [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]]
    polys += [[b + i for i in p] for p in box]
    mats += [2] * 6
    objs += [3] * 6
    b = len(v)
    v += [[1.5, 1.0, H - 0.01], [2.5, 1.0, H - 0.01], [2.5, 2.0, H - 0.01], [1.5, 2.0, H - 0.01]]
    polys.append([b, b + 3, b + 2, b + 1])
    mats.append(3)
    objs.append(4)
    names = ["Floor", "Ceiling", "Walls", "Box", "Lamp"]
    for quad, name in extra:
        b = len(v)
        v += [list(map(float, p)) for p in quad]
        polys.append([b, b + 1, b + 2, b + 3])
        mats.append(0)
        if name not in names:
            names.append(name)
        objs.append(names.index(name))
    refl = np.array([[0.7, 0.7, 0.7], [0.8, 0.8, 0.8], [0.4, 0.5, 0.6], [0.0, 0.0, 0.0]])
    em = np.zeros((4, 3))
    em[3] = 20.0
    return scene_from_polygons(np.array(v, dtype=float), polys, mats, refl, em,
                               face_objects=objs, object_names=names)


FLOOR = np.array([[0, 0, 0], [4, 0, 0], [4, 3, 0], [0, 3, 0]], dtype=float)
SETTINGS = BakeSettings(patch_size=0.5, seed=7)


@pytest.fixture(scope="module")
def plain():
    scene = _room()
    return scene, bake(scene, SETTINGS)


@pytest.mark.parametrize("variant", ["same", "flipped", "rotated_start", "jittered"])
def test_duplicate_floor_changes_nothing(plain, variant):
    """A floor left twice (as it is, flipped, starting at another corner, or moved by less than
    DUPLICATE_RTOL of its size) gives the room's colours unchanged, and its own corners the
    floor's colours; the warning names the objects."""
    scene0, res0 = plain
    quad = FLOOR.copy()
    if variant == "flipped":
        quad = quad[::-1]
    elif variant == "rotated_start":
        quad = np.roll(quad, 1, axis=0)
    elif variant == "jittered":
        quad = quad + 0.2 * DUPLICATE_RTOL * np.sqrt(12.0) * np.array([0.3, -0.5, 0.1])
    scene = _room([(quad, "Floor.001")])
    assert find_duplicates(scene)[-1] == 0
    res = bake(scene, SETTINGS)
    C0 = scene0.n_corners
    np.testing.assert_allclose(res.corner_colours[:C0], res0.corner_colours, rtol=SAME_RTOL,
                               atol=1e-12)
    np.testing.assert_allclose(res.patch_radiance, res0.patch_radiance, rtol=SAME_RTOL)
    # The duplicate's corners read the floor's colour at the same place.
    dup = res.corner_colours[C0:]
    floor_pos = scene.vertices[scene.corner_verts[:4]]
    dup_pos = scene.vertices[scene.corner_verts[C0:]]
    nearest = np.argmin(np.linalg.norm(dup_pos[:, None] - floor_pos[None], axis=2), axis=1)
    np.testing.assert_array_equal(dup, res.corner_colours[nearest])
    warn = [w for w in res.report["warnings"] if "duplicate" in w]
    assert len(warn) == 1 and '"Floor"' in warn[0] and '"Floor.001"' in warn[0]
    assert res.report["faces_dropped"] == 0


def test_near_copy_is_not_a_duplicate():
    """A floor copy 1 % of its size above the floor is a separate surface: not merged."""
    scene = _room([(FLOOR + [0, 0, 0.01 * np.sqrt(12.0)], "Floor.001")])
    assert np.all(find_duplicates(scene) < 0)


def test_near_copy_facing_the_same_way_is_named_in_a_warning():
    """A floor copy 0.1 % of its size above the floor (3.5 mm: a surface left twice by an
    import, offset) is solved as a thin gap, and the report names both objects and the gap."""
    lift = 1e-3 * np.sqrt(12.0)
    scene = _room([(FLOOR + [0, 0, lift], "Floor.001")])
    res = bake(scene, SETTINGS)
    warn = [w for w in res.report["warnings"] if "copy of themselves" in w]
    assert len(warn) == 1 and '"Floor"' in warn[0] and '"Floor.001"' in warn[0]
    assert warn[0].startswith(f"1 faces lie {lift:.3g} m or so")
    assert not any("duplicates" in w for w in res.report["warnings"])


def test_back_to_back_faces_are_not_named():
    """A pane's two sides (the same quad 0.5 % of its size apart, back to back: the lower one
    facing down, the upper one up) are a thin solid, not a leftover copy; a flipped copy over
    the floor (facing it) is named; copies farther apart than NEAR_DUPLICATE_RTOL are
    separate surfaces."""
    pane = FLOOR + [0, 0, 1.0]
    lift = [0, 0, 0.5 * NEAR_DUPLICATE_RTOL * np.sqrt(12.0)]
    thin = _room([(pane[::-1], "Pane"), (pane + lift, "Pane")])
    assert near_duplicate_warning(thin) is None
    facing = _room([((FLOOR + lift)[::-1], "Floor.001")])
    assert '"Floor.001"' in near_duplicate_warning(facing)
    far = _room([(FLOOR + [0, 0, 2 * NEAR_DUPLICATE_RTOL * np.sqrt(12.0)], "Floor.001")])
    assert near_duplicate_warning(far) is None
    near = _room([(FLOOR + [0, 0, 0.5 * NEAR_DUPLICATE_RTOL * np.sqrt(12.0)], "Floor.001")])
    assert '"Floor.001"' in near_duplicate_warning(near)


def test_duplicate_groups_keep_the_lowest_face():
    """Three copies of the floor: both extras point at the floor (face 0)."""
    scene = _room([(FLOOR, "A"), (FLOOR[::-1], "B")])
    dup = find_duplicates(scene)
    assert dup[-1] == 0 and dup[-2] == 0 and np.count_nonzero(dup >= 0) == 2


@pytest.mark.parametrize("variant", ["same", "flipped"])
def test_duplicate_floor_object_keeps_its_faces_in_the_radiosity_mesh(variant):
    """In the radiosity mesh a duplicate (which makes no patches) gets a copy of the kept face's
    output faces: the object it belongs to keeps a surface, at the same places, with the same
    colours, wound its own way."""
    quad = FLOOR.copy()[::-1] if variant == "flipped" else FLOOR.copy()
    scene = _room([(quad, "Floor.001")])
    res = bake(scene, BakeSettings(seed=7, element_levels=0))
    m = res.output
    dup = scene.n_faces - 1
    mine, floor = m.faces_of(np.array([dup])), m.faces_of(np.array([0]))
    assert mine.size == floor.size > 1
    face_of = m.face_of_corner()
    a, b = np.isin(face_of, mine), np.isin(face_of, floor)
    key = lambda pts, col: np.lexsort(np.c_[col, pts].T)
    pa, pb = m.vertices[m.corner_verts[a]], m.vertices[m.corner_verts[b]]
    ca, cb = m.corner_colours[a], m.corner_colours[b]
    np.testing.assert_array_equal(pa[key(pa, ca)], pb[key(pb, cb)])
    np.testing.assert_array_equal(ca[key(pa, ca)], cb[key(pb, cb)])
    # wound the duplicate's way: the copies' normals follow the duplicate's normal
    f = mine[0]
    tri = m.vertices[m.corner_verts[m.face_starts[f]:m.face_starts[f] + 3]]
    n = np.cross(tri[1] - tri[0], tri[2] - tri[0])
    assert n @ scene.face_normals[dup] > 0
    # every corner of a copy interpolates the duplicate's own corners
    src = m.corner_sources[a]
    assert np.all((src >= scene.face_starts[dup]) & (src < scene.face_starts[dup] + 4))
    assert res.report["mesh"]["per_object"]["Floor.001"]["output_faces"] == mine.size
