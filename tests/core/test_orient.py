"""Flipped normals (issue 11): every face is baked on the side that receives the light.

Both outputs: Existing Vertices (``output_mode='vertices'``) and the radiosity mesh (its leaves
gather along the reversed normal of a flipped face).

Oracle (invariance): the same room with some faces reversed (their polygons wound the other
way, as CAD imports leave them) gives the same colours as the room as modelled, within the
seed-noise of the rotated hemicubes (the reversed faces' rows are drawn in another order);
the noise is measured here as the spread between two seeds of the unflipped room. Existing
Vertices is tested without receiver elements (``element_levels=0``: their splits follow the
hemicube's noise); the radiosity mesh at its defaults, elements and cavity splits included
(both follow the side of a face that faces the room: core.elements, core.bake).
"""

import numpy as np
import pytest

from core.bake import bake
from core.scene import scene_from_polygons
from core.settings import BakeSettings
from test_duplicates import _room

#: Flipped vs as modelled: at most this many times the difference between two seeds.
NOISE_FACTOR = 2.0


def _flip(scene, faces):
    polys = [list(scene.corner_verts[s:s + k]) for s, k in zip(scene.face_starts, scene.face_sizes)]
    for f in faces:
        polys[f] = polys[f][::-1]
    return scene_from_polygons(scene.vertices, polys, scene.face_materials, scene.reflectance,
                               scene.emission, face_objects=scene.face_objects,
                               object_names=scene.object_names)


def _by_face_vertex(scene, colours):
    """Corner colours ordered by (face, vertex): independent of each face's winding."""
    corners, faces = scene.face_corner_indices()
    order = np.lexsort((scene.corner_verts[corners], faces))
    return colours[corners[order]]


def _by_face_centre(res):
    """Patch radiance ordered by (face, centre): independent of the patch grid's order."""
    c = np.round(res.patches.centres, 9)
    order = np.lexsort((c[:, 2], c[:, 1], c[:, 0], res.patches.face))
    return res.patch_radiance[order]


@pytest.fixture(scope="module")
def reference():
    scene = _room()
    out = {}
    for corners in ("gather", "average"):
        runs = [bake(scene, BakeSettings(patch_size=0.5, seed=s, corners=corners,
                                         element_levels=0, output_mode="vertices"))
                for s in (7, 8)]
        out[corners] = (scene, runs)
    return out


# Faces of _room: 0 floor, 1 ceiling, 2-5 walls, 6-11 the box, 12 the lamp.
@pytest.mark.parametrize("corners", ["gather", "average"])
@pytest.mark.parametrize("faces", [[0], [0, 3, 7], [1, 2, 4, 5, 8]])
def test_flipped_faces_bake_like_the_room_as_modelled(reference, corners, faces):
    scene0, (r0, r1) = reference[corners]
    scene = _flip(scene0, faces)
    rf = bake(scene, BakeSettings(patch_size=0.5, seed=7, corners=corners, element_levels=0,
                                   output_mode="vertices"))
    c0 = _by_face_vertex(scene0, r0.corner_colours)
    c1 = _by_face_vertex(scene0, r1.corner_colours)
    cf = _by_face_vertex(scene, rf.corner_colours)
    noise = np.abs(c1 - c0).max()
    assert np.abs(cf - c0).max() <= NOISE_FACTOR * noise
    p0, p1, pf = _by_face_centre(r0), _by_face_centre(r1), _by_face_centre(rf)
    assert np.abs(pf - p0).max() <= NOISE_FACTOR * np.abs(p1 - p0).max()
    for a in (rf.corner_colours, rf.patch_radiance):
        assert np.isfinite(a).all() and (a >= 0).all()
    warn = [w for w in rf.report["warnings"] if "back side (flipped normals?)" in w]
    assert len(warn) == 1 and warn[0].startswith(f"{len(faces)} faces ")
    for f in faces:
        assert f'"{scene.object_names[scene.face_objects[f]]}"' in warn[0]


def test_lamp_under_the_ceiling_is_not_flipped():
    """A two-sided lamp 1 cm under the ceiling, reversed (facing up): both its sides meet
    surfaces, so it is not reported (its own light on the ceiling lights its back)."""
    scene = _flip(_room(), [12])
    res = bake(scene, BakeSettings(patch_size=0.5, seed=7, output_mode="vertices"))
    assert not any("flipped normals" in w for w in res.report["warnings"])


