#!/usr/bin/env bash
# One command from a fresh Debian bookworm machine to a result (README "Quick start").
#   bash deploy/quickstart.sh demo   install what is missing, build, solve the Cornell box
#   bash deploy/quickstart.sh test   install what is missing, build, run the whole test suite
# Environment: BUILD_DIR (default build), JOBS (default: all cores), OUT (demo output dir),
# CMAKE_ARGS (more cmake options), CTEST_EXCLUDE (labels left out, a regex; default long).
set -euo pipefail
cd "$(dirname "$0")/.."
mode="${1:-demo}"
BUILD_DIR="${BUILD_DIR:-build}"
JOBS="${JOBS:-$(nproc)}"

install_packages() {
  local missing=()
  while read -r pkg; do
    [[ -z "$pkg" || "$pkg" == \#* ]] && continue
    dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || missing+=("$pkg")
  done < deploy/packages.txt
  if ((${#missing[@]})); then
    echo "quickstart: installing ${missing[*]}" >&2
    local sudo=""
    [[ "$(id -u)" -ne 0 ]] && sudo="sudo"
    $sudo apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}"
  fi
}

build() {
  cmake -S . -B "$BUILD_DIR" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo ${CMAKE_ARGS:-} >/dev/null
  cmake --build "$BUILD_DIR" -j "$JOBS"
}

case "$mode" in
  demo)
    install_packages
    build
    out="${OUT:-out/cornell_box}"
    "$BUILD_DIR/bin/radiosity" solve scenes/cornell_box.obj --out "$out"
    echo "quickstart: open $out/image.png (also image.exr, mesh.ply, elements.csv, summary.json)" >&2
    ;;
  test)
    install_packages
    build
    ctest --test-dir "$BUILD_DIR" --output-on-failure -j "$JOBS" -LE "${CTEST_EXCLUDE:-long}"
    ;;
  *)
    echo "usage: bash deploy/quickstart.sh demo|test" >&2
    exit 2
    ;;
esac
