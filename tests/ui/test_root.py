"""scripts/real_blender.sh itself: a root that cannot be built fails loudly, never silently."""

import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SCRIPT = os.path.join(ROOT, "scripts", "real_blender.sh")


def test_unbuildable_root_exits_non_zero_with_the_reason():
    # /proc takes no new folders: the root's parent cannot be created.
    env = dict(os.environ, RADIOSITY_REAL_BLENDER_ROOT="/proc/radiosity-baker-test/trixie")
    proc = subprocess.run(["bash", SCRIPT, "true"], capture_output=True, text=True, timeout=60,
                          env=env)
    assert proc.returncode != 0
    assert proc.stderr.startswith("real_blender.sh: ")
    assert "cannot create /proc/radiosity-baker-test" in proc.stderr


def test_cached_root_runs_a_command_in_the_project():
    proc = subprocess.run(["bash", SCRIPT, "sh", "-c", "pwd; test -f blender_manifest.toml && "
                           "blender --version | head -1"], capture_output=True, text=True,
                          timeout=900)
    assert proc.returncode == 0, proc.stderr[-2000:]
    lines = proc.stdout.splitlines()
    assert lines[0] == "/project" and lines[1].startswith("Blender 4.3")
    # Every bind mount is gone afterwards.
    root = os.environ.get("RADIOSITY_REAL_BLENDER_ROOT", "/var/cache/radiosity-baker/trixie")
    with open("/proc/mounts", encoding="utf-8") as fh:
        assert not [ln for ln in fh if f" {root}/" in ln]


def test_a_stage_that_could_not_run_counts_as_a_failure(tmp_path):
    total = os.path.join(ROOT, "scripts", "junit_total.py")
    xml = subprocess.run([sys.executable, total, "--failure", "ui-blender-4.3", "no root"],
                         capture_output=True, text=True, check=True).stdout
    (tmp_path / "ui.xml").write_text(xml)
    proc = subprocess.run([sys.executable, total, str(tmp_path / "ui.xml")], capture_output=True,
                          text=True)
    assert proc.returncode == 1
    assert proc.stdout.strip() == "total: 0 passed, 1 failed, 0 skipped"
