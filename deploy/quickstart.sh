#!/usr/bin/env bash
# One command from a fresh Debian bookworm machine to a result (README.md "Quick start").
#   bash deploy/quickstart.sh demo   install what the programs need (deploy/packages.txt), build
#                                    the CLI, the server and the model importer, solve the
#                                    Cornell box
#   bash deploy/quickstart.sh test   install what the tests need too (deploy/packages-test.txt),
#                                    build everything, run the whole test suite
# Environment: BUILD_DIR (default build), JOBS (default: all cores), OUT (demo output dir),
# CMAKE_ARGS (more cmake options), CTEST_EXCLUDE (labels left out, a regex; default long).
set -euo pipefail
cd "$(dirname "$0")/.."
mode="${1:-demo}"
BUILD_DIR="${BUILD_DIR:-build}"
JOBS="${JOBS:-$(nproc)}"

# The packages of the lists given that are not installed yet, installed (with sudo when not root).
install_packages() {
  local missing=()
  while read -r pkg; do
    [[ -z "$pkg" || "$pkg" == \#* ]] && continue
    dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || missing+=("$pkg")
  done < <(cat "$@")
  if ((${#missing[@]})); then
    echo "quickstart: installing ${missing[*]}" >&2
    local sudo=""
    [[ "$(id -u)" -ne 0 ]] && sudo="sudo"
    $sudo apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}"
  fi
}

# cmake options, then build targets (none: all).
build() {
  local options=("$1")
  shift
  cmake -S . -B "$BUILD_DIR" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo ${options[0]} ${CMAKE_ARGS:-} >/dev/null
  cmake --build "$BUILD_DIR" -j "$JOBS" ${1:+--target "$@"}
}

case "$mode" in
  demo)
    install_packages deploy/packages.txt
    # The programs only: the tests and the benchmark are left out of this build directory's
    # configuration until `test` turns them on again.
    build "-DRADIOSITY_TESTS=OFF -DRADIOSITY_BENCH=OFF" radiosity radiosity-server radiosity-import
    out="${OUT:-out/cornell_box}"
    "$BUILD_DIR/bin/radiosity" solve scenes/cornell_box.obj --out "$out"
    echo "quickstart: open $out/image.png (also image.exr, mesh.ply, elements.csv, summary.json)" >&2
    ;;
  test)
    install_packages deploy/packages.txt deploy/packages-test.txt
    build "-DRADIOSITY_TESTS=ON -DRADIOSITY_BENCH=ON"
    ctest --test-dir "$BUILD_DIR" --output-on-failure -j "$JOBS" -LE "${CTEST_EXCLUDE:-long}"
    ;;
  *)
    echo "usage: bash deploy/quickstart.sh demo|test" >&2
    exit 2
    ;;
esac
