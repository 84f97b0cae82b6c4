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


def run(spec, objective, scheduler=None, workers=None, progress=False):
    """Run the spec's method on ``objective``; returns a :class:`result.Result`."""
    from . import constellation, dynamic, local, salib_methods
    from .outputs import evaluate
    from .space import resolve

    space = resolve(spec, objective)
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
