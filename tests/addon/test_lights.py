"""The area-light power -> radiance conversion, measured against Cycles itself.

Oracle: Cycles. The same grey floor is baked by Cycles twice, once under the area light and once
under an emissive polygon of the radiance our conversion assigns to that light; the two bakes must
agree. 64 samples keep each bake under a second; the tolerance (3 %) covers their Monte Carlo noise
(two bakes of 400 corners each, measured spread ~0.5 %).
"""

import math

import bpy
import numpy as np
import pytest

from conftest import PACKAGE
from helpers import material, mesh_object

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
