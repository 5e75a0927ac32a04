"""The bake operator against real Blender data: values, attribute, modifiers, instances, errors."""

import json
import math
import os
import time

import bpy
import numpy as np
import pytest

from conftest import PACKAGE, ROOT
from helpers import Layout, box, material, mesh_object, read_colours, set_settings, square

core = PACKAGE.core
job = PACKAGE.radiosity_addon.job
write = PACKAGE.radiosity_addon.write

#: Colours go through float32 at the Blender boundary (vertex positions and the attribute), so two
#: routes to the same bake agree to float32 rounding amplified by the solve: 1e-5 relative.
F32_RTOL = 1e-5

CORNELL = os.path.join(ROOT, "sample_blends", "cornell_box.blend")


def bake_ok(**settings):
    """Run radiosity.bake with settings; return the stored report."""
    set_settings(bpy.context.scene, **settings)
    assert bpy.ops.radiosity.bake() == {"FINISHED"}
    return json.loads(bpy.context.scene.radiosity.last_report)


def light_over_floor(floor_size=2.0, height=1.0, radiance=5.0, grid=0):
    """A grey floor (z = 0, normal up) under a square emitter of side 1 facing down."""
    fv, ff = square(floor_size)
    floor = mesh_object("Floor", fv, ff, material("grey", (0.5, 0.5, 0.5)))
    if grid:
        mod = floor.modifiers.new("sub", "SUBSURF")
        mod.subdivision_type = "SIMPLE"
        mod.levels = grid
    lv, lf = square(1.0, z=height, down=True)
    lamp = mesh_object("Lamp", lv, lf, material("lamp", (0.0, 0.0, 0.0), emission=(1, 1, 1),
                                                strength=radiance, kind="emission"))
    return floor, lamp


def test_furnace_gives_le_over_one_minus_rho(package):
    # Closed box, every face emits Le and reflects rho: L = Le / (1 - rho) everywhere (the
    # furnace identity). Tolerance: the solver's 1e-6 tolerance; the hemicube sum rule is exact
    # in a closed box (every pixel sees a wall).
    rho, le = 0.3, 2.0
    v, f = box(1.0)
    obj = mesh_object("Furnace", v, f, material("m", (rho,) * 3, emission=(1, 1, 1), strength=le))
    bake_ok(patch_size=0.5, resolution=16, tolerance=1e-6, solver="JACOBI")
    np.testing.assert_allclose(read_colours(obj.data), le / (1 - rho), rtol=1e-5)


def test_attribute_name_type_domain_size_and_nothing_else(package):
    # Existing Vertices output: colours written on the user's own corners.
    set_settings(bpy.context.scene, output_mode="VERTICES")
    floor, lamp = light_over_floor()
    other = floor.data.color_attributes.new("Col", "BYTE_COLOR", "POINT")
    other.data.foreach_set("color", np.linspace(0, 1, 16, dtype=np.float32))
    uv_name = floor.data.uv_layers.new(name="UVMap").name  # RNA handles go stale: keep names
    before = {a.name: (a.data_type, a.domain) for a in floor.data.attributes}
    col_before = np.empty(16, np.float32)
    other.data.foreach_get("color", col_before)
    bake_ok(patch_size=0.5, resolution=16)
    mesh = floor.data
    attr = mesh.color_attributes["Radiosity"]
    assert (attr.data_type, attr.domain) == ("FLOAT_COLOR", "CORNER")
    assert len(attr.data) == len(mesh.loops)
    assert mesh.color_attributes.active_color_name == "Radiosity"
    assert mesh.color_attributes.render_color_index == mesh.color_attributes.find("Radiosity")
    lux = mesh.attributes["Radiosity Lux"]
    assert (lux.data_type, lux.domain, len(lux.data)) == ("FLOAT", "CORNER", len(mesh.loops))
    ours = ("Radiosity", "Radiosity Lux")
    after = {a.name: (a.data_type, a.domain) for a in mesh.attributes if a.name not in ours}
    assert after == before
    col_after = np.empty(16, np.float32)
    mesh.color_attributes["Col"].data.foreach_get("color", col_after)
    np.testing.assert_array_equal(col_after, col_before)
    assert uv_name in mesh.uv_layers
    # The emitter's own radiance is part of its outgoing radiance (Cycles convention).
    assert read_colours(lamp.data).min() >= 5.0
    # A second bake replaces the attribute instead of adding another.
    bake_ok()
    assert [a.name for a in mesh.color_attributes].count("Radiosity") == 1


def _rotation(rx, ry, rz):
    cx, sx, cy, sy, cz, sz = (math.cos(rx), math.sin(rx), math.cos(ry), math.sin(ry),
                              math.cos(rz), math.sin(rz))
    mx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    my = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    mz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return mz @ my @ mx  # Blender's XYZ Euler


