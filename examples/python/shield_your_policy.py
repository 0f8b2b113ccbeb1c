# Shield your own NumPy policy with a Python dynamics model (PYTHONPATH=build/python python3 this)
import numpy as np
from numpy.typing import NDArray

import secure

DT, BOUND, GOAL = np.float32(0.1), 3.0, np.array([8.5, 8.5])
Array = NDArray[np.float32]  # the package is typed: mypy checks this file against its stub


def my_policy(s: Array) -> Array:  # a PD controller straight at the goal (through (5, 5))
    return np.asarray(np.clip(0.25 * (GOAL - s[:2]) - 1.0 * s[2:], -BOUND, BOUND), np.float32)


def my_dynamics(s: Array, actions: Array) -> Array:  # T(s, a): M actions (M, 2) -> (M, 4)
    a = np.clip(actions, -BOUND, BOUND)
    pos = s[:2] + s[2:] * DT + a * (0.5 * DT * DT)
    return np.hstack([pos, s[2:] + a * DT]).astype(np.float32)

env = secure.make_env("double-integrator")  # x, y, vx, vy; obstacle (5, 5), radius 2
barrier = secure.Barrier.ground_truth("double-integrator")  # or secure.Barrier.load("my.model")
assert barrier is not None  # a domain without an analytic barrier gives None
dynamics = secure.Dynamics.from_callable(my_dynamics, state_dim=4, action_dim=2)
shield = secure.Shield(barrier, dynamics, seed=1)
sigma = np.full(2, 0.3, dtype=np.float32)

for shielded in (False, True):
    obs, _ = env.reset(seed=7)
    rng, collided, interventions = np.random.default_rng(0), False, 0
    for t in range(env.max_steps):
        if shielded:
            decision = shield.decide(obs, my_policy(obs), sigma)
            action, interventions = decision.action, interventions + decision.intervened
        else:
            action = my_policy(obs) + sigma * rng.standard_normal(2).astype(np.float32)
        obs, reward, terminated, truncated, info = env.step(action)
        collided |= info["collided"]
        if terminated or truncated:
            break
    print(f"{'shielded' if shielded else 'unshielded':>10}: collided={collided} "
          f"goal={info['reached_goal']} steps={t + 1} interventions={interventions}")
    assert not (shielded and collided), "the shield let the policy collide"
