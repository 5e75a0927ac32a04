"""Shadow lines from objects' feet (core/footlines.py): patches cut where a shadow leaves a corner.

Oracles, independent of the engine:

* plane geometry: a vertical edge standing at footprint corner ``c`` is a silhouette seen from a
  lamp corner ``L`` when the whole footprint lies on one side of the line through ``L`` and ``c``
  (seen from above); its shadow line then runs from ``c`` away from ``L``, to the shadow of the
  edge's top;
* the light on the floor around a black box's corners under a lamp: ``rho Le F_vis(x)``,
  F_vis by midpoint quadrature over the lamp (48 x 48) with one shadow ray per node against the
  box's own triangles (core.raycast, not the engine's patches), as in test_adaptive.py.
"""

import numpy as np
import pytest

from core import BakeSettings, bake, scene_from_polygons
from core.adaptive import coarse_patch_size
from core.contacts import MIN_PIECE, find_contacts, split_at_contacts
from core.footlines import REACH, SAME_ANGLE, foot_lines, shadow_lines
from core.patches import make_patches
from core.raycast import any_hit, build_bvh

from builders import floor_field as interpolate

LE, RHO = 10.0, 0.5
CENTRE, HALF, HEIGHT, TURN = np.array([1.6, 2.0]), 0.3, 0.5, np.radians(30)
#: x0, x1, y0, y1, z of the lamp (facing down): off to one side, so no corner is under it.
LAMP = (2.4, 2.8, 2.2, 2.6, 2.0)

#: Floor points 2, 4 and 8 cm from the box's corners against the oracle, as a share of the
#: open floor's light, at default settings (the lamp is 3 hemicube pixels wide: the hemicube
#: lights it). Measured: mean 0.020, worst 0.28 with the cuts; 0.043 and 0.77 without them
#: (the mesh's edges cross the shadow lines obliquely and smear a penumbra a few mm wide).
#: What is left is the hemicube's aliasing at the points that carry the penumbra, and the
#: mesh's interpolation inside the wedge.
MEAN_TOL = 0.025
WORST_TOL = 0.35


def footprint(centre=CENTRE, half=HALF, turn=TURN):
    c, s = np.cos(turn), np.sin(turn)
    return centre + (np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * half) \
        @ np.array([[c, s], [-s, c]])


def box_on_floor(lamp=LAMP, centre=CENTRE, lights=None, wall_x=None):
    """A 4 x 4 m floor as one quad, a black box (no bottom) standing on it, turned 30 degrees
    to the floor's edges, and a square lamp as one quad (or, with ``lights``, those lights and
    a lamp too dim to count); ``wall_x``: a wall across the floor at that x, 3 m high."""
    xy = footprint(centre)
    lo, hi = np.c_[xy, np.zeros(4)], np.c_[xy, np.full(4, HEIGHT)]
    x0, x1, y0, y1, z = lamp
    v = np.concatenate([[[0, 0, 0], [4, 0, 0], [4, 4, 0], [0, 4, 0]],
                        [[x0, y0, z], [x0, y1, z], [x1, y1, z], [x1, y0, z]], lo, hi])
    polys = [[0, 1, 2, 3], [4, 5, 6, 7], [12, 13, 14, 15]]
    polys += [[8 + i, 8 + (i + 1) % 4, 12 + (i + 1) % 4, 12 + i] for i in range(4)]
    mats = [0, 1] + [2] * 5
    if wall_x is not None:
        v = np.concatenate([v, [[wall_x, 0, 0], [wall_x, 4, 0], [wall_x, 4, 3], [wall_x, 0, 3]]])
        polys.append([16, 17, 18, 19])
        mats.append(2)
    le = LE if lights is None else 1e-9
    return scene_from_polygons(v, polys, mats, [[RHO] * 3, [0.0] * 3, [0.0] * 3],
                               [[0.0] * 3, [le] * 3, [0.0] * 3], face_objects=mats,
                               object_names=["floor", "lamp", "box"], lights=lights)


def lines_of(scene):
    """The shadow lines as rows (corner, direction, length), the count foot_lines reports, its
    rows and the patches it cuts."""
    patches = make_patches(scene, coarse_patch_size(scene))
    found = find_contacts(scene, patches)
    patches, _, _ = split_at_contacts(scene, patches, found)
    a, u, length, _ = shadow_lines(scene, patches, found)
    lines, count = foot_lines(scene, patches, found)
    return np.concatenate([a, u, length[:, None]], axis=1), count, lines, patches


