"""svZeroDSolver ``PiecewiseValve``: resistance Rmin when P_out < P_in, else Rmax.

Equations (SimVascular/svZeroDSolver src/model/PiecewiseValve.cpp, ``update_solution``):
    P_in - P_out - R Q = 0,  Q_in = Q_out,  R = Rmin if P_out < P_in else Rmax.
Units: Rmin, Rmax [mmHg*s/mL] (0 < Rmin <= Rmax).  The flow Q = (P_in - P_out)/R is continuous
in the pressures (a kink at equal pressures); the stamp is the conductance of the side the
current pressures are on (the nodal Newton iteration settles on a consistent side).
"""
from __future__ import annotations

from hemocircuit.component import Component, Observable, Param, kernel_method
from hemocircuit.kernels.stamps import conductance

from ..common import check_rmin_rmax, jit, R_UNIT


# --- the equations: p = [Rmin, Rmax]; local unknowns [P_in, P_out]
@jit
def _conductance(p, dp):
    """1/Rmin while P_in > P_out, else 1/Rmax."""
    return 1.0 / p[0] if dp > 0.0 else 1.0 / p[1]


@jit
def piecewise_valve_stamp(p, x, u, t, iopt, A, b):
    conductance(A, 0, 1, _conductance(p, u[0] - u[1]))


@jit
def piecewise_valve_report(p, x, u, t, iopt, out):
    dp = u[0] - u[1]
    out[0] = _conductance(p, dp) * dp  # Q


class PiecewiseValve(Component):
    type_name = "piecewise_valve"
    svzerod_blocks = ("PiecewiseValve",)
    terminals = ("in", "out")
    parameters = {"Rmin": Param(R_UNIT, lower=0.0, lower_open=True, doc="resistance when open (P_out < P_in)"),
                  "Rmax": Param(R_UNIT, lower=0.0, lower_open=True, doc="resistance when closed")}
    linear_in_pressure = False
    constant_matrix = False
    kernel = kernel_method(piecewise_valve_stamp, report=piecewise_valve_report)
    OBSERVABLES = (Observable("Q", "mL/s", "flow from in to out"),)
    check = check_rmin_rmax
