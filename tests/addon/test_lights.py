"""Blender's lights against Cycles itself: area-light radiance, point, spot and sun lights.

Oracle: Cycles. Area lights: the same grey floor is baked by Cycles twice, once under the area
light and once under an emissive polygon of the radiance our conversion assigns to that light; the
two bakes must agree. 64 samples keep each bake under a second; the tolerance (3 %) covers their
Monte Carlo noise (two bakes of 400 corners each, measured spread ~0.5 %).

Point, spot and sun lights: a floor (a 10 x 10 grid, 121 vertices, a pure Diffuse BSDF of colour
0.5, which the material reader takes as reflectance 0.5 exactly) with no other surface that
could reflect light onto it is baked by Cycles (DIFFUSE, DIRECT + COLOR, to the corners, 256
samples, adaptive sampling off) and by the add-on's bake operator ("Existing Vertices" output, so
both write the grid's own corners) and compared corner by corner where lit (Cycles > 1 % of its
brightest corner). Tolerance: 1 % mean relative difference and 3 % per corner, the latter
measured against the corner's value plus 3 % of the brightest (:data:`EDGE_ATOL`: Cycles bakes
a corner slightly inside its face, which shows at a spot's cone edge). Measured with bpy 5.0.1
and 4.2: lights of radius 0 and suns of angle 0 agree to 4e-4 (Cycles has no noise there;
spot: 2e-3 mean, 2 % at the cone edge), lights with a radius to 1e-3 per corner, which is
Cycles' seed-to-seed noise at 256 samples. Shadowed corners (blocker case) must be dark in both
(below 1 % of the brightest); the blocker is black (reflectance 0) so that it reflects nothing
onto the floor, and its shadow's edges lie at least 0.039 from every vertex.
"""

import importlib
import json
import math
from pathlib import Path

import bpy
import numpy as np
import pytest

from conftest import PACKAGE
from helpers import cycles_corners, material, mesh_object, read_colours, square

materials = PACKAGE.radiosity_addon.materials

#: Cycles samples per bake; and the relative tolerance (see module docstring).
SAMPLES = 64
RTOL = 0.03


def _cycles_floor():
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = SAMPLES
    scene.render.bake.use_pass_direct = True
    scene.render.bake.use_pass_indirect = False
    scene.render.bake.use_pass_color = True
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=9, y_subdivisions=9, size=1.0)
    floor = bpy.context.object
    mat = material("grey", (0.5, 0.5, 0.5))
    mat.node_tree.nodes["Principled BSDF"].inputs["Roughness"].default_value = 1.0
    floor.data.materials.append(mat)
    floor.data.color_attributes.new("bake", "FLOAT_COLOR", "CORNER")
    return floor


def _bake(floor):
    for obj in bpy.context.scene.objects:
        obj.select_set(False)
    floor.select_set(True)
    bpy.context.view_layer.objects.active = floor
    bpy.ops.object.bake(type="DIFFUSE", pass_filter={"DIRECT", "COLOR"}, target="VERTEX_COLORS")
    attr = floor.data.color_attributes["bake"]
    buf = np.empty(len(attr.data) * 4, np.float32)
    attr.data.foreach_get("color", buf)
    return buf.reshape(-1, 4)[:, :3].mean()


HAS_NORMALIZE = "normalize" in bpy.types.AreaLight.bl_rna.properties  # Blender 4.4 on

CASES = [("SQUARE", 1.0, 1.0, 1.0, True), ("RECTANGLE", 0.6, 0.3, 1.0, True),
         ("DISK", 0.5, 0.5, 1.0, True), ("SQUARE", 0.5, 0.5, 2.0, True)]
if HAS_NORMALIZE:
    CASES.append(("SQUARE", 0.5, 0.5, 1.0, False))


