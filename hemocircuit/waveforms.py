"""Time-dependent source values: steps, piecewise-linear/constant tables, sines and sums.

Netlist forms (every number with a unit; the source's own unit gives the value dimension):
  value: 80 mmHg                                   constant
  value: {steps: [[0 s, 80 mmHg], [10 s, 72 mmHg]]}   value from each time on (alias: pwc)
  value: {pwl: [[0 s, 80 mmHg], [5 s, 90 mmHg]]}      linear interpolation, held outside
  value: {pwl: {file: table.csv}}                  CSV (two columns, header 'time [s],value [mmHg]')
  value: {sine: {offset: 80 mmHg, amplitude: 8 mmHg, frequency: 0.1 Hz, phase: 0 deg, start: 0 s}}
  value: {sum: [<waveform>, <waveform>, ...]}
  value: {noise: {mean: 90 mmHg, sd: 5 mmHg, band: [0.02 Hz, 0.5 Hz], period: 600 s, seed: 1}}
                                                   seeded band-limited random fluctuations (a
                                                   Gaussian process): a sum of sines at the
                                                   frequencies k/period inside the band, with
                                                   random amplitudes and phases from ``seed``,
                                                   scaled so the standard deviation over one
                                                   period is exactly ``sd``; it repeats after
                                                   ``period`` (default 600 s); ``start``: the
                                                   value is ``mean`` before it
  value: {periodic: {period: 1 s, pwl: [[0 s, 5 mL/s], ..., [1 s, 5 mL/s]]}}
                                                   one cycle of a table (pwl or steps), repeated:
                                                   evaluated at t0 + (t - t0) mod period, t0 its
                                                   first time (svZeroDSolver's time series)
Tables are parsed at load time; evaluation is plain numpy.  ``breakpoints(t0, t1)`` lists the
times in (t0, t1) where the value or its slope jumps (a pwl table's times, less those between
two intervals of the same slope), so the transient solver restarts there;
``jumps(t0, t1)`` the ones of them where the value itself may jump (the others are slope-only
kinks, where the compiled integrator ends a step but needs no new evaluation).
"""
from __future__ import annotations

import os
import re
from dataclasses import dataclass

import numpy as np

from . import limits
from .errors import NetlistError, did_you_mean, excerpt
from .units import UnitError, parse_quantity


class Waveform:
    def __call__(self, t: float) -> float:
        raise NotImplementedError

    def breakpoints(self, t0=-np.inf, t1=np.inf) -> list[float]:
        """Times where the value or its slope jumps (those in (t0, t1) at least; a periodic
        waveform needs a finite range)."""
        return []

    def jumps(self, t0=-np.inf, t1=np.inf) -> list[float]:
        """The breakpoints where the value itself may jump, not only its slope (by default all)."""
        return self.breakpoints(t0, t1)

    def sample(self, t) -> np.ndarray:
        """Values at the times ``t`` (1-D array) [s]: the numbers calling it at each time gives
        (the output of a run evaluates every source at all its rows at once)."""
        return np.array([self(x) for x in np.asarray(t, dtype=float).reshape(-1).tolist()], dtype=float)

    def value_range(self) -> tuple[float, float]:
        """(lowest, highest) value it can take (at most: a sum adds its parts' ranges), for the
        bounds check of a parameter that takes a waveform."""
        raise NotImplementedError


