"""Periodic orbits by shooting: limit cycles (autonomous) and periodic steady states (forced).

Autonomous (e.g. the vasomotion limit cycle): unknowns (x0, T); equations
    phi_T(x0) - x0 = 0,   (x0 - x_s) . f(x_s) = 0   (phase: x0 on the section through x_s),
plus one row per conservation law (the conserved total is kept).  Newton with the monodromy
matrix M = d phi_T / d x0 from finite differences; the nx+1 perturbed trajectories are
integrated together as ONE vectorised batch.  Floquet multipliers are the eigenvalues of M:
one is 1 (the flow direction), one per conservation law is 1; the orbit is orbitally stable
when every other multiplier lies inside the unit circle.
Forced (a source with a sine term of frequency f): T = 1/f is fixed and phi_T(x0) = x0 gives
the periodic steady state directly instead of simulating many cycles.
The initial guess comes from a settling run (as in the envelope analysis).
Scaled coordinates (x / state_scale) keep states of very different size comparable.
"""
from __future__ import annotations

import numpy as np

from ..batch_integrator import integrate
from ..derivatives import dense_jacobian, flow_steps
from ..errors import HemocircuitError, SolverError
from ..provenance import clock, stamp
from ..results import Result


class PeriodicOrbit(Result):
    """One period of the orbit as a :class:`hemocircuit.results.Result` indexed by ``time`` [s]
    (401 points, both ends included), plus ``x0``, ``period``, ``x`` (states), ``multipliers``,
    ``converged``, ``iterations``, ``residual``, ``forced`` (measures also in ``metadata``)."""

    def __init__(self, x0, period, t, x, multipliers, converged, iterations, residual, forced, columns, units):
        super().__init__({"time": t, **columns}, {"time": "s", **units}, index=["time"])
        self.x0, self.period, self.x = x0, period, x
        self.multipliers, self.converged, self.iterations = multipliers, converged, iterations
        self.residual, self.forced = residual, forced
        self.n_laws = 0  # conserved quantities (each gives a trivial multiplier 1)

    @property
    def t(self):
        return self.data["time"]

    def time_average(self, name):
        """Mean of a column over the period (trapezoidal rule in time; the end point, equal to
        the start, is not counted twice)."""
        y, t = self[name], self.t
        return float(np.sum(0.5 * (y[1:] + y[:-1]) * np.diff(t)) / (t[-1] - t[0]))

    @property
    def nontrivial_multipliers(self):
        """Multipliers without the trivial ones (flow direction, conservation laws), by |mu|."""
        mu = np.array(sorted(self.multipliers, key=lambda z: -abs(z)))
        n_triv = 0 if self.forced else 1
        n_triv += self.n_laws
        # drop the n_triv multipliers closest to 1
        idx = np.argsort(np.abs(mu - 1.0))[:n_triv]
        return np.delete(mu, idx)

    @property
    def stable(self):
        """True / False; None when no multipliers were computed (shoot(multipliers=False))."""
        if self.multipliers.size == 0:
            return None
        nt = self.nontrivial_multipliers
        return bool(np.all(np.abs(nt) < 1.0))


ORBIT_POINTS = 401  # output points of one period of an orbit, both ends included
#: the period map's step-size rule: a rejection at least halves the step, which makes phi(x)
#: smoother in x than the transients' default (tableaus.CONTROLLERS: Anderson shooting of
#: closedLoopHeart_singleVessel from 16 starts, 6.25 periods on average against 7.0)
FLOW_CONTROLLER = "predictive-halving"


def _flow(circuit, X0, T, t0=0.0, rtol=1e-9, n_out=2):
    """phi over time T for a batch of starting states X0 (n, nx) of the SAME circuit."""
    n = X0.shape[0]
    bc = circuit if n == 1 else circuit.batch(n)
    grid = t0 + np.linspace(0.0, 1.0, n_out)[None, :] * np.atleast_1d(T)[:, None] * np.ones((n, 1))
    r = integrate(bc, X0, grid, rtol=rtol, atol=rtol, controller=FLOW_CONTROLLER)
    if not np.all(r.ok):
        raise SolverError(f"shooting integration failed: {[m for m in r.message if m][:1]}")
    return r.x[:, -1, :], r


