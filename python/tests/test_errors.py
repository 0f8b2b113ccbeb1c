"""Python's standard exceptions: a missing file is FileNotFoundError, a value of the wrong type
TypeError, a bad value ValueError (with the library's message naming the field), an unknown
option a ValueError listing the valid keys; and `import secure` without NumPy, or with an
extension built for another Python, is one ImportError saying what to do."""
import errno
import os
import shutil
import subprocess
import sys

import numpy as np
import pytest

import secure


def test_missing_files_are_file_not_found(tmp_path):
    missing = str(tmp_path / "no-such.model")
    loaders = [secure.Barrier.load, secure.Policy.load, secure.AirlReward.load,
               lambda p: secure.Demonstrations.load(p, ["x"], ["ax"])]
    for load in loaders:
        with pytest.raises(FileNotFoundError) as raised:
            load(missing)
        assert raised.value.errno == errno.ENOENT
        assert raised.value.filename == missing
        assert "no-such.model" in str(raised.value)
    with pytest.raises(FileNotFoundError):
        secure.Demonstrations.load(str(tmp_path / "demos.h5"), ["x"], ["ax"])


def test_a_file_that_is_not_a_model_stays_a_value_error(tmp_path):
    junk = tmp_path / "junk.model"
    junk.write_text("not a model\n")
    for load in (secure.Barrier.load, secure.Policy.load, secure.AirlReward.load):
        with pytest.raises(ValueError, match="junk.model"):
            load(str(junk))


def test_option_values_of_the_wrong_type_are_type_errors(di_data):
    safe, near = di_data["safe"][:50], di_data["near_dangerous"][:50]
    cases = [
        (lambda: secure.train_barrier(safe, near, max_epochs="many"),
         r"train_barrier options: option 'max_epochs' = 'many' \(str\), expected an int"),
        (lambda: secure.train_barrier(safe, near, max_epochs=1.5), r"'max_epochs' = 1.5 \(float\)"),
        (lambda: secure.train_barrier(safe, near, max_epochs=True), r"'max_epochs' = True \(bool\)"),
        (lambda: secure.train_barrier(safe, near, hidden=64), r"'hidden' = 64 \(int\), expected a list"),
        (lambda: secure.train_barrier(safe, near, learning_rate="fast"), "'learning_rate'"),
        (lambda: secure.train_bc(di_data["demonstrations"], epochs="3"), "train_bc options: option 'epochs'"),
        (lambda: secure.Shield(secure.Barrier.ground_truth("double-integrator"),
                               secure.Dynamics.builtin("double-integrator"), num_samples=64.0),
         "Shield options: option 'num_samples' = 64.0"),
        (lambda: secure.make_env("double-integrator", task="short"), "option 'task' = 'short' \\(str\\), expected a dict"),
        (lambda: secure.make_env("double-integrator", task={"max_steps": "long"}),
         r"options \[task\]: option 'max_steps' = 'long'"),
        (lambda: secure.train_barrier(safe, near, features="xyzw"), "features: expected a sequence of str"),
        (lambda: secure.train_barrier(safe, near, features=[1, 2, 3, 4]), "features: expected a sequence of str"),
        (lambda: secure.train_airl(di_data["demonstrations"], 3), "env: expected a secure.Env or a domain name"),
        (lambda: secure.Barrier.load(3), None),  # pybind11's own: incompatible arguments
        (lambda: secure.train_barrier(safe, near, hidden=[16], max_epochs=1, seed=object()), "seed"),
    ]
    for call, message in cases:
        with pytest.raises(TypeError, match=message):
            call()
    # Integers where a float is expected, NumPy scalars, and tuples for lists are fine.
    barrier, summary = secure.train_barrier(safe, near, hidden=(8,), max_epochs=np.int64(1),
                                            learning_rate=1, seed=np.uint64(2))
    assert summary["epochs"] == 1


def test_policy_sample_takes_an_rng_or_an_int(di_data):
    policy, _ = secure.train_bc(di_data["demonstrations"], hidden=[8], epochs=1)
    obs = di_data["demonstrations"].states[0]
    assert policy.sample(obs, 3).shape == (2,)
    for bad in ("3", 1.5, None, True):
        with pytest.raises(TypeError, match="rng: expected a secure.Rng or an int seed"):
            policy.sample(obs, bad)


