"""The method comparison: the Figure 9-style bars with the run's significance marks, the table of
the run's tests, and Table 3 beside the paper's numbers (from the registry: secure.paper_reference,
or the run directory's paper_reference.json; hints.py)."""
import html
import math

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

METHOD_LABELS = {
    "bc": "BC", "airl": "AIRL", "secure": "SECURE", "secure-random-safe": "random safe",
    "secure-no-resampling": "no resampling", "bc+shield": "BC + shield",
    "secure-myopic": "myopic", "joint": "joint", "cbf-qp": "CBF-QP",
    "secure-qp": "gradient-first", "first-safe": "first-safe", "cbf-grad": "gradient refinement",
}
METHOD_ORDER = ["bc", "airl", "secure", "secure-random-safe", "secure-no-resampling",
                "secure-myopic", "bc+shield", "joint", "cbf-qp", "secure-qp", "first-safe",
                "cbf-grad"]
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
    # "<a>_vs_<b>": SECURE vs AIRL, and the other safety filters (cbf-qp, secure-qp,
    # first-safe, cbf-grad) vs SECURE.
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
    if mean is None:
        return "&ndash;"
    return "%.1f" % mean if std is None else "%.1f (%.1f)" % (mean, std)


def table3(evaluation, domain, paper, why_none):
    """This run's rates beside the paper's (`paper`: the domain's Table 3 row from the registry,
    hints.paper_reference; None: a note saying `why_none`)."""
    methods = evaluation["methods"]
    theirs = {r["method"]: r for r in paper["rows"]} if paper else {}
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
            r = theirs.get(m)
            if r is not None:
                row += "<td>%s</td><td>%s</td>" % (paper_cell(r["success"], r["success_std"]),
                                                   paper_cell(r["dangerous"], r["dangerous_std"]))
            else:
                row += "<td>&ndash;</td><td>&ndash;</td>"
        out.append("<tr>%s</tr>" % row)
    out.append("</table>")
    if paper:
        out.append("<p>Paper (the SECURE paper, for %s): %s; its comparison: %s.</p>"
                   % (html.escape(domain), html.escape(paper["source"]),
                      html.escape(paper["comparison"] or "none given")))
    else:
        out.append('<p class="note">No paper numbers (Table 3) beside this run: %s.</p>'
                   % html.escape(why_none))
    return "".join(out)