def _laws(circuit):
    """Gradient rows of the conserved volumes (linear in the store volumes)."""
    rows = []
    x = np.zeros((1, circuit.nx))
    for k, _ in enumerate(circuit.law_specs):
        g = np.zeros(circuit.nx)
        for j in range(circuit.nx):
            e = np.zeros((1, circuit.nx))
            e[0, j] = 1.0
            g[j] = circuit.law_volumes(x + e)[k][0] - circuit.law_volumes(x)[k][0]
        rows.append(g)
    return np.array(rows).reshape(-1, circuit.nx)


def shoot(circuit, x_guess, T_guess, forced=False, rtol=1e-9, tol=1e-8, max_iter=25, rel_step=1e-6, progress=None,
          method="newton", memory=4, multipliers=True):
    """Shooting from (x_guess, T_guess).  Returns a PeriodicOrbit.  ``progress``: a bar
    of the iterations (with the residual) on stderr (:mod:`hemocircuit.progress`).

    ``method``: 'newton' (the monodromy by finite differences at every iteration: nx + 1
    periods integrated as one batch) or, for ``forced`` only, 'anderson': quasi-Newton
    shooting on x = phi_T(x) by Anderson acceleration (a multisecant Broyden update from the
    last ``memory`` periods; Walker & Ni, SIAM J. Numer. Anal. 49 (2011) 1715), one period per
    iteration and no monodromy.  A conserved volume is kept exactly (each update is an affine
    combination of phi values), unless the projection onto a hard limit moves a state it counts.  ``multipliers``: with 'anderson', compute the monodromy once
    at the orbit for the Floquet multipliers (nx + 1 periods); False leaves them empty.

    A Newton update that puts a state below its hard limit (a closed valve's flow below 0) is
    projected onto the limit: no state of the system lies below it, and from there the
    integration stops at t = 0 (before: "step size too small").  Without convergence the orbit
    is the iterate of smallest residual, not the last one: where Newton's iteration wanders
    (closedLoopHeart_singleVessel: residuals between 1e-4 and 1e-8, cause not found,
    docs/svzerod.md "Limitations") its last iterate may be far from its best."""
    from ..progress import bar
    if circuit.B != 1:
        raise HemocircuitError("periodic orbits are computed one parameter set at a time")
    with bar(max_iter, "shooting", unit="iteration", progress=progress) as b:
        if method == "anderson":
            if not forced:
                raise HemocircuitError("shooting method 'anderson' needs a forced orbit (fixed period); "
                                       "use method='newton' for a limit cycle")
            return _shoot_anderson(circuit, x_guess, float(T_guess), rtol, tol, max_iter, rel_step, memory,
                                   multipliers, b)
        if method != "newton":
            raise HemocircuitError(f"shooting method {method!r}: choose 'newton' or 'anderson'")
        return _shoot(circuit, x_guess, T_guess, forced, rtol, tol, max_iter, rel_step, b)


def _shoot_anderson(c, x_guess, T, rtol, tol, max_iter, rel_step, memory, multipliers, pbar):
    """Anderson-accelerated fixed-point shooting (type II, mixing 1): with f_k = (phi(x_k) - x_k)/S
    and g_k = phi(x_k)/S, x_{k+1} = S (g_k - dG gamma), gamma = argmin |f_k - dF gamma| over the
    differences of the last ``memory`` iterates.  The residual is max |f_k| (scaled, as Newton's)."""
    started = clock()
    S = c.state_scales
    limits = c.hard_limits()
    x = np.asarray(x_guess, dtype=float).copy()
    F, G = [], []
    best, converged = None, False
    for it in range(1, max_iter + 1):
        # each period on the orbit's output grid: the converged iterate's run is the orbit
        g, r = _flow(c, x[None], np.array([T]), rtol=rtol, n_out=ORBIT_POINTS)
        g = g[0]
        f = (g - x) / S
        res = float(np.max(np.abs(f)))
        pbar.update_to(it, residual=f"{res:.2e}")
        if best is None or res < best[0]:
            best = (res, x.copy(), r)
        if res < tol:
            converged = True
            break
        F.append(f)
        G.append(g / S)
        del F[:-(memory + 1)], G[:-(memory + 1)]
        if len(F) == 1:
            x = g
        else:
            dF = np.diff(np.array(F), axis=0).T
            dG = np.diff(np.array(G), axis=0).T
            gamma = np.linalg.lstsq(dF, F[-1], rcond=None)[0]
            x = (G[-1] - dG @ gamma) * S
        for li, bound, _ in limits:  # as Newton's updates: no state lies below its hard limit
            x[li] = max(x[li], bound)
    res, x, run = best
    M = None
    if multipliers:
        Mb, _ = dense_jacobian(lambda rows: _flow(c, rows, np.full(rows.shape[0], T), rtol=rtol)[0],
                               x[None], S, steps=flow_steps(S, rel_step))
        M = Mb[0]
    return _orbit(c, x, T, M, converged, it, res, True, len(c.law_specs), started, run=run,
                  settings={"forced": True, "method": "anderson", "memory": memory, "T_guess": T, "rtol": rtol,
                   "atol": rtol, "tol": tol, "max_iter": max_iter, "rel_step": rel_step})


