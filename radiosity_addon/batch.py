"""Headless bake: the same bake as the panel's button, from the command line.

Two ways to run it::

    blender --background scene.blend --python radiosity_addon/batch.py -- --output baked.blend
    python radiosity_addon/batch.py scene.blend --output baked.blend      # bpy module

Options: ``--report report.json``, ``--render out.png`` (Workbench render of the baked colours from
the scene camera), ``--render-lux lux.png`` (the same view of the lux in false colour, with its
legend; ``--lux-scale linear|log``, ``--lux-max LX|auto``), ``--patch-size``, ``--method``,
``--resolution``, ``--solver``, ``--tolerance``, ``--max-iterations``, ``--selected-only``,
``--make-single-user``, ``--in-place``. Anything not given comes from the .blend's own bake
settings (Scene > Radiosity). The input is never overwritten unless ``--in-place``; outputs are
written to a temporary file and renamed. Every output path is checked before the bake (its folder
exists and is writable, it is not a folder). Any error exits with status 1 (2 for a bad option)
and one line on stderr that names the path or option as given; this holds for failures before the
package loads too (NumPy missing from a distribution's Blender, options given without ``--``),
where Blender alone would print a traceback and exit 0.
"""

import argparse
import contextlib
import csv
import importlib
import importlib.util
import json
import os
import shutil
import sys
import tempfile

PROG = "radiosity-batch"


class BatchError(Exception):
    """A user-facing error: printed on one line, exit status 1."""


class _Parser(argparse.ArgumentParser):
    def error(self, message):
        raise BatchError(f"bad option: {message}")


#: What an ``auto`` row's option returns for ``auto`` (None means "not given").
AUTO = "auto"


def _option_type(row):
    """argparse type of a settings row: parse, then check against the row (one range)."""
    parse = int if row.type == "int" else float

    def convert(text):
        if row.auto and text.strip().lower() == "auto":
            return AUTO
        try:
            return row.check(parse(text))
        except ValueError as exc:      # core.SettingsError is a ValueError
            raise argparse.ArgumentTypeError(str(exc)) from None
    convert.__name__ = row.type        # argparse names the type in "invalid int value"
    return convert


def add_option(parser, row):
    """One command-line option from a settings row: ``--name-with-dashes``, help with units."""
    flag = "--" + row.name.replace("_", "-")
    text = f"{row.help}. Must be {row.describe()}"
    if row.type == "bool":
        parser.add_argument(flag, action=argparse.BooleanOptionalAction, default=None,
                            help=f"{row.help}")
    elif row.type == "choice":
        parser.add_argument(flag, choices=row.values(), help=f"{row.help}: " + "; ".join(
            f"{c.value}: {c.help}" for c in row.choices))
    else:
        if row.low is not None and row.high is not None and row.type == "int":
            metavar = f"{row.low}..{row.high}"
        else:
            metavar = row.unit.upper() if row.unit and " " not in row.unit else "N"
            if row.auto:
                metavar += "|auto"
        parser.add_argument(flag, type=_option_type(row), metavar=metavar, help=text)


