"""Speed-against-accuracy benchmark: our engine, Cycles and Radiance on the same scenes.

``metrics`` is pure NumPy; ``cycles`` needs ``bpy``; ``radiance`` needs ``pyradiance``; ``run`` is
the sweep (``python -m bench.compare.run --help``). Nothing here is part of the extension.
"""
