"""The parameter space of a sensitivity spec, resolved to numbers in each parameter's unit.

additive scheme: [lower, upper] as given (thesis table tabBounds);
multiplicative scheme: centre * (1 -/+ range/100) (thesis: +/-10 % and +/-50 % around the
fitted values).  Ties follow a varied parameter: value = centre * (source/centre_source)**power,
e.g. f1 ~ 1/v, which keeps f1 v and hence the steady state unchanged (thesis, dynamic
sensitivity on Kuo91 A).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import NetlistError
from ..units import UnitError, parse_quantity


@dataclass
class Space:
    names: list
    keys: list  # value-mapping keys (path, or path@event)
    units: list
    centre: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    scheme: str
    range_pct: float
    ties: list  # [(path, index of source, centre of path, power)]

    @property
    def k(self):
        return len(self.names)

    def from_unit(self, U):
        """Unit-cube points (B, k) -> parameter values (B, k)."""
        return self.lower + np.asarray(U) * (self.upper - self.lower)

    def values(self, M):
        """Parameter values (B, k) -> {key: (B,) array}, ties included."""
        M = np.atleast_2d(M)
        out = {key: M[:, i].copy() for i, key in enumerate(self.keys)}
        for path, src, c_path, power in self.ties:
            out[path] = c_path * (M[:, src] / self.centre[src]) ** power
        return out


def resolve(spec, objective) -> Space:
    """Numbers for every parameter of ``spec``: its unit, centre and bounds (from the spec,
    else from ``objective.parameter_info(path, event)``: the circuit's current value and,
    for a fit error, the fit spec's bounds)."""
    m = spec.method
    params = spec.parameters or objective.default_parameters()
    if not params:
        raise NetlistError("no parameters to vary", file=spec.file)
    names, keys, units, centre, lower, upper = [], [], [], [], [], []
    for p in params:
        info = objective.parameter_info(p.path, p.event)
        unit = info.get("unit", "")
        where = f"parameter {p.name!r}"

        def num(v, what, default):
            if v is None:
                return default
            try:
                return parse_quantity(v, unit or "dimensionless", f"{where} {what}") if unit else float(v)
            except (UnitError, ValueError, TypeError) as exc:
                raise NetlistError(f"{where}: {what} {v!r}: {exc}", file=spec.file) from None

        c = num(p.centre, "centre", info.get("centre"))
        lo = num(p.lower, "lower", info.get("lower"))
        hi = num(p.upper, "upper", info.get("upper"))
        if m["scheme"] == "multiplicative":
            if c is None or not np.isfinite(c) or c == 0:
                raise NetlistError(f"{where}: the multiplicative scheme needs a non-zero centre (got {c}); give "
                                   "'centre', or use scheme: additive with lower/upper", file=spec.file)
            r = m["range"] / 100.0
            lo, hi = sorted((c * (1 - r), c * (1 + r)))
        else:
            if lo is None or hi is None:
                raise NetlistError(f"{where}: the additive scheme needs 'lower' and 'upper'", file=spec.file)
            if not hi > lo:
                raise NetlistError(f"{where}: upper ({hi:g}) must exceed lower ({lo:g})", file=spec.file)
            if c is None:
                c = 0.5 * (lo + hi)
        for v in (lo, hi):
            problem = objective.check_value(p.path, v)
            if problem:
                raise NetlistError(f"{where}: the range [{lo:g}, {hi:g}] leaves the parameter's physical "
                                   f"bounds ({problem}); narrow it", file=spec.file)
        names.append(p.name)
        keys.append(p.key)
        units.append(unit)
        centre.append(float(c))
        lower.append(float(lo))
        upper.append(float(hi))
    centre = np.array(centre)
    ties = []
    for t in spec.ties:
        src = keys.index(t.source)
        if centre[src] == 0:
            raise NetlistError(f"tie of {t.path}: its source {t.source} has centre 0", file=spec.file)
        c_path = objective.parameter_info(t.path, None).get("centre")
        if c_path is None:
            raise NetlistError(f"tie of {t.path}: no current value to scale", file=spec.file)
        ties.append((t.path, src, float(c_path), t.power))
    return Space(names, keys, units, centre, np.array(lower), np.array(upper), m["scheme"], m["range"], ties)
