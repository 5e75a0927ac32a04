"""Fronts lying face to face on another face (core.covered): the floor under a box standing on
it, the box's bottom. Oracle: the geometry (which patches lie inside the footprint) and the
energy balance of a closed room (nothing escapes, nothing is counted twice)."""

import numpy as np
import pytest

from bench.scenes import _Builder, _cube_faces
from core import BakeSettings, bake
from core.covered import Covers, covered_fronts
from core.contacts import split_at_contacts
from core.patches import make_patches

FLOOR, BOX, LIT = 0, 1, 2

#: The box's footprint on the 2 x 2 m floor.
LO, HI = np.array([0.6, 0.7, 0.0]), np.array([1.3, 1.2, 0.5])


def _room(lift=0.0, lit_top=False, extra=None):
    """A closed 2 x 2 x 2 m room (one quad per side, normals in) with a closed box (normals
    out) standing on the floor, or ``lift`` metres over it; ``lit_top``: the box's top emits
    (both sides, as Blender's emission shader); ``extra(builder)`` adds faces."""
    b = _Builder()
    room = b.object("Room")
    for _, o, u, v in _cube_faces((0, 0, 0), (2, 2, 2), inward=True):
        b.grid(o, u, v, 1, 1, FLOOR, room)
    box = b.object("Box")
    for name, o, u, v in _cube_faces(LO + [0, 0, lift], HI + [0, 0, lift], inward=False):
        b.grid(o, u, v, 1, 1, LIT if (lit_top and name == "z+") else BOX, box)
    if extra is not None:
        extra(b)
    rho = [[0.5] * 3, [0.6, 0.4, 0.3], [0.5] * 3]
    le = [[0.0] * 3, [0.0] * 3, [1.0] * 3 if lit_top else [0.0] * 3]
    if not lit_top:
        le[FLOOR] = [0.0] * 3
        b.polygon([[0.8, 0.8, 1.9], [0.8, 1.2, 1.9], [1.2, 1.2, 1.9], [1.2, 0.8, 1.9]], LIT,
                  b.object("Lamp"))
        le[LIT] = [5.0] * 3
    return b.scene(rho, le)


def _patches(scene, size=0.25):
    return split_at_contacts(scene, make_patches(scene, size))[0]


def _under_box(patches):
    c = np.asarray(patches.corners).mean(axis=1)
    return np.all((c[:, :2] > LO[:2]) & (c[:, :2] < HI[:2]), axis=1) & (np.abs(c[:, 2]) < 1e-9)


def test_the_floor_under_a_standing_box_and_its_bottom_are_covered():
    scene = _room()
    patches = _patches(scene)
    covered = covered_fronts(scene, patches)
    want = _under_box(patches)              # floor pieces under the box and the box's bottom
    assert want.sum() >= 2 and np.any(patches.normals[want, 2] < 0)
    np.testing.assert_array_equal(covered, want)
    # The cut pieces tile the footprint twice: once the floor, once the bottom.
    area = float((HI[0] - LO[0]) * (HI[1] - LO[1]))
    assert patches.areas[covered].sum() == pytest.approx(2 * area, rel=1e-9)


def test_faces_apart_facing_copies_and_same_facing_faces_are_not_covered():
    assert not covered_fronts(_room(lift=0.05), _patches(_room(lift=0.05))).any()

    def flipped_copy(b):                   # a leftover copy of the floor, facing down onto it
        b.polygon([[0, 0, 0], [0, 2, 0], [2, 2, 0], [2, 0, 0]], FLOOR, b.object("Copy"))

    def rug(b):                            # lying on the floor, facing up like it
        b.polygon([[0.1, 0.1, 0], [0.5, 0.1, 0], [0.5, 0.5, 0], [0.1, 0.5, 0]], BOX,
                  b.object("Rug"))

    for extra in (flipped_copy, rug):
        scene = _room(lift=0.05, extra=extra)
        assert not covered_fronts(scene, _patches(scene)).any(), extra.__name__


def test_an_emitting_front_is_never_covered_and_a_cover_is_whole():
    # A panel lying face down on part of the box's top: the top's patches wholly under it are
    # covered, those it overlaps in part are not (nothing cuts the top along the panel's
    # outline), and the panel itself, facing the top, is not.
    z, x1, y1 = HI[2] + 0.05, 1.0, 1.1

    def lamp_face_down(b):
        b.polygon([[LO[0], LO[1], z], [LO[0], y1, z], [x1, y1, z], [x1, LO[1], z]], LIT,
                  b.object("Panel"))

    scene = _room(lift=0.05, extra=lamp_face_down)
    patches = _patches(scene, size=0.15)
    covered = covered_fronts(scene, patches)
    lamp = np.asarray(scene.emission)[patches.material].sum(axis=1) > 0
    c = np.asarray(patches.corners)
    top = (np.abs(c[:, :, 2] - z).max(axis=1) < 1e-9) & ~lamp
    whole = top & np.all((c[:, :, 0] <= x1 + 1e-9) & (c[:, :, 1] <= y1 + 1e-9), axis=1)
    part = top & ~whole & (c[:, :, 0].min(axis=1) < x1 - 1e-9) \
        & (c[:, :, 1].min(axis=1) < y1 - 1e-9)
    assert whole.any() and part.any()
    np.testing.assert_array_equal(covered, whole)
    assert not covered[lamp].any()