def _room_object():
    """One object: a floor quad, a pentagon wall (n-gon) and an emissive ceiling quad."""
    verts = np.array([[0, 0, 0], [2, 0, 0], [2, 2, 0], [0, 2, 0],            # floor
                      [0, 0, 0], [0, 2, 0], [0, 2, 1], [0, 1, 1.5], [0, 0, 1],  # pentagon wall
                      [0.5, 0.5, 1.25], [0.5, 1.5, 1.25], [1.5, 1.5, 1.25], [1.5, 0.5, 1.25]],
                     dtype=np.float64)
    faces = [(0, 1, 2, 3), (4, 5, 6, 7, 8), (9, 10, 11, 12)]
    obj = mesh_object("Room", verts, faces)
    obj.data.materials.append(material("wall", (0.6, 0.5, 0.4)))
    obj.data.materials.append(material("lamp", (0.2, 0.2, 0.2), emission=(1.0, 0.9, 0.8),
                                       strength=3.0))
    obj.data.polygons[2].material_index = 1
    return obj, verts, faces


def test_values_equal_core_for_same_arrays_with_ngon(package):
    # Existing Vertices output: colours written on the user's own corners.
    set_settings(bpy.context.scene, output_mode="VERTICES")
    # The oracle builds the world-space arrays itself and calls the core directly. Location and
    # scale are exact in float32, so both routes hand the core bit-identical positions and the
    # results must agree to float32 storage of the attribute.
    obj, verts, faces = _room_object()
    obj.location = (0.25, -0.5, 0.125)
    obj.scale = (1.5, 1.5, 1.5)
    report = bake_ok(patch_size=0.4, resolution=32, solver="DIRECT")
    got = read_colours(obj.data)

    world = verts * 1.5 + np.array([0.25, -0.5, 0.125])
    sizes = np.array([4, 5, 4])
    scene = core.make_scene(world, np.concatenate(faces), np.cumsum(sizes) - sizes, sizes,
                            [0, 0, 1], [(0.6, 0.5, 0.4), (0.2, 0.2, 0.2)],
                            [(0, 0, 0), (3.0, 2.7, 2.4)])
    want = core.bake(scene, core.BakeSettings(patch_size=0.4, resolution=32, solver="direct",
                                                       output_mode="vertices"))
    assert report["patches"] == want.report["patches"]
    np.testing.assert_allclose(got, want.corner_colours, rtol=F32_RTOL, atol=1e-6)


def test_extraction_applies_world_transform_and_unit_scale(package):
    # Independent transform (the oracle's own Euler matrix) against what the add-on hands the
    # core. Tolerance 1e-6 m: Blender stores positions and matrices in float32.
    obj, verts, faces = _room_object()
    obj.location = (0.3, -0.2, 0.1)
    obj.rotation_euler = (0.1, 0.2, 0.3)
    obj.scale = (1.5, 1.5, 1.5)
    bpy.context.scene.unit_settings.scale_length = 0.5
    ext = PACKAGE.radiosity_addon.extract.extract(bpy.context.evaluated_depsgraph_get())
    world = 0.5 * ((verts * 1.5) @ _rotation(0.1, 0.2, 0.3).T + np.array([0.3, -0.2, 0.1]))
    np.testing.assert_allclose(ext.arrays["vertices"], world, atol=1e-6)
    np.testing.assert_array_equal(ext.arrays["corner_verts"], np.concatenate(faces))
    np.testing.assert_array_equal(ext.arrays["face_sizes"], [4, 5, 4])
    np.testing.assert_allclose(ext.arrays["emission"][ext.arrays["face_materials"]],
                               [[0, 0, 0], [0, 0, 0], [3.0, 2.7, 2.4]], rtol=1e-6)


def test_cornell_box_through_operator(package):
    bpy.ops.wm.open_mainfile(filepath=CORNELL, load_ui=False)
    report = bake_ok(patch_size=0.2, resolution=16)
    meshes = [o for o in bpy.context.scene.objects if o.type == "MESH"]
    assert len(meshes) == 8 and report["objects"] == 8
    mean = {o.name: read_colours(o.data).mean(axis=0) for o in meshes}
    red, green = mean["Left_Wall"], mean["Right_Wall"]
    # Channel order is RGB: the red wall is red, the green wall green (under a warm light).
    assert red[0] > 3 * red[1] and green[1] > green[0] and green[1] > green[2]
    light = read_colours(bpy.data.objects["Light"].data)
    emitted = np.array(bpy.data.materials["light"].node_tree.nodes["Principled BSDF"]
                       .inputs["Emission Color"].default_value[:3]) * 50.0
    assert np.all(light >= emitted - 1e-4)  # own emission + what the ceiling sends back
    assert report["energy"]["emitted"] > 0 and report["energy"]["absorbed"] > 0
    assert report["notes"] == []  # every material read exactly (no texture or node guesses)


def _corner_keys(obj):
    """World position and face normal of every corner of an object's mesh (its own data)."""
    mesh = obj.data
    mw = np.array(obj.matrix_world)
    co = np.array([v.co for v in mesh.vertices]) @ mw[:3, :3].T + mw[:3, 3]
    cv = np.array([lp.vertex_index for lp in mesh.loops])
    normals = np.array([mesh.polygons[lp_face].normal for lp_face in
                        np.repeat(np.arange(len(mesh.polygons)),
                                  [p.loop_total for p in mesh.polygons])])
    return co[cv], normals


