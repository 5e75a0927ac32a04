"""Write docs/stability.md: every failure class of issue 11 provoked and measured.

    .venv/bin/python -m bench.stability            # full: 12 to 31 minutes on 2 shared cores
    .venv/bin/python -m bench.stability --quick    # fewer cases, smaller mesh: about a minute
    .venv/bin/python -m bench.stability --out DIR  # DIR/stability.md and DIR/images/

Prints one line per bake and the run time; the document and its charts are regenerated whole.
"""

import argparse
import sys
import time
from pathlib import Path

from . import (concave, duplicates, emitters, furnace, internal, near, orient, placement,
               slivers, unlit)
from .common import ROOT, Context
from .report import write

#: The failure classes in the document's order (issue 11).
CLASSES = (emitters, duplicates, orient, slivers, concave, placement, unlit, furnace, near,
           internal)

#: Seconds one bake of a non-default form-factor method may take before it is cancelled (and
#: larger cases of it skipped, as predicted over the cap).
CAP = 30.0
QUICK_CAP = 5.0


def main(argv=None):
    parser = argparse.ArgumentParser(prog="python -m bench.stability", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="fewer cases (about a minute)")
    parser.add_argument("--out", type=Path, default=ROOT / "docs",
                        help="directory of stability.md (charts in its images/)")
    parser.add_argument("--only", nargs="*", default=None,
                        help="module names of the classes to run (development)")
    args = parser.parse_args(argv)
    images = args.out / "images"
    images.mkdir(parents=True, exist_ok=True)
    ctx = Context(quick=args.quick, images=images, cap=QUICK_CAP if args.quick else CAP)
    t0 = time.perf_counter()
    sections = []
    for module in CLASSES:
        if args.only is not None and module.__name__.rsplit(".", 1)[-1] not in args.only:
            continue
        t = time.perf_counter()
        section = module.run(ctx)
        section.seconds = time.perf_counter() - t
        ctx.log(f"{section.title}: {section.seconds:.1f} s")
        sections.append(section)
    seconds = time.perf_counter() - t0
    command = ".venv/bin/python -m bench.stability" + (" --quick" if args.quick else "")
    path = args.out / "stability.md"
    write(path, sections, seconds=seconds, quick=args.quick, command=command)
    print(f"wrote {path} ({len(sections)} failure classes) in {seconds:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
