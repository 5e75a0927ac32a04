"""Gap lines (core/gaplines.py): a surface cut where another's edge runs a small gap in front of it.

Oracles: the line's own geometry (the edge projected onto the surface), and the same scene in two
equivalent forms. A cabinet stands against a wall; its top board stops 2 cm short of the wall,
so the cabinet's inside is lit only through that slot. Modelled as an architect does (the wall
one quad) the bake must agree with the copy whose wall the user cut along the board's edges
themselves: there no patch can straddle the slot, whatever the engine does.
"""

import numpy as np
import pytest

from bench.scenes import _Builder
from core import BakeSettings, bake
from core.contacts import find_contacts, split_at_contacts
from core.gaplines import gap_lines
from core.patches import make_patches

FLOOR, CABINET, WALL, LAMP = 0, 1, 2, 3
SIZE = 2.0
#: The cabinet: x from X0 to X1, its front at Y0, the wall at y = SIZE; the top board's
#: underside at TOP, its upper face at TOP + T; panels T thick.
X0, X1, Y0, TOP, T = 0.5, 1.5, 1.3, 0.6, 0.02


def _box(b, lo, hi, mat, obj, skip=()):
    """Outward quads of the box lo..hi, except the sides named in ``skip`` ('x-', 'y+', ...)."""
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    quads = {"x-": [[x0, y0, z0], [x0, y0, z1], [x0, y1, z1], [x0, y1, z0]],
             "x+": [[x1, y0, z0], [x1, y1, z0], [x1, y1, z1], [x1, y0, z1]],
             "y-": [[x0, y0, z0], [x1, y0, z0], [x1, y0, z1], [x0, y0, z1]],
             "y+": [[x0, y1, z0], [x0, y1, z1], [x1, y1, z1], [x1, y1, z0]],
             "z-": [[x0, y0, z0], [x0, y1, z0], [x1, y1, z0], [x1, y0, z0]],
             "z+": [[x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]]}
    for side, quad in quads.items():
        if side not in skip:
            b.polygon(quad, mat, obj)


def _cabinet_room(gap=0.02, cut_wall=False, scale=1.0, flip_wall=False):
    """A closed 2 m room, every surface one quad (the back wall y = SIZE cut by hand along the
    top board's two edges when ``cut_wall``; facing out of the room when ``flip_wall``), a
    ceiling lamp, and a cabinet against the back wall whose top board ends ``gap`` short of it.
    ``scale``: every length times it."""
    b = _Builder()
    s, h = SIZE, SIZE
    room = b.object("Room")
    b.polygon([[0, 0, 0], [s, 0, 0], [s, s, 0], [0, s, 0]], FLOOR, room)
    b.polygon([[0, 0, h], [0, s, h], [s, s, h], [s, 0, h]], WALL, room)
    b.polygon([[0, 0, 0], [0, 0, h], [s, 0, h], [s, 0, 0]], WALL, room)
    b.polygon([[0, 0, 0], [0, s, 0], [0, s, h], [0, 0, h]], WALL, room)
    b.polygon([[s, 0, 0], [s, 0, h], [s, s, h], [s, s, 0]], WALL, room)
    cuts = [0.0, TOP, TOP + T, h] if cut_wall else [0.0, h]
    for z0, z1 in zip(cuts[:-1], cuts[1:]):
        quad = [[0, s, z0], [s, s, z0], [s, s, z1], [0, s, z1]]
        b.polygon(quad[::-1] if flip_wall else quad, WALL, room)
    cab = b.object("Cabinet")
    _box(b, (X0, Y0 - T, 0), (X0 + T, s, TOP + T), CABINET, cab, ("y+", "z-"))
    _box(b, (X1 - T, Y0 - T, 0), (X1, s, TOP + T), CABINET, cab, ("y+", "z-"))
    _box(b, (X0 + T, Y0 - T, 0), (X1 - T, Y0, TOP), CABINET, cab, ("x-", "x+", "z-", "z+"))
    _box(b, (X0 + T, Y0 - T, TOP), (X1 - T, s - gap, TOP + T), CABINET, cab, ("x-", "x+"))
    c = s / 2
    b.polygon([[c - 0.3, c - 0.3, h - 0.01], [c - 0.3, c + 0.3, h - 0.01],
               [c + 0.3, c + 0.3, h - 0.01], [c + 0.3, c - 0.3, h - 0.01]], LAMP,
              b.object("Lamp"))
    for k, pts in enumerate(b.vertices):
        b.vertices[k] = pts * scale
    rho = [[0.5, 0.5, 0.5], [0.6, 0.6, 0.6], [0.7, 0.7, 0.7], [0.0, 0.0, 0.0]]
    le = [[0, 0, 0], [0, 0, 0], [0, 0, 0], [10.0, 10.0, 10.0]]
    return b.scene(rho, le, material_names=["floor", "cabinet", "wall", "lamp"])


