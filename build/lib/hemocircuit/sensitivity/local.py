"""Local sensitivities at the centre: derivatives and normalised (%/%) derivatives.

dY/dp_i by forward differences with the derivatives service's step rule
(``derivatives.fd_steps``: FD_REL max(|p_i|, scale_i), scale_i = the width of the parameter's
range); normalised S_i = (dY/dp_i) p_i / Y, the local counterpart of the multiplicative
scheme's elementary effect.  k + 1 model runs in one batch.
"""
from __future__ import annotations

import numpy as np

from ..derivatives import fd_steps
from ..errors import SolverError
from .result import Result, failure_list, param_rows


def run(space, evaluate, labels, units, **_):
    k = space.k
    c = space.centre
    h = fd_steps(c, space.upper - space.lower)
    M = np.repeat(c[None, :], k + 1, axis=0)
    M[np.arange(k) + 1, np.arange(k)] += h
    Y, errors = evaluate(space.values(M))
    if errors[0] is not None:
        raise SolverError(f"local sensitivity: the model fails at the centre: {errors[0]}")
    Y = np.where(np.array([e is None for e in errors])[:, None], Y, np.nan)
    dY = (Y[1:] - Y[:1]) / h[:, None]  # (k, m)
    with np.errstate(divide="ignore", invalid="ignore"):
        S = dY * c[:, None] / Y[:1]

    def stats(j):
        return {"value": np.full(k, Y[0, j]), "derivative": dY[:, j], "normalised": S[:, j]}

    rows = param_rows(space, labels, stats)
    for r in rows:
        r["derivative unit"] = f"{units[labels.index(r['output'])]}/({r['unit']})"
    cols = {"output": "", "parameter": "", "unit": "", "lower": "", "centre": "", "upper": "", "value": "",
            "derivative": "", "derivative unit": "", "normalised": "%/%"}
    return Result("local", space, labels, units, rows, cols,
                  failure_list(errors, lambda i: "centre" if i == 0 else f"step in {space.names[i - 1]}"), len(Y),
                  {"rank_key": "normalised", "Y0": Y[0], "steps": h})
