"""Lux in Blender: the 'Radiosity Lux' attribute of baked meshes and calculation surfaces, their
EN 12464-1 figures in the report, Clear Bake, and the batch's --calc-surface / --lux.

Oracle: a 1000 W point light of radius 0 over a one-quad floor, no other surface above the work
plane, so every point the plane and the floor measure takes the inverse-square law,
E = 683 lm/W x P / (4 pi) x cos / d^2 (Blender's point-light conversion, measured against Cycles
in test_lights.py). Tolerances: grid points 1e-4 (they are lifted 1e-6 of the scene's size off the
plane); vertex values 5e-3 (a corner's gather point sits 1e-3 of its face's size inside it).
"""

import csv
import json

import bpy
import numpy as np
import pytest

from conftest import PACKAGE
from helpers import material, mesh_object, square

LIGHT = np.array([0.3, 0.2, 2.0])
POWER = 1000.0


def _law(points):
    d = LIGHT - np.asarray(points, dtype=np.float64)
    r2 = (d * d).sum(axis=1)
    return 683.0 * POWER / (4 * np.pi) * d[:, 2] / np.sqrt(r2) / r2


def _scene():
    bpy.ops.wm.read_homefile(use_factory_startup=True, use_empty=True)
    floor = mesh_object("Floor", *square(4.0), material("grey", (0.5, 0.5, 0.5), kind="diffuse"))
    plane = mesh_object("WorkPlane", *square(2.0, z=0.8), material("any", (0.9, 0.9, 0.9)))
    lamp = bpy.data.lights.new("Lamp", "POINT")
    lamp.energy, lamp.shadow_soft_size = POWER, 0.0
    obj = bpy.data.objects.new("Lamp", lamp)
    obj.location = tuple(LIGHT)
    bpy.context.scene.collection.objects.link(obj)
    return floor, plane


def _values(mesh, domain):
    attr = mesh.attributes["Radiosity Lux"]
    assert attr.domain == domain and attr.data_type == "FLOAT"
    buf = np.empty(len(attr.data), dtype=np.float32)
    attr.data.foreach_get("value", buf)
    return buf.astype(np.float64)


def _grid_2m():
    # EN 12464-1 for a 2 m square: p = 0.2 x 5^log10(2) = 0.324 m -> 7 x 7 cells, centres.
    c = (np.arange(7) + 0.5) * 2.0 / 7 - 1.0
    x, y = np.meshgrid(c, c, indexing="ij")
    return np.stack([x.ravel(), y.ravel(), np.full(49, 0.8)], axis=1)


@pytest.mark.parametrize("mode", ["MESH", "VERTICES"])
def test_calculation_surface_reports_en_figures_and_blocks_nothing(package, mode):
    floor, plane = _scene()
    before = {a.name for a in plane.data.attributes}
    plane.radiosity_calc_surface = True
    scene = bpy.context.scene
    scene.radiosity.output_mode = mode
    assert bpy.ops.radiosity.bake() == {"FINISHED"}
    report = json.loads(scene.radiosity.last_report)
    (surf,) = report["calculation_surfaces"]
    want = _law(_grid_2m())
    assert surf["object"] == "WorkPlane" and surf["points"] == 49
    assert surf["Emin"] == pytest.approx(want.min(), rel=1e-4)
    assert surf["Emax"] == pytest.approx(want.max(), rel=1e-4)
    assert surf["Eavg"] == pytest.approx(want.mean(), rel=1e-4)
    assert surf["U0"] == pytest.approx(want.min() / want.mean(), rel=1e-4)
    # The panel's Last Bake shows the figures.
    lines = PACKAGE.radiosity_addon.panels.summary_lines(scene.radiosity.last_report)
    assert any(t.startswith("WorkPlane: Eavg ") and i == "LIGHT" for t, i in lines)
    # The plane's own vertices carry E; it was not baked (its mesh is the user's).
    assert not plane.data.get("radiosity_baked")
    co = np.array([v.co for v in plane.data.vertices])
    np.testing.assert_allclose(_values(plane.data, "POINT"), _law(co), rtol=5e-3)
    # The floor under it is lit as if the plane were not there: E at every corner (a blocking
    # plane would leave the 2 m square under it in its shadow).
    mesh = floor.data
    cv = np.array([lp.vertex_index for lp in mesh.loops])
    pos = np.array([v.co for v in mesh.vertices])[cv]
    np.testing.assert_allclose(_values(mesh, "CORNER"), _law(pos), rtol=5e-3)
    if mode == "MESH":
        assert len(mesh.vertices) > 4          # the radiosity mesh followed the light
    # Clear Bake leaves both as they were.
    assert bpy.ops.radiosity.clear() == {"FINISHED"}
    assert {a.name for a in plane.data.attributes} == before
    assert "Radiosity Lux" not in floor.data.attributes and len(floor.data.vertices) == 4


def test_a_baked_calculation_surface_is_refused_before_the_bake(package):
    _, plane = _scene()
    assert bpy.ops.radiosity.bake() == {"FINISHED"}           # the plane is baked as a mesh
    plane.radiosity_calc_surface = True
    with pytest.raises(RuntimeError, match="Calculation surface 'WorkPlane'.*Clear Bake"):
        bpy.ops.radiosity.bake()


def _batch(*args):
    from test_batch import run_batch
    return run_batch(*args)


def test_batch_writes_the_grid_as_csv_and_json(package, tmp_path):
    _scene()
    src = tmp_path / "room.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(src), check_existing=False)
    out = tmp_path / "baked.blend"
    table = tmp_path / "lux.csv"
    proc = _batch(src, "--output", out, "--calc-surface", "WorkPlane", "--lux", table)
    assert proc.returncode == 0, proc.stderr
    with open(table, newline="") as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == ["object", "x", "y", "z", "lux"] and len(rows) == 50
    pts = np.array([[float(v) for v in r[1:4]] for r in rows[1:]])
    lux = np.array([float(r[4]) for r in rows[1:]])
    np.testing.assert_allclose(lux, _law(pts), rtol=1e-4)
    assert np.allclose(np.sort(pts[:, 0]), np.sort(_grid_2m()[:, 0]))
    as_json = tmp_path / "lux.json"
    proc = _batch(src, "--output", tmp_path / "b2.blend", "--calc-surface", "WorkPlane",
                  "--lux", as_json)
    assert proc.returncode == 0, proc.stderr
    (surf,) = json.loads(as_json.read_text())
    assert surf["object"] == "WorkPlane" and len(surf["grid"]) == len(surf["lux"]) == 49
    assert surf["Eavg"] == pytest.approx(_law(np.array(surf["grid"])).mean(), rel=1e-4)


@pytest.mark.parametrize("args, message", [
    (["--lux", "{tmp}/lux.csv"], "--lux: no calculation surface"),
    (["--calc-surface", "Nope", "--lux", "{tmp}/lux.csv"], "--calc-surface Nope: the scene"),
    (["--calc-surface", "WorkPlane", "--lux", "{tmp}/lux.txt"], "give a .csv or .json"),
])
def test_batch_lux_mistakes_stop_before_the_bake(package, tmp_path, args, message):
    _scene()
    src = tmp_path / "room.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(src), check_existing=False)
    from test_batch import one_error_line
    proc = _batch(src, "--output", tmp_path / "o.blend",
                  *[a.format(tmp=tmp_path) for a in args])
    assert message in one_error_line(proc)
    assert not (tmp_path / "o.blend").exists()


