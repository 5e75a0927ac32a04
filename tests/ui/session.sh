#!/bin/sh
# The UI tier's Blender session, run inside the Debian 13 root by scripts/real_blender.sh:
#   sh tests/ui/session.sh OUT_DIR
# Builds the extension with Blender's own CLI, validates it, installs the zip into a throw-away
# user configuration (BLENDER_USER_RESOURCES) and enabled, then runs tests/ui/drive.py in a real
# Blender window under Xvfb on sample_blends/cornell_box.blend. Everything Blender prints goes to
# OUT_DIR/*.log; tests/ui/test_ui.py reads those and OUT_DIR/results.json.
set -eu
out="$1"
mkdir -p "$out"
work="$(mktemp -d /tmp/radiosity-ui.XXXXXX)"
trap 'rm -rf "$work"' EXIT
export BLENDER_USER_RESOURCES="$work/user"
mkdir -p "$work/dist"
blender --command extension build --source-dir . --output-dir "$work/dist" >"$out/build.log" 2>&1
zip="$(ls "$work"/dist/radiosity_baker-*.zip)"
blender --command extension validate "$zip" >"$out/validate.log" 2>&1
blender --command extension install-file --repo user_default --enable "$zip" >"$out/install.log" 2>&1
rc=0
xvfb-run -a -s "-screen 0 1280x800x24" \
  blender sample_blends/cornell_box.blend --python tests/ui/drive.py -- "$out" \
  >"$out/blender.log" 2>&1 || rc=$?
echo "$rc" >"$out/blender.rc"
