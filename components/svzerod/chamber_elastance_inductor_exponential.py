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

from hemocircuit.component import Param, kernel_method
from hemocircuit.elementwise import per_element

from ..common import E_UNIT, jit, observe_first_state
from .activation import act_parameters, activation
from .chamber_elastance_inductor import OWN_PARAMS, ChamberElastanceInductor, cei_derivs, cei_report, chamber_stamp


# --- the equations: p = [Emax, Kxp, Kxv, Vaso, Impedance, period, 13 activation parameters];
# iopt = [activation kind]; states [Vc, Q_out]; local unknowns [P_in, P_out, P_ref, q]
@jit
def atrium_pressure(A, Emax, Kxp, Kxv, Vaso, V):
    """P = A Emax (V - Vaso) + (1 - A) Kxp (exp((V - Vaso) Kxv) - 1) at activation A (also the
    atria of closed_loop_heart_pulmonary, their update_solution)."""
    return A * Emax * (V - Vaso) + Kxp * (math.exp((V - Vaso) * Kxv) - 1.0) * (1.0 - A)


@jit
def atrium_slope(A, Emax, Kxp, Kxv, Vaso, V):
    """dP/dV of atrium_pressure."""
    return A * Emax + Kxp * Kxv * math.exp((V - Vaso) * Kxv) * (1.0 - A)


@jit
def ceie_stamp(p, x, u, t, iopt, A, b):
    a = activation(iopt[0], t, p[5], p[6:19])
    chamber_stamp(atrium_pressure(a, p[0], p[1], p[2], p[3], x[0]), x, A, b)


@jit
def ceie_volume(p, target, iopt):
    """Vc with P(Vc, t = 0) = target: Newton from the linearisation at Vaso (the law increases
    in Vc for Emax, Kxp Kxv >= 0 and A in [0, 1]), steps clipped to 50 mL."""
    a = activation(iopt[0], 0.0, p[5], p[6:19])
    slope = atrium_slope(a, p[0], p[1], p[2], p[3], p[3])
    V = p[3] + target / (slope if slope > 0.0 else 1.0)
    for _ in range(50):
        slope = atrium_slope(a, p[0], p[1], p[2], p[3], V)
        step = (atrium_pressure(a, p[0], p[1], p[2], p[3], V) - target) / (slope if slope > 0.0 else 1.0)
        V = V - min(max(step, -50.0), 50.0)
    return V


class ChamberElastanceInductorExponential(ChamberElastanceInductor):
    type_name = "chamber_elastance_inductor_exponential"
    svzerod_blocks = ("ChamberElastanceInductorExponential",)
    # Impedance and period at the slots chamber_elastance_inductor's kernels read (4, 5)
    parameters = {"Emax": Param(E_UNIT, lower=0.0, doc="active elastance"),
                  "Kxp": Param("mmHg", doc="passive pressure scale"),
                  "Kxv": Param("1/mL", doc="passive volume exponent"),
                  "Vaso": Param("mL", doc="rest volume"),
                  "Impedance": OWN_PARAMS["Impedance"], **act_parameters()}
    kernel = kernel_method(ceie_stamp, cei_derivs, observe_first_state, ("Vc",), report=cei_report)

    def volume(self, p, P):
        """Vc with P(Vc, t = 0) = P [mmHg] (ceie_volume)."""
        return per_element(ceie_volume, self, p, P)
