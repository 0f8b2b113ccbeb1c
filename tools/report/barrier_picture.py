"""The learned barrier's picture, drawn from the domain's hints (hints.py; the schema is
tools/report/README.md, "Report hints"): seed-<k>/barrier.model loaded with the Python module,
h over a grid of two state features, the others those of a base state, in one or more panels."""
import os
import re

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from hints import import_secure, task_options  # noqa: E402
from run_dir import ReportError, first_model, read_states_csv  # noqa: E402
from shapes import caption, shape_patch  # noqa: E402


def axis_range(axis, feats, run_dir):
    """The axis hint's [lo, hi]; `upper_from` raises hi to a percentile of a states file's
    column (scaled, at least `at_least`) when the run directory holds the file."""
    lo, hi = axis.numbers("range", 2)
    up = axis.sub("upper_from")
    if up is not None:
        path = os.path.join(run_dir, up.get("file", str))
        if os.path.isfile(path):
            values = read_states_csv(path, feats)[:, feats.index(axis.get("feature", str))]
            hi = max(up.get("at_least", float, -np.inf),
                     up.get("scale", float, 1.0) * float(np.percentile(
                         values, up.get("percentile", float))))
    return lo, hi


def base_state(hint, feats, run_dir):
    """(the state the picture varies two features of, None) or (None, why there is none): zeros,
    `fill` values for the features matching a pattern, or one of a states file's rows (`above`
    a speed, `nearest` two features equal, else the `median` of one)."""
    state = np.zeros(len(feats), dtype=np.float32)
    base = hint.sub("base")
    if base is None:
        return state, None
    for fill in base.items("fill"):
        try:
            pattern = re.compile(fill.get("match", str))
        except re.error as e:
            raise ReportError("%s: '%s': not a regular expression: %s"
                              % (fill.source, fill.path("match"), e))
        value = fill.get("value", float)
        for i, name in enumerate(feats):
            if pattern.search(name):
                state[i] = value
    if not base.has("from_file"):
        return state, None
    name = base.get("from_file", str)
    path = os.path.join(run_dir, name)
    if not os.path.isfile(path):
        return None, "no %s in the run directory" % name
    states = read_states_csv(path, feats)
    above = base.sub("above")
    if above is not None:
        moving = states[states[:, feats.index(above.get("feature", str))] >
                        above.get("value", float)]
        states = moving if len(moving) else states
    nearest = base.get("nearest", list, None)
    if nearest and all(f in feats for f in nearest):
        gap = np.abs(states[:, feats.index(nearest[0])] - states[:, feats.index(nearest[1])])
        return states[int(np.argmin(gap))], None
    if base.has("median"):
        column = states[:, feats.index(base.get("median", str))]
        return states[int(np.argsort(column)[len(states) // 2])], None
    return states[0], None


def draw_barrier(page, secure, run_dir, result, hint):
    """The picture of hint (a Hint: the domain's `barrier` hints); a note when the run directory
    lacks what it needs."""
    path = first_model(run_dir)
    if path is None:
        page.note("No barrier picture: no seed-<k>/barrier.model in the run directory.")
        return
    b = secure.Barrier.load(path)
    feats = list(b.features or hint.get("default_features", list, []))
    xa, ya = hint.sub("x"), hint.sub("y")
    fx, fy = xa.get("feature", str), ya.get("feature", str)
    if fx not in feats or fy not in feats:
        page.note("No barrier picture: the barrier does not read %s and %s." % (fx, fy))
        return
    state, why = base_state(hint, feats, run_dir)
    if state is None:
        page.note("No barrier picture: %s." % why)
        return
    ix, iy = feats.index(fx), feats.index(fy)
    n = hint.get("grid", int, 101)
    X, Y = np.meshgrid(np.linspace(*axis_range(xa, feats, run_dir), n),
                       np.linspace(*axis_range(ya, feats, run_dir), n))
    gt = None
    if hint.get("ground_truth", bool, False):
        task = task_options(result)
        try:
            gt = secure.Barrier.ground_truth(result["experiment"]["domain"],
                                             **({"task": task} if task else {}))
        except ValueError:  # a domain the module does not register (hints from the run dir)
            gt = None
        if gt is not None and not all(f in feats for f in (gt.features or feats)):
            gt = None  # it reads a feature the picture does not set
    panels = hint.items("panels") or [None]
    if len(panels) > 1:
        fig, axes = plt.subplots(1, len(panels), figsize=(4.3 * len(panels), 4.0))
    else:
        fig, ax = plt.subplots(figsize=(5.2, 4.4))
        axes = [ax]
    always = hint.get("zero_level", str, "if_crossing") == "always"
    for ax, panel in zip(axes, panels):
        S = np.tile(state, (n * n, 1)).astype(np.float32)
        S[:, ix] = X.ravel()
        S[:, iy] = Y.ravel()
        if panel is not None:
            for f, v in panel.get("set", dict, {}).items():
                if f in feats:
                    S[:, feats.index(f)] = v
        H = np.asarray(b.h(S)).reshape(n, n)
        lim = max(1e-6, float(np.nanpercentile(np.abs(H), 98)))
        im = ax.pcolormesh(X, Y, H, cmap="RdBu", vmin=-lim, vmax=lim, shading="auto")
        if always or np.nanmin(H) < 0 < np.nanmax(H):
            ax.contour(X, Y, H, levels=[0.0], colors="black", linewidths=1.5)
        if gt is not None:
            G = np.asarray(gt.h(S[:, [feats.index(f) for f in (gt.features or feats)]]))
            ax.contour(X, Y, G.reshape(n, n), levels=[0.0], colors="gold", linewidths=1.5,
                       linestyles="--")
        for mark in hint.items("marks"):
            at = (state[ix], state[iy]) if mark.get("at", (str, list)) == "base" else \
                mark.numbers("at", 2)
            ax.plot([at[0]], [at[1]], marker=mark.get("marker", str, "o"),
                    color=mark.get("color", str, "black"))
        for shape in hint.items("shapes"):
            ax.add_patch(shape_patch(shape))
        if hint.get("aspect", str, "auto") == "equal":
            ax.set_aspect("equal")
        if panel is not None and panel.has("title"):
            ax.set_title(panel.get("title", str), fontsize=10)
        ax.set_xlabel(xa.get("label", str, fx))
        ax.set_ylabel(ya.get("label", str, fy))
        if len(panels) > 1:
            fig.colorbar(im, ax=ax, shrink=0.8, label="h")
        else:
            fig.colorbar(im, ax=ax, label="h")
    fig.tight_layout()
    page.figure(fig, "barrier", caption(hint, {
        "model": os.path.relpath(path, run_dir),
        "ground_truth": "" if gt is not None else " (not available)"}))


def barrier_section(page, run_dir, result, hints, why_none):
    """Section 4: the picture from `hints` (a Hint or None, with `why_none`)."""
    hint = hints.sub("barrier") if hints is not None else None
    if hint is None:
        page.note("No barrier picture for the %s domain: %s." % (
            result["experiment"].get("domain", ""),
            why_none or "no picture hints (its ReportHints has no barrier picture)"))
        return
    secure, why = import_secure()
    if secure is None:
        page.note("No barrier picture: %s." % why)
        return
    try:
        draw_barrier(page, secure, run_dir, result, hint)
    except Exception as e:
        page.note("No barrier picture: %s: %s" % (type(e).__name__, e))