def build_parser(need_input):
    """The command-line parser (*need_input*: the .blend is a positional argument).

    The bake options are made from the settings table (``props.OPTIONS``); anything not given
    comes from the .blend's own settings.
    """
    # Imported here, not at the top: this file also runs as a plain script (``__main__``),
    # where the package's relative imports exist only once _load_package() has run.
    from ..core.falsecolour import SETTINGS as LUX_SETTINGS
    from .props import OPTIONS

    p = _Parser(prog=PROG, description="Bake radiosity into vertex colours, headless. Bake "
                "options not given come from the .blend's own settings (Scene > Radiosity).")
    if need_input:
        p.add_argument("input", help="the .blend to bake (never modified unless --in-place)")
    p.add_argument("--output", help="where to save the baked .blend")
    p.add_argument("--in-place", action="store_true", help="overwrite the input .blend")
    p.add_argument("--report", help="write the bake report (JSON) here")
    p.add_argument("--render", help="render the baked colours (Workbench) to this PNG")
    p.add_argument("--calc-surface", action="append", default=[], metavar="OBJECT",
                   help="measure illuminance on this mesh object (repeatable): it becomes a "
                        "calculation surface, which neither blocks nor reflects light")
    p.add_argument("--lux", help="write the calculation surfaces' grid illuminance here: "
                                 ".csv (object, x, y, z, lux per point) or .json (per surface: "
                                 "Emin, Eavg, Emax, U0, grid points and their lux)")
    p.add_argument("--render-lux", metavar="FILE.png",
                   help="render the illuminance in false colour (Workbench, scene camera) with "
                        "a legend in lux to this PNG")
    p.add_argument("--group-strength", action="append", default=[], type=_group_strength,
                   metavar="NAME=FACTOR",
                   help="after the bake, multiply light group NAME's light by FACTOR before "
                        "saving (repeatable; groups: each emissive material, each point, spot "
                        "and sun light by its object's name, 'World', or Blender's light "
                        "groups; the report lists them). A weighted sum of each named group's "
                        "own solution (solved together on the kept form factors): no new bake")
    p.add_argument("--relight", nargs="?", const="", metavar="FILE.radiosity",
                   help="do not bake: relight the input's kept bake (FILE, default the input's "
                        "name with .radiosity, written by --save-relight or Save Relight Data) "
                        "with the light as the .blend holds it now, on its form factors")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="run the bake's hemicube calls on a Dask distributed cluster: a "
                        "scheduler's address (tcp://host:8786), a scheduler file (.json, on "
                        "shared storage), or 'local' for a LocalCluster of --workers processes "
                        "(docs/farm.md); the result is the same bits")
    p.add_argument("--scheduler-wait", type=float, default=30.0, metavar="SECONDS",
                   help="how long --scheduler waits for its file, the connection and a first "
                        "worker (default 30)")
    for row in OPTIONS + LUX_SETTINGS:
        add_option(p, row)
    return p


def _group_strength(text):
    """argparse type of --group-strength: 'NAME=FACTOR' -> (name, factor >= 0)."""
    name, sep, value = text.rpartition("=")
    try:
        factor = float(value)
    except ValueError:
        factor = -1.0
    if not sep or not name or not factor >= 0:
        raise argparse.ArgumentTypeError(f"give NAME=FACTOR with FACTOR >= 0; got {text!r}")
    return name, factor


def _apply_groups(context, given):
    """Set the light groups' strengths from --group-strength and write their mix."""
    from . import relight

    groups = context.scene.radiosity_groups
    for name, _ in given:
        if name not in groups:
            names = ", ".join(f"'{g.name}'" for g in groups) or "none"
            raise BatchError(f"--group-strength {name}: no light group of that name "
                             f"(this bake's groups: {names})")
    with relight.quiet():
        for name, factor in given:
            groups[name].strength = factor
    try:
        return relight.mix(context, every=False)
    except relight.job.BakeError as exc:
        raise BatchError(str(exc)) from None


#: Blender's own options that mean we run inside the blender executable (sys.argv is Blender's).
_BLENDER_FLAGS = ("--background", "-b", "--python", "-P", "--python-expr", "--factory-startup")

#: How to get NumPy when the Blender running us has none (distributions' Blender builds).
NUMPY_HELP = ("NumPy is missing from this Blender's Python. Blender from blender.org bundles it; "
              "for a distribution's Blender install its NumPy package (Debian/Ubuntu: "
              "sudo apt install python3-numpy), or run the bake with the project's environment: "
              "bash scripts/bake_sample.sh, or .venv/bin/python radiosity_addon/batch.py "
              "scene.blend --output baked.blend")


def _split_argv(argv):
    """(arguments for us, True when running inside the blender executable).

    Raises BatchError when Blender's own options reach us: the ``--`` that separates Blender's
    options from ours was forgotten.
    """
    if "--" in argv:  # blender --background f.blend --python batch.py -- <ours>
        return argv[argv.index("--") + 1:], True
    if any(a in _BLENDER_FLAGS for a in argv[1:]):
        raise BatchError(f"put -- between Blender's options and the batch options: "
                         f"{_with_separator(argv)}")
    return argv[1:], False


