"""Load the repository as the package the extension is, for scripts and tests run from the repo.

Inside Blender the extension's root is a package (``bl_ext.<repo>.radiosity_baker``) and
``radiosity_addon`` reaches the core relatively (``from ..core import bake``). Code run straight
from a checkout (the batch script, the tests, scripts/) needs the same package structure, so it
loads the repository root once as a package named :data:`PACKAGE`. This module imports nothing
but the standard library and is itself loaded by path, so it works before any package exists::

    spec = importlib.util.spec_from_file_location("radiosity_bootstrap", ".../bootstrap.py")
    ...
    package = module.load_package()
"""

import importlib
import importlib.util
import os
import sys

#: The name the repository root is imported under outside Blender's extension system.
PACKAGE = "radiosity_baker"

#: The repository root: the folder holding blender_manifest.toml and the top-level __init__.py.
REPO_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def load_package(name=PACKAGE, root=REPO_ROOT):
    """Import the repository root as a package and return it (idempotent).

    Parameters
    ----------
    name : str
        Package name to register in ``sys.modules``.
    root : str
        Folder that holds the top-level ``__init__.py``.

    Returns
    -------
    module
        The package; ``package.radiosity_addon`` and ``package.core`` are importable beneath it.
    """
    existing = sys.modules.get(name)
    if existing is not None:
        return existing
    init = os.path.join(root, "__init__.py")
    if not os.path.isfile(init):
        raise ImportError(f"root must hold __init__.py; got no such file in {root!r}")
    spec = importlib.util.spec_from_file_location(name, init, submodule_search_locations=[root])
    package = importlib.util.module_from_spec(spec)
    sys.modules[name] = package
    try:
        spec.loader.exec_module(package)
    except BaseException:
        del sys.modules[name]
        raise
    importlib.import_module(f"{name}.radiosity_addon")
    return package

