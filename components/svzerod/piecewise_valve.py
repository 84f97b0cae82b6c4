"""svZeroDSolver ``PiecewiseValve``: resistance Rmin when P_out < P_in, else Rmax.

Equations (SimVascular/svZeroDSolver src/model/PiecewiseValve.cpp, ``update_solution``):
    P_in - P_out - R Q = 0,  Q_in = Q_out,  R = Rmin if P_out < P_in else Rmax.
Units: Rmin, Rmax [mmHg*s/mL] (0 < Rmin <= Rmax).  The flow Q = (P_in - P_out)/R is continuous
in the pressures (a kink at equal pressures); the stamp is the conductance of the side the
current pressures are on (the nodal Newton iteration settles on a consistent side).
"""
from __future__ import annotations

import numpy as np

from hemocircuit.component import Component, Observable, Param, two_terminal_conductance

from ._common import R_UNIT, jit


class PiecewiseValve(Component):
    __doc__ = __doc__
    type_name = "piecewise_valve"
    svzerod_blocks = ("PiecewiseValve",)
    terminals = ("in", "out")
    parameters = {"Rmin": Param(R_UNIT, lower=0.0, lower_open=True, doc="resistance when open (P_out < P_in)"),
                  "Rmax": Param(R_UNIT, lower=0.0, lower_open=True, doc="resistance when closed")}
    role = "conductive"
    linear_in_pressure = False
    constant_matrix = False

    def check(self, p):
        bad = np.any(p["Rmax"] < p["Rmin"], axis=tuple(range(np.ndim(p["Rmin"]) - 1)))
        return [(int(i), "needs Rmin <= Rmax") for i in np.nonzero(np.atleast_1d(bad))[0]]

    def observables(self):
        return (Observable("Q", "mL/s", "flow from in to out"),)

    def _g(self, p, dp):
        return np.where(dp > 0.0, 1.0 / p["Rmin"], 1.0 / p["Rmax"])

    def stamp(self, p, x, u, t, src=None):
        dp = np.zeros(np.shape(p["Rmin"])) if u is None else u[..., 0] - u[..., 1]
        return two_terminal_conductance(self._g(p, dp) + 0.0 * p["Rmax"])

    def observe(self, p, x, u, t, src=None):
        if u is None:
            return {}
        dp = u[..., 0] - u[..., 1]
        return {"Q": self._g(p, dp) * dp}

    def kernel(self):
        from hemocircuit.kernels import Kernel
        from hemocircuit.kernels.stateless import no_derivs, no_observables
        return Kernel(stamp=piecewise_valve_stamp, derivs=no_derivs, observe=no_observables, observables=())


# --- compiled path: p = [Rmin, Rmax]; local unknowns [P_in, P_out]
@jit
def piecewise_valve_stamp(p, x, u, t, iopt, A, b):
    g = 1.0 / p[0] if u[0] - u[1] > 0.0 else 1.0 / p[1]
    A[0, 0] = g
    A[0, 1] = -g
    A[1, 0] = -g
    A[1, 1] = g
