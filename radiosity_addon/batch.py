"""Headless bake: the same bake as the panel's button, from the command line.

Two ways to run it::

    blender --background scene.blend --python radiosity_addon/batch.py -- --output baked.blend
    python radiosity_addon/batch.py scene.blend --output baked.blend      # bpy module

Options: ``--report report.json``, ``--render out.png`` (Workbench render of the baked colours from
the scene camera), ``--patch-size``, ``--method``, ``--resolution``, ``--solver``, ``--tolerance``,
``--max-iterations``, ``--selected-only``, ``--make-single-user``, ``--in-place``. Anything not given
comes from the .blend's own bake settings (Scene > Radiosity). The input is never overwritten unless
``--in-place``; outputs are written to a temporary file and renamed. Any error exits with status 1
(2 for a bad option) and one line on stderr.
"""

import argparse
import importlib
import importlib.util
import json
import os
import sys
import tempfile

PROG = "radiosity-batch"


class BatchError(Exception):
    """A user-facing error: printed on one line, exit status 1."""


class _Parser(argparse.ArgumentParser):
    def error(self, message):
        raise BatchError(f"bad option: {message}")


def _option_type(row):
    """argparse type of a settings row: parse, then check against the row (one range)."""
    parse = int if row.type == "int" else float

    def convert(text):
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
        parser.add_argument(flag, type=_option_type(row), metavar=metavar, help=text)


def build_parser(need_input):
    """The command-line parser (*need_input*: the .blend is a positional argument).

    The bake options are made from the settings table (``props.OPTIONS``); anything not given
    comes from the .blend's own settings.
    """
    # Imported here, not at the top: this file also runs as a plain script (``__main__``),
    # where the package's relative imports exist only once _load_package() has run.
    from .props import OPTIONS

    p = _Parser(prog=PROG, description="Bake radiosity into vertex colours, headless. Bake "
                "options not given come from the .blend's own settings (Scene > Radiosity).")
    if need_input:
        p.add_argument("input", help="the .blend to bake (never modified unless --in-place)")
    p.add_argument("--output", help="where to save the baked .blend")
    p.add_argument("--in-place", action="store_true", help="overwrite the input .blend")
    p.add_argument("--report", help="write the bake report (JSON) here")
    p.add_argument("--render", help="render the baked colours (Workbench) to this PNG")
    for row in OPTIONS:
        add_option(p, row)
    return p


def _split_argv(argv):
    """(arguments for us, True when running inside the blender executable)."""
    if "--" in argv:  # blender --background f.blend --python batch.py -- <ours>
        return argv[argv.index("--") + 1:], True
    return argv[1:], False


def _atomic_write(path, write):
    """Call write(tmp_path) and rename the temporary file onto *path* (same folder)."""
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise BatchError(f"output folder does not exist: {folder}")
    fd, tmp = tempfile.mkstemp(dir=folder, prefix=".radiosity-", suffix=os.path.splitext(path)[1])
    os.close(fd)
    os.remove(tmp)  # a name only: Blender would back up an existing file as <name>1
    umask = os.umask(0)
    os.umask(umask)
    try:
        write(tmp)
        if not os.path.isfile(tmp):
            raise BatchError(f"nothing was written for {path}")
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    finally:
        for leftover in (tmp, tmp + "1"):
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
    if args.in_place:
        if args.output and os.path.abspath(args.output) != src:
            raise BatchError("--in-place and --output name different files; give one")
        out = src
    elif args.output:
        out = os.path.abspath(args.output)
        if os.path.exists(out) and os.path.samefile(out, src):
            raise BatchError("--output is the input file; use --in-place to overwrite it")
    else:
        raise BatchError("give --output baked.blend (or --in-place)")
    if args.render and bpy.context.scene.camera is None:
        raise BatchError("--render needs a scene camera; the scene has none")

    from . import register
    from .job import CORE_OPTIONS, BakeError, bake_now, options_from_props

    if not hasattr(bpy.types.Scene, "radiosity"):
        register()
    options = options_from_props(bpy.context.scene.radiosity)
    for key in CORE_OPTIONS + ("selected_only", "make_single_user"):
        value = getattr(args, key)
        if value is not None:
            options[key] = value
    try:
        report = bake_now(bpy.context, options)
    except BakeError as exc:
        raise BatchError(str(exc))
    report["input"] = src
    report["output"] = out
    _atomic_write(out, lambda tmp: bpy.ops.wm.save_as_mainfile(
        filepath=tmp, copy=True, compress=False, check_existing=False))
    if args.render:
        _atomic_write(os.path.abspath(args.render),
                      lambda tmp: render_baked(bpy.context.scene, tmp))
        report["render"] = os.path.abspath(args.render)
    if args.report:
        def dump(tmp):
            with open(tmp, "w", encoding="utf-8") as fh:
                json.dump(report, fh, indent=2)
        _atomic_write(os.path.abspath(args.report), dump)
    return report


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


def main(argv=None):
    """Entry point: run and exit with 0, or print one line and exit non-zero."""
    argv = sys.argv if argv is None else argv
    try:
        report = run(argv)
    except BatchError as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 2 if str(exc).startswith("bad option") else 1
    except Exception as exc:  # one line, never a traceback, for any unexpected failure
        text = " ".join(str(exc).split()) or type(exc).__name__
        print(f"{PROG}: error: {type(exc).__name__}: {text}", file=sys.stderr)
        return 1
    print(f"{PROG}: baked {report.get('patches', '?')} patches in "
          f"{report.get('timings', {}).get('total', 0.0):.2f} s -> {report['output']}")
    return 0


def _load_package():
    """Import the repository as the extension package (see bootstrap.py)."""
    path = os.path.join(os.path.dirname(os.path.abspath(__file__)), "bootstrap.py")
    spec = importlib.util.spec_from_file_location("radiosity_bootstrap", path)
    bootstrap = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bootstrap)
    return bootstrap.load_package()


if __name__ == "__main__":
    _batch = importlib.import_module(f"{_load_package().__name__}.radiosity_addon.batch")
    _code = _batch.main(sys.argv)
    sys.stdout.flush()
    sys.stderr.flush()
    # os._exit: inside the blender executable a SystemExit from a --python script is not turned
    # into the process's status, and the bpy 4.2 module can crash while the interpreter shuts
    # down (exit status -11 after a successful bake). Every output is complete and renamed by now.
    os._exit(_code)
