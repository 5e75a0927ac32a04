"""The headless batch script, run as users run it: a separate Python process with the bpy module."""

import hashlib
import json
import os
import shutil
import subprocess
import sys

import bpy
import numpy as np
import pytest

from conftest import ROOT
from helpers import material, mesh_object, read_colours, square

BATCH = os.path.join(ROOT, "radiosity_addon", "batch.py")
CORNELL = os.path.join(ROOT, "sample_blends", "cornell_box.blend")

#: Settings for batch bakes of the Cornell box in tests: its surfaces are 5 cm grids, so the patch
#: size changes nothing below 5 cm; a coarse hemicube keeps the bake to a few seconds.
FAST = ["--patch-size", "0.2", "--resolution", "16"]


def run_batch(*args, timeout=240):
    proc = subprocess.run([sys.executable, BATCH, *map(str, args)], capture_output=True,
                          text=True, timeout=timeout, cwd=ROOT)
    return proc


def sha256(path):
    with open(path, "rb") as fh:
        return hashlib.sha256(fh.read()).hexdigest()


def one_error_line(proc):
    lines = [ln for ln in proc.stderr.splitlines() if ln.startswith("radiosity-batch:")]
    assert proc.returncode != 0
    assert len(lines) == 1, proc.stderr
    return lines[0]


def save_scene(path, *, light=True, meshes=True, patch_size=0.7):
    """Save a small scene (floor + emitter) with stored bake settings to *path*."""
    bpy.ops.wm.read_homefile(use_factory_startup=True, use_empty=True)
    if meshes:
        mesh_object("Floor", *square(2.0), material("grey", (0.5, 0.5, 0.5)))
    if meshes and light:
        mesh_object("Lamp", *square(1.0, z=1.0, down=True),
                    material("lamp", (0, 0, 0), emission=(1, 1, 1), strength=3.0,
                             kind="emission"))
    if hasattr(bpy.types.Scene, "radiosity"):
        bpy.context.scene.radiosity.patch_size = patch_size
    bpy.ops.wm.save_as_mainfile(filepath=str(path), check_existing=False)


def test_cornell_batch_bake_report_render_and_input_untouched(package, tmp_path):
    src = tmp_path / "cornell.blend"
    shutil.copyfile(CORNELL, src)
    digest = sha256(src)
    out, report, png = tmp_path / "baked.blend", tmp_path / "r.json", tmp_path / "cornell.png"
    proc = run_batch(src, "--output", out, "--report", report, "--render", png, *FAST)
    assert proc.returncode == 0, proc.stderr
    assert sha256(src) == digest
    assert sorted(os.listdir(tmp_path)) == ["baked.blend", "cornell.blend", "cornell.png", "r.json"]
    data = json.loads(report.read_text())
    for key in ("settings", "patches", "timings", "iterations", "residual", "energy", "warnings"):
        assert key in data
    assert data["settings"]["patch_size"] == pytest.approx(0.2)
    assert data["settings"]["resolution"] == 16

    bpy.ops.wm.open_mainfile(filepath=str(out), load_ui=False)
    wall = bpy.data.objects["Left_Wall"].data
    walls = read_colours(wall)
    assert walls.shape == (len(wall.loops), 3) and np.all(walls[:, 0] > 2 * walls[:, 1])

    bpy.ops.image.open(filepath=str(png))
    img = bpy.data.images[png.name]
    assert tuple(img.size) == (512, 512)
    px = np.empty(512 * 512 * img.channels, np.float32)
    img.pixels.foreach_get(px)
    rgb = px.reshape(512, 512, -1)[:, :, :3]
    # Left third is the red wall (red dominant), right third the green wall (green dominant).
    left, right = rgb[200:300, 20:80].mean((0, 1)), rgb[200:300, 440:490].mean((0, 1))
    assert left[0] > 1.5 * left[1] and right[1] > 1.2 * right[0]


