#!/usr/bin/python3
"""secure report RUN_DIR: one self-contained HTML page for a run directory.

A run directory is what `secure demo --out DIR` and `secure experiment KIND --domain D --out DIR`
write (docs/FILE_FORMATS.md, "Experiment output"): result.json, seed-<k>/ with the models and the
learning-curve CSVs, the data CSVs. The page embeds every figure as base64 PNG (one file, no
external references); the same figures are also written as PNG files into <page>_figures/.

Usage:  /usr/bin/python3 tools/report/report.py RUN_DIR [--out FILE.html]
        (`secure report RUN_DIR` runs this script; tools/report/README.md)

Figures: the method comparison (Figure 9 style: mean +- std over seeds, the run's significance
marks) beside the paper's Table 3, learning curves, sensitivity / ablation variants, and the
learned barriers and trajectories of AIRL and SECURE with the shield's interventions marked
(double integrator, Derby; through the Python module `secure`, if importable; else a note in
the page), and the run directory's *.mp4 videos (embedded as base64 up to 20 MB each).
Matplotlib with the Agg backend (no display). Errors: one line `secure report: error: ...`
naming the file, exit 1.
"""
import argparse
import base64
import csv
import html
import io
import json
import math
import os
import re
import stat
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


class ReportError(Exception):
    pass


# Paper Table 3 (SECURE paper, Section 6.1, "Table 3: ... comparison of SECURE (ours) with BC and
# AIRL in three domains"; mean (std) over ten seeds, 100 episodes), by our domain names.
PAPER_TABLE3 = {
    "derby": {
        "title": "Demolition Derby",
        "bc": ((17.9, 3.6), (65.7, 4.1)),
        "airl": ((46.8, 4.7), (75.4, 4.9)),
        "secure": ((49.2, 5.6), (4.2, 1.2)),
        "tests": ("success +2.4% (TOST p < .01 with bound=10); "
                  "dangerous -71.2% (Mann-Whitney U = 0, p < .001)"),
    },
    "panda-push": {
        "title": "Panda Arm Push",
        "bc": ((22.7, 3.2), (72.3, 3.5)),
        "airl": ((52.9, 22.6), (31.3, 17.9)),
        "secure": ((96.6, 5.3), (0.0, 0.0)),
        "tests": ("success +43.7% (Mann-Whitney U = 99.5, p < .001); "
                  "dangerous -31.3% (Mann-Whitney U = 0, p < .001)"),
    },
    # Section 7.1 (the real robot, 10 episodes, one run: no standard deviation).
    "kitchen-cutting": {
        "title": "Kitchen Cutting",
        "protocol": "the real robot (Section 7.1), one run of 10 episodes",
        "bc": ((70.0, None), (100.0, None)),
        "airl": ((80.0, None), (100.0, None)),
        "secure": ((90.0, None), (0.0, None)),
        "tests": "success +10%; dangerous -100% (10 episodes, no test)",
    },
}

METHOD_LABELS = {
    "bc": "BC", "airl": "AIRL", "secure": "SECURE", "secure-random-safe": "random safe",
    "secure-no-resampling": "no resampling", "bc+shield": "BC + shield",
    "secure-myopic": "myopic", "joint": "joint", "cbf-qp": "CBF-QP",
    "secure-qp": "gradient-first",
}
METHOD_ORDER = ["bc", "airl", "secure", "secure-random-safe", "secure-no-resampling",
                "secure-myopic", "bc+shield", "joint", "cbf-qp", "secure-qp"]
SUCCESS_COLOR, DANGER_COLOR = "#2a9d8f", "#e76f51"


def stars(p):
    if p is None or not isinstance(p, (int, float)) or not math.isfinite(p):
        return None
    if p < 0.001:
        return "***"
    if p < 0.01:
        return "**"
    if p < 0.05:
        return "*"
    return "n.s."


def num(v):
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return "n/a"
    return "%.3g" % v


def fmt_p(p):
    if p is None or not isinstance(p, (int, float)) or not math.isfinite(p):
        return "n/a"
    return "< .001" if p < 0.001 else "= %.3f" % p


# ---------------------------------------------------------------------------------------------
# Reading the run directory


def load_run(run_dir):
    if not os.path.exists(run_dir):
        raise ReportError("%s: no such directory" % run_dir)
    if not os.path.isdir(run_dir):
        raise ReportError("%s: not a directory (expected a run directory written by "
                          "`secure demo --out` or `secure experiment --out`)" % run_dir)
    path = os.path.join(run_dir, "result.json")
    if not os.path.isfile(path):
        raise ReportError("%s: missing: %s is not a run directory (written by `secure demo "
                          "--out` or `secure experiment --out`)" % (path, run_dir))
    try:
        with open(path, "rb") as f:
            result = json.loads(f.read().decode("utf-8"))
    except (UnicodeDecodeError, ValueError) as e:
        raise ReportError("%s: malformed JSON: %s" % (path, e))
    except OSError as e:
        raise ReportError("%s: cannot read: %s" % (path, e.strerror))
    if not isinstance(result, dict) or not isinstance(result.get("experiment"), dict):
        raise ReportError("%s: no object 'experiment': not the result of `secure demo` or "
                          "`secure experiment`" % path)
    if not isinstance(result.get("methods"), dict) and not isinstance(result.get("variants"),
                                                                       dict):
        raise ReportError("%s: neither 'methods' nor 'variants': no evaluation to report" % path)
    # The numbers the page shows, checked (issue 34: an empty 'methods', rates given as strings
    # or outside [0, 1] made a page of nonsense).
    groups = [("methods", result.get("methods"))] if isinstance(result.get("methods"), dict) \
        else [("variants.%s.methods" % k, v.get("methods") if isinstance(v, dict) else None)
              for k, v in result["variants"].items()]
    for where, methods in groups:
        if not isinstance(methods, dict) or not methods:
            raise ReportError("%s: '%s' holds no method" % (path, where))
        for name, m in methods.items():
            if not isinstance(m, dict):
                raise ReportError("%s: '%s.%s' is not an object" % (path, where, name))
            for rate in ("success_rate", "dangerous_rate"):
                r = m.get(rate)
                if not isinstance(r, dict):
                    raise ReportError("%s: '%s.%s.%s' is missing" % (path, where, name, rate))
                values = [("mean", r.get("mean"))] + [
                    ("per_seed[%d]" % i, v) for i, v in enumerate(r.get("per_seed") or [])]
                for key, v in values:
                    if isinstance(v, bool) or not isinstance(v, (int, float)) or \
                            not 0.0 <= v <= 1.0:
                        raise ReportError("%s: '%s.%s.%s.%s' = %s, must be a rate in [0, 1]"
                                          % (path, where, name, rate, key, json.dumps(v)))
    return result


