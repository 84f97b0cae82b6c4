"""Cycle-to-cycle convergence: svZeroDSolver's criterion, how many cycles it needs, and the
period of a model's time dependence (for the periodic steady state by shooting).

Their criterion (SimVascular/svZeroDSolver src/solve/Solver.cpp, ``use_cycle_to_cycle_error``,
``sim_cycle_to_cycle_percent_error`` (default 1 %) / 100 = tol):
  * quantities: flow and pressure at every vessel cap (``get_vessel_caps_dof_indices``: the
    inlet node of a vessel with only an inlet boundary condition, else the outlet node of a
    vessel with an outlet one; their create_vessels marks a vessel with both as ``outlet``);
  * the mean of each over a cycle is the plain mean of its N samples i = 0 .. N-1 (both ends
    of the cycle: ``get_cycle_to_cycle_errors_in_flow_and_pressure``);
  * error = |mean(last) - mean(previous)| / |mean(previous)|; converged when every error is
    <= tol (``check_vessel_cap_convergence``).
  * With an RCR boundary condition they do not test it: the number of cycles is set up front
    to ceil(-tau_max / T ln tol), tau = Rd C the largest RCR time constant (their "equation 21
    of Pfaller 2021"), and only the errors of the last two cycles are printed.
For a linear(ised) model the deviation from the periodic state shrinks by the dominant Floquet
multiplier mu per cycle (mu = exp(-T/tau) for one RCR), so cycle k's error is about
E_1 |mu|^(k-2) (E_1: cycles 1 vs 2) and the criterion needs n ~ 2 + log(tol/E_1)/log|mu|
cycles; their eq. 21 is log(tol)/log|mu| with mu = exp(-T/tau).
"""
from __future__ import annotations

import math

import numpy as np

from ..errors import HemocircuitError

DEFAULT_TOL = 0.01  # their default sim_cycle_to_cycle_percent_error 1 %


def their_tolerance(sim):
    """tol of their criterion from their simulation_parameters (percent / 100)."""
    return float(sim.get("sim_cycle_to_cycle_percent_error", 100.0 * DEFAULT_TOL)) / 100.0


def vessel_caps(cfg, model):
    """[(their cap label, flow column, pressure column)] of their vessel caps, in their order."""
    out = []
    for v in cfg.get("vessels") or []:
        bc, n = v.get("boundary_conditions") or {}, v["vessel_name"]
        if "outlet" in bc:  # 'outlet' also for a vessel with both (their create_vessels)
            out.append((f"{n}:outlet", model.columns[f"{n}:flow_out"], model.columns[f"{n}:pressure_out"]))
        elif "inlet" in bc:
            out.append((f"{n}:inlet", model.columns[f"{n}:flow_in"], model.columns[f"{n}:pressure_in"]))
    return out


def rcr_time_constants(circuit):
    """The time constants [s] their cycle count takes (Component.cycle_time_constants: Rd C of
    every RCR boundary condition) of a circuit's first parameter set, as it is (``--set``
    included)."""
    out = []
    for g, p in zip(circuit.groups, circuit.group_params()):
        tau = g.comp.cycle_time_constants(p)
        if tau is not None:
            out += [float(v) for v in np.reshape(tau, (-1, len(g.ids)))[0]]
    return out


def pfaller_cycles(taus, period, tol):
    """Their up-front cycle count with RCR boundary conditions (time constants ``taus`` [s]),
    ceil(-tau_max/T ln tol), or None without one (Solver.cpp constructor)."""
    if not taus:
        return None
    n = -max(taus) / period * math.log(tol)
    if not math.isfinite(n) or n > 1e15:
        raise HemocircuitError(f"use_cycle_to_cycle_error: their cycle count ceil(-tau/T ln tol) is {n:g} for the "
                               f"RCR time constant tau = {max(taus):g} s, period T = {period:g} s, tol = {tol:g}: "
                               "check the RCR's Rd and C (tau = Rd C) or turn use_cycle_to_cycle_error off")
    return max(1, int(math.ceil(n)))


def cycle_means(y, N):
    """Means of a series sampled N points per cycle ((N-1) k + 1 samples): cycle j's mean over
    its samples (N-1) j .. (N-1) (j+1), both ends included (theirs)."""
    y = np.asarray(y, float)
    k = (y.size - 1) // (N - 1)
    idx = (N - 1) * np.arange(k)[:, None] + np.arange(N)[None, :]
    return y[idx].mean(axis=1)


def cycle_errors(means):
    """Relative change of consecutive cycle means: (n_cycles - 1,) per quantity (last axis)."""
    m = np.atleast_2d(np.asarray(means, float))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.abs((m[:, 1:] - m[:, :-1]) / m[:, :-1])


