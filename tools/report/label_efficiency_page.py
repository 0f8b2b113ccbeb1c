"""The page of a `secure experiment label-efficiency --out DIR` run (issue 35; report.py calls
build() when DIR's result.json says "experiment": "label-efficiency").

The run's result.json (secure/experiments/label_efficiency.h) holds one curve per strategy and
seed: per round the labels asked so far and, where the domain has them, Table 1's over- and
under-conservative error (%, -1 without a ground truth) and the closed-loop dangerous and success
rates of the shielded run (%, -1 without a shield run). The page draws against labels used, one
line per strategy (the mean over seeds) with the spread over seeds (mean +- sample std, shaded):
  label_errors       under- and over-conservative error, the paper's full-data Table 1 result
                     (result.json "paper") as a dashed reference line;
  label_closed_loop  dangerous and success rates, the paper's SECURE row of Table 3 for the
                     domain (from the registry, hints.paper_table3) as the reference where it has
                     one;
and a table: per strategy the last round's means, the labels at which the mean first reaches the
paper's Table 1 errors, and the labels at which its under-conservative error first reaches
random's at random's last round (with random's labels over them: how many times fewer labels the
strategy needs).
A figure the run has no numbers for (no ground truth, no shield run) is a note instead.
"""
import html
import json
import math
import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

KIND = "label-efficiency"
MEASURES = ("under_conservative", "over_conservative", "dangerous", "success")
COLOURS = {"random": "#7f7f7f", "margin": "#e76f51", "disagreement": "#2a9d8f",
           "diversity": "#264653", "shield-relevant": "#e9c46a"}


def is_label_efficiency_dir(path):
    """True if `path` holds a result.json of the label-efficiency experiment (a malformed one is
    left to report.py's reader, which names the problem)."""
    p = os.path.join(path, "result.json")
    try:
        with open(p, "rb") as f:
            doc = json.loads(f.read().decode("utf-8"))
    except (OSError, UnicodeDecodeError, ValueError):
        return False
    return isinstance(doc, dict) and doc.get("experiment") == KIND


def _number(report, path, where, v, lo, hi):
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or \
            not (v == -1 or lo <= v <= hi):
        raise report.ReportError("%s: '%s' = %s, must be a number in [%g, %g] (or -1: not "
                                 "measured)" % (path, where, json.dumps(v), lo, hi))
    return float(v)


def load(report, run_dir):
    """result.json checked: {strategy: [(seed, {measure or "labels": np.array per round})]}."""
    path = os.path.join(run_dir, "result.json")
    with open(path, "rb") as f:
        doc = json.loads(f.read().decode("utf-8"))
    curves = doc.get("curves")
    if not isinstance(curves, list) or not curves:
        raise report.ReportError("%s: 'curves' holds no curve (a sharded run: rerun unsharded "
                                 "into the directory to merge)" % path)
    by_strategy = {}
    for i, c in enumerate(curves):
        pts = c.get("points") if isinstance(c, dict) else None
        if not isinstance(c, dict) or not isinstance(c.get("strategy"), str) or \
                not isinstance(pts, list) or not pts:
            raise report.ReportError("%s: 'curves[%d]' lacks 'strategy' or 'points'" % (path, i))
        series = {k: [] for k in ("labels",) + MEASURES}
        for j, p in enumerate(pts):
            where = "curves[%d].points[%d]" % (i, j)
            if not isinstance(p, dict):
                raise report.ReportError("%s: '%s' is not an object" % (path, where))
            series["labels"].append(_number(report, path, where + ".labels", p.get("labels"),
                                            0, 1e12))
            for m in MEASURES:
                series[m].append(_number(report, path, "%s.%s" % (where, m), p.get(m, -1),
                                         0, 100))
        by_strategy.setdefault(c["strategy"], []).append(
            (c.get("seed"), {k: np.array(v) for k, v in series.items()}))
    return doc, by_strategy


def mean_curve(seeds, measure):
    """(labels, mean, std) over the seeds at the rounds every seed measured, or None."""
    n = min(len(s["labels"]) for _, s in seeds)
    labels = seeds[0][1]["labels"][:n]
    ys = np.array([s[measure][:n] for _, s in seeds])
    keep = (ys >= 0).all(axis=0)
    if not keep.any():
        return None
    ys = ys[:, keep]
    std = ys.std(axis=0, ddof=1) if len(seeds) > 1 else np.zeros(ys.shape[1])
    return labels[keep], ys.mean(axis=0), std


