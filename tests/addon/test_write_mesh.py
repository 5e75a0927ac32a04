"""The baked mesh output: identity kept, conforming, Clear Bake exact, UVs, re-bake, failures.

The core's radiosity mesh is stood in for by a hand-built OutputMesh (tests/addon/outmesh_fake.py:
every scene quad split into 2 x 2, weights written down by hand), so these tests check the writer
alone against oracles that do not come from it.
"""

import bpy
import numpy as np
import pytest

from conftest import PACKAGE
from helpers import box, material, mesh_object, read_colours, set_settings, square
from outmesh_fake import smooth_colour, split_output

job = PACKAGE.radiosity_addon.job
write = PACKAGE.radiosity_addon.write
extract_mod = PACKAGE.radiosity_addon.extract

#: Positions, UVs and colours pass through float32 at the Blender boundary.
F32_ATOL = 1e-5


def lamp():
    lv, lf = square(1.0, z=3.0, down=True)
    return mesh_object("Lamp", lv, lf, material("lamp", (0, 0, 0), emission=(1, 1, 1),
                                                strength=5.0, kind="emission"))


def extraction():
    return extract_mod.extract(bpy.context.evaluated_depsgraph_get())


def bake_fake(colour=smooth_colour):
    """Extract the scene, build the 2 x 2 output, write it; returns (extraction, output)."""
    ext = extraction()
    out = split_output(ext.arrays, colour)
    write.write_mesh({o.name: o for o in bpy.context.scene.objects}, ext.parts, out)
    return ext, out


def snapshot(mesh):
    """Every array of a mesh (geometry, UVs, attributes) through foreach_get, and its names."""
    snap = {}

    def grab(key, coll, prop, n, dtype, width=1):
        buf = np.empty(n * width, dtype=dtype)
        coll.foreach_get(prop, buf)
        snap[key] = buf

    grab("co", mesh.vertices, "co", len(mesh.vertices), np.float32, 3)
    grab("loop_v", mesh.loops, "vertex_index", len(mesh.loops), np.int32)
    grab("loop_e", mesh.loops, "edge_index", len(mesh.loops), np.int32)
    grab("edge_v", mesh.edges, "vertices", len(mesh.edges), np.int32, 2)
    grab("start", mesh.polygons, "loop_start", len(mesh.polygons), np.int32)
    grab("total", mesh.polygons, "loop_total", len(mesh.polygons), np.int32)
    grab("mat", mesh.polygons, "material_index", len(mesh.polygons), np.int32)
    grab("smooth", mesh.polygons, "use_smooth", len(mesh.polygons), bool)
    for layer in mesh.uv_layers:
        grab(f"uv:{layer.name}", layer.uv, "vector", len(mesh.loops), np.float32, 2)
    for attr in mesh.attributes:
        prop = {"FLOAT_COLOR": "color", "BYTE_COLOR": "color", "FLOAT_VECTOR": "vector",
                "FLOAT2": "vector", "FLOAT": "value", "INT": "value",
                "BOOLEAN": "value"}.get(attr.data_type)
        if prop is None or attr.name.startswith("."):
            continue
        width = {"color": 4, "vector": 3 if attr.data_type == "FLOAT_VECTOR" else 2}.get(prop, 1)
        dtype = bool if attr.data_type == "BOOLEAN" else (
            np.int32 if attr.data_type == "INT" else np.float32)
        grab(f"attr:{attr.name}:{attr.domain}", attr.data, prop, len(attr.data), dtype, width)
    snap["names"] = (mesh.name, tuple(m.name if m else None for m in mesh.materials),
                     tuple(mesh.keys()), mesh.uv_layers.active.name if mesh.uv_layers.active
                     else None, mesh.color_attributes.active_color_name)
    return snap


def assert_same(a, b):
    assert a.keys() == b.keys()
    for key in a:
        if key == "names":
            assert a[key] == b[key]
        else:
            np.testing.assert_array_equal(a[key], b[key], err_msg=key)


def user_props(obj):
    return {k: obj[k] for k in obj.keys() if not k.startswith("radiosity")}


def edge_face_counts(mesh):
    """Number of faces using every edge of *mesh*."""
    loop_e = np.empty(len(mesh.loops), dtype=np.int32)
    mesh.loops.foreach_get("edge_index", loop_e)
    return np.bincount(loop_e, minlength=len(mesh.edges))


