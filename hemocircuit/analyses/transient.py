"""Transient simulation: stiff integration, restarted at every scheduled discontinuity.

Discontinuities are protocol events (parameter changes), source waveform breakpoints and
hard state limits (e.g. the Ca floor of second-order Ca dynamics: integration stops there,
the state is put on the limit, the rate state reset to zero, and integration continues).
The solver gets the batched finite-difference Jacobian of the circuit.
Results are named time series (see :class:`TransientResult`); a solver failure raises
SolverError carrying the time, the state and the part computed so far.
"""
from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp

from ..errors import SolverError
from ..protocol import Protocol
from ..provenance import clock, stamp
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


def _jac_for(c, method):
    """The Jacobian callable for solve_ivp.  Large circuits (c.sparse) give a scipy.sparse
    matrix from coloured finite differences, which BDF and Radau factorise with splu; LSODA
    takes dense matrices only."""
    if method not in ("BDF", "Radau", "LSODA"):
        return None
    if method == "LSODA" and getattr(c, "sparse", False):
        return lambda t, x: c.jacobian(t, x).toarray()
    return c.jacobian


def _limit_events(circuit, limits):
    evs = []
    for idx, bound, _ in limits:
        def ev(t, x, idx=idx, bound=bound):
            return x[idx] - bound
        ev.terminal = True
        ev.direction = -1
        evs.append(ev)
    return evs


def simulate(circuit, t_end, dt=None, t0=0.0, x0=None, protocol=None, method="BDF", rtol=1e-6, atol=None,
             max_step=np.inf, first_step=None, engine="auto", ic=None, progress=None):
    """Integrate from t0 to t_end [s].

    x0: initial states (default: the operating point after the protocol's initial settings).
    dt: output interval [s] (default: the solver's own steps; the compiled engine, which has
        no step list, then reports 1001 evenly spaced times).
    protocol: a Protocol (or path to a protocol YAML) with initial settings and timed events.
    ic: {ID.STATE: value} states to override in that start (x0 or the operating point), e.g.
        {'Cv.V': '20 mL'}; units allowed, plain numbers are in the state's unit (hemocircuit.ic).
    engine: 'compiled' (numba Rosenbrock-W ROS34PW2, hemocircuit.kernels), 'scipy'
        (solve_ivp with ``method``), or 'auto': compiled when every component type has a
        kernel and ``method`` is left at its default, scipy otherwise.
    progress: a bar of the simulated time on stderr (default: :mod:`hemocircuit.progress`'s
        setting, on for the command line unless --quiet).

    Returns a :class:`TransientResult`.  A solver failure raises SolverError whose ``partial``
    is the result up to the failure, marked ``metadata['status'] = 'partial'``.
    """
    started = clock()
    settings = {"t_end": t_end, "dt": dt, "t0": t0, "method": method, "engine": engine, "rtol": rtol,
                "atol": atol, "max_step": None if max_step == np.inf else max_step, "first_step": first_step,
                "ic": dict(ic) if ic else None, "x0": None if x0 is None else "given",
                "protocol": protocol if isinstance(protocol, str) else getattr(protocol, "file", None)}
    try:
        res = _simulate(circuit, t_end, dt, t0, x0, protocol, method, rtol, atol, max_step, first_step, engine, ic,
                        progress)
    except SolverError as exc:
        if exc.partial is not None:
            stamp(exc.partial, "tran", circuit, settings, started, status="partial")
            exc.partial.metadata["error"] = str(exc)
        raise
    return stamp(res, "tran", circuit, settings, started)