def seed_dirs(run_dir):
    out = []
    for name in os.listdir(run_dir):
        if name.startswith("seed-") and name[5:].isdigit() and \
                os.path.isdir(os.path.join(run_dir, name)):
            out.append((int(name[5:]), os.path.join(run_dir, name)))
    return [d for _, d in sorted(out)]


def read_curve(path):
    """A curve CSV as {column: np.array}, numeric columns only; None if unreadable."""
    try:
        with open(path, newline="") as f:
            rows = list(csv.reader(f))
    except OSError:
        return None
    if len(rows) < 2:
        return None
    header, body = rows[0], rows[1:]
    cols = {}
    for j, name in enumerate(header):
        try:
            cols[name] = np.array([float(r[j]) for r in body if len(r) == len(header)])
        except ValueError:
            continue
    return cols or None


# ---------------------------------------------------------------------------------------------
# Figures


class Page:
    def __init__(self, fig_dir):
        self.fig_dir = fig_dir
        self.parts = []
        self.figures = []  # file names

    def h2(self, text):
        self.parts.append("<h2>%s</h2>" % html.escape(text))

    def p(self, text, cls=None):
        self.parts.append("<p%s>%s</p>" % (' class="%s"' % cls if cls else "", text))

    def note(self, text):
        self.p(html.escape(text), "note")

    def raw(self, text):
        self.parts.append(text)

    def figure(self, fig, name, caption):
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=100)
        plt.close(fig)
        data = buf.getvalue()
        if self.fig_dir is not None:
            with open(os.path.join(self.fig_dir, name + ".png"), "wb") as f:
                f.write(data)
        self.figures.append(name + ".png")
        self.parts.append(
            '<figure><img id="fig-%s" alt="%s" src="data:image/png;base64,%s">'
            '<figcaption>%s</figcaption></figure>'
            % (name, html.escape(name), base64.b64encode(data).decode("ascii"), caption))


def ordered_methods(methods):
    known = [m for m in METHOD_ORDER if m in methods]
    return known + sorted(m for m in methods if m not in known)


def rate(methods, m, metric):
    r = methods[m].get(metric, {})
    mean = r.get("mean")
    std = r.get("std")
    per_seed = [v for v in r.get("per_seed", []) if isinstance(v, (int, float))]
    return (100.0 * mean if isinstance(mean, (int, float)) else float("nan"),
            100.0 * std if isinstance(std, (int, float)) else 0.0,
            [100.0 * v for v in per_seed])


def significance_pairs(evaluation, names, metric):
    """[(method a, method b, p, test name)] the run computed for this metric."""
    out = []
    comp = evaluation.get("comparisons") or {}
    # "<a>_vs_<b>": SECURE vs AIRL, and the other safety filters (cbf-qp, secure-qp) vs SECURE.
    pairs = sorted((k for k in comp if k.endswith(("_vs_airl", "_vs_secure"))
                    and isinstance(comp[k], dict)), key=lambda k: (k != "secure_vs_airl", k))
    for name in pairs:
        a, _, b = name.partition("_vs_")
        key = "success_mann_whitney" if metric == "success_rate" else "dangerous_mann_whitney"
        t = comp[name].get(key)
        if isinstance(t, dict):
            out.append((a, b, t.get("p_value"), "Mann-Whitney U = %s" % t.get("u")))
    abl = comp.get("ablations")
    if isinstance(abl, dict) and isinstance(abl.get(metric), dict):
        group = abl.get("methods", [])
        dunn = abl[metric].get("dunn") or {}
        for pair in dunn.get("pairs", []):
            i, j = pair.get("i"), pair.get("j")
            if isinstance(i, int) and isinstance(j, int) and i < len(group) and j < len(group):
                p = pair.get("p_adjusted", pair.get("p_value"))
                out.append((group[i], group[j], p, "Dunn"))
    return [x for x in out if x[0] in names and x[1] in names]


