"""Lux in false colour in Blender (radiosity_addon.luxview): the 'Radiosity Lux Colour' attribute,
the toggle that puts everything back, Clear Bake, and the batch's --render-lux PNG with legend.

Oracles: the attribute's colours against core.falsecolour's mapping of the 'Radiosity Lux' values
Blender holds (read back here, not taken from the display code); "restored exactly" as every
plain RNA property of every 3D view's shading, of the colour management and of every mesh's
colour attributes, compared before and after; the PNG's legend bar against the ramp at each
tick's position, computed here from the scale's definition (t = E / top, or log10 for log).
"""

import json
import os

import bpy
import numpy as np
import pytest

from conftest import PACKAGE
from helpers import material, mesh_object, square
from test_batch import one_error_line, run_batch

falsecolour, legend = PACKAGE.core.falsecolour, PACKAGE.core.legend
LOG_DECADES, make_scale, ramp = falsecolour.LOG_DECADES, falsecolour.make_scale, falsecolour.ramp

LUX = "Radiosity Lux"
COLOUR = "Radiosity Lux Colour"


def _scene(camera=False, plane=True):
    """A floor under a point light, a calculation surface (work plane) above it."""
    bpy.ops.wm.read_homefile(use_factory_startup=True, use_empty=True)
    floor = mesh_object("Floor", *square(4.0), material("grey", (0.5, 0.5, 0.5), kind="diffuse"))
    if plane:
        plane = mesh_object("WorkPlane", *square(2.0, z=0.8), material("any", (0.9, 0.9, 0.9)))
        plane.radiosity_calc_surface = True
    lamp = bpy.data.lights.new("Lamp", "POINT")
    lamp.energy, lamp.shadow_soft_size = 1000.0, 0.0
    obj = bpy.data.objects.new("Lamp", lamp)
    obj.location = (0.3, 0.2, 2.0)
    bpy.context.scene.collection.objects.link(obj)
    scene = bpy.context.scene
    scene.radiosity.patch_size = 0.5
    if camera:
        cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
        cam.location = (0.0, 0.0, 4.5)                     # looks down -Z onto the floor
        scene.collection.objects.link(cam)
        scene.camera = cam
        scene.render.resolution_x, scene.render.resolution_y = 200, 150
        scene.render.resolution_percentage = 100
    return floor, plane


def _corner_lux(mesh):
    """(C,) lux at the corners as Blender holds it (a point attribute read at each corner)."""
    attr = mesh.attributes[LUX]
    buf = np.empty(len(attr.data), np.float32)
    attr.data.foreach_get("value", buf)
    if attr.domain == "POINT":
        return buf[[lp.vertex_index for lp in mesh.loops]].astype(np.float64)
    return buf.astype(np.float64)


def _srgb(mesh, name=COLOUR):
    attr = mesh.color_attributes[name]
    buf = np.empty(len(attr.data) * 4, np.float32)
    attr.data.foreach_get("color_srgb", buf)
    return buf.reshape(-1, 4)[:, :3].astype(np.float64)


def _plain(struct):
    """Every plain (non-pointer, non-collection) RNA property of *struct*, by name."""
    out = {}
    for prop in struct.bl_rna.properties:
        if prop.identifier == "rna_type" or prop.type in ("POINTER", "COLLECTION"):
            continue
        value = getattr(struct, prop.identifier)
        out[prop.identifier] = tuple(value) if hasattr(value, "__len__") and \
            not isinstance(value, str) else value
    return out


def _snapshot():
    """Everything the display may touch: views, colour management, meshes' colour state."""
    scene = bpy.context.scene
    views = {(s.name, i, j): _plain(sp.shading) for s in bpy.data.screens
             for i, a in enumerate(s.areas) for j, sp in enumerate(a.spaces)
             if sp.type == "VIEW_3D"}
    meshes = {m.name: (sorted(a.name for a in m.attributes), m.color_attributes.active_color_name,
                       m.color_attributes.default_color_name, sorted(m.keys()))
              for m in bpy.data.meshes}
    return dict(views=views, colour=_plain(scene.view_settings), meshes=meshes,
                scene_keys=sorted(scene.keys()))