def _lines(scene, patch_size=0.5, gap=0.05):
    patches = make_patches(scene, patch_size)
    found = find_contacts(scene, patches)
    patches, _, _ = split_at_contacts(scene, patches, found)
    lines, count = gap_lines(scene, patches, gap, tol=found.tol)
    return patches, lines, count


def _wall_patches(patches):
    return np.flatnonzero(np.all(np.abs(patches.corners[:, :, 1] - SIZE) < 1e-9, axis=1))


def test_the_board_edges_cut_the_wall_along_their_projection():
    scene = _cabinet_room()
    patches, lines, count = _lines(scene)
    # The top board's upper and lower faces end 2 cm off the wall: two lines on it, at the
    # heights of those faces, from the inner face of one side panel to the other's.
    on_wall = np.abs(lines.a[:, 1] - SIZE) < 1e-12
    assert count == 2 and on_wall.all()
    z = np.unique(np.round(lines.a[:, 2], 12))
    assert np.allclose(z, [TOP, TOP + T])
    assert np.allclose(lines.length, X1 - X0 - 2 * T)
    assert np.allclose(np.abs(lines.u[:, 0]), 1.0)
    cut, _, info = split_at_contacts(scene, patches, lines)
    assert info["cuts"] == lines.patch.size > 0 and info["added"] > 0
    # Every wall piece now lies wholly on one side of each line, and the wall keeps its area.
    wall = _wall_patches(cut)
    zc = cut.corners[wall][:, :, 2]
    xc = cut.corners[wall][:, :, 0]
    inside_x = (xc.min(axis=1) >= X0 + T - 1e-9) & (xc.max(axis=1) <= X1 - T + 1e-9)
    for line_z in (TOP, TOP + T):
        straddle = (zc.min(axis=1) < line_z - 1e-9) & (zc.max(axis=1) > line_z + 1e-9)
        assert not np.any(straddle & inside_x)
    assert np.isclose(cut.areas[wall].sum(), SIZE * SIZE)
    before = _wall_patches(patches)
    assert np.isclose(patches.areas[before].sum(), SIZE * SIZE)


@pytest.mark.parametrize("gap, expected", [(0.0, 0), (0.02, 2), (0.049, 2), (0.06, 0)])
def test_only_an_edge_within_the_gap_makes_a_line(gap, expected):
    # 0: the board touches the wall (a contact, core.contacts's line, not this one); 6 cm: the
    # slot is wider than the 5 cm gap (core.gaplines.GAP_SHARE is 0).
    _, _, count = _lines(_cabinet_room(gap=gap))
    assert count == expected


def test_faces_behind_a_surface_or_parallel_to_it_make_no_line():
    # The panels' outer faces (x = X0, x = X1) have the top board 2 cm behind them, inside the
    # panel: hidden there, it casts nothing on them. The board's back face (y = SIZE - gap) is
    # parallel to the wall: it shades an area, not a line. The floor meets nothing within 5 cm.
    scene = _cabinet_room()
    patches, lines, _ = _lines(scene)
    planes = patches.corners[lines.patch, 0]
    assert np.allclose(planes[:, 1], SIZE)
    assert not np.any(np.isclose(planes[:, 0], X0) & np.isclose(patches.normals[lines.patch, 0],
                                                                -1.0))


def test_scale_invariant():
    # The same room in millimetres with the gap in millimetres: the same lines, scaled.
    patches, lines, count = _lines(_cabinet_room())
    patches_mm, lines_mm, count_mm = _lines(_cabinet_room(scale=1000.0), patch_size=500.0,
                                            gap=50.0)
    assert count_mm == count
    assert np.array_equal(lines_mm.patch, lines.patch)
    assert np.allclose(lines_mm.a, 1000.0 * lines.a, rtol=0, atol=1e-6)
    assert np.allclose(lines_mm.length, 1000.0 * lines.length)


def _inside_floor(result):
    """Area-weighted mean radiance of the floor inside the cabinet (its patches are the same in
    every form of the room) and its area."""
    p = result.patches
    c = p.corners
    x_in = (c[:, :, 0].min(axis=1) >= X0 + T - 1e-9) & (c[:, :, 0].max(axis=1) <= X1 - T + 1e-9)
    y_in = (c[:, :, 1].min(axis=1) >= Y0 - 1e-9)
    sel = x_in & y_in & np.all(np.abs(c[:, :, 2]) < 1e-9, axis=1)
    lum = result.patch_radiance[sel].mean(axis=1)
    return float(np.sum(lum * p.areas[sel]) / np.sum(p.areas[sel])), float(p.areas[sel].sum())


