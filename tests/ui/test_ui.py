"""The UI tier: a user's session in a real Blender 4.3 window (Debian 13's package, under Xvfb).

The extension is built, validated and installed by Blender's own command line, the bake is started
the way the panel's button starts it and cancelled with a real Esc key press (xdotool), and every
observation of tests/ui/drive.py is judged here. Runs inside the cached Debian root of
scripts/real_blender.sh (needs root); if the root cannot be made the tier fails, it never skips.
Artefacts (screenshots, Blender's logs, results.json) stay in out/ui/.
"""

import json
import os
import subprocess

import numpy as np
import pytest

from core.falsecolour import RAMP

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
OUT = os.path.join(ROOT, "out", "ui")
#: Esc must stop a bake within this many seconds (wall clock, key press to the panel's idle state).
CANCEL_LIMIT = 1.0
#: The whole session (root build excluded) must end within this many seconds.
SESSION_LIMIT = 900
#: A screenshot counts as not blank above this grey-level standard deviation (0..255).
MIN_PIXEL_STD = 10.0
#: ... and with at least this many distinct colours.
MIN_COLOURS = 200
LOGS = ("build.log", "validate.log", "install.log", "blender.log")


@pytest.fixture(scope="module")
def session():
    """Run the Blender session once; return (results dict, {log name: text})."""
    os.makedirs(OUT, exist_ok=True)
    for name in os.listdir(OUT):  # the last session's artefacts (out/ui/cli is test_batch_cli's)
        if name.endswith((".png", ".log", ".json", ".rc")):
            os.remove(os.path.join(OUT, name))
    cmd = ["bash", os.path.join(ROOT, "scripts", "real_blender.sh"),
           "sh", "tests/ui/session.sh", "out/ui"]
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=SESSION_LIMIT)
    if proc.returncode != 0:
        pytest.fail(f"the real-Blender session did not run (exit {proc.returncode}):\n"
                    f"{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}", pytrace=False)
    logs = {}
    for name in LOGS + ("blender.rc",):
        path = os.path.join(OUT, name)
        logs[name] = open(path, encoding="utf-8", errors="replace").read() \
            if os.path.isfile(path) else ""
    path = os.path.join(OUT, "results.json")
    if not os.path.isfile(path):
        pytest.fail(f"Blender wrote no results; its output:\n{logs['blender.log'][-3000:]}",
                    pytrace=False)
    with open(path, encoding="utf-8") as fh:
        results = json.load(fh)
    return results, logs


def test_driver_ran_to_the_end(session):
    results, logs = session
    assert results["error"] is None, results["error"]
    assert results.get("finished") is True, logs["blender.log"][-2000:]


def test_extension_built_validated_installed_by_blenders_cli(session):
    results, logs = session
    assert "created:" in logs["build.log"] and ".zip" in logs["build.log"]
    assert "Success parsing TOML" in logs["validate.log"]
    assert 'Installed "radiosity_baker"' in logs["install.log"]
    assert results["blender"].startswith("4.3")
    assert results["addon_enabled"] is True


def test_button_bakes_with_progress_and_writes_colours(session):
    results, _ = session
    assert results["invoke_2"] == ["RUNNING_MODAL"]
    progress = np.array([p for _, p, _ in results["progress"]])
    assert len(progress) > 5
    assert np.all(np.diff(progress) >= 0), "progress went backwards"
    inside = np.unique(progress[(progress > 0) & (progress < 100)])
    assert len(inside) >= 3, f"progress did not advance in steps: {inside}"
    assert progress.max() > 50
    statuses = {s for _, _, s in results["progress"]}
    assert len(statuses) >= 3, statuses
    baked = results["baked"]
    assert baked, "no visible meshes"
    for name, stats in baked.items():
        assert stats is not None, f"{name} has no Radiosity attribute"
        assert stats["finite"] and stats["min"] >= 0 and stats["max"] > 0, (name, stats)
    report = json.loads(results["last_report"])
    assert report["patches"] > 0 and report["timings"]["total"] > 0
    # Workers (auto: one per core) started from Blender's own Python, not the blender binary.
    if (os.cpu_count() or 1) >= 2:
        assert report["workers"]["processes"] >= 2, report["workers"]
    assert not [w for w in report.get("warnings", []) if w.startswith("workers:")]


