import numpy as np
import pytest

import secure
from conftest import run_cli


@pytest.fixture(scope="module")
def demos(di_data):
    return di_data["demonstrations"]


def test_demonstrations_from_arrays():
    states = np.arange(12, dtype=np.float32).reshape(6, 2)
    actions = np.ones((6, 1))
    d = secure.Demonstrations(states, actions, episode=[0, 0, 1, 1, 1, 2])
    assert d.episode_begin == [0, 2, 5, 6] and d.num_episodes == 3
    assert d.state_features == ["s0", "s1"] and d.action_features == ["a0"]
    np.testing.assert_array_equal(d.states, states)
    with pytest.raises(ValueError, match="actions: 5 rows, states have 6"):
        secure.Demonstrations(states, actions[:5])


def test_bc_round_trip_and_sampling(demos, tmp_path):
    policy, summary = secure.train_bc(demos, hidden=[16], epochs=3, seed=2)
    assert summary["epochs"] == 3
    assert policy.observation_features == demos.state_features
    path = str(tmp_path / "bc.model")
    policy.save(path)
    loaded = secure.Policy.load(path)
    obs = demos.states[:10]
    np.testing.assert_array_equal(loaded.mean(obs), policy.mean(obs))
    assert policy.mean(obs[0]).shape == (2,)
    np.testing.assert_allclose(policy.mean(obs[3]), policy.mean(obs)[3], rtol=1e-5)
    # Seeded sampling: a seed or a secure.Rng, reproducible, mean + sigma * normal.
    np.testing.assert_array_equal(policy.sample(obs[0], 5), loaded.sample(obs[0], 5))
    rng = secure.Rng(5)
    a = policy.sample(obs[0], rng)
    r = secure.Rng(5)
    expected = policy.mean(obs[0]) + policy.sigma * np.array([r.normal(), r.normal()], np.float32)
    np.testing.assert_allclose(a, expected, rtol=1e-6)
    assert np.isfinite(policy.log_prob(obs[0], a))
    with pytest.raises(ValueError, match="train_bc options: unknown (key|field) 'epoch'"):
        secure.train_bc(demos, epoch=3)


def test_bc_on_some_input_features_ignores_the_others(demos):
    # The double integrator's states are (x, y, vx, vy): a policy on the positions alone.
    policy, _ = secure.train_bc(demos, hidden=[16], epochs=3, seed=2, input_features=["x", "y"])
    assert policy.observation_features == demos.state_features
    assert policy.input_features == ["x", "y"]
    obs = demos.states[:10].copy()
    other = obs.copy()
    other[:, 2:] += 5.0
    np.testing.assert_array_equal(policy.mean(obs), policy.mean(other))
    with pytest.raises(ValueError, match="input_features = 'speed'"):
        secure.train_bc(demos, epochs=1, input_features=["speed"])


def test_bc_equals_cli_policy_train(cli, demos, tmp_path):
    demos_csv = str(tmp_path / "demos.csv")
    demos.save(demos_csv)
    out = str(tmp_path / "cli_bc.model")
    run_cli(cli, "policy", "train", "--algo", "bc", "--demos", demos_csv, "--out", out,
            "--domain", "double-integrator", "--epochs", "2", "--seed", "9")
    ours, _ = secure.train_bc(
        secure.Demonstrations.load(demos_csv, demos.state_features, demos.action_features),
        epochs=2, seed=9)
    theirs = secure.Policy.load(out)
    obs = demos.states[:50]
    np.testing.assert_array_equal(ours.mean(obs), theirs.mean(obs))
    np.testing.assert_array_equal(ours.sigma, theirs.sigma)


def test_airl_tiny(demos):
    env = secure.make_env("double-integrator", task={"max_steps": 20})
    policy, summary = secure.train_airl(demos, env, iterations=2, steps_per_iteration=40,
                                        minibatch_size=20, discriminator_updates=2,
                                        policy_hidden=[8], value_hidden=[8], reward_hidden=[8],
                                        shaping_hidden=[8], seed=1)
    assert summary["iterations"] == 2
    assert policy.action_dim == 2
    with pytest.raises(ValueError, match="train_airl options: unknown (key|field) 'iteration'"):
        secure.train_airl(demos, "double-integrator", iteration=1)