def expected_lines(lamp=LAMP, centre=CENTRE):
    """Per footprint corner, the extreme shadow directions over the lamp's corners that see its
    edge as a silhouette, by plane geometry seen from above."""
    fp = footprint(centre)
    x0, x1, y0, y1, z = lamp
    lamp_xy = np.array([[x0, y0], [x0, y1], [x1, y1], [x1, y0]])
    out = []
    for k, c in enumerate(fp):
        dirs, reach = [], []
        for q in lamp_xy:
            d = q - c
            others = np.delete(fp, k, axis=0) - c
            side = d[0] * others[:, 1] - d[1] * others[:, 0]
            if np.all(side >= -1e-12) or np.all(side <= 1e-12):
                u = (c - q) / np.linalg.norm(c - q)
                dirs.append(u)
                # the top (height HEIGHT) seen from the lamp's corner at height z
                reach.append(np.linalg.norm(c - q) * HEIGHT / (z - HEIGHT))
        if not dirs:
            continue
        ang = np.arctan2([d[1] for d in dirs], [d[0] for d in dirs])
        out_dir = -(fp.mean(axis=0) - c)                      # away from the box
        rel = np.angle(np.exp(1j * (ang - np.arctan2(out_dir[1], out_dir[0]))))
        for i in {int(np.argmin(rel)), int(np.argmax(rel))}:
            out.append((c, dirs[i], min(reach[i], REACH * HEIGHT), rel[i]))
    return out


def test_lines_leave_the_corners_that_cast_a_shadow_away_from_the_lamp():
    got, count, _, _ = lines_of(box_on_floor())
    want = expected_lines()
    # Lines from one corner within SAME_ANGLE of each other are one.
    merged = []
    for c, u, reach, ang in sorted(want, key=lambda w: (tuple(w[0]), w[3])):
        if merged and np.allclose(merged[-1][0], c) and ang - merged[-1][3] <= SAME_ANGLE:
            continue
        merged.append((c, u, reach, ang))
    assert count == len(merged) == got.shape[0]
    for c, u, reach, _ in merged:
        match = np.all(np.abs(got[:, :2] - c) < 1e-9, axis=1) \
            & np.all(np.abs(got[:, 3:5] - u) < 1e-9, axis=1)
        assert match.sum() == 1, (c, u, got)
        assert got[match, 6][0] == pytest.approx(reach, abs=1e-8)


@pytest.mark.parametrize("kind", ["point", "sun"])
def test_a_point_light_or_the_sun_casts_one_line_per_silhouette_corner(kind):
    # A light with no size: from each corner whose edge it sees as a silhouette (the footprint
    # on one side of the line through the light and the corner, seen from above), one line
    # away from the light, to the shadow of the edge's top.
    light = np.array([3.2, 1.1, 2.5])
    if kind == "point":
        lights = [dict(kind="point", position=light.tolist(), power=100.0)]
    else:
        to_sun = light - [CENTRE[0], CENTRE[1], 0.0]
        lights = [dict(kind="sun", direction=(-to_sun / np.linalg.norm(to_sun)).tolist(),
                       strength=3.0)]
    got, count, _, _ = lines_of(box_on_floor(lights=lights))
    fp = footprint()
    want = []
    for k, c in enumerate(fp):
        q = light[:2] if kind == "point" else c + (light[:2] - CENTRE)
        others = np.delete(fp, k, axis=0) - c
        d = q - c
        side = d[0] * others[:, 1] - d[1] * others[:, 0]
        if np.all(side >= 0) or np.all(side <= 0):
            rise = light[2] if kind == "point" else light[2]
            want.append((c, (c - q) / np.linalg.norm(c - q),
                         np.linalg.norm(c - q) * HEIGHT / (rise - HEIGHT) if kind == "point"
                         else np.linalg.norm(c - q) * HEIGHT / rise))
    assert count == len(want) == got.shape[0] == 2
    for c, u, reach in want:
        match = np.all(np.abs(got[:, :2] - c) < 1e-9, axis=1) \
            & np.all(np.abs(got[:, 3:5] - u) < 1e-9, axis=1)
        assert match.sum() == 1, (c, u, got)
        assert got[match, 6][0] == pytest.approx(min(reach, REACH * HEIGHT), abs=1e-8)


