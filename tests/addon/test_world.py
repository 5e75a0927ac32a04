"""A uniform world (Blender's world colour, or a Background node with unlinked inputs) against
Cycles itself.

Oracles: the closed form and Cycles. A lone floor under a uniform world of radiance L sees the
world over its whole hemisphere: it reflects rho x L, exactly; Cycles' bake of the same floor
(DIFFUSE, DIRECT + INDIRECT + COLOR, 256 samples) must agree with that closed form within its
noise (measured: 0 -- a uniform world sampled over a full hemisphere has none). An L of floor and
wall (each one quad, as architects model them) under the world: our bake against Cycles' corner
by corner. There the hemicube's sky fraction at each vertex (``world x (1 - row sum)``) and the
solve's interreflection are tested together; tolerance 3 % mean relative and 8 % per corner.
Measured (bpy 5.0.1): 0.6 % mean, 6.2 % at worst, at the wall-floor edge's corners, where a
corner's gather point sits just inside its face while Cycles bakes the corner at the vertex
itself: the other face is seen at a grazing angle there.
"""

import json

import bpy
import numpy as np
import pytest

from helpers import cycles_corners, material, mesh_object, read_colours, square

SAMPLES = 256
MEAN_RTOL, MAX_RTOL = 0.03, 0.08


def _world(colour, strength=1.0, textured=False):
    world = bpy.data.worlds.new("Sky")
    if bpy.app.version < (5, 0, 0):
        world.use_nodes = True
    background = world.node_tree.nodes["Background"]
    background.inputs["Color"].default_value = (*colour, 1.0)
    background.inputs["Strength"].default_value = strength
    world.color = colour
    bpy.context.scene.world = world
    return world


def _grid(name, size, location, rotation=(0.0, 0.0, 0.0), cuts=8):
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=cuts, y_subdivisions=cuts, size=size,
                                    location=location, rotation=rotation)
    obj = bpy.context.object
    obj.name = name
    obj.data.materials.append(material("diffuse grey", (0.5, 0.5, 0.5), kind="diffuse"))
    return obj


def _cycles(objects):
    return [cycles_corners(obj, SAMPLES, indirect=True) for obj in objects]


def _ours(objects):
    scene = bpy.context.scene
    scene.radiosity.output_mode = "VERTICES"
    assert bpy.ops.radiosity.bake() == {"FINISHED"}
    return [read_colours(obj.data) for obj in objects], json.loads(scene.radiosity.last_report)


def test_lone_floor_under_a_uniform_world_reflects_rho_times_the_world(package):
    floor = _grid("Floor", 2.0, (0.0, 0.0, 0.0))
    _world((0.2, 0.3, 0.5), strength=2.0)
    want = 0.5 * 2.0 * np.array([0.2, 0.3, 0.5])
    (cycles,) = _cycles([floor])
    (ours,), report = _ours([floor])
    np.testing.assert_allclose(ours, np.broadcast_to(want, ours.shape), rtol=1e-6)
    np.testing.assert_allclose(cycles, np.broadcast_to(want, cycles.shape), rtol=1e-3)
    assert not any("World" in w for w in report["warnings"])


def test_floor_and_wall_under_a_uniform_world_match_cycles(package):
    floor = _grid("Floor", 2.0, (0.0, 0.0, 0.0))
    wall = _grid("Wall", 2.0, (0.0, 1.0, 1.0), rotation=(np.pi / 2, 0.0, 0.0))   # normal -y
    _world((1.0, 1.0, 1.0))
    cycles = _cycles([floor, wall])
    ours, _ = _ours([floor, wall])
    c, o = np.concatenate(cycles), np.concatenate(ours)
    rel = np.abs(o - c) / c
    assert rel.mean() < MEAN_RTOL, f"mean {rel.mean():.4f}, max {rel.max():.4f}"
    assert rel.max() < MAX_RTOL, f"mean {rel.mean():.4f}, max {rel.max():.4f}"
    # the wall darkens the floor near it: the sky it hides is not all given back by the wall
    assert ours[0].min() < 0.95 * ours[0].max()


def test_world_with_diffuse_visibility_off_is_no_light(package):
    mesh_object("Floor", *square(1.0), material("grey"))
    world = _world((1.0, 1.0, 1.0))
    world.cycles_visibility.diffuse = False
    with pytest.raises(RuntimeError, match="No light"):
        bpy.ops.radiosity.bake()
