"""Waveforms (hemocircuit.waveforms) as flat float64 records, evaluated by compiled code.

Every record starts with a two-number header ``[kind, length]`` (``length`` = the whole record,
header included, so a reader can skip it); integers are stored as exact float64 values:

``[0, 3, value]``                                   Constant
``[1, 3 + 2n, n, t_0 .. t_{n-1}, v_0 .. v_{n-1}]``  Table, linear (np.interp; held outside)
``[2, 3 + 2n, n, t_0 .. t_{n-1}, v_0 .. v_{n-1}]``  Table, steps (searchsorted right)
``[3, 7, offset, amplitude, frequency, phase, start]``  Sine (frequency Hz, phase rad, start s)
``[4, 3 + sum of the parts' lengths, m, part_1 .. part_m]``  Sum of m nested records
``[5, 4 + table length, period, t_0, table record]``  Periodic: the table (kind 1 or 2) at
                                                    t_0 + (t - t_0) mod period

``encode(wf)`` builds the record of one waveform; ``concat(records)`` joins several into one
array and returns their start offsets; ``wave_value(data, start, t)`` evaluates the record that
begins at ``data[start]`` and agrees with ``Waveform.__call__`` operation for operation (same
summation order for nested sums, np.interp's end, duplicate-time and NaN rules).
"""
from __future__ import annotations

import math

import numba
import numpy as np

from ..waveforms import Constant, Periodic, Sine, Sum, Table, Waveform

CONSTANT, LINEAR, STEPS, SINE, SUM, PERIODIC = 0, 1, 2, 3, 4, 5
#: deepest nesting of Sum records ``wave_value`` evaluates (checked by ``encode``)
MAX_SUM_DEPTH = 16

_jit = numba.njit(cache=True, nogil=True, error_model="numpy")


def encode(wf: Waveform) -> np.ndarray:
    """The float64 record of ``wf`` (see the module docstring)."""
    out: list[float] = []
    _encode(wf, out, 0)
    return np.asarray(out, dtype=np.float64)


def _encode(wf, out, depth):
    if isinstance(wf, Constant):
        out += [CONSTANT, 3, float(wf.value)]
    elif isinstance(wf, Table):
        t = np.asarray(wf.times, dtype=np.float64).reshape(-1)
        v = np.asarray(wf.values, dtype=np.float64).reshape(-1)
        if t.size == 0 or t.size != v.size:
            raise ValueError(f"table waveform needs equally many (>= 1) times and values, got {t.size} and {v.size}")
        n = t.size
        out += [LINEAR if wf.linear else STEPS, 3 + 2 * n, n]
        out += t.tolist() + v.tolist()
    elif isinstance(wf, Sine):
        out += [SINE, 7, float(wf.offset), float(wf.amplitude), float(wf.frequency), float(wf.phase),
                float(wf.start)]
    elif isinstance(wf, Sum):
        if depth + 1 > MAX_SUM_DEPTH:
            raise ValueError(f"waveform sums nested deeper than {MAX_SUM_DEPTH} levels")
        head = len(out)
        out += [SUM, 0, len(wf.parts)]
        for part in wf.parts:
            _encode(part, out, depth + 1)
        out[head + 1] = len(out) - head
    elif isinstance(wf, Periodic):
        head = len(out)
        out += [PERIODIC, 0, float(wf.period), float(wf.table.times[0])]
        _encode(wf.table, out, depth)
        out[head + 1] = len(out) - head
    else:
        raise TypeError(f"no compiled form for waveform {type(wf).__name__}")


def concat(records) -> tuple[np.ndarray, np.ndarray]:
    """(data, starts): the records joined into one float64 array and the offset of each."""
    records = [np.asarray(r, dtype=np.float64) for r in records]
    starts = np.cumsum([0] + [r.size for r in records[:-1]]).astype(np.int64) if records else np.zeros(0, np.int64)
    data = np.concatenate(records) if records else np.zeros(0)
    return data, starts