def test_emitter_facing_the_void_is_flipped():
    """An emissive square above an open floor, its front facing up into the void: the side
    that lights the floor (its back) is baked, and the warning names it."""
    v = np.array([[0, 0, 0], [2, 0, 0], [2, 2, 0], [0, 2, 0],
                  [0.5, 0.5, 1], [1.5, 0.5, 1], [1.5, 1.5, 1], [0.5, 1.5, 1]], dtype=float)
    scene = scene_from_polygons(v, [[0, 1, 2, 3], [4, 5, 6, 7]], [0, 1],
                                [[0.5] * 3, [0.0] * 3], [[0.0] * 3, [5.0] * 3],
                                face_objects=[0, 1], object_names=["Floor", "Panel"])
    res = bake(scene, BakeSettings(patch_size=0.5, output_mode="vertices"))
    warn = [w for w in res.report["warnings"] if "flipped normals" in w]
    assert len(warn) == 1 and '"Panel"' in warn[0] and "1 of them emitting" in warn[0]
    assert '"Floor"' not in warn[0]


@pytest.fixture(scope="module")
def mesh_reference():
    scene = _room()
    return scene, [bake(scene, BakeSettings(seed=s)) for s in (7, 8)]


def _face_means(res, F):
    """(F,) area-weighted mean of each user face's written field in the radiosity mesh (an
    output face's mean: its corners' mean, exact for a linear field on a triangle)."""
    m = res.output
    means = np.zeros(F)
    for f in range(F):
        faces = m.faces_of([f])
        area = np.zeros(faces.size)
        col = np.zeros(faces.size)
        for k in (3, 4):
            sel = np.flatnonzero(m.face_sizes[faces] == k)
            idx = m.face_starts[faces[sel]][:, None] + np.arange(k)[None]
            p = m.vertices[m.corner_verts[idx]]
            area[sel] = 0.5 * np.linalg.norm(np.cross(p, np.roll(p, -1, axis=1)).sum(axis=1),
                                             axis=1)
            col[sel] = m.corner_colours[idx].mean(axis=(1, 2))
        means[f] = np.average(col, weights=area)
    return means


# The ceiling (over the lamp); every face but the lamp; the lamp alone (two-sided: its back
# faces the ceiling 1 cm above, as its front did).
@pytest.mark.parametrize("faces", [[0], [0, 3, 7], [1], list(range(12)), [12]])
def test_flipped_faces_bake_like_the_room_in_the_radiosity_mesh(mesh_reference, faces):
    scene0, (r0, r1) = mesh_reference
    scene = _flip(scene0, faces)
    rf = bake(scene, BakeSettings(seed=7))
    c0, c1 = _by_face_vertex(scene0, r0.corner_colours), _by_face_vertex(scene0, r1.corner_colours)
    cf = _by_face_vertex(scene, rf.corner_colours)
    assert np.abs(cf - c0).max() <= NOISE_FACTOR * max(np.abs(c1 - c0).max(), 1e-3 * c0.max())
    # the output faces of every face carry the room side's light: their means match, within
    # twice the seed noise of the face means (over the room's mean), the lamp's own left out
    F = scene0.n_faces - 1
    m0, m1, mf = (_face_means(r, scene0.n_faces)[:F] for r in (r0, r1, rf))
    noise = np.abs(m1 - m0).max() / m0.mean()
    assert np.abs(mf - m0).max() / m0.mean() <= NOISE_FACTOR * max(noise, 1e-3)
    flipped = [f for f in faces if f < F]
    assert any("back side (flipped normals?)" in w for w in rf.report["warnings"]) \
        == bool(flipped)


