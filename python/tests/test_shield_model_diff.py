"""tools/diagnostics/shield_model_diff.py: two shield models on the same episodes (paired by
episode and shield seed) and where their g disagree by |a|. The double integrator's ground-truth
barrier and exact model, against a model that differs only for large actions."""
import os
import sys

import numpy as np

import secure

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "tools",
                                "diagnostics"))
import shield_model_diff  # noqa: E402

OPTIONS = dict(num_samples=32, num_probes=32, dt=0.1, class_k_gain=1.0)


def setup():
    env = secure.EnvCore("double-integrator", "quick")
    barrier = secure.Barrier.ground_truth("double-integrator", "quick")
    return env, barrier


def test_g_disagreement_is_where_the_models_differ():
    env, barrier = setup()
    exact = env.dynamics
    obstacle = np.array(env.options["task"]["obstacle"], dtype=np.float32)

    def wild(state, actions):
        # The exact step, except that an action longer than 1.5 ends inside the obstacle.
        nxt = np.array(exact.step(state, actions), dtype=np.float32).reshape(len(actions), -1)
        far = np.linalg.norm(actions, axis=1) > 1.5
        nxt[far, :2] = obstacle
        nxt[far, 2:] = 0.0
        return nxt

    a = secure.Shield(barrier, exact, **OPTIONS)
    b = secure.Shield(barrier, secure.Dynamics.from_callable(wild, 4, 2), **OPTIONS)
    rng = np.random.default_rng(0)
    actions = rng.uniform(-3, 3, size=(200, 2)).astype(np.float32)
    states = np.array([[1.0, 1.0, 0.0, 0.0], [9.0, 1.0, 0.0, 0.0], [1.0, 9.0, 0.0, 0.0]],
                      dtype=np.float32)
    bins = [0.0, 1.0, 1.5, 2.0, 4.3]
    counts = shield_model_diff.g_disagreement(a, b, states, actions, bins)
    mag = np.linalg.norm(actions, axis=1)
    assert counts[2].tolist() == [3 * np.sum((mag >= lo) & (mag < hi))
                                  for lo, hi in zip(bins[:-1], bins[1:])]
    assert counts[0].sum() == 0  # the wild model is never the safer one
    assert counts[1, :2].sum() == 0  # below 1.5 the models agree
    # Above 1.5, every action the exact model calls safe (g of the exact shield, asked directly).
    safe = sum(np.concatenate([a.evaluate_g(s, actions[i:i + 32]) for i in range(0, 200, 32)]) >= 0
               for s in states)
    assert 0 < counts[1, 2:].sum() < counts[2, 2:].sum()
    assert counts[1, 2:].tolist() == [int(np.sum(safe[(mag >= lo) & (mag < hi)]))
                                      for lo, hi in zip(bins[2:-1], bins[3:])]


def test_drives_of_one_model_pair_episode_by_episode():
    env, barrier = setup()
    goal = np.array(env.options["task"]["goal"], dtype=np.float32)

    def mean(obs):  # a PD controller to the goal, through the obstacle's side
        return np.clip(1.5 * (goal - obs[:2]) - 2.0 * obs[2:], -3, 3).astype(np.float32)

    shields = {"hand-written": secure.Shield(barrier, env.dynamics, **OPTIONS),
               "learned": secure.Shield(barrier, env.dynamics, **OPTIONS)}
    sigma = np.array([0.5, 0.5], dtype=np.float32)
    first = shield_model_diff.drive(env, mean, sigma, shields, "hand-written", "learned", 3, 7,
                                    max_steps=120)
    second = shield_model_diff.drive(env, mean, sigma, shields, "learned", "hand-written", 3, 7,
                                     max_steps=120)
    for x, y in zip(first, second):
        assert x["episode"] == y["episode"]
        for key in ("steps", "success", "dangerous", "interventions", "ratio"):
            assert x[key] == y[key], key
        assert x["ratio"] == x["other_ratio"]  # the same model asked twice
    assert sum(r["interventions"] for r in first) > 0  # the obstacle is in the way
    summary = shield_model_diff.paired(first + second)
    assert summary["hand-written"] == summary["learned"]
    assert summary["lost only by hand-written"] == [] and summary["lost only by learned"] == []


def test_counts_below_one_are_one_line_errors(tmp_path):
    import subprocess
    script = os.path.join(os.path.dirname(shield_model_diff.__file__), "shield_model_diff.py")
    for flag in ("--episodes", "--g-episodes", "--actions", "--hold"):
        done = subprocess.run(
            [sys.executable, script, "--domain", "double-integrator", "--run", str(tmp_path),
             "--seed", "0", "--model", "m.model", flag, "0"],
            capture_output=True, text=True, env=dict(os.environ))
        assert done.returncode == 1, (flag, done.stderr)
        assert done.stderr.strip() == f"shield_model_diff: {flag} = 0, must be at least 1"