@_jit
def _last_at_or_before(data, ts, n, t):
    """Largest j with times[j] <= t (-1 if none), times = data[ts:ts+n] sorted."""
    lo, hi = 0, n
    while lo < hi:
        mid = lo + ((hi - lo) >> 1)
        if t >= data[ts + mid]:
            lo = mid + 1
        else:
            hi = mid
    return lo - 1


@_jit
def _interp(data, ts, n, t):
    """np.interp(t, data[ts:ts+n], data[ts+n:ts+2n]) with the default left/right values."""
    vs = ts + n
    if n == 1:
        return data[vs]
    if t != t:
        return t
    if t > data[ts + n - 1]:
        return data[vs + n - 1]
    if t < data[ts]:
        return data[vs]
    j = _last_at_or_before(data, ts, n, t)  # numpy's binary_search_with_guess
    if j == n - 1:
        return data[vs + j]
    xj = data[ts + j]
    if xj == t:
        return data[vs + j]
    yj, yj1, xj1 = data[vs + j], data[vs + j + 1], data[ts + j + 1]
    slope = (yj1 - yj) / (xj1 - xj)
    r = slope * (t - xj) + yj
    if r != r:
        r = slope * (t - xj1) + yj1
        if r != r and yj == yj1:
            r = yj
    return r


@_jit
def _steps(data, ts, n, t):
    """values[max(searchsorted(times, t, 'right') - 1, 0)]."""
    if t != t:  # NaN sorts after everything
        return data[ts + n + n - 1]
    i = _last_at_or_before(data, ts, n, t)
    if i < 0:
        i = 0
    return data[ts + n + i]


@_jit
def _leaf(data, pos, t):
    kind = int(data[pos])
    if kind == PERIODIC:  # Periodic.phase, then its table
        t0 = data[pos + 3]
        t = t0 + (t - t0) % data[pos + 2]
        pos += 4
        kind = int(data[pos])
    if kind == CONSTANT:
        return data[pos + 2]
    if kind == LINEAR:
        return _interp(data, pos + 3, int(data[pos + 2]), t)
    if kind == STEPS:
        return _steps(data, pos + 3, int(data[pos + 2]), t)
    if kind == SINE:
        offset, start = data[pos + 2], data[pos + 6]
        if t < start:
            return offset
        return offset + data[pos + 3] * math.sin(2 * np.pi * data[pos + 4] * (t - start) + data[pos + 5])
    return math.nan


@_jit
def wave_value(data, start, t):
    """Value at time ``t`` [s] of the record beginning at ``data[start]``."""
    return wave_value_with(data, start, t, np.empty(MAX_SUM_DEPTH), np.empty(MAX_SUM_DEPTH, dtype=np.int64))


@_jit
def wave_value_with(data, start, t, acc_stack, end_stack):
    """wave_value with caller-owned scratch (MAX_SUM_DEPTH,) float and int64 arrays: the engine
    runs without numba's runtime (no allocation, no reference counting) in its hot loop."""
    if int(data[start]) != SUM:
        return _leaf(data, start, t)
    # nested sums without recursion: a stack of (partial sum, end) of the enclosing sums, so
    # every sum adds its parts left to right and then joins its parent, as Python's sum() does
    depth = 0
    acc = 0.0
    end = start + int(data[start + 1])
    pos = start + 3
    while True:
        while pos >= end:
            if depth == 0:
                return acc
            depth -= 1
            acc = acc_stack[depth] + acc
            end = end_stack[depth]
        kind = int(data[pos])
        if kind == SUM:
            acc_stack[depth] = acc
            end_stack[depth] = end
            depth += 1
            acc = 0.0
            end = pos + int(data[pos + 1])
            pos += 3
        else:
            acc = acc + _leaf(data, pos, t)
            pos += int(data[pos + 1])