def _with_separator(argv):
    """The command line *argv* with ``--`` inserted after the script (what the user meant)."""
    words = [os.path.basename(argv[0]) or "blender"] + list(argv[1:])
    at = None
    for i, word in enumerate(words[:-1]):
        if word in ("--python", "-P"):
            at = i + 2
    if at is None:
        return ("blender --background scene.blend --python radiosity_addon/batch.py -- "
                "--output baked.blend")
    return " ".join(words[:at] + ["--"] + words[at:])


def check_numpy():
    """Raise BatchError with :data:`NUMPY_HELP` unless NumPy can be imported."""
    try:
        import numpy  # noqa: F401
    except ImportError:
        raise BatchError(NUMPY_HELP) from None


def _output_path(option, given, taken):
    """Check an output path before the bake; return it absolute.

    *option* is the option's name (``--report``), *given* the path as typed (used in messages),
    *taken* maps absolute paths already claimed by other options to those options.
    """
    path = os.path.abspath(given)
    if os.path.isdir(path):
        raise BatchError(f"{option} {given}: is a folder; give a file name in it")
    folder = os.path.dirname(path)
    shown = os.path.dirname(given) or "."
    if not os.path.isdir(folder):
        raise BatchError(f"{option} {given}: the folder {shown} does not exist")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise BatchError(f"{option} {given}: the folder {shown} is not writable")
    if os.path.exists(path) and not os.access(path, os.W_OK):
        raise BatchError(f"{option} {given}: the file exists and is read-only")
    if path in taken:
        raise BatchError(f"{option} {given}: the same file as {taken[path]}; give another name")
    taken[path] = option
    return path


@contextlib.contextmanager
def _quiet():
    """Silence what Blender's C code prints on stdout and stderr while it saves or renders.

    It names our temporary files ("Saved copy as .radiosity-....blend") and prints EGL errors of
    its headless GPU set-up although the render succeeds; the batch prints its own lines instead.
    """
    sys.stdout.flush()
    sys.stderr.flush()
    saved = (os.dup(1), os.dup(2))
    null = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(null, 1)
        os.dup2(null, 2)
        yield
    finally:
        _flush_c_stdio()
        sys.stdout.flush()
        sys.stderr.flush()
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        for fd in (*saved, null):
            os.close(fd)


def _flush_c_stdio():
    """fflush(NULL): C-level buffered output goes where it was meant to, before fds move back."""
    try:
        import ctypes
        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError, TypeError):
        pass  # no C library to flush (not POSIX): nothing buffered there either


def _atomic_write(option, given, path, write):
    """Call write(tmp_path) and rename the temporary file onto *path* (same folder).

    Errors name *option* and the path as the user gave it (*given*), never the temporary file.
    """
    folder = os.path.dirname(path)
    tmp = None
    umask = os.umask(0)
    os.umask(umask)
    try:
        fd, tmp = tempfile.mkstemp(dir=folder, prefix=".radiosity-",
                                   suffix=os.path.splitext(path)[1])
        os.close(fd)
        os.remove(tmp)  # a name only: Blender would back up an existing file as <name>1
        with _quiet():
            write(tmp)
        if not os.path.isfile(tmp):
            raise BatchError(f"{option} {given}: Blender wrote nothing")
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    except OSError as exc:
        reason = os.strerror(exc.errno) if exc.errno else "the file system refused it"
        raise BatchError(f"{option} {given}: cannot write it ({reason.lower()})") from None
    except RuntimeError:  # a Blender operator failed (its text names the temporary file)
        raise BatchError(f"{option} {given}: Blender could not write it") from None
    finally:
        for leftover in (tmp, tmp + "1") if tmp else ():
            if os.path.exists(leftover):
                os.remove(leftover)