def _shoot(circuit, x_guess, T_guess, forced, rtol, tol, max_iter, rel_step, pbar):
    started = clock()
    c = circuit
    nx = c.nx
    S = c.state_scales
    x0 = np.asarray(x_guess, dtype=float).copy()
    T = float(T_guess)
    x_s = x0.copy()
    f_s = c.rhs(0.0, x_s) * 1.0
    n_hat = (f_s / S) / max(np.linalg.norm(f_s / S), 1e-300)  # section normal, scaled
    L = _laws(c)
    limits = c.hard_limits()
    law0 = L @ x0 if L.size else np.zeros(0)
    res_norm = np.inf
    converged = False
    M = None
    best = None  # (residual, x0, T, M) of the best iterate
    for it in range(1, max_iter + 1):
        # monodromy d phi / d x0 by forward differences of the flow map (the derivatives
        # service; steps rel_step * scale, above the integrator's error), one batched run
        Mb, phi = dense_jacobian(lambda rows: _flow(c, rows, np.full(rows.shape[0], T), rtol=rtol)[0],
                                 x0[None], S, steps=flow_steps(S, rel_step))
        M, phi = Mb[0], phi[0]
        r_orbit = (phi - x0) / S
        rows = [r_orbit]
        J = [np.hstack([(M - np.eye(nx)) * (S[None, :] / S[:, None]), np.zeros((nx, 0 if forced else 1))])]
        if not forced:
            fT = c.rhs(T, phi) / S
            J[0][:, -1] = fT
            rows.append(np.array([n_hat @ ((x0 - x_s) / S)]))
            J.append(np.hstack([n_hat[None, :], np.zeros((1, 1))]))
        if L.size:
            rows.append((L @ x0 - law0) / 1.0)
            J.append(np.hstack([L * S[None, :], np.zeros((len(L), 0 if forced else 1))]))
        R = np.concatenate(rows)
        JJ = np.vstack(J)
        res_norm = float(np.max(np.abs(R)))
        pbar.update_to(it, residual=f"{res_norm:.2e}")
        if best is None or res_norm < best[0]:
            best = (res_norm, x0.copy(), T, M)
        if res_norm < tol:
            converged = True
            break
        dz = np.linalg.lstsq(JJ, -R, rcond=None)[0]
        x0 = x0 + dz[:nx] * S
        for li, bound, _ in limits:
            x0[li] = max(x0[li], bound)
        if not forced:
            T = T + dz[-1]
            if T <= 0:
                raise SolverError("shooting: the period became non-positive; give a better initial guess")
    if not converged and best is not None:
        res_norm, x0, T, M = best
    return _orbit(c, x0, T, M, converged, it, res_norm, forced, len(L), started,
                  settings={"forced": forced, "method": "newton", "T_guess": float(T_guess), "rtol": rtol, "atol": rtol,
                   "tol": tol, "max_iter": max_iter, "rel_step": rel_step})


