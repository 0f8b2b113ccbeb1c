import numpy as np
import pytest

import secure


def test_domains_lists_the_registered_domains():
    names = secure.domains()
    assert {"double-integrator", "derby"} <= set(names)
    assert names == sorted(names)


@pytest.mark.parametrize("name", secure.domains())
def test_every_domain_runs_gymnasium_style(name):
    env = secure.make_env(name, profile="quick")
    obs, info = env.reset(seed=1)
    assert obs.shape == (env.observation_dim,) and obs.dtype == np.float32
    assert info == {}
    assert len(env.observation_features) == env.observation_dim
    assert len(env.action_features) == env.action_dim
    assert env.dynamics.state_dim == env.observation_dim
    for _ in range(3):
        obs2, reward, terminated, truncated, info = env.step(np.zeros(env.action_dim))
        assert obs2.shape == obs.shape
        assert isinstance(reward, float) and isinstance(terminated, bool)
        assert set(info) == {"reached_goal", "collided", "collisions", "step"}
    # The same seed gives the same episode.
    again, _ = env.reset(seed=1)
    np.testing.assert_array_equal(again, obs)


def test_episode_ends_with_truncation_and_is_deterministic():
    env = secure.make_env("double-integrator", task={"max_steps": 5})
    assert env.max_steps == 5
    obs, _ = env.reset(seed=2)
    trace = []
    for t in range(5):
        obs, reward, terminated, truncated, info = env.step(np.array([0.1, 0.1]))
        trace.append(obs)
        assert truncated == (t == 4) and not terminated
    env.reset(seed=2)
    np.testing.assert_array_equal(env.step(np.array([0.1, 0.1]))[0], trace[0])


def test_env_errors():
    with pytest.raises(ValueError, match="unknown-domain"):
        secure.make_env("unknown-domain")
    with pytest.raises(ValueError, match="options \\[task\\]: unknown (key|field) 'max_step'"):
        secure.make_env("double-integrator", task={"max_step": 5})
    with pytest.raises(ValueError, match="profile = 'fast'"):
        secure.make_env("double-integrator", profile="fast")
    env = secure.make_env("double-integrator")
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros(2))
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"action: expected shape \(2,\)"):
        env.step(np.zeros(3))
    with pytest.raises(ValueError):
        env.step(np.array([np.nan, 0.0]))


def test_backup_action_and_rng():
    env = secure.make_env("double-integrator")
    obs, _ = env.reset(seed=3)
    backup = env.backup_action(np.array([1, 1, 0.2, -0.1], dtype=np.float32))
    np.testing.assert_allclose(backup, [-2.0, 1.0])
    rng = secure.Rng(7)
    assert secure.Rng(7).next_u64() == rng.next_u64()