# ------------------------------------------------------------------------------------- identity


def test_object_identity_kept_and_the_mesh_holds_the_output(package):
    lamp()
    coll = bpy.data.collections.new("Rooms")
    bpy.context.scene.collection.children.link(coll)
    parent = bpy.data.objects.new("Parent", None)
    bpy.context.scene.collection.objects.link(parent)
    parent.location = (0.5, 0.0, 0.0)
    v, f = box(1.0, inward=False)
    obj = mesh_object("Block", v, f, material("red", (0.8, 0.1, 0.1)))
    obj.data.materials.append(material("blue", (0.1, 0.1, 0.8)))
    obj.data.polygons[2].material_index = 1
    obj.data.polygons[3].use_smooth = True
    coll.objects.link(obj)
    obj.parent = parent
    obj.location = (0.2, 0.3, 0.4)
    obj.rotation_euler = (0.1, 0.2, 0.3)
    obj["client"] = "ACME"
    obj.keyframe_insert("location", frame=1)
    bpy.context.view_layer.update()
    before = dict(name=obj.name, matrix=np.array(obj.matrix_world), parent=obj.parent,
                  colls={c.name for c in obj.users_collection}, props=user_props(obj),
                  slots=[s.material for s in obj.material_slots],
                  action=obj.animation_data.action)
    original = obj.data
    ext, out = bake_fake()

    assert obj.name == before["name"] and obj.parent == before["parent"]
    np.testing.assert_allclose(np.array(obj.matrix_world), before["matrix"], atol=1e-7)
    assert {c.name for c in obj.users_collection} == before["colls"]
    assert user_props(obj) == before["props"]
    assert [s.material for s in obj.material_slots] == before["slots"]
    assert obj.animation_data.action == before["action"]
    mesh = obj.data
    assert mesh != original and original.use_fake_user and obj[write.PROP_ORIGINAL] == original
    assert len(mesh.polygons) == 4 * len(original.polygons)
    attrs = mesh.color_attributes
    assert attrs.active_color_name == write.ATTRIBUTE
    assert attrs.render_color_index == attrs.find(write.ATTRIBUTE)
    assert attrs[write.ATTRIBUTE].data_type == "FLOAT_COLOR"
    assert attrs[write.ATTRIBUTE].domain == "CORNER"
    # Every baked face lies in its parent: material and shading of the parent, centroid inside.
    mats = np.array([p.material_index for p in mesh.polygons])
    smooth = np.array([p.use_smooth for p in mesh.polygons])
    centres = np.array([p.center for p in mesh.polygons])
    parent_of = np.array([int(np.argmin([np.linalg.norm(np.cross(c - q.center, q.normal))
                                         + 10 * abs(np.dot(c - q.center, q.normal))
                                         for q in original.polygons])) for c in centres])
    assert np.array_equal(mats, [original.polygons[i].material_index for i in parent_of])
    assert np.array_equal(smooth, [original.polygons[i].use_smooth for i in parent_of])
    # Colours: the oracle function at each corner's world position (object space -> world).
    co = np.array([v.co for v in mesh.vertices])
    cv = np.array([lp.vertex_index for lp in mesh.loops])
    world = co[cv] @ np.array(obj.matrix_world)[:3, :3].T + np.array(obj.matrix_world)[:3, 3]
    np.testing.assert_allclose(read_colours(mesh), smooth_colour(world), atol=F32_ATOL)


def test_apply_dispatches_on_result_output(package):
    # Through job.prepare / compute / apply: with result.output the object gets a baked mesh and
    # the report lists input faces -> output vertices and faces; without it, today's colours.
    lamp()
    fv, ff = square(2.0)
    floor = mesh_object("Floor", fv, ff, material("grey"))
    opts = job.options_from_props(bpy.context.scene.radiosity)
    opts.update(patch_size=1.0, resolution=16)
    bake_input = job.prepare(bpy.context, opts)
    result = job.compute(bake_input)
    result.output = split_output(bake_input.extraction.arrays)
    report = job.apply(bpy.context, bake_input, result)
    assert write.is_baked(floor) and len(floor.data.polygons) == 4
    row = [r for r in report["output_objects"] if r["object"] == "Floor"][0]
    assert row == dict(object="Floor", input_faces=1, output_vertices=9, output_faces=4)
    # Existing Vertices over a baked object: the bake is cleared, the colours go on the original.
    result.output = None
    job.apply(bpy.context, bake_input, result)
    assert not write.is_baked(floor) and len(floor.data.polygons) == 1
    assert not any(m.get(write.PROP_BAKED) for m in bpy.data.meshes)
    assert write.ATTRIBUTE in floor.data.color_attributes


