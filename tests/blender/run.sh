#!/usr/bin/env bash
# ctest BlenderImportsBakedLight: solves the furnace and the Cornell box with the CLI and imports
# both mesh.glb files in headless Blender (import_glb.py says what is checked).
# Usage: run.sh RADIOSITY_CLI SOURCE_DIR.  Exit 77 (ctest: skipped) where Blender is absent.
set -euo pipefail
cli="$1"
src="$2"
if ! command -v blender >/dev/null; then
  echo "skipped: blender is not installed (apt-get install blender; deploy/packages-test.txt lists it)"
  exit 77
fi
out="$(mktemp -d)"
trap 'rm -rf "$out"' EXIT
"$cli" solve "$src/scenes/furnace.json" --out "$out/furnace" --quiet
"$cli" solve "$src/scenes/cornell_box.obj" --out "$out/cornell" --quiet
rc=0
blender -b --factory-startup --python-exit-code 1 --python "$src/tests/blender/import_glb.py" \
  -- "$out/furnace/mesh.glb" "$out/cornell/mesh.glb" >"$out/blender.log" 2>&1 || rc=$?
if ((rc != 0)); then
  cat "$out/blender.log"
  exit "$rc"
fi
grep -E "^(furnace|cornell|blender):" "$out/blender.log"
