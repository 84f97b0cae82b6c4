"""svZeroDSolver ``LinearElastanceChamber``: a time-varying elastance chamber (Regazzoni 2022).

Equations (SimVascular/svZeroDSolver src/model/LinearElastanceChamber.cpp,
``update_constant``, ``update_time``, ``get_elastance_values``):
    P_in = E(t) (Vc - Vrest),  E = Epass + Emax A(t);   P_in = P_out;   dVc/dt = Q_in - Q_out
with A(t) the activation function (option ``activation``, components/svzerod/activation.py).
Pressures relative to ``ref`` (ground in imported models).
Units: Emax, Epass [mmHg/mL], Vrest [mL], period [s].  State: Vc [mL] (a volume store).
Local unknowns [P_in, P_out, P_ref, q, q_out]: branch (in, ref) with P_in - P_ref =
E (Vc - Vrest) carrying q = dVc/dt, and branch (in, out) with P_in = P_out carrying Q_out.
"""
from __future__ import annotations


from hemocircuit.component import Component, Option, Param, kernel_method
from hemocircuit.elementwise import per_element
from hemocircuit.kernels.stamps import branch

from ..common import E_UNIT, jit, observe_first_state
from .activation import KINDS, Activated, act_parameters, activation


# --- the equations: p = [Emax, Epass, Vrest, period, 13 activation parameters];
# iopt = [activation kind]; state [Vc]; local unknowns [P_in, P_out, P_ref, q, q_out]
@jit
def lec_elastance(p, t, iopt):
    """E(t) = Epass + Emax A(t)."""
    return p[1] + p[0] * activation(iopt[0], t, p[3], p[4:17])


@jit
def lec_stamp(p, x, u, t, iopt, A, b):
    E = lec_elastance(p, t, iopt)
    branch(A, b, 0, 2, 3, E * (x[0] - p[2]))
    branch(A, b, 0, 1, 4, 0.0)  # P_in = P_out, carrying Q_out


@jit
def lec_derivs(p, x, u, t, iopt, dx):
    dx[0] = u[3]


@jit
def lec_report(p, x, u, t, iopt, out):
    out[0] = x[0]  # Vc
    out[1] = u[3] + u[4]  # Q_in
    out[2] = u[4]  # Q_out


class LinearElastanceChamber(Activated, Component):
    type_name = "linear_elastance_chamber"
    svzerod_blocks = ("LinearElastanceChamber",)
    parameters = {"Emax": Param(E_UNIT, lower=0.0, doc="active elastance (added at full activation)"),
                  "Epass": Param(E_UNIT, lower=0.0, lower_open=True, doc="passive elastance"),
                  "Vrest": Param("mL", doc="rest volume"),
                  **act_parameters()}
    options = {"activation": Option("piecewise_cosine", choices=KINDS, doc="activation function A(t)")}
    kernel = kernel_method(lec_stamp, lec_derivs, observe_first_state, ("Vc",), report=lec_report)
    BRANCHES = (("in", "ref"), ("in", "out"))
    EDGES = (("in", "ref", "pressure"), ("in", "out", "pressure"))

    def initial_states(self, p, u, flows=None, x=None):
        E = per_element(lec_elastance, self, p, 0.0)
        return ((u[..., 0] - u[..., 2]) / E + p["Vrest"])[..., None]