# ----------------------------------------------------------------------------------- conformity


def test_closed_box_stays_closed(package):
    # A closed cube is conforming; its 2 x 2 output must be too: every edge used by exactly two
    # faces (no crack, no T-junction), 6 * 4 faces, 26 vertices (8 + 12 + 6).
    lamp()
    v, f = box(1.0)
    obj = mesh_object("Room", v, f, material("grey"))
    bake_fake()
    mesh = obj.data
    assert len(mesh.polygons) == 24 and len(mesh.vertices) == 26
    assert np.all(edge_face_counts(mesh) == 2)


# ----------------------------------------------------------------------------------- Clear Bake


def modified_plane():
    """A 2-quad plane with a UV map, a generic attribute, a Simple subdivision (viewport on) and
    a render-only Bevel (viewport off)."""
    verts = [(0, 0, 0), (1, 0, 0), (2, 0, 0), (0, 1, 0), (1, 1, 0), (2, 1, 0)]
    obj = mesh_object("Plane", verts, [(0, 1, 4, 3), (1, 2, 5, 4)], material("grey"))
    uv = obj.data.uv_layers.new(name="Tiles")
    rng = np.random.default_rng(3)
    uv.uv.foreach_set("vector", rng.random(16).astype(np.float32))
    attr = obj.data.attributes.new("weight", "FLOAT", "POINT")
    attr.data.foreach_set("value", np.arange(6, dtype=np.float32))
    sub = obj.modifiers.new("Grid", "SUBSURF")
    sub.subdivision_type = "SIMPLE"
    sub.levels = 1
    bevel = obj.modifiers.new("Round", "BEVEL")
    bevel.show_viewport = False
    return obj


def test_clear_bake_restores_the_original_bit_for_bit(package):
    lamp()
    obj = modified_plane()
    original = obj.data
    before = snapshot(original)
    bake_fake()
    assert obj.data != original and len(obj.data.polygons) == 2 * 4 * 4
    assert not obj.modifiers["Grid"].show_viewport and not obj.modifiers["Grid"].show_render
    assert not obj.modifiers["Round"].show_viewport and obj.modifiers["Round"].show_render
    baked_name = obj.data.name
    set_settings(bpy.context.scene, selected_only=False)
    assert bpy.ops.radiosity.clear() == {"FINISHED"}
    assert obj.data == original and original.as_pointer() == obj.data.as_pointer()
    assert not original.use_fake_user
    assert_same(snapshot(obj.data), before)
    assert obj.modifiers["Grid"].show_viewport and obj.modifiers["Grid"].show_render
    assert not obj.modifiers["Round"].show_viewport and obj.modifiers["Round"].show_render
    assert baked_name not in bpy.data.meshes
    assert not any(k.startswith("radiosity") for k in obj.keys())


def test_clear_bake_keeps_a_fake_user_the_user_had(package):
    lamp()
    fv, ff = square(2.0)
    obj = mesh_object("Floor", fv, ff, material("grey"))
    obj.data.use_fake_user = True
    bake_fake()
    write.clear_bake([obj])
    assert obj.data.use_fake_user


