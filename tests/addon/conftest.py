"""Add-on tests: the repository loaded as the extension package, a fresh Blender file per test."""

import importlib.util
import os

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def _load_package():
    path = os.path.join(ROOT, "radiosity_addon", "bootstrap.py")
    spec = importlib.util.spec_from_file_location("radiosity_bootstrap", path)
    bootstrap = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bootstrap)
    return bootstrap.load_package()


PACKAGE = _load_package()

import bpy  # noqa: E402  (after the package, which needs nothing from it at import)


@pytest.fixture(scope="session")
def package():
    """The repository as a package, registered for the whole session."""
    PACKAGE.register()
    yield PACKAGE
    PACKAGE.unregister()


@pytest.fixture(autouse=True)
def fresh_file(request):
    """An empty factory-startup file before and after every test (no state leaks between tests).

    read_homefile, not read_factory_settings: after the latter the background undo stack is off.
    """
    bpy.ops.wm.read_homefile(use_factory_startup=True, use_empty=True)
    yield
    bpy.ops.wm.read_homefile(use_factory_startup=True, use_empty=True)


# The bpy 4.2 module can crash (SIGSEGV) while the interpreter shuts down, after every test has
# passed and every report is written. So once pytest is completely done (unconfigure runs after
# the terminal summary and the JUnit file), the process ends with pytest's own exit status
# instead of going through Blender's exit handlers. Those handlers would also remove Blender's
# session folder (/tmp/blender_*), so that is done here.
_EXIT = {}


def pytest_sessionfinish(session, exitstatus):
    _EXIT["status"] = int(exitstatus)


@pytest.hookimpl(trylast=True)
def pytest_unconfigure(config):
    if "status" in _EXIT and bpy.app.version < (5, 0, 0):
        import shutil
        import sys
        sys.stdout.flush()
        sys.stderr.flush()
        tmp = bpy.app.tempdir
        if tmp and os.path.basename(os.path.normpath(tmp)).startswith("blender_"):
            shutil.rmtree(tmp, ignore_errors=True)
        os._exit(_EXIT["status"])
