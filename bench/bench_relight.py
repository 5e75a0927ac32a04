"""Relight and light groups (issue 12) against the bake, on the bundled samples, through the add-on.

For each sample: the bake (radiosity.bake with the file's own settings), then a Relight after
every emissive material's strength and every light's power x 2 (each group scaled: a weighted sum
of the groups' own solutions, made at once when missing; ``relight_summed``), the same Relight
solved as before that (``relight_solved_s``: one new solve on the kept form factors, and the
lights' own solution; ``summed_vs_solved``: how far apart, max |difference| / max colour), the
first change of the first group (every
group's own solution, once, in one core.relight_many: a material's emission alone, a light
alone), a second one (a weighted sum, no solve), the first change of a point, spot or sun
light's group (``group_light_first_s``: made with the first, a weighted sum), every group's own
solution made again from none one core.relight at a time and then together
(``groups_one_by_one_s``, ``groups_together_s``: the ratio in one run) and the bytes the kept
bake holds in memory (radiosity_addon.relight.kept_bytes).

``--scenes generated --patches 10000``: instead of a sample, an open-plan office built here
(:func:`generated`: desks, four point lights, a spot, emissive ceiling panels) baked to vertices
with the patch size that gives about that many patches; its Relight scales the panels only (the
first summed Relight: every group's solution made), a second one the lights too (a sum). Relights
print their CPU seconds too (``*_cpu_s``, this process: fairer on a busy machine), whether the
bake's reciprocity scaling was reused (no Sinkhorn sweep) and the solver's sweeps
(``relight_reused``).

``--panel``: bake as the panel's button does (operators.panel_job): the worker makes every light
group's own solution after the core bake (``light_groups_in_bake_s``), so the first Relight is a
weighted sum; without it, as the operator's execute (scripts) bakes: the first Relight makes them.

Run: ``.venv/bin/python bench/bench_relight.py [--scenes cornell_box office generated]
[--patches 10000] [--panel]``. Prints one JSON line per scene (seconds per step, the kept MB, the groups).
"""

import argparse
import json
import math
import os
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "radiosity_addon"))

from bootstrap import load_package  # noqa: E402

PACKAGE = load_package()

import bpy  # noqa: E402


def emissive_inputs():
    """The Strength sockets of every emissive node material in the file."""
    out = []
    for mat in bpy.data.materials:
        if mat.node_tree is None:
            continue
        for node in mat.node_tree.nodes:
            for key in ("Strength", "Emission Strength"):
                sock = node.inputs.get(key) if hasattr(node, "inputs") else None
                if sock is not None and not sock.is_linked and sock.default_value > 0:
                    out.append(sock)
    return out


#: The generated office (m): its size, its desks (rows x columns, size), its lights' height.
OFFICE = (20.0, 12.0, 3.0)
DESKS = (4, 6, (1.6, 0.8, 0.75))
LIGHT_Z = 2.6


def _mesh(name, verts, faces, mat):
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata([tuple(v) for v in verts], [], faces)
    mesh.materials.append(mat)
    obj = bpy.data.objects.new(name, mesh)
    bpy.context.scene.collection.objects.link(obj)
    return obj


def _material(name, colour, emission=0.0):
    mat = bpy.data.materials.new(name)
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (*colour, 1.0)
    if emission:
        bsdf.inputs["Emission Color"].default_value = (1.0, 1.0, 1.0, 1.0)
        bsdf.inputs["Emission Strength"].default_value = emission
    return mat


def _box(lo, hi, outward=True):
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    v = [(x0, y0, z0), (x1, y0, z0), (x1, y1, z0), (x0, y1, z0),
         (x0, y0, z1), (x1, y0, z1), (x1, y1, z1), (x0, y1, z1)]
    f = [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)]
    return v, f if outward else [tuple(reversed(q)) for q in f]