def test_escape_cancels_within_a_second_and_changes_nothing(session):
    results, _ = session
    assert results["invoke_1"] == ["RUNNING_MODAL"]
    assert results["progress_before_esc"][-1] > 0, "Esc must land in the middle of the bake"
    assert results["escape"] == "ok"
    assert results["running_after_esc"] is False
    assert results["cancel_seconds"] < CANCEL_LIMIT
    assert results["unchanged_after_cancel"] is True
    assert results["shading_after_cancel"] == results["shading_before"]


def test_show_bake_switches_the_viewport(session):
    results, _ = session
    before = results["shading_before"]
    assert before["color_type"] != "VERTEX"
    assert results["show_bake_prop"] is True
    assert results["shading_after_bake"] == {"type": "SOLID", "color_type": "VERTEX",
                                             "light": "FLAT"}
    assert results["shading_show_off"]["color_type"] != "VERTEX"
    assert results["shading_show_on"] == results["shading_after_bake"]


def test_advanced_settings_start_folded(session):
    results, _ = session
    assert results["advanced_folded"] is True


def test_register_unregister_and_quit_mid_bake_leave_no_traceback(session):
    results, logs = session
    assert results["registered_after_disable"] is False
    assert results["registered_after_enable"] is True
    assert results["running_at_quit"] is True
    assert logs["blender.rc"].strip() == "0"
    assert "Blender quit" in logs["blender.log"]
    for name in LOGS:
        for bad in ("Traceback", "ReferenceError", "Error:"):
            assert bad not in logs[name], f"{bad!r} in {name}:\n{logs[name][-3000:]}"


def test_light_panel_shows_for_a_spot_light(session):
    """Properties > Light data of a spot light shows the Radiosity panel (its poll passes in
    the real window's Properties editor; the screenshot light_panel.png shows it)."""
    results, _ = session
    assert results["light_panel_poll"] is True


#: Relight and the group sliders against the bake: every light x 2 is the bake x 2 and every
#: group at 0.5 then the bake (the groups' own solutions add up to the bake by construction: the
#: last light's is the lights' solution less the others'; a factor of 2 is exact in floating
#: point), up to the float32 colour attribute.
RELIGHT_RTOL = 1e-5


def test_relight_button_and_the_group_sliders_rewrite_the_colours(session):
    """The bake with a lamp and a bulb made both groups' own solutions in its worker (the status
    and the report say so); after every light is doubled, Relight in the real window writes
    twice the bake (a weighted sum, no solve); every group's Strength at 0.5 then writes the
    bake again."""
    results, _ = session
    assert any(s.startswith("Light groups") for _, _, s in results["progress"])
    assert json.loads(results["last_report"])["timings"]["light_groups"] > 0.0
    assert results["relight"] == ["FINISHED"]
    assert results["relight_report"]["summed"] is True
    assert results["groups"] == ["light", "Bulb"]
    assert results["relight_error"] is not None and results["relight_error"] < RELIGHT_RTOL
    assert results["group_error"] is not None and results["group_error"] < RELIGHT_RTOL


#: The bulb moved and moved back, each cast again on the kept form factors: the bake's light
#: again, computed by the same code on the same gathers and shadow rays (seeded), so equal up to
#: the float32 colour attribute.
RECAST_RTOL = 1e-5


def test_a_relight_that_solves_runs_in_its_worker_from_the_button(session):
    """The bulb moved: the Relight button starts a modal Relight (its solve in a worker, the
    status shows it; 13.7 s here, the radiosity mesh made again), whose result differs from the
    bake's, then every light group's own solution (the status says "Light groups"); moved back,
    the next one writes the bake's mesh and colours again, and a group's slider is a sum."""
    results, _ = session
    for step in ("moved", "back"):
        assert results[f"relight_{step}"] == ["RUNNING_MODAL"]
        assert results[f"relight_{step}_report"]["summed"] is False
        statuses = results[f"relight_{step}_statuses"]
        assert any(s.startswith("Relight: ") for s in statuses), statuses
        assert results[f"relight_{step}_groups_made"] is True     # (its status may be brief)
        assert all(s == "Starting" or s.startswith(("Relight: ", "Light groups: "))
                   for s in statuses), statuses
    # Moved, the radiosity mesh is made again where the bulb's light now changes (apart: None,
    # the meshes differ), or at least its colours differ from the bake's.
    moved = results["relight_moved_error"]
    assert moved is None or moved > 1e-3
    assert results["relight_back_error"] < RECAST_RTOL
    # The run made every group's own solution after writing: a slider then writes a sum, and
    # set back to 1, the bake again.
    assert results["group_after_solve"]["summed"] is True
    assert results["group_after_solve_error"] < RECAST_RTOL


