"""Writing sensitivity results: CSV tables (units in the headers) and plots, through
hemocircuit.io (atomic: a temporary file in the target folder moved into place, so a reader
never sees a half-written file; only a regular file is replaced; the usual mode, 0644)."""
from __future__ import annotations

import csv
import math

import numpy as np

from ..errors import HemocircuitError
from ..io import atomic_file, pyplot, save_figure


def _fmt(v):
    if isinstance(v, (float, np.floating)):
        return "nan" if math.isnan(v) else repr(float(v))
    return str(v)


def write_table(path, rows, columns):
    """rows: list of dicts; columns: {key: unit} -> header 'key [unit]' (or 'key')."""
    try:
        with atomic_file(path, "w", newline="", encoding="utf-8") as fh:
            w = csv.writer(fh)
            w.writerow([f"{k} [{u}]" if u else k for k, u in columns.items()])
            for r in rows:
                w.writerow([_fmt(r.get(k, "")) for k in columns])
    except OSError as exc:
        raise HemocircuitError(f"cannot write {path}: {exc.strerror or exc}") from None


def write_failures(path, failures):
    try:
        with atomic_file(path, "w", newline="", encoding="utf-8") as fh:
            w = csv.writer(fh)
            w.writerow(["sample", "reason"])
            w.writerows(failures)
    except OSError as exc:
        raise HemocircuitError(f"cannot write {path}: {exc.strerror or exc}") from None


def _save(fig, path):
    save_figure(fig, path)


def plot(result, path, max_outputs=6):
    """The method's figure: sigma vs mu* on log axes (constellation, morris), Sobol bars with
    confidence intervals, local bars, or the time-resolved mean and variance (dynamic)."""
    if result.method == "dynamic":
        return plot_dynamic(result, path)
    plt = pyplot()
    m = min(len(result.labels), max_outputs)
    ncol = min(m, 3)
    nrow = -(-m // ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(5.2 * ncol, 4.4 * nrow), squeeze=False)
    for j in range(m):
        ax = axes[j // ncol, j % ncol]
        rows = [r for r in result.table if r["output"] == result.labels[j]]
        names = [r["parameter"] for r in rows]
        if result.method in ("constellation", "morris"):
            x = np.array([r["mu_star"] for r in rows])
            y = np.array([r["sigma"] for r in rows])
            ok = np.isfinite(x) & np.isfinite(y) & (x > 0) & (y > 0)
            ax.loglog(x[ok], y[ok], "o")
            for xi, yi, nm in zip(x[ok], y[ok], np.array(names)[ok]):
                ax.annotate(nm, (xi, yi), fontsize=7, xytext=(3, 3), textcoords="offset points")
            unit = "%/%" if result.space.scheme == "multiplicative" and result.method == "constellation" else ""
            ax.set_xlabel(f"mean magnitude of elementary effects mu*{' [' + unit + ']' if unit else ''}")
            ax.set_ylabel(f"standard deviation sigma{' [' + unit + ']' if unit else ''}")
            if (~ok).any():
                ax.text(0.01, 0.01, "not shown (zero): " + ", ".join(np.array(names)[~ok]), fontsize=6,
                        transform=ax.transAxes)
        elif result.method == "sobol":
            pos = np.arange(len(rows))
            ax.bar(pos - 0.2, [r["S1"] for r in rows], 0.4, yerr=[r["S1_conf"] for r in rows], capsize=3,
                   label="first order S1")
            ax.bar(pos + 0.2, [r["ST"] for r in rows], 0.4, yerr=[r["ST_conf"] for r in rows], capsize=3,
                   label="total order ST")
            ax.set_xticks(pos, names, rotation=60, ha="right", fontsize=7)
            ax.set_ylabel(f"Sobol index ({result.extra['conf_level']:.0%} confidence)")
            ax.legend(fontsize=7)
        else:  # local
            pos = np.arange(len(rows))
            ax.bar(pos, [r["normalised"] for r in rows])
            ax.set_xticks(pos, names, rotation=60, ha="right", fontsize=7)
            ax.set_ylabel("normalised sensitivity [%/%]")
        ax.set_title(result.labels[j], fontsize=8)
        ax.grid(alpha=0.3, which="both")
    for j in range(m, nrow * ncol):
        axes[j // ncol, j % ncol].axis("off")
    _save(fig, path)


def plot_dynamic(result, path):
    """Mean and variance (log) of each parameter's effect against time, with the baseline
    responses drawn behind in grey (thesis figures figdynSensitivity50radius/figdynSensitivity50)."""
    plt = pyplot()
    t = result.extra["times"]
    mean, var, base = result.extra["mean"], result.extra["variance"], result.extra["baseline"]
    col = result.extra["tran_columns"][0]
    unit = result.units[0]
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(8, 7), sharex=True)
    for ax in (a1, a2):
        bg = ax.twinx()
        bg.plot(t, base[:, :, 0].T, color="0.8", lw=0.5, zorder=0)
        bg.set_ylabel(f"{col} [{unit}] (baseline responses)", color="0.5", fontsize=8)
        ax.set_zorder(bg.get_zorder() + 1)
        ax.patch.set_visible(False)
    for i, name in enumerate(result.space.names):
        a1.plot(t, mean[i, :, 0], label=name)
        a2.semilogy(t, np.where(var[i, :, 0] > 0, var[i, :, 0], np.nan), label=name)
    scheme = "%/%" if result.space.scheme == "multiplicative" else ""
    a1.set_ylabel(f"mean elementary effect{' [' + scheme + ']' if scheme else ''}")
    a2.set_ylabel("variance of elementary effects")
    a2.set_xlabel("time [s]")
    a1.legend(fontsize=7, ncol=3)
    for ax in (a1, a2):
        ax.grid(alpha=0.3)
    _save(fig, path)