@dataclass
class Constant(Waveform):
    value: float

    def __call__(self, t):
        return self.value

    def sample(self, t):
        return np.full(np.asarray(t).reshape(-1).shape, float(self.value))

    def value_range(self):
        return float(self.value), float(self.value)


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

    def value_range(self):
        return float(np.min(self.values)), float(np.max(self.values))

    def sample(self, t):
        t = np.asarray(t, dtype=float).reshape(-1)
        if self.linear:  # np.interp of an array: element by element the scalar call's numbers
            return np.interp(t, self.times, self.values).astype(float)
        i = np.searchsorted(self.times, t, side="right") - 1
        return np.asarray(self.values, dtype=float)[np.maximum(i, 0)]

    def breakpoints(self, t0=-np.inf, t1=np.inf):
        if not self.linear:
            return [float(x) for x in self.times]
        # linear interpolation: an interior time between two intervals of the same slope
        # (e.g. a run of equal values, as the zero diastole of svZeroDSolver's pressure
        # tables) is no kink; the ends, repeated times and every slope change are
        t, v = np.asarray(self.times, dtype=float), np.asarray(self.values, dtype=float)
        keep = np.ones(t.size, bool)
        if t.size > 2:
            dt0, dt1 = t[1:-1] - t[:-2], t[2:] - t[1:-1]
            with np.errstate(over="ignore", invalid="ignore"):  # inf or nan: not equal, kept
                same = (dt0 > 0) & (dt1 > 0) & ((v[1:-1] - v[:-2]) * dt1 == (v[2:] - v[1:-1]) * dt0)
            keep[1:-1] = ~same
        return [float(x) for x in t[keep]]

    def jumps(self, t0=-np.inf, t1=np.inf):
        if not self.linear:  # a step at every time
            return self.breakpoints(t0, t1)
        # linear interpolation is continuous except at a repeated time with another value
        t, v = np.asarray(self.times, dtype=float), np.asarray(self.values, dtype=float)
        at = (t[1:] == t[:-1]) & (v[1:] != v[:-1])
        return sorted({float(x) for x in t[1:][at]})


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

    def breakpoints(self, t0=-np.inf, t1=np.inf):
        return [self.start]

    def value_range(self):
        return self.offset - abs(self.amplitude), self.offset + abs(self.amplitude)


@dataclass
class Sum(Waveform):
    parts: list

    def __call__(self, t):
        return sum(p(t) for p in self.parts)

    def sample(self, t):
        acc = np.zeros(np.asarray(t).reshape(-1).shape)  # parts added left to right, as sum()
        for p in self.parts:
            acc = acc + p.sample(t)
        return acc

    def breakpoints(self, t0=-np.inf, t1=np.inf):
        return sorted({b for p in self.parts for b in p.breakpoints(t0, t1)})

    def jumps(self, t0=-np.inf, t1=np.inf):
        return sorted({b for p in self.parts for b in p.jumps(t0, t1)})

    def value_range(self):
        ranges = [p.value_range() for p in self.parts]
        return sum(r[0] for r in ranges), sum(r[1] for r in ranges)


@dataclass
class Noise(Sum):
    """A ``noise`` waveform: a Sum of its mean and sines, all periodic in ``period``."""
    period: float = 600.0

    def value_range(self):
        """The lowest and highest values over one period, sampled at 20 points per cycle of
        its fastest sine, widened by 2 % of their spread (the sampled extremes miss the true
        ones by less than 1 - cos(pi/20) = 1.2 % of the amplitude)."""
        fastest = max((p.frequency for p in self.parts if isinstance(p, Sine)), default=0.0)
        n = int(min(2_000_000, max(100, 20 * fastest * self.period)))
        start = max((p.start for p in self.parts if isinstance(p, Sine)), default=0.0)
        v = self.sample(start + np.arange(n) * (self.period / n))
        margin = 0.02 * float(v.max() - v.min())
        return float(v.min()) - margin, float(v.max()) + margin


