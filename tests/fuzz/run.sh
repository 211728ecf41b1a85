#!/usr/bin/env bash
# Usage: tests/fuzz/run.sh [SECONDS]
# Builds the libFuzzer targets of tests/fuzz with clang in ${SOFTID_FUZZ_BUILD_DIR:-build-fuzz}
# (relative paths from the repository's top folder) and fuzzes each for SECONDS (default 60), one
# after the other, on a copy of its seed corpus (the committed corpus never grows). Exits 1 when a
# target crashes, leaks, times out or runs out of memory, printing the reproducer's path; 0 when
# none does. SOFTID_FUZZ_JOBS sets the build's parallel jobs (default: every core).
set -euo pipefail
cd "$(dirname "$0")/../.."
source_dir=$PWD
seconds=${1:-60}
if ! [[ $seconds =~ ^[1-9][0-9]*$ ]]; then
  echo "usage: tests/fuzz/run.sh [SECONDS]   (seconds per target, default 60)" >&2
  exit 2
fi
build_dir=${SOFTID_FUZZ_BUILD_DIR:-build-fuzz}
targets=(capture_json_fuzzer recording_json_fuzzer job_config_fuzzer manifest_fuzzer)

# clang-14 and its libFuzzer runtime are in the dependency list, with everything the configure
# below needs; the script returns at once when all is installed.
bash deploy/install-deps.sh

# Sanitizers and coverage are set per file in tests/fuzz/CMakeLists.txt; the build type only
# decides how the code that no fuzz input reaches (the simulator, the optimiser) is compiled:
# -O0 is the quickest to build.
cmake -S . -B "$build_dir" -G Ninja -DCMAKE_BUILD_TYPE=Debug \
  -DCMAKE_C_COMPILER=clang-14 -DCMAKE_CXX_COMPILER=clang++-14 \
  -DCMAKE_C_FLAGS_DEBUG=-O0 -DCMAKE_CXX_FLAGS_DEBUG=-O0 \
  -DSOFTID_BUILD_FUZZERS=ON -DSOFTID_BUILD_TESTS=OFF -DSOFTID_BUILD_SERVER=ON \
  -DSOFTID_PRECOMPILE_HEADERS=OFF >/dev/null
cmake --build "$build_dir" -j "${SOFTID_FUZZ_JOBS:-$(nproc)}" --target "${targets[@]}"
build_dir=$(cd "$build_dir" && pwd)

# Symbolised stack traces (llvm-symbolizer comes with llvm-14); UBSan's reports with their stack.
if command -v llvm-symbolizer-14 >/dev/null; then
  export ASAN_SYMBOLIZER_PATH=${ASAN_SYMBOLIZER_PATH:-$(command -v llvm-symbolizer-14)}
fi
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1}

work=$(mktemp -d "${TMPDIR:-/tmp}/softid-fuzz.XXXXXX")
trap 'rm -rf "$work"' EXIT
failed=()
for target in "${targets[@]}"; do
  corpus=$work/corpus/$target
  mkdir -p "$corpus"
  cp "$source_dir/tests/fuzz/corpus/$target"/* "$corpus"/
  # Reproducers outlive the temporary folder: they are what a failure hands to a developer.
  artifacts=$build_dir/fuzz-artifacts/$target
  mkdir -p "$artifacts"
  options=(-max_total_time="$seconds" -timeout=10 -rss_limit_mb=2048
           -artifact_prefix="$artifacts/" -print_final_stats=1)
  dictionary=$source_dir/tests/fuzz/$target.dict
  if [ -f "$dictionary" ]; then options+=(-dict="$dictionary"); fi
  log=$work/$target.log
  echo "fuzz: $target for ${seconds} s"
  if "$build_dir/tests/fuzz/$target" "${options[@]}" "$corpus" >"$log" 2>&1; then
    grep -E '^#[0-9]+[[:space:]]+DONE|^stat::(number_of_executed_units|new_units_added):' \
      "$log" | sed "s/^/fuzz: $target: /" || true
  else
    failed+=("$target")
    echo "fuzz: $target FAILED; the end of its log:" >&2
    tail -n 80 "$log" >&2
    # libFuzzer names the input it saved: "Test unit written to <path>".
    # (slow-unit-* files are only notes about slow inputs, not failures.)
    reproducers=$(sed -n 's/.*Test unit written to \(.*\)$/\1/p' "$log" |
      grep -v '/slow-unit-' || true)
    if [ -z "$reproducers" ]; then
      echo "fuzz: $target: no reproducer was written (see the log above)" >&2
    fi
    while IFS= read -r reproducer; do
      [ -n "$reproducer" ] || continue
      echo "fuzz: $target: reproducer: $reproducer" >&2
      echo "fuzz: $target: reproduce with: '$build_dir/tests/fuzz/$target' '$reproducer'" >&2
    done <<<"$reproducers"
  fi
done

if [ "${#failed[@]}" -gt 0 ]; then
  echo "fuzz: FAILED: ${failed[*]}" >&2
  exit 1
fi
echo "fuzz: ${#targets[@]} targets ran ${seconds} s each without a crash"