def comparison_figure(page, evaluation, title, name):
    methods = evaluation["methods"]
    names = ordered_methods(methods)
    fig, axes = plt.subplots(1, 2, figsize=(max(7.0, 1.5 * len(names) + 3), 4.2))
    for ax, metric, label, color in ((axes[0], "success_rate", "Success rate (%)", SUCCESS_COLOR),
                                     (axes[1], "dangerous_rate", "Dangerous rate (%)",
                                      DANGER_COLOR)):
        x = np.arange(len(names))
        means, stds = [], []
        for k, m in enumerate(names):
            mean, std, per_seed = rate(methods, m, metric)
            means.append(mean)
            stds.append(std)
            ax.scatter(np.full(len(per_seed), k) + np.linspace(-0.15, 0.15, len(per_seed)),
                       per_seed, s=8, color="black", alpha=0.5, zorder=3)
        ax.bar(x, means, yerr=stds, color=color, capsize=4, edgecolor="black", linewidth=0.5)
        ax.set_xticks(x)
        ax.set_xticklabels([METHOD_LABELS.get(m, m) for m in names], rotation=30, ha="right")
        ax.set_ylabel(label)
        top = max([m + s for m, s in zip(means, stds) if math.isfinite(m)] + [1.0])
        level = max(top, 5.0) * 1.05
        step = max(top, 5.0) * 0.09
        for a, b, p, _ in significance_pairs(evaluation, names, metric):
            mark = stars(p)
            if mark is None:
                continue
            i, j = sorted((names.index(a), names.index(b)))
            ax.plot([i, i, j, j], [level, level + step * 0.3, level + step * 0.3, level],
                    color="black", linewidth=0.8)
            ax.text((i + j) / 2, level + step * 0.35, mark, ha="center", va="bottom", fontsize=9)
            level += step
        ylim = max(level + step * 0.5, 10.0)
        if ylim > 40:  # rates are at most 100 %: no ticks in the brackets' room above
            ax.set_yticks([t for t in range(0, 101, 20) if t <= ylim])
        ax.set_ylim(0, ylim)
        ax.grid(axis="y", alpha=0.3)
    fig.suptitle(title)
    fig.tight_layout()
    caption = ("Mean &plusmn; standard deviation over seeds (dots: the seeds). Marks: the tests "
               "the run computed (result.json <code>comparisons</code>): * p &lt; .05, ** p &lt; "
               ".01, *** p &lt; .001, n.s. otherwise.")
    page.figure(fig, name, caption)


def tests_table(evaluation):
    comp = evaluation.get("comparisons") or {}
    rows = []
    # Pairwise comparisons "<a>_vs_<b>": SECURE vs AIRL, and the other safety filters (cbf-qp,
    # secure-qp) vs SECURE; each with Mann-Whitney on both rates and TOST on success.
    pairs = sorted((k for k in comp if k.endswith(("_vs_airl", "_vs_secure"))
                    and isinstance(comp[k], dict)), key=lambda k: (k != "secure_vs_airl", k))
    for name in pairs:
        sva = comp[name]
        a, _, b = name.partition("_vs_")
        label = "%s vs %s" % (METHOD_LABELS.get(a, a), METHOD_LABELS.get(b, b))
        for key, what in (("success_mann_whitney", "success, Mann-Whitney"),
                          ("dangerous_mann_whitney", "dangerous, Mann-Whitney")):
            t = sva.get(key) or {}
            rows.append((label, what, "U = %s" % num(t.get("u")), fmt_p(t.get("p_value"))))
        t = sva.get("success_tost") or {}
        test = "success, TOST (Welch), bound %s" % num(t.get("bound"))
        se = t.get("se")
        if isinstance(se, (int, float)) and not isinstance(se, bool) and not se > 0:
            # Both methods' success is the same on every seed (e.g. 0 % against 0 %): the
            # standard error is 0 and the p-value says nothing about equivalence.
            rows.append((label, test, "not informative: each method's success is "
                         "constant over the seeds (difference %s)" % num(t.get("difference")),
                         "n/a"))
        else:
            rows.append((label, test, "difference = %s" % num(t.get("difference")),
                         fmt_p(t.get("p_value"))))
    abl = comp.get("ablations")
    if isinstance(abl, dict):
        group = [METHOD_LABELS.get(m, m) for m in abl.get("methods", [])]
        for metric in ("success_rate", "dangerous_rate"):
            t = abl.get(metric) or {}
            if "note" in t:
                rows.append((", ".join(group), metric, t["note"], "n/a"))
                continue
            kw = t.get("kruskal_wallis") or {}
            rows.append((", ".join(group), metric + ", Kruskal-Wallis",
                         "H(%s) = %s" % (num(kw.get("df")), num(kw.get("h"))), fmt_p(kw.get("p_value"))))
            for pair in (t.get("dunn") or {}).get("pairs", []):
                i, j = pair.get("i", 0), pair.get("j", 0)
                if i < len(group) and j < len(group):
                    rows.append(("%s vs %s" % (group[i], group[j]), metric + ", Dunn",
                                 "z = %s" % num(pair.get("z")),
                                 fmt_p(pair.get("p_adjusted", pair.get("p_value")))))
    if not rows:
        return "<p class=\"note\">The run computed no significance tests (they need two seeds " \
               "or more and the methods they compare).</p>"
    out = ["<table><tr><th>comparison</th><th>test</th><th>statistic</th><th>p</th></tr>"]
    for r in rows:
        out.append("<tr>%s</tr>" % "".join("<td>%s</td>" % html.escape(str(c)) for c in r))
    out.append("</table>")
    return "".join(out)


def paper_cell(mean, std):
    return "%.1f" % mean if std is None else "%.1f (%.1f)" % (mean, std)


