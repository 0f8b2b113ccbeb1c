#!/usr/bin/env python3
"""Derby transitions with each observation slot kept on one car, for `secure dynamics train`.

Derby's observation lists the 12 nearest cars in order of distance, so slot i's car can change
from one step to the next and s' - s is then not a function of (s, a) (docs/RESULTS.md, issue
36). This re-orders the next observation's 12 car slots to follow the current observation's
cars: slot i at t is matched to the next car whose (dx, dy) is nearest its constant-velocity
guess (dx, dy) + dt (dvx, dvy), plus 0.1 x the velocity difference, one to one. A transition
whose cars are not all matched one to one within --threshold (a car entered or left the 12
nearest) is dropped. Only the recorded observations and actions are used (no simulator state).

Usage: derby_slot_transitions.py demos.csv out.csv [--threshold 0.06] [--dt 0.1]
Input: trajectories with episode, step, the 52 observation columns, ax, ay (demos.csv,
`secure dynamics collect`). Output: (s, a, next_<f>) triples.
"""
import argparse
import sys

import numpy as np

CARS, CAR_FEATURES, EGO_FEATURES = 12, 4, 4


def main():
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('source')
    parser.add_argument('out')
    parser.add_argument('--threshold', type=float, default=0.06)
    parser.add_argument('--dt', type=float, default=0.1)
    args = parser.parse_args()
    with open(args.source) as f:
        header = f.readline().strip().split(',')
    for name in ('episode', 'ax', 'ay', 'goal_dx', 'car11_dvy'):
        if name not in header:
            sys.exit(f'{args.source}: no column "{name}" (expected a Derby trajectories file)')
    data = np.loadtxt(args.source, delimiter=',', skiprows=1, dtype=np.float64, ndmin=2)
    if not np.isfinite(data).all():
        row = int(np.nonzero(~np.isfinite(data).all(axis=1))[0][0]) + 2
        sys.exit(f"{args.source}: line {row}: a non-finite value")
    episode = data[:, header.index('episode')]
    obs_cols = [c for c in header if c not in ('episode', 'step', 'ax', 'ay')]
    if len(obs_cols) != EGO_FEATURES + CARS * CAR_FEATURES:
        sys.exit(f'{args.source}: {len(obs_cols)} observation columns, expected '
                 f'{EGO_FEATURES + CARS * CAR_FEATURES}')
    obs = data[:, [header.index(c) for c in obs_cols]]
    act = data[:, [header.index('ax'), header.index('ay')]]
    rows, swapped, dropped = [], 0, 0
    pairs = np.nonzero(episode[1:] == episode[:-1])[0]
    for t in pairs:
        now = obs[t, EGO_FEATURES:].reshape(CARS, CAR_FEATURES)
        nxt = obs[t + 1, EGO_FEATURES:].reshape(CARS, CAR_FEATURES)
        guess = now[:, :2] + args.dt * now[:, 2:]
        cost = (np.linalg.norm(guess[:, None, :] - nxt[None, :, :2], axis=2)
                + 0.1 * np.linalg.norm(now[:, None, 2:] - nxt[None, :, 2:], axis=2))
        match = cost.argmin(axis=1)
        if len(set(match.tolist())) != CARS or cost[np.arange(CARS), match].max() > args.threshold:
            dropped += 1
            continue
        swapped += int((match != np.arange(CARS)).any())
        next_obs = obs[t + 1].copy()
        next_obs[EGO_FEATURES:] = nxt[match].reshape(-1)
        rows.append(np.concatenate([obs[t], act[t], next_obs]))
    if not rows:
        sys.exit(f'{args.source}: no transition kept (threshold {args.threshold})')
    columns = obs_cols + ['ax', 'ay'] + ['next_' + c for c in obs_cols]
    np.savetxt(args.out, np.array(rows), delimiter=',', header=','.join(columns), comments='',
               fmt='%.9g')
    print(f'{args.source}: {len(pairs)} transitions, kept {len(rows)} ({swapped} with slots '
          f're-ordered), dropped {dropped} (threshold {args.threshold})')


if __name__ == '__main__':
    main()
