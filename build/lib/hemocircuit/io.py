"""Writing files safely: atomic text and figure writes, output folders checked up front, and
the series plot.

Every output file (CSV, JSON, PNG) is written to a temporary file in the destination folder
and then renamed over the destination (``os.replace``, atomic on POSIX and Windows): an
interrupted write (an exception, SIGINT, SIGTERM) leaves the previous file intact and never a
truncated one.  The table formats themselves are in :mod:`hemocircuit.results`.
"""
from __future__ import annotations

import contextlib
import os
import tempfile

import numpy as np

from .errors import HemocircuitError


def prepare_output(path, flag="--out"):
    """Check (before any computation) that ``path`` can be written: its folder exists, or is
    created when the folder's parent exists; otherwise a clear error naming the option."""
    path = os.fspath(path)
    folder = os.path.dirname(os.path.abspath(path))
    if os.path.isdir(path):
        raise HemocircuitError(f"{flag} {path}: is a folder; give a file name")
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


@contextlib.contextmanager
def atomic_file(path, mode="w", **kwargs):
    """Open a temporary file beside ``path``; on a clean exit it replaces ``path`` (fsync'd
    first), on an exception it is removed and ``path`` is left as it was."""
    path = os.fspath(path)
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


def save_figure(fig, path, dpi=110):
    """Lay out, write (atomically) and close a figure."""
    import matplotlib.pyplot as plt

    fig.tight_layout()
    fmt = os.path.splitext(os.fspath(path))[1].lstrip(".").lower() or "png"
    try:
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
