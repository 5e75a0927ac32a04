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


def _skylight_room(W=4.0, H=2.0, a=2.0):
    """A black W x W x H room, normals inward, with an a x a opening in the middle of its
    ceiling; the floor in four quads (a vertex at its centre)."""
    s, o = W / 2, a / 2
    v = [(-s, -s, 0), (s, -s, 0), (s, s, 0), (-s, s, 0), (-s, -s, H), (s, -s, H), (s, s, H),
         (-s, s, H), (-o, -o, H), (o, -o, H), (o, o, H), (-o, o, H),
         (0, -s, 0), (s, 0, 0), (0, s, 0), (-s, 0, 0), (0, 0, 0)]
    faces = [(0, 12, 16, 15), (12, 1, 13, 16), (16, 13, 2, 14), (15, 16, 14, 3),
             (0, 4, 5, 1), (1, 5, 6, 2), (2, 6, 7, 3), (3, 7, 4, 0),
             (5, 9, 8, 4), (6, 10, 9, 5), (7, 11, 10, 6), (4, 8, 11, 7)]
    return mesh_object("Room", v, faces, material("black", (0.0, 0.0, 0.0), kind="diffuse"))


def _skylight_df(points, H=2.0, a=2.0, n=48):
    """Daylight factor (%) at upward-facing ``points`` (k, 3) under the opening: 100 / E_out x
    pi x (1/pi) integral over the opening of L cos_point cos_opening / r^2 dA (Gauss-Legendre),
    L the CIE overcast sky, E_out = 7 pi Lz / 9: independent of the hemicube."""
    x, w = np.polynomial.legendre.leggauss(n)
    X, Y = np.meshgrid(0.5 * a * x, 0.5 * a * x)
    wt = np.outer(w, w) * (0.5 * a) ** 2
    out = []
    for px, py, pz in points:
        dz = H - pz
        r2 = (X - px) ** 2 + (Y - py) ** 2 + dz ** 2
        cos = dz / np.sqrt(r2)
        E = ((1 + 2 * cos) / 3 * cos * cos / r2 * wt).sum()        # Lz = 1
        out.append(100.0 * E / (7 * np.pi / 9))
    return np.array(out)


def test_cie_overcast_sky_through_a_skylight_gives_the_daylight_factor(package):
    """sky='cie_overcast' with no light at all in the file: the floor and a small work plane
    under the opening get their lux and daylight factor; the quadrature over the opening's
    solid angle is the oracle, within the opening's outline quantised by the hemicube pixels
    (about 32 px across at R = 64, as in tests/core/test_sky.py): 3 %."""
    room = _skylight_room()
    plane = mesh_object("WorkPlane", *square(0.4, z=0.8), material("any", (0.9, 0.9, 0.9)))
    plane.radiosity_calc_surface = True
    scene = bpy.context.scene
    scene.world = None
    scene.radiosity.output_mode = "VERTICES"
    scene.radiosity.sky = "CIE_OVERCAST"
    assert scene.radiosity.sky_illuminance == pytest.approx(10_000.0)
    assert bpy.ops.radiosity.bake() == {"FINISHED"}
    report = json.loads(scene.radiosity.last_report)
    assert report["sky"]["kind"] == "cie_overcast"
    assert report["sky"]["outdoor_lux"] == pytest.approx(10_000.0, rel=1e-9)
    (surf,) = report["calculation_surfaces"]
    grid, _, weights = package.core.lux.calculation_grid([np.array(square(0.4, z=0.8)[0])])
    want = _skylight_df(grid)
    assert surf["DFavg"] == pytest.approx((want * weights).sum() / weights.sum(), rel=0.03)
    assert surf["DFmin"] == pytest.approx(want.min(), rel=0.03)
    assert surf["DFavg"] == pytest.approx(surf["Eavg"] / 100.0, rel=1e-9)
    # The floor's corners: lux and daylight factor (%) side by side; the centre under the
    # opening against the quadrature.
    mesh = room.data
    values = {}
    for name in ("Radiosity Lux", "Radiosity Daylight Factor"):
        attr = mesh.attributes[name]
        assert attr.domain == "CORNER" and attr.data_type == "FLOAT"
        buf = np.empty(len(attr.data), dtype=np.float32)
        attr.data.foreach_get("value", buf)
        values[name] = buf.astype(np.float64)
    cv = np.array([lp.vertex_index for lp in mesh.loops])
    floor = cv[:16]                                       # the four floor quads come first
    assert np.all(values["Radiosity Lux"][:16] > 0)
    np.testing.assert_allclose(values["Radiosity Daylight Factor"],
                               values["Radiosity Lux"] / 100.0, rtol=1e-6)
    centre = np.flatnonzero(floor == 16)
    np.testing.assert_allclose(values["Radiosity Daylight Factor"][centre],
                               _skylight_df([(0.0, 0.0, 0.0)])[0], rtol=0.03)
    # Clear Bake removes both.
    assert bpy.ops.radiosity.clear() == {"FINISHED"}
    assert "Radiosity Lux" not in mesh.attributes
    assert "Radiosity Daylight Factor" not in mesh.attributes


