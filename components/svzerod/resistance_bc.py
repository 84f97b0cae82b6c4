"""svZeroDSolver ``RESISTANCE`` boundary condition: P - Pd(t) = R Q.

Equation (SimVascular/svZeroDSolver src/model/ResistanceBC.cpp, ``update_time``):
    P_in - R Q_in - Pd = 0,  R [mmHg*s/mL] and distal pressure Pd [mmHg] (may be a waveform),
Q the flow from ``node`` into the block (to ``ref``, ground in imported models).
"""
from __future__ import annotations

import numpy as np

from hemocircuit.component import Component, Observable, Param, two_terminal_conductance

from ._common import R_UNIT, jit


class ResistanceBC(Component):
    __doc__ = __doc__
    type_name = "resistance_bc"
    svzerod_blocks = ("RESISTANCE",)
    terminals = ("node", "ref")
    parameters = {"R": Param(R_UNIT, lower=0.0, lower_open=True, doc="resistance"),
                  "Pd": Param("mmHg", default="0 mmHg", doc="distal pressure (constant or a waveform)")}
    waveform_params = ("Pd",)
    role = "conductive"

    def observables(self):
        return (Observable("Q_in", "mL/s", "flow into the block"),)

    def _Pd(self, p, src):
        return p["Pd"] + (0.0 if src is None else src)

    def stamp(self, p, x, u, t, src=None):
        g = 1.0 / p["R"]
        return two_terminal_conductance(g + 0.0 * p["Pd"], -g * self._Pd(p, src))

    def observe(self, p, x, u, t, src=None):
        if u is None:
            return {}
        return {"Q_in": (u[..., 0] - u[..., 1] - self._Pd(p, src)) / p["R"]}

    def kernel(self):
        from hemocircuit.kernels import Kernel
        from hemocircuit.kernels.stateless import no_derivs, no_observables
        return Kernel(stamp=resistance_stamp, derivs=no_derivs, observe=no_observables, observables=())


# --- compiled path: p = [R, Pd] (Pd with its waveform added); local unknowns [P_node, P_ref]
@jit
def resistance_stamp(p, x, u, t, iopt, A, b):
    g = 1.0 / p[0]
    A[0, 0] = g
    A[0, 1] = -g
    A[1, 0] = -g
    A[1, 1] = g
    j = -g * p[1]
    b[0] = -j
    b[1] = j
