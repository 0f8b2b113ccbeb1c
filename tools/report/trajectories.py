"""Trajectories: episodes of seed 0's AIRL policy without and with the shield over its barrier,
drawn from the domain's hints (hints.py; the schema is tools/report/README.md, "Report hints"),
and the run directory's videos.

`play_episodes` is the one episode loop (the evaluation stream's episodes, `Shield.decide` with
the run's shield options, or `Policy.sample`); it records each step's `decision.intervened` and
`info["collided"]`, which the figures mark. Two layouts: "overlay" (the demonstrations and the
episodes of each method overlaid in one panel each, fixed limits) and "grid" (a row per method,
a column per episode; limits that follow the paths)."""
import base64
import csv
import html
import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from hints import import_secure  # noqa: E402
from run_dir import ReportError, seed_dirs  # noqa: E402
from shapes import caption, shape_patch  # noqa: E402

INTERVENTION_COLOR = "#f77f00"  # orange: the shield changed the policy's action at this step
COLLISION_COLOR = "#d62828"


def seed0_players(secure, run_dir, result, domain):
    """The environment, seed 0's AIRL policy, a shield over its barrier (the run's shield
    options), a note on those options and the seed's evaluation stream; None if the first seed
    lacks airl.model or barrier.model."""
    exp = result["experiment"]
    seed_dir = (seed_dirs(run_dir) or [None])[0]
    if seed_dir is None or not os.path.isfile(os.path.join(seed_dir, "airl.model")) or \
            not os.path.isfile(os.path.join(seed_dir, "barrier.model")):
        return None
    opts = exp.get("domain_options") or {}
    task = opts.get("task") if isinstance(opts, dict) else None
    env = secure.make_env(domain, **({"task": task} if task else {}))
    policy = secure.Policy.load(os.path.join(seed_dir, "airl.model"))
    barrier = secure.Barrier.load(os.path.join(seed_dir, "barrier.model"))
    try:
        shield = secure.Shield(barrier, env.dynamics, **((exp.get("options") or {}).get("shield")
                                                          or {}))
        shield_note = "the run's shield options"
    except ValueError as e:
        shield = secure.Shield(barrier, env.dynamics)
        shield_note = "the default shield options (the run's were not accepted: %s)" % e
    first_seed = int((exp.get("options") or {}).get("first_seed", 0))
    eval_seed = first_seed ^ 0x5EC07E5EED5  # eval::EvaluationSeed
    return env, policy, shield, shield_note, eval_seed, task or {}


def play_episodes(secure, env, policy, shield, eval_seed, episodes):
    """Episodes 0..episodes-1 of the seed's evaluation stream, with the shield if `shield` is not
    None (else the policy's own samples). Each: obs (T+1, obs_dim), intervened (T,) and
    collided (T,) per step (the decision at obs[t]; contact after step t), reached (bool)."""
    out = []
    for i in range(episodes):
        obs, _ = env.reset(seed=secure.episode_seed(eval_seed, i))
        if shield is not None:
            shield.seed(env.rng.next_u64())
        seen, intervened, collided, reached = [obs.copy()], [], [], False
        for _ in range(env.max_steps):
            if shield is not None:
                shield.set_backup_action(env.backup_action(obs))
                decision = shield.decide(obs, policy.mean(obs), policy.sigma)
                action = decision.action
                intervened.append(bool(decision.intervened))
            else:
                action = policy.sample(obs, env.rng)
                intervened.append(False)
            obs, _, _, _, info = env.step(action)
            seen.append(obs.copy())
            collided.append(bool(info["collided"]))
            if info["reached_goal"]:
                reached = True
                break
        out.append({"obs": np.array(seen), "intervened": np.array(intervened, dtype=bool),
                    "collided": np.array(collided, dtype=bool), "reached": reached})
    return out


def outcome(ep):
    return "dangerous" if ep["collided"].any() else ("success" if ep["reached"] else "timeout")


def outcome_color(ep):
    return {"dangerous": COLLISION_COLOR, "success": "#2a9d8f", "timeout": "#457b9d"}[outcome(ep)]


