"""Writing files safely: atomic text and figure writes, output folders checked up front, and
the series plot.

Every output file (CSV, JSON, PNG, ...) is written to a temporary file in the destination
folder and then renamed over the destination (``os.replace``, atomic on POSIX and Windows): an
interrupted write (an exception, SIGINT, SIGTERM) leaves the previous file intact and never a
truncated one.  Only a regular file is replaced, or the regular file a symbolic link in the
same folder points to (the link stays): a FIFO, a device such as ``/dev/null``, a folder or a
link leading elsewhere is refused.  Files get the usual mode (0666 less the umask, so 0644).
The table formats themselves are in :mod:`hemocircuit.results`.
"""
from __future__ import annotations

import contextlib
import os
import tempfile

import numpy as np

from .errors import HemocircuitError


FIGURE_FORMATS = ("png", "pdf", "svg", "svgz", "eps", "ps", "jpg", "jpeg", "tif", "tiff", "webp")


def output_target(path, flag="--out"):
    """The file a write of ``path`` replaces: ``path`` itself, or the regular file a symbolic
    link ``path`` points to in the same folder.  Anything else is refused with a clear error
    (see the module's docstring)."""
    import stat

    from .inputs import check_path
    path = check_path(path, "output file", flag)
    if os.path.isdir(path):
        raise HemocircuitError(f"{flag} {path}: is a folder; give a file name")
    if not os.path.lexists(path):
        return path
    target = os.path.realpath(path) if os.path.islink(path) else path
    folder = os.path.realpath(os.path.dirname(os.path.abspath(path)))
    if target != path and os.path.dirname(target) != folder:
        raise HemocircuitError(f"{flag} {path}: a symbolic link to {target}, outside the output folder {folder}; "
                               "give the file itself, or remove the link")
    try:
        mode = os.stat(target).st_mode
    except FileNotFoundError:
        return target  # a dangling link inside the folder: the write creates its file
    except OSError as exc:
        raise HemocircuitError(f"{flag} {path}: {exc.strerror or exc}") from None
    if not stat.S_ISREG(mode):
        raise HemocircuitError(f"{flag} {path}: not a regular file (a device, FIFO, socket or folder); an output "
                               "only replaces a regular file: give another name")
    return target


def prepare_output(path, flag="--out"):
    """Check (before any computation) that ``path`` can be written: a file name that may be
    replaced (:func:`output_target`), a folder that exists or is created when the folder's
    parent exists; otherwise a clear error naming the option."""
    path = output_target(path, flag)
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        parent = os.path.dirname(folder)
        if not os.path.isdir(parent):
            raise HemocircuitError(f"{flag} {path}: the folder {folder} does not exist, nor its parent {parent}; "
                                   "create it first")
        try:
            os.mkdir(folder)
        except OSError as exc:
            raise HemocircuitError(f"{flag} {path}: cannot create the folder {folder}: {exc.strerror}") from None
    if not os.access(folder, os.W_OK | os.X_OK):
        raise HemocircuitError(f"{flag} {path}: the folder {folder} is not writable")
    return path


def prepare_folder(path, flag="--out"):
    """An output folder (reports, fits): created if missing when its parent exists; an
    existing file or a name no folder can have is a clear error naming the option."""
    from .inputs import check_path
    path = check_path(path, "output folder", flag)
    if os.path.lexists(path) and not os.path.isdir(path):
        raise HemocircuitError(f"{flag} {path}: exists and is not a folder; give a folder name")
    parent = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(parent):
        raise HemocircuitError(f"{flag} {path}: its parent folder {parent} does not exist; create it first")
    try:
        os.makedirs(path, exist_ok=True)
    except OSError as exc:
        raise HemocircuitError(f"{flag} {path}: cannot create the folder: {exc.strerror or exc}") from None
    if not os.access(path, os.W_OK | os.X_OK):
        raise HemocircuitError(f"{flag} {path}: the folder is not writable")
    return path


@contextlib.contextmanager
def atomic_file(path, mode="w", **kwargs):
    """Open a temporary file beside ``path``; on a clean exit it replaces ``path`` (fsync'd
    first), on an exception it is removed and ``path`` is left as it was."""
    path = output_target(path, "output")
    folder = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(prefix=f".{os.path.basename(path)}.", suffix=".tmp", dir=folder)
    try:
        with os.fdopen(fd, mode, **kwargs) as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        mask = os.umask(0)
        os.umask(mask)
        os.chmod(tmp, 0o666 & ~mask)  # mkstemp creates 0600; give the file the usual permissions
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def atomic_write(path, text):
    """Write ``text`` to ``path`` atomically (UTF-8)."""
    try:
        with atomic_file(path, "w", encoding="utf-8", newline="") as fh:
            fh.write(text)
    except OSError as exc:
        raise HemocircuitError(f"cannot write {path}: {exc.strerror or exc}") from None
    return str(path)


def pyplot():
    """matplotlib.pyplot on the non-interactive Agg backend (figures go to files only)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def figure_format(path, flag="--plot"):
    """The figure format of ``path`` from its extension (png without one), or a clear error."""
    fmt = os.path.splitext(os.fspath(path))[1].lstrip(".").lower() or "png"
    if fmt not in FIGURE_FORMATS:
        raise HemocircuitError(f"{flag} {path}: .{fmt} is not a figure format; use one of "
                               f"{', '.join('.' + f for f in FIGURE_FORMATS)}")
    return fmt


def save_figure(fig, path, dpi=110):
    """Lay out, write (atomically) and close a figure."""
    import matplotlib.pyplot as plt

    try:
        fmt = figure_format(path)
        fig.tight_layout()
        with atomic_file(path, "wb") as fh:
            fig.savefig(fh, dpi=dpi, format=fmt)
    except OSError as exc:
        raise HemocircuitError(f"cannot write {path}: {exc.strerror or exc}") from None
    finally:
        plt.close(fig)


def plot_series(path, x, xlabel, columns: dict, units: dict, title="", select=None):
    """One panel per unit (pressures, flows, volumes, ...), every selected column drawn."""
    plt = pyplot()

    names = [n for n in (select or columns) if n in columns and np.ndim(columns[n]) == 1]
    by_unit = {}
    for n in names:
        by_unit.setdefault(units.get(n, ""), []).append(n)
    k = max(len(by_unit), 1)
    fig, axes = plt.subplots(k, 1, figsize=(8, 2.2 * k + 0.6), sharex=True, squeeze=False)
    for ax, (u, ns) in zip(axes[:, 0], by_unit.items()):
        for n in ns[:12]:
            ax.plot(x, columns[n], label=n)
        ax.set_ylabel(f"[{u}]" if u else "")
        ax.legend(fontsize=7, loc="best", ncol=2)
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel(xlabel)
    if title:
        axes[0, 0].set_title(title)
    save_figure(fig, path)
