"""Relight and light groups in the panel (radiosity_addon.relight, relight_ops).

Oracle: a fresh bake of the scene with the new light. The solve is linear in the light, so a
relight on the kept form factors, or a weighted sum of the groups' solutions, must equal it to
the solver's stopping error (the ``tolerance`` setting, relative, on each of the two solves)
plus float32 at the Blender boundary. Receiver elements are off where groups are mixed: a fresh
bake places them where *its* light changes, a relight keeps the bake's (core.relight).
"""

import json
import os
import re
import tempfile

import bpy
import numpy as np
import pytest

from conftest import PACKAGE
from helpers import box, material, mesh_object, read_colours, relight_labels, set_settings, square

relight = PACKAGE.radiosity_addon.relight
write = PACKAGE.radiosity_addon.write

#: Two solves, each within ``tolerance`` (relative) of the exact solution, and float32 colours.
RTOL = 2 * PACKAGE.core.BakeSettings().tolerance + 1e-5


def room(power=40.0, lamp_strength=3.0, lamp_colour=(1.0, 1.0, 1.0)):
    """A closed grey 3 m room (two materials), a 1 m emissive ceiling panel and a point light."""
    bv, bf = box(3.0)
    walls = mesh_object("Room", bv, bf, material("grey", (0.6, 0.5, 0.4)))
    walls.data.materials.append(material("blue", (0.2, 0.3, 0.7)))
    walls.data.polygons[0].material_index = 1
    lv, lf = square(1.0, z=1.45, down=True)
    lamp = mesh_object("Lamp", lv, lf, material("lamp", emission=lamp_colour,
                                                strength=lamp_strength, kind="emission"))
    bulb = bpy.data.objects.new("Bulb", bpy.data.lights.new("Bulb", "POINT"))
    bulb.data.energy = power
    bulb.location = (0.8, -0.5, 0.3)
    bpy.context.scene.collection.objects.link(bulb)
    return walls, lamp, bulb


def bake(**settings):
    kw = dict(output_mode="VERTICES", element_levels=0)
    kw.update(settings)
    set_settings(bpy.context.scene, **kw)
    assert bpy.ops.radiosity.bake() == {"FINISHED"}


def colours_and_lux(obj):
    mesh = obj.data
    lux = np.empty(len(mesh.loops), dtype=np.float32)
    mesh.attributes["Radiosity Lux"].data.foreach_get("value", lux)
    return read_colours(mesh), lux.astype(np.float64)


def assert_close(actual, expected):
    for a, e in zip(actual, expected):
        assert a.shape == e.shape
        scale = np.abs(e).max()
        np.testing.assert_allclose(a, e, rtol=RTOL, atol=RTOL * scale)


def set_lamp(lamp, strength=None, colour=None):
    node = lamp.active_material.node_tree.nodes["Emission"]
    if strength is not None:
        node.inputs["Strength"].default_value = strength
    if colour is not None:
        node.inputs["Color"].default_value = (*colour, 1.0)


def fresh(*objects):
    """Colours and lux of a fresh bake of the scene as it is now (the oracle)."""
    relight.drop(bpy.context.scene)
    assert bpy.ops.radiosity.bake() == {"FINISHED"}
    return [colours_and_lux(o) for o in objects]


def test_relight_after_doubling_a_light_equals_a_fresh_bake(package):
    walls, lamp, bulb = room()
    bake()
    bulb.data.energy *= 2.0
    assert bpy.ops.radiosity.relight() == {"FINISHED"}
    report = json.loads(bpy.context.scene.radiosity.last_report)
    assert report["relight"]["seconds"] > 0 and report["relight"]["kept_mb"] > 0
    relit = colours_and_lux(walls)
    assert_close(relit, fresh(walls)[0])


def test_relight_of_the_radiosity_mesh_is_linear_in_the_light(package):
    # A fresh bake re-meshes where its light changes, so the oracle on the radiosity mesh is
    # linearity: every light x 2.5 (lamp and bulb) reads 2.5 x the bake on the same mesh.
    walls, lamp, bulb = room()
    bake(output_mode="MESH", element_levels=2)
    baked = colours_and_lux(walls)
    n_faces = len(walls.data.polygons)
    bulb.data.energy *= 2.5
    set_lamp(lamp, strength=2.5 * 3.0)
    assert bpy.ops.radiosity.relight() == {"FINISHED"}
    assert len(walls.data.polygons) == n_faces
    assert_close(colours_and_lux(walls), [2.5 * baked[0], 2.5 * baked[1]])


def test_relight_after_a_colour_change_of_an_emissive_material_equals_a_fresh_bake(package):
    walls, lamp, bulb = room(power=0.0)
    bake()
    before = colours_and_lux(walls)
    set_lamp(lamp, strength=5.0, colour=(1.0, 0.5, 0.2))
    assert bpy.ops.radiosity.relight() == {"FINISHED"}
    relit = colours_and_lux(walls)
    assert not np.allclose(relit[0], before[0])
    assert_close(relit, fresh(walls)[0])