def table3(evaluation, domain):
    methods = evaluation["methods"]
    paper = PAPER_TABLE3.get(domain)
    out = ["<table><tr><th>method</th><th>success % (this run)</th>"
           "<th>dangerous % (this run)</th>"]
    if paper:
        out.append("<th>success % (paper)</th><th>dangerous % (paper)</th>")
    out.append("</tr>")
    for m in ordered_methods(methods):
        s, ss, _ = rate(methods, m, "success_rate")
        d, ds, _ = rate(methods, m, "dangerous_rate")
        row = "<td>%s</td><td>%.1f (%.1f)</td><td>%.1f (%.1f)</td>" % (
            html.escape(METHOD_LABELS.get(m, m)), s, ss, d, ds)
        if paper:
            if m in paper:
                (ps, pss), (pd, pds) = paper[m]
                row += "<td>%s</td><td>%s</td>" % (paper_cell(ps, pss), paper_cell(pd, pds))
            else:
                row += "<td>&ndash;</td><td>&ndash;</td>"
        out.append("<tr>%s</tr>" % row)
    out.append("</table>")
    if paper:
        out.append("<p>Paper: Table 3 of the SECURE paper (Section 6.1), %s domain, %s; its "
                   "tests: %s.</p>"
                   % (paper["title"], html.escape(paper.get(
                       "protocol", "mean (std) over ten seeds, 100 episodes each")),
                      html.escape(paper["tests"])))
    else:
        out.append('<p class="note">The paper reports no Table 3 numbers for the %s domain '
                   "(its Table 3 has Demolition Derby, Panda Arm Push and the real-robot "
                   "cutting task).</p>" % html.escape(domain))
    return "".join(out)


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


def curves_figure(page, run_dir):
    seeds = seed_dirs(run_dir)
    panels = []  # (title, column, [(seed, x, y)])
    for file_name, label in CURVE_FILES:
        per_seed = [(os.path.basename(d), read_curve(os.path.join(d, file_name))) for d in seeds]
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


# ---------------------------------------------------------------------------------------------
# Barrier pictures (through the Python module `secure`)


def first_model(run_dir, name="barrier.model"):
    for d in seed_dirs(run_dir):
        p = os.path.join(d, name)
        if os.path.isfile(p):
            return p
    return None


def read_states_csv(path, features, limit=20000):
    with open(path, newline="") as f:
        reader = csv.reader(f)
        header = next(reader)
        idx = [header.index(n) for n in features]
        rows = []
        for r in reader:
            rows.append([float(r[i]) for i in idx])
            if len(rows) >= limit:
                break
    return np.array(rows, dtype=np.float32)


def barrier_double_integrator(page, secure, run_dir, result):
    path = first_model(run_dir)
    if path is None:
        page.note("No barrier picture: no seed-<k>/barrier.model in the run directory.")
        return
    b = secure.Barrier.load(path)
    gt = secure.Barrier.ground_truth("double-integrator")
    feats = b.features or ["x", "y", "vx", "vy"]
    opts = result["experiment"].get("domain_options") or {}
    task = opts.get("task", opts) if isinstance(opts, dict) else {}
    obstacle = task.get("obstacle", [5.0, 5.0]) if isinstance(task, dict) else [5.0, 5.0]
    radius = task.get("radius", 2.0) if isinstance(task, dict) else 2.0
    n = 121
    xs = np.linspace(0.0, 10.0, n)
    X, Y = np.meshgrid(xs, xs)
    slices = [(0.0, 0.0), (1.5, 1.5), (-1.5, 0.0)]
    fig, axes = plt.subplots(1, len(slices), figsize=(4.3 * len(slices), 4.0))
    for ax, (vx, vy) in zip(axes, slices):
        values = {"x": X.ravel(), "y": Y.ravel(), "vx": np.full(n * n, vx),
                  "vy": np.full(n * n, vy)}
        S = np.stack([values[f] for f in feats], axis=1).astype(np.float32)
        H = np.asarray(b.h(S)).reshape(n, n)
        lim = max(1e-6, float(np.nanpercentile(np.abs(H), 98)))
        im = ax.pcolormesh(X, Y, H, cmap="RdBu", vmin=-lim, vmax=lim, shading="auto")
        ax.contour(X, Y, H, levels=[0.0], colors="black", linewidths=1.5)
        if gt is not None:
            G = np.asarray(gt.h(np.stack([values[f] for f in (gt.features or feats)],
                                         axis=1).astype(np.float32))).reshape(n, n)
            ax.contour(X, Y, G, levels=[0.0], colors="gold", linewidths=1.5, linestyles="--")
        ax.add_patch(plt.Circle(obstacle, radius, fill=False, color="gray", linewidth=1))
        ax.set_aspect("equal")
        ax.set_title("v = (%g, %g)" % (vx, vy), fontsize=10)
        ax.set_xlabel("x")
        ax.set_ylabel("y")
        fig.colorbar(im, ax=ax, shrink=0.8, label="h")
    fig.tight_layout()
    page.figure(fig, "barrier", "The learned barrier h(x, y, v<sub>x</sub>, v<sub>y</sub>) of "
                "<code>%s</code> over the position at three velocities (blue: h &gt; 0, safe). "
                "Black: its zero level set; dashed gold: the ground-truth barrier's zero level "
                "set%s; gray: the obstacle."
                % (html.escape(os.path.relpath(path, run_dir)),
                   "" if gt is not None else " (not available)"))