@dataclass
class Periodic(Waveform):
    """One cycle of a table repeated with ``period`` [s]: the value at t is the table's at
    t0 + (t - t0) mod period (t0 = the table's first time; the table spans at most a period)."""

    period: float
    table: Table

    def phase(self, t):
        t0 = float(self.table.times[0])
        return t0 + (t - t0) % self.period

    def value_range(self):
        return self.table.value_range()

    def __call__(self, t):
        return self.table(self.phase(t))

    def sample(self, t):
        t0 = float(self.table.times[0])
        # np.remainder has Python's float % rules (sign of the divisor, same rounding)
        return self.table.sample(t0 + np.remainder(np.asarray(t, dtype=float).reshape(-1) - t0, self.period))

    def breakpoints(self, t0=-np.inf, t1=np.inf):
        # the table's kinks in every cycle, and the cycle boundaries (the value may jump there)
        return self._every_cycle(np.append(self.table.breakpoints(), self.table.times[0]), t0, t1)

    def jumps(self, t0=-np.inf, t1=np.inf):
        tab = self.table
        if not tab.linear:
            return self.breakpoints(t0, t1)
        t, v = np.asarray(tab.times, dtype=float), np.asarray(tab.values, dtype=float)
        # the boundary is continuous when the cycle ends on its first value (held or reached
        # at t0 + period) and no time is repeated at either end; otherwise the value may jump
        # there (listed as the cycle's start and its table's end: to rounding, one time)
        smooth = t.size == 1 or (v[-1] == v[0] and t[1] != t[0] and t[-1] != t[-2])
        return self._every_cycle(np.asarray(tab.jumps() + ([] if smooth else [t[0], t[-1]]), dtype=float), t0, t1)

    def _every_cycle(self, times, t0, t1):
        """``times`` (of one cycle) repeated in every cycle: those in [t0, t1]."""
        if not (np.isfinite(t0) and np.isfinite(t1)):
            raise ValueError("a periodic waveform's breakpoints need a finite time range")
        if not len(times):
            return []
        first = float(self.table.times[0])
        k0 = int(np.floor((t0 - first) / self.period))
        k1 = int(np.ceil((t1 - first) / self.period))
        offs = np.unique(np.asarray(times, dtype=float) - first)
        pts = (first + self.period * np.arange(k0, k1 + 1)[:, None] + offs[None, :]).ravel()
        return [float(b) for b in np.unique(pts) if t0 <= b <= t1]


def _table_rows(spec, base_dir, unit, where):
    if isinstance(spec, dict) and "file" in spec:
        if not isinstance(spec["file"], str) or not spec["file"] or len(spec) != 1:
            raise NetlistError(f"a table file is given as {{file: NAME.csv}}, got {excerpt(spec)}", **where)
        # netlists and protocols resolve and check the path against their allowed folders
        # (hemocircuit.access) before it gets here; relative paths left are the API's own
        path = spec["file"] if os.path.isabs(spec["file"]) else os.path.join(base_dir or ".", spec["file"])
        from .inputs import read_csv_rows
        rows = read_csv_rows(path, "table file", where=where)  # regular file, size, UTF-8 (hemocircuit.inputs)
        if len(rows) < 2:
            raise NetlistError(f"table file {path}: needs a header 'time [s],value [UNIT]' and at least one row",
                               **where)
        if len(rows) > limits.limit("TABLE_ROWS") + 1:
            raise NetlistError(f"table file {path}: {len(rows) - 1:,} rows {limits.how_to_raise('TABLE_ROWS')}",
                               **where)
        header, rows = rows[0], rows[1:]
        units = []
        for h in header[:2]:
            m = re.search(r"\[(.{1,40})\]", h)
            if not m:
                raise NetlistError(f"table file {path}: the header (line 1, {excerpt(','.join(header), 40)}) must "
                                   "give each column's unit in brackets: 'time [s],value [UNIT]'", **where)
            units.append(m.group(1))
        if len(units) < 2:
            raise NetlistError(f"table file {path}: the header needs two columns 'time [s],value [UNIT]'", **where)
        out = []
        for i, r in enumerate(rows):
            try:
                if len(r) < 2:
                    raise UnitError("expected two columns time,value")
                out.append((parse_quantity(f"{r[0][:60]} {units[0]}", "s", "time"),
                            parse_quantity(f"{r[1][:60]} {units[1]}", unit, "value")))
            except UnitError as exc:
                raise NetlistError(f"table file {path}, data row {i + 1}: {str(exc)[:200]}", **where) from None
        return out
    if not isinstance(spec, list) or not spec:
        raise NetlistError("a table needs a non-empty list of [time, value] pairs or {file: ...}", **where)
    if len(spec) > limits.limit("TABLE_ROWS"):
        raise NetlistError(f"a table of {len(spec):,} rows {limits.how_to_raise('TABLE_ROWS')}", **where)
    out = []
    for i, row in enumerate(spec):
        if not isinstance(row, (list, tuple)) or len(row) != 2:
            raise NetlistError(f"table row {i + 1} {excerpt(row)} is not a [time, value] pair", **where)
        out.append((parse_quantity(row[0], "s", f"table row {i + 1} time"),
                    parse_quantity(row[1], unit, f"table row {i + 1} value")))
    return out


