"""Learning curves (the seeds' *_curve.csv), the barrier's training accuracy, and the
sensitivity / ablation variants."""
import math
import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from comparison import METHOD_LABELS, METHOD_ORDER, rate  # noqa: E402
from run_dir import read_curve, seed_dirs  # noqa: E402


CURVE_FILES = [("bc_curve.csv", "BC"), ("airl_curve.csv", "AIRL"), ("joint_curve.csv", "joint")]
# The columns drawn, when present (docs/FILE_FORMATS.md; the trainers' curve rows); a curve file
# with none of them has every numeric column drawn but counters and timings.
CURVE_COLUMNS = ["train_nll", "validation_nll", "action_mse", "discriminator_loss", "d_expert",
                 "d_policy", "mean_reward", "success_rate", "collision_rate", "cbf_loss"]
SKIPPED_COLUMNS = {"env_steps", "episodes", "seconds", "iteration", "epoch"}


def clip_first_epochs(ax, ys):
    """A loss that starts far above where it settles (BC's negative log-likelihood starts near
    100 and ends near -3) flattens the rest of the curve: zoom the y axis to the values after the
    first tenth of the curve, with a note, when the first tenth reaches more than twice as far."""
    rest = [y[len(y) // 10 + 1:] for y in ys if len(y) >= 10]
    rest = [r[np.isfinite(r)] for r in rest]
    rest = [r for r in rest if r.size]
    if not rest:
        return
    lo = min(float(r.min()) for r in rest)
    hi = max(float(r.max()) for r in rest)
    all_hi = max(float(np.nanmax(y)) for y in ys if np.isfinite(y).any())
    all_lo = min(float(np.nanmin(y)) for y in ys if np.isfinite(y).any())
    span = max(hi - lo, 1e-12)
    if (all_hi - all_lo) > 2.0 * span * 1.1:
        pad = 0.08 * span
        ax.set_ylim(lo - pad, hi + pad)
        ax.text(0.98, 0.95, "first epochs clipped", transform=ax.transAxes, ha="right",
                va="top", fontsize=8, color="0.4")


def check_curves(run_dir):
    """Reads every seed's curve CSVs (a ReportError on a malformed one) before the report
    writes anything."""
    for d in seed_dirs(run_dir):
        for file_name, _ in CURVE_FILES:
            if os.path.lexists(os.path.join(d, file_name)):
                read_curve(os.path.join(d, file_name))


def curves_figure(page, run_dir):
    seeds = seed_dirs(run_dir)
    panels = []  # (title, column, [(seed, x, y)])
    for file_name, label in CURVE_FILES:
        # A curve a seed does not have is skipped; one that is there must be well formed.
        per_seed = [(os.path.basename(d), read_curve(os.path.join(d, file_name)))
                    for d in seeds if os.path.lexists(os.path.join(d, file_name))]
        per_seed = [(s, c) for s, c in per_seed if c]
        if not per_seed:
            continue
        columns = list(per_seed[0][1].keys())
        xcol = columns[0]
        chosen = [c for c in CURVE_COLUMNS if c in columns]
        if not chosen:
            chosen = [c for c in columns[1:]
                      if c not in SKIPPED_COLUMNS and not c.endswith("seconds")]
        for col in chosen:
            lines = [(s, c[xcol], c[col]) for s, c in per_seed if col in c]
            if lines and any(np.isfinite(y).any() for _, _, y in lines):
                panels.append(("%s: %s" % (label, col), xcol, lines))
    if not panels:
        page.note("No learning curves: the run directory has no seed-<k>/bc_curve.csv, "
                  "airl_curve.csv or joint_curve.csv.")
        return
    panels = panels[:12]
    cols = min(3, len(panels))
    rows = (len(panels) + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(4.4 * cols, 3.1 * rows), squeeze=False)
    for ax, (title, xcol, lines) in zip(axes.flat, panels):
        for s, x, y in lines:
            ax.plot(x, y, linewidth=1, label=s)
        label, _, metric = title.partition(": ")
        ax.set_title(label, fontsize=10)
        ax.set_xlabel(xcol, fontsize=9)
        ax.set_ylabel(metric, fontsize=9)
        ax.tick_params(labelsize=9)
        ax.grid(alpha=0.3)
        clip_first_epochs(ax, [y for _, _, y in lines])
    for ax in list(axes.flat)[len(panels):]:
        ax.axis("off")
    handles, labels = axes.flat[0].get_legend_handles_labels()
    fig.legend(handles, labels, fontsize=9, loc="lower center", ncol=min(10, len(labels)),
               frameon=False)
    fig.tight_layout(rect=(0, 0.045 * (3 / rows) ** 0.5, 1, 1))
    page.figure(fig, "learning_curves", "Learning curves per seed, from the run's "
                "<code>seed-&lt;k&gt;/*_curve.csv</code> files (one line per seed).")


def accuracy_leaves(training):
    """{"train safe": 0.99, ...} from a barrier training summary: the per-class accuracies
    (train_accuracy / validation_accuracy: {safe, near_dangerous, balanced}; the per-obstacle
    trainer nests them under states and entries: the states' are taken)."""
    out = {}
    for key, value in training.items():
        if not key.endswith("_accuracy") or not isinstance(value, dict):
            continue
        if isinstance(value.get("states"), dict):
            value = value["states"]
        for cls in ("safe", "near_dangerous"):
            x = value.get(cls)
            if isinstance(x, (int, float)) and not isinstance(x, bool):
                out["%s %s" % (key[:-len("_accuracy")], cls)] = 100.0 * x
    return out


def barrier_training_figure(page, result):
    seeds = result["experiment"].get("seeds") or []
    data = {}  # variant -> metric -> [values over seeds]
    for s in seeds:
        for variant, rec in ((s or {}).get("barriers") or {}).items():
            for metric, v in accuracy_leaves((rec or {}).get("training") or {}).items():
                data.setdefault(variant, {}).setdefault(metric, []).append(v)
    if not data:
        page.note("No barrier training accuracies in result.json (experiment.seeds[k].barriers).")
        return
    variants = list(data)
    metrics = sorted({m for v in data.values() for m in v})
    # A dot per class and split with its spread over seeds, on an axis zoomed to the values
    # (accuracies sit near 100 %, where bars from 0 show nothing), the legend below the plot.
    fig, ax = plt.subplots(figsize=(7.0, 1.2 + 0.45 * len(variants) * len(metrics)))
    cmap = plt.get_cmap("tab10")
    lows = []
    for k, metric in enumerate(metrics):
        for i, v in enumerate(variants):
            vals = data[v].get(metric, [])
            if not vals:
                continue
            y = i * (len(metrics) + 1) + k
            mean, lo, hi = np.mean(vals), np.min(vals), np.max(vals)
            lows.append(lo)
            ax.plot([lo, hi], [y, y], color=cmap(k), linewidth=2, alpha=0.5)
            ax.plot([mean], [y], "o", color=cmap(k), markersize=6,
                    label=metric if i == 0 else None)
            ax.annotate("%.1f" % mean, (hi, y), xytext=(4, -3), textcoords="offset points",
                        fontsize=8)
    ax.set_yticks([i * (len(metrics) + 1) + (len(metrics) - 1) / 2 for i in range(len(variants))])
    ax.set_yticklabels(variants, fontsize=9)
    ax.invert_yaxis()
    left = max(0.0, min(lows) - 2.0) if lows else 0.0
    ax.set_xlim(left, 100.8)
    ax.set_xlabel("accuracy (%): mean (dot), min to max over seeds (line)", fontsize=9)
    ax.tick_params(labelsize=9)
    ax.grid(axis="x", alpha=0.3)
    handles, labels = ax.get_legend_handles_labels()
    fig.legend(handles, labels, fontsize=8, ncol=min(4, len(metrics)), loc="lower center",
               frameon=False)
    fig.tight_layout(rect=(0, 0.6 / fig.get_figheight(), 1, 1))
    page.figure(fig, "barrier_training", "The barrier's classification accuracy on its safe and "
                "near-dangerous states at the end of training, per barrier-data variant (the "
                "trainer records no per-epoch curve; <code>experiment.seeds[k].barriers"
                ".&lt;variant&gt;.training</code>): the mean over seeds as a dot, the range as a "
                "line, on an axis zoomed to the values.")


def variants_figure(page, result):
    variants = result.get("variants") or {}
    names = list(variants.keys())
    methods = sorted({m for v in variants.values() for m in (v.get("methods") or {})},
                     key=lambda m: METHOD_ORDER.index(m) if m in METHOD_ORDER else 99)
    fig, axes = plt.subplots(1, 2, figsize=(max(8.0, 1.2 * len(names) * max(1, len(methods))),
                                            4.2))
    width = 0.8 / max(1, len(methods))
    cmap = plt.get_cmap("tab10")
    for ax, metric, label in ((axes[0], "success_rate", "Success rate (%)"),
                              (axes[1], "dangerous_rate", "Dangerous rate (%)")):
        for k, m in enumerate(methods):
            means, stds = [], []
            for v in names:
                ms = variants[v].get("methods") or {}
                if m in ms:
                    mean, std, _ = rate(ms, m, metric)
                else:
                    mean, std = float("nan"), 0.0
                means.append(mean)
                stds.append(std)
            xs = np.arange(len(names)) + (k - (len(methods) - 1) / 2) * width
            ax.bar(xs, means, width, yerr=stds, capsize=3, color=cmap(k), edgecolor="black",
                   linewidth=0.5, label=METHOD_LABELS.get(m, m))
            for x, mean in zip(xs, means):
                if math.isfinite(mean):
                    ax.text(x, mean + 1.0, "%.0f" % mean, ha="center", va="bottom", fontsize=7)
        ax.set_xticks(np.arange(len(names)))
        ax.set_xticklabels(names, rotation=30, ha="right", fontsize=8)
        ax.set_ylabel(label)
        ax.set_ylim(0, 105)
        ax.grid(axis="y", alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    page.figure(fig, "sensitivity", "Sensitivity (Section 6.3): every barrier-data variant "
                "(reduced data, label imbalance, label noise), mean &plusmn; std over seeds.")