def test_light_groups_mix_equals_a_fresh_bake_with_the_scaled_light(package):
    walls, lamp, bulb = room()
    bake()
    groups = bpy.context.scene.radiosity_groups
    assert [g.name for g in groups] == ["lamp", "Bulb"]
    groups["lamp"].strength = 0.5
    groups["lamp"].tint = (1.0, 0.8, 0.6)   # each change writes at once (update callback)
    groups["Bulb"].strength = 2.0
    mixed = colours_and_lux(walls)
    set_lamp(lamp, strength=1.5, colour=(1.0, 0.8, 0.6))
    bulb.data.energy *= 2.0
    for g in groups:
        g.strength, g.tint = 1.0, (1.0, 1.0, 1.0)
    assert_close(mixed, fresh(walls)[0])


def test_blender_light_groups_merge_what_they_hold(package):
    walls, lamp, bulb = room()
    lamp.lightgroup = bulb.lightgroup = "Ceiling"
    bake()
    assert [g.name for g in bpy.context.scene.radiosity_groups] == ["Ceiling"]


def _move_vertex(walls, lamp):
    write.original_mesh(walls).vertices[0].co.x -= 0.2   # the user's mesh, not the baked one


def _recolour_wall(walls, lamp):
    walls.active_material.node_tree.nodes["Principled BSDF"].inputs["Base Color"] \
        .default_value = (0.1, 0.9, 0.1, 1.0)