def _orbit(c, x0, T, M, converged, it, res_norm, forced, n_laws, started, settings, run=None):
    """The PeriodicOrbit from its start x0: the integration of the orbit itself on
    ORBIT_POINTS (``run``, when already made from x0, else one more) and the multipliers of the
    monodromy M (none when M is None)."""
    r = run if run is not None else _flow(c, x0[None], np.array([T]), rtol=settings["rtol"], n_out=ORBIT_POINTS)[1]
    t = r.t[0]
    xs = r.x[0]
    cols = c.outputs(t, xs)
    orb = PeriodicOrbit(x0, T, t, xs, np.linalg.eigvals(M) if M is not None else np.zeros(0), converged, it,
                        res_norm, forced, cols, c.column_units())
    orb.n_laws = n_laws
    orb.metadata["measures"] = {"period": T, "converged": converged, "method": settings["method"],
                                "iterations": it, "residual": res_norm,
                                "nontrivial_multipliers": orb.nontrivial_multipliers,
                                "orbitally_stable": orb.stable}
    return stamp(orb, "periodic", c, settings, started)


def periodic_start(c, ic=None, rtol=1e-9):
    """(state, orbit): the periodic steady state of ``c``'s own period (its periodic waveforms
    and chambers; svzerod.cycles.time_period) at phase 0, by Anderson-accelerated shooting from
    :func:`start_state`, for a run that starts on it (``tran --periodic-start``).  A SolverError
    when the shooting does not converge."""
    from ..svzerod.cycles import time_period
    from .transient import start_state

    T = time_period(c)
    orb = shoot(c, start_state(c, 0.0, None, ic), T, forced=True, rtol=rtol, method="anderson", multipliers=False)
    if not orb.converged:
        raise SolverError(f"--periodic-start: the shooting for the periodic state (period {T:g} s) did not "
                          f"converge in {orb.iterations} periods (residual {orb.residual:.3g}); start from the "
                          "operating point and run longer instead, or see 'hemocircuit periodic --forced'")
    return orb.x0, orb


def guess_from_run(circuit, output=None, t_settle=400.0, dt=0.05, kick=1e-3, rtol=1e-6):
    """(x on an upward mean crossing of ``output``, period estimate) from a settling run
    (a single run: the scipy LSODA transient is the faster integrator for one member).
    ``output`` defaults to the first of the netlist's ``outputs:`` for 'periodic'."""
    from ..outputs import default_outputs
    from .op import operating_point
    from .envelope import law_states, period_of
    if output is None:
        output = default_outputs(circuit, "periodic")[0]
    op = operating_point(circuit)
    x0 = np.array(op.x, dtype=float)
    free = [j for j in range(circuit.nx) if j not in law_states(circuit)]
    x0[free] += kick * circuit.state_scales[free]
    res = circuit.simulate(t_settle, dt=dt, x0=x0, method="LSODA", rtol=rtol, atol=rtol)
    grid = res.t
    n_win = len(grid) // 3
    X = res.x[-n_win:]
    y = res[output][-n_win:]
    if np.ptp(y) < 1e-6 * max(abs(np.mean(y)), 1e-300):
        raise SolverError(f"no oscillation of {output} after {t_settle:g} s: the equilibrium is stable here "
                          "(nothing to shoot for); see 'hemocircuit stability'")
    T = period_of(grid[-n_win:], y)
    z = y - y.mean()
    up = np.nonzero((z[:-1] < 0) & (z[1:] >= 0))[0]
    return X[up[-1] + 1], T


def register_cli(sub, common):
    sp = common(sub.add_parser("periodic", help="limit cycle (or forced periodic steady state) by shooting"),
                outputs=False)
    sp.add_argument("--output", help="output used to find the period (default: the first of the netlist's "
                                     "'outputs:' for periodic)")
    sp.add_argument("--t-settle", type=float, default=400.0, help="settling run for the initial guess, s")
    sp.add_argument("--forced", nargs="?", const="", metavar="SOURCE",
                    help="periodic steady state of a forced circuit: alone, at the period of the circuit's own "
                         "time dependence (periodic waveforms, chambers: an svZeroDSolver model's cardiac period), "
                         "with the cycles their cycle-to-cycle criterion needs; with SOURCE (a source with a "
                         "built-in sine term) at its frequency")
    sp.add_argument("--cycle-tol", type=float,
                    help="tolerance of the cycle-to-cycle criterion for --forced (default: an svZeroDSolver "
                         "model's sim_cycle_to_cycle_percent_error/100, else 0.01)")
    sp.add_argument("--out", help="CSV of one period of the orbit (or .json)")
    sp.add_argument("--plot", help="PNG of the orbit")
    sp.set_defaults(func=cmd_periodic)


