"""`pip install .` as a user runs it, offline (ctest python_pip_install; labels python, slow).

    python3 pip_install_check.py --source REPO --work DIR

With the interpreter running this script (the one the module is built for):
  1. a venv with --system-site-packages: `pip install --no-build-isolation --no-index .`, then
     `import secure` from another directory, out of the venv's site-packages, with its stub and
     py.typed, computing something; `pip show secure-cbf`;
  2. `pip install --user --break-system-packages ...` into a scratch user base (PYTHONUSERBASE),
     then the same import with that interpreter;
  3. `pip wheel --no-build-isolation --no-deps --no-index .`: one wheel for this interpreter
     holding the package, the extension, the stub and py.typed.
--no-index: nothing is fetched, so a step that would need the network fails. The CMake build
directory is DIR/cmake (or $SECURE_PIP_BUILD_DIR), kept between runs: only the first run
compiles.
Prints one line per step and exits 1 with the failing command's output on the first failure.
"""
import argparse
import os
import shutil
import subprocess
import sys
import sysconfig
import zipfile

IMPORT_CHECK = r"""
import os, sys
import numpy as np
import secure
package = os.path.dirname(secure.__file__)
expected = sys.argv[1]
assert os.path.realpath(package).startswith(os.path.realpath(expected)), (package, expected)
assert os.path.isfile(os.path.join(package, "py.typed")), package
assert os.path.isfile(os.path.join(package, "_secure.pyi")), package
assert "double-integrator" in secure.domains()
gt = secure.Barrier.ground_truth("double-integrator")
h = gt.h(np.array([[0.0, 0.0, 0.0, 0.0], [5.0, 5.0, 0.0, 0.0]], dtype=np.float32))
assert h[0] > 0 > h[1], h
print(secure.__version__, package)
"""


def run(command, env=None, cwd=None):
    print("+", " ".join(c if "\n" not in c else "'<script>'" for c in command), flush=True)
    r = subprocess.run(command, env=env, cwd=cwd, stdout=subprocess.PIPE,
                       stderr=subprocess.STDOUT, text=True)
    if r.returncode != 0:
        print(r.stdout)
        sys.exit(f"pip_install_check: failed (exit {r.returncode}): {' '.join(command)}")
    return r.stdout


def clean_env(work, **extra):
    env = {k: v for k, v in os.environ.items()
           if k not in ("PYTHONPATH", "PYTHONHOME", "PYTHONUSERBASE", "PYTHONNOUSERSITE",
                        "VIRTUAL_ENV", "PIP_USER", "PIP_TARGET", "PIP_PREFIX")}
    env["SECURE_PIP_BUILD_DIR"] = os.environ.get("SECURE_PIP_BUILD_DIR") or os.path.join(
        work, "cmake")
    env.setdefault("SECURE_BUILD_JOBS", "2")
    env["PIP_DISABLE_PIP_VERSION_CHECK"] = "1"
    env["PIP_NO_INPUT"] = "1"
    env.update(extra)
    return env


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--source", required=True, help="the repository (pyproject.toml)")
    parser.add_argument("--work", required=True, help="scratch directory (kept: the build)")
    args = parser.parse_args()
    source, work = os.path.abspath(args.source), os.path.abspath(args.work)
    os.makedirs(work, exist_ok=True)
    elsewhere = os.path.join(work, "elsewhere")  # imports run here, away from the sources
    for d in ("venv", "userbase", "wheels", "elsewhere"):
        shutil.rmtree(os.path.join(work, d), ignore_errors=True)
    os.makedirs(elsewhere)
    pip_flags = ["--no-build-isolation", "--no-index", "--no-cache-dir"]

    # 1. A venv that sees Debian's NumPy.
    venv = os.path.join(work, "venv")
    run([sys.executable, "-m", "venv", "--system-site-packages", venv])
    python = os.path.join(venv, "bin", "python")
    env = clean_env(work)
    run([python, "-m", "pip", "install", *pip_flags, source], env=env, cwd=elsewhere)
    site = run([python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
               env=env).strip()
    out = run([python, "-c", IMPORT_CHECK, site], env=env, cwd=elsewhere)
    print("venv: imported", out.strip())
    show = run([python, "-m", "pip", "show", "-f", "secure-cbf"], env=env)
    assert "Name: secure-cbf" in show and "secure/_secure.pyi" in show, show

    # 2. --user into a scratch user base (Debian's Python is externally managed: PEP 668).
    userbase = os.path.join(work, "userbase")
    env = clean_env(work, PYTHONUSERBASE=userbase)
    run([sys.executable, "-m", "pip", "install", "--user", "--break-system-packages",
         *pip_flags, source], env=env, cwd=elsewhere)
    out = run([sys.executable, "-c", IMPORT_CHECK, userbase], env=env, cwd=elsewhere)
    print("--user: imported", out.strip())

    # 3. A wheel.
    wheels = os.path.join(work, "wheels")
    env = clean_env(work)
    run([sys.executable, "-m", "pip", "wheel", *pip_flags, "--no-deps", "-w", wheels, source],
        env=env, cwd=elsewhere)
    built = os.listdir(wheels)
    tag = sys.implementation.cache_tag.replace("python-", "p")  # cpython-311 -> cp311
    assert len(built) == 1 and built[0].startswith("secure_cbf-") and f"-{tag}-{tag}-" in built[0], built
    names = zipfile.ZipFile(os.path.join(wheels, built[0])).namelist()
    extension = "secure/_secure" + sysconfig.get_config_var("EXT_SUFFIX")
    for name in ("secure/__init__.py", extension, "secure/_secure.pyi", "secure/py.typed"):
        assert name in names, (name, names)
    print("wheel:", built[0], f"({len(names)} files)")
    print("pip_install_check: venv, --user and wheel OK")


if __name__ == "__main__":
    main()
