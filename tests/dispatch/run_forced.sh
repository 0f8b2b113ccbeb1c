#!/usr/bin/env bash
# Runs one test program on one forced dispatch path (tests/dispatch/README.md):
#
#   run_forced.sh PATH PROGRAM [ARGS...]
#
# PATH is eigen (Eigen's GEMM for every layer), avx2 (LIBXSMM kernels for AVX2, target hsw) or
# avx512 (LIBXSMM kernels for AVX-512, target skx). A path this CPU cannot run exits 77, which
# CTest reports as skipped (SKIP_RETURN_CODE); every other outcome is the program's own.
set -euo pipefail
path="$1"
shift
has_flag() { grep -qw "$1" /proc/cpuinfo; }
case "$path" in
  eigen)
    export SECURE_MATMUL_BACKEND=eigen SECURE_DISPATCH_EXPECT=eigen
    unset LIBXSMM_TARGET ;;
  avx2)
    has_flag avx2 || { echo "dispatch: this CPU has no AVX2: path $path skipped"; exit 77; }
    export SECURE_MATMUL_BACKEND=libxsmm LIBXSMM_TARGET=hsw SECURE_DISPATCH_EXPECT=libxsmm:hsw ;;
  avx512)
    has_flag avx512f || { echo "dispatch: this CPU has no AVX-512: path $path skipped"; exit 77; }
    export SECURE_MATMUL_BACKEND=libxsmm LIBXSMM_TARGET=skx SECURE_DISPATCH_EXPECT=libxsmm:skx ;;
  *)
    echo "run_forced.sh: path '$path', must be one of eigen, avx2, avx512" >&2
    exit 2 ;;
esac
echo "dispatch: path $path (SECURE_MATMUL_BACKEND=$SECURE_MATMUL_BACKEND LIBXSMM_TARGET=${LIBXSMM_TARGET:-default})"
exec "$@"
