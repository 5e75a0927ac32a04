"""Bare ``pytest`` works without Blender: the add-on tests need the ``bpy`` module.

Without it, ``tests/addon`` is not collected (its conftest imports bpy to load the add-on) and the
header says so; ``tests/compare`` skips its Blender tests itself (``pytest.importorskip``).
``scripts/test.sh`` runs every directory with interpreters that have bpy.
"""

import importlib.util

HAVE_BPY = importlib.util.find_spec("bpy") is not None

collect_ignore = [] if HAVE_BPY else ["addon"]


def pytest_report_header(config):
    if not HAVE_BPY:
        return "bpy not installed: tests/addon not collected (they need Blender's bpy module)"
    return None
