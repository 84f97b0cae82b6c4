"""svZeroDSolver ``ValveTanh``: a smooth valve, resistance switching between Rmin and Rmax.

Equations (SimVascular/svZeroDSolver src/model/ValveTanh.cpp, ``update_constant`` and
``update_solution``):
    P_in - P_out - Q (Rmin + (Rmax - Rmin) / 2 (1 + tanh(k (P_out - P_in)))) = 0,  Q_in = Q_out
(their third equation only writes the output ``valve_status`` = (1 + tanh(k (P_out - P_in)))/2,
reported here as the observable ``status``).  Open (Rmin) when P_in > P_out.
Units: Rmin, Rmax [mmHg*s/mL] (0 <= Rmin <= Rmax, Rmax > 0), steepness k [1/mmHg].
Stamp: their residual P_in - P_out - R(dP) Q = 0 on a branch (in, out) carrying Q, linearised
at the iterate (dP0, Q0) with slope c = 1 - Q0 R'(dP0): c dP - R(dP0) Q = (c - 1) dP0, with
R' = -(Rmax - Rmin) k / (2 cosh^2(k dP)).  This form converges where the conductance form
Q = dP/R(dP) does not (its slope changes 1e5-fold within 1e-7 mmHg at their k = 1e4), and
Rmin = 0 is a short; where c < 1 (reverse flow) the step uses c = 1, the fixed-point iteration
dP = R(dP) Q, whose fixed point is the same root (its right-hand side is (c - 1) dP0 = 0).
(1 + tanh(-k dP))/2 is evaluated as 1/(1 + exp(2 k dP)), exponent clipped at 700.
"""
from __future__ import annotations

import math

from hemocircuit.component import Component, Observable, Param, kernel_method
from hemocircuit.kernels.stamps import branch

from ..common import check_rmin_rmax, jit, R_UNIT


# --- the equations: p = [Rmin, Rmax, steepness]; local unknowns [P_in, P_out, Q]
@jit
def valve_closure(k, dp):
    """s = (1 + tanh(-k dP))/2 = 1/(1 + exp(2 k dP)) (exponent clipped at +-700): the weight of
    Rmax, their valve_status."""
    return 1.0 / (1.0 + math.exp(min(max(2.0 * k * dp, -700.0), 700.0)))


@jit
def valve_tanh_stamp(p, x, u, t, iopt, A, b):
    Rmin, Rmax, k = p[0], p[1], p[2]
    dp = u[0] - u[1]
    q = u[2]
    s = valve_closure(k, dp)
    R = Rmin + (Rmax - Rmin) * s
    dR = -2.0 * (Rmax - Rmin) * k * s * (1.0 - s)
    c = max(1.0 - q * dR, 1.0)
    branch(A, b, 0, 1, 2, (c - 1.0) * dp, R)  # = -q R' dP0 (Newton) unless the slope is clamped to 1
    A[2, 0] = c
    A[2, 1] = -c


@jit
def valve_tanh_report(p, x, u, t, iopt, out):
    out[0] = u[2]  # Q
    out[1] = valve_closure(p[2], u[0] - u[1])  # status


class ValveTanh(Component):
    type_name = "valve_tanh"
    svzerod_blocks = ("ValveTanh",)
    terminals = ("in", "out")
    parameters = {"Rmin": Param(R_UNIT, lower=0.0, doc="resistance when open"),
                  "Rmax": Param(R_UNIT, lower=0.0, lower_open=True, doc="resistance when closed"),
                  "steepness": Param("1/mmHg", lower=0.0, lower_open=True, doc="steepness k of the tanh")}
    linear_in_pressure = False
    constant_matrix = False
    kernel = kernel_method(valve_tanh_stamp, report=valve_tanh_report)
    OBSERVABLES = (Observable("Q", "mL/s", "flow from in to out"),
                   Observable("status", "dimensionless", "their valve_status (1 + tanh(k (P_out - P_in)))/2"))
    BRANCHES = (("in", "out"),)
    check = check_rmin_rmax