def test_user_attributes_are_carried(package):
    # Oracles: a point attribute linear in position (interpolation reproduces it exactly at
    # every baked vertex), a face attribute (each baked face carries its parent's value, found
    # from the face centre), a corner colour attribute set to the corner's position (colour =
    # x, y, 0.5 at each baked corner).
    lamp()
    verts = [(0, 0, 0), (1, 0, 0), (2, 0, 0), (0, 1, 0), (1, 1, 0), (2, 1, 0)]
    obj = mesh_object("Plane", verts, [(0, 1, 4, 3), (1, 2, 5, 4)], material("grey"))
    mesh = obj.data
    co = np.array(verts, dtype=np.float64)
    mesh.attributes.new("height", "FLOAT", "POINT").data.foreach_set(
        "value", (co[:, 0] + 2 * co[:, 1]).astype(np.float32))
    mesh.attributes.new("room", "INT", "FACE").data.foreach_set("value", np.array([7, 9], np.int32))
    cv = np.array([lp.vertex_index for lp in mesh.loops])
    rgba = np.c_[co[cv][:, :2], np.full(8, 0.5), np.ones(8)].astype(np.float32)
    mesh.color_attributes.new("Col", "FLOAT_COLOR", "CORNER").data.foreach_set("color",
                                                                               rgba.ravel())
    bake_fake()
    baked = obj.data
    bco = np.array([v.co for v in baked.vertices])
    got = np.empty(len(baked.vertices), dtype=np.float32)
    baked.attributes["height"].data.foreach_get("value", got)
    np.testing.assert_allclose(got, bco[:, 0] + 2 * bco[:, 1], atol=F32_ATOL)
    rooms = np.empty(len(baked.polygons), dtype=np.int32)
    baked.attributes["room"].data.foreach_get("value", rooms)
    centres = np.array([p.center for p in baked.polygons])
    np.testing.assert_array_equal(rooms, np.where(centres[:, 0] < 1.0, 7, 9))
    bcv = np.array([lp.vertex_index for lp in baked.loops])
    col = np.empty(len(baked.loops) * 4, dtype=np.float32)
    baked.attributes["Col"].data.foreach_get("color", col)
    np.testing.assert_allclose(col.reshape(-1, 4)[:, :2], bco[bcv][:, :2], atol=F32_ATOL)
    assert baked.color_attributes.active_color_name == write.ATTRIBUTE


def test_material_edits_while_baked_reach_the_original(package):
    # The slot list edits the mesh the object shows (the baked one): a material changed or added
    # there must survive a re-bake (which starts from the original) and Clear Bake.
    lamp()
    fv, ff = square(2.0)
    obj = mesh_object("Floor", fv, ff, material("grey"))
    original = obj.data
    bake_fake()
    red, blue = material("red", (0.8, 0.1, 0.1)), material("blue", (0.1, 0.1, 0.8))
    obj.material_slots[0].material = red
    obj.data.materials.append(blue)
    ext = extraction()
    red_row = ext.arrays["material_names"].index("red")
    assert red_row in ext.arrays["face_materials"]        # the re-bake reads the new material
    bake_fake()
    assert list(obj.data.materials) == [red, blue]
    write.clear_bake([obj])
    assert obj.data == original and list(original.materials) == [red, blue]


# ------------------------------------------------------------------------------------------ UVs


def texture(uv):
    """A procedural texture: a smooth, non-periodic function of (u, v)."""
    return np.sin(5.0 * uv[:, 0]) + np.cos(3.0 * uv[:, 1]) + uv[:, 0] * uv[:, 1]


def uv_at(mesh, points, layer):
    """UV of *layer* at object-space points on the mesh (found in its loop triangles)."""
    mesh.calc_loop_triangles()
    n = len(mesh.loop_triangles)
    tri_loops = np.empty(n * 3, dtype=np.int32)
    mesh.loop_triangles.foreach_get("loops", tri_loops)
    tri_loops = tri_loops.reshape(n, 3)
    co = np.array([v.co for v in mesh.vertices], dtype=np.float64)
    cv = np.array([lp.vertex_index for lp in mesh.loops])
    uv = np.empty(len(mesh.loops) * 2, dtype=np.float32)
    mesh.uv_layers[layer].uv.foreach_get("vector", uv)
    uv = uv.reshape(-1, 2).astype(np.float64)
    out = np.full((points.shape[0], 2), np.nan)
    for i, p in enumerate(points):
        for t in tri_loops:
            a, b, c = co[cv[t]]
            w = np.linalg.lstsq(np.stack([b - a, c - a], axis=1), p - a, rcond=None)[0]
            bary = np.array([1 - w.sum(), w[0], w[1]])
            miss = np.linalg.norm(a + w[0] * (b - a) + w[1] * (c - a) - p)
            if bary.min() > -1e-9 and miss < 1e-6:
                out[i] = bary @ uv[t]
                break
    return out


