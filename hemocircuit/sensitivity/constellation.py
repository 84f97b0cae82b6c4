"""The thesis's 'constellation' method (chapter 4, section "A Novel Method").

Design: ``designs`` Latin hypercubes of ``n`` points in the unit cube of the k parameters;
the one with the greatest mean separation between its points is kept.  From every point one
step in each of the k dimensions ('star-shaped experiments'): n (k + 1) model evaluations,
all in one batch.  Elementary effects, per parameter i and point x:

  additive scheme (absolute bounds, tabBounds):  EE = (f(x + h_i e_i) - f(x)) / h_i,
      h_i = step (ub_i - lb_i), a fixed fraction of the range (stepping back from the upper
      edge); units: output unit per parameter unit, so the parameters' scales scale EE
      (the thesis's remark on this scheme).
  multiplicative scheme (+/-x % around a centre):  the step is x/100 % of the point's value
      (thesis: "100 times smaller than the factor defining the width of the sample space"),
      EE = ((b - a)/a) / (x/10^4), dimensionless %/%.

Statistics of each parameter's EEs over the points: mean mu, mean magnitude mu* and standard
deviation sigma (the thesis plots sigma against the mean magnitude on log axes).
"""
from __future__ import annotations

import numpy as np
from scipy.spatial.distance import pdist
from scipy.stats import qmc

from .result import Result, failure_list, param_rows

DEFAULT_ADDITIVE_STEP = 1e-6  # fraction of each parameter's range


EXACT_SEPARATION = 4000  # points up to which the mean separation is computed over every pair


def design(k, n, designs, rng):
    """The best of ``designs`` Latin hypercubes (n, k) in [0, 1]: greatest mean separation
    (over every pair of points; beyond EXACT_SEPARATION points, over the pairs of a random
    subset of that many, an unbiased estimate: every pair would take n^2/2 distances)."""
    best, best_d = None, -1.0
    for _ in range(designs):
        U = qmc.LatinHypercube(d=k, seed=rng).random(n)
        if n > EXACT_SEPARATION:
            d = pdist(U[rng.choice(n, EXACT_SEPARATION, replace=False)]).mean()
        else:
            d = pdist(U).mean() if n > 1 else 0.0
        if d > best_d:
            best, best_d = U, d
    return best


def star_points(space, U, step=None):
    """Base points and their k one-at-a-time steps.  Returns (M (n (k+1), k) parameter
    values, point-major: base then its k steps; h (n, k) the steps in parameter units
    (additive) or the relative step (multiplicative, scalar))."""
    n, k = U.shape
    base = space.from_unit(U)
    M = np.repeat(base[:, None, :], k + 1, axis=1)
    idx = np.arange(k)
    if space.scheme == "additive":
        d = DEFAULT_ADDITIVE_STEP if step is None else step
        du = np.where(U + d <= 1.0, d, -d)  # step back from the upper edge (Morris)
        h = du * (space.upper - space.lower)
        M[:, idx + 1, idx] = base + h
    else:
        s = space.range_pct / 1e4 if step is None else step  # x/100 % of the value
        h = np.full((n, k), s)
        M[:, idx + 1, idx] = base * (1.0 + s)
    return M.reshape(n * (k + 1), k), h


def elementary_effects(space, Y, h):
    """EE (n, k, m) from outputs Y (n (k+1), m) (NaN rows for failed runs)."""
    k = space.k
    Y = Y.reshape(-1, k + 1, Y.shape[-1])
    base, stepped = Y[:, :1, :], Y[:, 1:, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        if space.scheme == "additive":
            ee = (stepped - base) / h[:, :, None]
        else:
            ee = ((stepped - base) / base) / h[:, :, None]
    return np.where(np.isfinite(ee), ee, np.nan)


def statistics(ee):
    """mu, mu_star, sigma (ddof 1) and n_used of EE (n, k) over the points, NaN excluded."""
    n_used = np.sum(np.isfinite(ee), axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        mu = np.nanmean(ee, axis=0) if ee.size else np.full(ee.shape[1], np.nan)
        mu_star = np.nanmean(np.abs(ee), axis=0)
        sigma = np.sqrt(np.nansum((ee - mu) ** 2, axis=0) / np.maximum(n_used - 1, 1))
    return {"mu": mu, "mu_star": mu_star, "sigma": sigma, "n_used": n_used.astype(float)}


def run(space, evaluate, labels, units, n=100, designs=10, step=None, seed=1, **_):
    """Constellation analysis.  ``evaluate(values) -> (Y, errors)`` runs the batch."""
    rng = np.random.default_rng(seed)
    U = design(space.k, n, designs, rng)
    M, h = star_points(space, U, step)
    Y, errors = evaluate(space.values(M))
    Y = np.where(np.array([e is None for e in errors])[:, None], Y, np.nan)
    ee = elementary_effects(space, Y, h)
    k = space.k
    zero_base = np.any(Y.reshape(n, k + 1, -1)[:, 0] == 0) and space.scheme == "multiplicative"

    def describe(i):
        p, j = divmod(i, k + 1)
        return f"point {p}" + ("" if j == 0 else f", step in {space.names[j - 1]}")

    rows = param_rows(space, labels, lambda j: statistics(ee[:, :, j]))
    eu = ["%/%" if space.scheme == "multiplicative" else (f"{u}/({pu})" if pu else u)
          for u in units for pu in space.units]
    eu_head = "%/%" if space.scheme == "multiplicative" else ""
    cols = {"output": "", "parameter": "", "unit": "", "lower": "", "centre": "", "upper": "",
            "mu": eu_head, "mu_star": eu_head, "sigma": eu_head, "n_used": "", "EE unit": ""}
    res = Result("constellation", space, labels, units, rows, cols, failure_list(errors, describe), len(Y),
                 {"ee": ee, "Y": Y.reshape(n, k + 1, -1), "points": M.reshape(n, k + 1, k), "ee_units": eu,
                  "rank_key": "mu_star", "zero_base": bool(zero_base)})
    for r, u in zip(rows, eu):
        r["EE unit"] = u
    return res
