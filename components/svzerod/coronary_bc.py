"""svZeroDSolver ``CORONARY`` boundary condition (open-loop coronary, Kim et al. 2010).

Circuit (SimVascular/svZeroDSolver src/model/OpenLoopCoronaryBC.cpp; rearranged from the
``update_constant`` / ``update_time`` equations): inlet -> Ra1 -> node a (Ca to ``ref``) ->
Ra2 -> node im (Cc to the intramyocardial pressure Pim(t)) -> Rv1 -> venous pressure P_v.
    Ca d P_a/dt          = Q_in - (P_a - P_im)/Ra2
    Cc d(P_im - Pim)/dt  = (P_a - P_im)/Ra2 - (P_im - P_v)/Rv1
Their state ``volume_im`` is Cc (P_im - Pim) minus its initial value (P_Cim_0, Pim_0 offsets);
here the states are the physical volumes V_a = Ca P_a and V_im = Cc (P_im - Pim) [mL], which
gives the same pressures and flows.  Parameters Ra1, Ra2, Rv1 [mmHg*s/mL], Ca, Cc [mL/mmHg],
Pim [mmHg] (usually a waveform), P_v [mmHg].  Local unknowns [P_node, P_ref, Q_in]: branch row
P_node - P_ref - Ra1 Q_in = V_a/Ca.
"""
from __future__ import annotations

import numpy as np

from hemocircuit.component import Component, Observable, Param, State, kernel_method
from hemocircuit.kernels.stamps import branch

from ..common import C_UNIT, jit, R_UNIT


# --- the equations: p = [Ra1, Ra2, Rv1, Ca, Cc, Pim, P_v] (Pim with its waveform added);
# states [V_a, V_im]; local unknowns [P_node, P_ref, Q_in]
@jit
def coronary_stamp(p, x, u, t, iopt, A, b):
    branch(A, b, 0, 1, 2, x[0] / p[3], p[0])  # P_node - P_ref - Ra1 Q_in = V_a/Ca


@jit
def coronary_balance(p, x, u, Ram, dx):
    """dx/dt with the microvascular resistance Ram (Ra2, or CORONARY_VAR_RES's Ram(t))."""
    Pa = x[0] / p[3]
    Pc = x[1] / p[4] + p[5]
    q_am = (Pa - Pc) / Ram
    dx[0] = u[2] - q_am
    dx[1] = q_am - (Pc - p[6]) / p[2]


@jit
def coronary_derivs(p, x, u, t, iopt, dx):
    coronary_balance(p, x, u, p[1], dx)


@jit
def coronary_report(p, x, u, t, iopt, out):
    out[0] = u[2]  # Q_in


class CoronaryBC(Component):
    type_name = "coronary_bc"
    svzerod_blocks = ("CORONARY",)
    svzerod_steady_zeroed = (("Ca", "Cc"), ("V_a", "V_im"))  # their to_steady
    terminals = ("node", "ref")
    parameters = {"Ra1": Param(R_UNIT, lower=0.0, doc="arterial resistance"),
                  "Ra2": Param(R_UNIT, lower=0.0, lower_open=True, doc="micro-arterial resistance"),
                  "Rv1": Param(R_UNIT, lower=0.0, lower_open=True, doc="venous resistance"),
                  "Ca": Param(C_UNIT, lower=0.0, lower_open=True, doc="arterial capacitance"),
                  "Cc": Param(C_UNIT, lower=0.0, lower_open=True, doc="intramyocardial capacitance"),
                  "Pim": Param("mmHg", default="0 mmHg", doc="intramyocardial pressure (a waveform)"),
                  "P_v": Param("mmHg", default="0 mmHg", doc="venous pressure")}
    waveform_params = ("Pim",)
    role = "pressure"
    kernel = kernel_method(coronary_stamp, coronary_derivs, report=coronary_report)
    BRANCHES = (("node", "ref"),)
    STATES = (State("V_a", "mL", 1.0, "volume of Ca"), State("V_im", "mL", 1.0, "volume of Cc"))
    OBSERVABLES = (Observable("Q_in", "mL/s", "flow into the block"),)

    def dc_stamp(self, p, A_loc, b_loc, keep):
        """Steady state: capacitors open, Q_in = (P - P_v)/(Ra1 + Ra2 + Rv1)."""
        A_loc[..., 2, 2] = -(p["Ra1"] + p["Ra2"] + p["Rv1"])
        b_loc[..., 2] = p["P_v"]
        return A_loc, b_loc

    def initial_states(self, p, u, flows=None, x=None):
        q = u[..., 2]
        Pa = u[..., 0] - u[..., 1] - p["Ra1"] * q
        out = np.empty(u.shape[:2] + (2,))
        out[..., 0] = p["Ca"] * Pa
        out[..., 1] = p["Cc"] * (Pa - p["Ra2"] * q - p["Pim"])
        return out