@pytest.mark.parametrize("shape, sx, sy, scale, normalize", CASES)
def test_area_light_radiance_matches_cycles(package, shape, sx, sy, scale, normalize):
    floor = _cycles_floor()
    bpy.ops.object.light_add(type="AREA", location=(0, 0, 1))
    lamp_obj = bpy.context.object
    lamp = lamp_obj.data
    lamp.shape, lamp.size, lamp.size_y, lamp.energy = shape, sx, sy, 30.0
    lamp.color = (1.0, 0.8, 0.6)
    lamp_obj.scale = (scale, scale, 1.0)
    if HAS_NORMALIZE:
        lamp.normalize = normalize
    from_light = _bake(floor)

    pts, area = materials.area_light_polygon(lamp)
    world_area = area * scale * scale
    radiance = materials.area_light_radiance(lamp, world_area)
    bpy.data.objects.remove(lamp_obj)
    # The emissive stand-in: the light's exact outline for rectangles; for a disk, a 64-gon
    # (closer to the circle than our 16-gon, so the test checks the conversion, not the outline).
    if shape == "DISK":
        a = -np.linspace(0, 2 * math.pi, 64, endpoint=False)
        pts = np.stack([0.25 * np.cos(a), 0.25 * np.sin(a), np.zeros(64)], axis=1)
    pts = pts * [scale, scale, 1.0] + [0, 0, 1.0]
    mesh_object("Emitter", pts, [tuple(range(len(pts)))],
                material("e", (0, 0, 0), emission=tuple(radiance / radiance.max()),
                         strength=float(radiance.max()), kind="emission"))
    from_mesh = _bake(floor)
    assert from_light == pytest.approx(from_mesh, rel=RTOL)
    assert from_light > 0.01


# ---- point, spot and sun lights ------------------------------------------------------------

#: Cycles samples for the point/spot/sun references; tolerances (see module docstring).
LIGHT_SAMPLES = 256
POINT_MEAN_RTOL = 0.01
POINT_MAX_RTOL = 0.03
#: A corner counts as lit above this fraction of the largest Cycles value; shadowed corners stay
#: below it in both bakes.
LIT = 0.01
#: Cycles bakes each corner a little inside its face (the four corners of one vertex differ),
#: which matters where the light changes fast: at a spot's cone edge a corner at 1 % of the
#: brightest differs by up to 8 % (0.08 % of the brightest). The per-corner bound is
#: POINT_MAX_RTOL x (value + EDGE_ATOL x brightest).
EDGE_ATOL = 0.03

extract = PACKAGE.radiosity_addon.extract

HAS_LIGHT_NORMALIZE = "normalize" in bpy.types.PointLight.bl_rna.properties   # 4.4 on
HAS_EXPOSURE = "exposure" in bpy.types.Light.bl_rna.properties


def _grey_grid(size=2.0, cuts=10, location=(0.0, 0.0, 0.0)):
    """A floor grid of cuts x cuts quads (normal +Z) with a Diffuse BSDF of colour 0.5."""
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=cuts, y_subdivisions=cuts, size=size,
                                    location=location)
    floor = bpy.context.object
    floor.name = "Floor"
    floor.data.materials.append(material("diffuse grey", (0.5, 0.5, 0.5), kind="diffuse"))
    return floor


def _light(kind, location, rotation=(0.0, 0.0, 0.0), visible_diffuse=True, **props):
    lamp = bpy.data.lights.new(kind.title(), kind)
    for key, value in props.items():
        setattr(lamp, key, value)
    obj = bpy.data.objects.new(kind.title(), lamp)
    obj.visible_diffuse = visible_diffuse
    obj.location, obj.rotation_euler = location, rotation
    bpy.context.scene.collection.objects.link(obj)
    return obj


def _cycles_corners(floor, samples=LIGHT_SAMPLES):
    """Cycles' DIFFUSE bake (direct light x colour) of *floor*'s corners: (C, 3)."""
    return cycles_corners(floor, samples)


def _our_corners(floor):
    """The add-on's bake of the scene on *floor*'s own corners: (C, 3), and the report."""
    scene = bpy.context.scene
    scene.radiosity.output_mode = "VERTICES"
    assert bpy.ops.radiosity.bake() == {"FINISHED"}
    return read_colours(floor.data), json.loads(scene.radiosity.last_report)


def _compare(ours, cycles):
    """Mean relative difference over the lit corners, and the largest difference relative to
    ``cycles + EDGE_ATOL x max``; checks that the dark corners are dark in both."""
    top = cycles.max()
    lit = cycles.max(axis=1) > LIT * top
    diff = np.abs(ours - cycles)
    dark = ~lit
    if dark.any():
        assert ours[dark].max() < LIT * top
    return (float((diff[lit] / cycles[lit]).mean()),
            float((diff[lit] / (cycles[lit] + EDGE_ATOL * top)).max()))


def _point(radius, scale=1.0, visible_diffuse=True, **extra):
    def build():
        obj = _light("POINT", (0.3, -0.2, 1.0), energy=150.0, shadow_soft_size=radius,
                     color=(1.0, 0.8, 0.6), visible_diffuse=visible_diffuse, **extra)
        obj.scale = (scale, scale, scale)
    return build


def _spot(**extra):
    # 60 deg cone, blend 0.3, tilted 25 deg about X: its edge and blend cross the floor.
    def build():
        _light("SPOT", (0.0, -0.5, 1.5), (math.radians(25.0), 0.0, 0.0), energy=300.0,
               spot_size=math.radians(60.0), spot_blend=0.3, shadow_soft_size=0.0, **extra)
    return build


