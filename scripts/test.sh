#!/usr/bin/env bash
# The whole test suite, as CI runs it. Builds the pinned environments itself (first run ~2 min).
#   1. core tests on NumPy 2.x            (.venv-np2: no Blender at all)
#   2. core, add-on and benchmark-harness tests on bpy 5.0.1 with NumPy 1.26 (.venv)
#   3. the add-on tests again (extension build/validate/install/register included) on bpy 4.2 LTS
#   4. the UI tier: a real Blender 4.3 window under Xvfb in a cached Debian 13 root
#      (scripts/real_blender.sh: needs root; the first run builds the root, about a minute)
# Extra arguments go to every pytest run (e.g. -x, -k name).
set -uo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
set -e
bash scripts/setup_env.sh np2
bash scripts/setup_env.sh blender
bash scripts/setup_env.sh bpy42
set +e
# Everything the stages write to a temporary folder (JUnit files, pytest's tmp_path, Blender's
# blender_* session folders) goes under one folder, removed at the end.
scratch="$(mktemp -d "${TMPDIR:-/tmp}/radiosity-tests.XXXXXX")"
trap 'rm -rf "$scratch"' EXIT
results="$scratch/junit"
mkdir "$results"
export TMPDIR="$scratch"
status=0
nargs=$#
run() {  # run NAME PYTHON PYTEST-ARGS...
  local name="$1" py="$2"; shift 2
  echo "=== $name ==="
  "$py" -m pytest -q -p no:cacheprovider --junitxml="$results/$name.xml" "$@"
  local rc=$?
  # pytest exits 5 when it collected nothing: a failure of this script, except in a partial run
  # (extra arguments such as -k name leave some stages empty; junit_total.py still fails a run
  # in which nothing ran at all).
  [ $rc -eq 0 ] || { [ $rc -eq 5 ] && [ $nargs -gt 0 ]; } || status=1
}
run core-numpy2    .venv-np2/bin/python   tests/core "$@"
run blender-5.0    .venv/bin/python       tests --ignore=tests/ui "$@"
run blender-4.2    .venv-bpy42/bin/python tests/addon "$@"
# The UI tier's Debian root is built (once; cached) before its stage, with its own messages. If it
# cannot be built, the stage counts as one failure with the reason: never a silent skip.
if bash scripts/real_blender.sh true; then
  run ui-blender-4.3 .venv/bin/python tests/ui "$@"
else
  echo "=== ui-blender-4.3 ===" && echo "FAILED: the real-Blender root could not be built (above)"
  status=1
  .venv/bin/python scripts/junit_total.py --failure ui-blender-4.3 \
    "the real-Blender root could not be built (scripts/real_blender.sh)" >"$results/ui.xml"
fi
.venv/bin/python scripts/junit_total.py "$results"/*.xml || status=1
exit $status
