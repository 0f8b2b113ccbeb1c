"""What the report asks of a run's domain, through the registry (the report names no domain):
its picture hints (experiments::ReportHints) and the paper's numbers (Domain::PaperReference ...).

Both come from the Python module (`secure.report_hints`, `secure.paper_reference`, with the run's
task options), or from the run directory when it holds them: `report_hints.json` and
`paper_reference.json` (the same documents; a domain registered only at run time, as a test's,
can hand them over that way). The hints' schema is tools/report/README.md, "Report hints"; a
field of the wrong kind is one line naming the source, the field and the value (Hint.get).
"""
import json
import os

from run_dir import ReportError

HINTS_FILE = "report_hints.json"
PAPER_FILE = "paper_reference.json"
_MISSING = object()


def import_secure():
    """(the module `secure`, None) or (None, why it cannot be imported)."""
    try:
        import secure  # noqa: the Python module (python/README.md), PYTHONPATH=<build>/python
        return secure, None
    except Exception as e:  # ImportError, or a broken build's OSError
        return None, ("the Python module `secure` is not available (%s: %s). Build it (target "
                      "secure_python) and set PYTHONPATH=<build>/python, or run \"secure "
                      "report\", which does" % (type(e).__name__, e))


def task_options(result):
    """The run's task options (result.json experiment.domain_options.task), or {}."""
    opts = result["experiment"].get("domain_options") or {}
    task = opts.get("task") if isinstance(opts, dict) else None
    return task if isinstance(task, dict) else {}


def _read_json(path):
    try:
        with open(path, "rb") as f:
            return json.loads(f.read().decode("utf-8"))
    except (UnicodeDecodeError, ValueError) as e:
        raise ReportError("%s: malformed JSON: %s" % (path, e))
    except OSError as e:
        raise ReportError("%s: cannot read: %s" % (path, e.strerror))


def _from_registry(run_dir, result, file_name, function):
    """(document, source, why none): the run directory's file if present, else the module's
    `function`(domain, task=...); (None, None, reason) when neither gives one."""
    path = os.path.join(run_dir, file_name)
    if os.path.isfile(path):
        return _read_json(path), file_name, None
    domain = str(result["experiment"].get("domain", ""))
    secure, why = import_secure()
    if secure is None:
        return None, None, why
    task = task_options(result)
    try:
        doc = getattr(secure, function)(domain, **({"task": task} if task else {}))
    except ValueError as e:  # an unregistered domain, options the domain does not take
        return None, None, "%s('%s'): %s" % (function, domain, e)
    return doc, "secure.%s('%s')" % (function, domain), None


def report_hints(run_dir, result):
    """(hints as a Hint, None) or (None, why there are none)."""
    doc, source, why = _from_registry(run_dir, result, HINTS_FILE, "report_hints")
    if doc is None:
        domain = result["experiment"].get("domain", "")
        return None, why or ("no picture hints: the %s domain gives none (Domain::"
                             "MakeReportHints)" % domain)
    return Hint(doc, source, ""), None


def paper_table3(run_dir, result):
    """(the domain's Table 3 row {source, rows, comparison}, None) or (None, why none)."""
    doc, source, why = _from_registry(run_dir, result, PAPER_FILE, "paper_reference")
    if doc is None:
        return None, why
    top = Hint(doc, source, "")
    t = top.sub("table3")
    if t is None:
        return None, "the paper has no Table 3 row for the %s domain (%s)" % (
            result["experiment"].get("domain", ""), source)
    rows = []
    for r in t.items("rows"):
        row = {"method": r.get("method", str)}
        for k in ("success", "success_std", "dangerous", "dangerous_std"):
            row[k] = r.get(k, (int, float, type(None)), None)
        rows.append(row)
    return {"source": t.get("source", str), "rows": rows,
            "comparison": t.get("comparison", str, "")}, None


KINDS = {str: "a string", bool: "true or false", int: "an integer", float: "a number",
         list: "a list", dict: "an object", type(None): "null"}


class Hint:
    """A JSON object of the hints with its place (`where`: "barrier.x") and `source` for
    messages. get() checks a field's kind; sub() and items() descend."""

    def __init__(self, value, source, where):
        self.value, self.source, self.where = value, source, where
        if not isinstance(value, dict):
            self._bad(where or "(top)", value, "an object")

    def _bad(self, field, value, what):
        raise ReportError("%s: '%s' = %s, must be %s"
                          % (self.source, field, json.dumps(value)[:80], what))

    def path(self, key):
        return "%s.%s" % (self.where, key) if self.where else key

    def has(self, key):
        return self.value.get(key) is not None

    def get(self, key, kinds, default=_MISSING):
        """The field `key`, of one of `kinds` (a type or a tuple; int passes for float), or
        `default` when absent or null; absent without a default is an error."""
        kinds = kinds if isinstance(kinds, tuple) else (kinds,)
        v = self.value.get(key)
        if v is None and default is not _MISSING:
            return default
        ok = any(isinstance(v, k) and not (isinstance(v, bool) and k in (int, float))
                 for k in kinds) or (float in kinds and isinstance(v, int)
                                     and not isinstance(v, bool))
        if not ok:
            self._bad(self.path(key), v, " or ".join(KINDS.get(k, k.__name__) for k in kinds))
        return v

    def numbers(self, key, n, default=_MISSING):
        """A list of `n` numbers."""
        v = self.get(key, list, default)
        if v is default:
            return v
        if len(v) != n or not all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                  for x in v):
            self._bad(self.path(key), v, "a list of %d numbers" % n)
        return [float(x) for x in v]

    def sub(self, key):
        """The object `key` as a Hint, or None when absent or null."""
        v = self.value.get(key)
        return None if v is None else Hint(v, self.source, self.path(key))

    def items(self, key):
        """The list of objects `key` as Hints ([] when absent)."""
        v = self.get(key, list, [])
        return [Hint(x, self.source, "%s[%d]" % (self.path(key), i)) for i, x in enumerate(v)]
