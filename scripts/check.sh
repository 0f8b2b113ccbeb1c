#!/usr/bin/env bash
# The checking build, run by .ci/run after `make test`: one clang build of the library, the CLI,
# the unit tests and the libFuzzer targets under AddressSanitizer + UndefinedBehaviorSanitizer
# (any finding aborts), with libFuzzer's coverage instrumentation in every library; then
#  1. the unit tests run there (step `sanitizers`);
#  2. the fuzzers' corpora replayed, then each fuzzer run for a bounded time, as many at once as
#     there are cores (step `fuzz`).
# One build serves both steps: libFuzzer needs clang, and building the libraries twice (GCC for
# the unit tests, clang for the fuzzers) was the largest share of CI's time.
#
#   scripts/check.sh                               everything (FUZZ_SECONDS per fuzzer, default 30)
#   CHECK_LABELS='common|data' scripts/check.sh    only these ctest labels (a regex) in step 1
#   CHECK_STEPS=fuzz scripts/check.sh              only step 2 (sanitizers: only step 1)
#
# Tests that replace malloc to count allocations skip themselves under ASan (SECURE_TEST_ASAN in
# tests/sanitizers.h): ASan owns malloc and calls it before any static initialiser.
#
# Build dir: $SECURE_CHECK_BUILD_DIR (default build-check). A fuzzer's crash input is kept in
# <build>/fuzz-artifacts/<target>/; once the defect is fixed, add it to
# tests/fuzz/corpus/<target>/ as a regression input.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
check_dir="${SECURE_CHECK_BUILD_DIR:-$root/build-check}"
fuzz_seconds="${FUZZ_SECONDS:-30}"
steps="${CHECK_STEPS:-sanitizers fuzz}"
# Every module's label; `accuracy` and `experiments` train full-size models and take many minutes
# under the sanitizers, and are covered by the Release run of `make test` (they are not built here).
labels="${CHECK_LABELS:-common|data|nn|domains|cbf|shield|stats|policy|eval|apps}"
jobs="$(nproc)"

"$root/scripts/setup.sh" --check-deps

# detect_leaks=0: LibTorch and OpenBLAS keep process-lifetime allocations (thread pools) that
# LeakSanitizer reports; our own ownership is RAII throughout.
export ASAN_OPTIONS="detect_leaks=0:abort_on_error=1:strict_string_checks=1"
export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1"
# -O1 for the whole checking build (the Release type's flags otherwise say -O3): AddressSanitizer's
# documented setting for usable reports, and 3-12 % less compile time per translation unit than
# -O3 (measured on four of the largest; tests/README.md). The tests' own sources are at -O1 anyway.
cmake -S "$root" -B "$check_dir" -DCMAKE_BUILD_TYPE=Release -DCMAKE_CXX_COMPILER=clang++ \
  -DCMAKE_CXX_FLAGS_RELEASE="-O1 -DNDEBUG" \
  -DSECURE_SANITIZE=address,undefined -DSECURE_BUILD_FUZZERS=ON \
  -DSECURE_BUILD_BENCHMARKS=OFF -DSECURE_BUILD_PYTHON=OFF \
  -DCMAKE_GTEST_DISCOVER_TESTS_DISCOVERY_MODE=PRE_TEST
cmake --build "$check_dir" -j "$jobs"

if [[ " $steps " == *" sanitizers "* ]]; then
  # The `slow` tests (tests/slow_tests.cmake: whole quick experiments, and the fault-injection
  # test, which kills runs at wall-clock points) stay in the Release run: under the sanitizers the
  # CLI tests of an arm domain took 84 s and 61 s each. The domains' code runs here through their
  # own tests (the contract suite, label `domains`), the CLI wiring through the other CLI tests.
  (cd "$check_dir" && ctest --output-on-failure -j "$jobs" -L "$labels" -LE slow)
fi

if [[ " $steps " == *" fuzz "* ]]; then
  (cd "$check_dir" && ctest --output-on-failure -L fuzz)
  # The fuzzers run $jobs at a time (each is one process on one core), each for fuzz_seconds; a
  # fuzzer's output goes to <build>/fuzz-logs/<target>.log and its last lines are printed.
  logs="$check_dir/fuzz-logs"
  mkdir -p "$logs"
  fuzz_one() {
    local fuzzer="$1" name corpus artifacts
    name="$(basename "$fuzzer")"
    corpus="$check_dir/fuzz-corpus/$name"
    artifacts="$check_dir/fuzz-artifacts/$name/"
    mkdir -p "$corpus" "$artifacts"
    # New inputs go to the build's corpus; the seeds under tests/fuzz/ are only read.
    "$fuzzer" -seed=1 -max_total_time="$fuzz_seconds" -rss_limit_mb=4096 -print_final_stats=1 \
      -artifact_prefix="$artifacts" "$corpus" "$root/tests/fuzz/corpus/$name" >"$logs/$name.log" 2>&1
  }
  # FUZZ_SKIP: fuzzers whose corpus is replayed (above) but that are not run for new inputs
  # (none by default; hdf5_fuzz was, until its readers ran libhdf5 in a guarded child process).
  fuzz_skip=" ${FUZZ_SKIP-} "
  fuzzers=()
  for fuzzer in "$check_dir"/tests/fuzz/*_fuzz; do
    if [[ "$fuzz_skip" == *" $(basename "$fuzzer") "* ]]; then
      echo "check: not fuzzing $(basename "$fuzzer") (FUZZ_SKIP; its corpus was replayed)"
    else
      fuzzers+=("$fuzzer")
    fi
  done
  failed=0
  for ((i = 0; i < ${#fuzzers[@]}; i += jobs)); do
    pids=()
    for fuzzer in "${fuzzers[@]:i:jobs}"; do
      echo "check: fuzzing $(basename "$fuzzer") for ${fuzz_seconds} s"
      fuzz_one "$fuzzer" &
      pids+=($!)
    done
    for ((k = 0; k < ${#pids[@]}; ++k)); do
      fuzzer="${fuzzers[i + k]}"
      status=0
      wait "${pids[k]}" || status=$?
      echo "check: $(basename "$fuzzer") exited with $status; its last lines:"
      tail -n 12 "$logs/$(basename "$fuzzer").log"
      if [[ $status -ne 0 ]]; then failed=1; fi
    done
  done
  if [[ $failed -ne 0 ]]; then
    echo "check: a fuzzer failed (its input is in $check_dir/fuzz-artifacts/)" >&2
    exit 1
  fi
fi
echo "check: sanitizers and fuzzers passed"
