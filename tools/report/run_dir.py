"""Reading a run directory (docs/FILE_FORMATS.md, "Experiment output") for the report: result.json
checked (rates in [0, 1], std in [0, 1], p-values in [0, 1] or null, counts non-negative
integers, names strings), the seeds' directories, curve CSVs and state CSVs (a header of distinct
names, rows of as many finite decimal numbers). Inputs must be regular files within the input
limit. Every problem is a ReportError naming the file, the field or line and the value."""
import csv
import json
import math
import os
import re
import stat

import numpy as np


class ReportError(Exception):
    pass


# A cell of a CSV the report reads: a decimal number (no "nan", "inf", "1_000" or spaces, which
# Python's float() would take).
NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_.\[\]-]*\Z")
NUMBER = re.compile(r"[+-]?([0-9]+\.?[0-9]*|\.[0-9]+)([eE][+-]?[0-9]+)?\Z")


def max_input_bytes():
    """The input limit of the C++ readers (secure/common/input_limits.h)."""
    text = os.environ.get("SECURE_MAX_INPUT_BYTES", "")
    return int(text) if text.isdigit() and int(text) > 0 else 4 << 30


def check_input(path):
    """A regular file within the input limit (a FIFO would block, /dev/zero never ends)."""
    try:
        info = os.stat(path)
    except OSError as e:
        raise ReportError("%s: cannot read: %s" % (path, e.strerror))
    if not stat.S_ISREG(info.st_mode):
        raise ReportError("%s: not a regular file" % path)
    if info.st_size > max_input_bytes():
        raise ReportError("%s: %d bytes, more than the input limit of %d bytes (raise it with "
                          "SECURE_MAX_INPUT_BYTES)" % (path, info.st_size, max_input_bytes()))


def shown(value):
    """A value from a file, for a message: JSON, cut at 80 characters."""
    text = json.dumps(value)
    return text if len(text) <= 80 else text[:77] + "..."


def _number(path, where, v, low=None, high=None, integer=False, none_ok=False):
    if v is None and none_ok:
        return
    ok = not isinstance(v, bool) and isinstance(v, (int, float)) and math.isfinite(v)
    ok = ok and (not integer or float(v).is_integer())
    ok = ok and (low is None or v >= low) and (high is None or v <= high)
    if not ok:
        what = "an integer" if integer else "a finite number"
        bounds = " in [%s, %s]" % (low, high) if high is not None else \
            (" >= %s" % low if low is not None else "")
        raise ReportError("%s: '%s' = %s, must be %s%s" % (path, where, shown(v), what, bounds))


def _check_experiment(path, exp):
    for key in ("domain", "kind"):
        if key in exp and not isinstance(exp[key], str):
            raise ReportError("%s: 'experiment.%s' = %s, must be a string"
                              % (path, key, shown(exp[key])))
    for key in ("seconds", "demonstrations", "safe_states", "near_dangerous_states"):
        if key in exp:
            _number(path, "experiment." + key, exp[key], low=0, integer=key != "seconds")
    opts = exp.get("options")
    if opts is not None and not isinstance(opts, dict):
        raise ReportError("%s: 'experiment.options' = %s, must be an object" % (path, shown(opts)))
    for key in ("seeds", "episodes"):
        if isinstance(opts, dict) and key in opts:
            _number(path, "experiment.options." + key, opts[key], low=0, integer=True)


def _check_p_values(path, where, node, depth=0):
    """Every p_value / p_adjusted under `node` (the comparisons) is null or in [0, 1]."""
    if depth > 64:
        raise ReportError("%s: '%s' is nested more than 64 levels deep" % (path, where))
    items = node.items() if isinstance(node, dict) else \
        enumerate(node) if isinstance(node, list) else ()
    for key, value in items:
        here = "%s.%s" % (where, key) if isinstance(node, dict) else "%s[%d]" % (where, key)
        if key in ("p_value", "p_adjusted"):
            _number(path, here, value, low=0, high=1, none_ok=True)
        else:
            _check_p_values(path, here, value, depth + 1)


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
    check_input(path)
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
                if "per_seed" in r and not isinstance(r["per_seed"], list):
                    raise ReportError("%s: '%s.%s.%s.per_seed' = %s, must be a list of rates"
                                      % (path, where, name, rate, shown(r["per_seed"])))
                for key, v in values:
                    if isinstance(v, bool) or not isinstance(v, (int, float)) or \
                            not 0.0 <= v <= 1.0:
                        raise ReportError("%s: '%s.%s.%s.%s' = %s, must be a rate in [0, 1]"
                                          % (path, where, name, rate, key, shown(v)))
                if "std" in r:
                    _number(path, "%s.%s.%s.std" % (where, name, rate), r["std"], low=0, high=1)
    _check_experiment(path, result["experiment"])
    _check_p_values(path, "comparisons", result.get("comparisons") or {})
    for k, v in (result.get("variants") or {}).items():
        if isinstance(v, dict):
            _check_p_values(path, "variants.%s.comparisons" % k, v.get("comparisons") or {})
    return result