_SINE_FIELDS = ("offset", "amplitude", "frequency", "phase", "start")
_NOISE_FIELDS = ("mean", "sd", "band", "period", "seed", "start")
_KINDS = ("steps", "pwc", "pwl", "sine", "sum", "periodic", "noise")
#: most sines a noise waveform may sum (band x period): each costs a sine per evaluation
MAX_NOISE_LINES = 20_000


def parse_waveform(spec, unit: str, base_dir=None, where=None) -> Waveform:
    """Build a Waveform from a netlist value (constant or mapping)."""
    where = where or {}
    try:
        if not isinstance(spec, dict):
            return Constant(parse_quantity(spec, unit, "value"))
        if len(spec) != 1:
            raise NetlistError("a waveform has exactly one kind (steps, pwl, pwc, sine, sum, periodic, noise); got "
                               f"{excerpt(sorted(map(str, spec)))}", **where)
        (kind, body), = spec.items()
        if kind == "periodic":
            return _periodic(body, unit, base_dir, where)
        if kind in ("steps", "pwc", "pwl"):
            # stable sort on time only: rows with equal times keep their order (a jump)
            rows = sorted(_table_rows(body, base_dir, unit, where), key=lambda r: r[0])
            t = np.array([r[0] for r in rows])
            v = np.array([r[1] for r in rows])
            for what, arr, u in (("time", t, "s"), ("value", v, unit)):
                bad = np.flatnonzero(~np.isfinite(arr))
                if bad.size:
                    raise NetlistError(f"{kind} table: every {what} must be finite; got {arr[bad[0]]} {u}", **where)
            return Table(t, v, linear=(kind == "pwl"))
        if kind == "sine":
            if not isinstance(body, dict):
                raise NetlistError("sine needs a mapping {offset, amplitude, frequency, phase, start}", **where)
            unknown = set(body) - set(_SINE_FIELDS)
            if unknown:
                raise NetlistError(f"unknown sine field(s) {excerpt(sorted(map(str, unknown)))}"
                                   f"{did_you_mean(sorted(map(str, unknown))[0], _SINE_FIELDS)}", **where)
            fields = {}
            for fname, funit in (("offset", unit), ("amplitude", unit), ("frequency", "Hz"), ("phase", "rad"),
                                 ("start", "s")):
                v = parse_quantity(body.get(fname, f"0 {funit}"), funit, f"sine {fname}")
                if not np.isfinite(v):
                    raise NetlistError(f"sine {fname} = {v} {funit}: must be finite", **where)
                fields[fname] = v
            if fields["frequency"] < 0:
                raise NetlistError(f"sine frequency = {fields['frequency']:g} Hz: must be >= 0", **where)
            return Sine(**fields)
        if kind == "noise":
            return _noise(body, unit, where)
        if kind == "sum":
            if not isinstance(body, list) or not body:
                raise NetlistError("sum needs a non-empty list of waveforms", **where)
            return Sum([parse_waveform(b, unit, base_dir, where) for b in body])
        raise NetlistError(f"unknown waveform kind {excerpt(kind, 40)}{did_you_mean(kind, _KINDS)} "
                           "(use steps, pwl, pwc, sine, sum, periodic or noise)", **where)
    except UnitError as exc:
        raise NetlistError(str(exc), **where) from None
    except (TypeError, ValueError) as exc:  # unhashable or odd YAML values in a waveform mapping
        raise NetlistError(f"malformed waveform {excerpt(spec)}: {type(exc).__name__}", **where) from None


