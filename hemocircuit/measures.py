"""Measures: scalar findings computed from a result, like SPICE ``.measure``.

A measure is one line ``KIND COLUMN [ARGS] [key=value ...]`` (docs/analyses.md, "Measures"):

=================================  ==========================================================
``plateau Q(Rla) 10% ref=100mmHg``  (dc) the autoregulation plateau: the range of the swept
                                    parameter around ``ref`` over which the column stays within
                                    +/-10 % of its value at ``ref``; ``low``, ``high``, ``width``
``gain P(a) at=0.1Hz``              (ac, freq) gain and relative gain of the column at a
                                    frequency (interpolated in log f)
``phase P(a) at=0.1Hz``             (ac, freq) phase [deg] at a frequency
``resonance P(a)``                  (ac, freq) the frequency of the peak of the gain |H|
                                    and the peak (parabola through the top three points in
                                    log f, log gain)
``settle Q(Rla) tol=2% after=100s`` (tran) settling time after an event at ``after``: the time
                                    until the column stays within +/-tol of its final value
``min``/``max``/``mean COL``        over a window ``from=T1 to=T2`` of the independent variable
``average COL``                     time (x) average over the window: integral / length
                                    (trapezoid rule), not the mean of the samples
``period COL``                      (tran, periodic) mean spacing of the upward crossings of
                                    the column's mean in the window; a periodic orbit's own
                                    period (its table covers exactly one)
=================================  ==========================================================

Values in ``key=value`` take units (``ref=100mmHg``, ``at=0.1Hz``, ``from=10s``); a bare number
is in the unit of the independent variable.  A result with grid members (or several netlists,
compare) is measured member by member.  :func:`measure_all` stores every value in
``result.metadata['measures'][SPEC]`` (so it is written to the file's header) and returns the
printed lines.
"""
from __future__ import annotations

import re

import numpy as np

from .errors import HemocircuitError

KINDS = ("plateau", "gain", "phase", "resonance", "settle", "min", "max", "mean", "average", "period")
_FREQ_KINDS = ("gain", "phase", "resonance")


class MeasureError(HemocircuitError):
    pass


def parse(spec):
    """'plateau Q(Rla) 10% ref=100mmHg' -> (kind, column, [positional args], {key: text})."""
    words = str(spec).split()
    if len(words) < 2:
        raise MeasureError(f"--measure {spec!r}: expected KIND COLUMN [ARGS] [key=value ...] (kinds: {', '.join(KINDS)})")
    kind, column = words[0].lower(), words[1]
    if kind not in KINDS:
        import difflib
        near = difflib.get_close_matches(kind, KINDS, n=2)
        raise MeasureError(f"--measure {spec!r}: unknown kind {kind!r}" +
                           (f"; did you mean {' or '.join(near)}?" if near else f"; kinds: {', '.join(KINDS)}"))
    pos, kw = [], {}
    for w in words[2:]:
        if "=" in w:
            k, v = w.split("=", 1)
            kw[k.lower()] = v
        else:
            pos.append(w)
    return kind, column, pos, kw


def _value(text, unit, what, spec):
    """'100mmHg' / '100 mmHg' / '100' (in ``unit``) -> float in ``unit``."""
    from .units import UnitError, parse_quantity
    m = re.match(r"^([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(.*)$", text.strip())
    if not m:
        raise MeasureError(f"--measure {spec!r}: {what}={text!r} is not a number (with an optional unit)")
    if not m.group(2) or unit in ("", "1"):
        return float(m.group(1))
    try:
        return float(parse_quantity(f"{m.group(1)} {m.group(2)}", unit, what))
    except UnitError as exc:
        raise MeasureError(f"--measure {spec!r}: {exc}") from None


def _fraction(text, spec, what="tolerance"):
    t = text.strip()
    try:
        return float(t[:-1]) / 100 if t.endswith("%") else float(t)
    except ValueError:
        raise MeasureError(f"--measure {spec!r}: {what} {text!r} should read like 10% or 0.1") from None


def _axes(res):
    """(x column, group columns): the independent variable and what tells members apart."""
    if not res.index:
        raise MeasureError(f"a {res.analysis or 'point'} result has no independent variable to measure along")
    x = res.index[0] if res.analysis == "envelope" else res.index[-1]
    return x, [k for k in res.index if k != x]


