"""Two time series for a dynamic-autoregulation measure (input: arterial pressure; output:
cerebral blood flow or its velocity), from a result file or a user's own recording, brought to
one uniform grid as the CARNet white paper asks (Claassen et al. 2016, J Cereb Blood Flow
Metab 36:665; 2nd ed. Panerai et al. 2023): beat-to-beat means of pulsatile signals, then
interpolation onto a uniform grid (10 Hz by default).

Only what no library does is written here: the file is read by :meth:`Result.load` (every
result format, and plain CSV with a ``name [unit]`` or ``name`` header, under the input
policy), the beats are found by :func:`scipy.signal.find_peaks`, the interpolation is
:func:`numpy.interp`.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import HemocircuitError, did_you_mean

#: resampling rate of beat-to-beat or irregular series [Hz] (the CARNet sample data's rate)
DEFAULT_FS = 10.0
#: shortest heart period a beat detection accepts [s] (240 /min)
MIN_BEAT = 0.25


@dataclass
class Series:
    """Input and output on one uniform grid ``t`` [s] (sampling rate ``fs`` [Hz])."""
    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    fs: float
    names: tuple = ("input", "output")
    units: tuple = ("", "")
    notes: list = field(default_factory=list)  # what was done to the data (resampled, beats averaged)


def read_series(path, input, output, time=None):
    """(t, x, y, names, units) of columns ``input`` and ``output`` of a result file or a
    recording (CSV with a header row; .json/.npz/.parquet results).  ``time``: the time column
    [s] (default: the result's index, else a column named ``time`` or ``t``)."""
    from ..results import Result
    res = Result.load(path)
    names = list(res.keys())
    if len(names) == 1 and any(sep in names[0] for sep in ";\t"):
        raise HemocircuitError(f"{path}: the header is one column {names[0]!r}; separate the columns with commas "
                               "(a CSV file), not semicolons or tabs")
    if time is None:
        time = next((n for n in list(res.index) + ["time", "t", "Time", "TIME"] if n in res.data), None)
        if time is None:
            raise HemocircuitError(f"{path}: no time column (none is named 'time' or 't'); name it with --time "
                                   f"(columns: {names[:20]})")
    cols = {}
    for flag, name in (("--time", time), ("--input", input), ("--output", output)):
        if name not in res.data:
            raise HemocircuitError(f"{flag} {name!r}: {path} has no such column{did_you_mean(name, names)} "
                                   f"(columns: {names[:20]}{' ...' if len(names) > 20 else ''})")
        v = np.asarray(res[name])
        if v.dtype.kind not in "iuf":
            raise HemocircuitError(f"{flag} {name!r}: column of {path} is not numeric")
        v = v.astype(float)
        bad = np.flatnonzero(~np.isfinite(v))
        if bad.size:
            raise HemocircuitError(f"{flag} {name!r}: {bad.size} value(s) of {path} are not finite (first at data "
                                   f"row {bad[0] + 1}); replace artefacts before the analysis")
        cols[flag] = v
    t = cols["--time"]
    unit = {n: "" if res.units.get(n) in (None, "1") else res.units[n] for n in (time, input, output)}
    if unit[time] not in ("", "s"):  # a recording without units is taken to be in seconds
        from ..units import parse_quantity
        t = t * float(parse_quantity(f"1 {unit[time]}", "s"))
    steps = np.diff(t)
    if t.size < 2 or np.any(steps <= 0):
        row = int(np.flatnonzero(steps <= 0)[0]) + 2 if t.size >= 2 else 1
        raise HemocircuitError(f"--time {time!r}: the times of {path} must increase strictly (data row {row})")
    return t, cols["--input"], cols["--output"], (input, output), (unit[input], unit[output])


def uniform_series(t, x, y, fs=None, beats=False, names=("input", "output"), units=("", "")) -> Series:
    """The two series on a uniform grid.  ``beats``: average each heart beat first (beats found
    on ``x``, the arterial pressure: its systolic upstrokes); the beat means are placed at each
    beat's mid-time.  A uniform series is used at its own rate unless ``fs`` is given; beat
    means and irregular series are interpolated linearly at ``fs`` (default 10 Hz)."""
    t, x, y = (np.asarray(a, dtype=float) for a in (t, x, y))
    notes = []
    if beats:
        t, x, y = beat_means(t, x, y)
        notes.append(f"beat-to-beat means of {t.size} beats (mean heart period {np.mean(np.diff(t)):.3g} s)")
    dt = np.diff(t)
    regular = not beats and np.allclose(dt, dt[0], rtol=1e-6, atol=0.0)
    if regular and (fs is None or abs(fs * dt[0] - 1) < 1e-9):
        return Series(t, x, y, 1.0 / dt[0], tuple(names), tuple(units), notes)
    fs = DEFAULT_FS if fs is None else float(fs)
    if not fs > 0:
        raise HemocircuitError(f"--fs {fs}: the resampling rate must be positive (e.g. 10 Hz)")
    grid = t[0] + np.arange(int(np.floor((t[-1] - t[0]) * fs)) + 1) / fs
    notes.append(f"interpolated linearly at {fs:g} Hz")
    return Series(grid, np.interp(grid, t, x), np.interp(grid, t, y), fs, tuple(names), tuple(units), notes)


def beat_means(t, x, y):
    """(mid-times, mean x, mean y) of each heart beat, a beat running from one diastolic foot of
    ``x`` to the next; means are time averages (trapezoidal) over the beat.  Beats are found by
    their systolic upstrokes (the steepest rises: sharper than the minimum, which a slow run-off
    or a flat diastole leaves ill-defined); each beat starts at the lowest pressure in the quarter
    beat before its upstroke, where the pressure barely changes, so that cutting at a sample
    rather than at the true foot moves the mean least (cutting at the upstroke leaves a ripple of
    a few % in the beat means)."""
    from scipy.integrate import trapezoid
    from scipy.signal import find_peaks

    dt = np.median(np.diff(t))
    slope = np.gradient(x, t)
    spread = np.percentile(slope, 99) - np.percentile(slope, 1)
    if not spread > 0:
        raise HemocircuitError("beat averaging: the pressure does not pulsate (constant input); "
                               "leave out --beat-average")
    ups, _ = find_peaks(slope, distance=max(1, int(MIN_BEAT / dt)), prominence=0.3 * spread)
    if ups.size < 3:
        raise HemocircuitError(f"beat averaging: found {max(ups.size - 1, 0)} beat(s) in the input; a pulsatile "
                               "pressure sampled at >= 20 Hz is needed (or leave out --beat-average)")
    back = max(1, int(0.25 * np.median(np.diff(ups))))
    feet = [max(0, u - back) + int(np.argmin(x[max(0, u - back):u + 1])) for u in ups]
    mids, xm, ym = [], [], []
    for a, b in zip(feet[:-1], feet[1:]):
        span = t[b] - t[a]
        mids.append(0.5 * (t[a] + t[b]))
        xm.append(trapezoid(x[a:b + 1], t[a:b + 1]) / span)
        ym.append(trapezoid(y[a:b + 1], t[a:b + 1]) / span)
    return np.array(mids), np.array(xm), np.array(ym)
