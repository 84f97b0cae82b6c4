"""svZeroDSolver ``RCR`` boundary condition (three-element Windkessel).

Equations (SimVascular/svZeroDSolver src/model/WindkesselBC.cpp, ``update_constant`` and
``update_time``; internal variable ``pressure_c``):
    P_in - Rp Q_in - P_c = 0
    Rd Q_in - P_c - Rd C dP_c/dt + Pd = 0    <=>  C dP_c/dt = Q_in - (P_c - Pd)/Rd
Parameters Rp, Rd [mmHg*s/mL] (Rp may be 0), C [mL/mmHg] > 0, Pd [mmHg] (may be a waveform).
State V = C P_c [mL] (pressures relative to ``ref``, ground in imported models).  Local
unknowns [P_node, P_ref, Q_in]: the branch row P_node - P_ref - Rp Q_in = V/C.
"""
from __future__ import annotations

from hemocircuit.component import Component, Observable, Param, State, kernel_method
from hemocircuit.kernels.stamps import branch

from ..common import C_UNIT, jit, R_UNIT


# --- the equations: p = [Rp, C, Rd, Pd] (Pd with its waveform added); state [V]; local unknowns [P_node, P_ref, Q_in]
@jit
def rcr_stamp(p, x, u, t, iopt, A, b):
    branch(A, b, 0, 1, 2, x[0] / p[1], p[0])  # P_node - P_ref - Rp Q_in = V/C


@jit
def rcr_derivs(p, x, u, t, iopt, dx):
    dx[0] = u[2] - (x[0] / p[1] - p[3]) / p[2]


@jit
def rcr_observe(p, x, iopt, out):
    out[0] = x[0] / p[1]


@jit
def rcr_report(p, x, u, t, iopt, out):
    out[0] = u[2]  # Q_in
    rcr_observe(p, x, iopt, out[1:])  # P_c


class RCRBC(Component):
    type_name = "rcr_bc"
    svzerod_blocks = ("RCR",)
    svzerod_steady_zeroed = (("C",), ("V",))  # their to_steady
    terminals = ("node", "ref")
    parameters = {"Rp": Param(R_UNIT, lower=0.0, doc="proximal resistance"),
                  "C": Param(C_UNIT, lower=0.0, lower_open=True, doc="capacitance"),
                  "Rd": Param(R_UNIT, lower=0.0, lower_open=True, doc="distal resistance"),
                  "Pd": Param("mmHg", default="0 mmHg", doc="distal pressure (constant or a waveform)")}
    waveform_params = ("Pd",)
    role = "pressure"
    kernel = kernel_method(rcr_stamp, rcr_derivs, rcr_observe, ("P_c",), report=rcr_report)
    BRANCHES = (("node", "ref"),)
    STATES = (State("V", "mL", 1.0, "volume of C (C * P_c)"),)
    OBSERVABLES = (Observable("Q_in", "mL/s", "flow into the block"),
                   Observable("P_c", "mmHg", "pressure of the capacitor", state_only=True))

    def cycle_time_constants(self, p):
        """Rd C [s]: svZeroDSolver counts the cycles of a run with RCR outlets from it (Solver.cpp)."""
        return p["Rd"] * p["C"]

    def dc_stamp(self, p, A_loc, b_loc, keep):
        """Steady state: C open, so Q_in = (P - Pd)/(Rp + Rd) (Pd's constant part)."""
        A_loc[..., 2, 2] = -(p["Rp"] + p["Rd"])
        b_loc[..., 2] = p["Pd"]
        return A_loc, b_loc

    def initial_states(self, p, u, flows=None, x=None):
        return (p["C"] * (u[..., 0] - u[..., 1] - p["Rp"] * u[..., 2]))[..., None]
