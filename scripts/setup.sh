#!/usr/bin/env bash
# Sets up a Debian 12 machine for secure and builds it (Release).
#
#   scripts/setup.sh            install missing packages, configure, build everything
#   scripts/setup.sh --deps     only install missing packages
#   scripts/setup.sh --check-deps   only install missing packages, with those of the checking
#                                   build (scripts/check.sh: sanitizers and fuzzers)
#
# Every dependency is a Debian package; nothing is downloaded at build time. Packages are
# installed only when missing, so a second run is fast. Needs root or sudo for apt-get.
set -euo pipefail

# Why each package is here:
#   build-essential cmake       compiler and build system
#   ccache                      compiler cache: a rebuild (and CI on the same machine) recompiles only what changed
#   libtorch-dev                training (Adam, autograd); inference does not use it
#   libopenblas0-pthread        BLAS behind LibTorch: the reference BLAS is ~30x slower
#   libopenblas-pthread-dev     cblas.h for the sgemm peak benchmark (bench/peak_bench.cc)
#   libeigen3-dev               fast inference path (the shield's hot loop), linear algebra
#   libxsmm-dev                 JIT small-GEMM kernels: the inference path's layer products
#   libcli11-dev                command-line parsing
#   nlohmann-json3-dev          --json results, model file headers
#   libhdf5-dev                 demonstrations in robomimic's HDF5 layout (secure/data)
#   pkgconf                     finds HDF5 (its pkg-config file) for the build and for find_package(secure)
#   libyaml-cpp-dev             experiment config files
#   libboost-dev                Boost.CRC (model file checksums); Boost.Math (statistics)
#   libmujoco-dev libqhull-dev  MuJoCo for the Panda domain (its CMake config needs qhull)
#   libosmesa6-dev              software OpenGL (OSMesa): the Panda domain's offscreen renderer
#   libcairo2-dev fonts-dejavu-core
#                               `secure render`'s overlay (h, the shield's status, a plot of h) drawn
#                               into the frames (secure/eval/overlay.cc), in DejaVu Sans Mono
#   ffmpeg                      `secure render`: encodes rendered episodes as MP4 (libx264); its tests
#   libgtest-dev libgmock-dev   unit tests
#   librapidcheck-dev           property-based tests
#   libbenchmark-dev            benchmarks under bench/
#   openmpi-bin                 mpirun, for the sharded-experiment tests (tests/apps/shard_test.cc); nothing links MPI
#   python3-dev pybind11-dev    the Python module (python/): headers, the binding library
#   python3-numpy python3-pytest  the module's arrays; its tests (ctest -L python)
#   python3-pip python3-venv python3-setuptools python3-wheel mypy
#                               `pip install --no-build-isolation .` (pyproject.toml, setup.py: the
#                               PEP 517 backend and wheel building offline; venvs; its slow test)
#   mypy                        type-checks the package's stub and examples/python against it
#                               (ctest python_typecheck_*: the stub is usable, the examples typed)
#   python3-matplotlib          `secure report`: the run's figures (tools/report/report.py, Agg backend)
#   python3-h5py                reads our HDF5 files as robomimic does (h5py), and writes robomimic-style
#                               files with images, in a test (tests/data/robomimic_h5py_test.py)
#   chromium                    the report's test renders the page headless (ctest -L report)
PACKAGES=(
  build-essential cmake git ccache
  libtorch-dev libopenblas0-pthread libopenblas-pthread-dev
  libeigen3-dev libxsmm-dev libcli11-dev nlohmann-json3-dev libyaml-cpp-dev libboost-dev libboost-math-dev
  libhdf5-dev pkgconf
  libmujoco-dev libqhull-dev libosmesa6-dev
  ffmpeg libcairo2-dev fonts-dejavu-core
  libgtest-dev libgmock-dev librapidcheck-dev libbenchmark-dev
  python3-dev pybind11-dev python3-numpy python3-pytest
  python3-pip python3-venv python3-setuptools python3-wheel mypy
  openmpi-bin
  python3-matplotlib python3-h5py chromium
)
# The checking build (scripts/check.sh), installed only with --check-deps:
#   clang libclang-rt-14-dev    clang and its AddressSanitizer / UBSan runtimes
#   libfuzzer-14-dev            libFuzzer (tests/fuzz)
CHECK_PACKAGES=(clang libclang-rt-14-dev libfuzzer-14-dev)
if [ "${1:-}" = "--check-deps" ]; then PACKAGES+=("${CHECK_PACKAGES[@]}"); fi

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build_dir="${SECURE_BUILD_DIR:-$root/build}"

install_missing() {
  local missing=()
  for p in "${PACKAGES[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
  done
  if [ ${#missing[@]} -eq 0 ]; then
    echo "setup: all ${#PACKAGES[@]} packages present"
    return
  fi
  echo "setup: installing ${missing[*]}"
  local sudo=""
  if [ "$(id -u)" -ne 0 ]; then sudo="sudo"; fi
  export DEBIAN_FRONTEND=noninteractive
  $sudo apt-get update -qq
  $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}"
}

install_missing
# LibTorch must find OpenBLAS, not the reference BLAS, through the libblas.so.3 alternative.
blas="$(readlink -f /usr/lib/x86_64-linux-gnu/libblas.so.3 || true)"
case "$blas" in
  *openblas*) ;;
  *) echo "setup: warning: libblas.so.3 resolves to '$blas', not OpenBLAS: training will be slow" >&2 ;;
esac
case "${1:-}" in --deps|--check-deps) exit 0 ;; esac

jobs="$(nproc)"
cmake -S "$root" -B "$build_dir" -DCMAKE_BUILD_TYPE=Release
cmake --build "$build_dir" -j "$jobs"
echo "setup: built in $build_dir"