def _panel(ax, by_strategy, measure, title, reference, reference_label, log_x=False):
    drawn = False
    for strategy, seeds in by_strategy.items():
        c = mean_curve(seeds, measure)
        if c is None:
            continue
        x, m, s = c
        colour = COLOURS.get(strategy)
        ax.plot(x, m, "-o", ms=3, color=colour, label="%s (%d seeds)" % (strategy, len(seeds)))
        ax.fill_between(x, np.clip(m - s, 0, 100), np.clip(m + s, 0, 100), color=colour,
                        alpha=0.15, lw=0)
        drawn = True
    if drawn and reference is not None:
        ax.axhline(reference, color="black", ls="--", lw=1, label=reference_label)
    ax.set_title(title, fontsize=10)
    ax.set_xlabel("labels used (log scale)" if log_x else "labels used")
    if log_x:  # rounds growing by k_growth: evenly spaced in log(labels)
        ax.set_xscale("log")
    ax.set_ylabel("%")
    ax.grid(alpha=0.3)
    if drawn:
        ax.legend(fontsize=7)
    return drawn


def _figure(page, by_strategy, name, panels, caption, log_x=False):
    if log_x:
        caption += " Labels on a log scale (the rounds grow by k_growth)."
    fig, axes = plt.subplots(1, len(panels), figsize=(11, 4))
    drawn = [_panel(ax, by_strategy, *p, log_x=log_x) for ax, p in zip(axes, panels)]
    if not any(drawn):
        plt.close(fig)
        return False
    fig.tight_layout()
    page.figure(fig, name, caption)
    return True


def first_reaching(curve, targets):
    """The labels of the first round whose means are <= every target ({measure: value})."""
    for i, x in enumerate(curve["labels"]):
        if all(curve[m] is not None and curve[m][i] <= t for m, t in targets.items()):
            return int(x)
    return None


def _means(seeds):
    """{labels, measure: mean per round (None if unmeasured)} on the rounds all seeds share."""
    n = min(len(s["labels"]) for _, s in seeds)
    out = {"labels": seeds[0][1]["labels"][:n]}
    for m in MEASURES:
        ys = np.array([s[m][:n] for _, s in seeds])
        out[m] = ys.mean(axis=0) if (ys >= 0).all() else None
    return out


def summary_table(by_strategy, paper):
    means = {k: _means(v) for k, v in by_strategy.items()}
    random = means.get("random")
    errors = ("under_conservative", "over_conservative")
    has_errors = all(means[k][m] is not None for k in means for m in errors)
    # Random's under-conservative error at its last round (the error the strategies differ on;
    # random's over-conservative error is often the lowest: it asks few near-dangerous states).
    random_target = {"under_conservative": random["under_conservative"][-1]} \
        if random and has_errors else None
    head = ("<tr><th>strategy</th><th>seeds</th><th>labels</th><th>under %</th><th>over %</th>"
            "<th>dangerous %</th><th>success %</th><th>labels to the paper's Table 1</th>"
            "<th>labels to random's last under-conservative error</th></tr>")
    rows = ""
    for k, c in means.items():
        def last(m):
            return "%.1f" % c[m][-1] if c[m] is not None else "&ndash;"
        to_paper = to_random = "&ndash;"
        if has_errors and paper:
            n = first_reaching(c, {"under_conservative": paper["under_conservative"],
                                   "over_conservative": paper["over_conservative"]})
            to_paper = str(n) if n is not None else "not reached"
        if random_target is not None:
            n = first_reaching(c, random_target)
            to_random = "not reached" if n is None else "%d (%.1f&times; fewer than random's %d)" \
                % (n, random["labels"][-1] / n, random["labels"][-1])
        rows += "<tr><td>%s</td><td>%d</td><td>%d</td><td>%s</td><td>%s</td><td>%s</td>" \
                "<td>%s</td><td>%s</td><td>%s</td></tr>" % (
                    html.escape(k), len(by_strategy[k]), int(c["labels"][-1]),
                    last("under_conservative"), last("over_conservative"), last("dangerous"),
                    last("success"), to_paper, to_random)
    return "<table>%s%s</table>" % (head, rows)


