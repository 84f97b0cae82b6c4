"""Linear hydraulic resistor: q = (P_a - P_b) / R  (thesis eq. Poiseuille, R = dP/Q)."""
from __future__ import annotations

from hemocircuit.component import Component, Param, kernel_method
from hemocircuit.kernels.stamps import conductance

from .common import jit


@jit
def kernel_stamp(p, x, u, t, iopt, A, b):
    """p = [R] [mmHg*s/mL]; local unknowns [P_a, P_b]: q = (P_a - P_b)/R leaves a, enters b."""
    conductance(A, 0, 1, 1.0 / p[0])


class Resistor(Component):
    """Flow q [mL/s] from terminal ``a`` to ``b``: q = (P_a - P_b)/R, with R [mmHg*s/mL] > 0."""

    type_name = "resistor"
    terminals = ("a", "b")
    parameters = {"R": Param("mmHg*s/mL", lower=0.0, lower_open=True, doc="resistance")}
    kernel = kernel_method(kernel_stamp)
