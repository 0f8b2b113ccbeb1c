"""secure.Env in Gymnasium's API, on every domain of the registry (secure.domains(), never a
hard-coded list). Gymnasium is optional (not a Debian package): test_gymnasium_check_env runs
gymnasium's own check_env where it is installed; the conformance tests below mirror its checks
(gymnasium.utils.env_checker.check_env and passive_env_checker) so that they run everywhere:
spaces, reset's signature and seeding determinism, reset/step return types, observations in the
observation space with its dtype, step determinism, the render contract and close()."""
import copy
import inspect
import warnings

import numpy as np
import pytest

import secure
from secure import spaces as secure_spaces

DOMAINS = secure.domains()
INFO_KEYS = {"reached_goal", "collided", "collisions", "step"}


def quick(name, **kwargs):
    return secure.make_env(name, profile="quick", **kwargs)


def test_domains_lists_the_registered_domains():
    names = secure.domains()
    assert {"double-integrator", "derby"} <= set(names)
    assert names == sorted(names)


# ---------------------------------------------------------------------------------------------
# Conformance: gymnasium's check_env, check by check


@pytest.mark.parametrize("name", DOMAINS)
def test_spaces_are_float32_boxes_with_the_domains_bounds(name):
    env = quick(name)
    a, o = env.action_space, env.observation_space
    for space, dim in ((a, env.action_dim), (o, env.observation_dim)):
        assert space.shape == (dim,) and space.dtype == np.float32
        assert space.low.shape == space.shape and space.high.shape == space.shape
        assert np.all(space.low < space.high)
    assert env.observation_dim == len(env.observation_features)
    assert env.action_dim == len(env.action_features)
    # The actuator box is finite: an action outside it steps exactly as the clipped action.
    assert a.is_bounded("both")
    clipped = quick(name)
    env.reset(seed=5)
    clipped.reset(seed=5)
    rng = np.random.default_rng(0)
    width = a.high - a.low
    for _ in range(5):
        action = rng.uniform(a.low - 2 * width, a.high + 2 * width).astype(np.float32)
        x = env.step(action)
        y = clipped.step(np.clip(action, a.low, a.high))
        np.testing.assert_array_equal(x[0], y[0])
        assert x[1:] == y[1:]
    # Samples are points of the space; a seeded space samples the same points again.
    a.seed(3)
    first = [a.sample() for _ in range(5)]
    assert all(s in a and s.dtype == np.float32 for s in first)
    a.seed(3)
    np.testing.assert_array_equal(first, [a.sample() for _ in range(5)])
    assert o.sample() in o
    assert np.zeros(env.observation_dim + 1, dtype=np.float32) not in o
    assert np.full(env.action_dim, np.inf, dtype=np.float32) not in a


@pytest.mark.parametrize("name", DOMAINS)
def test_reset_signature_and_seeding_determinism(name):
    env = quick(name)
    params = inspect.signature(env.reset).parameters
    assert params["seed"].default is None and "options" in params
    assert not callable(getattr(env, "seed", None))  # no deprecated seed()
    obs_1, info = env.reset(seed=123)
    assert obs_1 in env.observation_space and info == {}
    assert env.unwrapped._np_random is not None
    rng_1 = copy.deepcopy(env.unwrapped._np_random)
    obs_2, _ = env.reset()
    obs_3, _ = env.reset(seed=123)
    rng_3 = copy.deepcopy(env.unwrapped._np_random)
    obs_4, _ = env.reset()
    assert obs_2 in env.observation_space and obs_4 in env.observation_space
    np.testing.assert_array_equal(obs_1, obs_3)  # exactly, not only close
    np.testing.assert_array_equal(obs_2, obs_4)
    assert rng_1.bit_generator.state == rng_3.bit_generator.state
    obs_5, _ = env.reset(seed=456)
    assert obs_5 in env.observation_space
    assert env.unwrapped._np_random.bit_generator.state != rng_1.bit_generator.state
    assert not np.array_equal(obs_5, obs_1)
    # np_random is seeded by reset's seed as Gymnasium seeds it (a PCG64 of SeedSequence(seed)).
    env.reset(seed=7)
    assert env.np_random.integers(1 << 30) == np.random.default_rng(7).integers(1 << 30)
    # options: None or {} (this environment takes none).
    obs, info = env.reset(options={})
    assert obs in env.observation_space and isinstance(info, dict)
    with pytest.raises(ValueError, match="options: unknown key 'start'"):
        env.reset(options={"start": 1})
    for bad in (-1, 1.5, "3", True):
        with pytest.raises(ValueError, match="seed = "):
            env.reset(seed=bad)


