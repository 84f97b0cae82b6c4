"""svZeroDSolver ``RESISTANCE`` boundary condition: P - Pd(t) = R Q.

Equation (SimVascular/svZeroDSolver src/model/ResistanceBC.cpp, ``update_time``):
    P_in - R Q_in - Pd = 0,  R [mmHg*s/mL] and distal pressure Pd [mmHg] (may be a waveform),
Q the flow from ``node`` into the block (to ``ref``, ground in imported models).
"""
from __future__ import annotations

from hemocircuit.component import Component, Observable, Param, kernel_method
from hemocircuit.kernels.stamps import conductance, imposed_flow

from ..common import jit, R_UNIT


# --- the equations: p = [R, Pd] (Pd with its waveform added); local unknowns [P_node, P_ref]
@jit
def resistance_stamp(p, x, u, t, iopt, A, b):
    g = 1.0 / p[0]
    conductance(A, 0, 1, g)
    imposed_flow(b, 0, 1, -g * p[1])  # q = g (P_node - P_ref - Pd)


@jit
def resistance_report(p, x, u, t, iopt, out):
    out[0] = (u[0] - u[1] - p[1]) / p[0]  # Q_in


class ResistanceBC(Component):
    type_name = "resistance_bc"
    svzerod_blocks = ("RESISTANCE",)
    terminals = ("node", "ref")
    parameters = {"R": Param(R_UNIT, lower=0.0, lower_open=True, doc="resistance"),
                  "Pd": Param("mmHg", default="0 mmHg", doc="distal pressure (constant or a waveform)")}
    waveform_params = ("Pd",)
    kernel = kernel_method(resistance_stamp, report=resistance_report)
    OBSERVABLES = (Observable("Q_in", "mL/s", "flow into the block"),)
