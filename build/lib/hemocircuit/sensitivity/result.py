"""The result of a sensitivity analysis, shared by all methods."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class Result:
    """``table``: one dict per (output component, parameter) with the method's statistics;
    ``columns``: {table key: unit} in order (the CSV headers are 'key [unit]');
    ``failures``: [(sample description, reason)]; ``n_runs``: model evaluations made;
    ``extra``: method-specific arrays (elementary effects, baseline responses, times)."""
    method: str
    space: object
    labels: list
    units: list
    table: list
    columns: dict
    failures: list = field(default_factory=list)
    n_runs: int = 0
    extra: dict = field(default_factory=dict)

    def ranking(self, output=0, key=None):
        """Parameter names of output component ``output``, most important first."""
        key = key or self.extra.get("rank_key", "mu_star")
        rows = [r for r in self.table if r["output"] == self.labels[output]]
        return [r["parameter"] for r in sorted(rows, key=lambda r: -np.nan_to_num(abs(r[key]), nan=-1.0))]

    def values(self, key, output=0):
        """{parameter: value of ``key``} for output component ``output``."""
        return {r["parameter"]: r[key] for r in self.table if r["output"] == self.labels[output]}


def failure_list(errors, describe):
    """[(description of sample i, reason)] for the failed members."""
    return [(describe(i), e) for i, e in enumerate(errors) if e is not None]


def param_rows(space, labels, per_output):
    """Rows (output x parameter) from per_output(j) -> {stat: (k,) array}."""
    rows = []
    for j, lab in enumerate(labels):
        stats = per_output(j)
        for i, name in enumerate(space.names):
            row = {"output": lab, "parameter": name, "unit": space.units[i], "lower": space.lower[i],
                   "centre": space.centre[i], "upper": space.upper[i]}
            row.update({k: float(v[i]) for k, v in stats.items()})
            rows.append(row)
    return rows