def test_a_corner_under_a_wide_lamp_casts_no_line():
    # The lamp covers the whole box: each corner's edge is a silhouette for parts of the lamp on
    # both sides of it, whose lines fan out all round; none bounds a penumbra.
    lamp = (1.0, 2.2, 1.4, 2.6, 2.0)
    got, count, _, _ = lines_of(box_on_floor(lamp=lamp))
    assert count == 0 and got.shape[0] == 0


def test_a_lamp_behind_a_wall_casts_no_line():
    # The same box and lamp with a wall between them (the lamp in the next room): the corners'
    # geometry allows the lines, but no corner sees the lamp.
    got, count, _, _ = lines_of(box_on_floor())
    assert count > 0
    got, count, _, _ = lines_of(box_on_floor(wall_x=2.2))
    assert count == 0 and got.shape[0] == 0


def test_lines_cut_the_patches_they_cross():
    scene = box_on_floor()
    _, count, lines, patches = lines_of(scene)
    cut, parent, info = split_at_contacts(scene, patches, lines)
    assert count > 0 and info["cuts"] > 0
    assert cut.n_patches == patches.n_patches + info["added"]
    assert np.isclose(cut.areas.sum(), patches.areas.sum(), rtol=1e-12)
    # No piece is crossed by a segment: where the line runs through a piece, the chord lies
    # beyond the segment's ends, or the piece's corners stray across it by less than
    # MIN_PIECE of the size of the patch it was cut from (a line grazing a corner is not cut).
    floor = np.flatnonzero(np.all(np.abs(cut.corners[:, :, 2]) < 1e-12, axis=1))
    k = np.where(cut.is_triangle[floor], 3, 4)
    margin = MIN_PIECE * np.sqrt(patches.areas[parent[floor]])
    for a, u, w, length in zip(lines.a, lines.u, lines.w, lines.length):
        h = np.einsum("pkj,j->pk", cut.corners[floor] - a, w)
        t = np.einsum("pkj,j->pk", cut.corners[floor] - a, u)
        # the chord: t where the edges cross h = 0
        nxt = (np.arange(4)[None] + 1) % k[:, None]
        h1, t1 = np.take_along_axis(h, nxt, axis=1), np.take_along_axis(t, nxt, axis=1)
        cross = (np.arange(4)[None] < k[:, None]) & (h * h1 < 0)
        tc = np.where(cross, t + (t1 - t) * h / np.where(cross, h - h1, 1.0), np.nan)
        lo, hi = np.nanmin(np.where(cross, tc, np.inf), axis=1), np.nanmax(
            np.where(cross, tc, -np.inf), axis=1)
        on_segment = cross.any(axis=1) & (hi > 1e-9) & (lo < length - 1e-9)
        straddle = (h.min(axis=1) < -margin) & (h.max(axis=1) > margin)
        assert not np.any(on_segment & straddle), floor[on_segment & straddle]


def oracle(points, lamp=LAMP, n=48):
    """rho Le F(x -> lamp) with visibility: midpoint quadrature, one ray per node."""
    x0, x1, y0, y1, z = lamp
    s = (np.arange(n) + 0.5) / n
    q = np.array([[x0 + (x1 - x0) * a, y0 + (y1 - y0) * b, z] for a in s for b in s])
    dA = (x1 - x0) * (y1 - y0) / n ** 2
    xy = footprint()
    lo, hi = np.c_[xy, np.zeros(4)], np.c_[xy, np.full(4, HEIGHT)]
    tris = [hi[[0, 1, 2]], hi[[0, 2, 3]]]
    for i in range(4):
        quad = np.array([lo[i], lo[(i + 1) % 4], hi[(i + 1) % 4], hi[i]])
        tris += [quad[[0, 1, 2]], quad[[0, 2, 3]]]
    bvh = build_bvh(np.array(tris))
    out = np.zeros(len(points))
    for i, x in enumerate(points):                   # per test point: a few hundred
        d = q - x
        r2 = np.sum(d * d, axis=1)
        cos = d[:, 2] / np.sqrt(r2)
        blocked = any_hit(bvh, np.repeat(x[None] + [0, 0, 1e-9], len(q), 0), d, t_max=1.0)
        out[i] = np.sum(~blocked * cos * cos / (np.pi * r2)) * dA
    return RHO * LE * out


