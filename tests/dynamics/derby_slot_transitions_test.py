"""secure/dynamics/tools/derby_slot_transitions.py: the next observation's car slots follow the
current observation's cars; transitions where a car enters or leaves the 12 are dropped; bad
input is a one-line error naming the file. Synthetic Derby trajectories (cars at constant
velocity, so each car's true next offset is known)."""
import os
import subprocess
import sys
import tempfile

import numpy as np

SCRIPT = os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', '..', 'secure', 'dynamics',
                      'tools', 'derby_slot_transitions.py')
DT = 0.1
CARS = 12


def header():
    cols = ['episode', 'step', 'goal_dx', 'goal_dy', 'vx', 'vy']
    for i in range(CARS):
        cols += [f'car{i}_dx', f'car{i}_dy', f'car{i}_dvx', f'car{i}_dvy']
    return cols + ['ax', 'ay']


def observe(positions, velocities):
    """Ego at rest at the origin: the cars' offsets, nearest first (the environment's order)."""
    order = np.argsort((positions ** 2).sum(axis=1), kind='stable')[:CARS]
    cars = np.concatenate([positions[order], velocities[order]], axis=1)
    return np.concatenate([[1.0, 1.0, 0.0, 0.0], cars.reshape(-1)]), order


def run(rows, *extra):
    with tempfile.TemporaryDirectory() as tmp:
        src, out = os.path.join(tmp, 'demos.csv'), os.path.join(tmp, 'out.csv')
        with open(src, 'w') as f:
            f.write(','.join(header()) + '\n')
            for r in rows:
                f.write(','.join(repr(float(x)) for x in r) + '\n')
        p = subprocess.run([sys.executable, SCRIPT, src, out, *extra], capture_output=True,
                           text=True)
        data = None
        if p.returncode == 0:
            with open(out) as f:
                cols = f.readline().strip().split(',')
            data = (cols, np.loadtxt(out, delimiter=',', skiprows=1, ndmin=2))
        return p, data, src


def trajectory(rng, cars, steps):
    positions = rng.uniform(-0.6, 0.6, size=(cars, 2))
    velocities = rng.uniform(-0.5, 0.5, size=(cars, 2))
    frames = []
    for _ in range(steps):
        frames.append(observe(positions, velocities))
        positions = positions + DT * velocities
    return frames


def rows_of(frames, episode=0):
    return [np.concatenate([[episode, t], obs, [0.0, 0.0]]) for t, (obs, _) in enumerate(frames)]


def test_slots_follow_the_cars():
    rng = np.random.default_rng(3)
    frames = trajectory(rng, CARS, 40)  # 12 cars: the set never changes, only the order
    reordered = sum((a[1] != b[1]).any() for a, b in zip(frames, frames[1:]))
    assert reordered > 0, 'the test needs at least one re-ordering'
    p, (cols, data), _ = run(rows_of(frames))
    assert p.returncode == 0, p.stderr
    assert data.shape == (39, 52 + 2 + 52)
    assert cols[54] == 'next_goal_dx' and cols[-1] == 'next_car11_dvy'
    for row in data:
        now = row[4:52].reshape(CARS, 4)
        nxt = row[58:].reshape(CARS, 4)
        np.testing.assert_allclose(nxt[:, :2], now[:, :2] + DT * now[:, 2:], atol=1e-9)
        np.testing.assert_allclose(nxt[:, 2:], now[:, 2:], atol=1e-12)
    assert f'kept 39 ({reordered} with slots re-ordered), dropped 0' in p.stdout


def test_a_car_entering_the_twelve_drops_the_transition():
    rng = np.random.default_rng(4)
    positions = rng.uniform(-0.5, 0.5, size=(13, 2))
    positions[12] = [3.0, 0.0]  # far: the 13th car is outside the 12 nearest ...
    velocities = np.zeros((13, 2))
    first, _ = observe(positions, velocities)
    positions[12] = [0.01, 0.0]  # ... and then the nearest (a jump the matching cannot follow)
    second, _ = observe(positions, velocities)
    third, _ = observe(positions, velocities)
    rows = [np.concatenate([[0, t], o, [0.0, 0.0]]) for t, o in enumerate([first, second, third])]
    p, (cols, data), _ = run(rows)
    assert p.returncode == 0, p.stderr
    assert data.shape[0] == 1  # first -> second dropped, second -> third kept
    assert 'kept 1 (0 with slots re-ordered), dropped 1' in p.stdout


def test_episodes_are_not_joined():
    rng = np.random.default_rng(5)
    rows = rows_of(trajectory(rng, CARS, 5), 0) + rows_of(trajectory(rng, CARS, 5), 1)
    p, (_, data), _ = run(rows)
    assert p.returncode == 0, p.stderr
    assert data.shape[0] == 8


def test_bad_input_is_a_one_line_error():
    rng = np.random.default_rng(6)
    rows = rows_of(trajectory(rng, CARS, 4))
    rows[2][7] = np.nan
    p, data, src = run(rows)
    assert p.returncode == 1 and data is None
    assert p.stderr.strip() == f'{src}: line 4: a non-finite value', p.stderr
    p, data, src = run(rows_of(trajectory(rng, CARS, 4)), '--threshold', '1e-12')
    assert p.returncode == 0  # constant velocity: matched exactly, nothing dropped
    rows = [r[:10] for r in rows_of(trajectory(rng, CARS, 4))]
    with tempfile.TemporaryDirectory() as tmp:
        src = os.path.join(tmp, 'short.csv')
        with open(src, 'w') as f:
            f.write(','.join(header()[:10]) + '\n')
            for r in rows:
                f.write(','.join(str(x) for x in r) + '\n')
        p = subprocess.run([sys.executable, SCRIPT, src, os.path.join(tmp, 'o.csv')],
                           capture_output=True, text=True)
    assert p.returncode == 1
    assert p.stderr.strip() == f'{src}: no column "ax" (expected a Derby trajectories file)'


if __name__ == '__main__':
    for name, fn in list(globals().items()):
        if name.startswith('test_'):
            fn()
            print(name, 'ok')