def _periodic(args, c):
    """The orbit (converged or not) and the output that found its period."""
    from ..outputs import default_outputs, drive_of, input_element

    if args.forced == "":
        # without --output or declared outputs: the quantities the cycle criterion watches
        # (an svZeroDSolver model's vessel caps), a pressure first
        interest = default_outputs(c, "periodic", required=False)
        orb = _forced_by_period(args, c, args.output)
        watched = list(orb.metadata["measures"].get("cycle_quantities") or [])
        interest = interest or sorted(watched, key=lambda k: not k.startswith("P("))
        if args.output is None and not interest:
            default_outputs(c, "periodic", required=True)  # the error naming the netlist
        return orb, args.output or interest[0], interest
    interest = default_outputs(c, "periodic", required=args.output is None)
    output = args.output or interest[0]
    if args.forced:
        src = input_element(c, args.forced)
        comp, drive = drive_of(c, src)
        if not drive.has_sine:
            raise HemocircuitError(f"--forced {src}: a '{comp.type_name}' has no built-in sine term")
        amp, freq = f"{src}.{drive.amplitude}", f"{src}.{drive.frequency}"
        f = float(c.parameters.values[freq][0])
        if f <= 0 or float(c.parameters.values[amp][0]) == 0:
            raise HemocircuitError(f"--forced {src}: give it a sine term (--set {amp}=..., {freq}=...)")
        from .op import operating_point
        c0 = c.with_values({amp: 0.0})
        orb = shoot(c, operating_point(c0).x, 1.0 / f, forced=True)
    else:
        x, T = guess_from_run(c, output, args.t_settle)
        orb = shoot(c, x, T)
    y = orb[output]
    orb.metadata["measures"].update({f"min({output})": float(y.min()), f"max({output})": float(y.max()),
                                     f"time_average({output})": orb.time_average(output)})
    return orb, output, interest


def forced_periodic_report(circuit, x_start, period, quantities=None, N=101, tol=None, rtol=1e-9,
                           max_cycles=500):
    """The periodic steady state by shooting from ``x_start`` with the circuit's period, its
    Floquet multipliers, and how many cycles cycle-by-cycle integration from the same start
    needs to meet their criterion (svzerod.cycles; ``tol`` None: their default 1 %), measured and
    predicted from the dominant multiplier.
    Returns the PeriodicOrbit; the cycle figures are added to ``metadata['measures']``.

    Anderson-accelerated shooting (``shoot(method='anderson')``), the multipliers from one
    monodromy at its orbit: on their pulsatile models it converges where Newton shooting
    wanders or diverges (closedLoopHeart_singleVessel: 7 periods to 7.7e-9 against Newton's 25
    iterations stopping at 5.8e-8; piecewise_Chamber_and_Valve 3.0e-7 against 3.2e2 after 25)."""
    from ..svzerod.cycles import DEFAULT_TOL, cycles_to_criterion, default_quantities, predicted_cycles

    tol = DEFAULT_TOL if tol is None else tol
    orb = shoot(circuit, x_start, period, forced=True, rtol=rtol, method="anderson")
    if quantities is None:
        quantities = default_quantities(circuit, orb.columns)
    mu = orb.nontrivial_multipliers
    mu_dom = complex(mu[np.argmax(np.abs(mu))]) if len(mu) else 0.0
    n, errs = cycles_to_criterion(circuit, x_start, period, quantities, N=N, tol=tol, max_cycles=max_cycles)
    first = float(errs[0]) if len(errs) else None
    orb.metadata["measures"].update({
        "dominant_multiplier": abs(mu_dom), "cycle_tolerance": tol,
        "cycles_measured": n, "cycle_errors": [float(e) for e in errs],
        "cycles_predicted": predicted_cycles(mu_dom, tol, first),
        "cycles_log_tol_over_log_mu": predicted_cycles(mu_dom, tol),
        "cycle_quantities": list(quantities)})
    return orb


