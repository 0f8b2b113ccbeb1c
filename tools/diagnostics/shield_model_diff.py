#!/usr/bin/env python3
"""Two shield models on the same policy, barrier and episodes: where they disagree, and what it costs.

A learned model (`secure dynamics train`) replaces a domain's hand-written one; when the shield
then does worse, this says where. For one seed of a finished run directory (its barrier.model and
a policy), the shield is run with each model in turn ("drive"), on the same episodes (the same
episode seeds and shield seeds). At every decision the other model's shield is asked too, on the
same state, mean and sigma. Written per episode: the outcome, steps, interventions, decisions
without a safe action, the safe ratio of both shields, the distance to the goal where the domain's
observation starts with the goal offset. Printed: the episodes each drive loses and the other
wins, and, over the decisions of the first --g-episodes episodes, how often an action is unsafe
under one model and safe under the other, by |a| (the sign of the exact g(a) of each shield on a
fixed uniform draw of actions in the actuator box).

Usage:
  shield_model_diff.py --domain derby --run RUN --seed 0 --model dyn.model [--hold 3]
      [--pessimism min|mean-std --pessimism-kappa K] [--policy airl.model] [--config C.yaml]
      [--episodes 100] [--g-episodes 40] [--stream-seed 10000] [--out records.json]
The shield's options are the domain's preset, with the config file's `shield:` over it
(secure.read_config_section), the episode stream that of tools/diagnostics/shield_directions.py.
Needs the `secure` Python module (PYTHONPATH=build/python).
docs/RESULTS.md, issue 36 (Derby): the measurement this was written for.
"""
import argparse
import json
import os
import sys

import numpy as np

import secure
from diagnostics_common import read_section


def drive(env, policy_mean, sigma, shields, first, other, episodes, seed, max_steps=None,
          stream_seed=0):
    """Episodes under shields[first], asking shields[other] at every decision. The episode and the
    shields' seeds depend only on (seed, episode), so two drives see the same episodes: episode e
    starts from secure.episode_seed(stream_seed + seed, e)."""
    records = []
    for e in range(episodes):
        for name in (first, other):
            shields[name].seed(1000 * seed + e)
        obs, _ = env.reset(seed=secure.episode_seed(stream_seed + seed, e))
        rec = {"drive": first, "episode": e, "steps": 0, "success": False, "dangerous": False,
               "interventions": 0, "no_safe_action": 0, "other_no_safe_action": 0,
               "ratio": [], "other_ratio": []}
        for t in range(max_steps or env.max_steps):
            mu = policy_mean(obs)
            d = shields[first].decide(obs, mu, sigma)
            o = shields[other].decide(obs, mu, sigma)
            rec["interventions"] += int(d.intervened)
            rec["no_safe_action"] += int(d.status == "no_safe_action")
            rec["other_no_safe_action"] += int(o.status == "no_safe_action")
            rec["ratio"].append(float(d.safe_ratio))
            rec["other_ratio"].append(float(o.safe_ratio))
            obs, _, _, _, info = env.step(d.action)
            rec["steps"] = t + 1
            rec["dangerous"] |= bool(info["collided"])
            if info["reached_goal"]:
                rec["success"] = True
                break
        records.append(rec)
    return records


def g_disagreement(shield_a, shield_b, states, actions, bins, chunk=32):
    """Per |a| bin: [unsafe under a only, unsafe under b only, actions] summed over the states.
    chunk: the shields' batch (evaluate_g takes at most max(num_samples, num_probes) actions)."""
    mag = np.linalg.norm(actions, axis=1)
    which = np.digitize(mag, bins) - 1
    counts = np.zeros((3, len(bins) - 1), dtype=np.int64)

    def g(shield, s):
        return np.concatenate([np.asarray(shield.evaluate_g(s, actions[i:i + chunk]))
                               for i in range(0, len(actions), chunk)])

    for s in states:
        ga, gb = g(shield_a, s), g(shield_b, s)
        for b in range(len(bins) - 1):
            sel = which == b
            counts[0, b] += np.sum((ga < 0) & (gb >= 0) & sel)
            counts[1, b] += np.sum((gb < 0) & (ga >= 0) & sel)
            counts[2, b] += np.sum(sel)
    return counts


