"""Hostile input from Python (issue 34): None, cyclic containers, objects made without __init__,
re-entrant shields, NaN from a dynamics callback, duplicate feature names, non-finite numbers and
the unclear messages. Each reproduction that used to crash the interpreter runs in a subprocess
(with faulthandler), so a crash fails this test instead of killing pytest."""
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

import secure

PRELUDE = """
import faulthandler, sys
faulthandler.enable()
import numpy as np
import secure
b = secure.Barrier.ground_truth("double-integrator")
d = secure.Dynamics.builtin("double-integrator")
def expect(exc, f, match=None):
    try:
        f()
    except exc as e:
        if match is not None and match not in str(e):
            raise SystemExit(f"wrong message: {type(e).__name__}: {e}")
        print("ok", type(e).__name__, str(e).splitlines()[0] if str(e) else "")
        return
    raise SystemExit("no exception")
"""


def run(code, timeout=60):
    """Runs PRELUDE + code in a fresh interpreter; returns (returncode, stdout + stderr)."""
    try:
        p = subprocess.run([sys.executable, "-c", PRELUDE + textwrap.dedent(code)],
                           capture_output=True, text=True, timeout=timeout, env=os.environ)
    except subprocess.TimeoutExpired:
        return "timeout", ""
    return p.returncode, p.stdout + p.stderr


def assert_clean(code, timeout=60):
    rc, out = run(code, timeout)
    assert rc == 0, f"exit {rc}:\n{out}"
    return out


def test_none_where_an_object_is_required_is_a_type_error():
    out = assert_clean("""
        expect(TypeError, lambda: secure.Shield(None, d), "barrier")
        expect(TypeError, lambda: secure.Shield(b, None), "dynamics")
        expect(TypeError, lambda: secure.run_episodes("double-integrator", None), "policy")
        expect(TypeError, lambda: secure.train_bc(None))
    """)
    assert out.count("ok TypeError") == 4


def test_cyclic_containers_are_rejected():
    assert_clean("""
        l = [1.0]; l.append(l)
        expect((TypeError, ValueError), lambda: secure.make_env("double-integrator", task=l))
        expect(ValueError, lambda: secure.make_env("double-integrator", task={"goal": l}),
               "nested")
        dd = {}; dd["self"] = dd
        expect(ValueError, lambda: secure.Dynamics.builtin("double-integrator", task=dd), "nested")
        safe = np.zeros((4, 4), np.float32); near = np.ones((4, 4), np.float32)
        expect(ValueError, lambda: secure.train_barrier(safe, near, hidden=l), "nested")
        expect((TypeError, ValueError), lambda: secure.Shield(b, d, num_samples=l))
    """)


def test_shared_reference_bombs_fail_fast():
    # 9 levels of lists holding the level below 9 times: 9^9 leaves if expanded.
    assert_clean("""
        x = [1.0]
        for _ in range(9):
            x = [x] * 9
        expect((TypeError, ValueError), lambda: secure.make_env("double-integrator", task=x))
        expect(ValueError, lambda: secure.make_env("double-integrator", task={"goal": x}),
               "nodes")
        safe = np.zeros((4, 4), np.float32)
        expect(ValueError, lambda: secure.train_barrier(safe, safe + 1, hidden=x), "nodes")
    """, timeout=30)


def test_shared_reference_bombs_in_any_argument_fail_fast_naming_it():
    # Issue 34: where pybind11 could not convert such a value, its message repr()ed all 9^9
    # leaves (no end); where NumPy converted it, it built a 9^9 array. Each bound function now
    # counts its arguments' containers first (python/src/arg_bounds.cc).
    out = assert_clean("""
        x = [1.0]
        for _ in range(9):
            x = [x] * 9
        s = np.zeros(4, np.float32)
        expect(ValueError, lambda: secure.domains(x), "secure.domains: argument 1")
        expect(ValueError, lambda: secure.make_env("double-integrator", task=x),
               "argument 'options' ['task'] holds more than 100000 nodes")
        expect(ValueError, lambda: b.h(x), "secure.Barrier.h: argument 'states'")
        expect(ValueError, lambda: secure.EnvCore(x, "full", False, {}), "argument 'name'")
        expect(ValueError, lambda: secure.Shield(b, d, num_samples=x), "argument 'num_samples'")
        expect(ValueError, lambda: secure.Rng(x), "secure.Rng.__init__")
        expect(ValueError, lambda: secure.make_env("double-integrator", render_mode=x),
               "render_mode = [[[[[[")
        expect(ValueError, lambda: secure.make_env("double-integrator", render_size=x),
               "render_size")
        expect(ValueError, lambda: secure.make_env("double-integrator").reset(seed=x), "seed")
        # An unbound method called on None crashed the interpreter (found by python_fuzz).
        expect(TypeError, lambda: secure.Rng.next_u64(None), "secure.Rng.next_u64: called on None")
        expect(TypeError, lambda: secure.Barrier.h(None, s), "called on None")
        c = [1.0]; c.append(c)
        expect(ValueError, lambda: b.h(c), "contains itself")
        # Ordinary nested lists still convert.
        print("h", b.h([[0.0, 0.0, 0.0, 0.0]] * 1000).shape)
    """, timeout=30)
    assert "h (1000,)" in out


