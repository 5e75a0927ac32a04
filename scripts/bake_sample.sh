#!/usr/bin/env bash
# The main job: bake a bundled sample scene headless and write the baked .blend, a JSON report and
# a Workbench render of the baked colours. Builds the pinned environment (.venv) on first run.
#   bash scripts/bake_sample.sh [scene-name] [extra batch.py options...]
# scene-name is a file in sample_blends/ without .blend (default: cornell_box).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
scene="${1:-cornell_box}"
[ $# -gt 0 ] && shift
bash scripts/setup_env.sh blender
mkdir -p out
.venv/bin/python radiosity_addon/batch.py "sample_blends/$scene.blend" \
  --output "out/${scene}_baked.blend" \
  --report "out/${scene}_report.json" \
  --render "out/${scene}.png" "$@"
