#!/usr/bin/python3
"""secure report RUN_DIR: one self-contained HTML page for a run directory.

A run directory is what `secure demo --out DIR` and `secure experiment KIND --domain D --out DIR`
write (docs/FILE_FORMATS.md, "Experiment output"): result.json, seed-<k>/ with the models and the
learning-curve CSVs, the data CSVs. The page embeds every figure as base64 PNG (one file, no
external references); the same figures are also written as PNG files into <page>_figures/.

Usage:  /usr/bin/python3 tools/report/report.py RUN_DIR [--out FILE.html]
        (`secure report RUN_DIR` runs this script; tools/report/README.md)

Figures: the method comparison (Figure 9 style: mean +- std over seeds, the run's significance
marks) beside the paper's Table 3 numbers, learning curves, sensitivity / ablation variants, and
the learned barrier and trajectories of AIRL and SECURE with the shield's interventions marked,
and the run directory's *.mp4 videos (embedded as base64 up to 20 MB each). The report names no
domain: the paper's numbers and how to draw a domain (its picture hints) come from the registry
through the Python module `secure` (hints.py); a domain without hints gets a note. Matplotlib
with the Agg backend (no display). Errors: one line `secure report: error: ...` naming the file,
exit 1. One module per job: run_dir.py, page.py, comparison.py, curves.py, hints.py, shapes.py,
barrier_picture.py, trajectories.py.
"""
import argparse
import html
import os
import sys

from barrier_picture import barrier_section
from comparison import comparison_figure, table3, tests_table
from curves import barrier_training_figure, check_curves, curves_figure, variants_figure
from hints import paper_table3, report_hints
from page import STYLE, Page, open_fifo_for_writing, output_kind, write_output
from run_dir import ReportError, load_run
from trajectories import trajectories_section

FIGURE_NAMES = ["comparison", "learning_curves", "barrier_training", "sensitivity", "barrier",
                "trajectories"]


def prepare_figures(out_path, write_to, names):
    """The figures' directory next to the page (None for a device or a FIFO: the figures are
    embedded only), with last time's figures `names` removed; the output checked first (a
    directory or a FIFO without a reader fails before any work)."""
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
        for name in names:  # a figure this run does not get must not survive
            old = os.path.join(fig_dir, name + ".png")
            if os.path.isfile(old):
                os.remove(old)
    return fig_dir


def finish_page(page, out_path, write_to, title):
    """Writes the page: to `write_to` (`secure report`'s scratch file, which its C++ writer
    installs) or to out_path by the C++ writers' rules."""
    doc = ("<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>%s</title>"
           "<style>%s</style></head><body>\n%s\n</body></html>\n"
           % (html.escape(title), STYLE, "\n".join(page.parts)))
    if write_to is not None:  # `secure report`: its C++ writer installs the page
        with open(write_to, "w", encoding="utf-8") as f:
            f.write(doc)
    else:
        write_output(out_path, doc)


def build_report(run_dir, out_path, write_to=None):
    result = load_run(run_dir)
    check_curves(run_dir)  # every input checked before anything is written
    exp = result["experiment"]
    domain = str(exp.get("domain", "?"))
    kind = str(exp.get("kind", "?"))
    fig_dir = prepare_figures(out_path, write_to, FIGURE_NAMES)
    page = Page(fig_dir)
    # What the registry says of the domain (a malformed file in the run directory is an error).
    paper, why_no_paper = paper_table3(run_dir, result)
    hints, why_no_hints = report_hints(run_dir, result)
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
        page.raw(table3(result, domain, paper, why_no_paper))
        page.raw(tests_table(result))
    else:
        baseline = (result.get("variants") or {}).get("baseline")
        if isinstance(baseline, dict) and isinstance(baseline.get("methods"), dict):
            comparison_figure(page, baseline, "baseline barrier data", "comparison")
            page.raw(table3(baseline, domain, paper, why_no_paper))
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
    barrier_section(page, run_dir, result, hints, why_no_hints)

    page.h2("5. Trajectories")
    trajectories_section(page, run_dir, result, out_path, hints, why_no_hints)

    finish_page(page, out_path, write_to, "SECURE report: %s on %s" % (kind, domain))
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
        import label_efficiency_page  # tools/report/label_efficiency_page.py (issue 35)
        if reproduce_page.is_reproduce_dir(args.run_dir):
            figures = reproduce_page.build(sys.modules[__name__], args.run_dir, out,
                                           args.write_to)
        elif label_efficiency_page.is_label_efficiency_dir(args.run_dir):
            figures = label_efficiency_page.build(sys.modules[__name__], args.run_dir, out,
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