def _areas(mesh):
    """(C,) the area each corner stands for: its face's area over its corners (unit scale)."""
    return np.array([p.area / p.loop_total for p in mesh.polygons for _ in range(p.loop_total)])


def _scale(mode="linear"):
    """The scale the display must use: core.falsecolour's, of the lux and areas Blender holds."""
    meshes = _lux_meshes()
    return make_scale(np.concatenate([_corner_lux(m) for m in meshes]), mode,
                      weights=np.concatenate([_areas(m) for m in meshes]))


def _lux_meshes():
    return [o.data for o in bpy.context.scene.objects
            if o.type == "MESH" and LUX in o.data.attributes]


@pytest.mark.parametrize("mode", ["MESH", "VERTICES"])
def test_colours_are_the_scale_of_the_lux_attribute(package, mode):
    _scene()
    scene = bpy.context.scene
    scene.radiosity.output_mode = mode
    assert bpy.ops.radiosity.bake() == {"FINISHED"}
    assert bpy.ops.radiosity.lux_display() == {"FINISHED"}
    meshes = _lux_meshes()
    assert {m.name.split(".")[0] for m in meshes} == {"Floor", "WorkPlane"}
    values = [_corner_lux(m) for m in meshes]
    scale = _scale()                                           # the panel's default: linear, auto
    assert scale.ticks[0] == 0 and scale.top >= np.percentile(np.concatenate(values), 50)
    for mesh, lux in zip(meshes, values):
        attrs = mesh.color_attributes
        assert attrs[COLOUR].data_type == "BYTE_COLOR" and attrs[COLOUR].domain == "CORNER"
        assert attrs.active_color_name == COLOUR and attrs.default_color_name == COLOUR
        np.testing.assert_allclose(_srgb(mesh), scale.colours(lux), atol=0.51 / 255)
    legend = json.loads(scene["radiosity_lux_display"])["scale"]
    assert legend["ticks"] == pytest.approx(list(scale.ticks), rel=1e-6)
    for space in (sp for s in bpy.data.screens for a in s.areas for sp in a.spaces
                  if sp.type == "VIEW_3D"):
        assert (space.shading.type, space.shading.light, space.shading.color_type) == \
            ("SOLID", "FLAT", "VERTEX")
    assert scene.view_settings.view_transform == "Standard"
    assert scene.view_settings.exposure == 0.0


def test_scale_settings_redraw_the_colours(package):
    _scene()
    scene = bpy.context.scene
    assert bpy.ops.radiosity.bake() == {"FINISHED"}
    assert bpy.ops.radiosity.lux_display() == {"FINISHED"}
    floor = bpy.data.objects["Floor"].data
    lux = _corner_lux(floor)
    scene.radiosity.lux_scale = "LOG"
    scene.radiosity.lux_max = 300.0
    want = make_scale(lux, "log", top=300.0)
    # The oracle: log10 position over the decades below 300 lx, clipped.
    t = np.clip(np.log10(np.maximum(lux, 0.3) / 0.3) / LOG_DECADES, 0, 1)
    np.testing.assert_allclose(want.position(lux), t, atol=1e-12)
    np.testing.assert_allclose(_srgb(floor), ramp(t), atol=0.51 / 255)
    assert json.loads(scene["radiosity_lux_display"])["scale"]["ticks"] == \
        pytest.approx([0.3, 3.0, 30.0, 300.0])


