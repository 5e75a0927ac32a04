"""Blender-side driver of the UI tier: a user's session in a real Blender window (under Xvfb).

Run by tests/ui/session.sh inside the Debian 13 root::

    blender sample_blends/cornell_box.blend --python tests/ui/drive.py -- OUT_DIR

Steps run from ``bpy.app.timers`` (the event loop keeps running between them, as for a user):
open the sidebar on the Radiosity tab, start the bake as the button does (``INVOKE_DEFAULT`` in
the 3D view's context), press Esc with xdotool in the middle, start it again and watch the progress
until it ends, toggle Show Bake, take screenshots with ImageMagick's ``import -window root``,
press Relight after doubling the lamp and a bulb added before the bakes (two light groups, made
in the bake's worker) and set the groups' strengths, disable and re-enable
the extension, and quit in the middle of a third bake. Every observation
goes to OUT_DIR/results.json; tests/ui/test_ui.py judges them. Nothing here asserts.
"""

import hashlib
import json
import os
import subprocess
import sys
import time
import traceback

import bpy
import numpy as np

OUT = os.path.abspath(sys.argv[sys.argv.index("--") + 1])
MODULE = "bl_ext.user_default.radiosity_baker"
#: Seconds between progress samples.
SAMPLE = 0.05
#: Progress (%) at which Esc is pressed during the first bake.
ESC_AT = 1.0
#: Give up waiting on any one step after this many seconds.
STEP_LIMIT = 240.0

results = {"error": None}


def save():
    with open(os.path.join(OUT, "results.json"), "w", encoding="utf-8") as fh:
        json.dump(results, fh, indent=1)


def view3d():
    """(window, area, UI region, WINDOW region) of the first 3D viewport."""
    window = bpy.context.window_manager.windows[0]
    area = next(a for a in window.screen.areas if a.type == "VIEW_3D")
    ui = next(r for r in area.regions if r.type == "UI")
    main = next(r for r in area.regions if r.type == "WINDOW")
    return window, area, ui, main


def running():
    wm = bpy.context.window_manager
    return bool(getattr(wm, "radiosity_status", ""))


def snapshot():
    """Every mesh's size, positions hash and colour attributes, and the object-to-mesh links."""
    state = {}
    for obj in bpy.data.objects:
        state["object:" + obj.name] = obj.data.name if obj.data else None
    for mesh in bpy.data.meshes:
        co = np.empty(len(mesh.vertices) * 3, np.float32)
        mesh.vertices.foreach_get("co", co)
        state["mesh:" + mesh.name] = [len(mesh.vertices), len(mesh.polygons),
                                      hashlib.sha1(co.tobytes()).hexdigest(),
                                      sorted(a.name for a in mesh.color_attributes)]
    state["last_report"] = bpy.context.scene.radiosity.last_report
    return state


def shading():
    _, area, _, _ = view3d()
    s = area.spaces[0].shading
    return {"type": s.type, "color_type": s.color_type, "light": s.light}


def xdotool(*args):
    return subprocess.run(["xdotool", *args], capture_output=True, text=True, timeout=10)


