"""Linear hydraulic resistor: q = (P_a - P_b) / R  (thesis eq. Poiseuille, R = dP/Q)."""
from __future__ import annotations

from hemocircuit.component import Component, Param
from hemocircuit.kernels.jit import njit

_jit = njit(cache=True, nogil=True, error_model="numpy", _nrt=False)  # numba imported on first use


# --- the equations (hemocircuit.kernels contract; p = [R], no states, no options) -----------
@_jit
def kernel_stamp(p, x, u, t, iopt, A, b):
    g = 1.0 / p[0]
    A[0, 0] = g
    A[0, 1] = -g
    A[1, 0] = -g
    A[1, 1] = g


class Resistor(Component):
    """Flow q [mL/s] from terminal ``a`` to ``b``: q = (P_a - P_b)/R, with R [mmHg*s/mL] > 0."""

    type_name = "resistor"
    terminals = ("a", "b")
    parameters = {"R": Param("mmHg*s/mL", lower=0.0, lower_open=True, doc="resistance")}
    role = "conductive"

    def kernel(self):
        from hemocircuit.kernels import Kernel
        from hemocircuit.kernels.stateless import no_derivs, no_observables
        return Kernel(stamp=kernel_stamp, derivs=no_derivs, observe=no_observables, observables=())