def paired(records):
    """(successes of each drive, episodes lost only by each drive) from both drives' records."""
    by = {}
    for r in records:
        by.setdefault(r["drive"], {})[r["episode"]] = r
    a, b = list(by)
    common = sorted(set(by[a]) & set(by[b]))
    lost_a = [e for e in common if by[b][e]["success"] and not by[a][e]["success"]]
    lost_b = [e for e in common if by[a][e]["success"] and not by[b][e]["success"]]
    return {a: sum(by[a][e]["success"] for e in common), b: sum(by[b][e]["success"] for e in common),
            f"lost only by {a}": lost_a, f"lost only by {b}": lost_b}


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--domain", required=True)
    p.add_argument("--run", required=True)
    p.add_argument("--seed", type=int, required=True)
    p.add_argument("--model", required=True, help="a learned dynamics model file")
    p.add_argument("--hold", type=int, default=1)
    p.add_argument("--pessimism", default="min")
    p.add_argument("--pessimism-kappa", type=float, default=1.0)
    p.add_argument("--policy", default="airl.model", help="file in the seed's directory")
    p.add_argument("--config")
    p.add_argument("--episodes", type=int, default=100)
    p.add_argument("--g-episodes", type=int, default=40)
    p.add_argument("--actions", type=int, default=1024, help="uniform actions for the g check")
    p.add_argument("--stream-seed", type=int, default=10_000,
                   help="episode e of seed S starts from secure.episode_seed(stream_seed + S, e)")
    p.add_argument("--out")
    args = p.parse_args()
    for flag in ("episodes", "g_episodes", "actions", "hold"):
        if getattr(args, flag) < 1:
            sys.exit(f"shield_model_diff: --{flag.replace('_', '-')} = {getattr(args, flag)}, "
                     "must be at least 1")
    seed_dir = os.path.join(args.run, f"seed-{args.seed}")
    for f in ("barrier.model", args.policy):
        if not os.path.isfile(os.path.join(seed_dir, f)):
            sys.exit(f"{os.path.join(seed_dir, f)}: not a regular file")
    section = read_section(args.domain, args.config)
    env = secure.EnvCore(args.domain, options=section["domain"])
    barrier = secure.Barrier.load(os.path.join(seed_dir, "barrier.model"))
    policy = secure.Policy.load(os.path.join(seed_dir, args.policy))
    lo, hi = env.action_bounds
    options = dict(section["experiment"]["shield"], action_low=lo, action_high=hi)
    learned = secure.Dynamics.learned(args.model, hold=args.hold, pessimism=args.pessimism,
                                      pessimism_kappa=args.pessimism_kappa)
    shields = {"hand-written": secure.Shield(barrier, env.dynamics, **options),
               "learned": secure.Shield(barrier, learned, **options)}
    sigma = np.asarray(policy.sigma, dtype=np.float32)
    records = []
    for first, other in (("hand-written", "learned"), ("learned", "hand-written")):
        records += drive(env, policy.mean, sigma, shields, first, other, args.episodes, args.seed,
                         stream_seed=args.stream_seed)
    summary = paired(records)
    for name in ("hand-written", "learned"):
        mine = [r for r in records if r["drive"] == name]
        ratio, other_ratio = (np.concatenate([r[k] for r in mine]) for k in ("ratio", "other_ratio"))
        either = (ratio < 1) | (other_ratio < 1)
        summary[f"{name} drive"] = {
            "interventions per episode": float(np.mean([r["interventions"] for r in mine])),
            "dangerous episodes": int(sum(r["dangerous"] for r in mine)),
            "mean safe ratio where either intervenes (this, other)":
                [float(ratio[either].mean()), float(other_ratio[either].mean())]
                if either.any() else None}
    # The g check over states of the learned drive's first episodes (replayed).
    rng = np.random.default_rng(args.seed)
    actions = rng.uniform(lo, hi, size=(args.actions, len(lo))).astype(np.float32)
    top = float(np.linalg.norm(np.maximum(np.abs(lo), np.abs(hi))))
    bins = [0.0] + [top * f for f in (0.125, 0.25, 0.375, 0.5, 0.75)] + [top * 1.0001]
    states = []
    for e in range(min(args.g_episodes, args.episodes)):
        shields["learned"].seed(1000 * args.seed + e)
        obs, _ = env.reset(seed=secure.episode_seed(args.stream_seed + args.seed, e))
        for _ in range(env.max_steps):
            states.append(obs.copy())
            d = shields["learned"].decide(obs, policy.mean(obs), sigma)
            obs, _, _, _, info = env.step(d.action)
            if info["reached_goal"]:
                break
    counts = g_disagreement(shields["learned"], shields["hand-written"], states[::2], actions, bins)
    summary["g sign by |a|"] = {
        "bins": bins, "states": len(states[::2]),
        "unsafe only under learned %": list(100.0 * counts[0] / np.maximum(counts[2], 1)),
        "unsafe only under hand-written %": list(100.0 * counts[1] / np.maximum(counts[2], 1))}
    print(json.dumps(summary, indent=1))
    if args.out:
        with open(args.out, "w") as f:
            json.dump({"summary": summary, "records": records}, f)


if __name__ == "__main__":
    main()