def press_escape():
    """Esc as a user presses it: pointer over the 3D view of the focused Blender window."""
    window, area, _, main = view3d()
    wid = xdotool("search", "--onlyvisible", "--name", "Blender").stdout.split()
    if not wid:
        return "no Blender window found by xdotool"
    wid = wid[0]
    x = main.x + main.width // 2
    y = window.height - (main.y + main.height // 2)
    out = [xdotool("windowfocus", "--sync", wid),
           xdotool("mousemove", "--window", wid, str(x), str(y)),
           xdotool("key", "Escape")]
    return "; ".join(r.stderr.strip() for r in out if r.returncode) or "ok"


def screenshot(name):
    path = os.path.join(OUT, name)
    r = subprocess.run(["import", "-window", "root", path], capture_output=True, text=True,
                       timeout=30)
    results.setdefault("screenshots", {})[name] = r.returncode == 0 and os.path.isfile(path)
    return path


def invoke_bake():
    window, area, ui, _ = view3d()
    with bpy.context.temp_override(window=window, area=area, region=ui):
        return sorted(bpy.ops.radiosity.bake("INVOKE_DEFAULT"))


def colours():
    """{visible mesh: its Radiosity colours (C, 3) float64}."""
    out = {}
    for obj in bpy.context.scene.objects:
        attr = obj.data.color_attributes.get("Radiosity") if obj.type == "MESH" else None
        if attr is not None and obj.visible_get():
            buf = np.empty(len(attr.data) * 4, np.float32)
            attr.data.foreach_get("color", buf)
            out[obj.name] = buf.reshape(-1, 4)[:, :3].astype(np.float64)
    return out


def stats(rgb):
    """A mesh's colours in brief (None: it has no Radiosity attribute)."""
    if rgb is None:
        return None
    return {"min": float(rgb.min()), "max": float(rgb.max()),
            "finite": bool(np.isfinite(rgb).all()), "corners": len(rgb)}


def apart(now, baked, factor):
    """max |now - factor x baked| / max |factor x baked| over every mesh (None: meshes differ)."""
    if sorted(now) != sorted(baked) or any(now[k].shape != baked[k].shape for k in now):
        return None
    top = max(float(np.abs(factor * b).max()) for b in baked.values())
    return max(float(np.abs(now[k] - factor * baked[k]).max()) for k in now) / top


def emission_strengths():
    """The unlinked, lit emission Strength sockets of every node material."""
    out = []
    for mat in bpy.data.materials:
        for node in mat.node_tree.nodes if mat.node_tree else ():
            for key in ("Strength", "Emission Strength"):
                sock = node.inputs.get(key) if hasattr(node, "inputs") else None
                if sock is not None and not sock.is_linked and sock.default_value > 0:
                    out.append(sock)
    return out


def redraw():
    for area in bpy.context.window_manager.windows[0].screen.areas:
        area.tag_redraw()


def scenario():
    """A generator of waits (seconds): each yield hands control back to Blender's event loop."""
    yield 1.0
    prefs = bpy.context.preferences
    results["addon_enabled"] = MODULE in prefs.addons
    results["blender"] = bpy.app.version_string
    window, area, ui, main = view3d()
    area.spaces[0].show_region_ui = True
    area.spaces[0].region_3d.view_perspective = "CAMERA"  # Numpad 0: look through the camera
    yield 0.5
    ui.active_panel_category = "Radiosity"
    redraw()
    yield 0.5
    results["sidebar"] = {"category": ui.active_panel_category, "width": ui.width,
                          "ui_scale": prefs.system.ui_scale}
    # A point light beside the ceiling lamp, as users light a room: two light groups, so the
    # bake's worker makes each group's own solution after the core bake (the panel's status
    # says "Light groups") and the first Relight below is their weighted sum.
    bulb = bpy.data.objects.new("Bulb", bpy.data.lights.new("Bulb", "POINT"))
    bulb.data.energy, bulb.location = 5.0, (0.28, 0.2, 0.4)
    bpy.context.scene.collection.objects.link(bulb)
    results["shading_before"] = shading()
    screenshot("before_bake.png")
    before = snapshot()

    # 1. Bake, then Esc in the middle.
    results["invoke_1"] = invoke_bake()
    t0 = time.perf_counter()
    seen = []
    while running() and time.perf_counter() - t0 < STEP_LIMIT:
        seen.append(bpy.context.window_manager.radiosity_progress)
        if seen[-1] >= ESC_AT:
            break
        yield SAMPLE
    results["progress_before_esc"] = seen
    results["escape"] = press_escape()
    t_esc = time.perf_counter()
    while running() and time.perf_counter() - t_esc < 10.0:
        yield 0.02
    results["cancel_seconds"] = time.perf_counter() - t_esc
    results["running_after_esc"] = running()
    yield 0.3
    results["unchanged_after_cancel"] = snapshot() == before
    results["shading_after_cancel"] = shading()

    # 2. Bake to the end, sampling the progress the panel shows.
    results["invoke_2"] = invoke_bake()
    t0 = time.perf_counter()
    samples = []
    shot = False
    while running() and time.perf_counter() - t0 < STEP_LIMIT:
        wm = bpy.context.window_manager
        samples.append([time.perf_counter() - t0, wm.radiosity_progress, wm.radiosity_status])
        if not shot and wm.radiosity_progress > 20.0:
            redraw()
            yield 0.2
            screenshot("during_bake.png")
            shot = True
        yield SAMPLE
    results["bake_seconds"] = time.perf_counter() - t0
    results["progress"] = samples
    yield 0.3
    rgbs = colours()
    results["baked"] = {obj.name: stats(rgbs.get(obj.name)) for obj in bpy.context.scene.objects
                        if obj.type == "MESH" and obj.visible_get()}
    results["last_report"] = bpy.context.scene.radiosity.last_report
    results["show_bake_prop"] = bpy.context.scene.radiosity.show_bake
    results["shading_after_bake"] = shading()
    bpy.context.scene.radiosity.show_bake = False
    yield 0.2
    results["shading_show_off"] = shading()
    bpy.context.scene.radiosity.show_bake = True
    redraw()
    yield 1.0
    results["shading_show_on"] = shading()
    screenshot("after_bake.png")
    # Unfold Advanced (as a click on its header does) to see its labels at the default width.
    results["advanced_folded"] = not bpy.context.window_manager.radiosity_show_advanced
    bpy.context.window_manager.radiosity_show_advanced = True
    redraw()
    yield 1.0
    screenshot("advanced_open.png")

    # The lux display, as its button runs it: false colour in the viewport and the legend drawn
    # by the draw handler (where the bar went is read back to check its pixels).
    luxview = __import__(MODULE + ".radiosity_addon.luxview", fromlist=["DRAWN"])
    relight = __import__(MODULE + ".radiosity_addon.relight", fromlist=["kept"])
    with bpy.context.temp_override(window=window, area=area, region=ui):
        results["lux_display"] = sorted(bpy.ops.radiosity.lux_display())
    redraw()
    yield 1.0
    results["lux_shading"] = shading()
    results["lux_bar"] = dict(luxview.DRAWN)
    results["lux_window_height"] = window.height
    screenshot("lux_view.png")
    with bpy.context.temp_override(window=window, area=area, region=ui):
        bpy.ops.radiosity.lux_display()
    redraw()
    yield 0.5
    results["lux_shading_off"] = shading()

    # Relight and the light groups' sliders, as after a bake: the lamp's strength and the
    # bulb's power doubled, the Relight button's operator in the sidebar, then each group's
    # Strength set as its slider sets it (its update writes the mix). Both are compared with the
    # bake's colours.
    baked = colours()
    strengths = emission_strengths()
    for sock in strengths:
        sock.default_value *= 2.0
    bulb.data.energy *= 2.0
    with bpy.context.temp_override(window=window, area=area, region=ui):
        results["relight"] = sorted(bpy.ops.radiosity.relight("INVOKE_DEFAULT"))
    redraw()
    yield 1.0
    results["relight_report"] = json.loads(bpy.context.scene.radiosity.last_report)["relight"]
    results["relight_error"] = apart(colours(), baked, 2.0)
    screenshot("after_relight.png")
    groups = bpy.context.scene.radiosity_groups
    results["groups"] = [g.name for g in groups]
    if len(groups):
        for group in groups:
            group.strength = 0.5
        redraw()
        yield 1.0
        results["group_error"] = apart(colours(), baked, 1.0)
        for group in groups:
            group.strength = 1.0
    for sock in strengths:
        sock.default_value *= 0.5
    bulb.data.energy *= 0.5
    yield 0.3

    # A Relight that solves (the bulb moved: its light cast again on the kept form factors)
    # runs in a worker from the same button, its progress in the status, as the bake's: the
    # bulb moved, then moved back (the bake's light again: the bake's colours).
    where = tuple(bulb.location)
    for step, place in (("moved", (where[0] - 0.15, where[1], where[2] - 0.15)),
                        ("back", where)):
        bulb.location = place
        with bpy.context.temp_override(window=window, area=area, region=ui):
            results[f"relight_{step}"] = sorted(bpy.ops.radiosity.relight("INVOKE_DEFAULT"))
        statuses, t0 = [], time.perf_counter()
        while running() and time.perf_counter() - t0 < STEP_LIMIT:
            statuses.append(bpy.context.window_manager.radiosity_status)
            if step == "moved" and "during_relight.png" not in results.get("screenshots", {}) \
                    and statuses[-1].startswith("Relight: mesh"):
                redraw()
                yield 0.2                  # the panel's bar and the status bar drawn
                screenshot("during_relight.png")
            yield SAMPLE
        yield 0.3
        results[f"relight_{step}_statuses"] = sorted(set(statuses))
        results[f"relight_{step}_report"] = json.loads(
            bpy.context.scene.radiosity.last_report)["relight"]
        results[f"relight_{step}_error"] = apart(colours(), baked, 1.0)
        entry = relight.kept(bpy.context.scene)
        results[f"relight_{step}_groups_made"] = sorted(entry.basis) == list(
            range(len(entry.units)))
    # Each run made every group's own solution after writing: a group change is a sum.
    groups[-1].strength = 0.5
    yield 0.3
    results["group_after_solve"] = json.loads(bpy.context.scene.radiosity.last_report)["relight"]
    groups[-1].strength = 1.0
    yield 0.3
    results["group_after_solve_error"] = apart(colours(), baked, 1.0)

    # Save Relight Data: saving the file (File > Save As) writes the kept bake beside it (the
    # save handler, in a real Blender); with the bake in memory forgotten, as after reopening,
    # the Relight button reads it back and writes the same colours.
    bpy.context.scene.radiosity.save_relight = True
    bpy.ops.wm.save_as_mainfile(filepath=os.path.join(OUT, "saved.blend"))
    yield 0.3
    side = os.path.join(OUT, "saved.radiosity")
    results["relight_file_mb"] = os.path.getsize(side) / 2 ** 20 if os.path.isfile(side) \
        else None
    before = colours()
    relight.drop(bpy.context.scene)
    redraw()                                   # the panel says the file beside will be read
    yield 1.0
    screenshot("relight_hint.png")
    with bpy.context.temp_override(window=window, area=area, region=ui):
        results["relight_from_file"] = sorted(bpy.ops.radiosity.relight("INVOKE_DEFAULT"))
    t0 = time.perf_counter()
    while running() and time.perf_counter() - t0 < STEP_LIMIT:
        yield SAMPLE
    yield 0.3
    results["relight_from_file_kept"] = relight.kept(bpy.context.scene) is not None
    results["relight_from_file_error"] = apart(colours(), before, 1.0)

    # The light's panel: a spot light made active, Properties > Light data shows its Radiosity
    # panel (the IES / EULUMDAT file field).
    lamp = bpy.data.objects.new("Spot", bpy.data.lights.new("Spot", "SPOT"))
    lamp.location = (0.0, 0.0, 0.5)
    bpy.context.scene.collection.objects.link(lamp)
    for obj in bpy.context.view_layer.objects:
        obj.select_set(False)
    lamp.select_set(True)
    bpy.context.view_layer.objects.active = lamp
    redraw()
    yield 0.5                       # the Properties editor offers the Light tab after a redraw
    props = [a for a in window.screen.areas if a.type == "PROPERTIES"]
    results["light_panel_poll"] = None
    if props:
        props[0].spaces[0].context = "DATA"
        redraw()
        yield 1.0
        with bpy.context.temp_override(window=window, area=props[0]):
            panel = getattr(bpy.types, "DATA_PT_radiosity_light", None)
            results["light_panel_poll"] = bool(panel and panel.poll(bpy.context))
        screenshot("light_panel.png")
    bpy.data.objects.remove(lamp)
    yield 0.3

    # 3. Disable and enable the extension (unregister, register) as Preferences does.
    bpy.ops.preferences.addon_disable(module=MODULE)
    yield 0.3
    results["registered_after_disable"] = hasattr(bpy.types.Scene, "radiosity")
    bpy.ops.preferences.addon_enable(module=MODULE)
    yield 0.3
    results["registered_after_enable"] = hasattr(bpy.types.Scene, "radiosity")

    # 4. Quit in the middle of a bake (unregister with a running worker).
    bpy.context.scene.radiosity.patch_size = bpy.context.scene.radiosity.patch_size / 2
    results["invoke_3"] = invoke_bake()
    yield 0.5
    results["running_at_quit"] = running()
    results["finished"] = True
    save()
    print("UI-DRIVER: quitting", flush=True)
    bpy.ops.wm.quit_blender()


_steps = scenario()


def tick():
    try:
        wait = next(_steps)
    except StopIteration:
        return None
    except Exception:  # recorded for the test, and Blender quits so the run never hangs
        results["error"] = traceback.format_exc()
        save()
        bpy.ops.wm.quit_blender()
        return None
    save()
    return wait


os.makedirs(OUT, exist_ok=True)
bpy.app.timers.register(tick, first_interval=1.0, persistent=True)