def _simulate(circuit, t_end, dt, t0, x0, protocol, method, rtol, atol, max_step, first_step, engine, ic,
              progress=None):
    from ..progress import bar
    from .op import operating_point

    c = circuit
    if isinstance(protocol, str):
        protocol = Protocol.load(protocol, c)
    if protocol is not None:
        c = protocol.apply_initial(c)
        if t_end is None:
            t_end = protocol.t_end
    if t_end is None:
        raise SolverError("no end time given (t_end or a protocol's t_end)")
    if c.B != 1:
        raise SolverError("simulate() runs one parameter set; use hemocircuit.batch for many")
    x = operating_point(c, t=t0).x if x0 is None else np.asarray(x0, dtype=float).copy()
    if ic:
        from ..ic import apply_ic
        x = apply_ic(c, x, ic)
    events = sorted([(ev.at, ev) for ev in (protocol.events if protocol else []) if t0 < ev.at < t_end],
                    key=lambda e: e[0])
    limits = c.hard_limits()
    scales = c.state_scales
    atol_v = (atol if atol is not None else rtol * 1e-3) * scales
    if engine not in ("auto", "compiled", "scipy"):
        raise SolverError(f"engine {engine!r}: choose 'auto', 'compiled' or 'scipy'")
    if engine != "scipy" and (engine == "compiled" or method == "BDF"):
        from ..kernels.system import CompiledSystem
        system = CompiledSystem.of(c)
        if system is None and engine == "compiled":
            raise SolverError("this circuit cannot run compiled (a component type without a kernel, or "
                              "too many nodal unknowns); use engine='scipy'")
        if system is not None:
            with bar(t_end - t0, "tran (simulated time)", unit="s", progress=progress) as pbar:
                return _simulate_compiled(system, c, x, t0, t_end, dt, events, rtol, atol, max_step, first_step,
                                          pbar)
    ts, xs, segs = [], [], []
    nfev = njev = nsteps = 0
    t_grid = None if dt is None else np.arange(t0, t_end + 0.5 * dt, dt)
    pbar = bar(t_end - t0, "tran (simulated time)", unit="s", progress=progress).__enter__()

    def one_segment(t_a, t_b, x_a):
        nonlocal nfev, njev, nsteps
        tpts = None
        if t_grid is not None:
            tpts = t_grid[(t_grid >= t_a) & (t_grid <= t_b)]
            if tpts.size == 0 or tpts[0] > t_a:
                tpts = np.concatenate([[t_a], tpts])
            if tpts[-1] < t_b:
                tpts = np.concatenate([tpts, [t_b]])

        def rhs(t, x):  # the bar follows the integrator's time
            pbar.update_to(t - t0)
            return c.rhs(t, x)

        try:
            sol = solve_ivp(rhs, (t_a, t_b), x_a, method=method, t_eval=tpts, rtol=rtol, atol=atol_v,
                            jac=_jac_for(c, method),
                            events=_limit_events(c, limits) or None, max_step=max_step,
                            first_step=first_step)
        except Exception as exc:  # a failing right-hand side or linear solve
            raise SolverError(f"integration failed: {exc}", time=t_a, state=c.state_dict(x_a),
                              partial=_partial()) from None
        nfev += sol.nfev
        njev += sol.njev
        nsteps += len(sol.t)
        if sol.status == -1 or not np.all(np.isfinite(sol.y)):
            tf = float(sol.t[-1]) if len(sol.t) else t_a
            xf = sol.y[:, -1] if sol.y.size else x_a
            raise SolverError(f"integrator {method} failed: {sol.message}", time=tf, state=c.state_dict(xf),
                              partial=_partial())
        return sol

    def _partial():
        if not ts:
            return None
        return _collect(c, ts, xs, segs)

    bounds = [t0] + [e[0] for e in events] + [t_end]
    try:
        for k in range(len(bounds) - 1):
            t_a, t_b = bounds[k], bounds[k + 1]
            if k > 0:
                c = events[k - 1][1].apply(c)
            # restart at waveform breakpoints inside the segment
            cuts = [t_a] + c.breakpoints(t_a, t_b) + [t_b]
            for a, b in zip(cuts, cuts[1:]):
                cur = a
                while cur < b:
                    sol = one_segment(cur, b, x)
                    ts.append(sol.t)
                    xs.append(sol.y.T)
                    segs.append(c)
                    x = sol.y[:, -1].copy() if sol.y.size else x
                    if sol.status == 1:  # a hard limit was reached: put the state on it, reset its rate
                        k_ev = min((j for j, e in enumerate(sol.t_events) if len(e)), key=lambda j: sol.t_events[j][0])
                        cur = float(sol.t_events[k_ev][0])
                        x = sol.y_events[k_ev][0].copy()
                        idx, bound, reset = limits[k_ev]
                        x[idx] = bound
                        if reset is not None:
                            x[reset] = max(x[reset], 0.0)
                        ts.append(np.array([cur]))
                        xs.append(x[None, :])
                        segs.append(c)
                    else:
                        cur = b
    finally:
        pbar.close()
    res = _collect(c, ts, xs, segs)
    res.stats = {"nfev": nfev, "njev": njev, "nsteps": nsteps, "method": method}
    return res


def _collect(c_last, ts, xs, segs):
    """Stack segments (dropping duplicated boundary points) and compute outputs per segment."""
    t_all, x_all, cols = [], [], {}
    for t, x, c in zip(ts, xs, segs):
        if t.size == 0:
            continue
        if t_all and t_all[-1].size and t[0] <= t_all[-1][-1]:
            # keep the later value at a restart time (after an event)
            t_all[-1], x_all[-1] = t_all[-1][:-1], x_all[-1][:-1]
            for k in cols:
                cols[k][-1] = cols[k][-1][:-1]
        for k, v in c.outputs(t, x).items():
            cols.setdefault(k, []).append(np.asarray(v))
        t_all.append(t)
        x_all.append(x)
    t = np.concatenate(t_all) if t_all else np.zeros(0)
    x = np.concatenate(x_all) if x_all else np.zeros((0, c_last.nx))
    columns = {k: np.concatenate(cols.pop(k)) for k in list(cols)}  # each part freed once copied
    return TransientResult(t, x, columns, c_last.column_units(), c_last.state_names)


