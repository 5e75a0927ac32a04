"""A uniform world (issue 12): what a hemicube sees where no surface is, ``world x (1 - row sum)``.

Oracles: closed forms (a lone floor reflects rho x L under a world of radiance L, on either
side), an invariance (a closed room is not changed by the world outside it, within the seeds'
noise) and the energy balance (every watt the world puts on the surfaces is absorbed or
escapes). Cycles' own bakes of the same cases: tests/addon/test_world.py.
"""

import numpy as np
import pytest

from core.bake import bake
from core.errors import SceneError
from core.scene import scene_from_polygons
from core.settings import BakeSettings
from test_duplicates import _room

WORLD = np.array([0.2, 0.3, 0.5])
RHO = 0.5


def _floor(flip=False, **kw):
    v = np.array([[-2, -2, 0], [2, -2, 0], [2, 2, 0], [-2, 2, 0]], float)
    face = [0, 1, 2, 3][::-1] if flip else [0, 1, 2, 3]
    return scene_from_polygons(v, [face], [0], [[RHO] * 3], [[0, 0, 0]], **kw)


@pytest.mark.parametrize("mode", ["mesh", "vertices"])
def test_lone_floor_reflects_rho_times_the_world(mode):
    result = bake(_floor(world=WORLD), BakeSettings(output_mode=mode))
    np.testing.assert_allclose(result.corner_colours,
                               np.broadcast_to(RHO * WORLD, result.corner_colours.shape),
                               rtol=1e-6)
    e = result.report["energy"]
    # both sides of the 16 m^2 floor see the whole world: pi x L x A each
    assert e["emitted"] == pytest.approx(2 * np.pi * 16 * WORLD.sum(), rel=1e-9)
    assert abs(e["balance"]) < 1e-9 * e["emitted"]


@pytest.mark.parametrize("mode", ["mesh", "vertices"])
def test_a_ground_facing_down_keeps_its_side_under_sun_and_world(mode):
    """Open on both sides, the ground is baked on the side its normal points to, as Cycles does:
    the underside sees the world only, not the sun above."""
    sun = [dict(kind="sun", name="Sun", direction=(0.2, 0.1, -1.0), strength=5.0)]
    result = bake(_floor(flip=True, world=WORLD, lights=sun), BakeSettings(output_mode=mode))
    np.testing.assert_allclose(result.corner_colours,
                               np.broadcast_to(RHO * WORLD, result.corner_colours.shape),
                               rtol=1e-6)
    assert not any("flipped" in w for w in result.report["warnings"])


@pytest.mark.parametrize("mode", ["mesh", "vertices"])
def test_the_world_outside_a_closed_room_changes_nothing_inside(mode):
    scene0 = _room()
    polys = [list(scene0.corner_verts[s:s + k]) for s, k in zip(scene0.face_starts,
                                                               scene0.face_sizes)]
    lit = scene_from_polygons(scene0.vertices, polys, scene0.face_materials, scene0.reflectance,
                              scene0.emission, face_objects=scene0.face_objects,
                              object_names=scene0.object_names, world=10 * WORLD)
    kw = dict(patch_size=0.5, element_levels=0, output_mode=mode)
    r0, r1, r2 = (bake(scene0, BakeSettings(seed=s, **kw)) for s in (7, 8, 9))
    rw = bake(lit, BakeSettings(seed=7, **kw))
    # The box's bottom (face 6) lies in the floor's plane facing down: it sees under the floor,
    # the outside, as a Cycles bake of it does. Every other corner is inside.
    corners, faces = scene0.face_corner_indices()
    inside = corners[faces != 6]
    noise = max(np.abs(a.corner_colours - b.corner_colours)[inside].max()
                for a, b in ((r0, r1), (r0, r2), (r1, r2)))
    assert np.abs(rw.corner_colours - r0.corner_colours)[inside].max() <= 2.0 * noise
    assert not any("flipped" in w for w in rw.report["warnings"])


def test_world_light_through_an_opening_balances():
    """A room open at the top (no ceiling) lit by the world only: the world's light lands on
    the walls and the floor, and all of it is absorbed or escapes through the opening."""
    scene0 = _room()
    keep = [f for f in range(scene0.n_faces) if f not in (1, 12)]        # no ceiling, no lamp
    polys = [list(scene0.corner_verts[scene0.face_starts[f]:scene0.face_starts[f]
                                      + scene0.face_sizes[f]]) for f in keep]
    scene = scene_from_polygons(scene0.vertices, polys, scene0.face_materials[keep],
                                scene0.reflectance, np.zeros_like(scene0.emission),
                                world=WORLD)
    result = bake(scene, BakeSettings(output_mode="vertices", patch_size=0.5))
    e = result.report["energy"]
    assert e["emitted"] > 0
    assert abs(e["balance"]) < 0.02 * e["emitted"]     # the hemicube's reciprocity, as always
    # the floor's centre sees less sky than a lone floor, and more than nothing
    c = result.corner_colours
    assert np.all(c < RHO * WORLD * 1.5) and np.all(c[:4].max(axis=1) > 0)


def test_world_must_be_three_radiances():
    with pytest.raises(SceneError, match="world must be 3 finite radiances"):
        _floor(world=(1.0, -1.0, 0.0))
    with pytest.raises(SceneError, match="no emitter"):
        _floor(world=(0.0, 0.0, 0.0))