def test_uninitialised_objects_raise_instead_of_crashing():
    out = assert_clean("""
        s = np.zeros(4, np.float32); a = np.zeros(2, np.float32)
        U = lambda cls: cls.__new__(cls)
        expect(TypeError, lambda: U(secure.Shield).decide(s, a, a + 1), "__init__")
        expect(TypeError, lambda: U(secure.Shield).evaluate_h(s))
        expect(TypeError, lambda: U(secure.Shield).seed(1))
        expect(TypeError, lambda: U(secure.Shield).state_dim)
        expect(TypeError, lambda: U(secure.Barrier).h(s))
        expect(TypeError, lambda: U(secure.Barrier).state_dim)
        expect(TypeError, lambda: U(secure.Dynamics).step(s, a[None]))
        expect(TypeError, lambda: U(secure.Dynamics).kind)
        expect(TypeError, lambda: U(secure.Policy).mean(s))
        expect(TypeError, lambda: U(secure.Policy).sample(s, 1))
        expect(TypeError, lambda: U(secure.Rng).uniform())
        expect(TypeError, lambda: U(secure.Rng).next_u64())
        expect(TypeError, lambda: U(secure.EnvCore).reset(0))
        expect(TypeError, lambda: U(secure.EnvCore).name)
        expect(TypeError, lambda: U(secure.Decision).safe)
        expect(TypeError, lambda: U(secure.Demonstrations).num_steps)
        expect(TypeError, lambda: U(secure.AirlReward).discount)
        expect(TypeError, lambda: secure.Shield(U(secure.Barrier), d))
        expect(TypeError, lambda: secure.Shield(b, U(secure.Dynamics)))
        expect(TypeError, lambda: secure.run_episodes(U(secure.EnvCore), None))
    """)
    assert out.count("ok TypeError") == 20


def test_a_shield_called_from_its_own_dynamics_callback_raises():
    assert_clean("""
        inner = secure.Dynamics.builtin("double-integrator")
        holder = {}
        def fn(state, actions):
            holder["shield"].decide(state, np.zeros(2, np.float32), np.ones(2, np.float32))
            return inner.step(state, actions)
        py = secure.Dynamics.from_callable(fn, 4, 2, name="reentrant")
        holder["shield"] = secure.Shield(b, py)
        s = np.array([1, 1, 0, 0], np.float32)
        expect(RuntimeError, lambda: holder["shield"].decide(s, np.zeros(2, np.float32),
                                                           np.ones(2, np.float32)), "re-entr")
        def fn2(state, actions):
            return py2.step(state, actions)
        py2 = secure.Dynamics.from_callable(fn2, 4, 2, name="steps itself")
        expect(RuntimeError, lambda: secure.Shield(b, py2).decide(
            s, np.zeros(2, np.float32), np.ones(2, np.float32)), "re-entr")
    """, timeout=30)


def test_nan_from_a_dynamics_callback_names_the_callback():
    inner = secure.Dynamics.builtin("double-integrator")

    def fn(state, actions):
        out = inner.step(state, actions)
        out[0, 1] = np.nan
        return out

    py = secure.Dynamics.from_callable(fn, 4, 2, name="my nan model")
    shield = secure.Shield(secure.Barrier.ground_truth("double-integrator"), py)
    s = np.array([1, 1, 0, 0], np.float32)
    with pytest.raises(ValueError, match="my nan model.*not finite"):
        shield.decide(s, np.zeros(2, np.float32), np.ones(2, np.float32))
    with pytest.raises(ValueError, match="my nan model"):
        py.step(s, np.zeros((3, 2), np.float32))


def test_train_barrier_rejects_duplicate_feature_names():
    safe = np.zeros((8, 3), np.float32)
    near = np.ones((8, 3), np.float32)
    with pytest.raises(ValueError, match="'x' .*twice|duplicate"):
        secure.train_barrier(safe, near, features=["x", "y", "x"], max_epochs=1)
    with pytest.raises(ValueError, match="duplicate"):
        secure.Demonstrations(safe, near[:, :2], state_features=["a", "a", "b"])


def test_policies_and_demonstrations_reject_non_finite_numbers(tmp_path, cli):
    data = secure.generate_data("double-integrator", seed=1, profile="quick")
    policy, _ = secure.train_bc(data["demonstrations"], epochs=1)
    obs = np.zeros(policy.observation_dim, np.float32)
    bad = obs.copy()
    bad[1] = np.nan
    with pytest.raises(ValueError, match=r"observation\[1\] = nan"):
        policy.mean(bad)
    with pytest.raises(ValueError, match="observation"):
        policy.mean(np.stack([obs, bad]))
    with pytest.raises(ValueError, match="observation"):
        policy.sample(bad, 1)
    action = np.zeros(policy.action_dim, np.float32)
    action[0] = np.inf
    with pytest.raises(ValueError, match=r"action\[0\] = inf"):
        policy.log_prob(obs, action)
    states = np.zeros((5, 4), np.float32)
    states[2, 3] = np.nan
    with pytest.raises(ValueError, match=r"states\[2, 3\] = nan"):
        secure.Demonstrations(states, np.zeros((5, 2), np.float32))
    with pytest.raises(ValueError, match=r"actions\[0, 1\] = inf"):
        secure.Demonstrations(np.zeros((5, 4)), np.array([[0, np.inf]] * 5))


def test_messages_name_the_thing_and_what_was_expected(tmp_path):
    data = secure.generate_data("double-integrator", seed=1, profile="quick")
    policy, _ = secure.train_bc(data["demonstrations"], epochs=1)
    obs = np.zeros(policy.observation_dim, np.float32)
    with pytest.raises(ValueError, match=r"rng: seed -1.*\[0, 2\*\*64\)"):
        policy.sample(obs, -1)
    with pytest.raises(ValueError, match=r"rng: seed .*\[0, 2\*\*64\)"):
        policy.sample(obs, 2**64)
    with pytest.raises(ValueError, match="is a directory, not a regular file"):
        secure.Barrier.load(str(tmp_path))
    barrier = secure.Barrier.ground_truth("double-integrator")
    big = np.array([1e300, 0, 0, 0])
    with pytest.raises(ValueError, match=r"1e\+300.*float32"):
        barrier.h(big)
