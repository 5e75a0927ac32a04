"""Re-time our bake against Cycles back to back in one process (ratios on a shared machine).

Run (from the repository root)::

    .venv/bin/python -m bench.compare.retime --scene office --samples 512 --repeat 2

Prints, per repetition, the wall time of our default bake, of one with a single element level,
and of a Cycles bake at ``--samples``: the sweep's cached Cycles times can be checked against the
machine's speed of the moment.
"""

import argparse
import time
from pathlib import Path

from . import cycles
from .run import ROOT, _face_size


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="office")
    ap.add_argument("--samples", type=int, default=512)
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--threads", type=int, default=2)
    args = ap.parse_args(argv)
    from core.bake import BakeSettings, bake
    from core.scene import make_scene

    sc = cycles.load(Path(ROOT) / "bench" / "blends" / ("%s.blend" % args.scene))
    arrays = cycles.extract(sc)
    scene = make_scene(**arrays)
    ps = _face_size(arrays) * (1 + 1e-6)
    for rep in range(args.repeat):
        t = time.perf_counter()
        res = bake(scene, BakeSettings(patch_size=ps))
        ours = time.perf_counter() - t
        t = time.perf_counter()
        bake(scene, BakeSettings(patch_size=ps, element_levels=1))
        one = time.perf_counter() - t
        _, sec = cycles.bake(sc, args.samples, seed=0, threads=args.threads)
        stages = ", ".join("%s %.1f" % kv for kv in res.report["timings"].items())
        print("rep %d: ours default %.1f s (%s); ours, one element level %.1f s; Cycles %d "
              "samples %.1f s" % (rep, ours, stages, one, args.samples, sec), flush=True)


if __name__ == "__main__":
    main()