def _sun(angle=0.0, blocker=False, also=None, **extra):
    def build():
        if also is not None:
            also()
        _light("SUN", (0.0, 0.0, 3.0), (math.radians(30.0), 0.0, 0.0), energy=3.0, angle=angle,
               color=(0.9, 1.0, 0.7), **extra)
        if blocker:
            # A black square 0.5 above the floor: its shadow is shifted by 0.5 tan 30 deg in
            # y, edges at x = +-0.25 and y = 0.039 / 0.539, every vertex >= 0.039 away.
            v, f = square(0.5, z=0.5, down=True)
            mesh_object("Blocker", v, f, material("black", (0.0, 0.0, 0.0), kind="diffuse"))
            v, f = square(0.5, z=0.5)
            mesh_object("Blocker top", v, f, material("black", (0.0, 0.0, 0.0), kind="diffuse"))
    return build


LIGHT_CASES = {
    "point r0": _point(0.0),
    "point r0.3 soft": _point(0.3),
    "point r0.3 hard": _point(0.3, use_soft_falloff=False),
    "point r0.3 object scale 2": _point(0.3, scale=2.0),
    "point diffuse factor 0.5 (ignored)": _point(0.0, diffuse_factor=0.5),
    "spot 60 blend 0.3": _spot(),
    "sun 30": _sun(),
    "sun 30 blocker": _sun(blocker=True),
    "sun 30 blocker, cast shadow off": _sun(blocker=True, use_shadow=False),
    "sun 30 + point without diffuse visibility": _sun(also=_point(0.0, visible_diffuse=False)),
}
#: Cycles still spends light samples on the invisible point light (they return nothing), which
#: leaves the sun's estimate noisy: measured 1.5 % per corner at 256 samples, 0.1 % at 4096.
CASE_SAMPLES = {"sun 30 + point without diffuse visibility": 16 * LIGHT_SAMPLES}
if HAS_LIGHT_NORMALIZE:
    LIGHT_CASES.update({
        "point r0 not normalized": _point(0.0, normalize=False),
        "point r0.3 not normalized": _point(0.3, normalize=False),
        "spot r0.3 not normalized": _spot(normalize=False),
        "sun angle 0.2 not normalized": _sun(angle=0.2, normalize=False),
    })
if HAS_EXPOSURE:
    LIGHT_CASES["point exposure 1 4000 K"] = _point(0.0, exposure=1.0, use_temperature=True,
                                                    temperature=4000.0)


@pytest.mark.parametrize("case", list(LIGHT_CASES))
def test_point_spot_sun_lights_match_cycles(package, case):
    floor = _grey_grid()
    LIGHT_CASES[case]()
    cycles = _cycles_corners(floor, CASE_SAMPLES.get(case, LIGHT_SAMPLES))
    ours, report = _our_corners(floor)
    mean, worst = _compare(ours, cycles)
    assert report["lights"]["count"] == 1
    assert not any("not supported" in w for w in report["warnings"])
    assert cycles.max() > 0.01
    assert mean < POINT_MEAN_RTOL and worst < POINT_MAX_RTOL, (mean, worst)
    if case == "sun 30 blocker":
        shadowed = (cycles.max(axis=1) < LIT * cycles.max()).sum()
        assert 10 <= shadowed <= 40     # the shadow falls on the floor


def test_unit_scale_keeps_cycles_blender_unit_irradiance(package):
    # Cycles ignores the unit scale: the same power 1000x further away (a model 1000x larger
    # with 1 unit = 1 mm) gives 1e-6 x the irradiance, which our bake must give too (its
    # geometry is in metres; Lights.scaled keeps the irradiance at Blender-unit distances).
    floor = _grey_grid()
    lamp = _light("POINT", (0.3, -0.2, 1.0), energy=150.0, shadow_soft_size=0.3)
    cycles_small = _cycles_corners(floor)
    ours_small, _ = _our_corners(floor)

    bpy.context.scene.unit_settings.scale_length = 0.001
    floor.scale = (1000.0, 1000.0, 1000.0)
    lamp.location = (300.0, -200.0, 1000.0)
    lamp.data.shadow_soft_size = 300.0
    props = bpy.context.scene.radiosity        # the panel's lengths are in scene units too
    props.min_element *= 1000.0
    cycles_big = _cycles_corners(floor)
    ours_big, _ = _our_corners(floor)
    np.testing.assert_allclose(cycles_big * 1e6, cycles_small, rtol=POINT_MAX_RTOL)
    mean, worst = _compare(ours_big, cycles_big)
    assert mean < POINT_MEAN_RTOL and worst < POINT_MAX_RTOL, (mean, worst)
    # Our two bakes agree to 1e-3 (measured: 1.9e-4 at 3 of 121 vertices, the rest 1e-7).
    np.testing.assert_allclose(ours_big * 1e6, ours_small, rtol=1e-3)


