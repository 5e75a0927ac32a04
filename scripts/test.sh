#!/usr/bin/env bash
# The whole test suite, as CI runs it. Builds the pinned environments itself (first run ~2 min).
#   1. core tests on NumPy 2.x            (.venv-np2: no Blender at all)
#   2. core, add-on and benchmark-harness tests on bpy 5.0.1 with NumPy 1.26 (.venv)
#   3. the add-on tests again (extension build/validate/install/register included) on bpy 4.2 LTS
# Extra arguments go to every pytest run (e.g. -x, -k name).
set -uo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
set -e
bash scripts/setup_env.sh np2
bash scripts/setup_env.sh blender
bash scripts/setup_env.sh bpy42
set +e
results="$(mktemp -d)"
status=0
run() {  # run NAME PYTHON PYTEST-ARGS...
  local name="$1" py="$2"; shift 2
  echo "=== $name ==="
  "$py" -m pytest -q -p no:cacheprovider --junitxml="$results/$name.xml" "$@"
  local rc=$?
  # pytest exits 5 when it collected nothing: that is a failure of this script, not a pass.
  [ $rc -eq 0 ] || status=1
}
run core-numpy2   .venv-np2/bin/python   tests/core "$@"
run blender-5.0   .venv/bin/python       tests "$@"
run blender-4.2   .venv-bpy42/bin/python tests/addon "$@"
.venv/bin/python scripts/junit_total.py "$results"/*.xml || status=1
exit $status
