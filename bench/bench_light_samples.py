"""Shadow rays against time: 16 point lights of 5 cm in bench.compare.lights' room.

The room of :mod:`bench.compare.lights` (5 x 4 x 2.7 m, one quad per wall, a table and a
cabinet), lit by a 4 x 4 grid of point lights (radius 5 cm, 60 W) under the ceiling, baked into
the radiosity mesh at defaults with each ``light_samples`` given: the wall time, the output
vertices and the shadow rays cast (points, elements and patches).

Run: ``.venv/bin/python bench/bench_light_samples.py [64 16 1]``. Prints one line per value.
"""

import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from bench.compare.lights import room_arrays  # noqa: E402
from core.bake import BakeSettings, bake  # noqa: E402
from core.scene import make_scene  # noqa: E402


def lights():
    """Sixteen soft point lights on a 4 x 4 grid, 2.4 m up."""
    return [dict(kind="point", name="L%d" % i, position=(0.6 + 1.25 * (i % 4),
                                                        0.5 + 1.0 * (i // 4), 2.4),
                 power=60.0, radius=0.05) for i in range(16)]


def main(argv):
    scene = make_scene(**room_arrays(), lights=lights())
    for n in [int(a) for a in argv] or [64, 16, 1]:
        t = time.perf_counter()
        result = bake(scene, BakeSettings(output_mode="mesh", light_samples=n))
        print("light_samples %d: %.1f s, %d vertices, %d shadow rays"
              % (n, time.perf_counter() - t, len(result.output.vertices),
                 result._state.direct.rays), flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
