"""The mean flow index Mx (Czosnyka et al. 1996, Stroke 27:1829): the Pearson correlation of
the cerebral flow velocity with the perfusion (or arterial: Mxa) pressure over a moving
window, averaged over the recording.  Near 0 or negative: flow independent of pressure
(autoregulation intact); towards 1: flow follows pressure (impaired; thresholds near 0.3-0.45
are used in the literature).

Both series are first reduced to means over consecutive blocks (10 s), then correlated over
windows of 30 blocks (300 s) moved by 6 blocks (60 s).
"""
from __future__ import annotations

import numpy as np

from ..errors import HemocircuitError


def block_means(t, x, block):
    """Means of ``x`` over consecutive, non-overlapping blocks of ``block`` seconds (a last
    incomplete block dropped; each sample stands for the interval up to the next):
    (block start times, means)."""
    span = t[-1] - t[0] + np.median(np.diff(t))
    n = int(np.floor(span / block + 1e-9))
    edges = t[0] + block * np.arange(n + 1)
    which = np.searchsorted(edges, t, side="right") - 1
    keep = (which >= 0) & (which < n)
    sums = np.bincount(which[keep], weights=x[keep], minlength=n)
    counts = np.bincount(which[keep], minlength=n)
    return edges[:-1], sums / np.maximum(counts, 1)


def moving_correlation(t, P, V, block=10.0, window=300.0, step=60.0):
    """(window start times, Pearson r of each window) of the block means of ``P`` and ``V``."""
    starts, pm = block_means(t, P, block)
    _, vm = block_means(t, V, block)
    per, move = int(round(window / block)), int(round(step / block))
    if per < 3 or move < 1:
        raise HemocircuitError(f"--window {window:g} s / --step {step:g} s: need at least 3 blocks of {block:g} s "
                               "per window and a step of at least one block")
    if len(pm) < per:
        raise HemocircuitError(f"the series last {t[-1] - t[0]:.4g} s, shorter than one {window:g} s window")
    out_t, out_r = [], []
    for k in range(0, len(pm) - per + 1, move):
        a, b = pm[k:k + per], vm[k:k + per]
        out_t.append(starts[k])
        out_r.append(np.corrcoef(a, b)[0, 1] if a.std() > 0 and b.std() > 0 else np.nan)
    return np.array(out_t), np.array(out_r)