def test_saving_the_file_keeps_the_bake_beside_it_and_relight_reads_it_back(session):
    """Save Relight Data on, File > Save As writes saved.radiosity beside the .blend (Blender's
    save handler); with nothing kept in memory, the Relight button reads it back and, the light
    unchanged, writes the colours it had (float32 at the write)."""
    results, _ = session
    assert results["relight_file_mb"] is not None and results["relight_file_mb"] > 1.0
    assert results["relight_from_file"] == ["FINISHED"]
    assert results["relight_from_file_kept"] is True
    assert results["relight_from_file_error"] < 1e-6


@pytest.mark.parametrize("name", ["before_bake.png", "during_bake.png", "after_bake.png",
                                  "advanced_open.png", "light_panel.png", "lux_view.png",
                                  "after_relight.png", "during_relight.png",
                                  "relight_hint.png"])
def test_screenshot_is_not_blank(session, name):
    from PIL import Image

    results, _ = session
    assert results["screenshots"][name] is True
    img = np.asarray(Image.open(os.path.join(OUT, name)).convert("RGB"))
    assert img.shape[:2] == (800, 1280)
    assert img.std() > MIN_PIXEL_STD
    assert len(np.unique(img.reshape(-1, 3), axis=0)) > MIN_COLOURS


def test_baked_screenshot_shows_the_colours(session):
    """The viewport area changes from material shading to the baked colours."""
    from PIL import Image

    before = np.asarray(Image.open(os.path.join(OUT, "before_bake.png")).convert("RGB"), float)
    after = np.asarray(Image.open(os.path.join(OUT, "after_bake.png")).convert("RGB"), float)
    view = (slice(150, 600), slice(100, 700))  # inside the camera frame of the 3D view
    assert np.abs(after[view] - before[view]).mean() > 5.0


#: The bar's pixels against the ramp (sRGB bytes): the screenshot is lossless, but the bar's
#: colours are interpolated across each quad by the GPU and blended over a translucent box edge.
LEGEND_LEVELS = 12


def test_lux_display_shows_false_colour_and_its_legend(session):
    """The Show Lux button's operator in the real window: the viewport shows the false-colour
    attribute, the draw handler draws the legend (its bar, sampled in the screenshot, runs
    through the ramp from bottom to top) and a second press gives the shading back."""
    from PIL import Image

    results, _ = session
    assert results["lux_display"] == ["FINISHED"]
    assert results["lux_shading"]["type"] == "SOLID"
    assert results["lux_shading"]["color_type"] == "VERTEX"
    assert results["lux_shading_off"] == results["shading_show_on"]
    bar = results["lux_bar"]
    assert bar, "the legend was never drawn"
    img = np.asarray(Image.open(os.path.join(OUT, "lux_view.png")).convert("RGB"), float)
    x = int(round(bar["left"] + bar["width"] / 2))
    ramp = np.array(RAMP) * 255.0
    for t in np.linspace(0.05, 0.95, 10):
        y_gl = bar["bottom"] + t * bar["height"]
        row = int(round(results["lux_window_height"] - 1 - y_gl))
        # The ramp is linear between its control points.
        k = t * (len(ramp) - 1)
        i = min(int(k), len(ramp) - 2)
        want = ramp[i] + (k - i) * (ramp[i + 1] - ramp[i])
        got = img[row, x]
        assert np.abs(got - want).max() <= LEGEND_LEVELS, (t, got.tolist(), want.tolist())
