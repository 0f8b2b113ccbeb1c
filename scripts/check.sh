#!/usr/bin/env bash
# The checking builds, run by .ci/run after `make test`:
#  1. the library, the CLI and the unit tests under AddressSanitizer + UndefinedBehaviorSanitizer
#     (GCC; any finding aborts the test), and the unit tests run there;
#  2. the libFuzzer targets under tests/fuzz (clang, with ASan + UBSan): their corpora replayed,
#     then each fuzzer run for a bounded time.
#
#   scripts/check.sh                               everything (FUZZ_SECONDS per fuzzer, default 60)
#   CHECK_LABELS='common|data' scripts/check.sh    only these ctest labels (a regex) in step 1
#   CHECK_STEPS=fuzz scripts/check.sh              only step 2 (sanitizers: only step 1)
#
# Step 1 uses GCC, the compiler of the Release build; libFuzzer needs clang, so step 2 uses it.
# Tests that replace malloc to count allocations skip themselves under ASan (SECURE_TEST_ASAN in
# tests/sanitizers.h): ASan owns malloc and calls it before any static initialiser.
#
# Build dirs: $SECURE_ASAN_BUILD_DIR (default build-asan), $SECURE_FUZZ_BUILD_DIR (build-fuzz).
# A fuzzer's crash input is kept in <fuzz build>/fuzz-artifacts/<target>/; once the defect is
# fixed, add it to tests/fuzz/corpus/<target>/ as a regression input.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
asan_dir="${SECURE_ASAN_BUILD_DIR:-$root/build-asan}"
fuzz_dir="${SECURE_FUZZ_BUILD_DIR:-$root/build-fuzz}"
fuzz_seconds="${FUZZ_SECONDS:-60}"
steps="${CHECK_STEPS:-sanitizers fuzz}"
# Every module's label; `accuracy` and `experiments` train full-size models and take many minutes
# under the sanitizers, and are covered by the Release run of `make test`.
labels="${CHECK_LABELS:-common|data|nn|domains|cbf|shield|stats|policy|eval|apps}"
jobs="$(nproc)"

"$root/scripts/setup.sh" --check-deps

# detect_leaks=0: LibTorch and OpenBLAS keep process-lifetime allocations (thread pools) that
# LeakSanitizer reports; our own ownership is RAII throughout.
export ASAN_OPTIONS="detect_leaks=0:abort_on_error=1:strict_string_checks=1"
export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1"
common=(-DCMAKE_BUILD_TYPE=Release -DSECURE_SANITIZE=address,undefined
        -DSECURE_BUILD_BENCHMARKS=OFF -DSECURE_BUILD_PYTHON=OFF
        -DCMAKE_GTEST_DISCOVER_TESTS_DISCOVERY_MODE=PRE_TEST)

if [[ " $steps " == *" sanitizers "* ]]; then
  cmake -S "$root" -B "$asan_dir" "${common[@]}"
  cmake --build "$asan_dir" -j "$jobs"
  # The fault-injection test kills runs at wall-clock points: it stays in the Release run.
  (cd "$asan_dir" && ctest --output-on-failure -j "$jobs" -L "$labels" -E "^FaultInjection")
fi

if [[ " $steps " == *" fuzz "* ]]; then
  cmake -S "$root" -B "$fuzz_dir" "${common[@]}" -DCMAKE_CXX_COMPILER=clang++ \
    -DSECURE_BUILD_TESTS=OFF -DSECURE_BUILD_FUZZERS=ON
  cmake --build "$fuzz_dir" -j "$jobs" --target fuzzers
  (cd "$fuzz_dir" && ctest --output-on-failure -L fuzz)
  for fuzzer in "$fuzz_dir"/tests/fuzz/*_fuzz; do
    name="$(basename "$fuzzer")"
    corpus="$fuzz_dir/fuzz-corpus/$name"
    artifacts="$fuzz_dir/fuzz-artifacts/$name/"
    mkdir -p "$corpus" "$artifacts"
    echo "check: fuzzing $name for ${fuzz_seconds} s"
    # New inputs go to the build's corpus; the seeds under tests/fuzz/ are only read.
    "$fuzzer" -seed=1 -max_total_time="$fuzz_seconds" -rss_limit_mb=4096 -print_final_stats=1 \
      -artifact_prefix="$artifacts" "$corpus" "$root/tests/fuzz/corpus/$name" 2>&1 | tail -n 12
    test "${PIPESTATUS[0]}" -eq 0
  done
fi
echo "check: sanitizers and fuzzers passed"