def barrier_derby(page, secure, run_dir, result):
    path = first_model(run_dir)
    if path is None:
        page.note("No barrier picture: no seed-<k>/barrier.model in the run directory.")
        return
    b = secure.Barrier.load(path)
    feats = list(b.features)
    if "car0_dx" not in feats or "car0_dy" not in feats:
        page.note("No barrier picture: the barrier does not read car0_dx, car0_dy.")
        return
    # One state: ego at rest, car 0 (the nearest) at the grid's relative position with zero
    # relative velocity, every other car far out of sensing range.
    state = np.zeros(len(feats), dtype=np.float32)
    for i, f in enumerate(feats):
        if f.startswith("car") and not f.startswith("car0_") and f.endswith(("_dx", "_dy")):
            state[i] = 1.0e3
    # The collision radius r and sensing radius R from the model's description
    # ("car_barrier 3-64-1 relu, 12 cars, r 0.07, R 1, cap 0.05, positions"): a window of a few r.
    found = dict(re.findall(r"\b(r|R) ([0-9.eE+-]+)", b.describe()))
    r = float(found.get("r", 0.07))
    extent = min(float(found.get("R", 1.0)) * 1.05, max(5.0 * r, 0.2))
    n = 161
    xs = np.linspace(-extent, extent, n)
    X, Y = np.meshgrid(xs, xs)
    S = np.tile(state, (n * n, 1)).astype(np.float32)
    S[:, feats.index("car0_dx")] = X.ravel()
    S[:, feats.index("car0_dy")] = Y.ravel()
    H = np.asarray(b.h(S)).reshape(n, n)
    fig, ax = plt.subplots(figsize=(5.2, 4.4))
    lim = max(1e-6, float(np.nanpercentile(np.abs(H), 98)))
    im = ax.pcolormesh(X, Y, H, cmap="RdBu", vmin=-lim, vmax=lim, shading="auto")
    if np.nanmin(H) < 0 < np.nanmax(H):
        ax.contour(X, Y, H, levels=[0.0], colors="black", linewidths=1.5)
    ax.plot([0], [0], marker="+", color="black")
    ax.add_patch(plt.Circle((0, 0), r, fill=False, color="gray", linewidth=1, linestyle=":"))
    ax.set_aspect("equal")
    ax.set_xlabel("car0_dx (other car - ego)")
    ax.set_ylabel("car0_dy")
    fig.colorbar(im, ax=ax, label="h")
    fig.tight_layout()
    page.figure(fig, "barrier", "The learned per-car barrier of <code>%s</code> around the ego "
                "car (+) as a function of one other car's relative position (relative "
                "velocity 0, ego at rest, every other car out of range). Black: h = 0; "
                "dotted gray: the collision radius."
                % html.escape(os.path.relpath(path, run_dir)))


