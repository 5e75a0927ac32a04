"""The extension as Blender installs it: validate, build, install the zip, register, unregister.

Runs under bpy 5.0.1 (.venv) and bpy 4.2 LTS (.venv-bpy42), the oldest Blender the manifest admits.
"""

import glob
import os
import shutil
import subprocess
import sys
import textwrap
import zipfile

import bpy
import pytest

from conftest import PACKAGE, ROOT

CLI = os.path.join(bpy.utils.system_resource("SCRIPTS"), "addons_core", "bl_pkg", "cli",
                   "blender_ext.py")


def cli(*args):
    return subprocess.run([sys.executable, CLI, *map(str, args)], capture_output=True, text=True,
                          timeout=120)


@pytest.fixture(scope="module")
def built_zip(tmp_path_factory):
    out = tmp_path_factory.mktemp("build")
    proc = cli("build", "--source-dir", ROOT, "--output-dir", out)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    zips = glob.glob(os.path.join(out, "*.zip"))
    assert len(zips) == 1
    return zips[0]


def test_manifest_validates():
    proc = cli("validate", ROOT)
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_zip_holds_the_add_on_and_leaves_the_rest_out(built_zip):
    names = zipfile.ZipFile(built_zip).namelist()
    for needed in ("blender_manifest.toml", "__init__.py", "radiosity_addon/__init__.py",
                   "radiosity_addon/batch.py", "core/__init__.py", "core/bake.py"):
        assert needed in names
    for left_out in ("tests/", "sample_blends/", "scripts/", "docs/", "bench/", ".venv", ".ci/",
                     "__pycache__", ".git/", ".blend"):
        assert not any(left_out in n for n in names), left_out


INSTALL_SCRIPT = textwrap.dedent("""
    import sys, bpy, numpy as np
    import addon_utils
    bpy.ops.extensions.package_install_files(filepath=sys.argv[-1], repo="user_default",
                                             enable_on_install=True)
    mods = [m for m in bpy.context.preferences.addons.keys() if m.endswith(".radiosity_baker")]
    assert mods == ["bl_ext.user_default.radiosity_baker"], mods
    assert hasattr(bpy.types.Scene, "radiosity") and "bake" in dir(bpy.ops.radiosity)
    # A bake through the installed copy: a closed furnace box, L = Le / (1 - rho) = 2.
    bpy.ops.wm.read_homefile(use_factory_startup=True, use_empty=True)
    assert bpy.context.preferences.addons.get(mods[0]) is not None
    verts = [(x, y, z) for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]
    faces = [(2, 3, 1, 0), (5, 7, 6, 4), (1, 5, 4, 0), (6, 7, 3, 2), (4, 6, 2, 0), (3, 7, 5, 1)]
    mesh = bpy.data.meshes.new("box")          # faces wound inward: the inside is the front
    mesh.from_pydata(verts, [], faces)
    cube = bpy.data.objects.new("box", mesh)
    bpy.context.scene.collection.objects.link(cube)
    mat = bpy.data.materials.new("m")
    if bpy.app.version < (5, 0, 0):
        mat.use_nodes = True
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (0.5, 0.5, 0.5, 1)
    bsdf.inputs["Emission Color"].default_value = (1, 1, 1, 1)
    bsdf.inputs["Emission Strength"].default_value = 1.0
    cube.data.materials.append(mat)
    bpy.context.scene.radiosity.patch_size = 1.0
    bpy.context.scene.radiosity.resolution = 16
    assert bpy.ops.radiosity.bake() == {"FINISHED"}
    attr = cube.data.color_attributes["Radiosity"]
    buf = np.empty(len(attr.data) * 4, np.float32)
    attr.data.foreach_get("color", buf)
    assert np.allclose(buf.reshape(-1, 4)[:, :3], 2.0, rtol=1e-4), buf
    addon_utils.disable(mods[0])
    assert not hasattr(bpy.types.Scene, "radiosity")
    print("INSTALLED-OK")
    # The bpy 4.2 module can crash while the interpreter shuts down, before Blender removes its
    # session folder: remove it and leave at once.
    import os, shutil
    sys.stdout.flush()
    shutil.rmtree(bpy.app.tempdir, ignore_errors=True)
    os._exit(0)
""")


def test_zip_installs_registers_and_bakes(built_zip, tmp_path):
    (tmp_path / "tmp").mkdir()
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "user"),
               TMPDIR=str(tmp_path / "tmp"))
    script = tmp_path / "install.py"
    script.write_text(INSTALL_SCRIPT)
    proc = subprocess.run([sys.executable, str(script), built_zip], capture_output=True,
                          text=True, timeout=180, env=env, cwd=str(tmp_path))
    assert "INSTALLED-OK" in proc.stdout, proc.stdout[-3000:] + proc.stderr[-3000:]
    assert os.path.isdir(tmp_path / "user" / "extensions" / "user_default" / "radiosity_baker")
    assert os.listdir(tmp_path / "tmp") == []  # Blender's session folder is gone


def _registered_state():
    addon = PACKAGE.radiosity_addon
    classes = addon.props.CLASSES + addon.operators.CLASSES + addon.panels.CLASSES
    return (hasattr(bpy.types.Scene, "radiosity"),
            hasattr(bpy.types.WindowManager, "radiosity_progress"),
            hasattr(bpy.types.WindowManager, "radiosity_status"),
            hasattr(bpy.types.WindowManager, "radiosity_show_advanced"),
            "bake" in dir(bpy.ops.radiosity),
            all(cls.is_registered for cls in classes),
            any(cls.is_registered for cls in classes))


def test_register_unregister_twice_leaves_nothing_behind():
    was = _registered_state()[0]
    if was:  # the session's registration (other test modules) is restored at the end
        PACKAGE.unregister()
    try:
        assert _registered_state() == (False,) * 7
        for _ in range(2):
            PACKAGE.register()
            assert _registered_state() == (True,) * 7
            PACKAGE.unregister()
            assert _registered_state() == (False,) * 7
    finally:
        if was:
            PACKAGE.register()


def readme_install_blocks():
    """The ```sh blocks of README.md's Install section, as shell text."""
    with open(os.path.join(ROOT, "README.md"), encoding="utf-8") as fh:
        text = fh.read()
    section = text.split("### Install", 1)[1].split("\n### ", 1)[0]
    return [b.split("\n", 1)[1] for b in section.split("```")[1::2] if b.startswith("sh\n")]


def fresh_clone(dest):
    """The repository's tracked files copied to *dest* (what a fresh clone holds: no dist/)."""
    files = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True,
                           text=True).stdout.split("\0")
    for name in filter(None, files):
        target = os.path.join(dest, name)
        os.makedirs(os.path.dirname(target), exist_ok=True)
        if os.path.isfile(os.path.join(ROOT, name)):
            shutil.copy2(os.path.join(ROOT, name), target)
    return dest


def test_readme_build_command_works_in_a_fresh_clone(tmp_path):
    blocks = [b for b in readme_install_blocks() if b.startswith("mkdir -p dist\n.venv/")]
    assert len(blocks) == 1, readme_install_blocks()
    clone = fresh_clone(str(tmp_path / "clone"))
    assert not os.path.exists(os.path.join(clone, "dist"))
    os.symlink(os.path.join(ROOT, ".venv"), os.path.join(clone, ".venv"))
    proc = subprocess.run(["bash", "-euc", blocks[0]], cwd=clone, capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert len(glob.glob(os.path.join(clone, "dist", "radiosity_baker-*.zip"))) == 1