@pytest.mark.parametrize("mode", ["mesh", "vertices"])
def test_sun_on_the_outside_walls_does_not_turn_them_inside_out(mode):
    """The room lit inside by its lamp and outside by a bright sun: the walls' outsides receive
    far more light than their insides, yet the walls face the room (their outsides are open to
    the sky: their rows sum to about 0) and are baked on the inside, as modelled."""
    scene0 = _room()
    sun = [dict(kind="sun", name="Sun", direction=(0.4, 0.3, -1.0), strength=50.0)]
    lit = scene_from_polygons(scene0.vertices, [list(scene0.corner_verts[s:s + k]) for s, k in
                                                zip(scene0.face_starts, scene0.face_sizes)],
                              scene0.face_materials, scene0.reflectance, scene0.emission,
                              face_objects=scene0.face_objects, object_names=scene0.object_names,
                              lights=sun)
    kw = dict(patch_size=0.5, element_levels=0, output_mode=mode)
    r0, r1, r2 = (bake(scene0, BakeSettings(seed=s, **kw)) for s in (7, 8, 9))
    rs = bake(lit, BakeSettings(seed=7, **kw))
    assert not any("flipped normals" in w or "check normals" in w for w in rs.report["warnings"])
    # a closed room: the sun outside changes nothing inside (within the seeds' noise: the sunlit
    # outsides take their rows first, so the rotated hemicubes are drawn in another order; in the
    # mesh the noise also moves where leaves split, so it is the largest of three seed pairs)
    noise = max(np.abs(a.corner_colours - b.corner_colours).max()
                for a, b in ((r0, r1), (r0, r2), (r1, r2)))
    assert np.abs(rs.corner_colours - r0.corner_colours).max() <= NOISE_FACTOR * noise


def test_flipped_floor_under_a_board_is_split_as_modelled():
    """A board 10 cm over the floor (facing down) bounds a thin cavity with the floor, which
    the radiosity mesh splits (core.criteria.cavity_mask). With the floor wound the other way
    the cavity is not seen before the solve; the solve turns the floor to the room, and the
    bake splits and solves again: the same patches as modelled, the same light within twice
    the seed noise."""
    board = np.array([[0.5, 2.0, 0.1], [0.5, 2.9, 0.1], [3.5, 2.9, 0.1], [3.5, 2.0, 0.1]])
    scene0 = _room([(board, "Board")])
    r0, r1 = (bake(scene0, BakeSettings(seed=s)) for s in (7, 8))
    rf = bake(_flip(scene0, [0]), BakeSettings(seed=7))
    assert "solved_twice" not in r0.report and "solved_twice" in rf.report
    assert rf.report["patches"] == r0.report["patches"]
    F = scene0.n_faces
    lit = np.ones(F, dtype=bool)
    lit[12] = False                                 # the lamp's own face
    m0, m1, mf = (_face_means(r, F)[lit] for r in (r0, r1, rf))
    noise = np.abs(m1 - m0).max() / m0.mean()
    assert np.abs(mf - m0).max() / m0.mean() <= NOISE_FACTOR * max(noise, 1e-3)


@pytest.mark.parametrize("seed", [0, 1])
def test_flipped_faces_leave_the_lamps_outline_on_the_ceiling_as_modelled(seed):
    # The stability report's room (bench/stability): a 1 m lamp 0.3 m under the ceiling lights
    # it from its back, and its outline falls off steeply across the ceiling. Reversing other
    # faces changes only the order of the hemicubes' draws; a refinement that trusted one
    # midpoint on that S-shaped edge (core.criteria.LINEAR_RATIO) kept the ceiling beside the
    # lamp coarse in some of those draws and 7.5 % too bright there: the worst face 1.4 to
    # 1.9 % of the room's mean off the room as modelled, in 4 of 16 flipped bakes at seeds 0 to
    # 3. Tolerance: 0.6 %, twice the worst of those 16 bakes with the ratio (0.32 %).
    from bench.stability.scenes import room

    scene0, groups = room()
    lamp = set(groups["lamp"])
    keep = np.array([f not in lamp for f in range(scene0.n_faces)])
    m0 = _face_means(bake(scene0, BakeSettings(seed=seed)), scene0.n_faces)[keep]
    for names in (["floor"], ["ceiling", "wall y0", "wall y1", "lamp"]):
        faces = [f for g in names for f in groups[g]]
        scene = _flip(scene0, faces)
        mf = _face_means(bake(scene, BakeSettings(seed=seed)), scene.n_faces)[keep]
        assert np.abs(mf - m0).max() / m0.mean() <= 0.006, names
