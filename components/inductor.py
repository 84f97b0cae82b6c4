"""Inductor (blood inertia, thesis eq. inertia): P_a - P_b = L dq/dt.  State: flow q [mL/s].

L [mmHg*s^2/mL]; for a bed of n vessels of radius r and length l: L = rho_b l / (pi r^2 n).
"""
from __future__ import annotations

import numpy as np

from hemocircuit.component import Component, Observable, Param, State
from hemocircuit.kernels.jit import njit

_jit = njit(cache=True, nogil=True, error_model="numpy", _nrt=False)  # numba imported on first use


# --- the equations (hemocircuit.kernels contract) -------------------------------------------
# p = [L], state [q], local unknowns [P_a, P_b], no options; observables (state-only): q.
@_jit
def kernel_stamp(p, x, u, t, iopt, A, b):
    b[0] = -x[0]  # imposed flow q from a to b (A stays zero)
    b[1] = x[0]


@_jit
def kernel_derivs(p, x, u, t, iopt, dx):
    dx[0] = (u[0] - u[1]) / p[0]


@_jit
def kernel_observe(p, x, iopt, out):
    out[0] = x[0]


class Inductor(Component):
    type_name = "inductor"
    terminals = ("a", "b")
    parameters = {"L": Param("mmHg*s**2/mL", lower=0.0, lower_open=True, doc="inertance")}
    role = "flow"
    matrix_params = ()  # A_loc = 0 (an imposed flow): L(r) of eq. inertia keeps the matrix constant

    def states(self):
        return (State("q", "mL/s", 10.0, "flow a -> b"),)

    def observables(self):
        return (Observable("q", "mL/s", "flow a -> b", state_only=True),)

    def dc_short(self):
        return True

    #: conductance [mL/s/mmHg] of the inductor in the DC guess (its local unknowns are the two
    #: terminal pressures only, with no branch row for an exact P_a = P_b constraint)
    DC_CONDUCTANCE = 1e6

    def dc_stamp(self, p, A_loc, b_loc, keep):
        """Short circuit: a large conductance between a and b, no imposed flow."""
        G = self.DC_CONDUCTANCE
        A_loc[..., 0, 0] += G
        A_loc[..., 0, 1] -= G
        A_loc[..., 1, 0] -= G
        A_loc[..., 1, 1] += G
        b_loc[..., :2] = 0.0
        return A_loc, b_loc

    def initial_states(self, p, u, flows=None, x=None):
        # DC: the inductor is a short circuit; its flow is what the guess network sends through it.
        return (np.zeros(u.shape[:2]) if flows is None else flows[..., 0])[..., None]

    def kernel(self):
        from hemocircuit.kernels import Kernel
        return Kernel(stamp=kernel_stamp, derivs=kernel_derivs, observe=kernel_observe, observables=("q",))
