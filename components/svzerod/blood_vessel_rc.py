"""svZeroDSolver ``BloodVesselRC``: a flow-through RC element (the pulmonary RC of Sankaran
2012, their eq. X6' = X4 - X7, as in ClosedLoopHeartAndPulmonary).

Equations (SimVascular/svZeroDSolver src/model/BloodVesselRC.cpp, ``update_constant``):
    Cp dP_in/dt + (P_in - P_out)/Rpd - Q_in = 0,      Q_in - Q_out = 0
The whole inflow leaves at the outlet: the capacitor does not store blood, it only sets the
inlet pressure (the same as the heart block's Cp P_pul), so this is NOT a CRL vessel with
L = 0 (there Q_out = Q_in - C dP_in/dt).  Pressures relative to ``ref`` (ground in imported
models).  Units: Rpd [mmHg*s/mL] > 0, Cp [mL/mmHg] > 0.  State X = Cp P_in [mL] (a charge,
not a volume store, so closed loops do not count it in their blood volume).
Local unknowns [P_in, P_out, P_ref, q]: branch (in, ref) with P_in - P_ref = X/Cp whose flow
q enters at ``in`` and leaves at ``out`` (Q_in = Q_out = q); dX/dt = q - (P_in - P_out)/Rpd.
"""
from __future__ import annotations

from hemocircuit.component import Component, Param, State, kernel_method

from ..common import C_UNIT, flow_observables, jit, R_UNIT


# --- the equations: p = [Rpd, Cp]; state [X]; local unknowns [P_in, P_out, P_ref, q]
@jit
def bvrc_stamp(p, x, u, t, iopt, A, b):
    A[0, 3] = 1.0
    A[1, 3] = -1.0
    A[3, 0] = 1.0
    A[3, 2] = -1.0
    b[3] = x[0] / p[1]


@jit
def bvrc_derivs(p, x, u, t, iopt, dx):
    dx[0] = u[3] - (u[0] - u[1]) / p[0]


@jit
def bvrc_report(p, x, u, t, iopt, out):
    out[0] = u[3]  # Q_in
    out[1] = u[3]  # Q_out


class BloodVesselRC(Component):
    type_name = "blood_vessel_rc"
    svzerod_blocks = ("BloodVesselRC",)
    terminals = ("in", "out", "ref")
    parameters = {"Rpd": Param(R_UNIT, lower=0.0, lower_open=True, doc="resistance"),
                  "Cp": Param(C_UNIT, lower=0.0, lower_open=True, doc="capacitance at the inlet")}
    kernel = kernel_method(bvrc_stamp, bvrc_derivs, report=bvrc_report)
    BRANCHES = (("in", "ref"),)
    EDGES = (("in", "out", "conductive"),)
    STATES = (State("X", "mL", 1.0, "Cp * P_in (not stored blood)"),)
    OBSERVABLES = flow_observables("the inlet (= out of the outlet)")

    def dc_stamp(self, p, A_loc, b_loc, keep):
        """Steady state: dX/dt = 0, so q = (P_in - P_out)/Rpd: the branch becomes Rpd."""
        A_loc[..., 3, :] = 0.0
        A_loc[..., 3, 0], A_loc[..., 3, 1], A_loc[..., 3, 3] = 1.0, -1.0, -p["Rpd"]
        b_loc[..., 3] = 0.0
        return A_loc, b_loc

    def initial_states(self, p, u, flows=None, x=None):
        return (p["Cp"] * (u[..., 0] - u[..., 2]))[..., None]
