"""Inductor (blood inertia, thesis eq. inertia): P_a - P_b = L dq/dt.  State: flow q [mL/s].

L [mmHg*s^2/mL]; for a bed of n vessels of radius r and length l: L = rho_b l / (pi r^2 n).
"""
from __future__ import annotations

import numpy as np

from hemocircuit.component import Component, Observable, Param, State, kernel_method, short
from hemocircuit.kernels.stamps import imposed_flow

from .common import jit, observe_first_state


# p = [L], state [q], local unknowns [P_a, P_b]; observable (state-only): q
@jit
def kernel_stamp(p, x, u, t, iopt, A, b):
    imposed_flow(b, 0, 1, x[0])  # the state q, from a to b (A stays zero)


@jit
def kernel_derivs(p, x, u, t, iopt, dx):
    dx[0] = (u[0] - u[1]) / p[0]  # dq/dt = (P_a - P_b)/L


class Inductor(Component):
    type_name = "inductor"
    terminals = ("a", "b")
    parameters = {"L": Param("mmHg*s**2/mL", lower=0.0, lower_open=True, doc="inertance")}
    role = "flow"
    matrix_params = ()  # A_loc = 0 (an imposed flow): L(r) of eq. inertia keeps the matrix constant
    kernel = kernel_method(kernel_stamp, kernel_derivs, observe_first_state, ("q",))
    STATES = (State("q", "mL/s", 10.0, "flow a -> b"),)
    OBSERVABLES = (Observable("q", "mL/s", "flow a -> b", state_only=True),)

    def dc_short(self):
        return True

    def dc_stamp(self, p, A_loc, b_loc, keep):
        return short(A_loc, b_loc)  # a short circuit: a large conductance, no imposed flow

    def initial_states(self, p, u, flows=None, x=None):
        # DC: the inductor is a short circuit; its flow is what the guess network sends through it.
        return (np.zeros(u.shape[:2]) if flows is None else flows[..., 0])[..., None]