def panel_title(name, eps):
    kinds = [outcome(ep) for ep in eps]
    title = "%s: %d success, %d dangerous of %d" % (name, kinds.count("success"),
                                                    kinds.count("dangerous"), len(eps))
    return title


VIDEO_CAP_BYTES = 20 * 1000 * 1000


def videos_section(page, run_dir, out_path):
    """Every RUN_DIR/*.mp4 (e.g. `secure render ... --out RUN_DIR/x.mp4`) as an HTML5 video,
    embedded as a base64 data URI up to VIDEO_CAP_BYTES; a larger one is linked relatively."""
    names = sorted(n for n in os.listdir(run_dir) if n.lower().endswith(".mp4") and
                   os.path.isfile(os.path.join(run_dir, n)))
    if not names:
        page.p("No videos: the run directory holds no <code>*.mp4</code> (<code>secure render "
               "... --out RUN_DIR/NAME.mp4</code> writes one; the report embeds it).", "note")
        return
    page.p("Videos: the run directory's <code>*.mp4</code> files.")
    for name in names:
        path = os.path.join(run_dir, name)
        size = os.path.getsize(path)
        if size > VIDEO_CAP_BYTES:
            rel = os.path.relpath(path, os.path.dirname(os.path.abspath(out_path)))
            page.raw('<figure class="video"><p class="note">%s is %.1f MB, over the %d MB '
                     'embedding cap: not embedded; <a href="%s">open the file</a> (a link '
                     'relative to this page).</p><figcaption>%s</figcaption></figure>'
                     % (html.escape(name), size / 1e6, VIDEO_CAP_BYTES // 1000000,
                        html.escape(rel), html.escape(name)))
            continue
        with open(path, "rb") as f:
            data = base64.b64encode(f.read()).decode("ascii")
        page.raw('<figure class="video"><video controls preload="metadata" '
                 'src="data:video/mp4;base64,%s"></video><figcaption>%s</figcaption></figure>'
                 % (data, html.escape(name)))


def positions(hint, feats):
    """A function obs (T+1, d) -> (positions (T+1, 2), goal or None) from the `position` hint:
    two features {x, y}, or {goal_offset: [dx, dy]} for an ego-relative observation (goal - p):
    the path is goal(0) - goal(t) from the start placed at (0, 0), the goal at goal(0)."""
    pos = hint.sub("position")
    if pos is None:
        raise ReportError("%s: '%s' is missing" % (hint.source, hint.path("position")))
    if pos.has("goal_offset"):
        names = pos.get("goal_offset", list)
        ig = [feats.index(n) for n in names]

        def relative(obs):
            goal = obs[0, ig]
            return goal - obs[:, ig], goal
        return relative
    ix, iy = feats.index(pos.get("x", str)), feats.index(pos.get("y", str))
    return lambda obs: (obs[:, [ix, iy]], None)


def observed_others(hint, feats):
    """[(dx column, dy column)] of the objects observed relative to the ego (`others`: patterns
    with {i}, counted from 0 while both features exist)."""
    others = hint.sub("others")
    if others is None:
        return []
    dx, dy = others.get("dx", str), others.get("dy", str)
    out, k = [], 0
    while dx.replace("{i}", str(k)) in feats and dy.replace("{i}", str(k)) in feats:
        out.append((feats.index(dx.replace("{i}", str(k))), feats.index(dy.replace("{i}", str(k)))))
        k += 1
    return out


def read_demos(demos, run_dir):
    """The first `max` (+1) demonstrations' (x, y) paths of the `demos` hint's CSV, or []."""
    path = os.path.join(run_dir, demos.get("file", str))
    if not os.path.isfile(path):
        return []
    x, y, most = demos.get("x", str), demos.get("y", str), demos.get("max", int, 20)
    paths = {}
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            if len(paths) > most and row["episode"] not in paths:
                break
            paths.setdefault(row["episode"], []).append((float(row[x]), float(row[y])))
    return [np.array(p) for p in paths.values()]


