"""secure.Dynamics.learned: a learned dynamics ensemble (`secure dynamics train`) as the shield
model, pessimistic over its members."""
import numpy as np
import pytest

import secure
from conftest import run_cli


@pytest.fixture(scope="module")
def learned_model(cli, tmp_path_factory):
    """An ensemble learned from (s, a, s') of the double integrator's exact step (dt 0.1)."""
    rng = np.random.default_rng(0)
    n = 3000
    s = rng.uniform([0, 0, -2, -2], [10, 10, 2, 2], size=(n, 4)).astype(np.float32)
    a = rng.uniform(-3, 3, size=(n, 2)).astype(np.float32)
    nxt = np.empty_like(s)
    nxt[:, :2] = s[:, :2] + 0.1 * s[:, 2:] + 0.005 * a
    nxt[:, 2:] = s[:, 2:] + 0.1 * a
    d = tmp_path_factory.mktemp("dynamics")
    header = "x,y,vx,vy,ax,ay,next_x,next_y,next_vx,next_vy"
    np.savetxt(d / "t.csv", np.hstack([s, a, nxt]), delimiter=",", header=header, comments="",
               fmt="%.9g")
    path = str(d / "dyn.model")
    summary = run_cli(cli, "dynamics", "train", "--transitions", str(d / "t.csv"),
                      "--domain", "double-integrator", "--out", path, "--members", "3",
                      "--hidden", "32", "--epochs", "40", "--seed", "1")
    assert summary["summary"]["train_transitions"] + summary["summary"][
        "validation_transitions"] == n
    return path


def test_learned_dynamics_steps_close_to_the_truth(learned_model):
    model = secure.Dynamics.learned(learned_model)
    assert model.kind == "learned"
    assert (model.state_dim, model.action_dim) == (4, 2)
    assert "ensemble of 3" in model.describe()
    state = np.array([5.0, 2.0, 0.5, -0.3], dtype=np.float32)
    actions = np.array([[1.0, -1.0], [0.0, 2.5], [-2.0, 0.0]], dtype=np.float32)
    nxt = model.step(state, actions)
    truth = np.empty((3, 4), dtype=np.float32)
    truth[:, :2] = state[:2] + 0.1 * state[2:] + 0.005 * actions
    truth[:, 2:] = state[2:] + 0.1 * actions
    assert nxt.shape == (3, 4)
    assert np.abs(nxt - truth).max() < 0.05  # a quick model (40 epochs)


def test_shield_through_the_learned_model_is_pessimistic(learned_model):
    barrier = secure.Barrier.ground_truth("double-integrator")
    learned = secure.Dynamics.learned(learned_model)
    exact = secure.Dynamics.builtin("double-integrator")
    state = np.array([5.0, 7.4, 0.0, -1.0], dtype=np.float32)  # heading for the disc
    actions = np.array([[0.0, -3.0], [0.0, 0.0], [0.0, 3.0]], dtype=np.float32)
    g_learned = secure.Shield(barrier, learned, num_samples=8, num_probes=8).evaluate_g(
        state, actions)
    g_exact = secure.Shield(barrier, exact, num_samples=8, num_probes=8).evaluate_g(
        state, actions)
    # The same ordering as the exact model (braking, ay > 0, is the safest), close values.
    assert g_learned[2] > g_learned[1] > g_learned[0]
    # g divides the change of h by dt = 0.1: a rough model's 0.02 error is a few units of g.
    assert np.all(np.abs(g_learned - g_exact) < 0.3 * np.abs(g_exact) + 1.0)
    shield = secure.Shield(barrier, learned, seed=3)
    d = shield.decide(state, np.array([0.0, -3.0], dtype=np.float32),
                      np.full(2, 0.3, dtype=np.float32))
    assert d.safe
    assert d.action[1] > -3.0  # the shield brakes the policy's dive into the disc


def test_learned_dynamics_errors(tmp_path, learned_model):
    with pytest.raises(ValueError, match="missing.model"):
        secure.Dynamics.learned(str(tmp_path / "missing.model"))
    with pytest.raises(ValueError, match="max_batch = 0"):
        secure.Dynamics.learned(learned_model, max_batch=0)
    with pytest.raises(ValueError, match="pessimism = 'max', must be min | mean-std"):
        secure.Dynamics.learned(learned_model, pessimism="max")
    with pytest.raises(ValueError, match="kappa"):
        secure.Dynamics.learned(learned_model, pessimism="mean-std", pessimism_kappa=-1)


def test_learned_pessimism_options(learned_model):
    """pessimism='mean-std' with kappa 0 scores by the members' mean h(s+), never below the
    minimum over the members (the default); a larger kappa is more careful."""
    barrier = secure.Barrier.ground_truth("double-integrator")
    state = np.array([5.0, 7.4, 0.0, -1.0], dtype=np.float32)
    actions = np.array([[0.0, -3.0], [0.0, 0.0], [0.0, 3.0]], dtype=np.float32)

    def g(**kw):
        model = secure.Dynamics.learned(learned_model, **kw)
        return secure.Shield(barrier, model, num_samples=8, num_probes=8).evaluate_g(state, actions)

    g_min, g_mean = g(), g(pessimism="mean-std", pessimism_kappa=0.0)
    g_careful = g(pessimism="mean-std", pessimism_kappa=3.0)
    assert np.all(g_mean >= g_min - 1e-4) and np.all(g_careful <= g_mean + 1e-4)
    assert np.any(g_mean > g_min + 1e-6)  # the members disagree somewhere
    g_linear = g(pessimism_linear=True)
    assert np.all(np.abs(g_linear - g_min) < 0.1 * np.abs(g_min) + 0.5)


def test_learned_hold_option(learned_model):
    """hold=H: one step() is H model steps with the action held (the double integrator's learned
    model stepped three times by hand from the mean agrees with it to the members' spread); 1 is
    the model as trained; outside [1, 20] is an error naming it."""
    state = np.array([5.0, 7.4, 0.0, -1.0], dtype=np.float32)
    actions = np.array([[0.0, -3.0], [0.0, 0.0], [1.0, 3.0]], dtype=np.float32)
    one = secure.Dynamics.learned(learned_model)
    held = secure.Dynamics.learned(learned_model, hold=3)
    by_hand = []
    for a in actions:
        s = state
        for _ in range(3):
            s = one.step(s, a[None, :])[0]
        by_hand.append(s)
    by_hand = np.array(by_hand)
    three = held.step(state, actions)
    assert np.all(np.abs(three - by_hand) < 0.05 * (1 + np.abs(by_hand)))
    assert np.max(np.abs(three - one.step(state, actions))) > 0.01  # three steps are not one
    assert np.array_equal(secure.Dynamics.learned(learned_model, hold=1).step(state, actions),
                          one.step(state, actions))
    for bad in (0, 21):
        with pytest.raises(ValueError, match=f"hold = {bad}"):
            secure.Dynamics.learned(learned_model, hold=bad)
