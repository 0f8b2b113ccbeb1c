"""The world's shapes of a picture hint (circles, rectangles) as matplotlib patches, and the
caption's placeholders."""
import html

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from run_dir import ReportError  # noqa: E402

# The style fields a shape may give, and their kinds (Hint.get).
STYLE_FIELDS = (("color", str), ("fill", bool), ("alpha", float), ("linestyle", str),
                ("linewidth", float))


def shape_patch(shape):
    """A new patch for the Hint `shape` ({kind: circle, center, radius} or {kind: rectangle,
    corner, size}, plus style fields); one per axes (a patch belongs to one)."""
    style = {k: shape.get(k, kind) for k, kind in STYLE_FIELDS if shape.has(k)}
    kind = shape.get("kind", str)
    if kind == "circle":
        return plt.Circle(tuple(shape.numbers("center", 2)), shape.get("radius", float), **style)
    if kind == "rectangle":
        w, h = shape.numbers("size", 2)
        return plt.Rectangle(tuple(shape.numbers("corner", 2)), w, h, **style)
    raise ReportError("%s: '%s' = \"%s\", must be circle or rectangle"
                      % (shape.source, shape.path("kind"), kind))


def caption(hint, values):
    """The hint's caption (HTML, the domain's words) with each {name} of `values` replaced by
    the escaped value."""
    text = hint.get("caption", str, "")
    for name, value in values.items():
        text = text.replace("{%s}" % name, html.escape(str(value)))
    return text