def test_a_box_top_lights_its_inside_once():
    # Blender's emission is two-sided: the top's back lights the box's inside. Shadow rays from
    # the floor under the box start above the bottom that lies on it, so it took that light
    # too (the room absorbed 113 % of the emitted power). Closed room: absorbed = emitted.
    scene = _room(lit_top=True)
    for mode in ("all", "off"):
        r = bake(scene, BakeSettings(patch_size=0.5, resolution=16, exact_direct=mode,
                                     output_mode="vertices"))
        e = r.report["energy"]
        assert abs(e["escaped"]) <= 1e-3 * e["emitted"], (mode, e)
        assert abs(e["balance"]) <= 1e-3 * e["emitted"], (mode, e)
        under = _under_box(r.patches)
        assert under.any()
        np.testing.assert_array_equal(covered_fronts(scene, r.patches), under)
        assert np.all(r.node_radiance[:under.size][under] == 0.0), mode
        inside = np.flatnonzero(r.patches.material == BOX) + under.size     # the box's backs
        assert r.node_radiance[inside].max() > 0, mode


def _face_at_floor(scene, up):
    """The face lying in the floor's plane whose normal points up (the floor) or down (the
    box's bottom)."""
    centre = np.array([scene.vertices[scene.corner_verts[a:a + n]].mean(axis=0)
                       for a, n in zip(scene.face_starts, scene.face_sizes)])
    pick = (np.abs(centre[:, 2]) < 1e-12) & (np.sign(scene.face_normals[:, 2]) == up)
    (face,) = np.flatnonzero(pick)
    return face


def test_points_under_a_box_are_covered_and_the_face_they_belong_to_decides():
    scene = _room()
    covers = Covers(scene)
    floor, bottom = _face_at_floor(scene, 1), _face_at_floor(scene, -1)
    x = np.array([[0.9, 0.9, 0.0],        # under the box
                  [1.3, 0.9, 0.0],        # on the footprint's outline: lit from outside
                  [1.3 - 1e-3, 0.9, 0.0],  # 1 mm inside it
                  [0.3, 0.3, 0.0]])       # beside the box
    up, down = np.tile([0.0, 0.0, 1.0], (4, 1)), np.tile([0.0, 0.0, -1.0], (4, 1))
    want = np.array([True, False, True, False])
    # The floor's front under the box: covered; the bottom's front (its points, on the
    # outline too) lies on the floor, which reaches beyond it: covered.
    np.testing.assert_array_equal(covers.points(x, up, np.full(4, floor)), want)
    assert covers.points(x[:3], down[:3], np.full(3, bottom)).all()
    # The same points facing up as the bottom's inner side: inside the box, not covered; and
    # the floor's back (facing down, away from the box): not covered.
    assert not covers.points(x, up, np.full(4, bottom)).any()
    assert not covers.points(x, down, np.full(4, floor)).any()
    # Lifted 1 cm off the floor: no longer in the cover's plane.
    assert not covers.points(x + [0.0, 0.0, 0.01], up, np.full(4, floor)).any()

    def flipped_copy(b):                   # a leftover copy of the floor, facing down onto it
        b.polygon([[0, 0, 0], [0, 2, 0], [2, 2, 0], [2, 0, 0]], FLOOR, b.object("Copy"))

    # A face and its flipped copy do not cover each other (both keep their light, as
    # covered_fronts); the box still covers the floor under it.
    scene = _room(extra=flipped_copy)
    covers = Covers(scene)
    low = scene.vertices[scene.corner_verts[scene.face_starts], 2] == 0.0
    (copy,) = np.flatnonzero(low & (scene.face_normals[:, 2] < 0)
                             & np.isclose(scene.face_areas, 4.0))
    np.testing.assert_array_equal(covers.points(x, up, np.full(4, floor)), want)
    assert not covers.points(x[[3]], down[[3]], [copy]).any()


@pytest.mark.parametrize("patch_size", [0.5, 0.3])
def test_a_box_top_lights_its_inside_once_without_contact_cuts(patch_size):
    # Without the cuts the floor's patches straddle the box's outline: part of each lies under
    # the box, where shadow rays start inside it and the top's back lit them (8.9 % and 11 % of
    # the emitted power counted twice at these patch sizes). Points under the box are covered
    # one by one (core.covered.Covers). Closed room: absorbed = emitted.
    scene = _room(lit_top=True)
    r = bake(scene, BakeSettings(patch_size=patch_size, resolution=16, exact_direct="all",
                                 contact_cuts=False, output_mode="vertices"))
    e = r.report["energy"]
    assert abs(e["escaped"]) <= 1e-3 * e["emitted"], e
    assert abs(e["balance"]) <= 1e-3 * e["emitted"], e
