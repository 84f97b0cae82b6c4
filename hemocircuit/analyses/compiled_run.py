"""A transient run on the compiled engine, and the time series every transient run returns.

Below both :mod:`hemocircuit.analyses.transient` (which chooses the engine and handles the
scipy path) and :mod:`hemocircuit.kernels.background` (which makes the same run in a second
process so that numba compiles and caches it): the run is written once, here.
"""
from __future__ import annotations

import numpy as np

from ..errors import Interrupted, SolverError
from ..results import Result


class TransientResult(Result):
    """Time series (a :class:`hemocircuit.results.Result` indexed by ``time`` [s]): ``t`` (T,),
    ``x`` (T, nx) states (not written to files; the outputs are), ``columns`` {name: (T,)
    array}, ``units``, ``state_names``, ``stats`` (solver statistics, ``metadata['solver']``)."""

    def __init__(self, t, x, columns, units, state_names, stats=None):
        super().__init__({"time": t, **columns}, {"time": "s", **units}, index=["time"])
        self.x = x
        self.state_names = state_names
        self.stats = stats or {}

    @property
    def t(self):
        return self.data["time"]

    @property
    def stats(self):
        return self.metadata["solver"]

    @stats.setter
    def stats(self, value):
        self.metadata["solver"] = dict(value)

    def __getitem__(self, key):
        return super().__getitem__("time" if key == "t" else key)


def from_time(t, t_from):
    """The times of ``t`` from ``t_from`` on (all if it is None; to rounding of a grid)."""
    if t_from is None:
        return t
    return t[t >= t_from - 1e-12 * max(1.0, abs(t_from))]


def _on_grid(t, grid):
    """Bool mask of the times ``t`` that are output times of ``grid`` (to rounding)."""
    j = np.clip(np.searchsorted(grid, t), 1, max(len(grid) - 1, 1))
    near = np.minimum(np.abs(t - grid[j - 1]), np.abs(t - grid[np.minimum(j, len(grid) - 1)]))
    return near <= 1e-9 * np.maximum(1.0, np.abs(t))


def collect(c_last, ts, xs, segs, t_from=None, grid=None):
    """Stack segments (dropping duplicated boundary points and rows before ``t_from``) and
    compute their outputs.  ``grid``: the requested output times; points the integrator
    added (a hard limit's event time, a segment's end) are left out, so the result has the
    grid the compiled engine gives (a measure on it, e.g. a period from interpolated
    crossings, must not depend on which engine ran)."""
    parts = []  # [t, x, c] of each segment, trimmed
    for t, x, c in zip(ts, xs, segs):
        if t_from is not None:
            keep = from_time(t, t_from).size
            t, x = t[t.size - keep:], x[x.shape[0] - keep:]  # times increase within a segment
        if grid is not None and t.size:
            on = _on_grid(t, grid)
            t, x = t[on], x[on]
        if t.size == 0:
            continue
        if parts and parts[-1][0].size and t[0] <= parts[-1][0][-1]:
            # keep the later value at a restart time (after an event, or a piece's start)
            parts[-1][0], parts[-1][1] = parts[-1][0][:-1], parts[-1][1][:-1]
        parts.append([t, x, c])
    # the outputs once per run of segments of one circuit: one call of many rows runs the
    # components' functions in one compiled loop per group (elementwise.LOOP_CALLS); many
    # short calls would each pay a call's fixed cost
    runs = []
    for t, x, c in parts:
        if runs and runs[-1][2] is c:
            runs[-1][0].append(t)
            runs[-1][1].append(x)
        else:
            runs.append(([t], [x], c))
    t_all, x_all, cols = [], [], {}
    for t_run, x_run, c in runs:
        t, x = np.concatenate(t_run), np.concatenate(x_run)
        if t.size == 0:
            continue
        for k, v in c.outputs(t, x).items():
            cols.setdefault(k, []).append(np.asarray(v))
        t_all.append(t)
        x_all.append(x)
    t = np.concatenate(t_all) if t_all else np.zeros(0)
    x = np.concatenate(x_all) if x_all else np.zeros((0, c_last.nx))
    columns = {k: np.concatenate(cols.pop(k)) for k in list(cols)}  # each part freed once copied
    return TransientResult(t, x, columns, c_last.column_units(), c_last.state_names)


