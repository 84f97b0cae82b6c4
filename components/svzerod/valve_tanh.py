"""svZeroDSolver ``ValveTanh``: a smooth valve, resistance switching between Rmin and Rmax.

Equations (SimVascular/svZeroDSolver src/model/ValveTanh.cpp, ``update_constant`` and
``update_solution``):
    P_in - P_out - Q (Rmin + (Rmax - Rmin) / 2 (1 + tanh(k (P_out - P_in)))) = 0,  Q_in = Q_out
(their third equation only writes the output ``valve_status`` = (1 + tanh(k (P_out - P_in)))/2,
reported here as the observable ``status``).  Open (Rmin) when P_in > P_out.
Units: Rmin, Rmax [mmHg*s/mL] (0 <= Rmin <= Rmax, Rmax > 0), steepness k [1/mmHg].
Stamp: their residual form, a branch (in, out) carrying Q with P_in - P_out - R(dP) Q = 0
(dP = P_in - P_out) linearised at the current iterate (dP0, Q0):
    (1 - Q0 R'(dP0)) dP - R(dP0) Q = -Q0 R'(dP0) dP0,   R' = -(Rmax - Rmin) k / (2 cosh^2(k dP)).
Newton on this form, in series with an inductor (Q given), solves dP = Q R(dP), whose slope
1 - Q R' >= 1 for forward flow: it converges where the conductance form Q = dP/R(dP) (slope
changing 1e5-fold within 1e-7 mmHg at their steepness 1e4) does not, and R -> 0 (Rmin = 0)
is a short, not a division by zero.  For reverse flow (Q R' > 0) the slope 1 - Q R' may
vanish in the switching band; there the iteration uses slope 1 (a fixed-point step
dP = Q R(dP)), which has the same solution (the residual is exact, only the step changes).
(1 + tanh(-k dP))/2 is evaluated as s = 1/(1 + exp(2 k dP)) (the same function), which stays
> 0 where 1 + tanh underflows to 0 (the exponent is clipped at 700).
"""
from __future__ import annotations

import math

import numpy as np

from hemocircuit.component import Component, Observable, Param

from ._common import R_UNIT, jit


def _r_and_dr(Rmin, Rmax, k, dp):
    """R(dP) and dR/d(dP)."""
    s = 1.0 / (1.0 + np.exp(np.clip(2.0 * k * dp, -700.0, 700.0)))  # (1 + tanh(-k dp))/2
    return Rmin + (Rmax - Rmin) * s, -2.0 * (Rmax - Rmin) * k * s * (1.0 - s)


class ValveTanh(Component):
    __doc__ = __doc__
    type_name = "valve_tanh"
    svzerod_blocks = ("ValveTanh",)
    terminals = ("in", "out")
    parameters = {"Rmin": Param(R_UNIT, lower=0.0, doc="resistance when open"),
                  "Rmax": Param(R_UNIT, lower=0.0, lower_open=True, doc="resistance when closed"),
                  "steepness": Param("1/mmHg", lower=0.0, lower_open=True, doc="steepness k of the tanh")}
    role = "conductive"
    linear_in_pressure = False
    constant_matrix = False

    def check(self, p):
        bad = np.any(p["Rmax"] < p["Rmin"], axis=tuple(range(np.ndim(p["Rmin"]) - 1)))
        return [(int(i), "needs Rmin <= Rmax") for i in np.nonzero(np.atleast_1d(bad))[0]]

    def observables(self):
        return (Observable("Q", "mL/s", "flow from in to out"),
                Observable("status", "dimensionless", "their valve_status (1 + tanh(k (P_out - P_in)))/2"))

    def branches(self):
        return (("in", "out"),)

    def edges(self):
        return (("in", "out", "conductive"),)

    def stamp(self, p, x, u, t, src=None):
        dp = np.zeros(np.shape(p["Rmin"])) if u is None else u[..., 0] - u[..., 1]
        q = np.zeros(np.shape(p["Rmin"])) if u is None else u[..., 2]
        R, dR = _r_and_dr(p["Rmin"], p["Rmax"], p["steepness"], dp)
        c = np.maximum(1.0 - q * dR, 1.0)
        A = np.zeros(np.shape(c) + (3, 3))
        b = np.zeros(np.shape(c) + (3,))
        A[..., 0, 2], A[..., 1, 2] = 1.0, -1.0
        A[..., 2, 0], A[..., 2, 1], A[..., 2, 2] = c, -c, -R
        b[..., 2] = -q * dR * dp
        return A, b

    def observe(self, p, x, u, t, src=None):
        if u is None:
            return {}
        dp = u[..., 0] - u[..., 1]
        return {"Q": u[..., 2], "status": 0.5 * (1.0 + np.tanh(-p["steepness"] * dp))}

    def kernel(self):
        from hemocircuit.kernels import Kernel
        from hemocircuit.kernels.stateless import no_derivs, no_observables
        return Kernel(stamp=valve_tanh_stamp, derivs=no_derivs, observe=no_observables, observables=())


# --- compiled path: p = [Rmin, Rmax, steepness]; local unknowns [P_in, P_out, Q]
@jit
def valve_tanh_stamp(p, x, u, t, iopt, A, b):
    Rmin, Rmax, k = p[0], p[1], p[2]
    dp = u[0] - u[1]
    q = u[2]
    s = 1.0 / (1.0 + math.exp(min(max(2.0 * k * dp, -700.0), 700.0)))
    R = Rmin + (Rmax - Rmin) * s
    dR = -2.0 * (Rmax - Rmin) * k * s * (1.0 - s)
    c = max(1.0 - q * dR, 1.0)
    A[0, 2] = 1.0
    A[1, 2] = -1.0
    A[2, 0] = c
    A[2, 1] = -c
    A[2, 2] = -R
    b[2] = -q * dR * dp
