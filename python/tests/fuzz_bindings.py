"""A fuzz driver for the Python binding (issue 34; Atheris is not in Debian): for a bounded time,
call every bound function, static method, method and property of secure._secure with randomised
arguments drawn from a pool of hostile values (None, cyclic and shared-reference containers,
wrong types, NaN / inf / out-of-range numbers, empty, huge-dimension and oddly shaped arrays,
objects made without __init__, FIFOs, directories and /dev/zero as paths, dynamics callbacks that
raise, return NaN or re-enter the shield) as well as valid ones. Any exception is a pass; the
interpreter dying (a signal), a SystemError, or a call that does not return is a failure.

    /usr/bin/python3 python/tests/fuzz_bindings.py [--seconds 30] [--seed N]

runs the calls in a child interpreter with faulthandler and reports the last calls before a
crash or hang (ctest: python_fuzz, label python, in `make test` and CI). Same seed, same calls
(the time budget only decides how many are made).
"""
import argparse
import math
import os
import random
import shutil
import subprocess
import sys
import tempfile
import time


def parse():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seconds", type=float,
                   default=float(os.environ.get("SECURE_PY_FUZZ_SECONDS", "30")))
    p.add_argument("--seed", type=int,
                   default=int(os.environ.get("SECURE_PY_FUZZ_SEED", "20261203")))
    p.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    return p.parse_args()


# ------------------------------------------------------------------------------------------------
# The child: builds the pool and calls.

