# Learn a barrier from your own NumPy arrays of safe and near-dangerous states, then shield a
# NumPy policy with it (PYTHONPATH=build/python python3 this). The README shows this file.
import numpy as np

import secure

rng = np.random.default_rng(0)
# States (x, y, vx, vy) of a point robot (|acceleration| <= 3); the danger is a disc of radius 2
# around (5, 5). Label by what happens if the robot brakes now: near-dangerous if it would stop
# less than 0.3 from the disc, safe if more than 0.8 (velocity matters, not only position).
s = rng.uniform([0, 0, -2, -2], [10, 10, 2, 2], size=(40000, 4)).astype(np.float32)
rel = s[:, :2] - 5.0
gap = np.linalg.norm(rel, axis=1) - 2.0
braking = np.maximum(-(rel * s[:, 2:]).sum(axis=1) / (gap + 2.0), 0) ** 2 / (2 * 3.0)
safe, near = s[gap > braking + 0.8][:2000], s[(gap > 0) & (gap < braking + 0.3)][:2000]

barrier, summary = secure.train_barrier(safe, near, features=["x", "y", "vx", "vy"],
                                        hidden=[64, 64], max_epochs=60, seed=1)
acc = summary["train_accuracy"]
print(f"barrier: train accuracy safe {acc['safe']:.3f}, near-dangerous {acc['near_dangerous']:.3f}")

env = secure.make_env("double-integrator")  # the same point robot; obstacle (5, 5), radius 2
shield = secure.Shield(barrier, secure.Dynamics.builtin("double-integrator"), seed=1)
goal, sigma = np.array([8.5, 8.5]), np.full(2, 0.3, dtype=np.float32)
for episode in range(5):
    obs, _ = env.reset(seed=episode)
    collided = interventions = 0
    for t in range(env.max_steps):
        mu = np.clip(0.25 * (goal - obs[:2]) - obs[2:], -3, 3).astype(np.float32)  # your policy
        decision = shield.decide(obs, mu, sigma)
        interventions += decision.intervened
        obs, reward, terminated, truncated, info = env.step(decision.action)
        collided += info["collided"]
        if terminated or truncated:
            break
    print(f"episode {episode}: collided={bool(collided)} goal={info['reached_goal']} "
          f"steps={t + 1} interventions={interventions}")
    assert not collided, "the shield let the policy collide"
