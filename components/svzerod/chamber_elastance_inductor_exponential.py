"""svZeroDSolver ``ChamberElastanceInductorExponential``: the elastance chamber with an outflow
inductor whose passive pressure-volume law is exponential (an atrium of the decomposed heart).

Equations (SimVascular/svZeroDSolver src/model/ChamberElastanceInductorExponential.cpp,
``get_elastance_values``, ``update_time``, ``update_solution``; the inductor and the mass
balance are ChamberElastanceInductor.cpp's ``update_constant``):
    P_in = A(t) Emax (Vc - Vaso) + (1 - A(t)) psi(Vc),   psi = Kxp (exp(Kxv (Vc - Vaso)) - 1)
    L dQ_out/dt = P_in - P_out,   dVc/dt = Q_in - Q_out
with A(t) the activation function (option ``activation``, components/svzerod/activation.py);
the same law as the atria of ClosedLoopHeartAndPulmonary.  Pressures relative to ``ref``.
Units: Emax [mmHg/mL], Kxp [mmHg], Kxv [1/mL], Vaso [mL], Impedance L [mmHg*s^2/mL] > 0,
period [s].  States Vc [mL] (a volume store), Q_out [mL/s]; local unknowns as
chamber_elastance_inductor's (whose derivatives and observables it shares).
"""
from __future__ import annotations

import math

import numpy as np

from hemocircuit.component import Param

from ._common import batch_shape, E_UNIT, jit
from .activation import act_parameters, activation, activation_np
from .chamber_elastance_inductor import _OWN, ChamberElastanceInductor, cei_derivs, cei_observe


class ChamberElastanceInductorExponential(ChamberElastanceInductor):
    __doc__ = __doc__
    type_name = "chamber_elastance_inductor_exponential"
    svzerod_blocks = ("ChamberElastanceInductorExponential",)
    # Impedance and period at the slots chamber_elastance_inductor's kernels read (4, 5)
    parameters = {"Emax": Param(E_UNIT, lower=0.0, doc="active elastance"),
                  "Kxp": Param("mmHg", doc="passive pressure scale"),
                  "Kxv": Param("1/mL", doc="passive volume exponent"),
                  "Vaso": Param("mL", doc="rest volume"),
                  "Impedance": _OWN["Impedance"], **act_parameters()}

    def _pressure(self, p, Vc, t):
        """(P_in - P_ref, dP/dVc) at volume Vc and time t."""
        a = activation_np(self.opts["activation"], t, p)
        e = np.exp(p["Kxv"] * (Vc - p["Vaso"]))
        P = a * p["Emax"] * (Vc - p["Vaso"]) + (1.0 - a) * p["Kxp"] * (e - 1.0)
        return P, a * p["Emax"] + (1.0 - a) * p["Kxp"] * p["Kxv"] * e

    def stamp(self, p, x, u, t, src=None):
        P, _ = self._pressure(p, x[..., 0], t)
        shape = batch_shape(p, P.shape, x.shape[:2])
        A = np.zeros(shape + (4, 4))
        b = np.zeros(shape + (4,))
        A[..., 0, 3], A[..., 2, 3] = 1.0, -1.0
        A[..., 3, 0], A[..., 3, 2] = 1.0, -1.0
        b[..., 3] = P
        b[..., 0], b[..., 1] = -x[..., 1], x[..., 1]
        return A, b

    def initial_states(self, p, u, flows=None, x=None):
        """Vc with P(Vc, 0) = the local pressure: Newton from the linearisation at Vaso (the
        law is increasing in Vc for Emax, Kxp Kxv >= 0 and A in [0, 1])."""
        target = u[..., 0] - u[..., 2]
        _, slope = self._pressure(p, p["Vaso"], 0.0)
        V = p["Vaso"] + target / np.where(slope > 0, slope, 1.0)
        for _ in range(50):
            P, dP = self._pressure(p, V, 0.0)
            step = (P - target) / np.where(dP > 0, dP, 1.0)
            V = V - np.clip(step, -50.0, 50.0)
        out = np.zeros(batch_shape(p, V.shape, u.shape[:2]) + (2,))
        out[..., 0] = V
        if flows is not None:
            out[..., 1] = -flows[..., 1]
        return out

    def kernel(self):
        from hemocircuit.kernels import Kernel
        return Kernel(stamp=ceie_stamp, derivs=cei_derivs, observe=cei_observe, observables=("Vc",))


# --- compiled path: p = [Emax, Kxp, Kxv, Vaso, Impedance, period, 13 activation parameters];
# iopt = [activation kind]; states [Vc, Q_out]; local unknowns [P_in, P_out, P_ref, q]
@jit
def ceie_stamp(p, x, u, t, iopt, A, b):
    a = activation(iopt[0], t, p[5], p[6:19])
    dV = x[0] - p[3]
    A[0, 3] = 1.0
    A[2, 3] = -1.0
    A[3, 0] = 1.0
    A[3, 2] = -1.0
    b[3] = a * p[0] * dV + (1.0 - a) * p[1] * (math.exp(p[2] * dV) - 1.0)
    b[0] = -x[1]
    b[1] = x[1]