def test_light_conversion_reads_blender_units_and_world_axes(package):
    # The dicts handed to core.make_lights, before the unit scale: world position, world -Z.
    spot = _light("SPOT", (1.0, 2.0, 3.0), (math.radians(90.0), 0.0, 0.0), energy=80.0,
                  spot_size=1.0, spot_blend=0.25, shadow_soft_size=0.2)
    spot.scale = (2.0, 2.0, 2.0)
    bpy.context.view_layer.update()
    # An instance is only valid while the depsgraph iterator is on it.
    d = next(extract.light_dict(i) for i in bpy.context.evaluated_depsgraph_get().object_instances
             if i.object.name == "Spot")
    assert d["kind"] == "spot" and d["name"] == "Spot"
    np.testing.assert_allclose(d["position"], (1.0, 2.0, 3.0), atol=1e-6)
    np.testing.assert_allclose(d["direction"], (0.0, 1.0, 0.0), atol=1e-6)  # -Z turned 90 deg
    assert d["radius"] == pytest.approx(0.2)      # object scale ignored, as in Cycles
    assert d["power"] == pytest.approx(80.0) and d["spot_size"] == pytest.approx(1.0)
    assert d["shadow"] and d["soft_falloff"]


def test_unsupported_light_features_warn_and_a_dark_light_is_no_light(package):
    _grey_grid()
    spot = _light("SPOT", (0.0, 0.0, 1.0), energy=100.0)
    spot.scale = (1.0, 2.0, 1.0)
    noded = _light("POINT", (0.5, 0.0, 1.0), energy=100.0)
    noded.name = "Noded"
    noded.data.use_nodes = True        # the default tree changes nothing: no warning yet
    assert not any("node trees" in w
                   for w in extract.extract(bpy.context.evaluated_depsgraph_get()).warnings)
    noded.data.node_tree.nodes["Emission"].inputs["Strength"].default_value = 2.0
    ext = extract.extract(bpy.context.evaluated_depsgraph_get())
    text = " | ".join(ext.warnings)
    assert "non-uniform scale" in text and "'Spot'" in text
    assert "node trees" in text and "'Noded'" in text
    assert ext.lights == 2 and ext.area_lights == 0 and len(ext.arrays["lights"]) == 2
    # Point and sun lights are no longer "not supported".
    assert "Point lights" not in text
    bpy.data.objects.remove(spot)
    bpy.data.objects.remove(noded)
    dark = _light("POINT", (0.0, 0.0, 1.0), energy=0.0)
    with pytest.raises(RuntimeError, match="No light"):
        bpy.ops.radiosity.bake()
    dark.data.energy = -10.0
    with pytest.raises(RuntimeError, match="power must be >= 0"):
        bpy.ops.radiosity.bake()


# ---- measured distributions (IES / LDT files on point and spot lights) ---------------------

photometry = importlib.import_module(PACKAGE.__name__ + ".core.photometry")

#: A published IES file (quadrant symmetric: its C0 and C90 planes differ by 15 % at gamma 5 deg);
#: source in tests/core/data/README.md.
IES_FILE = Path(__file__).parents[1] / "core" / "data" / "lithonia_ela_cds.ies"

#: Our bake against the core's closed form at the grid's corners: 2e-3 for where the light is
#: evaluated (a corner's gather point sits 1e-3 x the face's size inside it,
#: tests/core/test_direct_lights.py) plus the file's slope over the angle that inset turns the
#: direction (11 %/deg x 0.2 mm / 1 m = 1e-3): 3e-3.
IES_RTOL = 3e-3