def generated(patches):
    """Build the open-plan office in an empty file; returns the patch size (m) that cuts its
    surfaces into about ``patches`` patches (area / patches, square)."""
    bpy.ops.wm.read_homefile(use_factory_startup=True, use_empty=True)
    X, Y, Z = OFFICE
    _mesh("Room", *_box((0, 0, 0), OFFICE, outward=False), _material("wall", (0.7, 0.68, 0.62)))
    rows, cols, (w, d, h) = DESKS
    desk = _material("desk", (0.55, 0.4, 0.3))
    for i in range(rows):
        for j in range(cols):
            x, y = (j + 0.5) * X / cols - w / 2, (i + 0.5) * Y / rows - d / 2
            _mesh(f"Desk {i}-{j}", *_box((x, y, 0), (x + w, y + d, h)), desk)
    panel = _material("panel", (0.8, 0.8, 0.8), emission=6.0)
    for k in range(4):
        x, y = (k + 0.5) * X / 4, Y / 2
        _mesh(f"Panel {k}", [(x - 0.6, y - 0.3, Z - 0.02), (x - 0.6, y + 0.3, Z - 0.02),
                             (x + 0.6, y + 0.3, Z - 0.02), (x + 0.6, y - 0.3, Z - 0.02)],
              [(0, 1, 2, 3)], panel)
    for k, (kind, x, y) in enumerate([("POINT", 3, 3), ("POINT", 3, 9), ("POINT", 17, 3),
                                      ("POINT", 17, 9), ("SPOT", 10, 6)]):
        light = bpy.data.lights.new(f"Light {k}", kind)
        light.energy = 300.0 if kind == "POINT" else 800.0
        obj = bpy.data.objects.new(f"Light {k}", light)
        obj.location = (x, y, LIGHT_Z)
        bpy.context.scene.collection.objects.link(obj)
    area = 2 * (X * Y + X * Z + Y * Z) + rows * cols * 2 * (w * d + w * h + d * h) \
        + 4 * 1.2 * 0.6
    return math.sqrt(area / patches)


def _timings():
    """The core's seconds per stage of the last bake or relight (its report)."""
    timings = json.loads(bpy.context.scene.radiosity.last_report).get("timings", {})
    return {k: round(v, 3) for k, v in timings.items()}


def _reused():
    """Whether the last relight reused the bake's reciprocity scaling (no Sinkhorn sweep), and
    its solver's sweeps."""
    report = json.loads(bpy.context.scene.radiosity.last_report)
    return dict(balancing=bool(report.get("reciprocity", {}).get("reused", False)),
                iterations=report.get("iterations"))


def _bake(panel):
    """Bake as the operator's execute does (scripts), or with ``panel`` as the panel's button
    does (operators.panel_job: the worker makes every light group's solution after the bake)."""
    if not panel:
        assert bpy.ops.radiosity.bake() == {"FINISHED"}
        return
    addon, ctx = PACKAGE.radiosity_addon, bpy.context
    bake_input = addon.job.prepare(ctx, addon.job.options_from_props(ctx.scene.radiosity))
    work = addon.operators.panel_job(ctx, bake_input).start()
    work.join()
    if work.error is not None:
        raise work.error
    addon.job.apply(ctx, bake_input, work.result, ready=work.ready, warnings=work.warnings)


def run(name, patches=10000, exact_direct=None, panel=False):
    if name == "generated":
        size = generated(patches)
        settings = bpy.context.scene.radiosity
        settings.output_mode, settings.patch_size = "VERTICES", size
        if exact_direct:
            settings.exact_direct = exact_direct.upper()
    else:
        bpy.ops.wm.open_mainfile(filepath=os.path.join(ROOT, "sample_blends", f"{name}.blend"),
                                 load_ui=False)
    relight = PACKAGE.radiosity_addon.relight
    t0 = time.perf_counter()
    _bake(panel)
    bake = time.perf_counter() - t0
    report = json.loads(bpy.context.scene.radiosity.last_report)
    for sock in emissive_inputs():
        sock.default_value *= 2.0
    extra = {}
    if name == "generated":     # the emission alone first: exactly one new solve
        t0, c0 = time.perf_counter(), time.process_time()
        assert bpy.ops.radiosity.relight() == {"FINISHED"}
        extra["relight_emission_s"] = round(time.perf_counter() - t0, 3)
        extra["relight_emission_cpu_s"] = round(time.process_time() - c0, 3)
        extra["relight_emission_core"] = _timings()
        extra["relight_emission_summed"] = _summed()
        if not extra["relight_emission_summed"]:     # a sum reuses no solve of its own
            extra["relight_reused"] = _reused()
    for light in bpy.data.lights:
        light.energy *= 2.0
    t0, c0 = time.perf_counter(), time.process_time()
    assert bpy.ops.radiosity.relight() == {"FINISHED"}
    relit = time.perf_counter() - t0
    extra["relight_cpu_s"] = round(time.process_time() - c0, 3)
    extra["relight_summed"] = _summed()
    extra["relight_core"] = _timings()
    extra.update(_solved(relight))
    entry = relight.kept(bpy.context.scene)
    groups = bpy.context.scene.radiosity_groups
    t0 = time.perf_counter()
    groups[0].strength = 0.5
    first = time.perf_counter() - t0
    t0 = time.perf_counter()
    groups[0].strength = 0.25
    second = time.perf_counter() - t0
    lights = [u.group for u in entry.units if u.materials is None and u.lights]
    if len(lights) > 1:
        t0 = time.perf_counter()
        groups[lights[0]].strength = 0.5
        extra["group_light_first_s"] = round(time.perf_counter() - t0, 3)
    extra.update(_every_group(relight, entry))
    extra.update(_moved(relight))
    return dict(scene=name, panel=panel, bake_s=round(bake, 2),
                light_groups_in_bake_s=round(report["timings"].get("light_groups", 0.0), 3),
                bake_core_s=round(report["timings"]["total"], 2),
                bake_solve_s=round(report["timings"].get("solve", 0.0), 3), **extra,
                relight_s=round(relit, 3), group_first_s=round(first, 3),
                group_next_s=round(second, 3), groups=[g.name for g in groups],
                patches=report["patches"], form_factor_mb=round(
                    report["form_factor_bytes"] / 2 ** 20, 2),
                kept_mb=round(relight.kept_bytes(entry) / 2 ** 20, 2),
                group_seconds={k: round(v, 3) for k, v in entry.seconds.items()})