@pytest.mark.parametrize("kind", ["ARRAY", "MIRROR", "SUBSURF_SIMPLE"])
def test_topology_modifiers_write_what_the_user_sees(package, kind):
    # Existing Vertices output: colours written on the user's own corners.
    set_settings(bpy.context.scene, output_mode="VERTICES")
    # Oracle: the same scene with the modifier applied (its evaluated mesh made real), baked
    # again. An original corner must get the colour of the applied mesh's corner at the same
    # position on a face with the same normal (these modifiers keep the original positions).
    # Tolerance: corners are sampled CORNER_INSET of the way into their face, so they may differ
    # from the vertex's value by that fraction of the colour change across the face.
    fv, ff = square(1.0)
    floor = mesh_object("Floor", [(x + 0.5, y, z) for x, y, z in fv], ff,
                        material("grey", (0.5, 0.5, 0.5)))
    lv, lf = square(1.0, z=0.8, down=True)
    mesh_object("Lamp", lv, lf, material("lamp", (0, 0, 0), emission=(1, 1, 1), strength=4.0,
                                         kind="emission"))
    if kind == "ARRAY":
        mod = floor.modifiers.new("m", "ARRAY")
        mod.count = 2
        mod.use_merge_vertices = False
    elif kind == "MIRROR":
        mod = floor.modifiers.new("m", "MIRROR")
        mod.use_bisect_axis[0] = False
        mod.use_mirror_merge = False
    else:
        mod = floor.modifiers.new("m", "SUBSURF")
        mod.subdivision_type = "SIMPLE"
        mod.levels = 2
    bake_ok(patch_size=0.25, resolution=32, solver="DIRECT")
    got = read_colours(floor.data)
    assert got.shape == (4, 3)

    dg = bpy.context.evaluated_depsgraph_get()
    applied = bpy.data.meshes.new_from_object(floor.evaluated_get(dg))
    floor.modifiers.clear()
    floor.data = applied
    bake_ok()
    ref = read_colours(applied)
    ref_pos, ref_n = _corner_keys(floor)
    pos = np.array([[x + 0.5, y, z] for x, y, z in fv])[[0, 1, 2, 3]]
    spread = ref.max() - ref.min()
    # Only corners of faces inside the original face count (copies touch it along its edges).
    face_of = np.repeat(np.arange(len(applied.polygons)),
                        [p.loop_total for p in applied.polygons])
    centre = np.array([p.center for p in applied.polygons])[face_of]
    inside = (centre[:, 0] > 0) & (centre[:, 0] < 1)
    for k in range(4):
        match = np.flatnonzero((np.linalg.norm(ref_pos - pos[k], axis=1) < 1e-6)
                               & (ref_n[:, 2] > 0.9) & inside)
        assert match.size >= 1
        np.testing.assert_allclose(got[k], ref[match].mean(axis=0),
                                   atol=2 * write.CORNER_INSET * spread + 1e-5)


def test_catmull_clark_corners_sample_their_own_face_of_the_limit_surface(package):
    # Catmull-Clark moves every vertex, so no corner of the evaluated mesh sits where an original
    # corner is. Oracle: a field whose value is the evaluated position itself (colour = x, y, z
    # of each evaluated corner). Mapped onto an original corner it must give a point of the
    # evaluated surface on that corner's face (beyond the cube's centre along the face normal)
    # and in that corner's octant (the same signs as the original vertex).
    extract_mod = PACKAGE.radiosity_addon.extract
    v, f = box(0.6, inward=False)
    cube = mesh_object("Cube", v, f)
    cube.modifiers.new("s", "SUBSURF").levels = 2
    cube.location = (1.0, 2.0, 3.0)
    part = extract_mod.extract(bpy.context.evaluated_depsgraph_get()).parts[0]
    assert part.face_starts.size == 96
    field = part.world_vertices[part.corner_verts] - [1.0, 2.0, 3.0]
    layout = extract_mod.read_mesh_layout(cube.data)
    got = write.map_to_original(part, field, layout)
    verts, cv, fs, fz, _ = layout
    normals = np.array([p.normal for p in cube.data.polygons])[np.repeat(np.arange(6), fz)]
    corner = verts[cv]
    assert np.all(np.einsum("ij,ij->i", got, normals) > 0.15)   # limit surface: |x| up to 0.25
    assert np.all(np.sign(got) == np.sign(corner))
    # On the evaluated surface: as far from the centre as the evaluated vertices go, no farther.
    radius = np.linalg.norm(got, axis=1)
    ev_radius = np.linalg.norm(part.world_vertices - [1.0, 2.0, 3.0], axis=1)
    assert ev_radius.min() - 1e-6 <= radius.min() and radius.max() <= ev_radius.max() + 1e-6