def _groups(res, group_cols):
    if not group_cols:
        return [({}, np.ones(res.n_rows, bool))]
    keys = list(dict.fromkeys(zip(*(res[g].tolist() for g in group_cols))))
    out = []
    for key in keys:
        mask = np.all([np.array([v == k for v in res[g].tolist()]) for g, k in zip(group_cols, key)], axis=0)
        out.append((dict(zip(group_cols, key)), mask))
    return out


def _column(res, kind, column, spec):
    """The result column a measure reads (for ac/freq: the gain/phase columns of an output)."""
    if kind in _FREQ_KINDS:
        prefix = "phase(" if kind == "phase" else "rel_gain("
        cands = [k for k in res.keys() if k.startswith(prefix) and
                 (k[len(prefix):-1] == column or k[len(prefix):-1].split("/")[0] == column)]
        if not cands:
            outs = sorted({k[len(prefix):-1].split("/")[0] for k in res.keys() if k.startswith(prefix)})
            if not outs:
                raise MeasureError(f"--measure {spec!r}: needs an ac or freq result (gain and phase columns); "
                                   f"this is a {res.analysis or 'result'}")
            import difflib
            near = difflib.get_close_matches(column, outs, n=3)
            raise MeasureError(f"--measure {spec!r}: no output {column!r}" +
                               (f"; did you mean {', '.join(near)}?" if near else f"; outputs: {', '.join(outs)}"))
        return cands[0][len(prefix):-1]  # 'o/p'
    from .results import Result
    try:
        Result.check_columns(res, [column], "column")
    except HemocircuitError as exc:
        raise MeasureError(f"--measure {spec!r}: {exc}") from None
    return column


def measure(res, spec):
    """One measure of ``res`` -> a list of (member {group column: value}, {name [unit]: value})."""
    kind, column, pos, kw = parse(spec)
    x_name, group_cols = _axes(res)
    col = _column(res, kind, column, spec)
    xu = res.units.get(x_name, "")
    out = []
    for member, mask in _groups(res, group_cols):
        x = np.asarray(res[x_name][mask], dtype=float)
        order = np.argsort(x, kind="stable")
        x = x[order]
        if kind in _FREQ_KINDS:
            vals = _freq_measure(res, kind, col, x, mask, order, kw, spec)
        else:
            y = np.asarray(res[col][mask], dtype=float)[order]
            yu = res.units.get(col, "")
            vals = _series_measure(res, kind, col, x, y, x_name, xu, yu, pos, kw, spec)
        out.append((member, vals))
    return out


def _window(x, y, kw, xu, spec):
    lo = _value(kw["from"], xu, "from", spec) if "from" in kw else -np.inf
    hi = _value(kw["to"], xu, "to", spec) if "to" in kw else np.inf
    sel = (x >= lo) & (x <= hi) & np.isfinite(y)
    if sel.sum() < 1:
        raise MeasureError(f"--measure {spec!r}: no data in the window [{lo:g}, {hi:g}] {xu}")
    return x[sel], y[sel]