def child(seconds, seed):
    import faulthandler
    faulthandler.enable()
    import numpy as np
    import secure
    from secure import _secure

    rng = random.Random(seed)
    tmp = tempfile.mkdtemp(prefix="secure_pyfuzz_")
    os.chdir(tmp)  # a drawn string used as a path (save("derby")) lands here, not in the tree
    fifo = os.path.join(tmp, "fifo")
    os.mkfifo(fifo)
    zero = os.path.join(tmp, "zero.model")
    os.symlink("/dev/zero", zero)
    junk = os.path.join(tmp, "junk.model")
    with open(junk, "w") as f:
        f.write("not a model\n")

    # Valid objects, small and fast.
    gen = np.random.default_rng(0)
    safe = gen.uniform(0, 10, (64, 4)).astype(np.float32)
    near = gen.uniform(4, 6, (64, 4)).astype(np.float32)
    barrier, _ = secure.train_barrier(safe, near, hidden=[8], max_epochs=1)
    model_path = os.path.join(tmp, "b.model")
    barrier.save(model_path)
    gt = secure.Barrier.ground_truth("double-integrator")
    dyn = secure.Dynamics.builtin("double-integrator")
    env = secure.make_env("double-integrator")
    core = env._core
    data = secure.generate_data("double-integrator", seed=0, profile="quick")
    demos = secure.Demonstrations(data["demonstrations"].states[:50],
                                  data["demonstrations"].actions[:50])
    policy, _ = secure.train_bc(demos, epochs=1, hidden=[8])
    policy_path = os.path.join(tmp, "p.model")
    policy.save(policy_path)
    shield = secure.Shield(gt, dyn, num_samples=8, num_probes=8, max_iterations=2)

    def nan_fn(state, actions):
        out = np.zeros((len(actions), 4), np.float32)
        out[:, 0] = np.nan
        return out

    def raising_fn(state, actions):
        raise RuntimeError("callback raises")

    holder = {}

    def reentrant_fn(state, actions):
        holder["shield"].decide(state, np.zeros(2, np.float32), np.ones(2, np.float32))
        return np.zeros((len(actions), 4), np.float32)

    def wrong_fn(state, actions):
        return [[1.0]]

    reentrant = secure.Dynamics.from_callable(reentrant_fn, 4, 2, name="reentrant")
    holder["shield"] = secure.Shield(gt, reentrant, num_samples=8, num_probes=8)
    callables = [nan_fn, raising_fn, reentrant_fn, wrong_fn, lambda *a: None, print]

    cyclic_list = [1.0]
    cyclic_list.append(cyclic_list)
    cyclic_dict = {}
    cyclic_dict["self"] = cyclic_dict
    # Shared references: 9^9 leaves if expanded, over every argument's node limit (each bound
    # function counts its arguments' containers first: python/src/arg_bounds.cc; pybind11's
    # "incompatible function arguments" message would repr() them without end).
    bomb = [1.0]
    for _ in range(9):
        bomb = [bomb] * 9
    dict_bomb = {"goal": bomb}

    classes = [c for c in vars(_secure).values() if isinstance(c, type)]
    uninitialised = []
    for c in classes:
        try:
            uninitialised.append(c.__new__(c))
        except Exception:
            pass

    arrays = [
        np.zeros(4, np.float32), np.ones(2, np.float32), np.zeros((3, 4), np.float32),
        np.zeros((3, 2)), np.full(4, np.nan), np.full((2, 4), np.inf), np.array([1e300, 0, 0, 0]),
        np.zeros((0, 4), np.float32), np.zeros((4, 0), np.float32), np.zeros(0),
        np.zeros((2, 2, 2)), np.zeros((1, 10**6), np.float32)[:, :4],
        np.broadcast_to(np.float32(1), (100000, 4)), np.arange(8, dtype=np.int64).reshape(2, 4),
        np.array(["a", "b"]), np.array([1 + 2j, 0, 0, 0]), np.array([True, False, True, False]),
        np.array([None, 1, 2, 3], dtype=object), np.zeros(4, np.float32)[::-1],
        np.zeros((4, 8), np.float32)[:, ::2], safe[:5], near,
    ]
    scalars = [None, 0, 1, 3, -1, 2**31, 2**63, 2**64, 2**70, -2**63, 0.5, math.nan, math.inf,
               -math.inf, 1e300, True, False, "", "x", "double-integrator", "derby", "nope",
               "quick", "full", "mean", "top-q", b"bytes", object(), (), [], {}, [1, 2], {"a": 1},
               [None], ["x", "x"], ["x", "y", "z", "w"], cyclic_list, cyclic_dict, bomb, dict_bomb,
               tmp, fifo, zero, junk, "/dev/null", os.path.join(tmp, "missing.model"), model_path,
               policy_path, os.path.join(tmp, "out.model")]
    objects = [barrier, gt, dyn, core, env, demos, policy, shield, reentrant, secure.Rng(1)] + \
        uninitialised + callables
    pool = scalars + arrays + objects
    option_keys = ["hidden", "max_epochs", "epochs", "seed", "num_samples", "task", "goal",
                   "aggregation", "sampler", "dt", "nope", "layout", "iterations", "batch_size"]
    # Calls that train or roll out: keep them small whatever else is drawn (a fuzzer checks
    # robustness, not speed), and never ask for many episodes.
    small = {"train_barrier": dict(max_epochs=1), "train_car_barrier": dict(max_epochs=1),
             "train_bc": dict(epochs=1), "generate_data": dict(profile="quick"),
             "train_airl": dict(iterations=1, steps_per_iteration=10, ppo_epochs=1)}

    def draw():
        return rng.choice(pool)

    # Every target: (name, callable producer). Methods are called on valid and on uninitialised
    # instances; properties read.
    targets = []
    for name, value in vars(_secure).items():
        if name.startswith("__"):
            continue
        if isinstance(value, type):
            instances = [o for o in objects if isinstance(o, value)]
            for attr, member in vars(value).items():
                if attr.startswith("__") and attr not in ("__repr__", "__init__"):
                    continue
                if isinstance(member, property):
                    for inst in instances:
                        targets.append((f"{name}.{attr}", lambda i=inst, a=attr: getattr(i, a)))
                elif isinstance(member, staticmethod):
                    targets.append((f"{name}.{attr}", getattr(value, attr)))
                elif callable(member):
                    # On each instance (valid and uninitialised, __init__ again included), and
                    # through the class with a drawn `self`.
                    for inst in instances:
                        targets.append((f"{name}.{attr}", getattr(inst, attr)))
                    targets.append((f"{name}.{attr}(unbound)", getattr(value, attr)))
        elif callable(value):
            targets.append((name, value))
    targets.append(("make_env", secure.make_env))
    targets.append(("Dynamics.from_callable", secure.Dynamics.from_callable))

    # Valid calls to mutate: each argument replaced by a drawn value with probability 0.3, so
    # that most calls get past the argument count and reach the checks inside.
    s4, a2 = np.array([1, 1, 0, 0], np.float32), np.zeros(2, np.float32)
    templates = [
        ("Shield", secure.Shield, [gt, dyn], dict(num_samples=8)),
        ("Shield.decide", shield.decide, [s4, a2, a2 + 1], {}),
        ("Shield.decide(reentrant)", holder["shield"].decide, [s4, a2, a2 + 1], {}),
        ("Shield.evaluate_g", shield.evaluate_g, [s4, np.zeros((3, 2), np.float32)], {}),
        ("Shield.set_backup_action", shield.set_backup_action, [a2], {}),
        ("Barrier.h", barrier.h, [safe[:3]], {}),
        ("Barrier.load", secure.Barrier.load, [model_path], {}),
        ("Barrier.save", barrier.save, [os.path.join(tmp, "saved.model")], {}),
        ("Policy.load", secure.Policy.load, [policy_path], {}),
        ("Policy.mean", policy.mean, [s4], {}),
        ("Policy.sample", policy.sample, [s4, 1], {}),
        ("Policy.log_prob", policy.log_prob, [s4, a2], {}),
        ("Dynamics.step", dyn.step, [s4, np.zeros((3, 2), np.float32)], {}),
        ("Dynamics.linear", secure.Dynamics.linear, [np.eye(4), np.zeros((4, 2))], {}),
        ("Dynamics.from_callable", secure.Dynamics.from_callable, [nan_fn, 4, 2], {}),
        ("Dynamics.builtin", secure.Dynamics.builtin, ["double-integrator"], {}),
        ("train_barrier", secure.train_barrier, [safe[:16], near[:16]], dict(hidden=[4])),
        ("train_bc", secure.train_bc, [demos], dict(hidden=[4])),
        ("run_episodes", secure.run_episodes, ["double-integrator", policy, gt], {}),
        ("make_env", secure.make_env, ["double-integrator"], {}),
        ("EnvCore.reset", core.reset, [0], {}),
        ("EnvCore.step", core.step, [a2], {}),
        ("EnvCore.backup_action", core.backup_action, [s4], {}),
        ("Demonstrations", secure.Demonstrations, [safe[:5], near[:5, :2]], {}),
        ("Demonstrations.load", secure.Demonstrations.load, [junk, ["x"], ["a"]], {}),
        ("generate_data", secure.generate_data, ["double-integrator"], {}),
    ]

    deadline = time.monotonic() + seconds
    calls = 0
    outcomes = {}
    while time.monotonic() < deadline:
        kwargs = {}
        if rng.random() < 0.5:
            name, fn, args, kwargs = rng.choice(templates)
            args = [draw() if rng.random() < 0.3 else a for a in args]
            kwargs = dict(kwargs)
        else:
            name, fn = rng.choice(targets)
            args = [draw() for _ in range(rng.randint(0, 4))]
        if rng.random() < 0.4:
            for _ in range(rng.randint(1, 3)):
                kwargs[rng.choice(option_keys)] = draw()
        base = name.split(".")[0]
        if base in small:
            kwargs.update(small[base])
        if base in ("run_episodes",):
            kwargs["episodes"] = rng.choice([0, 1, -1, 2**70, None])
        print(f"call {calls}: {name} args={[type(a).__name__ for a in args]} "
              f"kwargs={sorted(kwargs)}", flush=True)
        try:
            fn(*args, **kwargs)
            outcome = "returned"
        except SystemError as e:  # a C++ exception that escaped without a Python error
            print(f"FAIL: {name} raised SystemError: {e}", flush=True)
            sys.exit(3)
        except Exception as e:  # noqa: BLE001 (any Python exception is a handled bad input)
            outcome = type(e).__name__
        outcomes[outcome] = outcomes.get(outcome, 0) + 1
        calls += 1
    print(f"done: {calls} calls over {len(targets)} targets in {seconds:g} s (seed {seed}); "
          f"outcomes {dict(sorted(outcomes.items()))}", flush=True)
    os.chdir("/")
    shutil.rmtree(tmp, ignore_errors=True)


# ------------------------------------------------------------------------------------------------
# The parent: runs the child, fails on a signal, a hang or a failure it reports.

def main():
    a = parse()
    if a.child:
        child(a.seconds, a.seed)
        return 0
    cmd = [sys.executable, "-X", "faulthandler", os.path.abspath(__file__), "--child",
           "--seconds", str(a.seconds), "--seed", str(a.seed)]
    try:
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=a.seconds + 90)
    except subprocess.TimeoutExpired as e:
        out = (e.stdout or b"").decode() if isinstance(e.stdout, bytes) else (e.stdout or "")
        print("\n".join(out.splitlines()[-10:]))
        print(f"FAIL: the fuzz run did not end within {a.seconds + 90:g} s (a hang in the last "
              f"call above; seed {a.seed})")
        return 1
    lines = p.stdout.splitlines()
    if p.returncode != 0:
        print("\n".join(lines[-15:]))
        print(p.stderr[-4000:])
        print(f"FAIL: the child interpreter exited with {p.returncode} (negative: a signal) "
              f"after the last call above; replay: {' '.join(cmd[2:])}")
        return 1
    print(lines[-1] if lines else "no output")
    return 0


if __name__ == "__main__":
    sys.exit(main())