def _simulate_compiled(system, c, x, t0, t_end, dt, events, rtol, atol, max_step, first_step, bar=None):
    """simulate() on the compiled engine: one kernel call per protocol segment (hard limits and
    source breakpoints are handled inside the kernel); with a progress ``bar`` shown, a segment
    is integrated in about 50 pieces so that the bar moves (each piece starts with the mean
    step of the piece before)."""
    from ..kernels.system import CompiledSystem

    if dt is None:
        t_grid = np.linspace(t0, t_end, 1001)
    else:
        t_grid = np.arange(t0, t_end + 0.5 * dt, dt)
        t_grid = t_grid[t_grid <= t_end + 1e-9 * max(1.0, abs(t_end))]
        if t_grid[-1] < t_end:
            t_grid = np.append(t_grid, t_end)
    bounds = [t0] + [e[0] for e in events] + [t_end]
    ts, xs, segs = [], [], []
    stats = {"steps": 0, "rejected": 0, "nfev": 0, "limit_events": 0}
    h0 = 1e-3 if first_step is None else first_step
    for k in range(len(bounds) - 1):
        t_a, t_b = bounds[k], bounds[k + 1]
        if k > 0:
            c = events[k - 1][1].apply(c)
            # an event may change waveforms, options or expressions: the layout follows the
            # circuit (cheap; the compiled engine itself is reused)
            system = CompiledSystem.of(c)
            if system is None:
                raise SolverError(f"the event at t = {t_a:g} s leaves a circuit that cannot run compiled; "
                                  "use engine='scipy'", time=t_a)
        if t_b <= t_a:  # several events at one time: apply them all, integrate nothing
            continue
        tpts = t_grid[(t_grid > t_a) & (t_grid < t_b)]
        tpts = np.concatenate([[t_a], tpts, [t_b]])
        X, st = _integrate_pieces(system, c, tpts, x, rtol, atol, h0, max_step, bar, t0)
        for key in stats:
            stats[key] += st[key]
        good = np.all(np.isfinite(X), axis=1)
        ts.append(tpts[good])
        xs.append(X[good])
        segs.append(c)
        if st["status"] < 0:
            bad = X[good][-1] if good.any() else x
            raise SolverError(f"compiled integrator failed: {st['message']}", time=st["t"],
                              state=c.state_dict(bad), partial=_collect(c, ts, xs, segs))
        x = X[-1].copy()
    res = _collect(c, ts, xs, segs)
    res.stats = {**stats, "method": "ROS34PW2 (compiled)"}
    return res


def _integrate_pieces(system, c, tpts, x, rtol, atol, h0, max_step, bar, t0):
    """One kernel call over ``tpts``; with a shown ``bar``, ~50 calls over consecutive pieces."""
    shown = bar is not None and getattr(bar, "_t", None) is not None
    n_pieces = min(50, (len(tpts) - 1) // 20) if shown else 1  # pieces of >= 20 output points
    if n_pieces <= 1:
        out = system.integrate(tpts, x, system.params(c)[0], rtol=rtol, atol=atol,
                               breaks=c.breakpoints(tpts[0], tpts[-1]), h0=h0, hmax=max_step)
        if bar is not None:
            bar.update_to(tpts[-1] - t0)
        return out
    cuts = np.unique(np.linspace(0, len(tpts) - 1, n_pieces + 1).round().astype(int))
    Xs, stats = [x[None, :]], None
    for a, b in zip(cuts[:-1], cuts[1:]):
        X, st = system.integrate(tpts[a:b + 1], x, system.params(c)[0], rtol=rtol, atol=atol,
                                 breaks=c.breakpoints(tpts[a], tpts[b]), h0=h0, hmax=max_step)
        Xs.append(X[1:])
        stats = dict(st) if stats is None else {**st, **{k: stats[k] + st[k] for k in
                                                       ("steps", "rejected", "nfev", "limit_events") if k in st}}
        bar.update_to(tpts[b] - t0)
        if st["status"] < 0:
            break
        x = X[-1].copy()
        h0 = (tpts[b] - tpts[a]) / max(st["steps"], 1)
    X = np.concatenate(Xs)
    if len(X) < len(tpts):  # stopped by a failure: the rest is NaN, as for one call
        X = np.vstack([X, np.full((len(tpts) - len(X), X.shape[1]), np.nan)])
    return X, stats
