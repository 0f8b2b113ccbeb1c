"""The build step behind `pip install --no-build-isolation .` (pyproject.toml): configures our
CMake build for the running interpreter (Release, only the target secure_python, ccache as
configured by CMakeLists.txt), builds it and puts the extension into the wheel next to the
package python/secure/. python/README.md#pip says how to use it.

Environment:
  SECURE_BUILD_JOBS      parallel build jobs (default: CMAKE_BUILD_PARALLEL_LEVEL if set, else
                         the number of cores)
  SECURE_PIP_BUILD_DIR   the CMake build directory (default build/pip/cmake-<python tag>; kept
                         between installs, so a second install rebuilds only what changed)
  SECURE_CMAKE_ARGS      extra configure arguments, e.g. -DSECURE_NATIVE_ARCH=OFF for a wheel
                         that runs on CPUs other than this one (the default build uses
                         -march=native)
"""
import glob
import os
import re
import shlex
import shutil
import subprocess
import sys
import sysconfig

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

ROOT = os.path.dirname(os.path.abspath(__file__))


def version():
    with open(os.path.join(ROOT, "CMakeLists.txt")) as f:
        m = re.search(r"project\(secure VERSION ([0-9.]+)", f.read())
    if not m:
        sys.exit("setup.py: CMakeLists.txt: no 'project(secure VERSION x.y.z)'")
    return m.group(1)


class CMakeExtension(Extension):
    def __init__(self, name, target):
        super().__init__(name, sources=[])
        self.target = target


class CMakeBuild(build_ext):
    def build_extension(self, ext):
        if shutil.which("cmake") is None:
            sys.exit("setup.py: cmake not found: scripts/setup.sh --deps installs the build's "
                     "Debian packages")
        tag = sys.implementation.cache_tag  # cpython-311: one build directory per interpreter
        build_dir = os.environ.get("SECURE_PIP_BUILD_DIR") or os.path.join(
            ROOT, "build", "pip", "cmake-" + tag)
        configure = [
            "cmake", "-S", ROOT, "-B", build_dir, "-DCMAKE_BUILD_TYPE=Release",
            "-DPython3_EXECUTABLE=" + sys.executable,
            "-DSECURE_BUILD_PYTHON=ON", "-DSECURE_BUILD_TESTS=OFF",
            "-DSECURE_BUILD_BENCHMARKS=OFF",
        ] + shlex.split(os.environ.get("SECURE_CMAKE_ARGS", ""))
        build = ["cmake", "--build", build_dir, "--target", "secure_python"]
        jobs = os.environ.get("SECURE_BUILD_JOBS")
        if jobs:
            if not jobs.isdigit() or int(jobs) < 1:
                sys.exit(f"setup.py: SECURE_BUILD_JOBS = '{jobs}', must be a positive integer")
            build += ["-j", jobs]
        elif not os.environ.get("CMAKE_BUILD_PARALLEL_LEVEL"):
            build += ["-j", str(os.cpu_count() or 1)]
        for command in (configure, build):
            print(" ".join(shlex.quote(c) for c in command), flush=True)
            subprocess.run(command, check=True)
        suffix = sysconfig.get_config_var("EXT_SUFFIX")
        built = os.path.join(build_dir, "python", "secure", "_secure" + suffix)
        if not os.path.isfile(built):
            found = glob.glob(os.path.join(build_dir, "python", "secure", "_secure*"))
            sys.exit(f"setup.py: the build made no {built} (found: {found or 'nothing'})")
        out = self.get_ext_fullpath(ext.name)
        os.makedirs(os.path.dirname(out), exist_ok=True)
        shutil.copyfile(built, out)
        shutil.copymode(built, out)


setup(
    version=version(),
    ext_modules=[CMakeExtension("secure._secure", target="secure_python")],
    cmdclass={"build_ext": CMakeBuild},
    # setuptools' own build files beside the CMake build, not in the repository's build/ root.
    options={"build": {"build_base": os.path.join("build", "pip", "setuptools")}},
)