def _new_emitter(walls, lamp):
    inputs = walls.data.materials[1].node_tree.nodes["Principled BSDF"].inputs
    inputs["Emission Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    inputs["Emission Strength"].default_value = 2.0


@pytest.mark.parametrize("change, message", [
    (_move_vertex, "geometry changed"), (_recolour_wall, "material colours changed"),
    (_new_emitter, "'blue' emits now")])
def test_relight_with_changed_scene_stops_and_changes_nothing(package, change, message):
    walls, lamp, bulb = room()
    bake(output_mode="MESH")
    before = colours_and_lux(walls)
    report = bpy.context.scene.radiosity.last_report
    change(walls, lamp)
    bulb.data.energy *= 2.0
    with pytest.raises(RuntimeError, match=f"{message}.*bake again"):
        bpy.ops.radiosity.relight()
    assert_close(colours_and_lux(walls), before)
    assert bpy.context.scene.radiosity.last_report == report


@pytest.mark.parametrize("mode", ["VERTICES", "MESH"])
def test_relight_with_lights_changed_apart_or_moved_equals_a_fresh_bake(package, mode):
    # The lights' direct light is kept summed: lights changed apart are cast again (shadow
    # rays and gathers; the radiosity mesh is made again), the form factors kept.
    walls, lamp, bulb = room()
    other = bpy.data.objects.new("Bulb2", bpy.data.lights.new("Bulb2", "SPOT"))
    other.data.energy = 60.0
    other.location = (-0.9, 0.4, 1.2)
    bpy.context.scene.collection.objects.link(other)
    bake(output_mode=mode)
    bulb.data.energy *= 2.0
    other.data.color = (1.0, 0.4, 0.1)
    other.location = (-0.5, -0.6, 1.1)
    assert bpy.ops.radiosity.relight() == {"FINISHED"}
    relit = colours_and_lux(walls)
    if mode == "VERTICES":                    # and relit again from there: scaled alike
        set_lamp(lamp, strength=1.0)
        bulb.data.energy *= 0.5
        other.data.energy *= 0.5
        assert bpy.ops.radiosity.relight() == {"FINISHED"}
        assert not np.allclose(relit[1], colours_and_lux(walls)[1])
        relit = colours_and_lux(walls)
    expected = fresh(walls)[0]
    assert relit[0].shape == expected[0].shape   # the radiosity mesh made again alike
    assert_close(relit, expected)


def test_relight_without_a_kept_bake_says_bake_again(package):
    walls, lamp, bulb = room()
    with pytest.raises(RuntimeError, match="no bake is kept.*bake again"):
        bpy.ops.radiosity.relight()
    bake()
    path = os.path.join(tempfile.mkdtemp(), "relight.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.open_mainfile(filepath=path)     # the kept data does not survive the file
    bpy.data.objects["Bulb"].data.energy *= 2.0
    with pytest.raises(RuntimeError, match="no bake is kept.*bake again"):
        bpy.ops.radiosity.relight()


@pytest.mark.parametrize("mode", ["VERTICES", "MESH"])
def test_clear_bake_after_relight_restores_the_scene_exactly(package, mode):
    from test_write_mesh import assert_same, snapshot

    walls, lamp, bulb = room()
    original = walls.data
    before = snapshot(original)
    bake(output_mode=mode)
    set_lamp(lamp, strength=6.0)
    assert bpy.ops.radiosity.relight() == {"FINISHED"}
    bpy.context.scene.radiosity_groups["Bulb"].strength = 0.3
    set_settings(bpy.context.scene, selected_only=False)
    assert bpy.ops.radiosity.clear() == {"FINISHED"}
    assert walls.data == original
    assert_same(snapshot(walls.data), before)
    assert not any(m.name.endswith(write.BAKED_SUFFIX) for m in bpy.data.meshes)
    assert not any(k.startswith("radiosity") for k in walls.keys())
    assert relight.kept(bpy.context.scene) is None
    with pytest.raises(RuntimeError, match="bake again"):
        bpy.ops.radiosity.relight()


def test_forget_frees_the_kept_bake_and_relight_says_bake_again(package):
    walls, lamp, bulb = room()
    bake()
    assert relight.kept(bpy.context.scene).kept_mb > 0
    assert bpy.ops.radiosity.relight_forget() == {"FINISHED"}
    assert relight.kept(bpy.context.scene) is None
    assert len(bpy.context.scene.radiosity_groups) == 0
    with pytest.raises(RuntimeError, match="no bake is kept.*bake again"):
        bpy.ops.radiosity.relight()


@pytest.mark.parametrize("mode", ["VERTICES", "MESH"])
def test_group_changes_after_the_first_are_a_weighted_sum_with_no_solve(package, monkeypatch,
                                                                        mode):
    # Oracles: the groups at 1 give the bake back (the groups' solutions add up to it), and
    # the groups alone add up to any mix (linearity) -- on the bake's radiosity mesh too.
    walls, lamp, bulb = room()
    bake(output_mode=mode, element_levels=2 if mode == "MESH" else 0)
    baked = colours_and_lux(walls)
    groups = bpy.context.scene.radiosity_groups
    groups["lamp"].strength = 2.0            # the groups' solutions are made here, once
    twice = colours_and_lux(walls)

    def no_solve(*args, **kwargs):
        raise AssertionError("a light group change solved again")
    monkeypatch.setattr(PACKAGE.core, "relight", no_solve)
    monkeypatch.setattr(PACKAGE.core, "relight_many", no_solve)
    groups["lamp"].strength = 1.0
    assert_close(colours_and_lux(walls), baked)
    groups["lamp"].strength = 2.0
    assert_close(colours_and_lux(walls), twice)
    groups["Bulb"].strength = 0.0          # the lamp alone: its own group's solution
    lamp_only = colours_and_lux(walls)
    groups["Bulb"].strength = 1.0
    groups["lamp"].strength = 0.0            # the bulb alone; the two add up to the mix
    bulb_only = colours_and_lux(walls)
    assert_close(twice, [lamp_only[k] + bulb_only[k] for k in range(2)])
    assert not np.allclose(twice[0], baked[0])
    assert bpy.ops.radiosity.groups_reset() == {"FINISHED"}
    assert [(g.strength, tuple(g.tint)) for g in groups] == [(1.0, (1.0, 1.0, 1.0))] * 2
    assert_close(colours_and_lux(walls), baked)


def test_batch_group_strength_equals_a_fresh_bake(package, tmp_path):
    from test_batch import one_error_line, run_batch

    walls, lamp, bulb = room()
    set_settings(bpy.context.scene, output_mode="VERTICES", element_levels=0)
    src, out = tmp_path / "room.blend", tmp_path / "mixed.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(src))
    proc = run_batch(src, "--output", out, "--group-strength", "lamp=0.5",
                     "--group-strength", "Bulb=2")
    assert proc.returncode == 0, proc.stderr
    bpy.ops.wm.open_mainfile(filepath=str(out))
    mixed = colours_and_lux(bpy.data.objects["Room"])
    set_lamp(bpy.data.objects["Lamp"], strength=1.5)
    bpy.data.objects["Bulb"].data.energy *= 2.0
    assert_close(mixed, fresh(bpy.data.objects["Room"])[0])
    line = one_error_line(run_batch(src, "--output", tmp_path / "x.blend",
                                    "--group-strength", "Sun=2"))
    assert "no light group of that name" in line and "'lamp', 'Bulb'" in line
    line = one_error_line(run_batch(src, "--output", tmp_path / "x.blend",
                                    "--group-strength", "lamp"))
    assert "NAME=FACTOR" in line


def test_relight_after_undoing_the_bake_says_bake_again_and_writes_nothing(package):
    walls, lamp, bulb = room()
    set_settings(bpy.context.scene, output_mode="VERTICES", element_levels=0)
    bpy.ops.ed.undo_push(message="scene")
    assert bpy.ops.radiosity.bake("EXEC_DEFAULT", True) == {"FINISHED"}
    bpy.ops.ed.undo()
    walls = bpy.data.objects["Room"]
    assert "Radiosity" not in walls.data.color_attributes
    with pytest.raises(RuntimeError, match="no longer shows the bake.*bake again"):
        bpy.ops.radiosity.relight()
    assert "Radiosity" not in walls.data.color_attributes


def test_relight_with_an_area_light_relights_both_sides_of_a_two_sided_emitter(package):
    # An area light makes the scene's emitters one-sided or two-sided per material (the core's
    # back_emission): the lamp's back, 5 cm under the ceiling, lights the ceiling, and must
    # follow the lamp's new colour as a fresh bake's does.
    walls, lamp, bulb = room(power=0.0)
    panel = bpy.data.objects.new("Panel", bpy.data.lights.new("Panel", "AREA"))
    panel.data.size, panel.data.energy = 0.5, 60.0
    panel.location = (-0.8, 0.6, 1.2)
    bpy.context.scene.collection.objects.link(panel)
    bake()
    assert [g.name for g in bpy.context.scene.radiosity_groups] == ["lamp", "light: Panel"]
    set_lamp(lamp, strength=4.0, colour=(0.3, 0.6, 1.0))
    panel.data.energy = 30.0
    assert bpy.ops.radiosity.relight() == {"FINISHED"}
    relit = colours_and_lux(walls)
    assert_close(relit, fresh(walls)[0])


def test_calculation_surfaces_follow_relight_and_groups(package):
    # Oracle: a fresh bake with the mixed light measures the same grid lux and vertex lux.
    walls, lamp, bulb = room()
    plane = mesh_object("Desk", *square(1.2, z=-0.7))
    plane.radiosity_calc_surface = True
    bake()
    set_lamp(lamp, strength=4.5)
    assert bpy.ops.radiosity.relight() == {"FINISHED"}
    bpy.context.scene.radiosity_groups["Bulb"].strength = 0.5

    def measured():
        report = json.loads(bpy.context.scene.radiosity.last_report)
        (summary,) = report["calculation_surfaces"]
        values = np.empty(len(plane.data.vertices), dtype=np.float32)
        plane.data.attributes["Radiosity Lux"].data.foreach_get("value", values)
        return [np.array([summary["Eavg"], summary["Emin"]]), values.astype(np.float64)]
    mixed = measured()
    bulb.data.energy *= 0.5
    bpy.context.scene.radiosity_groups["Bulb"].strength = 1.0
    fresh(walls)
    assert_close(mixed, measured())


def test_a_bake_whose_kept_data_exceeds_the_memory_budget_is_not_kept(package, monkeypatch):
    """The kept rows grow with the scene (the office: 458 MB): above the bake's memory budget
    (1 GiB by default; not a panel setting, so lowered here) they are dropped, and Relight says
    why."""
    walls, lamp, bulb = room()
    bake(output_mode="MESH", element_levels=2)
    size = relight.kept(bpy.context.scene).kept_mb * 2 ** 20
    budget = PACKAGE.core.settings.MIN_MEMORY_BUDGET
    assert size > budget          # this room keeps more than the smallest budget allowed
    monkeypatch.setattr(relight, "kept_budget", lambda bake_input: budget)
    bake(output_mode="MESH", element_levels=2)
    assert relight.kept(bpy.context.scene) is None
    assert len(bpy.context.scene.radiosity_groups) == 0
    with pytest.raises(RuntimeError, match=r"not kept in memory \(it needs \d+ MB, above the "
                                           r"Memory Budget of 1 MB\); bake again"):
        bpy.ops.radiosity.relight()
    labels = relight_labels(PACKAGE.radiosity_addon.relight_ops)   # the panel says so
    assert len(labels) == 1 and re.fullmatch(r"Not kept: needs \d+ MB \(budget 1\)",
                                              labels[0]), labels
    monkeypatch.undo()
    bake(output_mode="MESH", element_levels=2)           # the default budget keeps it again
    assert relight.kept(bpy.context.scene) is not None


# ----------------------------------------------------------------------------- one group a light

#: The core's light culling (core.lights.CULL): at each point the lights that give at most this
#: fraction of its unshadowed light cast one ray, to their centre, not their penumbra's rounds.
#: A mix is the bake (which culls) plus groups cast alone (which do not), so where a culled
#: light is in part hidden it may differ from a fresh bake by at most CULL of the light arriving
#: there, itself at most the brightest value of the bake.
CULL = PACKAGE.core.lights.CULL


@pytest.fixture
def fixed_cubes(monkeypatch):
    """Bakes with unrotated hemicubes. Each hemicube's random rotation is drawn in the order
    the form factors discover the nodes, which starts at the emitters: a fresh bake with a
    light off draws other rotations, and differs from the same light on the kept form factors
    by the hemicube's aliasing (up to 0.15 % in two_lights), not by the light's transport."""
    real = PACKAGE.core.BakeSettings
    monkeypatch.setattr(PACKAGE.radiosity_addon.job.core, "BakeSettings",
                        lambda **kw: real(**{**kw, "rotate_hemicube": False}))


def grid(n, size, z):
    """Vertices and n x n quads of a square centred on the z axis at height z, normal +z."""
    xs = np.linspace(-size / 2, size / 2, n + 1)
    verts = [(x, y, z) for y in xs for x in xs]
    faces = [(j * (n + 1) + i, j * (n + 1) + i + 1, (j + 1) * (n + 1) + i + 1,
              (j + 1) * (n + 1) + i) for j in range(n) for i in range(n)]
    return verts, faces


def two_lights(top=True):
    """A 3 m grey room (open at the top without ``top``) whose floor is a grid, a block on it
    that shadows it, a point light "Bulb" and a spot light "Spot" above the block."""
    bv, bf = box(3.0)
    bf = [f for f in bf if not all(bv[i][2] < 0 for i in f)                 # the floor: a grid
          and (top or not all(bv[i][2] > 0 for i in f))]
    objects = [mesh_object("Room", bv, bf, material("grey", (0.6, 0.5, 0.4))),
               mesh_object("Floor", *grid(6, 3.0, -1.5), material("floor", (0.7, 0.7, 0.7))),
               mesh_object("Block", *box(0.5, inward=False), material("block", (0.3, 0.5, 0.3)),
                           location=(0.2, 0.1, -1.25))]
    lights = []
    for name, kind, energy, location in (("Bulb", "POINT", 40.0, (0.8, -0.5, 0.0)),
                                         ("Spot", "SPOT", 80.0, (-0.4, 0.5, 1.3))):
        obj = bpy.data.objects.new(name, bpy.data.lights.new(name, kind))
        obj.data.energy, obj.location = energy, location
        bpy.context.scene.collection.objects.link(obj)
        lights.append(obj)
    lights[1].data.spot_size, lights[1].data.spot_blend = np.radians(80.0), 0.3
    return objects, lights


def assert_near(actual, expected, bake, cull=CULL):
    """assert_close per object, with ``cull`` x the brightest colour (lux) of ``bake``, the
    light with every group at 1, more (see CULL)."""
    for (a_col, a_lux), (e_col, e_lux), (b_col, b_lux) in zip(actual, expected, bake):
        for a, e, b in ((a_col, e_col, b_col), (a_lux, e_lux, b_lux)):
            np.testing.assert_allclose(a, e, rtol=RTOL,
                                       atol=RTOL * np.abs(e).max() + cull * np.abs(b).max())


@pytest.mark.parametrize("cull", [0.0, CULL])
def test_a_light_group_alone_equals_a_fresh_bake_with_the_other_light_off(package, fixed_cubes,
                                                                         monkeypatch, cull):
    # Oracle: a fresh bake of the scene with the other light's power set to 0. "Bulb" is cast
    # alone, "Spot" is then the rest of the lights' solution (no cast): without culling both
    # within the two solves' tolerance; with it up to CULL x the light there more (see CULL).
    # Without the shadow lines: with them, the patches follow the lights' powers (a light off
    # draws no lines), so the fresh bake with a light off is cut otherwise than the bake its
    # group comes from (2.3 % apart at a corner by the block here), as the radiosity mesh
    # follows the light; tests/core/test_recolour.py checks the groups' sum with the lines on.
    monkeypatch.setattr(PACKAGE.core.lights, "CULL", cull)
    objects, (bulb, spot) = two_lights()
    bake(shadow_cuts=False)
    full = [colours_and_lux(o) for o in objects]
    groups = bpy.context.scene.radiosity_groups
    assert [g.name for g in groups] == ["Bulb", "Spot"]
    groups["Bulb"].strength = 0.0
    spot_only = [colours_and_lux(o) for o in objects]
    groups["Bulb"].strength, groups["Spot"].strength = 1.0, 0.0
    bulb_only = [colours_and_lux(o) for o in objects]
    groups["Spot"].strength = 1.0
    assert_near([colours_and_lux(o) for o in objects], full, full, 0.0)   # the bake again
    power = bulb.data.energy
    bulb.data.energy = 0.0
    assert_near(spot_only, fresh(*objects), full, cull)
    bulb.data.energy, spot.data.energy = power, 0.0
    assert_near(bulb_only, fresh(*objects), full, cull)


@pytest.mark.parametrize("light", ["Bulb", "Spot"])
def test_a_red_tint_on_a_light_group_equals_a_fresh_bake_with_that_light_red(package, fixed_cubes,
                                                                             light):
    objects, _ = two_lights()
    bake()
    baked = [colours_and_lux(o) for o in objects]
    bpy.context.scene.radiosity_groups[light].tint = (1.0, 0.0, 0.0)
    tinted = [colours_and_lux(o) for o in objects]
    bpy.data.objects[light].data.color = (1.0, 0.0, 0.0)
    assert_near(tinted, fresh(*objects), baked)


def test_world_and_each_light_are_groups_of_their_own_and_relight_keeps_the_world(package,
                                                                                   fixed_cubes):
    # Oracles: fresh bakes without the world (its strength 0), without the bulb, and with the
    # lights' power doubled (a relight scales the lights' solution, never the world's).
    objects, (bulb, spot) = two_lights(top=False)
    world = bpy.data.worlds.new("Sky")
    if bpy.app.version < (5, 0, 0):
        world.use_nodes = True            # always on (deprecated) from 5.0
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.4, 0.6, 1.0, 1.0)
    bpy.context.scene.world = world
    bake()
    baked = [colours_and_lux(o) for o in objects]
    groups = bpy.context.scene.radiosity_groups
    assert [g.name for g in groups] == ["Bulb", "Spot", "World"]
    groups["World"].strength = 0.0
    no_world = [colours_and_lux(o) for o in objects]
    groups["World"].strength, groups["Bulb"].strength = 1.0, 0.0
    no_bulb = [colours_and_lux(o) for o in objects]
    groups["Bulb"].strength = 1.0
    bulb.data.energy *= 2.0
    spot.data.energy *= 2.0
    assert bpy.ops.radiosity.relight() == {"FINISHED"}
    assert_close(colours_and_lux(objects[1]), fresh(objects[1])[0])
    bulb.data.energy *= 0.5
    spot.data.energy *= 0.5
    strength = world.node_tree.nodes["Background"].inputs["Strength"]
    strength.default_value = 0.0
    assert_near(no_world, fresh(*objects), baked)
    strength.default_value, bulb.data.energy = 1.0, 0.0
    assert_near(no_bulb, fresh(*objects), baked)


def test_group_names_are_unique_on_either_output(package):
    # Two objects of one light datablock are two groups; a light named as a material is told
    # apart. On the radiosity mesh too: a light alone keeps the mesh (core.recolour).
    walls, lamp, bulb = room()
    twin = bpy.data.objects.new("lamp", bulb.data)    # the data of "Bulb", a material's name
    twin.location = (-0.7, 0.6, 0.2)
    bpy.context.scene.collection.objects.link(twin)
    bake()
    assert [g.name for g in bpy.context.scene.radiosity_groups] == ["lamp", "Bulb",
                                                                    "lamp (light)"]
    bake(output_mode="MESH")
    assert [g.name for g in bpy.context.scene.radiosity_groups] == ["lamp", "Bulb",
                                                                    "lamp (light)"]


def test_a_light_group_on_the_radiosity_mesh_equals_relight_with_that_light_off(package,
                                                                                fixed_cubes):
    # Oracle: Relight after the bulb's power is set to 0 in the scene (the spot's light alone,
    # one solve on the kept mesh), against the mix with the Bulb group at 0 (the bake minus the
    # bulb's own solution). Both keep the radiosity mesh; they agree within two solves and
    # CULL (the bake culls, the bulb alone does not).
    objects, (bulb, spot) = two_lights()
    bake(output_mode="MESH", element_levels=2)
    full = [colours_and_lux(o) for o in objects]
    groups = bpy.context.scene.radiosity_groups
    assert [g.name for g in groups] == ["Bulb", "Spot"]
    groups["Bulb"].strength = 0.0
    spot_only = [colours_and_lux(o) for o in objects]
    groups["Bulb"].strength = 1.0
    bulb.data.energy = 0.0
    assert bpy.ops.radiosity.relight() == {"FINISHED"}
    relit = [colours_and_lux(o) for o in objects]
    assert [c.shape for c, _ in relit] == [c.shape for c, _ in full]
    assert_near(spot_only, relit, full)
    assert not np.allclose(spot_only[1][0], full[1][0], rtol=0.05)


def test_a_group_change_makes_every_group_alone_once(package, monkeypatch):
    # Cost: the first change of a group makes every group's own solution, in one
    # core.relight_many (one matrix swept for all): the first light cast alone (lights=), the
    # last light's group the rest of the lights' solution (no cast); changes after that solve
    # nothing.
    objects, _ = two_lights()
    bake()
    calls, one, many = [], PACKAGE.core.relight, PACKAGE.core.relight_many
    monkeypatch.setattr(PACKAGE.core, "relight",
                        lambda result, **kw: calls.append(sorted(kw)) or one(result, **kw))
    monkeypatch.setattr(PACKAGE.core, "relight_many",
                        lambda result, changes: calls.append([sorted(c) for c in changes])
                        or many(result, changes))
    groups = bpy.context.scene.radiosity_groups
    groups["Bulb"].strength = 0.5
    assert calls == [[["emission", "lights"], ["emission"]]]
    groups["Spot"].strength = 0.5
    groups["Bulb"].tint, groups["Spot"].strength = (1.0, 0.5, 0.2), 2.0
    assert len(calls) == 1


def test_relight_that_moves_the_shadow_lines_bakes_again(package, fixed_cubes):
    # With Cut at Shadows (the default) the patches are cut along the lines each light draws
    # from the block's feet: moving the bulb moves its lines, so Relight bakes the scene again
    # (core.relight says so in the report) and writes what a fresh bake writes; keeping the
    # bake's patches would keep the old lines.
    objects, (bulb, spot) = two_lights()
    bake(output_mode="MESH", shadow_cuts=True)
    baked = json.loads(bpy.context.scene.radiosity.last_report)
    assert baked["contacts"]["shadow_lines"] > 0
    bulb.location = (-0.7, 0.8, 0.0)
    assert bpy.ops.radiosity.relight() == {"FINISHED"}
    report = json.loads(bpy.context.scene.radiosity.last_report)
    assert any("baked again" in w for w in report["warnings"])
    relit = [colours_and_lux(o) for o in objects]
    expected = fresh(*objects)
    for (col, lux), (e_col, e_lux) in zip(relit, expected):
        assert col.shape == e_col.shape                # the same radiosity mesh
        assert_close((col, lux), (e_col, e_lux))


def lamp_and_two_lights():
    """:func:`two_lights` and a 0.6 m lamp under the ceiling, baked without shadow lines:
    (the meshes, the lamp, the lights, each mesh's colours and lux as baked)."""
    objects, lights = two_lights()
    lamp = mesh_object("Lamp", *square(0.6, z=1.45, down=True),
                       material("lamp", emission=(1.0, 1.0, 1.0), strength=4.0,
                                kind="emission"))
    objects.append(lamp)
    bake(shadow_cuts=False)
    return objects, lamp, lights, [colours_and_lux(o) for o in objects]


def no_solve(*args, **kw):
    raise AssertionError("solved")


@pytest.mark.parametrize("cull", [0.0, CULL])
def test_relight_that_only_scales_groups_is_their_weighted_sum_with_no_solve(package,
                                                                           fixed_cubes,
                                                                           monkeypatch, cull):
    # Each group's light scaled alone (a material's strength and colour, a light's power and
    # colour) is a weighted sum of the groups' own solutions, which the first such Relight
    # makes at once (one core.relight_many). Oracle: a fresh bake of the scene as it is, within
    # the two solves' tolerance and the light culling's share (CULL: a light alone is culled
    # at the points where it is dim, not where the sum is).
    monkeypatch.setattr(PACKAGE.core.lights, "CULL", cull)
    objects, lamp, (bulb, spot), baked = lamp_and_two_lights()
    calls, one, many = [], PACKAGE.core.relight, PACKAGE.core.relight_many
    monkeypatch.setattr(PACKAGE.core, "relight_many",
                        lambda result, changes: calls.append(len(changes)) or many(result,
                                                                                  changes))
    bulb.data.energy *= 2.0
    assert bpy.ops.radiosity.relight() == {"FINISHED"}
    assert calls == [3]          # the lamp alone, the lights, the bulb alone (no world here)
    assert json.loads(bpy.context.scene.radiosity.last_report)["relight"]["summed"]

    monkeypatch.setattr(PACKAGE.core, "relight", no_solve)
    monkeypatch.setattr(PACKAGE.core, "relight_many", no_solve)
    set_lamp(lamp, strength=6.0, colour=(1.0, 0.6, 0.3))
    spot.data.energy, spot.data.color = 30.0, (0.5, 0.7, 1.0)
    assert bpy.ops.radiosity.relight() == {"FINISHED"}
    report = json.loads(bpy.context.scene.radiosity.last_report)
    assert sorted(report["timings"]) == ["light_groups", "total", "write"]  # not the bake's
    assert report["timings"]["total"] == pytest.approx(report["relight"]["seconds"], abs=1e-4)
    bpy.context.scene.radiosity_groups["Spot"].strength = 0.5       # the groups on top
    summed = [colours_and_lux(o) for o in objects]
    monkeypatch.setattr(PACKAGE.core, "relight", one)
    monkeypatch.setattr(PACKAGE.core, "relight_many", many)
    bpy.context.scene.radiosity_groups["Spot"].strength = 1.0
    spot.data.energy = 15.0
    expected = fresh(*objects)
    assert not np.allclose(summed[1][0], baked[1][0], rtol=0.05)
    assert_near(summed, expected, baked, cull)


def test_relight_of_a_change_that_is_not_a_group_scaled_solves(package, fixed_cubes,
                                                               monkeypatch):
    # Two lights in one Blender light group are one unit: the bulb's power changed alone is no
    # weighted sum of the groups, so Relight casts the lights again (core.relight(lights=)).
    # Oracle: a fresh bake, within the two solves' tolerance.
    objects, (bulb, spot) = two_lights()
    bulb.lightgroup = spot.lightgroup = "Lights"
    bake()
    assert [g.name for g in bpy.context.scene.radiosity_groups] == ["Lights"]
    calls, one = [], PACKAGE.core.relight
    monkeypatch.setattr(PACKAGE.core, "relight",
                        lambda result, **kw: calls.append(sorted(kw)) or one(result, **kw))
    bulb.data.energy *= 3.0
    assert bpy.ops.radiosity.relight() == {"FINISHED"}
    assert calls == [["emission", "lights"]]
    assert not json.loads(bpy.context.scene.radiosity.last_report)["relight"]["summed"]
    relit = [colours_and_lux(o) for o in objects]
    monkeypatch.setattr(PACKAGE.core, "relight", one)
    assert_close(relit[1], fresh(objects[1])[0])


def test_relight_after_deleting_every_light_is_a_sum_with_the_lights_at_zero(package,
                                                                            fixed_cubes,
                                                                            monkeypatch):
    # Every light deleted is every light's group scaled by 0: a weighted sum of the kept
    # solutions (the lamp's alone, made by the first Relight), no solve. Oracle: a fresh bake of
    # the scene without the lights, within the two solves' tolerance (CULL: the culled share).
    objects, _, lights, baked = lamp_and_two_lights()
    for obj in lights:
        bpy.data.objects.remove(obj)
    calls, many = [], PACKAGE.core.relight_many

    monkeypatch.setattr(PACKAGE.core, "relight", no_solve)
    monkeypatch.setattr(PACKAGE.core, "relight_many",
                        lambda result, changes: calls.append(len(changes)) or many(result,
                                                                                  changes))
    assert bpy.ops.radiosity.relight() == {"FINISHED"}
    assert calls == [3]          # the groups' solutions, made once; then only summed
    assert json.loads(bpy.context.scene.radiosity.last_report)["relight"]["summed"]
    summed = [colours_and_lux(o) for o in objects]
    monkeypatch.setattr(PACKAGE.core, "relight_many", many)
    expected = fresh(*objects)
    assert np.abs(expected[0][1]).max() < 0.9 * np.abs(baked[0][1]).max()   # the lights counted
    assert_near(summed, expected, baked)


def test_unit_factors_are_one_per_group_and_channel_or_none(package):
    same, Unit = PACKAGE.radiosity_addon.same, PACKAGE.radiosity_addon.light_units.Unit
    make = PACKAGE.core.make_lights

    def lights(power=(40.0, 80.0), where=(0.0, 0.0, 1.0)):
        return make([dict(kind="point", name=f"L{i}", position=where, power=p)
                     for i, p in enumerate(power)])

    units = [Unit("a", np.array([0])), Unit("b", np.array([1, 2])), Unit("L0", None, (0,)),
             Unit("World", None, (1,), True)]
    em = np.array([[1.0, 1.0, 1.0], [2.0, 1.0, 0.5], [3.0, 3.0, 3.0], [0.0, 0.0, 0.0]])
    old = (em, None, lights())
    got = same.unit_factors(units, old, (em * [[2, 1, 1], [3, 3, 3], [3, 3, 3], [0, 0, 0]],
                                         None, lights((20.0, 80.0))))
    assert sorted(got) == [0, 1, 2, 3]
    np.testing.assert_allclose([got[k] for k in range(4)],
                               [[2, 1, 1], [3, 3, 3], [0.5, 0.5, 0.5], [1, 1, 1]])
    apart = em.copy()
    apart[2] *= 2.0                                            # b's two materials apart
    assert same.unit_factors(units, old, (apart, None, lights())) is None
    lit = em.copy()
    lit[3] = 1.0                                               # a dark material emits
    assert same.unit_factors(units, old, (lit, None, lights())) is None
    assert same.unit_factors(units, old, (em, None, lights(where=(0.1, 0, 1)))) is None
    assert same.unit_factors(units, old, (em, None, lights((40.0, 60.0)))) is None  # the world
    assert same.unit_factors(units, old, (em, None, None)) is None
    near = same.unit_factors(units, old, (em * (1 + 1e-7), None, lights()))
    assert all(np.array_equal(f, np.ones(3)) for f in near.values())   # unchanged: exactly 1