def test_instances_light_the_scene_but_receive_nothing(package):
    # Existing Vertices output: colours written on the user's own corners.
    set_settings(bpy.context.scene, output_mode="VERTICES")
    # The floor is a 2 x 2 grid of quads, so it has a vertex at its centre, right under the
    # instanced blocker: from there the whole lamp is hidden (the blocker's shadow cone through
    # the lamp's edges reaches +-0.25 m at the blocker's height, the blocker spans +-0.3 m).
    t = [-1.0, 0.0, 1.0]
    fv = [(x, y, 0.0) for y in t for x in t]
    ff = [(0, 1, 4, 3), (1, 2, 5, 4), (3, 4, 7, 6), (4, 5, 8, 7)]
    floor = mesh_object("Floor", fv, ff, material("grey", (0.5, 0.5, 0.5)))
    lv, lf = square(1.0, z=1.0, down=True)
    mesh_object("Lamp", lv, lf, material("lamp", (0.0, 0.0, 0.0), emission=(1, 1, 1),
                                         strength=5.0, kind="emission"))
    coll = bpy.data.collections.new("Blockers")
    bv, bf = square(0.6, z=0.5)
    blocker_mesh = bpy.data.meshes.new("blocker")
    blocker_mesh.from_pydata(bv, [], bf)
    blocker = bpy.data.objects.new("Blocker", blocker_mesh)
    coll.objects.link(blocker)
    empty = bpy.data.objects.new("Instancer", None)
    empty.instance_type = "COLLECTION"
    empty.instance_collection = coll
    bpy.context.scene.collection.objects.link(empty)
    report = bake_ok(patch_size=0.25, resolution=32, solver="DIRECT")
    shadowed = read_colours(floor.data)
    assert report["instances"] == 1
    assert "Radiosity" not in blocker_mesh.color_attributes

    bpy.data.objects.remove(empty)
    bake_ok()
    lit = read_colours(floor.data)
    centre = np.array([floor.data.loops[i].vertex_index == 4 for i in range(len(floor.data.loops))])
    assert centre.sum() == 4
    # In the umbra only indirect light is left: far darker than in the open.
    assert np.all(shadowed[centre] < 0.5 * lit[centre])
    # The floor's outer corners see the whole lamp past the blocker either way.
    np.testing.assert_allclose(shadowed[~centre], lit[~centre], rtol=0.05)


def test_geometry_nodes_instances_take_part(package):
    floor, lamp = light_over_floor()
    host = mesh_object("Host", *square(0.01, z=0.5))
    tree = bpy.data.node_groups.new("inst", "GeometryNodeTree")
    tree.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    tree.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    gin, gout = tree.nodes.new("NodeGroupInput"), tree.nodes.new("NodeGroupOutput")
    grid = tree.nodes.new("GeometryNodeMeshGrid")
    grid.inputs["Size X"].default_value = 0.6
    grid.inputs["Size Y"].default_value = 0.6
    inst = tree.nodes.new("GeometryNodeInstanceOnPoints")
    point = tree.nodes.new("GeometryNodePoints")
    join = tree.nodes.new("GeometryNodeJoinGeometry")
    tree.links.new(point.outputs[0], inst.inputs["Points"])
    tree.links.new(grid.outputs[0], inst.inputs["Instance"])
    tree.links.new(gin.outputs[0], join.inputs[0])
    tree.links.new(inst.outputs[0], join.inputs[0])
    tree.links.new(join.outputs[0], gout.inputs[0])
    mod = host.modifiers.new("gn", "NODES")
    mod.node_group = tree
    report = bake_ok(patch_size=0.25, resolution=32, solver="DIRECT")
    assert report["instances"] >= 1
    assert "Radiosity" in host.data.color_attributes


def test_shared_mesh_stops_or_gets_single_user(package):
    # Existing Vertices output: colours written on the user's own corners.
    set_settings(bpy.context.scene, output_mode="VERTICES")
    floor, lamp = light_over_floor()
    twin = bpy.data.objects.new("Twin", floor.data)
    twin.location = (3.0, 0.0, 0.0)
    bpy.context.scene.collection.objects.link(twin)
    set_settings(bpy.context.scene, patch_size=0.5, resolution=16)
    with pytest.raises(RuntimeError, match="shared by 2 objects"):
        bpy.ops.radiosity.bake()
    assert "Radiosity" not in floor.data.color_attributes
    report = bake_ok(make_single_user=True)
    assert floor.data is not twin.data
    near, far = read_colours(floor.data), read_colours(twin.data)
    assert near.mean() > 2 * far.mean() and report["objects"] == 3


def test_missing_material_uses_documented_grey_and_warns(package):
    # Existing Vertices output: colours written on the user's own corners.
    set_settings(bpy.context.scene, output_mode="VERTICES")
    floor, lamp = light_over_floor()
    report = bake_ok(patch_size=0.5, resolution=16, solver="DIRECT")
    with_grey = read_colours(floor.data)
    floor.data.materials.clear()
    report = bake_ok()
    assert any("No material on 'Floor'" in w and "0.8" in w for w in report["warnings"])
    # The default reflectance is 0.8: the floor's reflected light scales by 0.8 / 0.5 (the
    # floor receives only direct light from the lamp, which has no reflectance).
    np.testing.assert_allclose(read_colours(floor.data), with_grey * 0.8 / 0.5, rtol=1e-5)


def test_no_light_and_no_meshes_are_clear_errors(package):
    with pytest.raises(RuntimeError, match="Nothing to bake"):
        bpy.ops.radiosity.bake()
    mesh_object("Floor", *square(1.0), material("grey"))
    point = bpy.data.objects.new("Bulb", bpy.data.lights.new("Bulb", "POINT"))
    point.data.energy = 0.0          # a light of power 0 is no light
    bpy.context.scene.collection.objects.link(point)
    with pytest.raises(RuntimeError, match="No light"):
        bpy.ops.radiosity.bake()


