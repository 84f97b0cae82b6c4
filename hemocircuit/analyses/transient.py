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

from .. import plausibility
from ..errors import Interrupted, SolverError
from ..protocol import Protocol
from ..provenance import clock, stamp
from .compiled_run import TransientResult, collect, from_time, output_grid, simulate_compiled  # noqa: F401 (TransientResult: its public home)


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
        component types is not built yet (its first run; building takes about 45-55 s on 2 cores):
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
        # the run started on the operating point: its first row (when written) is that state
        start = res.x[0] if res.n_rows and res.t[0] == t0 else None
        unstable = _unstable_start(protocol.apply_initial(circuit) if protocol is not None else circuit, t0, start)
        if unstable:
            res.metadata.setdefault("warnings", []).append(unstable)
    return stamp(res, "tran", circuit, settings, started)


#: states up to which a run from the operating point checks that equilibrium's stability
#: (a dense eigen-decomposition: cheap below this size)
UNSTABLE_CHECK_STATES = 300


def _unstable_start(c, t0, x=None):
    """A warning when a run starting unperturbed on the operating point (``x``, when the run
    has it; computed otherwise) starts on an unstable equilibrium: without a perturbation it
    stays there up to round-off (a flat line where a limit cycle was expected).  None
    otherwise, and for circuits above UNSTABLE_CHECK_STATES."""
    from .op import operating_point
    from .stability import eigenvalues

    if not 0 < c.nx <= UNSTABLE_CHECK_STATES:
        return None
    try:
        lam = eigenvalues(c, operating_point(c, t=t0).x if x is None else x, t=t0)
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
        print(f"hemocircuit: compiling the engine for these component types (their first run; about 15 s on 2 cores, "
              f"cached in {cache_dir()} for every later run)", file=sys.stderr, flush=True)


def start_state(c, t0=0.0, x0=None, ic=None):
    """The state a run of ``c`` starts from at t0: ``x0``, or the operating point, with the
    netlist's ic (from the operating point only) and then ``ic`` state by state over it; an ic
    naming every state is the whole start (no operating point is computed)."""
    from ..ic import apply_ic, names_every_state
    from .op import operating_point

    ic = {**(c.netlist.ic if x0 is None else {}), **(ic or {})}
    if x0 is not None:
        x = np.asarray(x0, dtype=float).copy()
    else:
        x = np.zeros(c.nx) if names_every_state(c, ic) else operating_point(c, t=t0).x
    return apply_ic(c, x, ic) if ic else x


def _simulate(circuit, t_end, dt, t0, x0, protocol, method, rtol, atol, max_step, first_step, engine, ic,
              progress=None, compile="wait", output_from=None, compiled_method=None):
    from ..progress import bar, wanted

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
    x = start_state(c, t0, x0, ic)
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
                          "background (first run, about 45-55 s on 2 cores); integrating on the scipy path meanwhile",
                          file=sys.stderr)
            else:
                with bar(t_end - t0, "tran (simulated time)", unit="s", progress=progress) as pbar:
                    res = simulate_compiled(system, c, x, t0, t_end, dt, events, rtol, atol, max_step, first_step,
                                             pbar, output_from=output_from, method=compiled_method)
                background.mark_ready(system)
                return res
    ts, xs, segs = [], [], []
    nfev = njev = nsteps = 0
    t_grid = None if dt is None else from_time(np.arange(t0, t_end + 0.5 * dt, dt), output_from)
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

        from scipy.integrate import solve_ivp  # (0.8 s of imports: only the scipy path needs it)

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
        return collect(c, ts, xs, segs, output_from)

    bounds = [t0] + [e[0] for e in events] + [t_end]
    compiled = None
    try:
        switch = _scipy_segments(c, x, bounds, events, limits, one_segment, ts, xs, segs, handover, t_grid,
                                 partial=_partial)
        if switch is not None:  # the background build is ready: the rest on the compiled engine
            k, t_s, x_s, c_k = switch
            compiled = simulate_compiled(c_k.system.compiled(), c_k, x_s, t_s, t_end, dt, events[k:], rtol, atol,
                                          max_step, first_step, pbar, t_grid=output_grid(t0, t_end, dt),
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
    res = collect(segs[-1] if segs else c, ts, xs, segs, output_from,
                   grid=None if dt is None else output_grid(t0, t_end, dt))
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


#: a run on the scipy path stops as stalled after this many pieces in a row that a hard limit
#: ended within STALL_ADVANCE [s] of their start: solve_ivp cannot hold a state on its bound
#: while its rate points outward (a closed valve's flow at 0: the integrator's iterates dip
#: below, the limit fires again at once), and the restarts would go on for hours.  While the
#: compiled engine builds in the background (a handover) the run waits for it instead
STALL_RESTARTS = 200
STALL_ADVANCE = 1e-6


def _scipy_segments(c, x, bounds, events, limits, one_segment, ts, xs, segs, handover=None, t_grid=None,
                    partial=None):
    """Integrate the protocol segments (solve_ivp), appending to ts, xs, segs.  With a
    ``handover`` (:class:`_Handover`), in pieces: returns (segment index, time, state,
    circuit) where the compiled engine is to go on, or None when the scipy path finished.
    ``partial()``: the rows so far, kept with a stall's error."""
    import time

    stuck = 0
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
                    stuck = stuck + 1 if cur - (sol.t[0] if sol.t.size else cur) < STALL_ADVANCE else 0
                    if stuck >= STALL_RESTARTS and handover is None:  # (a build under way takes over)
                        raise SolverError(
                            f"integration stalled at t = {cur:.6g} s: the hard limit {c.state_names[idx]} >= {bound:g} "
                            f"was reached again at once after each of {STALL_RESTARTS} restarts (scipy's integrators "
                            "cannot hold a state on its bound, e.g. a closed valve's flow); run on the compiled "
                            "engine (--integrator rodas5p, simulate(integrator='rodas5p')), which holds it there",
                            time=cur, state=c.state_dict(x), partial=partial() if partial else None)
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


