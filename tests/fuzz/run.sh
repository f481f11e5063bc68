#!/usr/bin/env bash
# Builds the libFuzzer targets with clang (ASan + UBSan) and runs each for SECONDS (default 60).
#   bash tests/fuzz/run.sh [SECONDS] [TARGET ...]     (targets: obj scene model; default obj scene)
# `model` drives assimp, which is not ours: it runs with leak detection off (assimp leaks on some
# malformed files), and what it finds in assimp (crashes, hangs) is what the service's import
# process (radiosity-import) contains; CI runs obj and scene.
# Inputs that crash are written to build-fuzz/artifacts/ and the script fails; copy each into
# tests/fuzz/regressions/{obj,scene,model}/ so that tests/solver/fuzz_regression_test.cc replays it
# forever.
set -euo pipefail
cd "$(dirname "$0")/../.."
seconds="${1:-60}"
shift || true
targets=("$@")
[[ ${#targets[@]} -gt 0 ]] || targets=(obj scene)
dir="${FUZZ_BUILD_DIR:-build-fuzz}"
cmake -S . -B "$dir" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_CXX_COMPILER=clang++ \
  -DRADIOSITY_FUZZ=ON >/dev/null
cmake --build "$dir" -j "$(nproc)" --target "${targets[@]/#/fuzz_}"
mkdir -p "$dir/artifacts" "$dir/corpus/obj" "$dir/corpus/scene" "$dir/corpus/model"
status=0
for target in "${targets[@]}"; do
  leaks=1
  [[ $target == model ]] && leaks=0
  echo "fuzz: $target for ${seconds}s" >&2
  # New inputs go to the build dir's corpus (the first folder); the committed seed corpus and
  # regressions are read-only input. The regression folders are kept in git by a README, which
  # libFuzzer reads as one more input (plain text: harmless to the entry points).
  inputs=("$dir/corpus/$target" "tests/fuzz/corpus/$target" "tests/fuzz/regressions/$target")
  for input in "${inputs[@]:1}"; do
    [[ -d "$input" ]] || { echo "fuzz: $input is missing" >&2; exit 1; }
  done
  "$dir/bin/fuzz_$target" -max_total_time="$seconds" -timeout=10 -rss_limit_mb=2048 -detect_leaks=$leaks \
    -max_len=65536 -print_final_stats=1 -artifact_prefix="$dir/artifacts/$target-" \
    "${inputs[@]}" 2>"$dir/fuzz_$target.log" || status=$?
  grep -E "stat::number_of_executed_units|stat::peak_rss_mb" "$dir/fuzz_$target.log" >&2 || true
  if [[ $status -ne 0 ]]; then
    tail -40 "$dir/fuzz_$target.log" >&2
    echo "fuzz: $target FAILED; reproducer in $dir/artifacts/" >&2
    exit $status
  fi
done
echo "fuzz: no crash" >&2