def rings(radii=(0.02, 0.04, 0.08), k=72):
    """Floor points on circles round the footprint's corners, outside the box."""
    a = 2 * np.pi * np.arange(k) / k
    pts = np.concatenate([np.c_[c[0] + r * np.cos(a), c[1] + r * np.sin(a), np.zeros(k)]
                          for c in footprint() for r in radii])
    c, s = np.cos(-TURN), np.sin(-TURN)
    rel = (pts[:, :2] - CENTRE) @ np.array([[c, s], [-s, c]])
    return pts[np.abs(rel).max(axis=1) > HALF + 1e-3]


@pytest.fixture(scope="module")
def corner_errors():
    scene = box_on_floor()
    points = rings()
    exact = oracle(points)
    open_floor = oracle(np.array([[3.0, 1.0, 0.0]]))[0]
    out = {}
    for cuts in (True, False):
        field = interpolate(bake(scene, BakeSettings(shadow_cuts=cuts)).output, points)[:, 0]
        out[cuts] = np.abs(field - exact) / open_floor
    return out


def test_the_floor_round_a_box_corner_matches_the_oracle(corner_errors):
    err = corner_errors[True]
    assert err.mean() <= MEAN_TOL and err.max() <= WORST_TOL, (err.mean(), err.max())


def test_without_the_lines_the_corners_are_smeared(corner_errors):
    # What the cuts buy, on the same points: the test above would fail without them.
    err = corner_errors[False]
    assert err.mean() > MEAN_TOL and err.max() > WORST_TOL, (err.mean(), err.max())


def test_regression_furnace_needles_at_a_wall_foot():
    """Found by tests/core/test_fuzz.py::test_white_furnace_radiosity_mesh: in a furnace (every
    face a lamp) the box's lines met the wall's foot a fraction of a millimetre from another
    line's crossing, and the needle left between them read Le (1.0 for 2.0) at 3 corners: its
    gather points stood behind the wall. A shadow line now cuts no patch where it would cross
    an edge nearer its ends than core.contacts.MIN_PIECE of the patch's size (a contact line
    still does: there the radiance jumps). Oracle: B = Le / (1 - rho) everywhere."""
    x0, x1, x2 = -0.7132928207901014, 0.7132928207901014, 3.3179571792098987
    y0, y1, y2 = -0.7151279449462891, 0.7151279449462891, 3.118856430053711
    plan = np.array([[x0, y0], [x2, y0], [x2, y1], [x1, y1], [x1, y2], [x0, y2]])
    verts, polys, mats = [], [], []

    def add(points, mat):
        polys.append(list(range(len(verts), len(verts) + len(points))))
        verts.extend(np.asarray(points, dtype=np.float64).tolist())
        mats.append(mat)

    add(np.c_[plan, np.zeros(6)], 0)
    add(np.c_[plan[::-1], np.full(6, 2.0)], 0)
    for i in range(6):
        (a0, b0), (a1, b1) = plan[i], plan[(i + 1) % 6]
        add([[a0, b0, 0], [a0, b0, 2.0], [a1, b1, 2.0], [a1, b1, 0]], 0)
    bx, by0, by1 = 0.2521870952761807, -0.4375, 0.03343709527618072
    fp = np.array([[-bx, by0], [bx, by0], [bx, by1], [-bx, by1]])
    add(np.c_[fp[::-1], np.zeros(4)], 1)
    add(np.c_[fp, np.ones(4)], 2)
    for i in range(4):
        (a0, b0), (a1, b1) = fp[i], fp[(i + 1) % 4]
        add([[a0, b0, 0], [a1, b1, 0], [a1, b1, 1.0], [a0, b0, 1.0]], 1)
    v = np.array(verts) + [0.0, 0.0, 276.0]
    scene = scene_from_polygons(v, polys, mats, np.full((3, 3), 0.5), np.ones((3, 3)))
    result = bake(scene, BakeSettings(output_mode="mesh", patch_size=2.015625, resolution=16,
                                      element_levels=0, min_element=0.50390625,
                                      exact_direct="off", vertex_budget=300, shadow_cuts=True))
    assert result.report["contacts"]["shadow_lines"] > 0
    np.testing.assert_allclose(result.output.corner_colours, 2.0, rtol=1e-3)