def _sky_texture_world(elevation, rotation):
    """Blender's own sky model (Nishita in 4.x, multiple scattering in 5.0), sun disc on."""
    world = _world((0.0, 0.0, 0.0))
    nt = world.node_tree
    sky = nt.nodes.new("ShaderNodeTexSky")
    sky.sun_disc = True
    sky.sun_elevation, sky.sun_rotation = elevation, rotation
    nt.links.new(sky.outputs["Color"], nt.nodes["Background"].inputs["Color"])
    return world


#: A textured world against Cycles, corner by corner (luminance): the sky as a 64 x 32 map (5.6
#: degree texels) and its sun disc as a sun light. Measured (bpy 5.0.1): 0.67 % mean, 3.5 % at
#: worst (the wall's foot, as for the uniform world); the tolerances of the uniform world.
SKY_MEAN_RTOL, SKY_MAX_RTOL = MEAN_RTOL, MAX_RTOL


def test_floor_and_wall_under_blenders_sky_texture_match_cycles(package):
    """The world is rendered into a map and its sun found (radiosity_addon/world_map.py): the
    sunlit floor, the wall's shadow on it and the sky light on both agree with Cycles' bake of
    the same world (which samples the sky texture itself)."""
    floor = _grid("Floor", 2.0, (0.0, 0.0, 0.0))
    wall = _grid("Wall", 2.0, (0.0, 1.0, 1.0), rotation=(np.pi / 2, 0.0, 0.0))   # normal -y
    _sky_texture_world(np.radians(40.0), np.radians(200.0))
    cycles = _cycles([floor, wall])
    ours, report = _ours([floor, wall])
    c, o = np.concatenate(cycles), np.concatenate(ours)
    lum_c, lum_o = c @ [0.2126, 0.7152, 0.0722], o @ [0.2126, 0.7152, 0.0722]
    rel = np.abs(lum_o - lum_c) / lum_c
    msg = f"mean {rel.mean():.4f}, max {rel.max():.4f}"
    assert rel.mean() < SKY_MEAN_RTOL, msg
    assert rel.max() < SKY_MAX_RTOL, msg
    assert any("map rendered by Cycles" in n and "sun light" in n for n in report["notes"])
    assert [n for n in report["lights"]["names"] if "sun" in n] == ["World 'Sky' sun"]
    # The rendering left nothing behind in the file.
    assert [s.name for s in bpy.data.scenes] == [bpy.context.scene.name]
    assert "Radiosity world map" not in bpy.data.cameras