def _moved(relight):
    """A light moved (its light cast again), relit as the panel's Relight runs it: seconds of
    the main thread's read and write (relight.begin, finish) around the worker's solve
    (relight.compute, while the UI stays live), then of the next worker's groups
    (relight.make_groups); {} without a light."""
    light = next((o for o in bpy.context.scene.objects if o.type == "LIGHT"), None)
    if light is None:
        return {}
    light.location.x += 0.1
    t0 = time.perf_counter()
    pending = relight.begin(bpy.context)
    t1 = time.perf_counter()
    relight.compute(pending)
    t2 = time.perf_counter()
    report = relight.finish(bpy.context, pending)
    t3 = time.perf_counter()
    entry = relight.kept(bpy.context.scene)
    groups = relight.needs_groups(entry) and relight.make_groups(entry)   # the next worker
    return dict(moved_begin_s=round(t1 - t0, 3), moved_compute_s=round(t2 - t1, 3),
                moved_finish_s=round(t3 - t2, 3), moved_summed=_summed(),
                moved_groups_s=round(time.perf_counter() - t3, 3) if groups else None,
                moved_warnings=[w for w in report["warnings"] if w.startswith("relight")])


def _summed():
    return bool(json.loads(bpy.context.scene.radiosity.last_report)["relight"]["summed"])


def _colours():
    """Every baked object's written colours, (C, 4) float64."""
    import numpy as np
    out = []
    for obj in bpy.context.scene.objects:
        attr = obj.data.color_attributes.get(PACKAGE.radiosity_addon.extract.ATTRIBUTE) \
            if obj.type == "MESH" else None
        if attr is not None:
            buf = np.empty(4 * len(attr.data), np.float32)
            attr.data.foreach_get("color", buf)
            out.append(buf.reshape(-1, 4))
    return np.concatenate(out).astype(np.float64)


def _solved(relight):
    """The same Relight solved (as before the weighted sum: ``unit_factors`` said no): its
    seconds and how far the summed colours are from it (max |difference| / max colour)."""
    import numpy as np
    summed, factors = _colours(), relight.unit_factors
    relight.unit_factors = lambda *args: None
    try:
        t0 = time.perf_counter()
        assert bpy.ops.radiosity.relight() == {"FINISHED"}
        seconds = time.perf_counter() - t0
    finally:
        relight.unit_factors = factors
    solved = _colours()
    return dict(relight_solved_s=round(seconds, 3), summed_vs_solved=float(
        np.abs(summed - solved).max() / np.abs(solved).max()))


def _every_group(relight, entry):
    """Seconds to make every group's own solution from none: one core.relight at a time (as
    before core.relight_many), then all in one core.relight_many (the add-on's way)."""
    import numpy as np
    relight_solve = PACKAGE.radiosity_addon.relight_solve
    weights = {g: np.full(3, 0.5) for g in relight.group_names(entry)}
    out, prefetch = {}, relight_solve._prefetch
    for label, together in (("one_by_one", False), ("together", True)):
        entry.basis, entry.own, entry.lit, entry.world = {}, {}, None, None
        if not together:
            relight_solve._prefetch = lambda entry, ks: None
        try:
            t0 = time.perf_counter()
            relight_solve.mixed(entry, weights)
            out[f"groups_{label}_s"] = round(time.perf_counter() - t0, 3)
        finally:
            relight_solve._prefetch = prefetch
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", nargs="+", default=["cornell_box", "office"],
                        help="bundled samples, or 'generated' (see --patches)")
    parser.add_argument("--patches", type=int, default=10000,
                        help="about how many patches the generated scene has (default 10000)")
    parser.add_argument("--exact-direct", choices=["auto", "all", "off"],
                        help="the generated scene's Exact Emitters (default: the add-on's, auto)")
    parser.add_argument("--panel", action="store_true",
                        help="bake as the panel's button does: every light group's solution is "
                             "made in the bake (light_groups_in_bake_s), so the first Relight "
                             "is a sum")
    args = parser.parse_args()
    PACKAGE.register()
    for name in args.scenes:
        print(json.dumps(run(name, args.patches, args.exact_direct, args.panel)), flush=True)


if __name__ == "__main__":
    main()
