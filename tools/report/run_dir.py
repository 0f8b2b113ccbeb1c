"""Reading a run directory (docs/FILE_FORMATS.md, "Experiment output") for the report: result.json
checked (rates are numbers in [0, 1]), the seeds' directories, curve CSVs and state CSVs. Every
problem is a ReportError naming the file."""
import csv
import json
import os

import numpy as np


class ReportError(Exception):
    pass


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