def barrier_panda(page, secure, run_dir, result):
    path = first_model(run_dir)
    safe = os.path.join(run_dir, "safe.csv")
    if path is None or not os.path.isfile(safe):
        page.note("No barrier picture: no seed-<k>/barrier.model or safe.csv in the run "
                  "directory.")
        return
    b = secure.Barrier.load(path)
    feats = b.features
    if "ee_z" not in feats or "ee_vx" not in feats:
        page.note("No barrier picture: the barrier does not read ee_z and ee_vx.")
        return
    states = read_states_csv(safe, feats)
    iz, iv = feats.index("ee_z"), feats.index("ee_vx")
    # A pushing state: among the safe states moving along +x, the one with the end effector
    # nearest the block (if the barrier reads the block's position), else the median-speed one.
    moving = states[states[:, iv] > 0.02]
    if len(moving) == 0:
        moving = states
    if "block_x" in feats:
        gap = np.abs(moving[:, feats.index("block_x")] - moving[:, feats.index("ee_x")])
        state = moving[int(np.argmin(gap))]
    else:
        state = moving[int(np.argsort(moving[:, iv])[len(moving) // 2])]
    v_top = 1.0
    nd_path = os.path.join(run_dir, "near_dangerous.csv")
    if os.path.isfile(nd_path):  # up to the near-dangerous pushes' speeds
        nd = read_states_csv(nd_path, feats)
        v_top = max(0.5, 1.05 * float(np.percentile(nd[:, iv], 95)))
    n = 101
    zs = np.linspace(0.0, 0.15, n)
    vs = np.linspace(0.0, v_top, n)
    Z, V = np.meshgrid(zs, vs)
    S = np.tile(state, (n * n, 1)).astype(np.float32)
    S[:, iz] = Z.ravel()
    S[:, iv] = V.ravel()
    H = np.asarray(b.h(S)).reshape(n, n)
    fig, ax = plt.subplots(figsize=(5.2, 4.4))
    lim = max(1e-6, float(np.nanpercentile(np.abs(H), 98)))
    im = ax.pcolormesh(Z, V, H, cmap="RdBu", vmin=-lim, vmax=lim, shading="auto")
    if np.nanmin(H) < 0 < np.nanmax(H):
        ax.contour(Z, V, H, levels=[0.0], colors="black", linewidths=1.5)
    ax.plot([state[iz]], [state[iv]], marker="o", color="black")
    ax.set_xlabel("ee_z (m)")
    ax.set_ylabel("ee_vx (m/s)")
    fig.colorbar(im, ax=ax, label="h")
    fig.tight_layout()
    page.figure(fig, "barrier", "The learned barrier of <code>%s</code> over the end-effector "
                "height and pushing speed (x), the other features those of a pushing safe state "
                "(moving along +x, nearest the block). Black: h = 0; dot: that state." % html.escape(os.path.relpath(path, run_dir)))


BARRIER_PICTURES = {"double-integrator": barrier_double_integrator, "derby": barrier_derby,
                    "panda-push": barrier_panda}


def barrier_section(page, run_dir, result):
    domain = result["experiment"].get("domain", "")
    picture = BARRIER_PICTURES.get(domain)
    if picture is None:
        page.note("No barrier picture for the %s domain (the report draws the double "
                  "integrator, derby and panda-push)." % domain)
        return
    try:
        import secure  # noqa: the Python module (python/README.md), PYTHONPATH=<build>/python
    except Exception as e:  # ImportError, or a broken build's OSError
        page.note("No barrier picture: the Python module `secure` is not available (%s: %s). "
                  "Build it (target secure_python) and set PYTHONPATH=<build>/python, or run "
                  "\"secure report\", which does." % (type(e).__name__, e))
        return
    try:
        picture(page, secure, run_dir, result)
    except Exception as e:
        page.note("No barrier picture: %s: %s" % (type(e).__name__, e))


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


def trajectories_double_integrator(page, secure, run_dir, result):
    """The expert demonstrations and five episodes of AIRL and SECURE (seed 0's models)."""
    players = seed0_players(secure, run_dir, result, "double-integrator")
    if players is None:
        page.note("No trajectories: the run's first seed has no airl.model and barrier.model.")
        return
    env, policy, shield, shield_note, eval_seed, task = players
    episodes = 5
    fig, axes = plt.subplots(1, 3, figsize=(13.5, 4.6))
    demos = os.path.join(run_dir, "demos.csv")
    if os.path.isfile(demos):
        with open(demos, newline="") as f:
            reader = csv.DictReader(f)
            paths = {}
            for row in reader:
                if len(paths) > 20 and row["episode"] not in paths:
                    break
                paths.setdefault(row["episode"], []).append((float(row["x"]), float(row["y"])))
        for xy in paths.values():
            xy = np.array(xy)
            axes[0].plot(xy[:, 0], xy[:, 1], color="#555555", linewidth=0.8, alpha=0.7)
    axes[0].set_title("expert demonstrations (first 20)", fontsize=10)
    for ax, name, shielded in ((axes[1], "AIRL", False), (axes[2], "SECURE (AIRL + shield)",
                                                           True)):
        eps = play_episodes(secure, env, policy, shield if shielded else None, eval_seed,
                            episodes)
        for ep in eps:
            xy = ep["obs"][:, :2]
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
    obstacle = task.get("obstacle", [5.0, 5.0])
    radius = task.get("radius", 2.0)
    goal = task.get("goal", [8.5, 8.5])
    for ax in axes:
        ax.add_patch(plt.Circle(obstacle, radius, color="gray", alpha=0.3))
        ax.plot(goal[0], goal[1], marker="*", color="black", markersize=10)
        ax.set_xlim(0, 10)
        ax.set_ylim(0, 10)
        ax.set_aspect("equal")
        ax.set_xlabel("x")
        ax.set_ylabel("y")
    fig.tight_layout()
    page.figure(fig, "trajectories", "Left: the expert demonstrations (<code>demos.csv</code>). "
                "Middle and right: five episodes of seed 0's AIRL policy without and with the "
                "shield over its barrier (%s), start states drawn from the seed's evaluation "
                "stream; green: reached the goal (star), red: entered the obstacle (gray), blue: "
                "neither. Orange dots: the steps where the shield intervened (changed the "
                "policy's action; their number is in the panel's title). Played with the Python "
                "module's environment and shield."
                % html.escape(shield_note))


def trajectories_derby(page, secure, run_dir, result):
    """Three episodes of AIRL and SECURE (seed 0's AIRL policy and per-car barrier) over the
    arena: the ego car's path, the observed cars' positions faint, collisions and the shield's
    interventions marked."""
    players = seed0_players(secure, run_dir, result, "derby")
    if players is None:
        page.note("No trajectories: the run's first seed has no airl.model and barrier.model.")
        return
    env, policy, shield, shield_note, eval_seed, task = players
    feats = list(env.observation_features)
    ig = (feats.index("goal_dx"), feats.index("goal_dy"))
    cars = []  # (dx column, dy column) of each observed car block
    k = 0
    while "car%d_dx" % k in feats:
        cars.append((feats.index("car%d_dx" % k), feats.index("car%d_dy" % k)))
        k += 1
    side = float(task.get("arena_side", 2 ** 0.5))
    goal_radius = float(task.get("goal_radius", 0.05))
    collision_radius = float(task.get("collision_radius", 0.07))
    episodes = 3
    rows = (("AIRL", None), ("SECURE (AIRL + shield)", shield))
    fig, axes = plt.subplots(len(rows), episodes, figsize=(4.0 * episodes + 0.5, 8.2),
                             squeeze=False)
    lo, hi = -0.25, side + 0.25  # the axes' range: the arena, and every ego path (bounded)
    for r, (name, sh) in enumerate(rows):
        eps = play_episodes(secure, env, policy, sh, eval_seed, episodes)
        for c, ep in enumerate(eps):
            ax = axes[r][c]
            obs = ep["obs"]
            # The observation is ego-relative (goal - p, v, car - p, ...): the ego's path is
            # drawn from its start, placed at the nominal start (0, 0).
            goal = obs[0, list(ig)]
            p = goal - obs[:, list(ig)]
            for jx, jy in cars:
                ax.scatter(p[:, 0] + obs[:, jx], p[:, 1] + obs[:, jy], s=2, color="#888888",
                           alpha=0.35, linewidths=0, zorder=1)
            ax.add_patch(plt.Rectangle((0, 0), side, side, fill=False, color="#999999",
                                       linestyle="--", linewidth=0.8))
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
                ax.add_patch(plt.Circle((x, y), collision_radius, fill=False,
                                        color=COLLISION_COLOR, linewidth=0.8, zorder=4))
            ax.scatter(hit[:, 0], hit[:, 1], s=22, marker="x", color=COLLISION_COLOR,
                       zorder=5)
            title = "%s, episode %d: %s" % (name.split(" ")[0], c, outcome(ep))
            if sh is not None:
                title += ", %d interventions" % int(ep["intervened"].sum())
            ax.set_title(title, fontsize=9)
            lo = min(lo, float(p.min()) - 0.05)
            hi = max(hi, float(p.max()) + 0.05)
            if c == 0:
                ax.set_ylabel("%s\ny" % panel_title(name, eps), fontsize=9)
            if r == len(rows) - 1:
                ax.set_xlabel("x")
    lo, hi = max(lo, -1.0 - side), min(hi, 2.0 * side + 1.0)
    for ax in axes.ravel():
        ax.set_xlim(lo, hi)
        ax.set_ylim(lo, hi)
        ax.set_aspect("equal")
    fig.tight_layout()
    page.figure(fig, "trajectories", "Episodes 0&ndash;%d of seed 0's evaluation stream, played "
                "with seed 0's AIRL policy without (top) and with (bottom) the shield over its "
                "per-car barrier (%s), the same episodes in each column. The ego car's path: "
                "green reached the goal (star, circle: the goal radius), red touched a car, blue "
                "neither; red crosses (circle: the collision radius): the steps it was in "
                "contact; orange dots: the steps where the shield intervened (changed the "
                "policy's action; counted in the titles). Faint gray dots: the %d nearest "
                "(observed) cars' positions at every step, which trace their paths (the "
                "observation does not name the cars). Dashed: the arena [0, %.2f]&sup2; of the "
                "starts. The observation is ego-relative, so positions are drawn relative to "
                "the ego's start placed at (0, 0) (its start jitter is not observed). Played "
                "with the Python module's environment and shield."
                % (episodes - 1, html.escape(shield_note), len(cars), side))


TRAJECTORY_PICTURES = {"double-integrator": trajectories_double_integrator,
                       "derby": trajectories_derby}
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


def trajectories_section(page, run_dir, result, out_path):
    domain = result["experiment"].get("domain", "")
    picture = TRAJECTORY_PICTURES.get(domain)
    if picture is None:
        page.note("No trajectories for the %s domain: the run directory records no evaluation "
                  "trajectories, and the report draws them only for the double integrator and "
                  "derby (\"secure render\" plays an episode of a domain with a renderer)."
                  % domain)
    else:
        try:
            import secure  # noqa
        except Exception as e:
            page.note("No trajectories: the Python module `secure` is not available (%s: %s)."
                      % (type(e).__name__, e))
            secure = None
        if secure is not None:
            try:
                picture(page, secure, run_dir, result)
            except Exception as e:
                page.note("No trajectories: %s: %s" % (type(e).__name__, e))
    videos_section(page, run_dir, out_path)


# ---------------------------------------------------------------------------------------------

FIGURE_NAMES = ["comparison", "learning_curves", "barrier_training", "sensitivity", "barrier",
                "trajectories"]

STYLE = """
body { font-family: sans-serif; max-width: 1100px; margin: 1.5em auto; color: #222; }
h1 { font-size: 1.5em; } h2 { font-size: 1.2em; border-bottom: 1px solid #ccc; }
table { border-collapse: collapse; margin: 0.5em 0; font-size: 0.9em; }
td, th { border: 1px solid #bbb; padding: 3px 8px; text-align: left; }
figure { margin: 0.5em 0; } img, video { max-width: 100%; }
figcaption, .note { font-size: 0.85em; color: #555; }
.note { background: #fff6dd; padding: 4px 8px; }
"""


# ---------------------------------------------------------------------------------------------
# Writing the page: the rules of the C++ writers (secure/common/atomic_file.h). `secure report`
# hands the page to the C++ writer itself (--write-to); these are for the script run alone.


def output_kind(path):
    """What `path` is, following symlinks: None (does not exist), "file", "device", "fifo";
    a directory, a socket or a block device is a ReportError (nothing touched)."""
    try:
        st = os.stat(path)
    except FileNotFoundError:
        return None
    except OSError as e:
        raise ReportError("cannot write '%s': %s" % (path, e.strerror))
    if stat.S_ISREG(st.st_mode):
        return "file"
    if stat.S_ISCHR(st.st_mode):
        return "device"
    if stat.S_ISFIFO(st.st_mode):
        return "fifo"
    what = "a directory" if stat.S_ISDIR(st.st_mode) else \
        "a socket" if stat.S_ISSOCK(st.st_mode) else "a block device" \
        if stat.S_ISBLK(st.st_mode) else "not a regular file"
    raise ReportError("cannot write '%s': it is %s, not a regular file" % (path, what))


def open_fifo_for_writing(path):
    try:
        fd = os.open(path, os.O_WRONLY | os.O_NONBLOCK)
    except OSError as e:
        if e.errno == 6:  # ENXIO
            raise ReportError("cannot write '%s': a FIFO that no process has open for reading"
                              % path)
        raise ReportError("cannot write '%s': %s" % (path, e.strerror))
    os.set_blocking(fd, True)
    return fd


def write_output(path, text):
    """Writes the page as every C++ writer does: a regular file atomically (temporary + fsync +
    rename, its mode kept), through symlinks to their target, a device or a FIFO (with a reader)
    directly; a directory refused. No temporary is left behind on failure."""
    data = text.encode("utf-8")
    kind = output_kind(path)
    if kind in ("device", "fifo"):
        try:
            fd = open_fifo_for_writing(path) if kind == "fifo" else os.open(path, os.O_WRONLY)
            with os.fdopen(fd, "wb", buffering=0) as f:
                view = memoryview(data)
                while view:
                    view = view[f.write(view):]
        except OSError as e:
            raise ReportError("cannot write '%s': %s" % (path, e.strerror))
        return
    target = os.path.realpath(path)
    if kind == "file":
        mode = os.stat(target).st_mode & 0o7777
    else:
        umask = os.umask(0)
        os.umask(umask)
        mode = 0o666 & ~umask
    tmp = "%s.tmp-%d" % (target, os.getpid())
    try:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        try:
            with os.fdopen(fd, "wb") as f:
                f.write(data)
                f.flush()
                os.fsync(f.fileno())
            os.chmod(tmp, mode)
            os.replace(tmp, target)
        except BaseException:
            try:
                os.unlink(tmp)
            except OSError:
                pass
            raise
    except OSError as e:
        raise ReportError("cannot write '%s': %s" % (path, e.strerror or e))


def build_report(run_dir, out_path, write_to=None):
    result = load_run(run_dir)
    exp = result["experiment"]
    domain = str(exp.get("domain", "?"))
    kind = str(exp.get("kind", "?"))
    # The output first (a directory or a FIFO without a reader fails before any work); figure
    # files next to a page that is a file, not next to a device or a FIFO (they are embedded).
    out_kind = output_kind(out_path)
    if out_kind == "fifo" and write_to is None:
        os.close(open_fifo_for_writing(out_path))
    fig_dir = None
    if out_kind in (None, "file"):
        fig_dir = os.path.splitext(out_path)[0] + "_figures"
        try:
            os.makedirs(fig_dir, exist_ok=True)
        except OSError as e:
            raise ReportError("cannot create the figures' directory '%s': %s"
                              % (fig_dir, e.strerror))
        for name in FIGURE_NAMES:  # a figure this run does not get must not survive
            old = os.path.join(fig_dir, name + ".png")
            if os.path.isfile(old):
                os.remove(old)
    page = Page(fig_dir)
    opts = exp.get("options") or {}
    seeds = opts.get("seeds", len(exp.get("seeds") or []))
    page.raw("<h1>SECURE run report: %s on %s</h1>" % (html.escape(kind), html.escape(domain)))
    page.p("Run directory <code>%s</code>: %s seeds &times; %s episodes per method; %s "
           "demonstrations, %s safe + %s near-dangerous states; %.1f s."
           % (html.escape(os.path.abspath(run_dir)), seeds, opts.get("episodes", "?"),
              exp.get("demonstrations", "?"), exp.get("safe_states", "?"),
              exp.get("near_dangerous_states", "?"), float(exp.get("seconds", 0.0) or 0.0)))

    page.h2("1. Method comparison")
    if isinstance(result.get("methods"), dict):
        comparison_figure(page, result, "%s on %s" % (kind, domain), "comparison")
        page.raw(table3(result, domain))
        page.raw(tests_table(result))
    else:
        baseline = (result.get("variants") or {}).get("baseline")
        if isinstance(baseline, dict) and isinstance(baseline.get("methods"), dict):
            comparison_figure(page, baseline, "baseline barrier data", "comparison")
            page.raw(table3(baseline, domain))
            page.raw(tests_table(baseline))
        else:
            page.note("No baseline variant in result.json: see the variants below.")

    page.h2("2. Learning curves")
    curves_figure(page, run_dir)
    barrier_training_figure(page, result)

    page.h2("3. Sensitivity and ablation variants")
    if isinstance(result.get("variants"), dict):
        variants_figure(page, result)
    elif kind == "ablation" or (result.get("comparisons") or {}).get("ablations"):
        page.p("The ablation variants (random safe action, no adaptive resampling, myopic) are "
               "the bars of section 1, with the Kruskal-Wallis and Dunn marks.")
    else:
        page.note("This run has no sensitivity or ablation variants (kind %s); \"secure "
                  "experiment sensitivity\" and \"secure experiment ablation\" have them." % kind)

    page.h2("4. Learned barrier")
    barrier_section(page, run_dir, result)

    page.h2("5. Trajectories")
    trajectories_section(page, run_dir, result, out_path)

    doc = ("<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>SECURE report: %s on %s"
           "</title><style>%s</style></head><body>\n%s\n</body></html>\n"
           % (html.escape(kind), html.escape(domain), STYLE, "\n".join(page.parts)))
    if write_to is not None:  # `secure report`: its C++ writer installs the page
        with open(write_to, "w", encoding="utf-8") as f:
            f.write(doc)
    else:
        write_output(out_path, doc)
    return page.figures


def main(argv):
    parser = argparse.ArgumentParser(prog="secure report", description=__doc__.split("\n")[0])
    parser.add_argument("run_dir")
    parser.add_argument("--out", help="the HTML file (default RUN_DIR/report.html)")
    parser.add_argument("--write-to", help=argparse.SUPPRESS)  # secure report's scratch file
    args = parser.parse_args(argv)
    out = args.out or os.path.join(args.run_dir, "report.html")
    try:
        import reproduce_page  # tools/report/reproduce_page.py: a `secure reproduce` directory
        if reproduce_page.is_reproduce_dir(args.run_dir):
            figures = reproduce_page.build(sys.modules[__name__], args.run_dir, out,
                                           args.write_to)
        else:
            figures = build_report(args.run_dir, out, args.write_to)
    except ReportError as e:
        print("secure report: error: %s" % e, file=sys.stderr)
        return 1
    except OSError as e:  # a full disk, a vanished file: one line naming it
        print("secure report: error: %s%s" % ("'%s': " % e.filename if e.filename else "",
                                              e.strerror or e), file=sys.stderr)
        return 1
    except Exception as e:  # noqa: BLE001 (one line, never a traceback)
        print("secure report: error: %s: %s" % (type(e).__name__, e), file=sys.stderr)
        return 1
    print("report: %s (%d figures in %s)" % (out, len(figures),
                                           os.path.splitext(out)[0] + "_figures"))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
