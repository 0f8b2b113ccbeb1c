"""The page of a `secure reproduce --out DIR` directory (report.py calls build() when DIR holds
reproduce.json instead of result.json).

One page: the plan (every study on every domain, where the paper has it, what the run did, its
time), then per study its table in the paper's form as the library wrote it (beside the paper's
numbers where the domain has them), and for each experiment run (a run directory with an
experiment's result.json) its comparison figure embedded and a link to the run's own page, which
report.py writes into the run directory (DIR/<domain>/<study>/report.html) with every figure.
"""
import base64
import html
import json
import os


def is_reproduce_dir(path):
    return (os.path.isdir(path) and not os.path.exists(os.path.join(path, "result.json"))
            and os.path.isfile(os.path.join(path, "reproduce.json")))


def load_plan(report, parent):
    path = os.path.join(parent, "reproduce.json")
    try:
        with open(path, "rb") as f:
            doc = json.loads(f.read().decode("utf-8"))
    except (UnicodeDecodeError, ValueError) as e:
        raise report.ReportError("%s: malformed JSON: %s" % (path, e))
    if not isinstance(doc, dict) or not isinstance(doc.get("tasks"), list):
        raise report.ReportError("%s: no list 'tasks': not written by `secure reproduce`" % path)
    for i, t in enumerate(doc["tasks"]):
        if not isinstance(t, dict) or not all(isinstance(t.get(k), str)
                                              for k in ("domain", "study", "dir")):
            raise report.ReportError("%s: tasks[%d] lacks 'domain', 'study' or 'dir'" % (path, i))
        if os.path.isabs(t["dir"]) or ".." in t["dir"].split("/"):
            raise report.ReportError("%s: tasks[%d].dir = '%s' is not inside %s"
                                     % (path, i, t["dir"], parent))
    return doc


def build(report, parent, out_path, write_to=None):
    doc = load_plan(report, parent)
    page = report.Page(None)
    page.raw("<h1>SECURE: the paper reproduced (%s profile)</h1>"
             % html.escape(str(doc.get("profile", "?"))))
    rows = ""
    for t in doc["tasks"]:
        seconds = t.get("seconds")
        rows += "<tr><td>%s</td><td>%s</td><td>%s</td><td>%s</td><td>%s</td></tr>" % (
            html.escape(str(t.get("paper", ""))), html.escape(t["study"]),
            html.escape(t["domain"]), html.escape(str(t.get("status", ""))),
            "%.1f" % seconds if isinstance(seconds, (int, float)) else "")
    page.p("Directory <code>%s</code>: %d studies, %.1f s in the last run."
           % (html.escape(os.path.abspath(parent)), len(doc["tasks"]),
              float(doc.get("seconds", 0.0) or 0.0)))
    page.raw("<table><tr><th>paper</th><th>study</th><th>domain</th><th>this run</th>"
             "<th>s</th></tr>%s</table>" % rows)
    figures = []
    for t in doc["tasks"]:
        run_dir = os.path.join(parent, t["dir"])
        page.h2("%s: %s on %s" % (t.get("paper", ""), t["study"], t["domain"]))
        table = t.get("table")
        if isinstance(table, str) and table:
            page.raw("<pre>%s</pre>" % html.escape(table))
        else:
            page.note("No table (a sharded run: run `secure reproduce` unsharded to merge).")
        try:
            report.load_run(run_dir)
        except report.ReportError:
            continue  # not an experiment's run directory (Table 1, the user study): the table
        run_page = os.path.join(run_dir, "report.html")
        figures += [os.path.join(t["dir"], f) for f in report.build_report(run_dir, run_page)]
        png = os.path.join(run_dir, "report_figures", "comparison.png")
        if os.path.isfile(png):
            with open(png, "rb") as f:
                data = base64.b64encode(f.read()).decode("ascii")
            page.raw('<figure><img alt="comparison" src="data:image/png;base64,%s">'
                     '<figcaption>The comparison of %s on %s (every figure: <a href="%s">its '
                     'page</a>).</figcaption></figure>'
                     % (data, html.escape(t["study"]), html.escape(t["domain"]),
                        html.escape(os.path.relpath(run_page, os.path.dirname(
                            os.path.abspath(out_path))))))
    doc_html = ("<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>SECURE: the paper "
                "reproduced</title><style>%s</style></head><body>\n%s\n</body></html>\n"
                % (report.STYLE, "\n".join(page.parts)))
    if write_to is not None:
        with open(write_to, "w", encoding="utf-8") as f:
            f.write(doc_html)
    else:
        report.write_output(out_path, doc_html)
    return figures