def test_same_bake_as_the_operator_and_defaults_from_the_file(package, tmp_path):
    src, out = tmp_path / "scene.blend", tmp_path / "out.blend"
    save_scene(src, patch_size=0.7)
    proc = run_batch(src, "--output", out, "--report", tmp_path / "r.json")
    assert proc.returncode == 0, proc.stderr
    assert json.loads((tmp_path / "r.json").read_text())["settings"]["patch_size"] == \
        pytest.approx(0.7)
    bpy.ops.wm.open_mainfile(filepath=str(out), load_ui=False)
    batch = read_colours(bpy.data.objects["Floor"].data)
    bpy.ops.wm.open_mainfile(filepath=str(src), load_ui=False)
    assert bpy.ops.radiosity.bake() == {"FINISHED"}
    np.testing.assert_array_equal(read_colours(bpy.data.objects["Floor"].data), batch)


def test_corner_and_refinement_options_reach_the_bake(package, tmp_path):
    src, out = tmp_path / "scene.blend", tmp_path / "out.blend"
    save_scene(src, patch_size=0.5)
    proc = run_batch(src, "--output", out, "--report", tmp_path / "r.json",
                     "--corners", "average", "--refine-levels", "1",
                     "--output-mode", "vertices")
    assert proc.returncode == 0, proc.stderr
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["settings"]["corners"] == "average"
    assert report["settings"]["refine_levels"] == 1
    assert report["refinement"][0]["level"] == 0
    assert "elements" not in report          # receiver elements serve the vertex gather only


def test_element_levels_reach_the_bake(package, tmp_path):
    src = tmp_path / "scene.blend"
    save_scene(src, patch_size=0.5)
    reports = {}
    for levels in ("0", "1"):
        proc = run_batch(src, "--output", tmp_path / ("out%s.blend" % levels),
                         "--report", tmp_path / ("r%s.json" % levels), "--element-levels", levels)
        assert proc.returncode == 0, proc.stderr
        reports[levels] = json.loads((tmp_path / ("r%s.json" % levels)).read_text())
    assert reports["0"]["settings"]["element_levels"] == 0
    assert reports["1"]["settings"]["element_levels"] == 1
    assert "elements" not in reports["0"]
    assert len(reports["1"]["elements"]["levels"]) <= 1


def test_contact_cuts_reach_the_bake(package, tmp_path):
    # The Cornell box's blocks stand on the floor: the default bake cuts the floor's patches
    # along their outlines and the shadow lines that leave their corners (--shadow-cuts),
    # --no-shadow-cuts along the outlines only, --no-contact-cuts cuts nothing.
    src = tmp_path / "cornell.blend"
    shutil.copyfile(CORNELL, src)
    reports = {}
    for name, extra in (("outlines", ["--no-shadow-cuts"]), ("off", ["--no-contact-cuts"]),
                        ("on", ["--shadow-cuts"])):
        proc = run_batch(src, "--output", tmp_path / ("%s.blend" % name), "--report",
                         tmp_path / ("%s.json" % name), *FAST, *extra)
        assert proc.returncode == 0, proc.stderr
        reports[name] = json.loads((tmp_path / ("%s.json" % name)).read_text())
    assert reports["on"]["settings"]["contact_cuts"] is True
    assert reports["off"]["settings"]["contact_cuts"] is False
    assert reports["on"]["contacts"]["cut"] > 0
    on, outlines = reports["on"]["contacts"], reports["outlines"]["contacts"]
    assert reports["outlines"]["settings"]["shadow_cuts"] is False
    assert reports["on"]["settings"]["shadow_cuts"] is True
    assert on["shadow_lines"] > 0 and on["shadow_added"] > 0 and "shadow_lines" not in outlines
    assert reports["outlines"]["patches"] == reports["off"]["patches"] + outlines["added"]
    assert reports["on"]["patches"] == reports["outlines"]["patches"] + on["shadow_added"]
    assert "contacts" not in reports["off"]


