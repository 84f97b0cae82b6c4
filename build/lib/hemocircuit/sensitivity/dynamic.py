"""Dynamic (time-resolved) sensitivity of a transient output (thesis, "Dynamic Results").

The constellation method (default: multiplicative, +/-50 %, n = 100) on a ``tran`` output
sampled at many times: every base point is a whole baseline response and every elementary
effect a time series, so the mean and variance of each parameter's effect are functions of
time.  The thesis does this on Kuo91 A for v, f2, tau_Ca1, tau_Ca2 and the NO speed factor,
with f1 tied inversely to v (a ``ties`` entry) so that the steady state is unchanged.
"""
from __future__ import annotations

import numpy as np

from . import constellation


def run(space, evaluate, labels, units, times=None, n_columns=1, **settings):
    """``times`` (T,): the output's sample times; the output components are T x n_columns
    (time-major, as TranObjective lays them out)."""
    res = constellation.run(space, evaluate, labels, units, **settings)
    ee = res.extra["ee"]  # (n, k, T * m)
    n, k, _ = ee.shape
    T = len(times)
    ee = ee.reshape(n, k, T, n_columns)
    with np.errstate(invalid="ignore"):
        mean = np.nanmean(ee, axis=0)  # (k, T, m)
        var = np.nanvar(ee, axis=0, ddof=1)
    base = res.extra["Y"][:, 0, :].reshape(n, T, n_columns)
    series = []
    columns = [lab.split(" @ ")[0] for lab in labels[:n_columns]]
    for c, col in enumerate(columns):
        for ti, t in enumerate(times):
            for i, name in enumerate(space.names):
                series.append({"output": col, "time": float(t), "parameter": name, "mean": float(mean[i, ti, c]),
                               "variance": float(var[i, ti, c]),
                               "n_used": float(np.sum(np.isfinite(ee[:, i, ti, c])))})
    res.method = "dynamic"
    res.extra.update({"times": np.asarray(times), "mean": mean, "variance": var, "baseline": base,
                      "series": series, "series_columns": {"output": "", "time": "s", "parameter": "",
                                                           "mean": "%/%" if space.scheme == "multiplicative" else "",
                                                           "variance": "", "n_used": ""},
                      "tran_columns": columns})
    return res