def overlay_figure(page, secure, players, run_dir, hint):
    """The demonstrations (if hinted) and the episodes of AIRL and SECURE, each method's
    overlaid in one panel, with the world's shapes and the goal."""
    env, policy, shield, shield_note, eval_seed, _ = players
    where = positions(hint, list(env.observation_features))
    episodes = hint.get("episodes", int, 5)
    demos = hint.sub("demos")
    panels = 3 if demos is not None else 2
    fig, axes = plt.subplots(1, panels, figsize=(4.5 * panels, 4.6))
    if demos is not None:
        for xy in read_demos(demos, run_dir):
            axes[0].plot(xy[:, 0], xy[:, 1], color="#555555", linewidth=0.8, alpha=0.7)
        axes[0].set_title("expert demonstrations (first %d)" % demos.get("max", int, 20),
                          fontsize=10)
    for ax, name, shielded in ((axes[-2], "AIRL", False),
                               (axes[-1], "SECURE (AIRL + shield)", True)):
        eps = play_episodes(secure, env, policy, shield if shielded else None, eval_seed,
                            episodes)
        for ep in eps:
            xy = where(ep["obs"])[0]
            color = outcome_color(ep)
            ax.plot(xy[:, 0], xy[:, 1], color=color, linewidth=1.2)
            ax.plot(xy[0, 0], xy[0, 1], marker="o", color=color, markersize=3)
            at = xy[:-1][ep["intervened"]]
            ax.scatter(at[:, 0], at[:, 1], s=9, color=INTERVENTION_COLOR, zorder=3)
        title = panel_title(name, eps)
        if shielded:
            title += "\n%d shield interventions (orange)" % sum(int(ep["intervened"].sum())
                                                                for ep in eps)
        ax.set_title(title, fontsize=10)
    goal = hint.sub("goal")
    limits = hint.numbers("limits", 2, None)
    labels = hint.get("labels", list, ["x", "y"])
    for ax in axes:
        for shape in hint.items("shapes"):
            ax.add_patch(shape_patch(shape))
        if goal is not None:
            at = goal.numbers("at", 2)
            ax.plot(at[0], at[1], marker="*", color="black", markersize=10)
        if limits is not None:
            ax.set_xlim(*limits)
            ax.set_ylim(*limits)
        ax.set_aspect("equal")
        ax.set_xlabel(labels[0])
        ax.set_ylabel(labels[1])
    fig.tight_layout()
    page.figure(fig, "trajectories", caption(hint, {"shield_note": shield_note,
                                                    "last_episode": episodes - 1}))


def grid_limits(hint):
    """(fixed [lo, hi] or None, at_least [lo, hi], at_most [lo, hi]) of the `limits` hint."""
    if isinstance(hint.value.get("limits"), list):
        return hint.numbers("limits", 2), None, None
    lim = hint.sub("limits")
    if lim is None:
        return None, [np.inf, -np.inf], [-np.inf, np.inf]
    return None, lim.numbers("at_least", 2), lim.numbers("at_most", 2, [-np.inf, np.inf])


