#!/usr/bin/python3
"""ctest `report_html` (label `report`): `secure report` as a user sees it.

A quick method comparison on the double integrator writes a run directory; `secure report` turns
it into report.html; headless Chromium renders the page to a PNG. Checked: every expected figure
is embedded (an <img> with a base64 PNG) and written next to the page, none is blank (pixel
variance), the screenshot is not uniform and shows the figures' colours; the checker itself
fails on a page with a figure removed; bad run directories are one-line errors naming the file,
exit 1. Environment (set by tests/CMakeLists.txt): SECURE_CLI (the binary), SECURE_REPORT_WORK
(a scratch directory), SECURE_EXPECT_BARRIER=1 when the Python module is built (then the
barrier picture and the trajectories are required too), CHROMIUM (default `chromium`). A fake
.mp4 in the run directory must appear as an embedded <video> (one over the size cap as a link).
"""
import base64
import io
import json
import os
import re
import shutil
import subprocess
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.image as mpimg  # noqa: E402
import numpy as np  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from script_checks import check, exit_status, failures  # noqa: E402,F401 (label_efficiency_report_test)

CLI = os.environ["SECURE_CLI"]
WORK = os.environ["SECURE_REPORT_WORK"]
EXPECT_BARRIER = os.environ.get("SECURE_EXPECT_BARRIER") == "1"
CHROMIUM = os.environ.get("CHROMIUM", "chromium")


def run(args, **kw):
    return subprocess.run(args, capture_output=True, text=True, timeout=120, **kw)


def non_blank(png_bytes):
    """True if the PNG's pixels vary (a blank or uniform image has no variance)."""
    img = mpimg.imread(io.BytesIO(png_bytes), format="png")
    return img.size > 0 and float(np.std(img[..., :3])) > 0.02


def figure_problems(html_text, fig_dir, expected):
    """What is missing or blank, as a list of messages (empty: all good)."""
    problems = []
    imgs = dict(re.findall(r'<img id="fig-([a-z_]+)"[^>]*src="data:image/png;base64,([^"]+)"',
                           html_text))
    for name in expected:
        if name not in imgs:
            problems.append("figure %s is not embedded in the page" % name)
        elif not non_blank(base64.b64decode(imgs[name])):
            problems.append("embedded figure %s is blank" % name)
        path = os.path.join(fig_dir, name + ".png")
        if not os.path.isfile(path):
            problems.append("figure file %s is missing" % path)
        else:
            with open(path, "rb") as f:
                if not non_blank(f.read()):
                    problems.append("figure file %s is blank" % path)
    if re.search(r'src="(?!data:)', html_text):
        problems.append("the page references an external file (not self-contained)")
    return problems