def test_toggle_off_restores_everything_exactly(package):
    floor, _ = _scene()
    scene = bpy.context.scene
    scene.radiosity.output_mode = "VERTICES"               # the colours go on the user's mesh
    paint = floor.data.color_attributes.new("Paint", "BYTE_COLOR", "POINT")
    assert bpy.ops.radiosity.bake() == {"FINISHED"}
    attrs = floor.data.color_attributes
    attrs.active_color_name, attrs.default_color_name = paint.name, "Radiosity"
    spaces = [sp for s in bpy.data.screens for a in s.areas for sp in a.spaces
              if sp.type == "VIEW_3D"]
    assert len(spaces) > 1
    for i, space in enumerate(spaces):                     # views in several states
        space.shading.type = ("MATERIAL", "SOLID", "WIREFRAME")[i % 3]
        space.shading.show_cavity = bool(i % 2)
        space.shading.show_xray = i == 1
    scene.view_settings.view_transform = "AgX"
    scene.view_settings.exposure, scene.view_settings.gamma = 0.7, 1.3
    before = _snapshot()
    assert bpy.ops.radiosity.lux_display() == {"FINISHED"}
    assert _snapshot() != before
    assert bpy.ops.radiosity.lux_display() == {"FINISHED"}  # the toggle: off again
    assert _snapshot() == before
    assert COLOUR not in attrs and attrs.active_color_name == "Paint"


@pytest.mark.parametrize("mode", ["MESH", "VERTICES"])
def test_clear_bake_removes_the_display(package, mode):
    _scene()
    scene = bpy.context.scene
    scene.radiosity.output_mode = mode
    scene.view_settings.exposure = -0.5
    before = _snapshot()
    assert bpy.ops.radiosity.bake() == {"FINISHED"}
    baked = _snapshot()
    assert bpy.ops.radiosity.lux_display() == {"FINISHED"}
    assert bpy.ops.radiosity.clear() == {"FINISHED"}
    after = _snapshot()
    assert not any(COLOUR in m.attributes for m in bpy.data.meshes)
    assert after["meshes"] == before["meshes"] and after["colour"] == before["colour"]
    assert after["views"] == baked["views"] and after["scene_keys"] == before["scene_keys"]


def test_a_new_bake_while_shown_shows_the_new_lux(package):
    floor, _ = _scene()
    scene = bpy.context.scene
    assert bpy.ops.radiosity.bake() == {"FINISHED"}
    assert bpy.ops.radiosity.lux_display() == {"FINISHED"}
    bpy.data.lights["Lamp"].energy = 4000.0
    assert bpy.ops.radiosity.bake() == {"FINISHED"}
    mesh = floor.data
    scale = _scale()
    np.testing.assert_allclose(_srgb(mesh), scale.colours(_corner_lux(mesh)), atol=0.51 / 255)
    assert mesh.color_attributes.active_color_name == COLOUR
    assert bpy.ops.radiosity.lux_display() == {"FINISHED"}
    assert mesh.color_attributes.active_color_name == "Radiosity"


def test_nothing_baked_says_so(package):
    _scene()
    with pytest.raises(RuntimeError, match="No illuminance to show in scene 'Scene': bake first"):
        bpy.ops.radiosity.lux_display()
    assert "radiosity_lux_display" not in bpy.context.scene


def test_panel_draws_the_toggle(package):
    _scene()
    assert bpy.ops.radiosity.bake() == {"FINISHED"}
    labels = []

    class Layout:                              # records what the panel asks the layout for
        def __getattr__(self, name):
            def call(*args, **kw):
                if name == "operator":
                    labels.append((args[0], kw.get("depress")))
                return self
            return call
    assert PACKAGE.radiosity_addon.luxview.RADIOSITY_OT_lux_display.bl_label == \
        "Show Lux (false colour)"
    PACKAGE.radiosity_addon.panels.draw_lux(Layout(), bpy.context.scene)
    assert labels == [("radiosity.lux_display", False)]


# --------------------------------------------------------------------------------- batch


def _save(tmp_path, camera=True):
    # No work plane: its 4 vertices would blend their colours across the picture's middle (a
    # colour between two vertices is a mix of theirs, not the ramp's colour of the mixed lux).
    _scene(camera=camera, plane=False)
    src = tmp_path / "room.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(src), check_existing=False)
    return src