def _noise(body, unit, where):
    """{noise: {mean, sd, band: [lo, hi], period, seed, start}} as a Sum of a Constant and sines."""
    if not isinstance(body, dict) or "sd" not in body or "band" not in body:
        raise NetlistError("noise needs a mapping {sd: <value>, band: [<low> Hz, <high> Hz]} (and optionally mean, "
                           f"period, seed, start); got {excerpt(body)}", **where)
    unknown = set(body) - set(_NOISE_FIELDS)
    if unknown:
        raise NetlistError(f"unknown noise field(s) {excerpt(sorted(map(str, unknown)))}"
                           f"{did_you_mean(sorted(map(str, unknown))[0], _NOISE_FIELDS)}", **where)
    mean = parse_quantity(body.get("mean", f"0 {unit}"), unit, "noise mean")
    sd = parse_quantity(body["sd"], unit, "noise sd")
    period = parse_quantity(body.get("period", "600 s"), "s", "noise period")
    start = parse_quantity(body.get("start", "0 s"), "s", "noise start")
    band = body["band"]
    if not isinstance(band, (list, tuple)) or len(band) != 2:
        raise NetlistError(f"noise band must be [<low> Hz, <high> Hz]; got {excerpt(band)}", **where)
    lo, hi = (parse_quantity(b, "Hz", "noise band") for b in band)
    seed = body.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise NetlistError(f"noise seed must be a whole number >= 0; got {excerpt(seed)}", **where)
    for name, v in (("mean", mean), ("sd", sd), ("period", period), ("start", start), ("band", lo), ("band", hi)):
        if not np.isfinite(v):
            raise NetlistError(f"noise {name} = {v}: must be finite", **where)
    if sd < 0 or period <= 0 or not 0 <= lo < hi:
        raise NetlistError(f"noise needs sd >= 0, period > 0 and 0 <= low < high (got sd {sd:g} {unit}, period "
                           f"{period:g} s, band [{lo:g}, {hi:g}] Hz)", **where)
    k = np.arange(max(1, int(np.ceil(lo * period - 1e-9))), int(np.floor(hi * period + 1e-9)) + 1)
    if k.size == 0:
        raise NetlistError(f"noise band [{lo:g}, {hi:g}] Hz holds no frequency k/period (period {period:g} s): "
                           "widen the band or lengthen the period", **where)
    if k.size > MAX_NOISE_LINES:
        raise NetlistError(f"noise band x period gives {k.size:,} sines (more than {MAX_NOISE_LINES:,}): narrow the "
                           "band or shorten the period", **where)
    rng = np.random.default_rng(seed)
    c = rng.standard_normal(k.size) + 1j * rng.standard_normal(k.size)  # a Gaussian process's Fourier lines
    amp = np.abs(c) * sd / np.sqrt(np.sum(np.abs(c) ** 2) / 2.0)  # sd over one period: sqrt(sum a^2 / 2)
    return Noise([Constant(mean)] + [Sine(0.0, float(a), float(f), float(ph), start)
                                     for a, f, ph in zip(amp, k / period, np.angle(c))], period)


def _periodic(body, unit, base_dir, where):
    """{periodic: {period: T, pwl|steps|pwc: table}}: the table spans at most one period."""
    if not isinstance(body, dict) or "period" not in body or len(body) != 2:
        raise NetlistError("periodic needs a mapping {period: <time>, pwl|steps|pwc: <table>}; got "
                           f"{excerpt(body)}", **where)
    period = parse_quantity(body["period"], "s", "periodic period")
    if not (np.isfinite(period) and period > 0):
        raise NetlistError(f"periodic period = {period:g} s: must be > 0 and finite", **where)
    (kind, table), = ((k, v) for k, v in body.items() if k != "period")
    if kind not in ("pwl", "steps", "pwc"):
        raise NetlistError(f"periodic repeats a table (pwl, steps or pwc), got {excerpt(kind, 40)}", **where)
    tab = parse_waveform({kind: table}, unit, base_dir, where)
    span = float(tab.times[-1] - tab.times[0])
    if span > period * (1 + 1e-12):
        raise NetlistError(f"periodic table spans {span:g} s, more than its period {period:g} s", **where)
    return Periodic(period, tab)
