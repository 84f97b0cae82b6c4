"""Morris (mu*, sigma) and Sobol (first and total order, Saltelli sampling) through SALib.

The samples come from SALib, run as one batch through the objective, and go back to SALib's
analysers.  Failed runs: a Morris trajectory or a Saltelli block (k + 2 rows) containing one
is dropped whole (the analysers need complete ones) and reported.
Morris elementary effects are SALib's: output change per unit of the *normalised* range
(output unit), so parameters of different units compare directly.
"""
from __future__ import annotations

import numpy as np

from .result import Result, failure_list, param_rows


def _problem(space):
    return {"num_vars": space.k, "names": list(space.names),
            "bounds": [[float(lo), float(hi)] for lo, hi in zip(space.lower, space.upper)]}


def _complete(errors, block):
    """Mask of rows in blocks of ``block`` rows without a failure."""
    ok = np.array([e is None for e in errors]).reshape(-1, block)
    return np.repeat(ok.all(axis=1), block)


def morris(space, evaluate, labels, units, trajectories=20, levels=4, seed=1, **_):
    from SALib.analyze import morris as morris_analyze
    from SALib.sample import morris as morris_sample

    prob = _problem(space)
    X = morris_sample.sample(prob, trajectories, num_levels=levels, seed=seed)
    Y, errors = evaluate(space.values(X))
    keep = _complete(errors, space.k + 1)
    if keep.sum() < 2 * (space.k + 1):
        from ..errors import SolverError
        raise SolverError(f"morris: fewer than two complete trajectories ({int(keep.sum()) // (space.k + 1)} "
                          f"of {trajectories}); first failure: {next(e for e in errors if e)}")

    def stats(j):
        r = morris_analyze.analyze(prob, X[keep], Y[keep, j], num_levels=levels, seed=seed,
                                   print_to_console=False)
        return {"mu": np.asarray(r["mu"]), "mu_star": np.asarray(r["mu_star"]), "sigma": np.asarray(r["sigma"]),
                "mu_star_conf": np.asarray(r["mu_star_conf"]),
                "n_used": np.full(space.k, keep.sum() // (space.k + 1), float)}

    rows = param_rows(space, labels, stats)
    for r in rows:
        r["EE unit"] = units[labels.index(r["output"])] + " per range"
    cols = {"output": "", "parameter": "", "unit": "", "lower": "", "centre": "", "upper": "", "mu": "",
            "mu_star": "", "sigma": "", "mu_star_conf": "", "n_used": "", "EE unit": ""}
    k1 = space.k + 1
    return Result("morris", space, labels, units, rows, cols,
                  failure_list(errors, lambda i: f"trajectory {i // k1}, point {i % k1}"), len(Y),
                  {"rank_key": "mu_star", "X": X, "Y": Y})


def sobol(space, evaluate, labels, units, n=256, conf_level=0.95, resamples=100, seed=1, **_):
    from SALib.analyze import sobol as sobol_analyze
    from SALib.sample import sobol as sobol_sample

    prob = _problem(space)
    X = sobol_sample.sample(prob, n, calc_second_order=False, seed=seed)
    Y, errors = evaluate(space.values(X))
    keep = _complete(errors, space.k + 2)
    if keep.sum() < 2 * (space.k + 2):
        from ..errors import SolverError
        raise SolverError(f"sobol: fewer than two complete Saltelli blocks; first failure: "
                          f"{next(e for e in errors if e)}")

    def stats(j):
        r = sobol_analyze.analyze(prob, Y[keep, j], calc_second_order=False, num_resamples=resamples,
                                  conf_level=conf_level, seed=seed, print_to_console=False)
        return {"S1": np.asarray(r["S1"]), "S1_conf": np.asarray(r["S1_conf"]), "ST": np.asarray(r["ST"]),
                "ST_conf": np.asarray(r["ST_conf"]), "n_used": np.full(space.k, keep.sum() // (space.k + 2), float)}

    rows = param_rows(space, labels, stats)
    cols = {"output": "", "parameter": "", "unit": "", "lower": "", "centre": "", "upper": "", "S1": "",
            "S1_conf": "", "ST": "", "ST_conf": "", "n_used": ""}
    k2 = space.k + 2
    return Result("sobol", space, labels, units, rows, cols,
                  failure_list(errors, lambda i: f"Saltelli block {i // k2}, row {i % k2}"), len(Y),
                  {"rank_key": "ST", "conf_level": conf_level})