def _ies_closed_form(floor, lamp, phot, scale):
    """rho E / pi at *floor*'s corners under *lamp* (object) with distribution *phot*:
    E = power / (4 pi) x f(dir) x cos / d^2, nadir the lamp's -Z, C0 its -Y, C90 its -X."""
    mesh = floor.data
    co = np.empty(len(mesh.vertices) * 3)
    mesh.vertices.foreach_get("co", co)
    cv = np.empty(len(mesh.loops), dtype=np.int64)
    mesh.loops.foreach_get("vertex_index", cv)
    m = np.array(floor.matrix_world)
    pts = co.reshape(-1, 3)[cv] @ m[:3, :3].T + m[:3, 3]
    r = np.array(lamp.matrix_world)[:3, :3]
    nadir, c0, c90 = -r[:, 2], -r[:, 1], -r[:, 0]
    d = pts - np.array(lamp.matrix_world)[:3, 3]
    dist = np.linalg.norm(d, axis=1)
    u = d / dist[:, None]
    cd = phot.intensity(np.arccos(np.clip(u @ nadir, -1, 1)), np.arctan2(u @ c90, u @ c0))
    gain = 4 * np.pi / phot.flux() if scale == "POWER" else 4 * np.pi / 177.83
    e = lamp.data.energy / (4 * np.pi) * gain * cd * np.maximum(-u[:, 2], 0) / dist ** 2
    return 0.5 * e[:, None] * np.array(lamp.data.color[:3]) / np.pi


@pytest.mark.parametrize("scale", ["POWER", "CYCLES"])
def test_ies_file_on_a_light_bakes_its_distribution(package, tmp_path, scale):
    """The light's radiosity_ies file (relative to the saved .blend) shapes its light: our bake
    matches the core's closed form, turned with the light (30 deg about Z), and differs from the
    same light without the file."""
    floor = _grey_grid()
    lamp = _light("POINT", (0.3, -0.2, 1.0), (0.0, 0.0, math.radians(30.0)), energy=150.0,
                  shadow_soft_size=0.0, color=(1.0, 0.8, 0.6))
    plain, _ = _our_corners(floor)
    (tmp_path / "lamp.ies").write_bytes(IES_FILE.read_bytes())
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "scene.blend"))
    lamp.data.radiosity_ies = "//lamp.ies"
    lamp.data.radiosity_ies_scale = scale
    ours, report = _our_corners(floor)
    want = _ies_closed_form(floor, lamp, photometry.read_ies(IES_FILE), scale)
    assert report["lights"]["count"] == 1
    np.testing.assert_allclose(ours, want, rtol=IES_RTOL, atol=1e-4 * want.max())
    assert np.abs(ours - plain).max() > 0.2 * plain.max()


def test_an_unreadable_ies_file_stops_the_bake_naming_the_light(package, tmp_path):
    _grey_grid()
    lamp = _light("SPOT", (0.0, 0.0, 1.0), energy=100.0)
    lamp.name = "Desk lamp"
    lamp.data.radiosity_ies = str(tmp_path / "missing.ies")
    with pytest.raises(RuntimeError,
                       match=r'light "Desk lamp": its IES / LDT file .*missing\.ies'):
        bpy.ops.radiosity.bake()
    (tmp_path / "broken.ies").write_text("IESNA:LM-63-2002\nTILT=NONE\n1 -1 1 3\n")
    lamp.data.radiosity_ies = str(tmp_path / "broken.ies")
    with pytest.raises(RuntimeError, match=r'light "Desk lamp".*broken\.ies: expected'):
        bpy.ops.radiosity.bake()


#: Ours ('CYCLES' scale) against Cycles' own IES Texture node on the light: Cycles interpolates
#: the table bicubically, we bilinearly; on this file's steep, integer-rounded table the two
#: differ by 0.9 % mean and 2.5 % worst with bpy 5.0.1, 1.3 % and 5 % with 4.2 (radius 0: no
#: Monte Carlo noise). The distribution turned 90 deg about the light's axis would differ by
#: 6.5 % mean and 20 % worst (measured), so the bounds also pin the orientation.
IES_CYCLES_MEAN, IES_CYCLES_MAX = 0.025, 0.08


def test_ies_file_matches_cycles_ies_texture_node(package):
    floor = _grey_grid()
    lamp = _light("POINT", (0.3, -0.2, 1.0), (0.0, 0.0, math.radians(30.0)), energy=150.0,
                  shadow_soft_size=0.0, color=(1.0, 0.8, 0.6))
    lamp.data.use_nodes = True
    tree = lamp.data.node_tree
    ies = tree.nodes.new("ShaderNodeTexIES")
    ies.mode = "EXTERNAL"
    ies.filepath = str(IES_FILE)
    tree.links.new(ies.outputs["Fac"], tree.nodes["Emission"].inputs["Strength"])
    cycles = _cycles_corners(floor)
    lamp.data.radiosity_ies = str(IES_FILE)
    lamp.data.radiosity_ies_scale = "CYCLES"
    ours, _ = _our_corners(floor)
    mean, worst = _compare(ours, cycles)
    assert cycles.max() > 1.0
    assert mean < IES_CYCLES_MEAN and worst < IES_CYCLES_MAX, (mean, worst)
