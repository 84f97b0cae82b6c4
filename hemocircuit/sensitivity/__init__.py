"""Global and local sensitivity analysis of any output of a circuit (thesis chapter 4,
section "Sensitivity Analysis").

    spec = load_spec("sens.yaml")
    result = run(spec, objective)            # objective: outputs.make_objective(spec, circuit)

Modules: spec (the YAML), space (bounds, centres, ties), outputs (what is measured, batched),
constellation (the thesis's method), salib_methods (Morris, Sobol), local, dynamic, report
(CSV and plots).  The command is ``hemocircuit sensitivity NETLIST SPEC.yaml``
(hemocircuit/analyses/sensitivity.py).
"""
from __future__ import annotations

import functools

from .spec import load_spec, parse_spec  # noqa: F401


def prepare(spec, objective):
    """The resolved parameter space of ``spec`` on ``objective`` and the number of model
    evaluations its method will make, checked against the limits (SENS_RUNS, SENS_VALUES):
    everything :func:`run` checks before the first model evaluation."""
    from .. import limits
    from ..errors import FitSpecError
    from .space import resolve
    from .spec import check_runs

    space = resolve(spec, objective)
    runs = check_runs(spec.method, space.k, spec.file)
    if runs * len(objective.labels) > limits.limit("SENS_VALUES"):
        raise FitSpecError(f"{runs:,} model evaluations x {len(objective.labels):,} output components = "
                           f"{runs * len(objective.labels):,} values, more than allowed "
                           f"{limits.how_to_raise('SENS_VALUES')}; fewer points or output components",
                           file=spec.file, key="method")
    return space, runs


def run(spec, objective, scheduler=None, workers=None, progress=False):
    """Run the spec's method on ``objective``; returns a :class:`result.Result`."""
    from . import constellation, dynamic, local, salib_methods
    from .outputs import evaluate

    space, _ = prepare(spec, objective)
    ev = functools.partial(evaluate, objective, scheduler=scheduler, workers=workers, progress=progress)
    m = dict(spec.method)
    name = m.pop("name")
    args = (space, ev, list(objective.labels), list(objective.units))
    if name == "constellation":
        return constellation.run(*args, seed=spec.seed, **m)
    if name == "dynamic":
        return dynamic.run(*args, times=objective.times, n_columns=len(objective.columns), seed=spec.seed, **m)
    if name == "morris":
        return salib_methods.morris(*args, seed=spec.seed, **m)
    if name == "sobol":
        return salib_methods.sobol(*args, seed=spec.seed, **m)
    return local.run(*args, **m)
