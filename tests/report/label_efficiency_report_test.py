#!/usr/bin/python3
"""ctest `report_label_efficiency` (label `report`): `secure report` on a label-efficiency run
directory (issue 35; tools/report/label_efficiency_page.py).

A quick run (double integrator, random and margin, 2 seeds) gets its page: both figures embedded,
written next to the page and non-blank, the paper's reference line named, the table's last-round
means equal to result.json's. Constructed curves check the table's counts (labels to the paper's
Table 1; labels to random's last under-conservative error, and how many times fewer), a note
instead of the closed-loop figure when the run has no closed-loop rates, and bad result.json values
as one line naming the field. Environment as report_test.py (whose helpers this uses).
"""
import json
import os
import shutil
import sys

from report_test import CLI, WORK, check, failures, figure_problems, run


def label_efficiency():
    """A label-efficiency run directory (issue 35) gets its own page: error and closed-loop rates
    against labels used, one line per strategy with the spread over seeds, the paper's Table 1 as
    the reference line, and a table of the labels each strategy needs."""
    run_dir = os.path.join(WORK, "label-efficiency")
    r = run([CLI, "experiment", "label-efficiency", "--domain", "double-integrator", "--quick",
             "--strategies", "random,margin", "--threads", "2", "--out", run_dir])
    if not check(r.returncode == 0, "the quick label-efficiency run failed: " + r.stderr[-2000:]):
        return
    r = run([CLI, "report", run_dir])
    page = os.path.join(run_dir, "report.html")
    if not check(r.returncode == 0 and os.path.isfile(page),
                 "secure report on the label-efficiency run failed: " + r.stderr[-3000:]):
        return
    with open(page, encoding="utf-8") as f:
        text = f.read()
    for p in figure_problems(text, os.path.join(run_dir, "report_figures"),
                             ["label_errors", "label_closed_loop"]):
        check(False, "label efficiency: " + p)
    check("paper's Table 1 with the full data set" in text,
          "the error figure does not name the paper's reference line")
    with open(os.path.join(run_dir, "result.json")) as f:
        doc = json.load(f)
    for strategy in ("random", "margin"):  # the table's last-round mean, from result.json
        last = [c["points"][-1]["under_conservative"] for c in doc["curves"]
                if c["strategy"] == strategy]
        check(len(last) == 2 and "<tr><td>%s</td><td>2</td><td>30</td><td>%.1f</td>"
              % (strategy, sum(last) / 2) in text,
              "the table's row of %s does not show its mean under-conservative error" % strategy)

    # Constructed curves: the counts of the table (labels to the paper's Table 1, labels to
    # random's error at its last round and how many times fewer).
    made = os.path.join(WORK, "label-efficiency-made")
    os.makedirs(made)

    def curve(strategy, seed, under, over):
        return {"strategy": strategy, "seed": seed, "points": [
            {"round": i, "labels": 20 * (i + 1), "under_conservative": u, "over_conservative": o,
             "dangerous": -1, "success": -1} for i, (u, o) in enumerate(zip(under, over))]}
    made_doc = {"experiment": "label-efficiency", "domain": "double-integrator",
                "paper": {"under_conservative": 4.1, "over_conservative": 1.9}, "curves": [
                    curve("random", 0, [30, 20, 10], [5, 4, 3]),
                    curve("random", 1, [30, 20, 10], [5, 4, 3]),
                    curve("margin", 0, [20, 9, 3], [4, 3, 1.5]),
                    curve("margin", 1, [20, 11, 3], [4, 3, 1.5])]}

    def report_on(doc):
        """`secure report` on `doc` as made/result.json: (the process, the page or "")."""
        with open(os.path.join(made, "result.json"), "w") as f:
            json.dump(doc, f)
        r = run([CLI, "report", made])
        if r.returncode != 0:
            return r, ""
        with open(os.path.join(made, "report.html"), encoding="utf-8") as f:
            return r, f.read()

    r, mtext = report_on(made_doc)
    if check(r.returncode == 0, "secure report on constructed curves failed: " + r.stderr):
        check("<td>60</td><td>40 (1.5&times; fewer than random&#x27;s 60)</td>" in mtext or
              "<td>60</td><td>40 (1.5&times; fewer than random's 60)</td>" in mtext,
              "margin's counts (paper's Table 1 at 60, random's error at 40) are not in the table")
        check("No closed-loop run" in mtext and 'id="fig-label_closed_loop"' not in mtext,
              "curves without closed-loop rates do not get a note instead of a figure")
        check("× 2^round" not in mtext and "log scale" not in mtext,
              "a run without k_growth is described as growing")
    # Rounds growing by k_growth = 2: the page says so and draws labels on a log scale.
    r, mtext = report_on(dict(made_doc, options={"initial_labels": 20, "rounds": 2, "k": 20,
                                                 "k_growth": 2}))
    if check(r.returncode == 0, "secure report on growing rounds failed: " + r.stderr):
        check("2 rounds of k = 20 × 2^round queries" in mtext,
              "the page does not state the growing rounds (k × k_growth^round)")
        check("Labels on a log scale" in mtext, "growing rounds are not drawn on a log scale")
    # A rate outside [0, 100] and a run without curves: one line naming the file and the field.
    made_doc["curves"][1]["points"][2]["under_conservative"] = 150
    r, _ = report_on(made_doc)
    check(r.returncode == 1 and len(r.stderr.strip().splitlines()) == 1 and
          "curves[1].points[2].under_conservative' = 150" in r.stderr,
          "a rate of 150 %%: expected one line naming the field, got %d %r"
          % (r.returncode, r.stderr))
    made_doc["curves"] = []
    r, _ = report_on(made_doc)
    check(r.returncode == 1 and "holds no curve" in r.stderr and "result.json" in r.stderr,
          "a run without curves: expected one line naming result.json, got %r" % r.stderr)

if __name__ == "__main__":
    shutil.rmtree(WORK, ignore_errors=True)
    os.makedirs(WORK)
    label_efficiency()
    if failures:
        print("%d check(s) failed" % len(failures), file=sys.stderr)
        sys.exit(1)
    print("report_label_efficiency: all checks passed")
