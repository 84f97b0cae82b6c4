"""Transient simulation: stiff integration, restarted at every scheduled discontinuity.

Discontinuities are protocol events (parameter changes), source waveform breakpoints and
hard state limits (e.g. the Ca floor of second-order Ca dynamics: integration stops there,
the state is put on the limit, the rate state reset to zero, and integration continues).
The solver gets the batched finite-difference Jacobian of the circuit.
Results are named time series (see :class:`TransientResult`); a solver failure raises
SolverError carrying the time, the state and the part computed so far.
"""
from __future__ import annotations

import sys

import numpy as np
from scipy.integrate import solve_ivp

from .. import plausibility
from ..errors import Interrupted, SolverError
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


#: the integrators by name (tran --integrator, simulate(integrator=...)): (engine, method)
INTEGRATORS = {
    "rodas5p": ("compiled", "rodas5p"),     # Rosenbrock, order 5(4), stiffly accurate (the default)
    "rodas4": ("compiled", "rodas4"),       # Rosenbrock, order 4(3)
    "ros34pw2": ("compiled", "ros34pw2"),   # Rosenbrock W-method, order 3(2), Jacobian reused
    "bdf": ("compiled", "bdf"),             # variable-order BDF (1-5), compiled
    "scipy-bdf": ("scipy", "BDF"),          # scipy.integrate.solve_ivp's BDF
    "scipy-radau": ("scipy", "Radau"),      # scipy.integrate.solve_ivp's Radau IIA, order 5
    "lsoda": ("scipy", "LSODA"),            # scipy.integrate.solve_ivp's LSODA (ODEPACK)
}


def resolve_integrator(integrator, method="BDF", engine="auto"):
    """(engine, scipy method, compiled method or None) of an integrator name (None: ``method``
    and ``engine`` as given, the compiled engine's default method)."""
    if integrator is None:
        return engine, method, None
    if integrator not in INTEGRATORS:
        from ..errors import did_you_mean
        raise SolverError(f"integrator {integrator!r}{did_you_mean(integrator, INTEGRATORS)}: choose one of "
                          f"{', '.join(INTEGRATORS)}")
    eng, meth = INTEGRATORS[integrator]
    return (eng, meth, None) if eng == "scipy" else (eng, "BDF", meth)