def python_episodes(env, policy, shield, episodes, seed, per_episode=None):
    """secure.run_episodes (eval::EpisodeRunner) step by step in Python; each episode's
    (success, dangerous, steps, first_dangerous_step, interventions) appended to `per_episode`."""
    counts = dict(successes=0, dangerous=0, collision_events=0, steps=0, decisions=0,
                  interventions=0)
    for i in range(episodes):
        obs, _ = env.reset(seed=secure.episode_seed(seed, i))
        if shield is not None:
            shield.seed(env.rng.next_u64())
        collided = False
        before = dict(counts)
        first_dangerous_step = -1
        for step in range(env.max_steps):
            if shield is not None:
                shield.set_backup_action(env.backup_action(obs))
                d = shield.decide(obs, policy.mean(obs), policy.sigma)
                action = d.action
                counts["decisions"] += 1
                counts["interventions"] += d.intervened
            else:
                action = policy.sample(obs, env.rng)
            obs, reward, terminated, truncated, info = env.step(action)
            counts["steps"] += 1
            if info["collided"]:
                if not collided:
                    first_dangerous_step = step
                collided = True
                counts["collision_events"] += max(1, info["collisions"])
            if info["reached_goal"]:
                counts["successes"] += 1
                break
        counts["dangerous"] += collided
        if per_episode is not None:
            per_episode.append((counts["successes"] - before["successes"], int(collided),
                                counts["steps"] - before["steps"], first_dangerous_step,
                                counts["interventions"] - before["interventions"]))
    return counts


@pytest.mark.parametrize("shielded", [False, True])
def test_run_episodes_equals_a_python_loop(demos, tiny_barrier, shielded):
    _, barrier, _ = tiny_barrier
    policy, _ = secure.train_bc(demos, hidden=[16], epochs=3, seed=2)
    env = secure.make_env("double-integrator", task={"max_steps": 60})
    shield = secure.Shield(barrier, env.dynamics) if shielded else None
    rows = []
    ours = python_episodes(env, policy, shield, 3, seed=4, per_episode=rows)
    theirs = secure.run_episodes(env, policy, barrier if shielded else None, episodes=3, seed=4)
    assert theirs["episodes"] == 3
    for key, value in ours.items():
        assert theirs[key] == value, key
    # The per-episode outcomes: one entry per episode, as the Python loop saw them.
    outcomes = theirs["episode_outcomes"]
    np.testing.assert_array_equal(outcomes["episode"], [0, 1, 2])
    for c, name in enumerate(("success", "dangerous", "steps", "first_dangerous_step",
                              "interventions")):
        assert outcomes[name].dtype == np.int64
        np.testing.assert_array_equal(outcomes[name], [row[c] for row in rows], err_msg=name)
    assert list(np.flatnonzero(outcomes["dangerous"])) == theirs["dangerous_episodes"]
    assert list(np.flatnonzero(outcomes["success"] == 0)) == theirs["failed_episodes"]
    assert outcomes["collision_events"].sum() == theirs["collision_events"]


def test_top_q_shield_with_airls_reward(demos, tiny_barrier, tmp_path):
    """aggregation='top-q': AIRL's reward model as the task value, in a Shield and in
    run_episodes (the same decisions), Q = g(s) + gamma V(s+), and the reward model's file."""
    _, barrier, _ = tiny_barrier
    env = secure.make_env("double-integrator", task={"max_steps": 20})
    policy, _, reward = secure.train_airl(
        demos, env, iterations=2, steps_per_iteration=40, minibatch_size=20,
        discriminator_updates=2, policy_hidden=[8], value_hidden=[8], reward_hidden=[8],
        shaping_hidden=[8], seed=1, with_reward=True)
    assert isinstance(reward, secure.AirlReward)
    assert reward.discount == pytest.approx(0.99)
    assert reward.observation_features == env.observation_features
    path = str(tmp_path / "airl_reward.model")
    reward.save(path)
    again = secure.AirlReward.load(path)
    state = np.array([1.0, 2.0, 0.1, -0.2], dtype=np.float32)
    nxt = np.array([[1.0, 2.0, 0.1, -0.2], [1.5, 2.5, 0.3, 0.0]], dtype=np.float32)
    q = reward.q(state, nxt)
    assert q.shape == (2,) and np.isfinite(q).all()
    assert np.array_equal(q, again.q(state, nxt))

    with pytest.raises(ValueError, match="needs task_value"):
        secure.Shield(barrier, env.dynamics, aggregation="top-q")
    with pytest.raises(ValueError, match="only with aggregation='top-q'"):
        secure.Shield(barrier, env.dynamics, task_value=reward)
    shield = secure.Shield(barrier, env.dynamics, aggregation="top-q", task_value=reward)
    ours = python_episodes(env, policy, shield, 3, seed=4)
    theirs = secure.run_episodes(env, policy, barrier, episodes=3, seed=4, aggregation="top-q",
                                 task_value=again)
    for key, value in ours.items():
        assert theirs[key] == value, key
