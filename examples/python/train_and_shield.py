# Learn a barrier from your own NumPy arrays of safe and near-dangerous states, then shield a
# NumPy policy with it (PYTHONPATH=build/python python3 this). The README shows this file.
import numpy as np

import secure

rng = np.random.default_rng(0)
# States (x, y, vx, vy) of a point robot; the danger is a disc of radius 2 around (5, 5).
states = rng.uniform([0, 0, -2, -2], [10, 10, 2, 2], size=(20000, 4)).astype(np.float32)
d = np.linalg.norm(states[:, :2] - 5.0, axis=1)
safe, near = states[d > 3.0][:2000], states[(d > 2.0) & (d < 2.5)][:2000]

barrier, summary = secure.train_barrier(safe, near, features=["x", "y", "vx", "vy"],
                                        hidden=[64, 64], max_epochs=60, seed=1)
acc = summary["train_accuracy"]
print(f"barrier: train accuracy safe {acc['safe']:.3f}, near-dangerous {acc['near_dangerous']:.3f}")

env = secure.make_env("double-integrator")  # the same point robot; obstacle (5, 5), radius 2
shield = secure.Shield(barrier, secure.Dynamics.builtin("double-integrator"), seed=1)
goal, sigma = np.array([8.5, 8.5]), np.full(2, 0.3, dtype=np.float32)
obs, _ = env.reset(seed=7)
collided = interventions = 0
for t in range(env.max_steps):
    mu = np.clip(0.25 * (goal - obs[:2]) - obs[2:], -3, 3).astype(np.float32)  # your policy
    decision = shield.decide(obs, mu, sigma)
    interventions += decision.intervened
    obs, reward, terminated, truncated, info = env.step(decision.action)
    collided += info["collided"]
    if terminated or truncated:
        break
print(f"shielded: collided={bool(collided)} goal={info['reached_goal']} steps={t + 1} "
      f"interventions={interventions}")
assert not collided, "the shield let the policy collide"