def test_bad_values_are_value_errors(di_data):
    safe, near = di_data["safe"][:50], di_data["near_dangerous"][:50]
    with pytest.raises(ValueError, match="BarrierTrainerOptions::batch_size = 0"):
        secure.train_barrier(safe, near, batch_size=0)
    with pytest.raises(ValueError, match="activation"):
        secure.train_barrier(safe, near, activation="sigmoidish")
    with pytest.raises(ValueError, match=r"expected shape \(N, 4\)"):
        secure.train_barrier(safe, near[:, :3])
    with pytest.raises(ValueError, match="features: 3 names for 4 columns"):
        secure.train_barrier(safe, near, features=["a", "b", "c"])


@pytest.mark.parametrize("call, valid", [
    (lambda d: secure.train_barrier(d["safe"][:50], d["near_dangerous"][:50], max_epoch=3),
     "train_barrier options: unknown field 'max_epoch' in the barrier trainer options (valid: "
     "activation, balance_classes, batch_size, "),
    (lambda d: secure.train_car_barrier(d["safe"][:50], d["near_dangerous"][:50], epochs=3),
     "(valid: "),
    (lambda d: secure.train_bc(d["demonstrations"], epoch=3), "(valid: activation, batch_size, "),
    (lambda d: secure.train_airl(d["demonstrations"], "double-integrator", iteration=3), "(valid: "),
    (lambda d: secure.Shield(secure.Barrier.ground_truth("double-integrator"),
                             secure.Dynamics.builtin("double-integrator"), samples=3), "(valid: "),
])
def test_unknown_options_list_the_valid_keys(di_data, call, valid):
    with pytest.raises(ValueError) as raised:
        call(di_data)
    message = str(raised.value)
    assert valid in message, message
    assert "\n" not in message


def test_train_barrier_docstring_promises_what_it_does():
    doc = secure.train_barrier.__doc__
    assert "an unknown key is a ValueError naming it and listing the valid ones" in " ".join(
        doc.split())
    assert "TypeError" in doc


def _import_secure(tmp_path, code, pythonpath):
    env = dict(os.environ, PYTHONPATH=pythonpath)
    return subprocess.run([sys.executable, *code], capture_output=True, text=True, env=env,
                          cwd=str(tmp_path))


def _package_dir():
    return os.path.dirname(os.path.dirname(os.path.abspath(secure.__file__)))


def test_import_without_numpy_says_what_to_install(tmp_path):
    # -S: no site-packages, so Debian's NumPy is not importable (as under a pyenv python3); and
    # NumPy masked in sys.modules, as a venv without it.
    for code in (["-S", "-c", "import secure"],
                 ["-c", "import sys; sys.modules['numpy'] = None; import secure"]):
        r = _import_secure(tmp_path, code, _package_dir())
        assert r.returncode == 1, r.stderr
        last = r.stderr.strip().splitlines()[-1]
        assert last.startswith("ImportError: secure needs NumPy, which this Python (" +
                               sys.executable), last
        assert "apt install python3-numpy" in last and "--system-site-packages" in last
        assert "pip install numpy" in last


def test_import_without_the_extension_names_the_interpreter(tmp_path):
    # The package without an extension for this Python (as when it was built for another one).
    package = tmp_path / "secure"
    package.mkdir()
    shutil.copy(secure.__file__, package / "__init__.py")
    r = _import_secure(tmp_path, ["-c", "import secure"], str(tmp_path))
    assert r.returncode == 1
    last = r.stderr.strip().splitlines()[-1]
    assert last.startswith("ImportError: secure's C++ extension secure._secure is not built for "
                           f"this Python ({sys.executable}"), last
    assert "holds none" in last


@pytest.mark.parametrize("name", secure.domains())
def test_every_domain_lists_its_valid_task_keys_and_accepts_each(name):
    import re
    env = secure.make_env(name, profile="quick")
    for options, section in (({"no_such_key": 1}, None), ({"task": {"no_such_key": 1}}, "task")):
        with pytest.raises(ValueError) as raised:
            secure.make_env(name, profile="quick", **options)
        m = re.search(r"\(valid: ([^)]*)\)$", str(raised.value))
        assert m, str(raised.value)
        keys = m.group(1).split(", ")
        if section is None:
            assert "task" in keys, keys
            continue
        # The task section lists every key of its options, and each takes its current value.
        current = env.options["task"]
        assert set(keys) >= set(current), (keys, sorted(current))
        for key in keys:
            if key in current:
                secure.make_env(name, profile="quick", task={key: current[key]})
