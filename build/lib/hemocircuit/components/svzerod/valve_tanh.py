"""svZeroDSolver ``ValveTanh``: a smooth valve, resistance switching between Rmin and Rmax.

Equations (SimVascular/svZeroDSolver src/model/ValveTanh.cpp, ``update_constant`` and
``update_solution``):
    P_in - P_out - Q (Rmin + (Rmax - Rmin) / 2 (1 + tanh(k (P_out - P_in)))) = 0,  Q_in = Q_out
(their third equation only writes the output ``valve_status`` = (1 + tanh(k (P_out - P_in)))/2,
reported here as the observable ``status``).  Open (Rmin) when P_in > P_out.
Units: Rmin, Rmax [mmHg*s/mL] (0 < Rmin <= Rmax), steepness k [1/mmHg].
Stamp: the flow Q = dP / R(dP) (dP = P_in - P_out) linearised at the current pressures,
dQ/d(dP) = (1 - dP R'(dP)/R) / R with R' = -(Rmax - Rmin) k / (2 cosh^2(k dP)).
"""
from __future__ import annotations

import math

import numpy as np

from hemocircuit.component import Component, Observable, Param, two_terminal_conductance

from ._common import R_UNIT, jit


def _r_and_slope(Rmin, Rmax, k, dp):
    th = np.tanh(-k * dp)
    R = Rmin + 0.5 * (Rmax - Rmin) * (1.0 + th)
    dR = -0.5 * (Rmax - Rmin) * k * (1.0 - th * th)
    return R, (1.0 - dp * dR / R) / R


class ValveTanh(Component):
    __doc__ = __doc__
    type_name = "valve_tanh"
    terminals = ("in", "out")
    parameters = {"Rmin": Param(R_UNIT, lower=0.0, lower_open=True, doc="resistance when open"),
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
    th = math.tanh(-k * dp)
    R = Rmin + 0.5 * (Rmax - Rmin) * (1.0 + th)
    dR = -0.5 * (Rmax - Rmin) * k * (1.0 - th * th)
    g = (1.0 - dp * dR / R) / R
    j = dp / R - g * dp
    A[0, 0] = g
    A[0, 1] = -g
    A[1, 0] = -g
    A[1, 1] = g
    b[0] = -j
    b[1] = j