def _series_measure(res, kind, col, x, y, x_name, xu, yu, pos, kw, spec):
    if kind in ("min", "max", "mean", "average"):
        xw, yw = _window(x, y, kw, xu, spec)
        if kind == "min":
            k = int(np.argmin(yw))
            return {f"min [{yu}]": float(yw[k]), f"at [{xu}]": float(xw[k])}
        if kind == "max":
            k = int(np.argmax(yw))
            return {f"max [{yu}]": float(yw[k]), f"at [{xu}]": float(xw[k])}
        if kind == "mean":
            return {f"mean [{yu}]": float(np.mean(yw)), "samples [1]": int(len(yw))}
        if len(xw) < 2 or xw[-1] == xw[0]:
            raise MeasureError(f"--measure {spec!r}: the window holds fewer than two distinct {x_name} values")
        return {f"average [{yu}]": float(np.trapezoid(yw, xw) / (xw[-1] - xw[0])),
                f"over [{xu}]": float(xw[-1] - xw[0])}
    if kind == "period":
        if res.analysis == "periodic":
            return {f"period [{xu}]": float(x[-1] - x[0])}
        xw, yw = _window(x, y, kw, xu, spec)
        swing, level = float(np.ptp(yw)), float(np.max(np.abs(yw)))
        if swing <= 1e-9 * level:  # crossings of the mean by round-off are no oscillation
            raise MeasureError(f"--measure {spec!r}: {col} varies by {swing:.3g} around {float(np.mean(yw)):.6g} in "
                               "the window, round-off: no oscillation to time")
        T, n = period_of(xw, yw)
        if not np.isfinite(T):
            raise MeasureError(f"--measure {spec!r}: {col} does not cross its mean upwards twice in the window "
                               "(no oscillation to time)")
        return {f"period [{xu}]": T, "cycles [1]": n}
    if kind == "plateau":
        tol = _fraction(pos[0] if pos else kw.get("tol", "10%"), spec)
        if "ref" not in kw:
            raise MeasureError(f"--measure {spec!r}: give the reference, e.g. ref=100mmHg")
        ref = _value(kw["ref"], xu, "ref", spec)
        low, high, y_ref = plateau(x, y, ref, tol)
        return {f"low [{xu}]": low, f"high [{xu}]": high, f"width [{xu}]": high - low,
                f"{col} at ref [{yu}]": y_ref, "tolerance [1]": tol}
    if kind == "settle":
        tol = _fraction(kw.get("tol", pos[0] if pos else "2%"), spec)
        after = _value(kw["after"], xu, "after", spec) if "after" in kw else float(x[0])
        t_s, final = settling_time(x, y, after, tol)
        return {f"settling_time [{xu}]": t_s, f"final [{yu}]": final, "tolerance [1]": tol}
    raise MeasureError(f"--measure {spec!r}: {kind} needs an ac or freq result")


def _freq_measure(res, kind, col, f, mask, order, kw, spec):
    rel = np.asarray(res[f"rel_gain({col})"][mask], dtype=float)[order]
    gain = np.asarray(res[f"gain({col})"][mask], dtype=float)[order]
    phase = np.asarray(res[f"phase({col})"][mask], dtype=float)[order]
    gu = res.units.get(f"gain({col})", "")
    ok = np.isfinite(gain) & (f > 0)
    f, rel, gain, phase = f[ok], rel[ok], gain[ok], phase[ok]
    if len(f) < 2:
        raise MeasureError(f"--measure {spec!r}: fewer than two frequencies with a value")
    if kind == "resonance":
        # the peak of |H| (the relative gain is |H| times the constant p0/y0, undefined when y0 = 0)
        fr, peak, k = resonance(f, gain)
        ratio = rel / gain
        ratio = ratio[np.isfinite(ratio)]
        return {"frequency [Hz]": fr, f"peak_gain [{gu}]": peak,
                "peak_rel_gain [1]": float(peak * ratio[0]) if ratio.size else float("nan"),
                "at_edge": bool(k in (0, len(f) - 1))}
    if "at" not in kw:
        raise MeasureError(f"--measure {spec!r}: give the frequency, e.g. at=0.1Hz")
    fa = _value(kw["at"], "Hz", "at", spec)
    if not f[0] <= fa <= f[-1]:
        raise MeasureError(f"--measure {spec!r}: {fa:g} Hz is outside the result's frequencies "
                           f"{f[0]:g}..{f[-1]:g} Hz")
    lf = np.log(f)
    if kind == "phase":
        return {"phase [deg]": float(np.interp(np.log(fa), lf, np.unwrap(phase, period=360)))}
    return {f"gain [{gu}]": float(np.exp(np.interp(np.log(fa), lf, np.log(gain)))),
            "rel_gain [1]": float(np.exp(np.interp(np.log(fa), lf, np.log(np.abs(rel))))),
            "phase [deg]": float(np.interp(np.log(fa), lf, np.unwrap(phase, period=360)))}


