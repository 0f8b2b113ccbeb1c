"""The HTML page of the report: figures embedded as base64 PNG (and written into the figures'
directory), notes, the style sheet, and writing the page as every C++ writer writes
(secure/common/atomic_file.h)."""
import base64
import html
import io
import os
import stat

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from run_dir import ReportError  # noqa: E402


class Page:
    def __init__(self, fig_dir):
        self.fig_dir = fig_dir
        self.parts = []
        self.figures = []  # file names

    def h2(self, text):
        self.parts.append("<h2>%s</h2>" % html.escape(text))

    def p(self, text, cls=None):
        self.parts.append("<p%s>%s</p>" % (' class="%s"' % cls if cls else "", text))

    def note(self, text):
        self.p(html.escape(text), "note")

    def raw(self, text):
        self.parts.append(text)

    def figure(self, fig, name, caption):
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=100)
        plt.close(fig)
        data = buf.getvalue()
        if self.fig_dir is not None:
            with open(os.path.join(self.fig_dir, name + ".png"), "wb") as f:
                f.write(data)
        self.figures.append(name + ".png")
        self.parts.append(
            '<figure><img id="fig-%s" alt="%s" src="data:image/png;base64,%s">'
            '<figcaption>%s</figcaption></figure>'
            % (name, html.escape(name), base64.b64encode(data).decode("ascii"), caption))


STYLE = """
body { font-family: sans-serif; max-width: 1100px; margin: 1.5em auto; color: #222; }
h1 { font-size: 1.5em; } h2 { font-size: 1.2em; border-bottom: 1px solid #ccc; }
table { border-collapse: collapse; margin: 0.5em 0; font-size: 0.9em; }
td, th { border: 1px solid #bbb; padding: 3px 8px; text-align: left; }
figure { margin: 0.5em 0; } img, video { max-width: 100%; }
figcaption, .note { font-size: 0.85em; color: #555; }
.note { background: #fff6dd; padding: 4px 8px; }
"""


# ---------------------------------------------------------------------------------------------
# Writing the page: the rules of the C++ writers (secure/common/atomic_file.h). `secure report`
# hands the page to the C++ writer itself (--write-to); these are for the script run alone.


def output_kind(path):
    """What `path` is, following symlinks: None (does not exist), "file", "device", "fifo";
    a directory, a socket or a block device is a ReportError (nothing touched)."""
    try:
        st = os.stat(path)
    except FileNotFoundError:
        return None
    except OSError as e:
        raise ReportError("cannot write '%s': %s" % (path, e.strerror))
    if stat.S_ISREG(st.st_mode):
        return "file"
    if stat.S_ISCHR(st.st_mode):
        return "device"
    if stat.S_ISFIFO(st.st_mode):
        return "fifo"
    what = "a directory" if stat.S_ISDIR(st.st_mode) else \
        "a socket" if stat.S_ISSOCK(st.st_mode) else "a block device" \
        if stat.S_ISBLK(st.st_mode) else "not a regular file"
    raise ReportError("cannot write '%s': it is %s, not a regular file" % (path, what))


def open_fifo_for_writing(path):
    try:
        fd = os.open(path, os.O_WRONLY | os.O_NONBLOCK)
    except OSError as e:
        if e.errno == 6:  # ENXIO
            raise ReportError("cannot write '%s': a FIFO that no process has open for reading"
                              % path)
        raise ReportError("cannot write '%s': %s" % (path, e.strerror))
    os.set_blocking(fd, True)
    return fd


def write_output(path, text):
    """Writes the page as every C++ writer does: a regular file atomically (temporary + fsync +
    rename, its mode kept), through symlinks to their target, a device or a FIFO (with a reader)
    directly; a directory refused. No temporary is left behind on failure."""
    data = text.encode("utf-8")
    kind = output_kind(path)
    if kind in ("device", "fifo"):
        try:
            fd = open_fifo_for_writing(path) if kind == "fifo" else os.open(path, os.O_WRONLY)
            with os.fdopen(fd, "wb", buffering=0) as f:
                view = memoryview(data)
                while view:
                    view = view[f.write(view):]
        except OSError as e:
            raise ReportError("cannot write '%s': %s" % (path, e.strerror))
        return
    target = os.path.realpath(path)
    if kind == "file":
        mode = os.stat(target).st_mode & 0o7777
    else:
        umask = os.umask(0)
        os.umask(umask)
        mode = 0o666 & ~umask
    tmp = "%s.tmp-%d" % (target, os.getpid())
    try:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        try:
            with os.fdopen(fd, "wb") as f:
                f.write(data)
                f.flush()
                os.fsync(f.fileno())
            os.chmod(tmp, mode)
            os.replace(tmp, target)
        except BaseException:
            try:
                os.unlink(tmp)
            except OSError:
                pass
            raise
    except OSError as e:
        raise ReportError("cannot write '%s': %s" % (path, e.strerror or e))