def test_unsupported_lights_world_and_non_mesh_objects_are_named(package):
    floor, lamp = light_over_floor()
    for name, kind in (("Bulb", "POINT"), ("Oval", "SPOT")):
        obj = bpy.data.objects.new(name, bpy.data.lights.new(name, kind))
        bpy.context.scene.collection.objects.link(obj)
    obj.scale = (1.0, 2.0, 1.0)      # an elliptic cone: read as a round one, with a warning
    curve = bpy.data.curves.new("Txt", "FONT")
    bpy.context.scene.collection.objects.link(bpy.data.objects.new("Label", curve))
    bpy.context.scene.collection.objects.link(bpy.data.objects.new("Empty", None))
    world = bpy.data.worlds.new("Sky")        # a textured world: baked from a rendered map
    if bpy.app.version < (5, 0, 0):
        world.use_nodes = True
    nodes = world.node_tree.nodes
    sky = nodes.new("ShaderNodeTexSky")
    world.node_tree.links.new(sky.outputs["Color"], nodes["Background"].inputs["Color"])
    bpy.context.scene.world = world
    report = bake_ok(patch_size=0.5, resolution=16)
    text = " | ".join(report["warnings"])
    assert "'Bulb'" not in text       # point lights are baked (tests/addon/test_lights.py)
    assert "non-uniform scale" in text and "'Oval'" in text
    assert "'Label'" in text and "World" not in text
    notes = " | ".join(report["notes"])
    assert "World 'Sky' (Background) is lit from a 64 x 32 map rendered by Cycles" in notes


def test_area_lights_match_an_emitting_polygon_of_the_converted_radiance(package):
    # An area light of power P over area A must light the floor like an emissive polygon of
    # radiance P / (pi A) facing down (the conversion measured against Cycles in
    # test_lights.py). Both bakes use the same settings; the area light is one-sided (black
    # back), the polygon two-sided, and the floor cannot see either's back. Tolerance 1 %: the
    # polygon's back lights the floor's back too, and the two emitters are patched differently.
    floor = mesh_object("Floor", *square(2.0), material("grey", (0.5, 0.5, 0.5)))
    lamp = bpy.data.lights.new("Panel", "AREA")
    lamp.shape, lamp.size, lamp.size_y, lamp.energy = "RECTANGLE", 1.0, 0.5, 40.0
    lamp_obj = bpy.data.objects.new("Panel", lamp)
    lamp_obj.location = (0.0, 0.0, 1.0)
    bpy.context.scene.collection.objects.link(lamp_obj)
    # The exact method: no occluder here, so its form factors carry no sampling noise and the
    # comparison measures the light conversion alone (a rotated hemicube's aliasing differs
    # between the two emitters' patchings by ~2 % per corner).
    report = bake_ok(patch_size=0.25, method="EXACT", solver="DIRECT")
    assert report["area_lights"] == 1
    ext = PACKAGE.radiosity_addon.extract.extract(bpy.context.evaluated_depsgraph_get())
    assert ext.arrays["material_names"] == ("grey", "light: Panel")
    np.testing.assert_array_equal(ext.arrays["back_emission"][1], 0.0)
    np.testing.assert_array_equal(ext.arrays["back_reflectance"][1], 0.0)
    np.testing.assert_array_equal(ext.arrays["reflectance"][1], 0.0)
    from_light = read_colours(floor.data)

    bpy.data.objects.remove(lamp_obj)
    radiance = 40.0 / (math.pi * 0.5)
    mesh_object("Emitter", [(-0.5, -0.25, 1), (0.5, -0.25, 1), (0.5, 0.25, 1), (-0.5, 0.25, 1)],
                [(0, 3, 2, 1)], material("e", (0, 0, 0), emission=(1, 1, 1), strength=radiance,
                                         kind="emission"))
    bake_ok(patch_size=0.25, method="EXACT", solver="DIRECT")
    np.testing.assert_allclose(from_light, read_colours(floor.data), rtol=0.01)


def test_disk_light_polygon_keeps_area_and_faces_down(package):
    materials = PACKAGE.radiosity_addon.materials
    lamp = bpy.data.lights.new("Disk", "AREA")
    lamp.shape, lamp.size, lamp.size_y = "ELLIPSE", 1.0, 0.4
    pts, area = materials.area_light_polygon(lamp)
    p = pts - pts.mean(axis=0)
    newell = 0.5 * np.cross(p, np.roll(p, -1, axis=0)).sum(axis=0)
    assert area == pytest.approx(math.pi * 0.5 * 0.2)
    assert newell[2] == pytest.approx(-area, rel=1e-12)  # same area, normal -Z
    np.testing.assert_allclose(newell[:2], 0.0, atol=1e-15)


def test_unit_scale_sets_patch_size_in_metres(package):
    # Lengths in the panel are in scene units, shown (and baked) times the unit scale: with
    # 1 unit = 2 m, the faces are 2 m across and a patch size of 0.5 units is 1 m.
    v, f = box(1.0)
    mesh_object("Furnace", v, f, material("m", (0.5,) * 3, emission=(1, 1, 1)))
    assert bake_ok(patch_size=0.5, resolution=8)["patches"] == 6 * 4
    bpy.context.scene.unit_settings.scale_length = 2.0
    report = bake_ok()
    assert report["patches"] == 6 * 4
    assert report["settings"]["patch_size"] == pytest.approx(1.0)
    assert bake_ok(patch_size=0.25)["patches"] == 6 * 16