# ------------------------------------------------------------------ the computations ------
def plateau(x, y, ref, tol):
    """(low, high, y(ref)): the interval of x around ``ref`` (inside the sampled range) on which
    |y/y(ref) - 1| <= tol, its ends interpolated linearly between samples; an end that
    reaches the sampled range is that range's end."""
    y_ref = float(np.interp(ref, x, y))
    if not x[0] <= ref <= x[-1]:
        raise MeasureError(f"plateau: the reference {ref:g} is outside the swept range {x[0]:g}..{x[-1]:g}")
    if y_ref == 0:
        raise MeasureError("plateau: the value at the reference is zero (a relative band is undefined)")
    dev = np.abs(y / y_ref - 1.0) - tol  # <= 0 inside the band; -tol at the reference itself

    def edge(order):
        xp, dp = float(ref), -tol  # the last point known inside the band
        for i in order:
            if not np.isfinite(dev[i]) or dev[i] > 0:
                if not np.isfinite(dev[i]):
                    return xp
                # the band's edge, linearly between the last inside point and sample i
                return float(xp + (x[i] - xp) * (0 - dp) / (dev[i] - dp))
            xp, dp = float(x[i]), float(dev[i])
        return xp  # inside up to the end of the sweep

    above = [i for i in range(len(x)) if x[i] > ref]
    below = [i for i in range(len(x) - 1, -1, -1) if x[i] < ref]
    return edge(below), edge(above), y_ref


def resonance(f, g):
    """(frequency, peak, index of the largest sample) of the largest g: a parabola through the
    top three points in (log f, log g); the sample itself at an end of the range."""
    k = int(np.nanargmax(g))
    if k in (0, len(f) - 1):
        return float(f[k]), float(g[k]), k
    X, Y = np.log(f[k - 1:k + 2]), np.log(g[k - 1:k + 2])
    a, b, c = np.polyfit(X, Y, 2)
    if a >= 0:
        return float(f[k]), float(g[k]), k
    xv = -b / (2 * a)
    return float(np.exp(xv)), float(np.exp(c - b * b / (4 * a))), k


def settling_time(t, y, after, tol):
    """(time after ``after`` until y stays within +/-tol of its final value, final value)."""
    sel = t >= after
    tt, yy = t[sel], y[sel]
    if len(tt) < 2:
        raise MeasureError(f"settle: no data after {after:g}")
    final = float(yy[-1])
    band = tol * max(abs(final), 1e-300)
    out = np.nonzero(np.abs(yy - final) > band)[0]
    if len(out) == 0:
        return 0.0, final
    i = out[-1]
    if i + 1 >= len(tt):
        raise MeasureError("settle: the column is still outside the band at the end of the run; run longer")
    # interpolate the last exit from the band between samples i (outside) and i+1 (inside)
    d0, d1 = abs(yy[i] - final) - band, abs(yy[i + 1] - final) - band
    ts = tt[i] + (tt[i + 1] - tt[i]) * d0 / (d0 - d1) if d0 != d1 else tt[i + 1]
    return float(ts - after), final


def period_of(t, y):
    """(mean spacing of the upward crossings of y's mean, number of whole cycles)."""
    z = y - y.mean()
    up = np.nonzero((z[:-1] < 0) & (z[1:] >= 0))[0]
    if len(up) < 2:
        return float("nan"), 0
    tc = t[up] - z[up] * (t[up + 1] - t[up]) / (z[up + 1] - z[up])
    return float((tc[-1] - tc[0]) / (len(tc) - 1)), len(tc) - 1


# ------------------------------------------------------------------ applying them ---------
def measure_all(res, specs):
    """Compute every measure, store it in ``res.metadata['measures'][spec]`` (a {name [unit]:
    value} dict, or per member a list of {**member, **values}), return printable lines."""
    md = res.metadata.setdefault("measures", {})
    lines = []
    for spec in specs:
        found = measure(res, spec)
        if len(found) == 1 and not found[0][0]:
            md[spec] = found[0][1]
            lines.append(f"{spec}: {_text(found[0][1])}")
        else:
            md[spec] = [{**{k: _plain(v) for k, v in m.items()}, **vals} for m, vals in found]
            lines.append(f"{spec}:")
            for m, vals in found:
                lines.append(f"  {', '.join(f'{k}={_fmt(v)}' for k, v in m.items())}: {_text(vals)}")
    return lines


def _plain(v):
    return v.item() if hasattr(v, "item") else v


def _fmt(v):
    if isinstance(v, (bool, np.bool_)):
        return "yes" if v else "no"
    return f"{v:.6g}" if isinstance(v, (float, np.floating)) else str(v)


def _text(vals):
    from .results import parse_label
    parts = []
    for k, v in vals.items():
        name, unit = parse_label(k)
        parts.append(f"{name} = {_fmt(v)}" + (f" {unit}" if unit and unit != "1" else ""))
    return ", ".join(parts)