def grid_figure(page, secure, players, run_dir, hint):
    """A row per method (AIRL, SECURE), a column per episode: the path, the observed objects'
    positions faint, contacts (crosses, circles of `contact_radius`) and interventions marked."""
    env, policy, shield, shield_note, eval_seed, _ = players
    feats = list(env.observation_features)
    where = positions(hint, feats)
    others = observed_others(hint, feats)
    goal_hint = hint.sub("goal")
    goal_radius = goal_hint.get("radius", float, 0.0) if goal_hint is not None else 0.0
    contact_radius = hint.get("contact_radius", float, 0.0)
    labels = hint.get("labels", list, ["x", "y"])
    fixed, (lo, hi), at_most = grid_limits(hint)
    episodes = hint.get("episodes", int, 3)
    rows = (("AIRL", None), ("SECURE (AIRL + shield)", shield))
    fig, axes = plt.subplots(len(rows), episodes, figsize=(4.0 * episodes + 0.5, 8.2),
                             squeeze=False)
    for r, (name, sh) in enumerate(rows):
        eps = play_episodes(secure, env, policy, sh, eval_seed, episodes)
        for c, ep in enumerate(eps):
            ax = axes[r][c]
            obs = ep["obs"]
            p, goal = where(obs)
            for jx, jy in others:
                ax.scatter(p[:, 0] + obs[:, jx], p[:, 1] + obs[:, jy], s=2, color="#888888",
                           alpha=0.35, linewidths=0, zorder=1)
            for shape in hint.items("shapes"):
                ax.add_patch(shape_patch(shape))
            if goal is None and goal_hint is not None and goal_hint.get("at", (str, list)) != \
                    "observed":
                goal = goal_hint.numbers("at", 2)
            if goal is not None:
                if goal_radius > 0:
                    ax.add_patch(plt.Circle(goal, goal_radius, color="black", fill=False,
                                            linewidth=0.8))
                ax.plot(goal[0], goal[1], marker="*", color="black", markersize=9, zorder=4)
            color = outcome_color(ep)
            ax.plot(p[:, 0], p[:, 1], color=color, linewidth=1.4, zorder=2)
            ax.plot(p[0, 0], p[0, 1], marker="o", color=color, markersize=4, zorder=3)
            at = p[:-1][ep["intervened"]]
            ax.scatter(at[:, 0], at[:, 1], s=12, color=INTERVENTION_COLOR, zorder=3)
            hit = p[1:][ep["collided"]]
            for x, y in hit:
                if contact_radius > 0:
                    ax.add_patch(plt.Circle((x, y), contact_radius, fill=False,
                                            color=COLLISION_COLOR, linewidth=0.8, zorder=4))
            ax.scatter(hit[:, 0], hit[:, 1], s=22, marker="x", color=COLLISION_COLOR,
                       zorder=5)
            title = "%s, episode %d: %s" % (name.split(" ")[0], c, outcome(ep))
            if sh is not None:
                title += ", %d interventions" % int(ep["intervened"].sum())
            ax.set_title(title, fontsize=9)
            if fixed is None:
                lo = min(lo, float(p.min()) - 0.05)
                hi = max(hi, float(p.max()) + 0.05)
            if c == 0:
                ax.set_ylabel("%s\n%s" % (panel_title(name, eps), labels[1]), fontsize=9)
            if r == len(rows) - 1:
                ax.set_xlabel(labels[0])
    lo, hi = fixed if fixed is not None else (max(lo, at_most[0]), min(hi, at_most[1]))
    for ax in axes.ravel():
        ax.set_xlim(lo, hi)
        ax.set_ylim(lo, hi)
        ax.set_aspect("equal")
    fig.tight_layout()
    page.figure(fig, "trajectories", caption(hint, {
        "shield_note": shield_note, "last_episode": episodes - 1, "others": len(others)}))


LAYOUTS = {"overlay": overlay_figure, "grid": grid_figure}


def trajectories_section(page, run_dir, result, out_path, hints, why_none):
    """Section 5: the trajectories from `hints` (a Hint or None, with `why_none`), then the
    run directory's videos."""
    domain = result["experiment"].get("domain", "")
    hint = hints.sub("trajectories") if hints is not None else None
    if hint is None:
        page.note("No trajectories for the %s domain: %s; the run directory records no "
                  "evaluation trajectories (\"secure render\" plays an episode of a domain "
                  "with a renderer)." % (domain, why_none or "no picture hints (its "
                                         "ReportHints has no trajectory picture)"))
    else:
        secure, why = import_secure()
        if secure is None:
            page.note("No trajectories: %s." % why)
        else:
            try:
                layout = hint.get("layout", str)
                if layout not in LAYOUTS:
                    raise ReportError("%s: '%s' = \"%s\", must be overlay or grid"
                                      % (hint.source, hint.path("layout"), layout))
                players = seed0_players(secure, run_dir, result, domain)
                if players is None:
                    page.note("No trajectories: the run's first seed has no airl.model and "
                              "barrier.model.")
                else:
                    LAYOUTS[layout](page, secure, players, run_dir, hint)
            except Exception as e:
                page.note("No trajectories: %s: %s" % (type(e).__name__, e))
    videos_section(page, run_dir, out_path)