def _closed_loop_reference(report, run_dir, domain):
    """The paper's SECURE row of Table 3 for the domain: ({measure: %}, source) or ({}, why)."""
    table3, why = report.paper_table3(run_dir, {"experiment": {"domain": domain}})
    for row in (table3 or {}).get("rows", []):
        if str(row.get("method", "")).lower() == "secure":
            ref = {m: row[m] for m in ("dangerous", "success") if row.get(m) is not None}
            return ref, table3.get("source", "the paper")
    return {}, why or "the paper's Table 3 has no SECURE row for the %s domain" % domain


def build(report, run_dir, out_path, write_to=None):
    doc, by_strategy = load(report, run_dir)
    domain = str(doc.get("domain", "?"))
    opts = doc.get("options") if isinstance(doc.get("options"), dict) else {}
    fig_dir = report.prepare_figures(out_path, write_to, ["label_errors", "label_closed_loop"])
    page = report.Page(fig_dir)
    page.raw("<h1>SECURE label efficiency on %s</h1>" % html.escape(domain))
    growth = opts.get("k_growth", 1)
    log_x = isinstance(growth, (int, float)) and growth > 1
    k = "%s × %s^round" % (opts.get("k", "?"), growth) if log_x else opts.get("k", "?")
    page.p("Run directory <code>%s</code>: %s initial labels, then %s rounds of k = %s queries "
           "per strategy (pool %s, diversity radius %s), %s closed-loop episodes per round and %s "
           "at the last; labeller: %s; %.1f s."
           % (tuple(html.escape(str(v)) for v in (
               os.path.abspath(run_dir), opts.get("initial_labels", "?"),
               opts.get("rounds", "?"), k, opts.get("pool", "?"),
               opts.get("radius", "?"), opts.get("episodes", "?"),
               opts.get("final_episodes", "?"), doc.get("labeller", "?"))) +
           (float(doc.get("seconds", 0) or 0),)))
    paper = doc.get("paper") if isinstance(doc.get("paper"), dict) else None
    page.h2("1. Table 1's errors against labels used")
    if opts.get("errors_from_labeller"):
        page.note("This domain has no ground truth: the errors are against the labeller's "
                  "answers on the estimate states (the simulated person, not physics).")
    p_under = paper.get("under_conservative") if paper else None
    p_over = paper.get("over_conservative") if paper else None
    if not _figure(page, by_strategy, "label_errors",
                   [("under_conservative", "under-conservative (predicted safe | unsafe)",
                     p_under, "paper, full data (%s %%)" % p_under),
                    ("over_conservative", "over-conservative (predicted unsafe | safe)",
                     p_over, "paper, full data (%s %%)" % p_over)],
                   "Mean over seeds (shaded: &plusmn; one sample std) of Table 1's errors on the "
                   "estimate states of each round, one line per query strategy; dashed: the "
                   "paper's Table 1 with the full data set." if paper else
                   "Mean over seeds (shaded: &plusmn; one sample std); the paper has no Table 1 "
                   "for this domain.", log_x=log_x):
        page.note("No ground truth on the %s domain: the run measured no Table 1 error." % domain)
    page.h2("2. SECURE in closed loop against labels used")
    ref, source = _closed_loop_reference(report, run_dir, domain)
    if not _figure(page, by_strategy, "label_closed_loop",
                   [("dangerous", "dangerous episodes", ref.get("dangerous"),
                     "paper's SECURE (%s %%)" % ref.get("dangerous")),
                    ("success", "successful episodes", ref.get("success"),
                     "paper's SECURE (%s %%)" % ref.get("success"))],
                   "The shielded run with each round's barrier (mean over seeds, shaded &plusmn; "
                   "one sample std); dashed: %s." % html.escape(
                       "SECURE with the full data set, " + source if ref else
                       "none (" + str(source) + ")"), log_x=log_x):
        page.note("No closed-loop run on the %s domain (Domain::HasShieldRun is false): the run "
                  "measured no dangerous or success rate." % domain)
    page.h2("3. Per strategy")
    page.raw(summary_table(by_strategy, paper))
    page.p("Means over seeds at the last round; a count is the labels of the first round whose "
           "mean errors are at or below the target (the curves need not be monotone).", "note")
    report.finish_page(page, out_path, write_to, "SECURE label efficiency on %s" % domain)
    return page.figures
