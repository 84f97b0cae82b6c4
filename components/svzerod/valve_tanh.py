"""svZeroDSolver ``ValveTanh``: a smooth valve, resistance switching between Rmin and Rmax.

Equations (SimVascular/svZeroDSolver src/model/ValveTanh.cpp, ``update_constant`` and
``update_solution``):
    P_in - P_out - Q (Rmin + (Rmax - Rmin) / 2 (1 + tanh(k (P_out - P_in)))) = 0,  Q_in = Q_out
(their third equation only writes the output ``valve_status`` = (1 + tanh(k (P_out - P_in)))/2,
reported here as the observable ``status``).  Open (Rmin) when P_in > P_out.
Units: Rmin, Rmax [mmHg*s/mL] (0 <= Rmin <= Rmax, Rmax > 0), steepness k [1/mmHg].
Stamp: the flow Q = dP / R(dP) (dP = P_in - P_out) linearised at the current pressures,
dQ/d(dP) = (1 - dP R'(dP)/R) / R with R' = -(Rmax - Rmin) k / (2 cosh^2(k dP)).
(1 + tanh(-k dP))/2 is evaluated as s = 1/(1 + exp(2 k dP)) (the same function), which stays
> 0 where 1 + tanh underflows to 0: with Rmin = 0 (their chamber_sphere case) R = Rmax s is
then still positive (the exponent is clipped at 700, R >= Rmax e^-700).
"""
from __future__ import annotations

import math

import numpy as np

from hemocircuit.component import Component, Observable, Param, two_terminal_conductance

from ._common import R_UNIT, jit


def _r_and_slope(Rmin, Rmax, k, dp):
    s = 1.0 / (1.0 + np.exp(np.clip(2.0 * k * dp, -700.0, 700.0)))  # (1 + tanh(-k dp))/2
    R = Rmin + (Rmax - Rmin) * s
    dR = -2.0 * (Rmax - Rmin) * k * s * (1.0 - s)
    return R, (1.0 - dp * dR / R) / R


class ValveTanh(Component):
    __doc__ = __doc__
    type_name = "valve_tanh"
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

    def stamp(self, p, x, u, t, src=None):
        dp = np.zeros(np.shape(p["Rmin"])) if u is None else u[..., 0] - u[..., 1]
        R, g = _r_and_slope(p["Rmin"], p["Rmax"], p["steepness"], dp)
        return two_terminal_conductance(g, dp / R - g * dp)

    def observe(self, p, x, u, t, src=None):
        if u is None:
            return {}
        dp = u[..., 0] - u[..., 1]
        R, _ = _r_and_slope(p["Rmin"], p["Rmax"], p["steepness"], dp)
        return {"Q": dp / R, "status": 0.5 * (1.0 + np.tanh(-p["steepness"] * dp))}

    def kernel(self):
        from hemocircuit.kernels import Kernel
        from hemocircuit.kernels.stateless import no_derivs, no_observables
        return Kernel(stamp=valve_tanh_stamp, derivs=no_derivs, observe=no_observables, observables=())


# --- compiled path: p = [Rmin, Rmax, steepness]; local unknowns [P_in, P_out]
@jit
def valve_tanh_stamp(p, x, u, t, iopt, A, b):
    Rmin, Rmax, k = p[0], p[1], p[2]
    dp = u[0] - u[1]
    s = 1.0 / (1.0 + math.exp(min(max(2.0 * k * dp, -700.0), 700.0)))
    R = Rmin + (Rmax - Rmin) * s
    dR = -2.0 * (Rmax - Rmin) * k * s * (1.0 - s)
    g = (1.0 - dp * dR / R) / R
    j = dp / R - g * dp
    A[0, 0] = g
    A[0, 1] = -g
    A[1, 0] = -g
    A[1, 1] = g
    b[0] = -j
    b[1] = j
