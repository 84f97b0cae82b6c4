"""How a result's rows are grouped and labelled in legends and messages (below both the results
and the plots that use them)."""
from __future__ import annotations

import numpy as np


def label_value(v) -> str:
    """A grid or sweep value as written in plot legends and messages (4 significant figures)."""
    return f"{v:.4g}" if isinstance(v, (float, np.floating)) else str(v)


def members(res, columns=None):
    """Rows of a result grouped by ``columns`` (default: its grid parameters, else every index
    column but the last): [(label, row mask)] in order of first appearance, one group (the
    whole table) when there is nothing to group by.  ``label`` reads 'art.tau_Ca=10 s, art.ca_order=2'."""
    if columns is None:
        columns = [p for p in res.metadata.get("grid", []) if p in res.data] or \
            [p for p in res.index[:-1] if p in res.data]
    if not columns:
        return [("", np.ones(res.n_rows, bool))]
    keys = list(dict.fromkeys(zip(*(res[p].tolist() for p in columns))))
    out = []
    for key in keys:
        mask = np.all([np.array([x == v for x in res[p].tolist()]) for p, v in zip(columns, key)], axis=0)
        lab = ", ".join(f"{p}={label_value(v)} {_unit(res.units.get(p, ''))}".rstrip() for p, v in zip(columns, key))
        out.append((lab, mask))
    return out


def _unit(u):
    return "" if u in ("1", "dimensionless") else u