@pytest.mark.parametrize("name", DOMAINS)
def test_reset_and_step_return_gymnasium_types(name):
    env = quick(name)
    result = env.reset(seed=1)
    assert isinstance(result, tuple) and len(result) == 2
    obs, info = result
    assert isinstance(obs, np.ndarray) and obs.dtype == env.observation_space.dtype
    assert obs in env.observation_space and isinstance(info, dict)
    env.action_space.seed(1)
    for t in range(3):
        result = env.step(env.action_space.sample())
        assert isinstance(result, tuple) and len(result) == 5
        obs, reward, terminated, truncated, info = result
        assert isinstance(obs, np.ndarray) and obs.dtype == env.observation_space.dtype
        assert obs in env.observation_space
        assert isinstance(reward, float) and np.isfinite(reward)
        assert isinstance(terminated, bool) and isinstance(truncated, bool)
        assert isinstance(info, dict) and set(info) == INFO_KEYS and info["step"] == t + 1


@pytest.mark.parametrize("name", DOMAINS)
def test_step_is_deterministic(name):
    env = quick(name)
    env.action_space.seed(123)
    action = env.action_space.sample()
    env.reset(seed=123)
    first = env.step(action)
    rng = copy.deepcopy(env.unwrapped._np_random)
    env.reset(seed=123)
    second = env.step(action)
    assert env.unwrapped._np_random.bit_generator.state == rng.bit_generator.state
    np.testing.assert_array_equal(first[0], second[0])
    assert first[1:] == second[1:]
    assert first[3] is False  # no truncation after one step


@pytest.mark.parametrize("name", DOMAINS)
def test_render_contract(name):
    env = quick(name)
    modes = env.metadata["render_modes"]
    assert isinstance(modes, list) and all(isinstance(m, str) for m in modes)
    assert set(modes) <= {"rgb_array"}
    fps = env.metadata["render_fps"]
    assert isinstance(fps, float) and fps > 0
    assert fps == pytest.approx(1.0 / env.dt)
    assert env.render_mode is None and env.spec is None
    env.reset(seed=0)
    # render_mode None: nothing is drawn (Gymnasium's convention), with a warning.
    with pytest.warns(UserWarning, match="render_mode is None"):
        assert env.render() is None
    if "rgb_array" not in modes:
        with pytest.raises(ValueError, match=rf"render_mode = 'rgb_array', the {name} domain "
                                             r"renders in \[\]"):
            quick(name, render_mode="rgb_array")
        return
    drawn = quick(name, render_mode="rgb_array", render_size=(64, 48))
    assert drawn.render_mode == "rgb_array"
    obs, _ = drawn.reset(seed=0)
    frames = [drawn.render()]
    action = np.zeros(drawn.action_dim, dtype=np.float32)
    for _ in range(3):
        stepped = drawn.step(action)
        frames.append(drawn.render())
    for frame in frames:
        assert isinstance(frame, np.ndarray) and frame.dtype == np.uint8
        assert frame.shape == (48, 64, 3)
    assert frames[0].std() > 0  # a picture, not a blank buffer
    # Rendering does not change the episode.
    env.reset(seed=0)
    for _ in range(3):
        plain = env.step(action)
    np.testing.assert_array_equal(plain[0], stepped[0])
    with pytest.raises(ValueError, match="render_size"):
        quick(name, render_mode="rgb_array", render_size=(0, 48))


@pytest.mark.parametrize("name", DOMAINS)
def test_close_is_idempotent_and_final(name):
    with quick(name) as env:
        env.reset(seed=0)
    env.close()  # a second close is fine
    assert "closed" in repr(env)
    for call in (lambda: env.reset(), lambda: env.step(np.zeros(env.action_dim))):
        with pytest.raises(RuntimeError, match="closed"):
            call()
    assert env.action_space.shape == (env.action_dim,)  # the spaces stay readable