def test_uvs_survive_texture_lookup_matches(package):
    # Each face has its own UV island: UVs a random affine function of position per face (so any
    # triangulation of a face interpolates them alike), two UV maps. A writer that mixed up
    # corners, faces, islands or maps would read other texels. Oracle: the texture looked up at
    # random points of each face through the original mesh's UVs.
    lamp()
    verts = [(0, 0, 0), (1, 0, 0), (2, 0, 0), (0, 1, 0), (1, 1, 0), (2, 1, 0)]
    obj = mesh_object("Plane", verts, [(0, 1, 4, 3), (1, 2, 5, 4)], material("grey"))
    obj.rotation_euler = (0.3, 0.0, 0.2)
    co = np.array(verts, dtype=np.float64)
    cv = np.array([lp.vertex_index for lp in obj.data.loops])
    face_of = np.repeat([0, 1], 4)
    rng = np.random.default_rng(7)
    for name in ("A", "B"):
        maps = rng.normal(size=(2, 2, 3))
        shift = rng.normal(size=(2, 2))
        uv = np.einsum("cij,cj->ci", maps[face_of], co[cv]) + shift[face_of]
        obj.data.uv_layers.new(name=name).uv.foreach_set("vector", uv.astype(np.float32).ravel())
    s = rng.uniform(0.05, 0.95, size=(20, 2))
    pts = np.concatenate([np.c_[s[:10, 0], s[:10, 1], np.zeros(10)],
                          np.c_[1.0 + s[10:, 0], s[10:, 1], np.zeros(10)]])
    obj.data.uv_layers["B"].active_render = True
    before = {n: texture(uv_at(obj.data, pts, n)) for n in ("A", "B")}
    assert obj.data.uv_layers.active.name == "A"
    assert all(np.isfinite(b).all() for b in before.values())
    bake_fake()
    for n in ("A", "B"):
        after = texture(uv_at(obj.data, pts, n))
        np.testing.assert_allclose(after, before[n], atol=1e-4)
    assert obj.data.uv_layers.active.name == "A"
    assert [la.name for la in obj.data.uv_layers if la.active_render] == ["B"]


# ------------------------------------------------------------------------- re-bake and failures


def test_rebake_starts_from_the_original(package):
    lamp()
    obj = modified_plane()
    original = obj.data
    before = snapshot(original)
    ext1, _ = bake_fake()
    meshes = len(bpy.data.meshes)
    ext2, _ = bake_fake()
    p1 = [p for p in ext1.parts if p.object_name == "Plane"][0]
    p2 = [p for p in ext2.parts if p.object_name == "Plane"][0]
    # The second extraction read the original with its subdivision, not the baked mesh.
    np.testing.assert_array_equal(p1.object_vertices, p2.object_vertices)
    np.testing.assert_array_equal(p1.corner_verts, p2.corner_verts)
    assert len(obj.data.polygons) == 2 * 4 * 4
    assert len(bpy.data.meshes) == meshes and obj[write.PROP_ORIGINAL] == original
    write.clear_bake([obj])
    assert obj.data == original and obj.modifiers["Grid"].show_viewport
    assert not original.use_fake_user
    assert_same(snapshot(original), before)


def test_failed_or_cancelled_bake_changes_nothing(package):
    lamp()
    obj = modified_plane()
    bake_fake()
    baked = obj.data
    state = (snapshot(baked), obj.modifiers["Grid"].show_viewport,
             obj.modifiers["Grid"].show_render, obj[write.PROP_MODIFIERS].to_dict())
    opts = job.options_from_props(bpy.context.scene.radiosity)
    opts.update(patch_size=1.0, resolution=16)
    # Cancelled: prepare ran (the originals were shown for the read), the worker never finished.
    bake_input = job.prepare(bpy.context, opts)
    bj = job.BakeJob(bake_input)
    bj.cancel()
    bj.start().join(60)
    assert obj.data == baked
    # Failed while writing: a result whose corners belong to no object of this scene.
    out = split_output(bake_input.extraction.arrays)
    bad = type(out)(**{**out.__dict__, "corner_sources": out.corner_sources + 10_000})
    result = job.compute(bake_input)
    result.output = bad
    with pytest.raises(job.BakeError, match="refers to corners"):
        job.apply(bpy.context, bake_input, result)
    assert obj.data == baked
    assert (snapshot(baked), obj.modifiers["Grid"].show_viewport,
            obj.modifiers["Grid"].show_render, obj[write.PROP_MODIFIERS].to_dict()) \
        .__repr__() == state.__repr__()


