"""The cost of a Python dynamics model in the shield (python/README.md, "what the callback costs").
Run: PYTHONPATH=build/python /usr/bin/python3 python/bench/callback_cost.py"""
import os
import sys
import time
import timeit

import numpy as np

import secure

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tests"))
from test_shield import double_integrator, pd_mean  # noqa: E402

SIGMA = np.full(2, 0.3, np.float32)
data = secure.generate_data("double-integrator", seed=3, profile="quick")
barrier, _ = secure.train_barrier(data["safe"], data["near_dangerous"], features=data["features"],
                                  hidden=[64, 64, 64], max_epochs=30, seed=1)
states = np.concatenate([data["safe"][:500], data["near_dangerous"][:500]])
mus = [pd_mean(s) for s in states]


def run(model, name):
    shield = secure.Shield(barrier, model, seed=1)
    passes = []
    for _ in range(5):
        shield.seed(1)
        inside, rounds, start = 0.0, 0, time.perf_counter()
        for s, mu in zip(states, mus):
            d = shield.decide(s, mu, SIGMA)
            inside, rounds = inside + d.seconds, rounds + d.iterations
        passes.append(((time.perf_counter() - start) / len(states), inside / len(states)))
    loop, inside = min(passes)
    print(f"{name:>16}: {inside * 1e6:6.1f} us inside decide(), {loop * 1e6:6.1f} us per call "
          f"from Python, {rounds / len(states):.2f} rounds per decision")
    return inside


model = double_integrator()
calls = [0]


def counted(s, a):
    calls[0] += 1
    return model(s, a)


builtin = secure.Dynamics.builtin("double-integrator")
native = run(builtin, "built-in (C++)")
python = run(secure.Dynamics.from_callable(model, 4, 2), "NumPy callable")
shield = secure.Shield(barrier, secure.Dynamics.from_callable(counted, 4, 2), seed=1)
for s, mu in zip(states, mus):
    shield.decide(s, mu, SIGMA)
per_decision = calls[0] / len(states)
print(f"model calls per decision {per_decision:.2f}; "
      f"cost per call {(python - native) / per_decision * 1e6:.1f} us")

a64, s0, n = np.zeros((64, 2), np.float32), states[0].copy(), 5000
out = np.zeros((64, 4), np.float32)
trivial = secure.Dynamics.from_callable(lambda s, a: out, 4, 2)
for name, fn in [("the NumPy function alone", lambda: model(s0, a64)),
                 ("Dynamics.step, a trivial callable", lambda: trivial.step(s0, a64)),
                 ("Dynamics.step, the built-in model", lambda: builtin.step(s0, a64))]:
    print(f"{name} (64 actions): {min(timeit.repeat(fn, number=n, repeat=5)) / n * 1e6:.1f} us")