def simulate(circuit, t_end, dt=None, t0=0.0, x0=None, protocol=None, method="BDF", rtol=1e-6, atol=None,
             max_step=np.inf, first_step=None, engine="auto", ic=None, progress=None, compile="wait",
             output_from=None, integrator=None):
    """Integrate from t0 to t_end [s].

    x0: initial states (default: the operating point after the protocol's initial settings).
    dt: output interval [s] (default: the solver's own steps; the compiled engine, which has
        no step list, then reports 1001 evenly spaced times).
    output_from: first output time [s] (SPICE's TSTART): the run starts at t0, but only the
        rows from this time on are kept and get outputs (e.g. the last cardiac cycle).
    protocol: a Protocol (or path to a protocol YAML) with initial settings and timed events.
    ic: {ID.STATE: value} states to override in that start (x0 or the operating point), e.g.
        {'Cv.V': '20 mL'}; units allowed, plain numbers are in the state's unit (hemocircuit.ic).
    integrator: a name of :data:`INTEGRATORS` (rodas5p, rodas4, ros34pw2, bdf on the compiled
        engine; scipy-bdf, scipy-radau, lsoda through solve_ivp); it sets ``engine`` and
        ``method``.  None: as ``engine`` and ``method`` say.
    rtol, atol: relative tolerance and absolute tolerance per unit of each state's scale
        (default rtol * 1e-3); max_step: the largest step [s].
    engine: 'compiled' (numba Rosenbrock RODAS5P, hemocircuit.kernels), 'scipy'
        (solve_ivp with ``method``), or 'auto': compiled when every component type has a
        kernel and ``method`` is left at its default, scipy otherwise.
    progress: a bar of the simulated time on stderr (default: :mod:`hemocircuit.progress`'s
        setting, on for the command line unless --quiet).
    compile: with engine 'auto', what a run does when the compiled engine of the circuit's
        component types is not built yet (its first run; building takes 20-45 s):
        'wait' compiles it first; 'background' starts the build in another process
        (:mod:`hemocircuit.kernels.background`), integrates on the scipy path meanwhile and
        continues on the compiled engine from the first piece after the build is ready
        (``stats['method']`` says where it switched).  The command line uses 'background'.

    Returns a :class:`TransientResult`; implausible values (:mod:`hemocircuit.plausibility`)
    are listed in ``metadata['warnings']``.  A solver failure (or a non-finite value) raises
    SolverError, and SIGINT/SIGTERM :class:`~hemocircuit.errors.Interrupted`; the ``partial``
    of either is the result up to that point, marked ``metadata['status'] = 'partial'``.
    """
    started = clock()
    engine, method, compiled_method = resolve_integrator(integrator, method, engine)
    if not (isinstance(rtol, (int, float, np.number)) and 0 < rtol < 1):
        raise SolverError(f"rtol = {rtol!r}: the relative tolerance must be a number between 0 and 1 (e.g. 1e-6)")
    if atol is not None and not (np.size(atol) and np.all(np.isfinite(atol)) and np.all(np.asarray(atol) > 0)):
        raise SolverError(f"atol = {atol!r}: the absolute tolerance must be positive (per unit of each state's "
                          "scale, e.g. 1e-9; or one per state)")
    if not (isinstance(max_step, (int, float, np.number)) and max_step > 0):
        raise SolverError(f"max_step = {max_step!r}: the largest step must be a positive time [s]")
    settings = {"t_end": t_end, "dt": dt, "t0": t0, "integrator": integrator, "method": method, "engine": engine,
                "rtol": rtol,
                "atol": atol, "max_step": None if max_step == np.inf else max_step, "first_step": first_step,
                "ic": dict(ic) if ic else None, "x0": None if x0 is None else "given",
                "protocol": protocol if isinstance(protocol, str) else getattr(protocol, "file", None),
                "compile": compile, "output_from": output_from}
    if compile not in ("wait", "background"):
        raise SolverError(f"compile {compile!r} (tran --compile, $HEMOCIRCUIT_COMPILE): choose 'wait' or 'background'")
    try:
        res = _simulate(circuit, t_end, dt, t0, x0, protocol, method, rtol, atol, max_step, first_step, engine, ic,
                        progress, compile, output_from, compiled_method)
    except SolverError as exc:
        if exc.partial is not None:
            stamp(exc.partial, "tran", circuit, settings, started, status="partial")
            exc.partial.metadata["error"] = str(exc)
        raise
    except KeyboardInterrupt as exc:  # SIGINT/SIGTERM: the series up to the last finished piece
        part = getattr(exc, "partial", None)
        if part is not None:
            stamp(part, "tran", circuit, settings, started, status="partial")
            part.metadata["members_done"] = (f"t = {part.t[0]:g} .. {part.t[-1]:g} s of {settings['t_end']} s "
                                             f"computed" if part.n_rows else "nothing computed")
        raise Interrupted.of(exc, partial=part) from None
    findings = plausibility.check(circuit, res.columns, t=res.t)
    bad = plausibility.errors(findings)
    if bad:
        raise SolverError("implausible solution: " + "; ".join(map(str, bad)),
                          partial=stamp(res, "tran", circuit, settings, started, status="partial"))
    plausibility.add_warnings(res, findings)
    if isinstance(protocol, str):
        protocol = Protocol.load(protocol, circuit)
    if x0 is None and not ic and not circuit.netlist.ic and not (protocol is not None and protocol.events):
        unstable = _unstable_start(protocol.apply_initial(circuit) if protocol is not None else circuit, t0)
        if unstable:
            res.metadata.setdefault("warnings", []).append(unstable)
    return stamp(res, "tran", circuit, settings, started)


#: states up to which a run from the operating point checks that equilibrium's stability
#: (a dense eigen-decomposition: cheap below this size)
UNSTABLE_CHECK_STATES = 300