def cycles_to_criterion(circuit, x0, period, quantities, N=101, tol=DEFAULT_TOL, max_cycles=500, chunk=10,
                        rtol=1e-8):
    """Run cycles plainly from x0 (chunks of ``chunk`` cycles) until their criterion holds for
    every output column in ``quantities``: returns (n, errors) with n the number of cycles
    simulated when the relative change of every cycle mean between cycles n-1 and n is <= tol,
    and errors (n-1,) the worst quantity's error after each cycle.  Raises when max_cycles do
    not suffice."""
    from ..analyses.transient import simulate

    dt = period / (N - 1)
    x = np.asarray(x0, float)
    means = []
    for start in range(0, max_cycles, chunk):
        k = min(chunk, max_cycles - start)
        t0 = start * period
        res = simulate(circuit, t0 + k * period, t0=t0, dt=dt, x0=x, rtol=rtol, progress=False)
        cols = res.columns
        m = np.array([cycle_means(cols[q], N) for q in quantities])  # (q, k)
        x = np.asarray(res.x[-1])
        means.append(m)
        allm = np.concatenate(means, axis=1)
        errs = np.nanmax(cycle_errors(allm), axis=0)
        ok = np.nonzero(errs <= tol)[0]
        if ok.size:
            n = int(ok[0]) + 2  # errs[j] compares cycles j+1 and j+2 (counted from 1)
            return n, errs[:n - 1]
    raise HemocircuitError(f"their cycle-to-cycle criterion (tol {tol:g}) not met in {max_cycles} cycles")


def predicted_cycles(mu, tol, first_error=None):
    """Cycles their criterion needs from the dominant Floquet multiplier mu.  With E_1, the
    criterion's error between cycles 1 and 2 (cycle j+1 vs j+2 is then ~E_1 |mu|^j):
    2 + ceil(log(tol/E_1)/log|mu|) (2 when E_1 <= tol: the criterion compares two cycles);
    without it, ceil(log(tol)/log|mu|) (their eq. 21's form: a deviation of relative size 1)."""
    a = abs(complex(mu))
    if a >= 1.0:
        return math.inf
    if first_error is None:
        return 1 if a == 0.0 else max(1, int(math.ceil(math.log(tol) / math.log(a))))
    if first_error <= tol:
        return 2
    if a == 0.0:
        return 3
    return 2 + int(math.ceil(math.log(tol / first_error) / math.log(a)))


def time_period(circuit):
    """The period [s] of a circuit's time dependence: that of its periodic waveforms (their
    time series) and of the elements with a ``period`` parameter (chambers, the heart), which
    must all agree; a non-periodic waveform (a table or steps without ``periodic``) is an error."""
    from ..waveforms import Constant, Periodic, Sine, Sum

    found = {}

    def visit(wf, where):
        if isinstance(wf, Constant):
            return
        if isinstance(wf, Periodic):
            found[where] = float(wf.period)
        elif isinstance(wf, Sine) and wf.start <= 0.0 and wf.frequency > 0:
            found[where] = 1.0 / float(wf.frequency)
        elif isinstance(wf, Sum):
            for p in wf.parts:
                visit(p, where)
        else:
            raise HemocircuitError(f"{where}: its waveform ({type(wf).__name__.lower()}) is not periodic; "
                                   "give it as {periodic: {period: T, pwl: ...}} or a sine")

    for g in circuit.groups:
        for i, name, wf in g.waves:
            visit(wf, f"{g.ids[i]}.{name}")
        if "period" in g.comp.parameters and g.comp.time_dependent:
            for eid in g.ids:
                found[f"{eid}.period"] = float(circuit.parameters.values[f"{eid}.period"][0])
    if not found:
        raise HemocircuitError("the circuit has no periodic time dependence (no periodic waveform, no element "
                               "with a period); name a source with a sine term: --forced SOURCE")
    periods = sorted(set(found.values()))
    if periods[-1] - periods[0] > 1e-9 * periods[-1]:
        raise HemocircuitError("the circuit's time dependence has several periods: " +
                               ", ".join(f"{k} {v:g} s" for k, v in found.items()))
    return periods[-1]


def default_quantities(circuit, orbit_columns):
    """Outputs a cycle-to-cycle criterion watches on a circuit that is not an svZeroDSolver model:
    every node pressure, and every element flow whose mean over the orbit is not ~0 (a
    relative criterion is meaningless there)."""
    P = [k for k in orbit_columns if k.startswith("P(")]
    Q = [k for k in orbit_columns if k.startswith("Q(")]
    qm = {k: abs(float(np.mean(orbit_columns[k]))) for k in Q}
    big = max(qm.values(), default=0.0)
    return P + [k for k in Q if qm[k] > 1e-6 * big and qm[k] > 0]