def test_image_texture_colour_is_averaged_and_reported(package):
    mat = material("tex", (0.1, 0.1, 0.1))
    img = bpy.data.images.new("checker", 2, 2, float_buffer=True)
    pixels = np.array([[0.2, 0.4, 0.6, 1], [0.4, 0.4, 0.2, 1],
                       [0.6, 0.0, 0.4, 1], [0.0, 0.4, 0.2, 1]], dtype=np.float32)
    img.pixels.foreach_set(pixels.ravel())
    tex = mat.node_tree.nodes.new("ShaderNodeTexImage")
    tex.image = img
    mat.node_tree.links.new(tex.outputs["Color"],
                            mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"])
    reader = PACKAGE.radiosity_addon.materials.MaterialReader()
    rho, le = reader.evaluate(mat)
    np.testing.assert_allclose(rho, pixels[:, :3].mean(axis=0), rtol=1e-6)
    assert any("mean colour of image 'checker'" in n for n in reader.notes)


def _snapshot():
    """Everything a bake may change: meshes, their attributes and values, object data links."""
    state = {}
    for obj in bpy.data.objects:
        state[obj.name] = obj.data.name if obj.data else None
    for mesh in bpy.data.meshes:
        attrs = {}
        for a in mesh.color_attributes:
            buf = np.empty(len(a.data) * 4, np.float32)
            a.data.foreach_get("color", buf)
            attrs[a.name] = buf.tobytes()
        state["mesh:" + mesh.name] = (attrs, mesh.color_attributes.active_color_name)
    state["report"] = bpy.context.scene.radiosity.last_report
    return state


def test_one_undo_step_restores_the_scene(package):
    floor, lamp = light_over_floor()
    twin = bpy.data.objects.new("Twin", floor.data)
    bpy.context.scene.collection.objects.link(twin)
    set_settings(bpy.context.scene, patch_size=0.5, resolution=16, make_single_user=True)
    bpy.ops.ed.undo_push(message="settings")
    before = _snapshot()
    # As a click in the UI does: run with an undo push (scripts' bpy.ops calls skip it).
    assert bpy.ops.radiosity.bake("EXEC_DEFAULT", True) == {"FINISHED"}
    assert _snapshot() != before and floor.data is not twin.data
    bpy.ops.ed.undo()
    assert _snapshot() == before
    assert bpy.data.objects["Floor"].data == bpy.data.objects["Twin"].data


def test_cancel_stops_within_a_second_and_changes_nothing(package):
    floor, lamp = light_over_floor(floor_size=4.0)
    set_settings(bpy.context.scene, patch_size=0.05, resolution=64)
    before = _snapshot()
    ctx = bpy.context
    bake_input = job.prepare(ctx, job.options_from_props(ctx.scene.radiosity))
    work = job.BakeJob(bake_input).start()
    time.sleep(0.3)
    assert not work.done(), "the bake must still be running for this test to mean anything"
    t0 = time.perf_counter()
    work.cancel()
    assert work.join(timeout=1.0), "worker did not stop within a second"
    assert time.perf_counter() - t0 < 1.0
    assert isinstance(work.error, core.BakeCancelled) and work.result is None
    assert _snapshot() == before


def test_worker_result_applies_on_main_thread(package):
    floor, lamp = light_over_floor()
    set_settings(bpy.context.scene, patch_size=0.5, resolution=16, solver="DIRECT")
    ctx = bpy.context
    bake_input = job.prepare(ctx, job.options_from_props(ctx.scene.radiosity))
    work = job.BakeJob(bake_input).start()
    assert work.join(timeout=30)
    assert work.error is None and work.fraction == pytest.approx(1.0)
    job.apply(ctx, bake_input, work.result)
    sync = read_colours(floor.data)
    bake_ok()
    np.testing.assert_array_equal(read_colours(floor.data), sync)


def test_clear_removes_only_our_attribute_and_viewport_shows_it(package):
    floor, lamp = light_over_floor()
    floor.data.color_attributes.new("Paint", "FLOAT_COLOR", "CORNER")
    bake_ok(patch_size=0.5, resolution=16)
    spaces = [s for w in bpy.context.window_manager.windows for a in w.screen.areas
              if a.type == "VIEW_3D" for s in a.spaces if s.type == "VIEW_3D"]
    assert all(s.shading.color_type == "VERTEX" for s in spaces)
    assert bpy.ops.radiosity.clear() == {"FINISHED"}
    assert "Radiosity" not in floor.data.color_attributes
    assert "Paint" in floor.data.color_attributes
    assert bpy.context.scene.radiosity.last_report == ""


def test_bad_setting_and_edit_mode_are_reported(package):
    light_over_floor()
    # The panel holds what the core's settings table allows (one range): an odd resolution
    # becomes the next even one, a tolerance of 0 (the range is open) is refused by the core,
    # by name, before any work.
    set_settings(bpy.context.scene, resolution=33)
    assert bpy.context.scene.radiosity.resolution == 34
    set_settings(bpy.context.scene, resolution=2047)
    assert bpy.context.scene.radiosity.resolution == 2048        # the hemicube's largest
    set_settings(bpy.context.scene, tolerance=0.0)
    with pytest.raises(RuntimeError, match="tolerance must be a number in"):
        bpy.ops.radiosity.bake()


def test_panel_properties_are_the_settings_table(package):
    # Every exposed row of core.settings is a property with the row's label, default and
    # bounds; enums keep upper-case identifiers that map back to the core's values.
    settings = PACKAGE.core.settings
    job = PACKAGE.radiosity_addon.job
    rna = bpy.types.Scene.bl_rna.properties["radiosity"].fixed_type.properties
    for name in settings.EXPOSED:
        row = settings.BY_NAME[name]
        prop = rna[name]
        assert prop.name == row.label
        if row.type == "choice":
            assert prop.default.lower() == row.default
            assert [i.identifier.lower() for i in prop.enum_items] == list(row.values())
        elif row.auto and row.default is None:     # "auto" is 0 in the panel
            assert prop.default == 0
        else:
            assert prop.default == pytest.approx(row.default)
        if row.type in ("int", "float") and row.low is not None:
            assert prop.hard_min == pytest.approx(row.low)
        if row.type in ("int", "float") and row.high is not None:
            assert prop.hard_max == pytest.approx(row.high)
    options = job.options_from_props(bpy.context.scene.radiosity)
    defaults = settings.BakeSettings()
    for name in settings.EXPOSED:      # float32 in Blender: 1e-4 comes back as 9.99999974e-05
        want = getattr(defaults, name)
        # An auto length (0 in the panel) goes to the core as None and resolves there, as in
        # a bake (min_element: core.adaptive.min_element_size, in metres whatever the units).
        got = getattr(settings.BakeSettings(**{name: options[name]}), name)
        if isinstance(want, str) or want is None:
            assert got == want, name
        else:
            assert got == pytest.approx(want, rel=1e-6), name


def _draw_panels():
    """Everything the panel and its sub-panels draw: [(kind, args, kwargs)]."""
    log = []
    panels = PACKAGE.radiosity_addon.panels
    for cls in panels.CLASSES:
        if hasattr(cls, "poll") and not cls.poll(bpy.context):
            continue
        cls.draw(type("P", (), {"layout": Layout(log)})(), bpy.context)
    return log


def test_panel_draws_every_setting_the_button_and_the_summary(package):
    light_over_floor()
    before = _draw_panels()
    drawn = [a[1] for kind, a, _ in before if kind == "prop"]
    # Before any bake there is nothing to show: no Show toggle that claims a bake is shown.
    assert "show_bake" not in drawn and "exposure" not in drawn
    bake_ok(patch_size=0.5, resolution=16)
    log = _draw_panels()
    drawn = [a[1] for kind, a, _ in log if kind == "prop"]
    settings = [p.identifier for p in bpy.context.scene.radiosity.bl_rna.properties
                if p.identifier not in ("rna_type", "name", "last_report", "show_bake")]
    for name in settings + ["show_bake", "exposure"]:
        assert name in drawn, name
    # Quality settings come first, the advanced ones after the bake button (folded sub-panel).
    order = [a[1] if kind == "prop" else a[0] for kind, a, _ in log if kind in ("prop", "operator")]
    assert order.index("output_mode") == 0 and order.index("patch_size") == 1
    assert order.index("radiosity.bake") < order.index("solver")
    assert bpy.context.window_manager.radiosity_show_advanced is False  # folded by default
    labels = [k.get("text", "") for kind, a, k in log if kind == "label"]
    total = [i for i, t in enumerate(labels) if t.startswith("Total: ")]
    patches = [i for i, t in enumerate(labels) if t.startswith("Patches: ")]
    assert total and patches and total[0] < patches[0]
    assert any(t.startswith("Form factors: ") for t in labels)
    assert not any(t.startswith(("form_factors", "read_scene", "total")) for t in labels)


def test_summary_lines_put_the_total_first_with_human_labels():
    report = {"patches": 12, "iterations": 3, "residual": 1e-5, "warnings": ["w"],
              "timings": {"patches": 0.5, "total": 2.0, "form_factors": 1.0, "n_rays": 9,
                          "solve": 0.25, "read_scene": 0.125, "mystery_stage": 0.0625}}
    lines = [t for t, _ in PACKAGE.radiosity_addon.panels.summary_lines(json.dumps(report))]
    assert lines[0] == "Total: 2.00 s"
    assert lines.index("Read scene: 0.12 s") < lines.index("Make patches: 0.50 s") \
        < lines.index("Form factors: 1.00 s") < lines.index("Solve: 0.25 s")
    assert "Mystery stage: 0.06 s" in lines and lines[-1] == "w"
    assert not any("n_rays" in t or "9" == t[-1] for t in lines)
    assert PACKAGE.radiosity_addon.panels.summary_lines("not json") == []


def test_summary_lines_give_the_workers_and_the_peak_memory():
    report = {"patches": 12, "timings": {"total": 2.0},
              "workers": {"processes": 2, "shared_calls": 40, "peak_mb": 180.4},
              "peak_mb": {"patches": 120.0, "form_factors": 610.6, "colours": 300.0}}
    lines = [t for t, _ in PACKAGE.radiosity_addon.panels.summary_lines(json.dumps(report))]
    assert "Workers: 2 processes" in lines
    assert "Peak memory: 611 MB, workers up to 180 MB" in lines
    del report["workers"]
    lines = [t for t, _ in PACKAGE.radiosity_addon.panels.summary_lines(json.dumps(report))]
    assert "Peak memory: 611 MB" in lines and not any(t.startswith("Workers") for t in lines)


class _Event:
    """What the modal handler reads of a bpy.types.Event: type and value, nothing more (no
    'timer': Event has none in 4.2 to 5.0)."""

    __slots__ = ("type", "value")

    def __init__(self, type_, value="NOTHING"):
        self.type, self.value = type_, value


class _Operator:
    """Stands in for the operator instance (the bpy module never runs a modal operator)."""

    def __init__(self, cls=None):
        self.reports = []
        self.cls = cls or PACKAGE.radiosity_addon.operators.RADIOSITY_OT_bake
        self.bl_label, self.failed = self.cls.bl_label, self.cls.failed
        for name in ("_step", "_finish", "_finish_job", "_done", "_ended", "_start",
                     "_continue", "_groups_made"):
            if hasattr(self.cls, name):              # its helpers, bound to the stand-in
                setattr(self, name, getattr(self.cls, name).__get__(self))

    def report(self, kind, text):
        self.reports.append((set(kind), text))


def _start_modal():
    ops = PACKAGE.radiosity_addon.operators
    ctx = bpy.context
    bake_input = job.prepare(ctx, job.options_from_props(ctx.scene.radiosity))
    ops._Running.job = ops.panel_job(ctx, bake_input).start()      # as invoke starts it
    return ops


def test_modal_timer_ticks_drive_the_bake_to_its_end(package):
    floor, lamp = light_over_floor()
    set_settings(bpy.context.scene, patch_size=0.5, resolution=16)
    ops = _start_modal()
    assert ops.RADIOSITY_OT_bake.running() and not ops.RADIOSITY_OT_bake.poll(bpy.context)
    me = _Operator()
    result, _ = drive(me, 60.0)
    assert result == {"FINISHED"}, me.reports
    assert "Radiosity" in floor.data.color_attributes
    assert not ops.RADIOSITY_OT_bake.running() and ops.RADIOSITY_OT_bake.poll(bpy.context)
    assert any(t.startswith("Radiosity baked: ") for _, t in me.reports)


def test_modal_escape_cancels_and_changes_nothing(package):
    light_over_floor(floor_size=4.0)
    set_settings(bpy.context.scene, patch_size=0.05, resolution=64)
    before = _snapshot()
    ops = _start_modal()
    me = _Operator()
    assert _modal(me, _Event("ESC", "PRESS")) == {"RUNNING_MODAL"}
    t0 = time.perf_counter()
    result, _ = drive(me, 5.0)
    assert result == {"CANCELLED"} and time.perf_counter() - t0 < 1.0
    assert not ops.RADIOSITY_OT_bake.running()
    assert _snapshot() == before
    assert any("cancelled" in t for _, t in me.reports)


def test_unregister_mid_bake_stops_the_worker(package):
    light_over_floor(floor_size=4.0)
    set_settings(bpy.context.scene, patch_size=0.05, resolution=64)
    ops = _start_modal()
    work = ops._Running.job
    PACKAGE.unregister()
    try:
        assert work.done() and work.cancelled and not ops.RADIOSITY_OT_bake.running()
    finally:
        PACKAGE.register()


def drive(me=None, seconds=120.0):
    """Tick the modal job that _start_modal (or a Relight's invoke) started until it ends (or
    ``seconds`` pass): (its last result, the reports of ``me``, the stand-in operator)."""
    me, t0, result = me or _Operator(), time.perf_counter(), None
    while time.perf_counter() - t0 < seconds:
        result = _modal(me, _Event("TIMER"))
        if result not in ({"PASS_THROUGH"}, {"RUNNING_MODAL"}):   # (a next worker: on)
            break
        time.sleep(0.02)
    return result, me.reports


def _modal(me, event):
    """Call the operator's modal with a stand-in instance (its helpers bound to it)."""
    return me.cls.modal(me, bpy.context, event)


def test_summary_lines_say_what_the_mesh_output_wrote():
    # The radiosity mesh output: the user's faces and what they became, summed over objects.
    report = {"patches": 5, "iterations": 1, "timings": {"total": 1.0},
              "output_objects": [dict(object="Floor", input_faces=1, output_vertices=200,
                                      output_faces=276),
                                 dict(object="Wall", input_faces=2, output_vertices=21,
                                      output_faces=24)]}
    lines = [t for t, _ in PACKAGE.radiosity_addon.panels.summary_lines(json.dumps(report))]
    assert "Mesh: 3 faces -> 300 (221 vertices)" in lines
    del report["output_objects"]           # Existing Vertices: nothing about a mesh
    lines = [t for t, _ in PACKAGE.radiosity_addon.panels.summary_lines(json.dumps(report))]
    assert not any(t.startswith("Mesh:") for t in lines)
