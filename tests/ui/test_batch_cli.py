"""The batch bake and the README's commands through a real Blender executable (Debian's 4.3).

The bpy module of the other tiers runs batch.py as a plain script; here it runs as users of a
Blender executable run it, ``blender -b scene.blend --python radiosity_addon/batch.py -- ...``,
where an uncaught error used to print a traceback and still exit 0. Inside the cached Debian 13
root of scripts/real_blender.sh (needs root; fails, never skips, when the root cannot be made).
"""

import json
import os
import shutil
import subprocess

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
OUT = os.path.join(ROOT, "out", "ui", "cli")
REL = "out/ui/cli"  # the same folder, as Blender inside the root sees it from /project
BATCH = "radiosity_addon/batch.py"
SCENE = "sample_blends/cornell_box.blend"
FAST = "--patch-size 0.3 --resolution 16"


def in_root(script, cwd="/project", timeout=600):
    """Run *script* with sh inside the root; returns the CompletedProcess (stdout and stderr)."""
    proc = subprocess.run(["bash", os.path.join(ROOT, "scripts", "real_blender.sh"), "sh", "-c",
                           f"cd {cwd} && {script}"], capture_output=True, text=True,
                          timeout=timeout, cwd=ROOT)
    return proc


@pytest.fixture(scope="module", autouse=True)
def out_dir():
    shutil.rmtree(OUT, ignore_errors=True)
    os.makedirs(OUT)
    yield OUT


def console(proc):
    return proc.stdout + proc.stderr


def test_blender_batch_bakes_renders_and_keeps_the_console_clean():
    proc = in_root(f"blender -b {SCENE} --python {BATCH} -- --output {REL}/b.blend "
                   f"--render {REL}/b.png --report {REL}/b.json {FAST}")
    text = console(proc)
    assert proc.returncode == 0, text[-3000:]
    for noise in (".radiosity-", "Saved copy", "EGL", "Traceback", "Saved:"):
        assert noise not in text, text
    said = [ln for ln in text.splitlines() if ln.startswith("radiosity-batch: ")]
    assert [ln.split(" -> ")[1] for ln in said] == [f"{REL}/b.blend", f"{REL}/b.png",
                                                    f"{REL}/b.json"]
    assert sorted(os.listdir(OUT)) == ["b.blend", "b.json", "b.png"]
    assert json.load(open(os.path.join(OUT, "b.json")))["patches"] > 0


def test_missing_numpy_exits_non_zero_and_says_how_to_get_it():
    # Debian's Blender uses the system Python: without python3-numpy, 'import numpy' fails.
    block = "import sys; sys.modules['numpy'] = None"
    proc = in_root(f"blender -b {SCENE} --python-expr \"{block}\" --python {BATCH} -- "
                   f"--output {REL}/n.blend")
    assert proc.returncode == 1, console(proc)
    assert "NumPy is missing" in proc.stderr and "apt install python3-numpy" in proc.stderr
    assert "Traceback" not in console(proc)
    assert not os.path.exists(os.path.join(OUT, "n.blend"))


def test_forgotten_double_dash_says_what_to_type():
    proc = in_root(f"blender -b {SCENE} --python {BATCH} --output {REL}/c.blend")
    assert proc.returncode == 1, console(proc)
    assert (f"put -- between Blender's options and the batch options: blender -b {SCENE} "
            f"--python {BATCH} -- --output {REL}/c.blend") in proc.stderr
    assert "Traceback" not in console(proc)


def test_missing_report_folder_stops_before_the_bake():
    proc = in_root(f"blender -b {SCENE} --python {BATCH} -- --output {REL}/m.blend "
                   f"--report {REL}/nowhere/r.json")
    assert proc.returncode == 1
    assert f"--report {REL}/nowhere/r.json: the folder {REL}/nowhere does not exist" in proc.stderr
    assert not os.path.exists(os.path.join(OUT, "m.blend"))


def test_readme_blender_build_command_works_in_a_fresh_clone():
    with open(os.path.join(ROOT, "README.md"), encoding="utf-8") as fh:
        section = fh.read().split("### Install", 1)[1].split("\n### ", 1)[0]
    blocks = [b.split("\n", 1)[1] for b in section.split("```")[1::2]
              if b.startswith("sh\n") and "\nblender --command extension build" in b]
    assert len(blocks) == 1, section
    clone = os.path.join(OUT, "clone")
    files = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, text=True,
                           check=True).stdout.split("\0")
    for name in filter(None, files):
        if os.path.isfile(os.path.join(ROOT, name)):
            os.makedirs(os.path.dirname(os.path.join(clone, name)), exist_ok=True)
            shutil.copy2(os.path.join(ROOT, name), os.path.join(clone, name))
    assert not os.path.exists(os.path.join(clone, "dist"))
    script = blocks[0].strip().replace("\n", " && ")
    proc = in_root(script, cwd=f"/project/{REL}/clone")
    assert proc.returncode == 0, console(proc)
    zips = [n for n in os.listdir(os.path.join(clone, "dist")) if n.endswith(".zip")]
    assert len(zips) == 1
    shutil.rmtree(clone)
