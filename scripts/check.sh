#!/usr/bin/env bash
# The checking build: the library, the CLI and the unit tests built with clang under
# AddressSanitizer + UndefinedBehaviorSanitizer (any finding aborts), the unit tests run there,
# then every libFuzzer target under tests/fuzz for a bounded time. Run by .ci/run after `make test`.
#
#   scripts/check.sh                       everything (FUZZ_SECONDS per fuzzer, default 60)
#   CHECK_LABELS='common|data' scripts/check.sh   only these ctest labels (a regex)
#
# Build dir: $SECURE_CHECK_BUILD_DIR (default build-check). A fuzzer's crash input is kept in
# <build>/fuzz-artifacts/<target>/; once the defect is fixed, add it to tests/fuzz/corpus/<target>/ as a regression input.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build_dir="${SECURE_CHECK_BUILD_DIR:-$root/build-check}"
fuzz_seconds="${FUZZ_SECONDS:-60}"
# Every module's label; `accuracy` and `experiments` train full-size models and take many minutes
# under the sanitizers, and are covered by the Release run of `make test`.
labels="${CHECK_LABELS:-common|data|nn|domains|cbf|shield|stats|policy|eval|apps|fuzz}"

"$root/scripts/setup.sh" --check-deps
cmake -S "$root" -B "$build_dir" -DCMAKE_BUILD_TYPE=Release -DCMAKE_CXX_COMPILER=clang++ \
  -DSECURE_SANITIZE=address,undefined -DSECURE_BUILD_FUZZERS=ON -DSECURE_BUILD_BENCHMARKS=OFF
cmake --build "$build_dir" -j "$(nproc)"

# detect_leaks=0: LibTorch and OpenBLAS keep process-lifetime allocations (thread pools) that
# LeakSanitizer reports; our own ownership is RAII throughout.
export ASAN_OPTIONS="detect_leaks=0:abort_on_error=1:strict_string_checks=1"
export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1"
(cd "$build_dir" && ctest --output-on-failure -j "$(nproc)" -L "$labels")

for fuzzer in "$build_dir"/tests/fuzz/*_fuzz; do
  name="$(basename "$fuzzer")"
  corpus="$build_dir/fuzz-corpus/$name"
  artifacts="$build_dir/fuzz-artifacts/$name/"
  mkdir -p "$corpus" "$artifacts"
  echo "check: fuzzing $name for ${fuzz_seconds} s"
  # New inputs go to the build's corpus; the seeds under tests/fuzz/ are read only.
  "$fuzzer" -seed=1 -max_total_time="$fuzz_seconds" -rss_limit_mb=4096 \
    -print_final_stats=1 -artifact_prefix="$artifacts" "$corpus" \
    "$root/tests/fuzz/corpus/$name" 2>&1 | tail -n 12
  test "${PIPESTATUS[0]}" -eq 0
done
echo "check: sanitizers and fuzzers passed"
