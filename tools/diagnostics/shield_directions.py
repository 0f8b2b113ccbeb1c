#!/usr/bin/env python3
"""Why does a gradient filter (CBF-QP) let episodes in where SECURE's sampling shield does not?

Runs episodes of a run's AIRL policy under one shield (--follow qp: the gradient-first shield,
proposal 'qp'; --follow secure: the sampling shield), and at every decision asks BOTH shields for
an action at the same state. Where the policy's mean fails the check (g(mu) < 0) it records:
  - the angle between the two corrections (a_qp - mu) and (a_secure - mu): does the barrier's
    gradient point where the sampling shield goes?
  - their sizes (also per action axis), g at each action, and the QP's status (accepted /
    rejected by the exact g / infeasible);
  - for the action taken, h at the true next state against h at the shield model's prediction:
    is the shield model wrong in the states that this shield visits?

    PYTHONPATH=build/python python3 tools/diagnostics/shield_directions.py \\
        --domain panda-push --run RUN --seeds 5,6,7,8,9 --episodes 40 --follow qp
    (then --follow secure) prints one line per seed and a summary; --out F.json keeps every
    decision. The shield options are the domain's preset (or --config FILE's section, e.g.
    `panda_push: {shield: {qp_metric: policy}}` for the projection in the policy's metric), as
    `secure experiment` uses them; RUN is a `secure experiment method-comparison` directory
    (seed-K/barrier.model, seed-K/airl.model). docs/RESULTS.md (issue 37) quotes a Panda run.
"""
import argparse
import json
import math
import os
import statistics
import sys

import numpy as np

import secure
from diagnostics_common import read_section


def quantile(xs, p):
    xs = sorted(xs)
    return xs[min(len(xs) - 1, int(p * len(xs)))] if xs else float("nan")


def run_seed(args, shield_options, seed):
    barrier = secure.Barrier.load(os.path.join(args.run, f"seed-{seed}", "barrier.model"))
    policy = secure.Policy.load(os.path.join(args.run, f"seed-{seed}", "airl.model"))
    env = secure.EnvCore(args.domain)
    dynamics = env.dynamics
    options = dict(shield_options, seed=seed)
    sampling = secure.Shield(barrier, dynamics, **options)
    gradient = secure.Shield(barrier, dynamics, **dict(options, proposal="qp"))
    sigma = np.asarray(policy.sigma, dtype=np.float32)
    columns = [env.observation_features.index(f) for f in barrier.features]

    def h(state):
        return float(barrier.h(np.asarray(state, dtype=np.float32)[columns][None, :])[0])

    rows = []
    for episode in range(args.episodes):
        obs, _ = env.reset(seed=secure.episode_seed(args.stream_seed + seed, episode))
        for step in range(env.max_steps):
            mu = policy.mean(obs)
            g_mu = float(sampling.evaluate_g(obs, mu[None, :])[0])
            by_qp = gradient.decide(obs, mu, sigma)
            by_sampling = sampling.decide(obs, mu, sigma)
            action = by_qp.action if args.follow == "qp" else by_sampling.action
            h_predicted = h(dynamics.step(obs, action[None, :])[0])
            obs, _, terminated, truncated, info = env.step(action)
            c_qp, c_s = by_qp.action - mu, by_sampling.action - mu
            n_qp, n_s = float(np.linalg.norm(c_qp)), float(np.linalg.norm(c_s))
            rows.append(dict(
                seed=seed, episode=episode, step=step, g_mu=g_mu, qp=by_qp.qp,
                correction_qp=n_qp, correction_secure=n_s, g_qp=float(by_qp.g),
                g_secure=float(by_sampling.g),
                axes_qp=[float(x) for x in np.abs(c_qp)], axes_secure=[float(x) for x in np.abs(c_s)],
                cos=float(c_qp @ c_s / (n_qp * n_s)) if min(n_qp, n_s) > 1e-9 else float("nan"),
                h_true=h(obs), h_predicted=h_predicted, collided=bool(info.get("collided", False))))
            if terminated or truncated:
                break
    return rows


def summarise(rows, label):
    intervened = [r for r in rows if r["g_mu"] < 0]
    episodes = {(r["seed"], r["episode"]) for r in rows}
    dangerous = {(r["seed"], r["episode"]) for r in rows if r["collided"]}
    cos = [r["cos"] for r in intervened if not math.isnan(r["cos"])]
    miss = sum(r["h_predicted"] >= 0 > r["h_true"] for r in intervened)
    error = [r["h_true"] - r["h_predicted"] for r in intervened]
    med = lambda key: statistics.median(r[key] for r in intervened) if intervened else float("nan")
    qp = {s: sum(r["qp"] == s for r in intervened) for s in sorted({r["qp"] for r in intervened})}
    print(f"{label}: {len(episodes)} episodes, {len(dangerous)} dangerous; {len(intervened)} "
          f"decisions with g(mu) < 0: cos(QP, SECURE correction) median {quantile(cos, .5):+.2f}, "
          f"p10 {quantile(cos, .1):+.2f}, share < 0 {sum(c < 0 for c in cos) / max(1, len(cos)):.2f}; "
          f"|a - mu| QP {med('correction_qp'):.3f}, SECURE {med('correction_secure'):.3f}; "
          f"g at the action QP {med('g_qp'):+.2f}, SECURE {med('g_secure'):+.2f}; "
          f"h(true next) - h(predicted) median {quantile(error, .5):+.4f}, p10 {quantile(error, .1):+.4f}; "
          f"predicted h >= 0 but true h < 0: {miss} ({miss / max(1, len(intervened)):.1%}); QP {qp}")
    if intervened:
        # Per action axis: where each shield moves the action (the QP's metric decides this).
        axes = lambda key: " ".join(
            f"{statistics.median(r[key][i] for r in intervened):.3f}"
            for i in range(len(intervened[0][key])))
        print(f"  |a - mu| per axis (medians): QP {axes('axes_qp')}; SECURE {axes('axes_secure')}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--domain", required=True)
    ap.add_argument("--run", required=True, help="a method-comparison run directory")
    ap.add_argument("--seeds", required=True, help="comma-separated training seeds of the run")
    ap.add_argument("--episodes", type=int, default=40)
    ap.add_argument("--follow", choices=["qp", "secure"], default="qp",
                    help="whose action the episode takes (both are asked at every decision)")
    ap.add_argument("--config", help="a config file whose domain section sets the shield")
    ap.add_argument("--stream-seed", type=int, default=10_000,
                    help="episode starts: secure.episode_seed(stream_seed + seed, episode)")
    ap.add_argument("--out", help="write every decision's record here (JSON)")
    args = ap.parse_args()
    if args.episodes < 1:
        ap.error(f"--episodes = {args.episodes}, must be at least 1")
    try:
        seeds = [int(s) for s in args.seeds.split(",")]
    except ValueError:
        ap.error(f"--seeds = '{args.seeds}', expected comma-separated integers")
    section = read_section(args.domain, args.config)
    shield_options = {k: v for k, v in section["experiment"]["shield"].items() if k != "seed"}
    rows = []
    for seed in seeds:
        seed_rows = run_seed(args, shield_options, seed)
        summarise(seed_rows, f"seed {seed} (following {args.follow})")
        rows += seed_rows
    summarise(rows, f"all seeds (following {args.follow})")
    if args.out:
        with open(args.out, "w") as f:
            json.dump(rows, f)


if __name__ == "__main__":
    try:
        main()
    except (ValueError, FileNotFoundError, RuntimeError) as e:
        sys.exit(f"shield_directions: error: {e}")
