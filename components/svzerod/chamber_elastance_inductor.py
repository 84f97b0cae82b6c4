"""svZeroDSolver ``ChamberElastanceInductor``: a time-varying elastance chamber with an
outflow inductor.

Equations (SimVascular/svZeroDSolver src/model/ChamberElastanceInductor.cpp,
``update_constant``, ``update_time``, ``get_elastance_values``):
    P_in = E(t) (Vc - Vrest(t))                 E = (Emax - Emin) A(t) + Emin
    L dQ_out/dt = P_in - P_out                  Vrest = (1 - A(t)) (Vrd - Vrs) + Vrs
    dVc/dt = Q_in - Q_out
with A(t) the activation function (option ``activation``, parameters as in
components/svzerod/activation.py).  Pressures relative to ``ref`` (ground in imported models).
Units: Emax, Emin [mmHg/mL], Vrd, Vrs [mL], Impedance L [mmHg*s^2/mL] > 0, period [s].
States: Vc [mL] (a volume store, so closed loops conserve it), Q_out [mL/s].
Q_out's scale is 0.1 mL/s, not 10: it sets the engine's difference step (1e-7 x the scale),
which must stay below the switching width of the ValveTanh it feeds (docs/svzerod.md, "Speed").
Local unknowns [P_in, P_out, P_ref, q]: branch (in, ref) with P_in - P_ref = E (Vc - Vrest)
carrying q = dVc/dt; Q_out (state) imposed from in to out, so Q_in = q + Q_out.
"""
from __future__ import annotations

import numpy as np

from hemocircuit.component import Component, Option, Param, State, kernel_method, short
from hemocircuit.elementwise import per_element
from hemocircuit.kernels.stamps import branch, imposed_flow

from ..common import E_UNIT, jit, L_UNIT, observe_first_state
from .activation import KINDS, Activated, act_parameters, activation

OWN_PARAMS = {"Emax": Param(E_UNIT, lower=0.0, doc="maximum elastance"),
        "Emin": Param(E_UNIT, lower=0.0, doc="minimum elastance"),
        "Vrd": Param("mL", doc="rest volume at diastole"),
        "Vrs": Param("mL", doc="rest volume at systole"),
        "Impedance": Param(L_UNIT, lower=0.0, lower_open=True, doc="outflow inductance L")}


# --- the equations: p = [Emax, Emin, Vrd, Vrs, Impedance, period, 13 activation parameters];
# iopt = [activation kind]; states [Vc, Q_out]; local unknowns [P_in, P_out, P_ref, q]
@jit
def cei_law(p, t, iopt):
    """(E, Vrest) at time t: E = (Emax - Emin) A + Emin, Vrest = (1 - A)(Vrd - Vrs) + Vrs."""
    a = activation(iopt[0], t, p[5], p[6:19])
    return (p[0] - p[1]) * a + p[1], (1.0 - a) * (p[2] - p[3]) + p[3]


@jit
def chamber_stamp(P, x, A, b):
    """Branch (in, ref) with P_in - P_ref = P carrying dVc/dt; Q_out = x[1] imposed in -> out."""
    branch(A, b, 0, 2, 3, P)
    imposed_flow(b, 0, 1, x[1])


@jit
def cei_stamp(p, x, u, t, iopt, A, b):
    E, Vrest = cei_law(p, t, iopt)
    chamber_stamp(E * (x[0] - Vrest), x, A, b)


@jit
def cei_derivs(p, x, u, t, iopt, dx):
    dx[0] = u[3]
    dx[1] = (u[0] - u[1]) / p[4]


@jit
def cei_report(p, x, u, t, iopt, out):
    out[0] = x[0]  # Vc
    out[1] = u[3] + x[1]  # Q_in
    out[2] = x[1]  # Q_out


class ChamberElastanceInductor(Activated, Component):
    type_name = "chamber_elastance_inductor"
    svzerod_blocks = ("ChamberElastanceInductor",)
    parameters = {**OWN_PARAMS, **act_parameters()}
    options = {"activation": Option("half_cosine", choices=KINDS, doc="activation function A(t)")}
    kernel = kernel_method(cei_stamp, cei_derivs, observe_first_state, ("Vc",), report=cei_report)
    BRANCHES = (("in", "ref"),)
    EDGES = (("in", "ref", "pressure"), ("in", "out", "flow"))
    STATES = (*Activated.STATES, State("Q_out", "mL/s", 0.1, "outflow (inductor)"))

    def dc_stamp(self, p, A_loc, b_loc, keep):
        """Steady state: the store open (Activated), the inductor a short (as the inductor component)."""
        return short(*super().dc_stamp(p, A_loc, b_loc, keep))

    def volume(self, p, P):
        """Vc with P(Vc, t = 0) = P [mmHg]: P / E + Vrest."""
        law = per_element(cei_law, self, p, 0.0)  # [E, Vrest] at t = 0
        return P / law[..., 0] + law[..., 1]

    def initial_states(self, p, u, flows=None, x=None):
        Vc = self.volume(p, u[..., 0] - u[..., 2])
        out = np.zeros(Vc.shape + (2,))
        out[..., 0] = Vc
        if flows is not None:
            out[..., 1] = -flows[..., 1]
        return out