def _forced_by_period(args, c, output):
    """--forced without a source: the circuit's own period (svzerod.cycles.time_period); an
    svZeroDSolver model watches their vessel caps with their N points per cycle and starts as
    their run does (hemocircuit.svzerod.output.start_state)."""
    from ..svzerod import cycles

    T = cycles.time_period(c)
    svz = _svzerod_model(args.netlist, getattr(args, "svzerod_units", None))
    if svz is not None:
        model, cfg = svz
        from ..arguments import parse_sets
        from ..svzerod.output import start_state
        x0 = start_state(model, c, sets=parse_sets(getattr(args, "set", None)))
        quantities = [col for _, q, p in cycles.vessel_caps(cfg, model) for col in (q, p)]
        N, tol = model.points, cycles.their_tolerance(model.sim)
    else:
        from .op import operating_point
        x0, quantities, N, tol = operating_point(c).x, None, 101, cycles.DEFAULT_TOL
    if args.cycle_tol is not None:
        tol = args.cycle_tol
    orb = forced_periodic_report(c, x0, T, quantities, N=N, tol=tol)
    if svz is not None:  # their up-front count with RCR boundary conditions (their eq. 21)
        taus = cycles.rcr_time_constants(c)
        orb.metadata["measures"]["cycles_their_rcr_rule"] = cycles.pfaller_cycles(taus, T, tol)
    return orb


def _svzerod_model(path, units=None):
    """(SvzModel, their config) when ``path`` is an svZeroDSolver JSON model, else None;
    ``units``: --svzerod-units (default the importer's guess)."""
    import os

    if not str(path).endswith(".json"):
        return None
    from ..inputs import read_json
    from ..svzerod.importer import import_svzerod, is_svzerod_model
    cfg = read_json(path, "svZeroDSolver model file")  # under the input policy, as the netlist's first read
    if not is_svzerod_model(cfg):
        return None
    return import_svzerod(cfg, units=units, name=os.path.splitext(os.path.basename(str(path)))[0], source=path), cfg


def compute_periodic(args, sets):
    """One --grid member (:func:`hemocircuit.commands.computed`)."""
    from ..commands import circuit_of_args
    return _periodic(args, circuit_of_args(args, sets)[0])[0]


def cmd_periodic(args):
    from ..commands import computed, load_args, report_grid, save_outputs

    if args.grid:
        return report_grid(args, computed(args, compute_periodic))
    orb, output, interest = _periodic(args, load_args(args)[0])
    y = orb[output]
    print(f"{'converged' if orb.converged else 'NOT converged'} after {orb.iterations} iterations of "
          f"{orb.metadata['measures']['method'].capitalize()} shooting "
          f"(residual {orb.residual:.2e}); period {orb.period:.6g} s")
    print(f"{orb.label(output)}: min {y.min():.6g}, max {y.max():.6g}, time average {orb.time_average(output):.6g}")
    mu = orb.nontrivial_multipliers
    print("Floquet multipliers (non-trivial): " + ", ".join(f"{m:.4g}" for m in mu))
    print("orbitally stable" if orb.stable else "orbitally UNSTABLE")
    m = orb.metadata["measures"]
    if "cycles_measured" in m:
        print(f"x(T) - x(0): {orb.residual:.2e} (scaled); cycle-by-cycle integration from the same start meets the "
              f"cycle-to-cycle criterion (relative change of cycle means <= {m['cycle_tolerance']:g}) after "
              f"{m['cycles_measured']} cycles; predicted from |mu| = {m['dominant_multiplier']:.4g}: "
              f"{m['cycles_predicted']} (log(tol)/log|mu|: {m['cycles_log_tol_over_log_mu']})")
        if m.get("cycles_their_rcr_rule") is not None:
            print(f"svZeroDSolver with use_cycle_to_cycle_error runs {m['cycles_their_rcr_rule']} cycles here "
                  "(ceil(-tau_max/T ln tol), tau = Rd C of its RCR boundary conditions)")
    select = [output] + [k for k in interest if k in orb.columns and k != output]
    save_outputs(args, orb, plot=lambda path: orb.plot(path, select=select, title="periodic orbit"))