def test_in_place_overwrites_only_when_asked(package, tmp_path):
    src = tmp_path / "scene.blend"
    save_scene(src)
    line = one_error_line(run_batch(src, "--output", src))
    assert "--in-place" in line
    digest = sha256(src)
    proc = run_batch(src, "--in-place")
    assert proc.returncode == 0, proc.stderr
    assert sha256(src) != digest
    assert sorted(os.listdir(tmp_path)) == ["scene.blend"]  # no temporary or backup left
    bpy.ops.wm.open_mainfile(filepath=str(src), load_ui=False)
    assert "Radiosity" in bpy.data.objects["Floor"].data.color_attributes


@pytest.mark.parametrize("args, expect", [
    (["--method", "magic"], "bad option"),
    (["--patch-size", "-1"], "bad option"),
    (["--resolution", "abc"], "bad option"),
    (["--frobnicate"], "bad option"),
    (["--resolution", "33"], "resolution"),
    (["--corners", "median"], "bad option"),
    (["--refine-levels", "7"], "bad option"),
    (["--element-levels", "4"], "bad option"),
    ([], "--output"),
])
def test_bad_options_exit_non_zero_with_one_line(package, tmp_path, args, expect):
    src = tmp_path / "scene.blend"
    save_scene(src)
    digest = sha256(src)
    out = ["--output", tmp_path / "o.blend"] if args else []
    line = one_error_line(run_batch(src, *out, *args))
    assert expect in line
    assert sha256(src) == digest and not (tmp_path / "o.blend").exists()


@pytest.mark.parametrize("case, expect", [
    ("missing", "not found"), ("no meshes", "Nothing to bake"), ("no light", "No light"),
])
def test_scene_errors_exit_non_zero_with_one_line(package, tmp_path, case, expect):
    src = tmp_path / "scene.blend"
    if case != "missing":
        save_scene(src, meshes=case != "no meshes", light=case != "no light")
    line = one_error_line(run_batch(src, "--output", tmp_path / "o.blend"))
    assert expect in line
    assert not (tmp_path / "o.blend").exists()


def test_render_needs_a_camera(package, tmp_path):
    src = tmp_path / "scene.blend"
    save_scene(src)
    line = one_error_line(run_batch(src, "--output", tmp_path / "o.blend", "--render",
                                    tmp_path / "x.png"))
    assert "camera" in line


def test_console_names_no_temporary_file_and_no_egl_noise(package, tmp_path):
    src = tmp_path / "scene.blend"
    save_scene(src)
    bpy.ops.wm.open_mainfile(filepath=str(src))
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.location = (0.0, 0.0, 3.0)
    bpy.context.scene.collection.objects.link(cam)
    bpy.context.scene.camera = cam
    bpy.ops.wm.save_mainfile()
    os.remove(tmp_path / "scene.blend1")  # Blender's backup of the first save
    proc = run_batch(src, "--output", tmp_path / "o.blend", "--render", tmp_path / "o.png",
                     "--report", tmp_path / "o.json")
    assert proc.returncode == 0, proc.stderr
    console = proc.stdout + proc.stderr
    for noise in (".radiosity-", "Saved copy", "EGL", "Saved:"):
        assert noise not in console, console
    said = [ln for ln in proc.stdout.splitlines() if ln.startswith("radiosity-batch: ")]
    assert [ln.split(" -> ")[1] for ln in said] == [str(tmp_path / n)
                                                    for n in ("o.blend", "o.png", "o.json")]
    assert sorted(os.listdir(tmp_path)) == ["o.blend", "o.json", "o.png", "scene.blend"]