# ---------------------------------------------------------------------------------------------
# Reward and info: per step, as documented (python/README.md)


@pytest.mark.parametrize("name", DOMAINS)
def test_reward_and_info_describe_each_step(name):
    """reward = reached_goal - collided; collisions = 1 exactly on the step a contact begins;
    terminated = goal; truncated = max_steps; info['step'] counts the steps."""
    env = quick(name)
    env.action_space.seed(11)
    contact_steps = 0
    for episode in range(4):
        env.reset(seed=100 + episode)
        before = False
        for t in range(env.max_steps):
            obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
            assert reward == float(info["reached_goal"]) - float(info["collided"])
            assert info["collisions"] == int(info["collided"] and not before), (episode, t)
            assert terminated == info["reached_goal"]
            assert truncated == (not terminated and t + 1 == env.max_steps)
            assert info["step"] == t + 1
            contact_steps += info["collided"]
            before = info["collided"]
            if terminated or truncated:
                break
    assert contact_steps >= 0


def test_derby_lasting_contact_is_collided_without_a_new_collision():
    """The issue's case: a Derby step with collided=True, collisions=0 is a contact that goes on
    (reward -1 on every step of it); the step that began it has collisions=1."""
    env = quick("derby")
    env.action_space.seed(0)
    lasting = entered = 0
    for episode in range(60):
        env.reset(seed=episode)
        before = False
        for _ in range(env.max_steps):
            _, reward, _, truncated, info = env.step(env.action_space.sample())
            if info["collided"]:
                assert reward == -1.0 or info["reached_goal"]
                if before:
                    assert info["collisions"] == 0
                    lasting += 1
                else:
                    assert info["collisions"] == 1
                    entered += 1
            before = info["collided"]
            if truncated or info["reached_goal"]:
                break
        if lasting and entered:
            break
    assert entered > 0 and lasting > 0, (entered, lasting)


def test_double_integrator_contact_counts_once_and_costs_every_step():
    env = secure.make_env("double-integrator")
    obs, _ = env.reset(seed=0)
    infos, rewards = [], []
    # Accelerate toward the obstacle's centre (5, 5) and keep pushing: in, then through it.
    for _ in range(env.max_steps):
        push = np.clip(3.0 * (5.0 - obs[:2]) - 2.0 * obs[2:], -3, 3).astype(np.float32)
        obs, reward, terminated, truncated, info = env.step(push)
        infos.append(info)
        rewards.append(reward)
        if sum(i["collided"] for i in infos) >= 3:
            break
    collided = [i["collided"] for i in infos]
    first = collided.index(True)
    assert infos[first]["collisions"] == 1 and rewards[first] == -1.0
    assert all(i["collisions"] == 0 for i in infos[first + 1:])
    assert all(r == -1.0 for r, c in zip(rewards, collided) if c)
    assert sum(i["collisions"] for i in infos) == 1


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


def test_old_forms_keep_working():
    """Code written against the earlier secure.Env: reset(seed) positionally, 5-tuple step,
    the library's attributes, env handed to run_episodes / Dynamics from the env."""
    env = secure.make_env("double-integrator")
    obs, info = env.reset(3)
    again, _ = env.reset(seed=3)
    np.testing.assert_array_equal(obs, again)
    assert info == {}
    assert env.dynamics.state_dim == env.observation_dim == 4
    assert env.shield_model_is_exact and env.options["task"]["max_steps"] == env.max_steps
    assert env.describe() and env.observation_features == ["x", "y", "vx", "vy"]
    assert isinstance(env.rng, secure.Rng)
    assert isinstance(env, secure.Env)


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


class _Wrapper:
    """Stands in for a Gymnasium wrapper (gymnasium.make's): the env is `unwrapped`."""

    def __init__(self, env):
        self.unwrapped = env


