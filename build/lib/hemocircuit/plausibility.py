"""Plausibility of a computed solution: an implausible result is never silent.

Checked on the solution's columns (an operating point, a time series, the members of a batch):

* a state or output that is not finite (NaN, inf)                           -> error
* a pressure (a column in mmHg) beyond +/- ``PRESSURE_LIMIT`` = 1e4 mmHg     -> warning
  (about 13 atm: far outside any circulation; such numbers come from a value off by orders of
  magnitude, e.g. R = 1e300 mmHg*s/mL in series with a flow source)
* a quantity outside its component's physical range                        -> warning
  (:meth:`hemocircuit.component.Component.physical_limits`, e.g. a compliance's stored
  volume below 0 mL)

Each finding names its column and so the node (``P(node)``) or the element.  The one place
these checks live; used by op (:func:`hemocircuit.analyses.op.operating_point`: an error
raises SolverError, warnings go to ``metadata['warnings']``), tran
(:func:`hemocircuit.analyses.transient.simulate`) and the batch analyses per member (dc,
stability, compare through op; freq and envelope on each member's run).  The CLI prints every
warning on stderr.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

PRESSURE_LIMIT = 1e4  # mmHg


@dataclass(frozen=True)
class Finding:
    """One implausible column: ``severity`` 'error' or 'warning', ``column``, ``text``."""

    severity: str
    column: str
    text: str

    def __str__(self):
        return self.text


def _limits(circuit):
    """{column: (lower, upper, element id)} from the components' physical_limits (per structure)."""
    def compute():
        out = {}
        for g in circuit.groups:
            lim = g.comp.physical_limits()
            if not lim:
                continue
            vols = set(g.comp.volume_observables())
            for e in g.ids:
                for name, (lo, hi) in lim.items():
                    out[f"V({e})" if name in vols else f"{e}.{name}"] = (lo, hi, e)
        return out

    structure = getattr(circuit, "structure", None)
    return structure.cached(("plausibility_limits",), compute) if structure is not None else compute()


def _where(column):
    """'P(a)' -> "node 'a'"; 'Q(R1)', 'V(C1)', 'art.r' -> "element 'R1'" ..."""
    if column.startswith("P(") and column.endswith(")"):
        return f"node '{column[2:-1]}'"
    if column[:2] in ("Q(", "V(") and column.endswith(")"):
        return f"element '{column[2:-1]}'"
    if "." in column:
        return f"element '{column.split('.', 1)[0]}'"
    return f"'{column}'"


def _rows(mask, members, t):
    """' in member 0, 3' / ' from t = 12.5 s' / '' for the rows of ``mask``."""
    idx = np.nonzero(mask)[0]
    if members and mask.size > 1:
        shown = ", ".join(str(int(k)) for k in idx[:5]) + (", ..." if idx.size > 5 else "")
        return f" in member{'s' if idx.size > 1 else ''} {shown}"
    if t is not None and mask.size > 1:
        return f" from t = {float(np.asarray(t)[idx[0]]):.6g} s"
    return ""


def check(circuit, columns, members=False, t=None):
    """Findings for ``columns`` {name: value or 1-D array} of ``circuit``'s outputs (other
    names are ignored).  ``members``: axis 0 is the members of a batch (findings name them);
    otherwise it is time (``t``: the times, to say when).  Returns [Finding], errors first."""
    units = circuit.structure.cached(("column_units",), circuit.column_units) \
        if getattr(circuit, "structure", None) is not None else circuit.column_units()
    limits = _limits(circuit)
    errors, warnings = [], []
    for name, unit in units.items():
        if name not in columns:
            continue
        v = np.atleast_1d(np.asarray(columns[name], dtype=float))
        if v.size == 0:
            continue
        bad = ~np.isfinite(v)
        if bad.any():
            errors.append(Finding("error", name, f"{name} is {v[bad][0]} (not finite){_rows(bad, members, t)} "
                                                 f"at {_where(name)}"))
            continue
        if unit == "mmHg":
            high = np.abs(v) > PRESSURE_LIMIT
            if high.any():
                worst = v[np.argmax(np.abs(v))]
                warnings.append(Finding("warning", name, f"{name} = {worst:.4g} mmHg{_rows(high, members, t)}: "
                                                         f"beyond +/-{PRESSURE_LIMIT:g} mmHg, implausible; check the "
                                                         f"values of the elements at {_where(name)}"))
        if name in limits:
            lo, hi, eid = limits[name]
            tol = 1e-9 * max(1.0, abs(lo if lo is not None else hi or 0.0))
            out = np.zeros(v.shape, bool)
            if lo is not None:
                out |= v < lo - tol
            if hi is not None:
                out |= v > hi + tol
            if out.any():
                worst = v[out][np.argmax(np.abs(v[out]))]
                rng = " and ".join(x for x in ((f">= {lo:g}" if lo is not None else ""),
                                               (f"<= {hi:g}" if hi is not None else "")) if x)
                warnings.append(Finding("warning", name, f"{name} = {worst:.4g} {unit}{_rows(out, members, t)}: "
                                                         f"outside the physical range of element '{eid}' "
                                                         f"({rng} {unit})"))
    return errors + warnings


def check_members(circuit, columns):
    """Per member of a batch: [[Finding], ...] (B lists), checking each member's values."""
    B = len(next(iter(columns.values()))) if columns else 0
    return [check(circuit, {k: np.atleast_1d(v)[b] for k, v in columns.items()}) for b in range(B)]


def errors(findings):
    return [f for f in findings if f.severity == "error"]


def warnings(findings):
    return [f for f in findings if f.severity == "warning"]


def add_warnings(result, findings, where=None):
    """Record the warnings of ``findings`` in ``result.metadata['warnings']`` (text, prefixed
    by ``where`` for a batch member) and return them."""
    ws = [f.text if where is None else f"{where}: {f.text}" for f in warnings(findings)]
    if ws:
        result.metadata.setdefault("warnings", []).extend(w for w in ws if w not in result.metadata["warnings"])
    return ws
