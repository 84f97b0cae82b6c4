"""Time-dependent source values: steps, piecewise-linear/constant tables, sines and sums.

Netlist forms (every number with a unit; the source's own unit gives the value dimension):
  value: 80 mmHg                                   constant
  value: {steps: [[0 s, 80 mmHg], [10 s, 72 mmHg]]}   value from each time on (alias: pwc)
  value: {pwl: [[0 s, 80 mmHg], [5 s, 90 mmHg]]}      linear interpolation, held outside
  value: {pwl: {file: table.csv}}                  CSV (two columns, header 'time [s],value [mmHg]')
  value: {sine: {offset: 80 mmHg, amplitude: 8 mmHg, frequency: 0.1 Hz, phase: 0 deg, start: 0 s}}
  value: {sum: [<waveform>, <waveform>, ...]}
Tables are parsed at load time; evaluation is plain numpy.  ``breakpoints()`` lists the times
where the value or its slope jumps, so the transient solver restarts there.
"""
from __future__ import annotations

import csv
import os
import re
from dataclasses import dataclass

import numpy as np

from .errors import NetlistError
from .units import UnitError, parse_quantity


class Waveform:
    def __call__(self, t: float) -> float:
        raise NotImplementedError

    def breakpoints(self) -> list[float]:
        return []


@dataclass
class Constant(Waveform):
    value: float

    def __call__(self, t):
        return self.value


@dataclass
class Table(Waveform):
    times: np.ndarray
    values: np.ndarray
    linear: bool

    def __call__(self, t):
        if self.linear:
            return float(np.interp(t, self.times, self.values))
        i = np.searchsorted(self.times, t, side="right") - 1
        return float(self.values[max(i, 0)])

    def breakpoints(self):
        return [float(x) for x in self.times]


@dataclass
class Sine(Waveform):
    offset: float
    amplitude: float
    frequency: float  # Hz
    phase: float  # rad
    start: float  # s

    def __call__(self, t):
        if t < self.start:
            return self.offset
        return self.offset + self.amplitude * np.sin(2 * np.pi * self.frequency * (t - self.start) + self.phase)

    def breakpoints(self):
        return [self.start]


@dataclass
class Sum(Waveform):
    parts: list

    def __call__(self, t):
        return sum(p(t) for p in self.parts)

    def breakpoints(self):
        return sorted({b for p in self.parts for b in p.breakpoints()})


def _table_rows(spec, base_dir, unit, where):
    if isinstance(spec, dict) and "file" in spec:
        if not isinstance(spec["file"], str) or not spec["file"] or len(spec) != 1:
            raise NetlistError(f"a table file is given as {{file: NAME.csv}}, got {spec!r}", **where)
        path = spec["file"] if os.path.isabs(spec["file"]) else os.path.join(base_dir or ".", spec["file"])
        if not os.path.isfile(path):
            raise NetlistError(f"table file not found: {path}", **where)
        try:
            with open(path, newline="") as fh:
                rows = [r for r in csv.reader(fh) if r and not r[0].lstrip().startswith("#")]
        except (OSError, UnicodeDecodeError, csv.Error) as exc:
            raise NetlistError(f"table file {path}: cannot read: {exc}", **where) from None
        if len(rows) < 2:
            raise NetlistError(f"table file {path}: needs a header 'time [s],value [UNIT]' and at least one row",
                               **where)
        header, rows = rows[0], rows[1:]
        units = []
        for h in header[:2]:
            m = re.search(r"\[(.+)\]", h)
            if not m:
                raise NetlistError(f"table file {path}: header {h!r} must give its unit in brackets, "
                                   "e.g. 'time [s]'", **where)
            units.append(m.group(1))
        try:
            return [(parse_quantity(f"{r[0]} {units[0]}", "s"), parse_quantity(f"{r[1]} {units[1]}", unit))
                    for r in rows]
        except (UnitError, IndexError) as exc:
            raise NetlistError(f"table file {path}: {exc}", **where) from None
    if not isinstance(spec, list) or not spec:
        raise NetlistError("a table needs a non-empty list of [time, value] pairs or {file: ...}", **where)
    out = []
    for row in spec:
        if not isinstance(row, (list, tuple)) or len(row) != 2:
            raise NetlistError(f"table row {row!r} is not a [time, value] pair", **where)
        out.append((parse_quantity(row[0], "s", "table time"), parse_quantity(row[1], unit, "table value")))
    return out


def parse_waveform(spec, unit: str, base_dir=None, where=None) -> Waveform:
    """Build a Waveform from a netlist value (constant or mapping)."""
    where = where or {}
    try:
        if not isinstance(spec, dict):
            return Constant(parse_quantity(spec, unit, "value"))
        if len(spec) != 1:
            raise NetlistError(f"a waveform has exactly one kind (steps, pwl, pwc, sine, sum); got {sorted(spec)}",
                               **where)
        (kind, body), = spec.items()
        if kind in ("steps", "pwc", "pwl"):
            # stable sort on time only: rows with equal times keep their order (a jump)
            rows = sorted(_table_rows(body, base_dir, unit, where), key=lambda r: r[0])
            t = np.array([r[0] for r in rows])
            v = np.array([r[1] for r in rows])
            if not (np.all(np.isfinite(t)) and np.all(np.isfinite(v))):
                raise NetlistError(f"{kind} table: every time and value must be finite", **where)
            return Table(t, v, linear=(kind == "pwl"))
        if kind == "sine":
            if not isinstance(body, dict):
                raise NetlistError("sine needs a mapping {offset, amplitude, frequency, phase, start}", **where)
            unknown = set(body) - {"offset", "amplitude", "frequency", "phase", "start"}
            if unknown:
                raise NetlistError(f"unknown sine field(s) {sorted(unknown)}", **where)
            sine = Sine(offset=parse_quantity(body.get("offset", f"0 {unit}"), unit, "sine offset"),
                        amplitude=parse_quantity(body.get("amplitude", f"0 {unit}"), unit, "sine amplitude"),
                        frequency=parse_quantity(body.get("frequency", "0 Hz"), "Hz", "sine frequency"),
                        phase=parse_quantity(body.get("phase", "0 rad"), "rad", "sine phase"),
                        start=parse_quantity(body.get("start", "0 s"), "s", "sine start"))
            if not np.all(np.isfinite([sine.offset, sine.amplitude, sine.frequency, sine.phase, sine.start])):
                raise NetlistError("sine: every field must be finite", **where)
            return sine
        if kind == "sum":
            if not isinstance(body, list) or not body:
                raise NetlistError("sum needs a non-empty list of waveforms", **where)
            return Sum([parse_waveform(b, unit, base_dir, where) for b in body])
        raise NetlistError(f"unknown waveform kind {kind!r} (use steps, pwl, pwc, sine or sum)", **where)
    except UnitError as exc:
        raise NetlistError(str(exc), **where) from None