# --------------------------------------------------------------------------- shared and mirrored


def test_objects_sharing_a_mesh_get_their_own_baked_meshes(package):
    lamp()
    fv, ff = square(1.0)
    a = mesh_object("A", fv, ff, material("grey"), location=(-1.0, 0.0, 0.0))
    b = bpy.data.objects.new("B", a.data)
    b.location = (1.0, 0.0, 0.0)
    bpy.context.scene.collection.objects.link(b)
    shared = a.data
    bake_fake()
    assert a.data != b.data and a.data != shared and b.data != shared
    # Each mesh carries its own object's light (the oracle is a function of world position).
    for obj in (a, b):
        co = np.array([v.co for v in obj.data.vertices])
        cv = np.array([lp.vertex_index for lp in obj.data.loops])
        world = co[cv] + np.array(obj.location)
        np.testing.assert_allclose(read_colours(obj.data), smooth_colour(world), atol=F32_ATOL)
    write.clear_bake([a, b])
    assert a.data == shared and b.data == shared and shared.users == 2


@pytest.mark.parametrize("scale", [(1.0, 1.0, 1.0), (-1.0, 1.0, 1.0), (-1.0, -1.0, -1.0)])
def test_faces_keep_their_orientation(package, scale):
    # A cube with outward normals, mirrored or not: every baked face still points out of the
    # cube in object space (the scene reverses a mirrored object's faces; the writer must not).
    lamp()
    v, f = box(1.0, inward=False)
    obj = mesh_object("Cube", v, f, material("grey"), location=(0.0, 0.0, 1.0))
    obj.scale = scale
    bake_fake()
    normals = np.array([p.normal for p in obj.data.polygons])
    centres = np.array([p.center for p in obj.data.polygons])
    assert np.all(np.einsum("ij,ij->i", normals, centres) > 0.1)


def test_mesh_bake_is_one_undo_step(package, monkeypatch):
    # The operator (as a click runs it) with the core's output stood in for: one undo brings
    # back the original mesh, modifiers and no memory of the bake; redo brings the bake back.
    lamp()
    obj = modified_plane()
    set_settings(bpy.context.scene, patch_size=1.0, resolution=16)
    real_compute = job.compute

    def compute(bake_input, progress=None, cancel=None):
        result = real_compute(bake_input, progress, cancel)
        result.output = split_output(bake_input.extraction.arrays)
        return result

    monkeypatch.setattr(job, "compute", compute)
    bpy.ops.ed.undo_push(message="settings")
    before = snapshot(obj.data)
    assert bpy.ops.radiosity.bake("EXEC_DEFAULT", True) == {"FINISHED"}
    obj = bpy.data.objects["Plane"]
    assert write.is_baked(obj) and len(obj.data.polygons) == 32
    bpy.ops.ed.undo()
    obj = bpy.data.objects["Plane"]
    assert not write.is_baked(obj) and obj.data.name == "Plane"
    assert obj.modifiers["Grid"].show_viewport and obj.modifiers["Grid"].show_render
    assert_same(snapshot(obj.data), before)
    bpy.ops.ed.redo()
    obj = bpy.data.objects["Plane"]
    assert write.is_baked(obj) and len(obj.data.polygons) == 32
    assert not obj.modifiers["Grid"].show_viewport


def test_area_light_faces_in_the_output_are_left_out(package):
    # An area light is a scene face of no object: output faces over it are not written anywhere,
    # and the floor still gets exactly its own 2 x 2 faces.
    light = bpy.data.lights.new("Panel", "AREA")
    light.size = 1.0
    light.energy = 100.0
    lamp_obj = bpy.data.objects.new("Panel", light)
    lamp_obj.location = (0.0, 0.0, 2.0)
    bpy.context.scene.collection.objects.link(lamp_obj)
    fv, ff = square(2.0)
    floor = mesh_object("Floor", fv, ff, material("grey"))
    ext, out = bake_fake()
    assert ext.lights == 1 and len(ext.parts) == 1
    assert out.face_parent.max() == 1                     # the light's face is in the output
    assert len(floor.data.polygons) == 4
