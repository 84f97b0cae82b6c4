"""DC sweep: the operating point along a parameter range, continued from point to point."""
from __future__ import annotations

import re

import numpy as np

from ..errors import NetlistError, SolverError
from ..units import UnitError, parse_quantity


MAX_POINTS = 1_000_000  # points of one sweep
_BARE_NUMBER = re.compile(r"^[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$")


def parse_range(spec: str, unit: str) -> np.ndarray:
    """'20:200:5 mmHg' (start:stop:step, stop included) or '1,2,5 s' -> values in ``unit``."""
    text = spec.strip()
    parts = text.split()
    body, u = (parts[0], " ".join(parts[1:])) if len(parts) > 1 else (text, "")
    m = re.match(r"^([-+0-9.eE]+):([-+0-9.eE]+):([-+0-9.eE]+)([A-Za-z].*)?$", body)
    try:
        if m:
            u = u or (m.group(4) or "")
            a, b, s = (parse_quantity(f"{m.group(i)} {u}".strip(), unit, "sweep") if u else float(m.group(i))
                       for i in (1, 2, 3))
            if not u and unit not in ("dimensionless", "", "1"):
                raise NetlistError(f"sweep range {spec!r} needs a unit (in {unit})")
            if not np.all(np.isfinite([a, b, s])):
                raise NetlistError(f"sweep range {spec!r}: start, stop and step must be finite")
            if s == 0 or (b - a) / s < 0:
                raise NetlistError(f"sweep range {spec!r}: the step must move from start towards stop")
            n = (b - a) / s
            if not n < MAX_POINTS:
                raise NetlistError(f"sweep range {spec!r} has {n:.3g} points, more than {MAX_POINTS:,}")
            return a + s * np.arange(int(np.floor(n + 1e-9)) + 1)
        items = [x for x in re.split(r",", text) if x.strip()]
        if not items:
            raise NetlistError(f"sweep {spec!r}: no values (write START:STOP:STEP UNIT or V1,V2,... UNIT)")
        if len(items) > MAX_POINTS:
            raise NetlistError(f"sweep {spec[:60]!r}: more than {MAX_POINTS:,} values")
        # a unit written once at the end applies to every item: '1,2,5 s'
        last = items[-1].strip().split()
        tail = " ".join(last[1:]) if len(last) > 1 else ""
        vals = []
        for it in items:
            it = it.strip()
            if tail and _BARE_NUMBER.match(it):  # '1e8' is a number, not '1' with a unit 'e8'
                it = f"{it} {tail}"
            vals.append(parse_quantity(it, unit, "sweep value"))
        vals = np.array(vals)
        if not np.all(np.isfinite(vals)):
            raise NetlistError(f"sweep {spec[:60]!r}: every value must be finite")
        return vals
    except (UnitError, ValueError) as exc:
        raise NetlistError(f"sweep {spec[:60]!r}: {exc}") from None


def dc_sweep(circuit, param: str, values, progress=False):
    """Operating points for ``param`` (ID.PARAM) over ``values`` (array in the declared unit,
    or a range string like '20:200:5 mmHg').  Each point starts from the previous solution.

    Returns a dict column -> array with the swept parameter first; points that fail are NaN
    and listed in result['_failed'] with their reasons.
    """
    from .op import operating_point

    unit = circuit.param_unit(param)
    vals = parse_range(values, unit) if isinstance(values, str) else np.asarray(values, dtype=float)
    c = circuit.copy()
    rows, failed = [], []
    x_prev = None
    for v in vals:
        c.set_param(param, float(v))
        try:
            op = operating_point(c, x0=None if x_prev is None else x_prev)
        except SolverError:
            try:  # continuation failed: retry from a fresh DC guess
                op = operating_point(c)
            except SolverError as exc2:
                failed.append((float(v), str(exc2)))
                rows.append(None)
                continue
        x_prev = op.x
        rows.append(op.values)
    keys = next((list(r) for r in rows if r is not None), [])
    out = {f"{param}": vals}
    for k in keys:
        out[k] = np.array([r[k] if r is not None else np.nan for r in rows])
    units = {param: unit, **c.column_units()}
    return SweepResult(out, units, failed)


class SweepResult(dict):
    """Columns of a sweep (dict name -> array) with units and failures."""

    def __init__(self, data, units, failed):
        super().__init__(data)
        self.units = units
        self.failed = failed
