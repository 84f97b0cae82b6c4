"""svZeroDSolver's ``steady_initial`` procedure, as an option (hemocircuit's default start is the
true operating point, found by Newton).

Theirs (SimVascular/svZeroDSolver src/solve/Solver.cpp ``setup_initial``): from their initial
condition (``initial_condition``, 0 where not given, derivatives 0) the model with every time
series at its mean (``Model::to_steady``: Parameter::to_steady, and the capacitance of every
RCR and ClosedLoopRCR set to 0, OpenLoopCoronaryBC switched to its steady equations
P_in = (Ra + Ram + Rv) Q_in + P_v, V_im = 0) takes 31 generalized-alpha steps of T/10
(src/algebra/Integrator.cpp), step i from t = i T/10, evaluated at t + alpha_f h, with their
``rho_infty`` (0.5 by default).  So it is 3.1 cardiac periods of pseudo-time, not a steady
state: vessel capacitors, inductors and chambers (whose activation keeps running on that
pseudo-time) are still relaxing at its end.

Here the same scheme is applied to hemocircuit's ODE form x' = f(t, x) of the time-averaged
circuit, compiled (the engine's gen_alpha_run): per step the predictor x_{n+1} = x_n,
x'_{n+1} = (1 - 1/gamma) x'_n, then Newton on
x'_{n+alpha_m} = f(t_n + alpha_f h, x_{n+alpha_f}) with x_{n+1} = x_n + h (x'_n + gamma (x'_{n+1} - x'_n)),
alpha_m = (3 - rho)/(2 (1 + rho)), alpha_f = 1/(1 + rho), gamma = 1/2 + alpha_m - alpha_f
(their Integrator constructor).  Their zero capacitances make those variables algebraic; here
the capacitances of rcr_bc, closed_loop_rcr (C) and coronary_bc (Ca, Cc) are scaled by
EPS = 1e-9 for the procedure (a mode of time constant ~EPS tau, which the scheme damps like an
algebraic variable: by -rho per step) and their volume states scaled back at the end, so the
pressures they carry are kept.  Their algebraic variables are not states here, so only the
states are taken from the procedure.
"""
from __future__ import annotations

import numpy as np

from ..errors import HemocircuitError, SolverError

EPS = 1e-9
STEPS = 31  # Solver.cpp setup_initial


def gen_alpha_coefficients(rho):
    """(alpha_m, alpha_f, gamma) of their first-order generalized-alpha scheme."""
    am = 0.5 * (3.0 - rho) / (1.0 + rho)
    af = 1.0 / (1.0 + rho)
    return am, af, 0.5 + am - af


#: gen_alpha_run's failure codes
_FAILURES = {1: "Newton did not converge in {max_iter} iterations", 2: "no Newton step reduces the residual",
             3: "a state became non-finite",
             4: "the right-hand side or its Jacobian failed (a singular or non-converging nodal system)"}


def gen_alpha_steps(c, x0, h, n_steps, rho=0.5, t0=0.0, max_iter=30, tol=1e-11):
    """``n_steps`` generalized-alpha steps of size h [s] of x' = f(t, x) (circuit ``c``) from x0
    with x'(0) = 0, as their Integrator::step: one call of the compiled engine's
    ``gen_alpha_run`` (Newton with its Jacobian and a halving line search, the convergence test
    max |r| h / scale < tol or the last update below tol).  Returns the final state."""
    from ..kernels.system import CompiledSystem

    x = np.array(x0, float)
    if x.size == 0:  # no states: nothing relaxes
        return x
    system = CompiledSystem.of(c)
    if system is None:
        raise HemocircuitError("their steady_initial runs on the compiled engine: this circuit has a component "
                               "type without a kernel (docs/components.md)")
    am, af, gamma = gen_alpha_coefficients(rho)
    P = system.params(c)[0]
    x, status, step = system.mod.gen_alpha_run(x, float(h), int(n_steps), am, af, gamma, float(t0), P,
                                               system.lay_for(P)[0], system.scales, int(max_iter), float(tol))
    if status:
        t = t0 + (step + af) * h
        raise SolverError(f"their steady_initial: {_FAILURES[int(status)].format(max_iter=max_iter)} in pseudo-time "
                          f"step {step} (t = {t:g} s)", time=t)
    return x


def their_initial(model, circuit):
    """Their initial_condition as {ID.STATE: value} for the states ``circuit`` has (the
    importer's index reduction removes a capacitor under a PRESSURE or an inductor in series
    with a FLOW: the source fixes those)."""
    return {k: v for k, v in model.initial.items() if k in circuit.state_names}


def their_steady_initial(model, mean_circuit):
    """The state their steady_initial procedure gives for an imported ``model``
    (:class:`~hemocircuit.svzerod.model.SvzModel`), on ``mean_circuit`` (the circuit of
    ``model.mean_netlist``).  Their cardiac period T, ``rho_infty`` from their
    simulation_parameters."""
    from ..ic import apply_ic
    from ..registry import get_type

    cm = mean_circuit
    if model.closed:
        raise HemocircuitError("their steady_initial does not apply to a closed loop (their Solver.cpp rejects it "
                               "with ClosedLoopHeartAndPulmonary); it starts from its initial_condition")
    rho = float(model.sim.get("rho_infty", 0.5))
    changes, scaled = {}, []
    for e in model.netlist["elements"]:
        # the capacitances their to_steady removes and the volume states they carry: the type's
        # own declaration, as for svzerod_blocks (coronary_var_res_bc, a subclass of coronary_bc,
        # declares none: their steady form of it also fixes Ram at Ra2_min, which this does not)
        params, states = vars(get_type(e["type"])).get("svzerod_steady_zeroed", ((), ()))
        for p in params:
            path = f"{e['id']}.{p}"
            changes[path] = float(cm.parameters.values[path][0]) * EPS
        scaled += [cm.state_names.index(f"{e['id']}.{s}") for s in states]
    x0 = apply_ic(cm, np.zeros(cm.nx), their_initial(model, cm))
    x0[scaled] *= EPS
    c0 = cm.with_values(changes) if changes else cm
    x = gen_alpha_steps(c0, x0, model.period / 10.0, STEPS, rho)
    x[scaled] /= EPS
    return x