def run(argv):
    """Parse *argv* (sys.argv layout), bake, save; returns the report dict."""
    args_list, inside_blender = _split_argv(argv)
    import bpy

    need_input = not inside_blender or not bpy.data.filepath
    args = build_parser(need_input).parse_args(args_list)
    if need_input:
        src = os.path.abspath(args.input)
        if not os.path.isfile(src):
            raise BatchError(f"input file not found: {args.input}")
        try:
            bpy.ops.wm.open_mainfile(filepath=src, load_ui=False)
        except RuntimeError as exc:
            raise BatchError(f"cannot open {args.input}: {str(exc).strip().splitlines()[-1]}")
    src = os.path.abspath(bpy.data.filepath)
    taken = {src: "the input"}
    if args.in_place:
        if args.output and os.path.abspath(args.output) != src:
            raise BatchError("--in-place and --output name different files; give one")
        out_given, out = bpy.data.filepath, src
        if not os.access(src, os.W_OK) or not os.access(os.path.dirname(src), os.W_OK):
            raise BatchError(f"--in-place: {out_given} or its folder is not writable")
        taken[src] = "--in-place"
    elif args.output:
        if os.path.exists(args.output) and os.path.samefile(args.output, src):
            raise BatchError("--output is the input file; use --in-place to overwrite it")
        out_given, out = args.output, _output_path("--output", args.output, taken)
    else:
        raise BatchError("give --output baked.blend (or --in-place)")
    render = args.render and _output_path("--render", args.render, taken)
    report_path = args.report and _output_path("--report", args.report, taken)
    if args.render and bpy.context.scene.camera is None:
        raise BatchError("--render needs a scene camera; the scene has none")
    render_lux = args.render_lux and _output_path("--render-lux", args.render_lux, taken)
    if args.render_lux and os.path.splitext(args.render_lux)[1].lower() != ".png":
        raise BatchError(f"--render-lux {args.render_lux}: give a .png file name")
    if args.render_lux and bpy.context.scene.camera is None:
        raise BatchError("--render-lux needs a scene camera; the scene has none")
    lux_path = args.lux and _output_path("--lux", args.lux, taken)
    if args.lux and os.path.splitext(args.lux)[1].lower() not in (".csv", ".json"):
        raise BatchError(f"--lux {args.lux}: give a .csv or .json file name")

    from . import register
    from .job import CORE_OPTIONS, BakeError, apply, compute, options_from_props, prepare

    if not hasattr(bpy.types.Scene, "radiosity"):
        register()
    objects = bpy.context.scene.objects
    for name in args.calc_surface:
        obj = objects.get(name)
        if obj is None or obj.type != "MESH":
            raise BatchError(f"--calc-surface {name}: the scene has no mesh object of that name")
        obj.radiosity_calc_surface = True
    if args.lux and not any(o.type == "MESH" and o.radiosity_calc_surface for o in objects):
        raise BatchError("--lux: no calculation surface; mark one (Object > Calculation "
                         "Surface) or give --calc-surface OBJECT")
    options = options_from_props(bpy.context.scene.radiosity)
    for key in CORE_OPTIONS + ("selected_only", "make_single_user"):
        value = getattr(args, key)
        if value is not None:
            options[key] = None if value is AUTO else value
    if args.relight is not None:
        report, bake_input = _relight(bpy.context, args, src, args_list)
    else:
        with _cluster(args, options):
            try:
                bake_input = prepare(bpy.context, options)
                report = apply(bpy.context, bake_input, compute(bake_input))
            except BakeError as exc:
                raise BatchError(str(exc))
    if args.group_strength:
        report = _apply_groups(bpy.context, args.group_strength)
    report["input"] = src
    report["output"] = out
    from . import kept_file
    with kept_file.held():
        _atomic_write("--in-place" if args.in_place else "--output", out_given, out,
                      lambda tmp: bpy.ops.wm.save_as_mainfile(
                          filepath=tmp, copy=True, compress=False, check_existing=False))
    if options["save_relight"] if args.save_relight is None else args.save_relight:
        try:
            report["relight_data"], size = kept_file.save_scene(bpy.context.scene, out)
        except kept_file.RelightError as exc:
            raise BatchError(f"--save-relight: {exc}") from None
        _say(f"kept bake for Relight ({size / 2 ** 20:.0f} MB) -> {report['relight_data']}")
    # One line per file as it is written: should Blender abort in the render (no GPU), the
    # console still says what was done.
    _say(f"baked {report.get('patches', '?')} patches in "
         f"{report.get('timings', {}).get('total', 0.0):.2f} s -> {out_given}")
    if render:
        _atomic_write("--render", args.render, render,
                      lambda tmp: render_baked(bpy.context.scene, tmp))
        report["render"] = render
        _say(f"rendered the baked colours -> {args.render}")
    if render_lux:
        report["lux_scale"] = show_lux(bpy.context.scene, args).as_dict()
        _atomic_write("--render-lux", args.render_lux, render_lux,
                      lambda tmp: render_false_colour(bpy.context.scene, tmp,
                                                      report["lux_scale"]))
        report["render_lux"] = render_lux
        _say(f"rendered the lux in false colour -> {args.render_lux}")
    if lux_path:
        _atomic_write("--lux", args.lux, lux_path,
                      lambda tmp: write_lux_file(tmp, bake_input.extraction.surfaces,
                                                 args.lux.lower().endswith(".csv")))
        report["lux"] = lux_path
        _say(f"illuminance of {len(bake_input.extraction.surfaces)} calculation surface(s) "
             f"-> {args.lux}")
    if report_path:
        def dump(tmp):
            with open(tmp, "w", encoding="utf-8") as fh:
                json.dump(report, fh, indent=2)
        _atomic_write("--report", args.report, report_path, dump)
        _say(f"report -> {args.report}")
    return report