def seed_dirs(run_dir):
    out = []
    for name in os.listdir(run_dir):
        if name.startswith("seed-") and name[5:].isdigit() and \
                os.path.isdir(os.path.join(run_dir, name)):
            out.append((int(name[5:]), os.path.join(run_dir, name)))
    return [d for _, d in sorted(out)]


def csv_rows(path):
    """(line number, cells) of each row of a CSV file that is a regular file within the input
    limit; an unreadable file or one that is no UTF-8 CSV is a ReportError naming it."""
    check_input(path)
    try:
        with open(path, newline="", encoding="utf-8") as f:
            reader = csv.reader(f)
            for row in reader:
                yield reader.line_num, row
    except OSError as e:
        raise ReportError("%s: cannot read: %s" % (path, e.strerror))
    except (UnicodeDecodeError, csv.Error) as e:
        raise ReportError("%s: not a CSV file: %s" % (path, e))


def read_curve(path):
    """A curve CSV (seed-<k>/*_curve.csv) as {column: np.array}; an empty cell (a value not
    measured in that row) is NaN. The file must be a header of distinct names and rows of as
    many decimal numbers (or empty cells); anything else is a ReportError naming the file, the
    line, the column and the value."""
    numbered = list(csv_rows(path))
    rows = [row for _, row in numbered]
    if not rows:
        raise ReportError("%s: empty file (expected a header such as 'epoch,...')" % path)
    header, body = rows[0], rows[1:]
    for j, name in enumerate(header):
        if not NAME.match(name) or name in header[:j]:
            raise ReportError("%s: line 1: column %d: name %s is %s" % (
                path, j + 1, shown(name), "repeated" if NAME.match(name) else
                "not a column name (letters, digits, '_', '.', '[', ']', '-')"))
    if not body:
        raise ReportError("%s: a header and no rows" % path)
    values = np.full((len(body), len(header)), np.nan)
    for i, row in enumerate(body):
        line = numbered[i + 1][0]
        if len(row) != len(header):
            raise ReportError("%s: line %d: %d cells, but the header has %d"
                              % (path, line, len(row), len(header)))
        for j, cell in enumerate(row):
            if cell == "":
                continue
            if not NUMBER.match(cell) or not math.isfinite(float(cell)):
                raise ReportError("%s: line %d: column '%s': value %s is not a finite number"
                                  % (path, line, header[j], shown(cell)))
            values[i, j] = float(cell)
    if np.isnan(values[:, 0]).any():
        raise ReportError("%s: line %d: column '%s' (the x axis) is empty"
                          % (path, numbered[int(np.isnan(values[:, 0]).argmax()) + 1][0],
                             header[0]))
    return {name: values[:, j] for j, name in enumerate(header)}


def first_model(run_dir, name="barrier.model"):
    for d in seed_dirs(run_dir):
        p = os.path.join(d, name)
        if os.path.isfile(p):
            return p
    return None


def read_states_csv(path, features, limit=20000):
    """The columns `features` of a state CSV (at most `limit` rows), checked as read_curve."""
    rows, idx, header = [], None, None
    for line, r in csv_rows(path):
        if header is None:
            header = r
            missing = [n for n in features if n not in header]
            if missing:
                raise ReportError("%s: no column %s (the header: %s)"
                                  % (path, shown(missing[0]), shown(",".join(header))))
            idx = [header.index(n) for n in features]
            continue
        if len(r) != len(header):
            raise ReportError("%s: line %d: %d cells, but the header has %d"
                              % (path, line, len(r), len(header)))
        for i, n in zip(idx, features):
            if not NUMBER.match(r[i]) or not math.isfinite(float(r[i])):
                raise ReportError("%s: line %d: column '%s': value %s is not a finite number"
                                  % (path, line, n, shown(r[i])))
        rows.append([float(r[i]) for i in idx])
        if len(rows) >= limit:
            break
    if header is None:
        raise ReportError("%s: empty file (expected a header of feature names)" % path)
    if not rows:
        raise ReportError("%s: no rows" % path)
    return np.array(rows, dtype=np.float32)