def _unstable_start(c, t0):
    """A warning when a run starting unperturbed on the operating point starts on an unstable
    equilibrium: without a perturbation it stays there up to round-off (a flat line where a
    limit cycle was expected).  None otherwise, and for circuits above UNSTABLE_CHECK_STATES."""
    from .op import operating_point
    from .stability import eigenvalues

    if not 0 < c.nx <= UNSTABLE_CHECK_STATES:
        return None
    try:
        lam = eigenvalues(c, operating_point(c, t=t0).x, t=t0)
    except (SolverError, np.linalg.LinAlgError):
        return None
    lam = lam[np.isfinite(lam)]
    if not lam.size or lam.real.max() <= 0:
        return None
    top = lam[np.argmax(lam.real)]
    mode = f", an oscillation of period {2 * np.pi / abs(top.imag):.4g} s" if abs(top.imag) > 1e-12 else ""
    return (f"the run started on an unstable equilibrium (growth rate {top.real:.3g} 1/s{mode}) and, unperturbed, "
            "stays on it up to round-off; perturb the start: --ic ID.STATE=VALUE, a protocol event, or an 'ic:' "
            "entry in the netlist (docs/netlist.md)")


_told = []


def _say_compiling():
    """Once per process: the first run of a set of component types waits for its compile."""
    if not _told:
        _told.append(True)
        from ..kernels.codegen import cache_dir
        print(f"hemocircuit: compiling the engine for these component types (their first run; about 15-30 s, "
              f"cached in {cache_dir()} for every later run)", file=sys.stderr, flush=True)


def _simulate(circuit, t_end, dt, t0, x0, protocol, method, rtol, atol, max_step, first_step, engine, ic,
              progress=None, compile="wait", output_from=None, compiled_method=None):
    from ..progress import bar, wanted
    from .op import operating_point

    c = circuit
    handover = None
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
    if output_from is not None and not (isinstance(output_from, (int, float, np.number))
                                        and np.isfinite(output_from) and t0 <= output_from <= t_end):
        raise SolverError(f"output_from = {output_from!r} s: the first output time must lie in the run, "
                          f"between t0 = {t0:g} s and t_end = {t_end:g} s")
    if engine != "scipy" and compile == "wait" and (engine == "compiled" or method == "BDF"):
        from ..kernels import prebuild
        system = c.system.compiled()  # the System chooses the engine
        if system is not None:  # a first compile: its second process starts before the operating point
            from ..kernels import background
            if not background.ready(system) and progress is not False:
                _say_compiling()
            prebuild.start(system)
    x = operating_point(c, t=t0).x if x0 is None else np.asarray(x0, dtype=float).copy()
    # the netlist's starting perturbation (from the operating point only), --ic state by state over it
    ic = {**(c.netlist.ic if x0 is None else {}), **(ic or {})}
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
        system = c.system.compiled()
        if system is None and engine == "compiled":
            raise SolverError("this circuit cannot run compiled (a component type without a kernel, or "
                              "too many nodal unknowns); use engine='scipy'")
        if system is not None:
            from ..kernels import background
            if compile == "background" and engine == "auto" and not background.ready(system) \
                    and background.start(system, c, x, t0, rtol):
                handover = _Handover(system, t0, t_end)  # the scipy path below, until the build is ready
                if wanted(progress):
                    print("hemocircuit: the compiled engine for these component types is being built in the "
                          "background (first run, about 20-45 s); integrating on the scipy path meanwhile",
                          file=sys.stderr)
            else:
                with bar(t_end - t0, "tran (simulated time)", unit="s", progress=progress) as pbar:
                    res = _simulate_compiled(system, c, x, t0, t_end, dt, events, rtol, atol, max_step, first_step,
                                             pbar, output_from=output_from, method=compiled_method)
                background.mark_ready(system)
                return res
    ts, xs, segs = [], [], []
    nfev = njev = nsteps = 0
    t_grid = None if dt is None else _from(np.arange(t0, t_end + 0.5 * dt, dt), output_from)
    pbar = bar(t_end - t0, "tran (simulated time)", unit="s", progress=progress).__enter__()

    def one_segment(c, t_a, t_b, x_a):
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
        return _collect(c, ts, xs, segs, output_from)

    bounds = [t0] + [e[0] for e in events] + [t_end]
    compiled = None
    try:
        switch = _scipy_segments(c, x, bounds, events, limits, one_segment, ts, xs, segs, handover, t_grid)
        if switch is not None:  # the background build is ready: the rest on the compiled engine
            k, t_s, x_s, c_k = switch
            compiled = _simulate_compiled(c_k.system.compiled(), c_k, x_s, t_s, t_end, dt, events[k:], rtol, atol,
                                          max_step, first_step, pbar, t_grid=_output_grid(t0, t_end, dt),
                                          parts=(ts, xs, segs), bar_t0=t0, output_from=output_from)
    except KeyboardInterrupt as exc:
        raise Interrupted.of(exc, partial=_partial()) from None
    finally:
        pbar.close()
    scipy_stats = {"nfev": nfev, "njev": njev, "nsteps": nsteps, "method": method}
    if compiled is not None:
        compiled.stats = {**compiled.stats, "method": f"{method} (scipy) to t = {switch[1]:.6g} s while the compiled "
                                                      f"engine was built, then {compiled.stats['method']}",
                          "switched_at": switch[1], "scipy": scipy_stats}
        return compiled
    res = _collect(segs[-1] if segs else c, ts, xs, segs, output_from,
                   grid=None if dt is None else _output_grid(t0, t_end, dt))
    res.stats = scipy_stats if handover is None else {**scipy_stats, "compiled_engine": "building in the background"}
    return res