@pytest.mark.parametrize("gap", [0.02, 0.04])
def test_the_slot_takes_the_light_of_the_hand_cut_wall(gap):
    fast = dict(output_mode="vertices", patch_size=0.5, resolution=64, element_levels=0)
    one = bake(_cabinet_room(gap=gap), BakeSettings(**fast))
    hand = bake(_cabinet_room(gap=gap, cut_wall=True), BakeSettings(**fast))
    leak = bake(_cabinet_room(gap=gap), BakeSettings(gap_cuts=False, **fast))
    (m_one, a_one), (m_hand, a_hand), (m_leak, _) = (_inside_floor(r) for r in (one, hand, leak))
    assert np.isclose(a_one, (X1 - X0 - 2 * T) * (SIZE - Y0)) and np.isclose(a_hand, a_one)
    assert one.report["contacts"]["gap_lines"] == 2
    assert hand.report["contacts"]["gap_cuts"] == 0   # its patch edges already lie there
    print("inside floor: one quad %.5f, hand-cut %.5f, without gap cuts %.5f"
          % (m_one, m_hand, m_leak))
    assert m_hand > 0
    # Tolerance: the two forms' wall patches differ (0.5 m rows cut at 0.6 and 0.62 m against
    # 0.3 m rows), and the wall just under the slot, which lights the floor, falls steeply:
    # each form is off the converged floor by its own discretisation (at 2 cm 1.10 and 1.17
    # times the hand-cut room's at 1/8 m patches, at 4 cm 1.25 and 1.09: core.gaplines).
    assert abs(m_one - m_hand) < 0.25 * m_hand
    # Without the cuts the wall patch across the slot carries the lit wall's light inside: 4.1
    # and 2.1 times the hand-cut room's.
    assert m_leak > 1.5 * m_hand and m_leak > 1.5 * m_one


def test_a_flipped_wall_is_cut_on_its_room_side():
    # A wall facing out of the room (a CAD import) has the cabinet behind its back: the first
    # solve finds it lit from behind (core.orient), and the patches made again for the second
    # take their gap lines from that side. The inside then reads as with the wall turned right.
    fast = dict(output_mode="mesh", patch_size=0.5, resolution=32, element_levels=0,
                emitter_levels=1)
    right = bake(_cabinet_room(), BakeSettings(**fast))
    flipped = bake(_cabinet_room(flip_wall=True), BakeSettings(**fast))
    leak = bake(_cabinet_room(flip_wall=True), BakeSettings(gap_cuts=False, **fast))
    assert "solved_twice" in flipped.report
    assert flipped.report["contacts"]["gap_cuts"] == right.report["contacts"]["gap_cuts"] > 0
    m_right, m_flipped, m_leak = (_inside_floor(r)[0] for r in (right, flipped, leak))
    print("inside floor: right %.5f, flipped %.5f, flipped without gap cuts %.5f"
          % (m_right, m_flipped, m_leak))
    # The same wall, the same cuts: only the hemicubes' random rotations differ.
    assert abs(m_flipped - m_right) < 0.05 * m_right
    assert m_leak > 1.5 * m_right


def test_a_lamp_is_not_cut():
    # A box whose top stops 10 cm under the ceiling lamp: its sides' top edges run within the
    # gap of the lamp's plane, and would cut it. A lamp's light is its emission (a cut changes
    # nothing) and the exact direct light integrates it over its pieces: a cut one let 16 % of
    # its power escape a closed room (tests/core/test_fuzz.py). The ceiling is cut instead.
    b = _Builder()
    room = b.object("Room")
    b.polygon([[0, 0, 0], [2, 0, 0], [2, 2, 0], [0, 2, 0]], FLOOR, room)
    b.polygon([[0, 0, 2], [0, 2, 2], [2, 2, 2], [2, 0, 2]], WALL, room)
    _box(b, (0.7, 1.0, 0.0), (1.3, 1.6, 1.89), CABINET, b.object("Box"), ("z-",))
    b.polygon([[0.75, 0.75, 1.99], [0.75, 1.25, 1.99], [1.25, 1.25, 1.99], [1.25, 0.75, 1.99]],
              LAMP, b.object("Lamp"))
    rho = [[0.5] * 3, [0.6] * 3, [0.7] * 3, [0.0] * 3]
    scene = b.scene(rho, [[0] * 3, [0] * 3, [0] * 3, [10.0] * 3])
    patches, lines, count = _lines(scene, patch_size=1.0, gap=0.15)
    lamp = scene.face_materials[patches.face[lines.patch]] == LAMP
    assert lines.patch.size > 0 and not lamp.any()
    # The same edges do cut the ceiling, 11 cm above the box's top.
    assert np.all(np.isclose(patches.corners[lines.patch, :, 2], 2.0))