def main():
    shutil.rmtree(WORK, ignore_errors=True)
    os.makedirs(WORK)
    run_dir = os.path.join(WORK, "run")
    r = run([CLI, "experiment", "method-comparison", "--domain", "double-integrator", "--quick",
             "--out", run_dir])
    if not check(r.returncode == 0, "the quick experiment failed: " + r.stderr[-2000:]):
        return

    r = run([CLI, "report", run_dir])
    check(r.returncode == 0, "secure report failed: " + r.stderr[-3000:])
    page = os.path.join(run_dir, "report.html")
    check(page in r.stdout, "secure report does not print the page's path: " + r.stdout)
    if not check(os.path.isfile(page), "no report.html"):
        return
    with open(page, encoding="utf-8") as f:
        text = f.read()
    expected = ["comparison", "learning_curves", "barrier_training"]
    if EXPECT_BARRIER:
        expected += ["barrier", "trajectories"]
        check("Python module `secure` is not available" not in text,
              "the barrier picture was skipped though the module is built")
    else:
        check("No barrier picture" in text, "the page does not say the barrier picture is skipped")
    fig_dir = os.path.join(run_dir, "report_figures")
    for p in figure_problems(text, fig_dir, expected):
        check(False, p)
    if EXPECT_BARRIER:
        check("the steps where the shield intervened" in text,
              "the trajectories' caption does not explain the intervention markers")
    check("<video" not in text, "a video is embedded though the run directory holds no .mp4")
    check("Table 3" in text, "the page has no Table 3 section")
    check("Mann-Whitney" in text, "the page does not list the run's tests")

    # The checker notices a missing figure (so the checks above can fail).
    broken = re.sub(r'<img id="fig-learning_curves"[^>]*>', "", text)
    check(any("learning_curves" in p for p in figure_problems(broken, fig_dir, expected)),
          "the checker does not notice a figure removed from the page")

    # Videos: each RUN_DIR/*.mp4 is embedded as an HTML5 video (a data URI; the bytes are not
    # decoded here), one over the size cap is linked relatively instead.
    with open(os.path.join(run_dir, "episode-0.mp4"), "wb") as f:
        f.write(b"\x00\x00\x00\x18ftypmp42not-a-real-video")
    with open(os.path.join(run_dir, "huge.mp4"), "wb") as f:
        f.truncate(21 * 1000 * 1000)  # sparse: over the 20 MB cap
    video_page = os.path.join(WORK, "video-report.html")
    r = run([CLI, "report", run_dir, "--out", video_page])
    if check(r.returncode == 0 and os.path.isfile(video_page),
             "secure report with videos failed: " + r.stderr[-3000:]):
        with open(video_page, encoding="utf-8") as f:
            vtext = f.read()
        embedded = re.findall(r'<video controls[^>]*src="data:video/mp4;base64,([^"]+)"', vtext)
        check(len(embedded) == 1 and base64.b64decode(embedded[0]).endswith(b"not-a-real-video"),
              "episode-0.mp4 is not embedded as a <video> with a data URI")
        check("<figcaption>episode-0.mp4</figcaption>" in vtext,
              "the embedded video has no caption naming the file")
        check('href="run/huge.mp4"' in vtext and "over the 20 MB" in vtext,
              "the video over the cap is not linked relatively with a note")
        check(not re.search(r'src="(?!data:)', vtext), "the video page references an external file")
    os.remove(os.path.join(run_dir, "episode-0.mp4"))
    os.remove(os.path.join(run_dir, "huge.mp4"))

    # Success constant over the seeds on both sides (0 % against 0 %): TOST's standard error is
    # 0 and its p-value meaningless; the page says the test is not informative.
    flat = os.path.join(WORK, "flat")
    shutil.copytree(run_dir, flat)
    with open(os.path.join(flat, "result.json")) as f:
        doc = json.load(f)
    tosts = []

    def zero_se(node):
        if isinstance(node, dict):
            for key, value in node.items():
                if key == "success_tost" and isinstance(value, dict):
                    value["se"], value["p_value"] = 0.0, 0.0
                    tosts.append(value)
                zero_se(value)
        elif isinstance(node, list):
            for value in node:
                zero_se(value)

    zero_se(doc)

    # Every "<a>_vs_<b>" comparison is listed (the other safety filters against SECURE, issue 37).
    def add_filter_comparison(node):
        if isinstance(node, dict):
            if isinstance(node.get("comparisons"), dict) and "secure_vs_airl" in node["comparisons"]:
                node["comparisons"]["cbf-qp_vs_secure"] = node["comparisons"]["secure_vs_airl"]
            for value in node.values():
                add_filter_comparison(value)

    add_filter_comparison(doc)
    if check(tosts, "result.json has no success_tost to alter"):
        with open(os.path.join(flat, "result.json"), "w") as f:
            json.dump(doc, f)
        r = run([CLI, "report", flat])
        if check(r.returncode == 0, "secure report on the flat run failed: " + r.stderr[-2000:]):
            with open(os.path.join(flat, "report.html"), encoding="utf-8") as f:
                ftext = f.read()
            check("not informative" in ftext,
                  "a TOST with standard error 0 is not called uninformative")
            check("<td>CBF-QP vs SECURE</td>" in ftext,
                  "the cbf-qp_vs_secure comparison is not in the tests table")

    # As a user sees it: headless Chromium's screenshot of the page.
    shot = os.path.join(WORK, "screenshot.png")
    r = run([CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
             "--screenshot=" + shot, "--window-size=1200,3000", "file://" + page])
    if check(os.path.isfile(shot), "chromium wrote no screenshot: " + r.stderr[-2000:]):
        img = mpimg.imread(shot)[..., :3]
        check(float(np.std(img)) > 0.05, "the screenshot is (nearly) uniform")
        # The success bars' colour (#2a9d8f) and the dangerous bars' (#e76f51) are on screen.
        for hexcolor in ("2a9d8f", "e76f51"):
            rgb = np.array([int(hexcolor[i:i + 2], 16) / 255.0 for i in (0, 2, 4)])
            count = int((np.abs(img - rgb).max(axis=2) < 0.03).sum())
            check(count > 2000, "the screenshot shows %d pixels of #%s (the comparison's bars)"
                  % (count, hexcolor))

    # Bad input: one line naming the file, exit 1.
    not_dir = os.path.join(WORK, "plain-file")
    with open(not_dir, "w") as f:
        f.write("x")
    empty = os.path.join(WORK, "empty")
    os.makedirs(empty)
    bad = os.path.join(WORK, "bad")
    os.makedirs(bad)
    with open(os.path.join(bad, "result.json"), "w") as f:
        f.write('{"experiment": {')
    other = os.path.join(WORK, "other")
    os.makedirs(other)
    with open(os.path.join(other, "result.json"), "w") as f:
        f.write('{"a": 1}')
    # Numbers the page would show, checked: no method, a rate as a string, a rate of 7.
    with open(os.path.join(run_dir, "result.json")) as f:
        good = json.load(f)
    edited = {}
    for name, change in (("no_methods", lambda r: r.update(methods={})),
                         ("string_rate", lambda r: r["methods"]["bc"]["success_rate"].update(
                             mean="0.5")),
                         ("rate_7", lambda r: r["methods"]["bc"]["success_rate"]["per_seed"]
                          .__setitem__(0, 7.0)),
                         # Issue 34: the other fields the page shows, typed and in range.
                         ("empty_objects", lambda r: (r.clear(), r.update(experiment={},
                                                                        methods={}))),
                         ("negative_std", lambda r: r["methods"]["bc"]["success_rate"].update(
                             std=-1)),
                         ("string_seeds", lambda r: r["experiment"].setdefault(
                             "options", {}).update(seeds="2")),
                         ("string_p", lambda r: r["comparisons"]["secure_vs_airl"][
                             "success_mann_whitney"].update(p_value="0.01"))):
        d = os.path.join(WORK, name)
        os.makedirs(d)
        r = json.loads(json.dumps(good))
        change(r)
        with open(os.path.join(d, "result.json"), "w") as f:
            json.dump(r, f)
        edited[name] = d
    # Garbage curve CSVs.
    curve = os.path.join("seed-0", "bc_curve.csv")
    for name, text in (("curve_garbage", "\x00\x01garbage\n"),
                       ("curve_text", "epoch,train_nll\n1,0.5\n2,lots\n"),
                       ("curve_nan", "epoch,train_nll\n1,nan\n"),
                       ("curve_short_row", "epoch,train_nll\n1,0.5\n2\n"),
                       ("curve_repeated", "epoch,epoch\n1,2\n"),
                       ("curve_empty", "")):
        d = os.path.join(WORK, name)
        shutil.copytree(run_dir, d, ignore=shutil.ignore_patterns("report*"))
        with open(os.path.join(d, curve), "w") as f:
            f.write(text)
        edited[name] = d
    for path, named, what in ((edited["empty_objects"], "result.json", "holds no method"),
                              (edited["negative_std"], "success_rate.std' = -1", "in [0, 1]"),
                              (edited["string_seeds"], "options.seeds' = \"2\"", "an integer"),
                              (edited["string_p"], "p_value' = \"0.01\"", "in [0, 1]"),
                              (edited["curve_garbage"], curve + ": line 1: column 1",
                               "not a column name"),
                              (edited["curve_text"], curve + ": line 3: column 'train_nll'",
                               "value \"lots\" is not a finite number"),
                              (edited["curve_nan"], curve + ": line 2", "\"nan\" is not a finite"),
                              (edited["curve_short_row"], curve + ": line 3", "1 cells, but"),
                              (edited["curve_repeated"], curve + ": line 1: column 2",
                               "is repeated"),
                              (edited["curve_empty"], curve, "empty file"),
                              (edited["no_methods"], "result.json", "holds no method"),
                              (edited["string_rate"], "success_rate.mean' = \"0.5\"",
                               "must be a rate in [0, 1]"),
                              (edited["rate_7"], "per_seed[0]' = 7.0", "must be a rate"),
                              (os.path.join(WORK, "missing"), "missing", "no such directory"),
                              (not_dir, not_dir, "not a directory"),
                              (empty, os.path.join(empty, "result.json"), "missing"),
                              (bad, os.path.join(bad, "result.json"), "malformed JSON"),
                              (other, os.path.join(other, "result.json"), "experiment")):
        r = run([CLI, "report", path])
        lines = r.stderr.strip().splitlines()
        check(r.returncode == 1, "%s: exit code %d, expected 1" % (path, r.returncode))
        check(len(lines) == 1 and named in lines[0] and what in lines[0],
              "%s: expected one line naming %s (%s), got %r" % (path, named, what, r.stderr))
        check(not os.path.exists(os.path.join(path, "report.html")),
              "%s: a page was written for a bad run directory" % path)

    output_rules(run_dir)


