"""DC sweep: the operating point along a parameter range, continued from point to point."""
from __future__ import annotations

import re

import numpy as np

from ..errors import HemocircuitError, Interrupted, NetlistError
from ..provenance import clock, stamp
from ..results import Result
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


def dc_sweep(circuit, param: str, values, progress=None):
    """Operating points for ``param`` (ID.PARAM) over ``values`` (array in the declared unit,
    or a range string like '20:200:5 mmHg').  Each point starts from the previous solution.

    Returns a :class:`SweepResult` indexed by ``param``.  A point that fails, for any reason
    (no operating point, a value outside the model's domain, a non-finite solution), is a NaN
    row, listed in ``result.failed`` [(value, reason)] (``metadata['failed']``) and in an
    ``error`` column; the sweep goes on.  Implausible values are ``metadata['warnings']``.
    Interrupted (SIGINT/SIGTERM), it raises :class:`~hemocircuit.errors.Interrupted` whose
    ``partial`` holds the points computed (the others: error 'not run (interrupted)').
    """
    from .op import operating_point

    started = clock()
    unit = circuit.param_unit(param)
    vals = parse_range(values, unit) if isinstance(values, str) else np.asarray(values, dtype=float)
    rows, failed, warnings = [], [], []
    x_prev = None
    from ..progress import bar
    try:
        with bar(len(vals), "dc sweep", unit="point", progress=progress) as b:
            for v in vals:
                b.update(1)
                try:
                    c = circuit.with_values({param: float(v)})
                    try:
                        op = operating_point(c, x0=x_prev)
                    except HemocircuitError:  # continuation failed: retry from a fresh DC guess
                        if x_prev is None:  # it was one already
                            raise
                        op = operating_point(c)
                except HemocircuitError as exc:
                    failed.append((float(v), str(exc)))
                    rows.append(None)
                    continue
                x_prev = op.x
                rows.append(op.values)
                warnings += [f"{param}={float(v):g}: {w}" for w in op.metadata.get("warnings", [])]
    except KeyboardInterrupt as exc:
        res = _sweep_result(circuit, param, unit, vals, rows, failed, warnings, values, started)
        raise Interrupted.of(exc, partial=res) from None
    return _sweep_result(circuit, param, unit, vals, rows, failed, warnings, values, started)


def _sweep_result(circuit, param, unit, vals, rows, failed, warnings, values, started):
    """The SweepResult of the rows computed (None: failed; missing at the end: not run)."""
    n_run = len(rows)
    rows = rows + [None] * (len(vals) - n_run)
    keys = next((list(r) for r in rows if r is not None), [])
    if not keys:  # no point solved: the columns the circuit would have had
        keys = list(circuit.column_units())
    out = {f"{param}": vals}
    for k in keys:
        out[k] = np.array([r[k] if r is not None else np.nan for r in rows])
    reasons = dict((v, why) for v, why in failed)
    if failed or n_run < len(vals):
        out["error"] = np.array([reasons.get(float(v), "") if i < n_run else "not run (interrupted)"
                                 for i, v in enumerate(vals)], dtype=object)
    units = {param: unit, **circuit.column_units()}
    res = SweepResult(out, units, failed, param)
    if warnings:
        res.metadata["warnings"] = warnings
    if n_run < len(vals):
        res.metadata["members_done"] = f"{n_run} of {len(vals)} points computed"
    # partial: some point has no answer (failed or not run); the table still has every row
    return stamp(res, "dc", circuit, {"param": param, "values": values if isinstance(values, str) else None,
                                      "continuation": True}, started,
                 status="partial" if failed or n_run < len(vals) else None)


class SweepResult(Result):
    """Operating points along a swept parameter (the index column); ``failed`` [(value, reason)]."""

    def __init__(self, data, units, failed, param=None):
        param = param or next(iter(data))
        super().__init__(data, units, index=[param])
        self.metadata["failed"] = [[v, why] for v, why in failed]

    @property
    def param(self):
        return self.index[0]

    @property
    def failed(self):
        return [(v, why) for v, why in self.metadata.get("failed", [])]