@pytest.mark.parametrize("mode", ["linear", "log"])
def test_batch_png_has_the_scene_and_a_legend_on_the_ramp(package, tmp_path, mode):
    src = _save(tmp_path)
    out, png, rep = tmp_path / "o.blend", tmp_path / "lux.png", tmp_path / "r.json"
    proc = run_batch(src, "--output", out, "--render-lux", png, "--report", rep,
                     "--lux-scale", mode)
    assert proc.returncode == 0, proc.stderr
    assert f"-> {png}" in proc.stdout
    report = json.loads(rep.read_text())
    # The saved file holds the bake (not the display); its lux gives the scale.
    bpy.ops.wm.open_mainfile(filepath=str(out), load_ui=False)
    assert not any(COLOUR in m.attributes for m in bpy.data.meshes)
    scale = _scale(mode)
    assert report["lux_scale"]["ticks"] == pytest.approx(list(scale.ticks), rel=1e-6)

    image = bpy.data.images.load(str(png))
    w, h = image.size
    px = np.empty(w * h * image.channels, np.float32)
    image.pixels.foreach_get(px)
    rgb = px.reshape(h, w, -1)[::-1, :, :3].astype(np.float64)      # rows top-down
    assert h == 150 and w > 200                                      # the legend is added
    scene_part = rgb[:, :200]
    assert len(np.unique(np.round(scene_part * 255).reshape(-1, 3), axis=0)) > 20
    # The scene's pixels are false colours: nearly all lie near the ramp (flat shading, Standard
    # view; between two vertices the colour is a mix of theirs, a little off the ramp).
    dense = ramp(np.linspace(0, 1, 1024))
    dist = np.sqrt(((scene_part.reshape(-1, 1, 3) - dense[None]) ** 2).sum(-1)).min(axis=1)
    assert np.mean(dist < 6 / 255) > 0.99 and np.median(dist) < 2 / 255
    # The legend: the bar's place from the legend's layout; its colour at each tick's row must
    # be the ramp's at the tick's position t, computed here.
    left, right, top_row, bottom_row = legend.layout(h, 200, scale).bar
    assert left > 200
    column = rgb[:, (left + right) // 2]
    ticks = np.array(scale.ticks)
    t = ticks / scale.top if mode == "linear" else np.log10(ticks / scale.bottom) / LOG_DECADES
    half_row = 0.5 / (bottom_row - top_row)       # a tick lies within half a row of its row
    for ti in t:
        row = int(np.rint(bottom_row - ti * (bottom_row - top_row)))
        near = ramp([max(ti - half_row, 0.0), ti, min(ti + half_row, 1.0)])
        slack = np.abs(near - near[1]).max() + 0.6 / 255             # + the PNG's bytes
        np.testing.assert_allclose(column[row], near[1], atol=slack)
        assert np.all(rgb[row, right] > 0.99)                      # the white tick mark
    # Between the ticks the bar runs through the ramp, dark at the bottom, bright at the top.
    np.testing.assert_allclose(column[top_row:bottom_row + 1],
                               ramp(np.linspace(1, 0, bottom_row - top_row + 1)), atol=1.5 / 255)


@pytest.mark.parametrize("args, message", [
    (["--render-lux", "{tmp}/none/x.png"], "--render-lux {tmp}/none/x.png: the folder"),
    (["--render-lux", "{tmp}/x.jpg"], "--render-lux {tmp}/x.jpg: give a .png file name"),
    (["--render-lux", "{tmp}/x.png", "--lux-scale", "cubic"], "bad option"),
    (["--render-lux", "{tmp}/x.png", "--lux-max", "-3"], "bad option"),
])
def test_batch_mistakes_stop_before_the_bake(package, tmp_path, args, message):
    src = _save(tmp_path)
    proc = run_batch(src, "--output", tmp_path / "o.blend",
                     *[a.format(tmp=tmp_path) for a in args])
    assert message.format(tmp=tmp_path) in one_error_line(proc)
    assert not (tmp_path / "o.blend").exists() and "baked" not in proc.stdout


def test_batch_render_lux_needs_a_camera(package, tmp_path):
    src = _save(tmp_path, camera=False)
    proc = run_batch(src, "--output", tmp_path / "o.blend", "--render-lux", tmp_path / "x.png")
    assert "--render-lux needs a scene camera" in one_error_line(proc)
    assert sorted(os.listdir(tmp_path)) == ["room.blend"]