def _cie_world(zenith):
    """Cycles' own CIE overcast sky, built from nodes: the world's Background strength
    ``Lz (1 + 2 z) / 3`` above the horizon and 0 below it, z the direction's height (the
    Texture Coordinate node's Generated output is the ray's direction in a world)."""
    world = _world((1.0, 1.0, 1.0))
    nt = world.node_tree
    coords, xyz = nt.nodes.new("ShaderNodeTexCoord"), nt.nodes.new("ShaderNodeSeparateXYZ")
    shape, above, value = (nt.nodes.new("ShaderNodeMath") for _ in range(3))
    shape.operation, above.operation, value.operation = "MULTIPLY_ADD", "GREATER_THAN", "MULTIPLY"
    shape.inputs[1].default_value, shape.inputs[2].default_value = 2.0, 1.0    # 1 + 2 z
    above.inputs[1].default_value = 0.0
    nt.links.new(coords.outputs["Generated"], xyz.inputs[0])
    nt.links.new(xyz.outputs["Z"], shape.inputs[0])
    nt.links.new(xyz.outputs["Z"], above.inputs[0])
    nt.links.new(shape.outputs[0], value.inputs[0])
    nt.links.new(above.outputs[0], value.inputs[1])
    scaled = nt.nodes.new("ShaderNodeMath")
    scaled.operation = "MULTIPLY"
    scaled.inputs[1].default_value = zenith / 3.0
    nt.links.new(value.outputs[0], scaled.inputs[0])
    nt.links.new(scaled.outputs[0], nt.nodes["Background"].inputs["Strength"])
    return world


def test_floor_and_wall_under_the_cie_overcast_sky_match_cycles(package):
    """sky='cie_overcast' (core.sky.CIEOvercast, gathered per direction through the
    hemicube's empty pixels) against Cycles' bake under the same sky made of world nodes:
    corner by corner (luminance), the uniform world's tolerances (the same hemicube edge
    effect at the wall's foot)."""
    floor = _grid("Floor", 2.0, (0.0, 0.0, 0.0))
    wall = _grid("Wall", 2.0, (0.0, 1.0, 1.0), rotation=(np.pi / 2, 0.0, 0.0))   # normal -y
    scene = bpy.context.scene
    zenith = package.core.sky.zenith_radiance(10_000.0)
    _cie_world(zenith)
    cycles = _cycles([floor, wall])
    scene.radiosity.sky = "CIE_OVERCAST"
    ours, report = _ours([floor, wall])
    assert report["sky"]["kind"] == "cie_overcast"
    c, o = np.concatenate(cycles), np.concatenate(ours)
    lum_c, lum_o = c @ [0.2126, 0.7152, 0.0722], o @ [0.2126, 0.7152, 0.0722]
    rel = np.abs(lum_o - lum_c) / lum_c
    msg = f"mean {rel.mean():.4f}, max {rel.max():.4f}, ours/Cycles {lum_o.sum() / lum_c.sum():.4f}"
    print(msg)
    assert rel.mean() < MEAN_RTOL, msg
    assert rel.max() < MAX_RTOL, msg
    # The open floor far from the wall sees nearly the whole sky: rho x (the sky's horizontal
    # irradiance / pi), the closed form 7 pi Lz / 9 / pi, less the wall's share.
    assert lum_o.max() < 0.5 * 7.0 * zenith / 9.0 * (1 + 1e-3)


def test_the_cie_overcast_sky_replaces_the_whole_world_its_sun_disc_too(package):
    """sky='cie_overcast' replaces the world, so a Sky Texture world with its sun disc adds no
    sun light (an overcast sky has none) and is not even rendered: the bake equals the same
    bake with no world at all (the same scene in two equivalent forms)."""
    floor = _grid("Floor", 2.0, (0.0, 0.0, 0.0), cuts=4)
    wall = _grid("Wall", 2.0, (0.0, 1.0, 1.0), rotation=(np.pi / 2, 0.0, 0.0), cuts=4)
    scene = bpy.context.scene
    scene.radiosity.sky = "CIE_OVERCAST"
    scene.world = None
    bare, _ = _ours([floor, wall])
    _sky_texture_world(np.radians(40.0), np.radians(200.0))
    ours, report = _ours([floor, wall])
    assert not report.get("lights", {}).get("names"), report.get("lights")
    assert not any("map rendered by Cycles" in n for n in report["notes"])
    for a, b in zip(ours, bare):
        np.testing.assert_array_equal(a, b)