def output_grid(t0, t_end, dt):
    """The compiled engine's output times: every dt from t0, and t_end (1001 points without dt)."""
    if dt is None:
        return np.linspace(t0, t_end, 1001)
    tol = 1e-9 * max(1.0, abs(t_end))
    n = int(np.floor((t_end - t0 + tol) / dt)) + 1
    t_grid = t0 + dt * np.arange(n)
    if n > 1 and t_end - t_grid[-1] <= tol:  # the last multiple of dt is t_end (to rounding):
        t_grid[-1] = t_end                   # t_end itself, not a second point next to it
        return t_grid
    return np.append(t_grid, t_end)


def simulate_compiled(system, c, x, t0, t_end, dt, events, rtol, atol, max_step, first_step, bar=None,
                       t_grid=None, parts=None, bar_t0=None, output_from=None, method=None):
    """simulate() on the compiled engine: kernel calls per protocol segment (hard limits and
    source breakpoints are handled inside the kernel), in pieces (:func:`_segment`):
    at most PIECE_STEPS steps each and, with a progress ``bar`` shown, about 50 per segment.
    A run handed over from the scipy path at t0 passes its output grid ``t_grid``, its series
    so far ``parts`` (ts, xs, segs; appended to) and its start ``bar_t0``."""
    if t_grid is None:
        t_grid = output_grid(t0, t_end, dt)
    if output_from is not None:
        # rows before output_from are dropped by _collect; ~100 of them stay as the points a
        # run that needs more than PIECE_STEPS continues from (not every dt: dense output)
        late = from_time(t_grid, output_from)
        early = t_grid[:t_grid.size - late.size]
        t_grid = np.concatenate([early[::max(1, early.size // 100)], late])
    bounds = [t0] + [e[0] for e in events] + [t_end]
    ts, xs, segs = parts if parts is not None else ([], [], [])
    stats = {"steps": 0, "rejected": 0, "nfev": 0, "limit_events": 0}
    h0 = 1e-3 if first_step is None else first_step
    for k in range(len(bounds) - 1):
        t_a, t_b = bounds[k], bounds[k + 1]
        if k > 0:
            c = events[k - 1][1].apply(c)
            # an event may change waveforms, options or expressions: the layout follows the
            # circuit (cheap; the compiled engine itself is reused)
            system = c.system.compiled()
            if system is None:
                raise SolverError(f"the event at t = {t_a:g} s leaves a circuit that cannot run compiled; "
                                  "use engine='scipy'", time=t_a)
        if t_b <= t_a:  # several events at one time: apply them all, integrate nothing
            continue
        tpts = t_grid[(t_grid > t_a) & (t_grid < t_b)]
        tpts = np.concatenate([[t_a], tpts, [t_b]])
        try:
            x = _segment(system, c, tpts, x, rtol, atol, h0, max_step, stats, ts, xs, segs, bar,
                                  t0 if bar_t0 is None else bar_t0, method)
        except KeyboardInterrupt as exc:
            raise Interrupted.of(exc, partial=collect(c, ts, xs, segs, output_from) if ts else None) from None
        except SolverError as exc:  # its partial: the rows from output_from on, as the result's
            if exc.partial is not None and output_from is not None:
                exc.partial = collect(c, ts, xs, segs, output_from)
            raise
    res = collect(c, ts, xs, segs, output_from)
    from ..kernels.tableaus import DEFAULT
    res.stats = {**stats, "method": f"{(method or DEFAULT).upper()} (compiled)"}
    return res


#: steps per call of the compiled integrator: Python regains control (a signal is handled, the
#: series so far kept) at least this often; a run needing more steps continues from its last
#: output point (the output grid's times are kept)
PIECE_STEPS = 200_000
MAX_STEPS = 10_000_000  # per protocol segment, as the compiled integrator's own limit


def _segment(system, c, tpts, x, rtol, atol, h0, max_step, stats, ts, xs, segs, bar=None, t0=0.0,
                      method=None):
    """One protocol segment on the output times ``tpts``; appends to ts, xs, segs; returns the
    final state.  The compiled integrator returns to Python at least every PIECE_STEPS steps
    and, with a progress ``bar`` shown, after each of ~50 consecutive ranges of output times
    (each starting with the mean step of the range before) so that the bar moves."""
    P = system.params(c)[0]
    shown = bar is not None and getattr(bar, "_t", None) is not None
    n_ranges = min(50, (len(tpts) - 1) // 20) if shown else 1  # ranges of >= 20 output points
    cuts = np.unique(np.linspace(0, len(tpts) - 1, max(n_ranges, 1) + 1).round().astype(int))
    used = 0
    for a, b in zip(cuts[:-1], cuts[1:]):
        before = used
        x, used = _range(system, c, P, tpts[a:b + 1], x, rtol, atol, h0, max_step, stats, ts, xs, segs,
                                  used, method)
        if bar is not None:
            bar.update_to(tpts[b] - t0)
        h0 = (tpts[b] - tpts[a]) / max(used - before, 1)
    return x


def _range(system, c, P, tpts, x, rtol, atol, h0, max_step, stats, ts, xs, segs, used, method=None):
    """The output times ``tpts`` in calls of at most PIECE_STEPS steps (``used``: the steps the
    segment took so far, at most MAX_STEPS); appends to ts, xs, segs; returns (final state, used)."""
    from ..execution import check_interrupted

    # steps end on every breakpoint; where a waveform only changes its slope (a pwl table's
    # times) its value is continuous and the integrator needs no new evaluation there
    breaks, kinks = c.jumps_and_kinks(tpts[0], tpts[-1])
    budget = PIECE_STEPS
    while True:
        check_interrupted()
        X, st = system.integrate(tpts, x, P, rtol=rtol, atol=atol, breaks=breaks, kinks=kinks, h0=h0,
                                 hmax=max_step, max_steps=min(budget, MAX_STEPS - used), method=method)
        for key in stats:
            stats[key] += st[key]
        used += st["steps"]
        good = np.all(np.isfinite(X), axis=1)
        if st["status"] == -2 and used < MAX_STEPS:  # the piece's budget ran out, not the run's
            n_good = len(good) if good.all() else int(np.argmin(good))  # rows before the first NaN
            if n_good > 1:  # keep the rows done, go on from the last one
                ts.append(tpts[:n_good])
                xs.append(X[:n_good])
                segs.append(c)
                tpts, x, budget = tpts[n_good - 1:], X[n_good - 1].copy(), PIECE_STEPS
            else:  # one output interval needs more than a piece: give it the rest of the budget
                budget = MAX_STEPS
            continue
        ts.append(tpts[good])
        xs.append(X[good])
        segs.append(c)
        if st["status"] < 0:
            bad = X[good][-1] if good.any() else x
            t_bad = float(tpts[good][-1]) if good.any() else float(tpts[0])
            raise SolverError(f"compiled integrator failed: {st['message']}{fastest_state(system, c, P, t_bad, bad)}"
                              f"{_bdf_hint(system, method, st['status'])}",
                              time=st["t"], state=c.state_dict(bad), partial=collect(c, ts, xs, segs))
        return X[-1].copy(), used


def _bdf_hint(system, method, status):
    """How to go on when the BDF method's step collapsed in a circuit with hard limits: it
    does not locate where a held state (a closed valve's flow) is released, the Rosenbrock
    methods do (engine_rosenbrock.release_fraction); the whole-body heart stops it at its
    first valve opening."""
    from ..kernels.tableaus import BDF

    if method != BDF or status != -1 or system.lim_i.size == 0:
        return ""
    return ("; the bdf integrator does not locate where a state held on its hard limit (a closed valve's flow) "
            "is released: run this circuit with --integrator rodas5p (the default), which does")


def fastest_state(system, c, P, t, x):
    """'; fastest there: ...' naming the state whose derivative is largest against its size
    (|dx/dt| / max(|x|, its scale)) at (t, x) and its element's type: where a run's step size
    collapses that is usually the element at fault (a closed valve's flow, an arteriole's
    collapsing stretch).  Empty when the right-hand side cannot be evaluated there."""
    try:
        f = np.asarray(system.rhs(t, x, P), dtype=float)
    except Exception:  # noqa: BLE001 - a diagnosis must never hide the failure it explains
        return ""
    if f.size == 0 or not np.all(np.isfinite(f)):
        return ""
    rate = np.abs(f) / np.maximum(np.abs(x), np.asarray(c.state_scales, dtype=float))
    k = int(np.argmax(rate))
    name, unit = c.state_names[k], c.state_units[k]
    eid = name.rsplit(".", 1)[0]
    type_name = getattr(getattr(c.elements.get(eid), "cls", None), "type_name", None)
    kind = f", type {type_name}" if type_name else ""
    per_s = "1/s" if unit in ("dimensionless", "1", "") else f"{unit}^2" if unit.endswith("/s") else f"{unit}/s"
    shown = "" if unit in ("dimensionless", "1", "") else f" {unit}"
    return f"; fastest there (t = {t:g} s): {name} ({eid}{kind}) = {x[k]:.6g}{shown}, d/dt = {f[k]:.3g} {per_s}"