@pytest.mark.parametrize("option, given, expect", [
    ("--report", "missing/r.json", "the folder missing does not exist"),
    ("--render", "missing/x.png", "the folder missing does not exist"),
    ("--output", "missing/o.blend", "the folder missing does not exist"),
    ("--report", "folder", "is a folder"),
    ("--report", "o.blend", "the same file as --output"),
])
def test_output_paths_are_checked_before_the_bake(package, tmp_path, option, given, expect):
    src = tmp_path / "scene.blend"
    save_scene(src)
    (tmp_path / "folder").mkdir()
    args = ["--output", "o.blend"] if option != "--output" else []
    proc = subprocess.run([sys.executable, BATCH, str(src), *args, option, given],
                          capture_output=True, text=True, timeout=120, cwd=str(tmp_path))
    line = one_error_line(proc)
    assert f"{option} {given}: {expect}" in line, line
    assert ".radiosity-" not in proc.stdout + proc.stderr
    assert "baked" not in proc.stdout  # stopped before the bake: nothing written
    assert sorted(os.listdir(tmp_path)) == ["folder", "scene.blend"]


def test_forgotten_double_dash_says_what_to_type(package, tmp_path):
    src = tmp_path / "scene.blend"
    save_scene(src)
    # What a user types when they forget '--' (here run by the bpy module, which sees the same
    # argv a blender executable would hand to the script).
    line = one_error_line(run_batch("--background", src, "--python", BATCH,
                                    "--output", tmp_path / "o.blend"))
    assert "put -- between" in line
    assert f"--python {BATCH} -- --output {tmp_path / 'o.blend'}" in line
    assert not (tmp_path / "o.blend").exists()


def test_missing_numpy_exits_non_zero_and_says_how_to_get_it(package, tmp_path):
    src = tmp_path / "scene.blend"
    save_scene(src)
    blocker = ("import runpy, sys; sys.modules['numpy'] = None; "  # import numpy -> ImportError
               "sys.argv = sys.argv[1:]; runpy.run_path(sys.argv[0], run_name='__main__')")
    proc = subprocess.run([sys.executable, "-c", blocker, BATCH, str(src), "--output",
                           str(tmp_path / "o.blend")], capture_output=True, text=True,
                          timeout=120, cwd=ROOT)
    line = one_error_line(proc)
    assert "NumPy is missing" in line and "python3-numpy" in line
    assert "Traceback" not in proc.stderr
    assert not (tmp_path / "o.blend").exists()


def test_batch_leaves_no_blender_folder_in_tmp(package, tmp_path):
    src, tmp = tmp_path / "scene.blend", tmp_path / "tmp"
    save_scene(src)
    tmp.mkdir()
    env = dict(os.environ, TMPDIR=str(tmp), TMP=str(tmp), TEMP=str(tmp))
    for args in (["--output", tmp_path / "o.blend"], ["--output", tmp_path / "none" / "o.blend"]):
        subprocess.run([sys.executable, BATCH, str(src), *map(str, args)], capture_output=True,
                       timeout=120, env=env, cwd=ROOT)
    assert (tmp_path / "o.blend").exists()
    assert os.listdir(tmp) == []
    # ... and Blender does put its session folder there (so the check above means something).
    where = subprocess.run([sys.executable, "-c", "import bpy; print(bpy.app.tempdir)"],
                           capture_output=True, text=True, timeout=60, env=env).stdout
    assert where.strip().startswith(os.path.join(str(tmp), "blender_"))


def test_readme_caption_states_the_samples_own_settings(package):
    """The picture caption quotes what the sample fixes, no counts that drift with the core."""
    import re

    with open(os.path.join(ROOT, "README.md"), encoding="utf-8") as fh:
        caption = fh.read().split("](docs/images/cornell_box.png)", 1)[1].split("\n\n", 2)[1]
    bpy.ops.wm.open_mainfile(filepath=CORNELL, load_ui=False)
    resolution = int(re.search(r"hemicube R = (\d+)", caption).group(1))
    assert resolution == bpy.context.scene.radiosity.resolution
    assert bpy.context.scene.radiosity.corners == "GATHER" and "gathered at every vertex" in caption
    assert bpy.context.scene.radiosity.output_mode == "MESH" and "radiosity mesh" in caption
    assert not re.search(r"\d[\d,]* (patches|receiver elements)", caption), caption