def output_rules(run_dir):
    """The page is written as every C++ writer writes (issue 34): through `secure report` (its
    C++ writer) and by the script run alone (its own copy of the rules)."""
    import glob
    import stat as st
    out = os.path.join(WORK, "outputs")
    os.makedirs(out)
    script = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "tools",
                          "report", "report.py")
    for tag, command in (("cli", [CLI, "report", run_dir, "--out"]),
                         ("script", [sys.executable, script, run_dir, "--out"])):
        d = os.path.join(out, tag)
        os.makedirs(os.path.join(d, "a_directory"))
        os.mkfifo(os.path.join(d, "fifo"))
        os.symlink("/dev/null", os.path.join(d, "null.html"))
        with open(os.path.join(d, "target.html"), "w") as f:
            f.write("old")
        os.symlink("target.html", os.path.join(d, "link.html"))
        with open(os.path.join(d, "private.html"), "w") as f:
            f.write("old")
        os.chmod(os.path.join(d, "private.html"), 0o640)
        for name, want in (("a_directory", "it is a directory, not a regular file"),
                           ("fifo", "no process has open for reading")):
            try:
                r = subprocess.run(command + [os.path.join(d, name)], capture_output=True,
                                   text=True, timeout=120)
            except subprocess.TimeoutExpired:
                check(False, "%s --out %s: hangs" % (tag, name))
                continue
            lines = r.stderr.strip().splitlines()
            check(r.returncode == 1 and len(lines) == 1 and want in lines[0] and
                  os.path.join(d, name) in lines[0],
                  "%s --out %s: expected exit 1 and one line with %r, got %d %r"
                  % (tag, name, want, r.returncode, r.stderr))
            if tag == "cli":
                check(lines[0].startswith("secure: error: ") if lines else False,
                      "%s --out %s: not a 'secure: error:' line: %r" % (tag, name, r.stderr))
        check(os.path.isdir(os.path.join(d, "a_directory")) and
              not os.listdir(os.path.join(d, "a_directory")), "%s: the directory changed" % tag)
        check(st.S_ISFIFO(os.lstat(os.path.join(d, "fifo")).st_mode), "%s: the FIFO is gone" % tag)
        for name in ("null.html", "link.html", "private.html"):
            r = run(command + [os.path.join(d, name)])
            check(r.returncode == 0, "%s --out %s failed: %s" % (tag, name, r.stderr[-2000:]))
        check(os.path.islink(os.path.join(d, "null.html")) and
              st.S_ISCHR(os.stat("/dev/null").st_mode), "%s: /dev/null through a link" % tag)
        check(os.path.islink(os.path.join(d, "link.html")), "%s: the symlink was replaced" % tag)
        with open(os.path.join(d, "target.html"), encoding="utf-8") as f:
            check(f.read().startswith("<!DOCTYPE html>"), "%s: not written through the link" % tag)
        check(st.S_IMODE(os.stat(os.path.join(d, "private.html")).st_mode) == 0o640,
              "%s: the page's mode 0640 was not kept" % tag)
        left = glob.glob(os.path.join(d, "*.tmp-*")) + glob.glob(os.path.join(d, "*", "*.tmp-*"))
        check(not left, "%s: temporary files left behind: %s" % (tag, left))


if __name__ == "__main__":
    main()
    sys.exit(exit_status("report_html: all checks passed"))
