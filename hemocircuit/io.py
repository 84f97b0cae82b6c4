"""Writing results: CSV for series and sweeps, JSON for an operating point, PNG plots.

Column names carry their unit: ``time [s]``, ``P(a) [mmHg]``, ``Q(Rla) [mL/s]``, ``V(Ca) [mL]``,
``art.r [um]``.
"""
from __future__ import annotations

import csv
import json
import math

import numpy as np


def labelled(name, units):
    u = units.get(name, "")
    return f"{name} [{u}]" if u else name


def write_csv(path, columns: dict, units: dict, first=None):
    """Write equal-length columns; ``first`` (name, array, unit) is put in front (time, swept param)."""
    names = list(columns)
    header = ([f"{first[0]} [{first[2]}]"] if first else []) + [labelled(n, units) for n in names]
    data = ([np.asarray(first[1])] if first else []) + [np.asarray(columns[n]) for n in names]
    n = len(data[0]) if data else 0
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        for i in range(n):
            w.writerow([_fmt(col[i]) for col in data])


def _fmt(v):
    try:
        f = float(v)
    except (TypeError, ValueError):
        return str(v)
    return "nan" if math.isnan(f) else repr(f)


def write_json(path, flat: dict):
    with open(path, "w") as fh:
        json.dump(flat, fh, indent=1)


def pyplot():
    """matplotlib.pyplot on the non-interactive Agg backend (figures go to files only)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def save_figure(fig, path, dpi=110):
    """Lay out, write and close a figure."""
    import matplotlib.pyplot as plt

    fig.tight_layout()
    fig.savefig(path, dpi=dpi)
    plt.close(fig)


def plot_series(path, x, xlabel, columns: dict, units: dict, title="", select=None):
    """One panel per unit (pressures, flows, volumes, ...), every selected column drawn."""
    plt = pyplot()

    names = [n for n in (select or columns) if n in columns and np.ndim(columns[n]) == 1
             and np.all(np.isfinite(columns[n])) is not None]
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