class _Handover:
    """The scipy path in pieces while the compiled engine builds in the background
    (simulate's ``compile='background'``): each piece takes about PIECE_WALL seconds of wall
    time, after each :meth:`ready` says whether the rest can run compiled."""

    PIECE_WALL = 0.25  # [s] of wall time between checks

    def __init__(self, system, t0, t_end):
        self.system = system
        self.piece = (t_end - t0) / 1000.0  # [s] simulated: a first guess, adapted after each piece

    def end_of(self, cur, b, t_grid):
        """End of the piece starting at ``cur`` in a stretch ending at ``b`` (an output time
        when there is an output grid, so that pieces add no rows)."""
        end = min(b, cur + self.piece)
        if t_grid is not None and end < b:
            later = t_grid[t_grid >= end]
            end = min(b, float(later[0])) if later.size else b
        return end

    def after(self, simulated, wall):
        """Adapt the piece length to the speed of the last piece (at most 4x per piece)."""
        target = simulated * self.PIECE_WALL / max(wall, 1e-4)
        self.piece = min(max(target, self.piece / 4), self.piece * 4)

    def ready(self):
        from ..kernels import background
        return background.ready(self.system)


def _scipy_segments(c, x, bounds, events, limits, one_segment, ts, xs, segs, handover=None, t_grid=None):
    """Integrate the protocol segments (solve_ivp), appending to ts, xs, segs.  With a
    ``handover`` (:class:`_Handover`), in pieces: returns (segment index, time, state,
    circuit) where the compiled engine is to go on, or None when the scipy path finished."""
    import time

    for k in range(len(bounds) - 1):
        t_a, t_b = bounds[k], bounds[k + 1]
        if k > 0:
            c = events[k - 1][1].apply(c)
        # restart at waveform breakpoints inside the segment
        cuts = [t_a] + c.breakpoints(t_a, t_b) + [t_b]
        for a, b in zip(cuts, cuts[1:]):
            cur = a
            while cur < b:
                end = b if handover is None else handover.end_of(cur, b, t_grid)
                started = time.perf_counter()
                sol = one_segment(c, cur, end, x)
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
                    t_reached = cur
                else:
                    t_reached = end
                if handover is not None:
                    # asked after every piece, also one that a hard limit ended (in an oscillation
                    # every piece may end on one): the compiled engine goes on from that state
                    handover.after(t_reached - (sol.t[0] if sol.t.size else t_reached), time.perf_counter() - started)
                    if t_reached < bounds[-1] and handover.ready():
                        return k, t_reached, x, c
                cur = t_reached
    return None


def _from(t, t_from):
    """The times of ``t`` from ``t_from`` on (all if it is None; to rounding of a grid)."""
    if t_from is None:
        return t
    return t[t >= t_from - 1e-12 * max(1.0, abs(t_from))]


