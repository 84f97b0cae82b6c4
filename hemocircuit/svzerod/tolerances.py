"""The tolerances a svZeroDSolver case is compared and integrated at (the conformance runner
and ``tran --svzerod-output`` share them): the acceptance rules per case, the integrator's rtol,
and for a case whose run does not forget its start (a mode slower than the run) the drift
tolerances and the start by their procedure.
"""
from __future__ import annotations

import numpy as np

from ..errors import HemocircuitError

VALVE_CHAMBER_TYPES = {"ValveTanh", "PiecewiseValve", "ChamberElastanceInductor", "LinearElastanceChamber",
                       "ChamberSphere", "ClosedLoopRCR", "ClosedLoopHeartAndPulmonary", "ClosedLoopCoronaryLeft",
                       "ClosedLoopCoronaryRight"}


def tolerances(name, model):
    """(pressure tol, flow tol) of the issue's acceptance rules for this case."""
    if set(model.block_types) & VALVE_CHAMBER_TYPES:
        return 1e-2, 2e-2
    if name == "pulsatileFlow_CRL":
        return 2e-2, 2e-2
    steady = all(not isinstance(v, dict) for e in model.netlist["elements"] for v in e.values())
    return (1e-6, 1e-6) if steady else (1e-3, 1e-3)


def case_rtol(model):
    """Integrator tolerance appropriate to the comparison (errors relative to a variable's
    range): 1e-8 for the steady cases (compared at 1e-6; they start at the operating point),
    1e-5 for the simple pulsatile ones (compared at 1e-3: the integration error is then ~1e-6 of
    the range, with the engine's default method RODAS5P), 1e-6 with valves, chambers or the
    closed-loop heart (compared at 1e-2): there every state, the heart's own valve flows
    included, is within 8.4e-3 of its range of a rtol 1e-10 run (closedLoopHeart_singleVessel's
    mitral flow, where the valve events shift; 6.3e-3 at 1e-7, which takes 1.9x longer; 1.6e-2
    at 1e-5), docs/svzerod.md "Speed".  A case that keeps its start is integrated at
    DRIFT_RTOL and :func:`drift_atol` instead (:func:`simulate_case`)."""
    if set(model.block_types) & VALVE_CHAMBER_TYPES:
        return 1e-6
    return 1e-8 if tolerances(model.name, model)[0] <= 1e-6 else 1e-5


#: integrator tolerances of a case that does not forget its start (:func:`keeps_its_start`):
#: its written cycle carries the drift of every cycle before it (chamber_elastance_inductor:
#: Vc moves 1.1e-5 mL per cycle against a range of 0.002 mL in the last one, while Vc itself
#: is 96 mL, so rtol |Vc| is no useful bound: at rtol 1e-5 .. 1e-8 each opening and closing
#: of its inflow valve left an error of ~9e-7 and ~6e-7 mL that the error estimate did not see,
#: 1.5e-6 mL per cycle, 2 % of the range after 30 cycles).  Absolute tolerances per unit of
#: state scale (:func:`drift_atol`): DRIFT_ATOL on the states the slow modes move (the
#: drift), DRIFT_ATOL_OTHERS on the rest, which forget their errors within a cycle
#: (chamber_elastance_inductor: 1e-8 on every state took 6 942 steps and left Vc 8.2e-3 of
#: its range off their converged result; these 4 476 steps and 1.6e-3, docs/svzerod.md "Speed")
DRIFT_RTOL, DRIFT_ATOL, DRIFT_ATOL_OTHERS = 1e-10, 1e-10, 1e-6
#: a state is moved by a slow mode when its component of the mode (in units of the state
#: scales) is at least this fraction of the mode's largest
DRIFT_COMPONENT = 0.1


def starts_steady(model, mean_circuit):
    """True when the run may start from a steady state (theirs or our operating point): an
    open loop with states and steady_initial (their default); otherwise their initial
    condition is the start and no operating point is needed."""
    return mean_circuit.nx > 0 and not model.closed and model.sim.get("steady_initial", True)


def slow_modes(model, mean_circuit, x_op):
    """(rates [1/s] (nx,), modes in units of the state scales, one per column) of the
    time-averaged model linearised at its operating point ``x_op``; None for a closed loop, a
    model without states or one whose run starts from their initial condition (steady_initial
    false)."""
    cm = mean_circuit
    if not starts_steady(model, cm):
        return None
    J = cm.jacobian(0.0, x_op)
    J = J.toarray() if hasattr(J, "toarray") else np.asarray(J)
    s = np.asarray(cm.state_scales, dtype=float)
    w, V = np.linalg.eig(J * s[None, :] / s[:, None])  # scaled states: components compare
    return np.abs(w.real), np.abs(V)


def keeps_its_start(model, mean_circuit, x_op):
    """True when the time-averaged model's slowest mode (linearised at its operating point
    ``x_op``) has a time constant longer than the whole run (number of cycles x period): the
    cycles they write then still depend on where the run started, so their steady_initial
    procedure (:mod:`hemocircuit.svzerod.steady_initial`) is the start to compare with, not
    our operating point.  chamber_elastance_inductor: 5.5e5 s (both valves closed, Rmax 1e5)
    against 30 s; every other shared open-loop case <= 0.1 s."""
    modes = slow_modes(model, mean_circuit, x_op)
    return modes is not None and float(modes[0].min()) * model.n_cycles * model.period < 1.0


def drift_atol(model, mean_circuit, x_op, circuit):
    """Absolute tolerances per unit of state scale (nx,) for ``circuit``'s run of a case that
    keeps its start: DRIFT_ATOL on the states its slow modes move (those whose time constant
    outlasts the run, as :func:`keeps_its_start`; a state is moved by a mode when its
    component is >= DRIFT_COMPONENT of the mode's largest), DRIFT_ATOL_OTHERS elsewhere.
    chamber_elastance_inductor: one such mode, the chamber volume Vc (components 1, 9e-5 for
    its outflow, 9e-7 for the vessel).  The states of ``circuit`` and of the time-averaged
    ``mean_circuit`` must be the same, in the same order."""
    modes = slow_modes(model, mean_circuit, x_op)
    run = model.n_cycles * model.period
    if modes is None or not np.any(modes[0] * run < 1.0):
        raise HemocircuitError(f"{model.name}: drift tolerances are for a run that keeps its start "
                               "(a mode slower than the run); this one forgets it")
    if list(circuit.state_names) != list(mean_circuit.state_names):
        raise HemocircuitError(f"{model.name}: the time-averaged model's states {list(mean_circuit.state_names)} "
                               f"are not the model's {list(circuit.state_names)}")
    rates, V = modes
    slow = V[:, rates * run < 1.0]
    moved = np.any(slow >= DRIFT_COMPONENT * slow.max(axis=0), axis=1)  # each slow mode by its own largest
    return np.where(moved, DRIFT_ATOL, DRIFT_ATOL_OTHERS)


def run_tolerances(model, mean_circuit, circuit):
    """(rtol, atol) the runner integrates ``circuit`` (the model) at: DRIFT_RTOL and
    :func:`drift_atol` for a run that keeps its start, else :func:`case_rtol` and None (the
    integrator's default atol).  The conformance runner and ``tran --svzerod-output``."""
    from ..analyses.op import steady_state

    if starts_steady(model, mean_circuit):
        x_op = steady_state(mean_circuit)
        if keeps_its_start(model, mean_circuit, x_op):
            return DRIFT_RTOL, drift_atol(model, mean_circuit, x_op, circuit)
    return case_rtol(model), None
