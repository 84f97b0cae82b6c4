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

from ..errors import FitSpecError, NetlistError
from ..spec_inputs import shown
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
    for a fit error, the fit spec's bounds).  Errors name the spec file and the parameter's key."""
    m = spec.method
    params = spec.parameters or objective.default_parameters()
    if not params:
        raise FitSpecError("no parameters to vary", file=spec.file, key="parameters")
    names, keys, units, centre, lower, upper = [], [], [], [], [], []
    for i, p in enumerate(params):
        key = f"parameters[{i}]" if spec.parameters else f"output.{next(iter(spec.output), '')}"
        try:
            info = objective.parameter_info(p.path, p.event)
        except NetlistError as exc:
            raise FitSpecError(f"parameter {shown(p.name)}: {exc.bare_message}", file=spec.file, key=key) from None
        unit = info.get("unit", "")
        where = f"parameter {shown(p.name)}"

        def num(v, what, default):
            if v is None:
                return default
            try:
                x = parse_quantity(v, unit or "dimensionless", f"{where} {what}") if unit else float(v)
            except (UnitError, ValueError, TypeError, OverflowError) as exc:
                raise FitSpecError(f"{where}: {what} {shown(v)}: {str(exc)[:200]}", file=spec.file,
                                   key=f"{key}.{what}") from None
            if not np.isfinite(x):
                raise FitSpecError(f"{where}: {what} {shown(v)} must be finite", file=spec.file, key=f"{key}.{what}")
            return x

        c = num(p.centre, "centre", info.get("centre"))
        lo = num(p.lower, "lower", info.get("lower"))
        hi = num(p.upper, "upper", info.get("upper"))
        if m["scheme"] == "multiplicative":
            if c is None or not np.isfinite(c) or c == 0:
                raise FitSpecError(f"{where}: the multiplicative scheme needs a non-zero centre (got {c}); give "
                                   "'centre', or use scheme: additive with lower/upper", file=spec.file,
                                   key=f"{key}.centre")
            r = m["range"] / 100.0
            lo, hi = sorted((c * (1 - r), c * (1 + r)))
        else:
            if lo is None or hi is None:
                raise FitSpecError(f"{where}: the additive scheme needs 'lower' and 'upper'", file=spec.file, key=key)
            if not (np.isfinite(lo) and np.isfinite(hi)):
                raise FitSpecError(f"{where}: lower and upper must be finite", file=spec.file, key=key)
            if not hi > lo:
                raise FitSpecError(f"{where}: upper ({hi:g}) must exceed lower ({lo:g})", file=spec.file,
                                   key=f"{key}.upper")
            if c is None:
                c = 0.5 * (lo + hi)
        if not (np.isfinite(hi - lo) and np.isfinite(c)):
            raise FitSpecError(f"{where}: the range [{lo:g}, {hi:g}] is too wide for a floating-point number",
                               file=spec.file, key=key)
        for v in (lo, hi):
            problem = objective.check_value(p.path, v)
            if problem:
                raise FitSpecError(f"{where}: the range [{lo:g}, {hi:g}] leaves the parameter's physical "
                                   f"bounds ({problem}); narrow it", file=spec.file, key=key)
        names.append(p.name)
        keys.append(p.key)
        units.append(unit)
        centre.append(float(c))
        lower.append(float(lo))
        upper.append(float(hi))
    centre = np.array(centre)
    ties = []
    for i, t in enumerate(spec.ties):
        key = f"ties[{i}]"
        if t.source not in keys:
            raise FitSpecError(f"tie of {shown(t.path)}: scale_with {shown(t.source)} is not one of the varied "
                               f"parameters {shown(keys)}", file=spec.file, key=f"{key}.scale_with")
        if t.path in keys:
            raise FitSpecError(f"tie of {shown(t.path)}: it is also a varied parameter", file=spec.file, key=key)
        src = keys.index(t.source)
        if centre[src] == 0:
            raise FitSpecError(f"tie of {shown(t.path)}: its source {shown(t.source)} has centre 0", file=spec.file,
                               key=key)
        try:
            c_path = objective.parameter_info(t.path, None).get("centre")
        except NetlistError as exc:
            raise FitSpecError(f"tie of {shown(t.path)}: {exc.bare_message}", file=spec.file, key=f"{key}.path") \
                from None
        if c_path is None:
            raise FitSpecError(f"tie of {shown(t.path)}: no current value to scale", file=spec.file, key=key)
        if t.power < 0 and lower[src] <= 0 <= upper[src]:
            raise FitSpecError(f"tie of {shown(t.path)}: power {t.power:g} of {t.source}, whose range "
                               f"[{lower[src]:g}, {upper[src]:g}] includes 0; narrow the range", file=spec.file,
                               key=key)
        for v in (lower[src], upper[src]):
            tv = float(c_path) * (v / centre[src]) ** t.power if v != 0 or t.power >= 0 else float("inf")
            problem = None if not np.isfinite(tv) else objective.check_value(t.path, tv)
            if not np.isfinite(tv) or problem:
                raise FitSpecError(f"tie of {shown(t.path)}: at {t.source} = {v:g} it takes {tv:g}, which it may not"
                                   + (f" ({problem})" if problem else "") + "; narrow the range of "
                                   f"{t.source} or change the power", file=spec.file, key=key)
        ties.append((t.path, src, float(c_path), t.power))
    return Space(names, keys, units, centre, np.array(lower), np.array(upper), m["scheme"], m["range"], ties)