def _relight(context, args, src, given):
    """--relight: the input's kept bake relit with the light the .blend holds (kept_file);
    (report, the kept bake's input). Bake options are refused: they need a new bake."""
    from . import kept_file
    from .props import OPTIONS
    flags = {"--" + row.name.replace("_", "-") for row in OPTIONS if row.name != "save_relight"}
    bad = sorted({a.split("=")[0].replace("--no-", "--") for a in given} & flags)
    bad += ["--scheduler"] if args.scheduler else []
    if bad:
        raise BatchError(f"--relight re-solves the kept bake, so {', '.join(bad)} would need a "
                         f"new bake; leave out --relight to bake")
    path = os.path.abspath(args.relight) if args.relight else kept_file.beside(src)
    try:
        done = kept_file.relight_from(context, path)
    except kept_file.RelightError as exc:
        raise BatchError(f"--relight: {exc}") from None
    _say(f"relit the kept bake of {path}")
    return done


@contextlib.contextmanager
def _cluster(args, options):
    """With ``--scheduler``: the bake's hemicube calls on that Dask cluster (radiosity_addon/
    cluster.py), connected before the bake (a scheduler out of reach stops the batch here)."""
    if not args.scheduler:
        yield
        return
    if args.scheduler_wait <= 0:
        raise BatchError(f"--scheduler-wait must be > 0 seconds; got {args.scheduler_wait:g}")
    from ..core import parallel
    from . import cluster

    local = args.scheduler == "local"
    workers = options.get("workers") or parallel.cpu_count()
    try:
        client = cluster.connect(None if local else args.scheduler, workers=workers,
                                 wait=args.scheduler_wait)
    except cluster.ClusterError as exc:
        raise BatchError(f"--scheduler: {exc}") from None
    previous = cluster.use(client, parallel)
    try:
        yield
    finally:
        parallel.set_backend(previous)
        cluster_obj = client.cluster if local else None
        client.close()
        if cluster_obj is not None:
            cluster_obj.close()


def write_lux_file(path, surfaces, as_csv):
    """The calculation surfaces' grid illuminance: CSV rows (object, x, y, z, lux) or JSON (per
    surface its summary and points)."""
    from .surfaces import rows

    with open(path, "w", encoding="utf-8", newline="") as fh:
        if as_csv:
            csv.writer(fh).writerows(rows(surfaces))
        else:
            json.dump([dict(s.summary, grid=s.grid.tolist(), lux=s.grid_lux.tolist())
                       for s in surfaces], fh, indent=1)


def _say(text):
    print(f"{PROG}: {text}", flush=True)


