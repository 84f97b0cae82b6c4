"""DC sweep: the operating point along a parameter range, continued from point to point."""
from __future__ import annotations

import numpy as np

from ..errors import NetlistError, SolverError
from ..provenance import clock, stamp
from ..results import Result
from ..units import UnitError, parse_quantity


def parse_range(spec: str, unit: str) -> np.ndarray:
    """'20:200:5 mmHg' (start:stop:step, stop included) or '1,2,5 s' -> values in ``unit``."""
    text = spec.strip()
    parts = text.split()
    body, u = (parts[0], " ".join(parts[1:])) if len(parts) > 1 else (text, "")
    import re
    m = re.match(r"^([-+0-9.eE]+):([-+0-9.eE]+):([-+0-9.eE]+)([A-Za-z].*)?$", body)
    try:
        if m:
            u = u or (m.group(4) or "")
            a, b, s = (parse_quantity(f"{m.group(i)} {u}".strip(), unit, "sweep") if u else float(m.group(i))
                       for i in (1, 2, 3))
            if not u and unit not in ("dimensionless", "", "1"):
                raise NetlistError(f"sweep range {spec!r} needs a unit (in {unit})")
            if s == 0 or (b - a) / s < 0:
                raise NetlistError(f"sweep range {spec!r}: the step must move from start towards stop")
            n = int(np.floor((b - a) / s + 1e-9)) + 1
            return a + s * np.arange(n)
        items = [x for x in re.split(r",", text) if x.strip()]
        # a unit written once at the end applies to every item: '1,2,5 s'
        last = items[-1].strip().split()
        tail = " ".join(last[1:]) if len(last) > 1 else ""
        vals = []
        for it in items:
            it = it.strip()
            if tail and len(it.split()) == 1 and not re.search(r"[A-Za-z]", it):
                it = f"{it} {tail}"
            vals.append(parse_quantity(it, unit, "sweep value"))
        return np.array(vals)
    except UnitError as exc:
        raise NetlistError(f"sweep {spec!r}: {exc}") from None


def dc_sweep(circuit, param: str, values, progress=None):
    """Operating points for ``param`` (ID.PARAM) over ``values`` (array in the declared unit,
    or a range string like '20:200:5 mmHg').  Each point starts from the previous solution.

    Returns a :class:`SweepResult` indexed by ``param``; points that fail are NaN rows and
    listed in ``result.failed`` [(value, reason)] (``metadata['failed']``).
    """
    from .op import operating_point

    started = clock()
    unit = circuit.param_unit(param)
    vals = parse_range(values, unit) if isinstance(values, str) else np.asarray(values, dtype=float)
    rows, failed = [], []
    x_prev = None
    from ..progress import bar
    with bar(len(vals), "dc sweep", unit="point", progress=progress) as b:
        for v in vals:
            b.update(1)
            c = circuit.with_values({param: float(v)})
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
    units = {param: unit, **circuit.column_units()}
    res = SweepResult(out, units, failed, param)
    return stamp(res, "dc", circuit, {"param": param, "values": values if isinstance(values, str) else None,
                                      "continuation": True}, started)


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
