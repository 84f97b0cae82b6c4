"""Linear hydraulic resistor: q = (P_a - P_b) / R  (thesis eq. Poiseuille, R = dP/Q)."""
from __future__ import annotations

from hemocircuit.component import Component, Param, two_terminal_conductance


class Resistor(Component):
    """Flow q [mL/s] from terminal ``a`` to ``b``: q = (P_a - P_b)/R, with R [mmHg*s/mL] > 0."""

    type_name = "resistor"
    terminals = ("a", "b")
    parameters = {"R": Param("mmHg*s/mL", lower=0.0, lower_open=True, doc="resistance")}
    role = "conductive"

    def stamp(self, p, x, u, t, src=None):
        return two_terminal_conductance(1.0 / p["R"])