def render_baked(scene, path):
    """Render the baked colours, flat-shaded, from the scene camera (Workbench) to a PNG.

    Changes render settings of the in-memory scene only (after the .blend was saved).
    """
    import bpy

    scene.render.engine = "BLENDER_WORKBENCH"
    shading = scene.display.shading
    shading.light = "FLAT"
    shading.color_type = "VERTEX"
    shading.show_shadows = False
    shading.show_cavity = False
    shading.show_object_outline = False
    shading.show_specular_highlight = False
    scene.render.film_transparent = False
    # Baked values are scene-linear radiance: show them through the plain sRGB transform (no
    # filmic/AgX tone curve), with the scene's exposure.
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.render.image_settings.file_format = "PNG"
    scene.render.filepath = path
    # Workbench draws with the GPU; the module build renders off-screen without a window.
    scene.render.use_file_extension = False
    bpy.ops.render.render(write_still=True)


def show_lux(scene, args):
    """Show the bake's lux in false colour (luxview.show) on the scale the options ask for;
    options not given come from the scene's Lux Scale and Lux Max."""
    from .luxview import LuxViewError, scale_settings, show

    mode, top = scale_settings(scene.radiosity)
    if args.lux_scale is not None:
        mode = args.lux_scale
    if args.lux_max is not None:
        top = None if args.lux_max is AUTO else args.lux_max
    try:
        return show(scene, (mode, top))
    except LuxViewError as exc:
        raise BatchError(f"--render-lux: {exc}") from None


def render_false_colour(scene, path, scale):
    """Render the false-colour display (:func:`render_baked`, colours exactly as stored: exposure
    0, gamma 1, no curves, no dither) and add the legend of *scale* (``Scale.as_dict()``)."""
    from ..core.falsecolour import Scale
    from .luxview import add_legend

    view = scene.view_settings
    view.exposure, view.gamma, view.use_curve_mapping = 0.0, 1.0, False
    scene.render.dither_intensity = 0.0
    render_baked(scene, path)
    add_legend(path, Scale(scale["mode"], scale["top"], scale["bottom"], tuple(scale["ticks"])))


def main(argv=None):
    """Entry point: run and exit with 0, or print one line and exit non-zero."""
    argv = sys.argv if argv is None else argv
    try:
        run(argv)
    except BatchError as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 2 if str(exc).startswith("bad option") else 1
    except Exception as exc:  # one line, never a traceback, for any unexpected failure
        text = " ".join(str(exc).split()) or type(exc).__name__
        print(f"{PROG}: error: {type(exc).__name__}: {text}", file=sys.stderr)
        return 1
    return 0


def _load_package():
    """Import the repository as the extension package (see bootstrap.py)."""
    path = os.path.join(os.path.dirname(os.path.abspath(__file__)), "bootstrap.py")
    spec = importlib.util.spec_from_file_location("radiosity_bootstrap", path)
    bootstrap = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bootstrap)
    return bootstrap.load_package()


def _exit(code):
    """End the process with *code*, after removing Blender's session temporary folder.

    os._exit: inside the blender executable a SystemExit from a --python script is not turned
    into the process's status, and the bpy 4.2 module can crash while the interpreter shuts down
    (exit status -11 after a successful bake). Every output is complete and renamed by now. Blender
    removes its /tmp/blender_* folder only on a normal exit, so that is done here.
    """
    sys.stdout.flush()
    sys.stderr.flush()
    bpy = sys.modules.get("bpy")
    tmp = getattr(getattr(bpy, "app", None), "tempdir", "") if bpy else ""
    if tmp and os.path.basename(os.path.normpath(tmp)).startswith("blender_"):
        shutil.rmtree(tmp, ignore_errors=True)
    os._exit(code)


def _script_main(argv):
    """The script's entry point: checks that need no package (the ``--``, NumPy), then main."""
    try:
        _split_argv(argv)
        check_numpy()
        batch = importlib.import_module(f"{_load_package().__name__}.radiosity_addon.batch")
    except BatchError as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 1
    except Exception as exc:  # the package failed to load: one line, never exit 0
        text = " ".join(str(exc).split()) or type(exc).__name__
        print(f"{PROG}: error: cannot load Radiosity Baker ({type(exc).__name__}: {text})",
              file=sys.stderr)
        return 1
    return batch.main(argv)


if __name__ == "__main__":
    _exit(_script_main(sys.argv))
