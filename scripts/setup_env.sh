#!/usr/bin/env bash
# Create (or reuse) the project's virtual environments with pinned packages.
#   bash scripts/setup_env.sh            -> .venv        (bpy 5.0.1, NumPy 1.26, pytest, matplotlib, pyradiance)
#   bash scripts/setup_env.sh np2        -> .venv-np2    (NumPy 2.x, pytest: the core without Blender)
#   bash scripts/setup_env.sh bpy42      -> .venv-bpy42  (bpy 4.2 LTS: the extension on the oldest Blender)
# Each environment is rebuilt when its requirements file changes.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
which="${1:-blender}"
case "$which" in
  blender) venv="$here/.venv";       req="$here/requirements/blender.txt" ;;
  np2)     venv="$here/.venv-np2";   req="$here/requirements/core-numpy2.txt" ;;
  bpy42)   venv="$here/.venv-bpy42"; req="$here/requirements/blender42.txt" ;;
  *) echo "setup_env.sh: unknown environment '$which' (expected blender, np2 or bpy42)" >&2; exit 2 ;;
esac
python="${PYTHON:-python3.11}"
command -v "$python" >/dev/null 2>&1 || python=python3
stamp="$venv/.requirements.sha256"
want="$(sha256sum "$req" | cut -d' ' -f1)"
if [ -x "$venv/bin/python" ] && [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$want" ]; then
  exit 0
fi
echo "setup_env.sh: building $venv from $(basename "$req")" >&2
rm -rf "$venv"
"$python" -m venv "$venv"
"$venv/bin/python" -m pip install --quiet --upgrade pip >&2
"$venv/bin/python" -m pip install --quiet -r "$req" >&2
echo "$want" > "$stamp"