def _on_grid(t, grid):
    """Bool mask of the times ``t`` that are output times of ``grid`` (to rounding)."""
    j = np.clip(np.searchsorted(grid, t), 1, max(len(grid) - 1, 1))
    near = np.minimum(np.abs(t - grid[j - 1]), np.abs(t - grid[np.minimum(j, len(grid) - 1)]))
    return near <= 1e-9 * np.maximum(1.0, np.abs(t))


def _collect(c_last, ts, xs, segs, t_from=None, grid=None):
    """Stack segments (dropping duplicated boundary points and rows before ``t_from``) and
    compute outputs per segment.  ``grid``: the requested output times; points the integrator
    added (a hard limit's event time, a segment's end) are left out, so the result has the
    grid the compiled engine gives (a measure on it, e.g. a period from interpolated
    crossings, must not depend on which engine ran)."""
    t_all, x_all, cols = [], [], {}
    for t, x, c in zip(ts, xs, segs):
        if t_from is not None:
            keep = _from(t, t_from).size
            t, x = t[t.size - keep:], x[x.shape[0] - keep:]  # times increase within a segment
        if grid is not None and t.size:
            on = _on_grid(t, grid)
            t, x = t[on], x[on]
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


def _output_grid(t0, t_end, dt):
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


def _simulate_compiled(system, c, x, t0, t_end, dt, events, rtol, atol, max_step, first_step, bar=None,
                       t_grid=None, parts=None, bar_t0=None, output_from=None, method=None):
    """simulate() on the compiled engine: kernel calls per protocol segment (hard limits and
    source breakpoints are handled inside the kernel), in pieces (:func:`_compiled_segment`):
    at most PIECE_STEPS steps each and, with a progress ``bar`` shown, about 50 per segment.
    A run handed over from the scipy path at t0 passes its output grid ``t_grid``, its series
    so far ``parts`` (ts, xs, segs; appended to) and its start ``bar_t0``."""
    if t_grid is None:
        t_grid = _output_grid(t0, t_end, dt)
    if output_from is not None:
        # rows before output_from are dropped by _collect; ~100 of them stay as the points a
        # run that needs more than PIECE_STEPS continues from (not every dt: dense output)
        late = _from(t_grid, output_from)
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
            x = _compiled_segment(system, c, tpts, x, rtol, atol, h0, max_step, stats, ts, xs, segs, bar,
                                  t0 if bar_t0 is None else bar_t0, method)
        except KeyboardInterrupt as exc:
            raise Interrupted.of(exc, partial=_collect(c, ts, xs, segs, output_from) if ts else None) from None
        except SolverError as exc:  # its partial: the rows from output_from on, as the result's
            if exc.partial is not None and output_from is not None:
                exc.partial = _collect(c, ts, xs, segs, output_from)
            raise
    res = _collect(c, ts, xs, segs, output_from)
    from ..kernels.tableaus import DEFAULT
    res.stats = {**stats, "method": f"{(method or DEFAULT).upper()} (compiled)"}
    return res


#: steps per call of the compiled integrator: Python regains control (a signal is handled, the
#: series so far kept) at least this often; a run needing more steps continues from its last
#: output point (the output grid's times are kept)
PIECE_STEPS = 200_000
MAX_STEPS = 10_000_000  # per protocol segment, as the compiled integrator's own limit


def _compiled_segment(system, c, tpts, x, rtol, atol, h0, max_step, stats, ts, xs, segs, bar=None, t0=0.0,
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
        x, used = _compiled_range(system, c, P, tpts[a:b + 1], x, rtol, atol, h0, max_step, stats, ts, xs, segs,
                                  used, method)
        if bar is not None:
            bar.update_to(tpts[b] - t0)
        h0 = (tpts[b] - tpts[a]) / max(used - before, 1)
    return x


def _compiled_range(system, c, P, tpts, x, rtol, atol, h0, max_step, stats, ts, xs, segs, used, method=None):
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
            raise SolverError(f"compiled integrator failed: {st['message']}", time=st["t"],
                              state=c.state_dict(bad), partial=_collect(c, ts, xs, segs))
        return X[-1].copy(), used