def test_library_calls_take_the_env_or_a_wrapper_of_it(di_data):
    policy, _ = secure.train_bc(di_data["demonstrations"], hidden=[8], epochs=1, seed=0)
    env = secure.make_env("double-integrator", task={"max_steps": 10})
    direct = secure.run_episodes(env, policy, episodes=2, seed=1)
    wrapped = secure.run_episodes(_Wrapper(env), policy, episodes=2, seed=1)
    for key in ("steps", "successes", "dangerous", "collision_events"):
        assert direct[key] == wrapped[key], key
    assert direct["steps"] > 0
    with pytest.raises(TypeError, match="env: expected a secure.Env or a domain name \\(str\\), got"):
        secure.run_episodes(42, policy, episodes=1)
    env.close()
    with pytest.raises(RuntimeError, match="closed"):
        secure.run_episodes(env, policy, episodes=1)


def test_backup_action_and_rng():
    env = secure.make_env("double-integrator")
    obs, _ = env.reset(seed=3)
    backup = env.backup_action(np.array([1, 1, 0.2, -0.1], dtype=np.float32))
    np.testing.assert_allclose(backup, [-2.0, 1.0])
    rng = secure.Rng(7)
    assert secure.Rng(7).next_u64() == rng.next_u64()


# ---------------------------------------------------------------------------------------------
# Registration with Gymnasium (optional)


def test_env_ids_are_derived_from_the_registry():
    assert secure.env_id("double-integrator") == "secure/DoubleIntegrator-v0"
    assert secure.env_id("derby") == "secure/Derby-v0"
    ids = [secure.env_id(n) for n in secure.domains()]
    assert len(set(ids)) == len(ids)
    assert all(i.startswith("secure/") and i.endswith("-v0") for i in ids)
    with pytest.raises(ValueError, match="env_id"):
        secure.env_id("--")


def test_gymnasium_check_env():
    gym = pytest.importorskip("gymnasium")
    from gymnasium.utils.env_checker import check_env

    ids = secure.register_gymnasium()
    assert ids == [secure.env_id(n) for n in secure.domains()]
    for gid, name in zip(ids, secure.domains()):
        env = gym.make(gid, profile="quick")
        assert isinstance(env.unwrapped, secure.Env) and env.unwrapped.name == name
        assert isinstance(env.observation_space, gym.spaces.Box)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # unbounded observations, unnormalised actions
            check_env(env.unwrapped)
        env.close()


def test_without_gymnasium_the_spaces_are_our_box():
    try:
        import gymnasium  # noqa: F401
        pytest.skip("gymnasium is installed: the spaces are gymnasium.spaces.Box")
    except ImportError:
        pass
    env = secure.make_env("derby")
    assert isinstance(env.action_space, secure_spaces.Box)
    with pytest.raises(ImportError, match="gymnasium is not installed"):
        secure.register_gymnasium()


def test_fallback_box_follows_gymnasiums_rules():
    box = secure_spaces.Box(low=np.array([-1, 0, -np.inf, -np.inf], dtype=np.float32),
                            high=np.array([1, np.inf, 2, np.inf], dtype=np.float32), seed=0)
    assert box.shape == (4,) and box.dtype == np.float32 and not box.is_bounded()
    assert box.is_bounded("below") is False
    x = np.array([box.sample() for _ in range(2000)])
    assert x.dtype == np.float32 and all(s in box for s in x)
    assert -1 <= x[:, 0].min() and x[:, 0].max() <= 1 and abs(x[:, 0].mean()) < 0.1
    assert x[:, 1].min() >= 0 and abs(x[:, 1].mean() - 1.0) < 0.1  # low + Exp(1)
    assert x[:, 2].max() <= 2 and abs(x[:, 2].mean() - 1.0) < 0.1  # high - Exp(1)
    assert abs(x[:, 3].mean()) < 0.1 and abs(x[:, 3].std() - 1.0) < 0.1  # N(0, 1)
    assert [0.0, 0.0, 0.0, 0.0] in box and np.zeros(4, dtype=np.float64) not in box
    assert np.zeros(3, dtype=np.float32) not in box and "a" not in box
    assert secure_spaces.Box(-1.0, 1.0, shape=(2,)) == secure_spaces.Box(-1.0, 1.0, shape=(2,))
    with pytest.raises(ValueError, match="above high"):
        secure_spaces.Box(1.0, -1.0, shape=(2,))
