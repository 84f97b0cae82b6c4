"""svZeroDSolver ``ClosedLoopRCR`` boundary condition: Rp, then C to the reference, then Rd
on to the outlet (a two-port Windkessel in a closed loop).

Equations (SimVascular/svZeroDSolver src/model/ClosedLoopRCRBC.cpp, ``update_constant``):
    C dP_c/dt = Q_in - Q_out,   P_in - Rp Q_in - P_c = 0,   P_c - Rd Q_out - P_out = 0
Units: Rp [mmHg*s/mL] >= 0, C [mL/mmHg] > 0, Rd [mmHg*s/mL] > 0.  State: V = C P_c [mL]
(pressures relative to ``ref``, ground in imported models), a volume store.
Local unknowns [P_in, P_out, P_ref, P_c, q_p, q_c]: internal node c; branch (in, c) with
P_in - P_c - Rp q_p = 0 (Rp may be 0), branch (c, ref) with P_c - P_ref = V/C carrying
q_c = dV/dt; Rd a conductance from c to out.
"""
from __future__ import annotations

from hemocircuit.component import Component, Observable, Param, State, Storage, kernel_method, open_branches
from hemocircuit.kernels.stamps import branch, conductance

from ..common import C_UNIT, flow_observables, jit, R_UNIT


# --- the equations: p = [Rp, C, Rd]; state [V]; local unknowns [P_in, P_out, P_ref, P_c, q_p, q_c]
@jit
def clrcr_stamp(p, x, u, t, iopt, A, b):
    branch(A, b, 0, 3, 4, 0.0, p[0])  # P_in - P_c - Rp q_p = 0
    branch(A, b, 3, 2, 5, x[0] / p[1])
    conductance(A, 3, 1, 1.0 / p[2])


@jit
def clrcr_derivs(p, x, u, t, iopt, dx):
    dx[0] = u[5]


@jit
def clrcr_observe(p, x, iopt, out):
    out[0] = x[0]
    out[1] = x[0] / p[1]


@jit
def clrcr_report(p, x, u, t, iopt, out):
    clrcr_observe(p, x, iopt, out)  # V, P_c
    out[2] = u[4]  # Q_in
    out[3] = (u[3] - u[1]) / p[2]  # Q_out


class ClosedLoopRCR(Component):
    type_name = "closed_loop_rcr"
    svzerod_blocks = ("ClosedLoopRCR",)
    svzerod_steady_zeroed = (("C",), ("V",))  # their to_steady
    terminals = ("in", "out", "ref")
    parameters = {"Rp": Param(R_UNIT, lower=0.0, doc="proximal resistance"),
                  "C": Param(C_UNIT, lower=0.0, lower_open=True, doc="capacitance"),
                  "Rd": Param(R_UNIT, lower=0.0, lower_open=True, doc="distal resistance")}
    #: the distal resistance may vary in time (a waveform: spontaneous fluctuations of the
    #: peripheral resistance, a thigh-cuff release; docs/body.md)
    waveform_params = ("Rd",)
    kernel = kernel_method(clrcr_stamp, clrcr_derivs, clrcr_observe, ("V", "P_c"), report=clrcr_report)
    INTERNAL_NODES = ("c",)
    BRANCHES = (("in", "c"), ("c", "ref"))
    EDGES = (("in", "c", "conductive"), ("c", "out", "conductive"), ("c", "ref", "pressure"))
    STATES = (State("V", "mL", 1.0, "volume of C (C * P_c)"),)
    STORAGES = (Storage("c", "ref", "V", state="V"),)
    OBSERVABLES = (Observable("V", "mL", "volume of C", state_only=True),
                   Observable("P_c", "mmHg", "pressure of the capacitor", state_only=True),
                   *flow_observables())

    def dc_stamp(self, p, A_loc, b_loc, keep):
        """Steady state: C open (q_c = 0) unless it anchors a conservation law."""
        return open_branches(A_loc, b_loc, (5,), keep)

    def initial_states(self, p, u, flows=None, x=None):
        return (p["C"] * (u[..., 3] - u[..., 2]))[..., None]
