"""Inductor (blood inertia, thesis eq. inertia): P_a - P_b = L dq/dt.  State: flow q [mL/s].

L [mmHg*s^2/mL]; for a bed of n vessels of radius r and length l: L = rho_b l / (pi r^2 n).
"""
from __future__ import annotations

import numpy as np

from hemocircuit.component import Component, Observable, Param, State, flow_branch


class Inductor(Component):
    type_name = "inductor"
    terminals = ("a", "b")
    parameters = {"L": Param("mmHg*s**2/mL", lower=0.0, lower_open=True, doc="inertance")}
    role = "flow"

    def states(self):
        return (State("q", "mL/s", 10.0, "flow a -> b"),)

    def observables(self):
        return (Observable("q", "mL/s", "flow a -> b", state_only=True),)

    def stamp(self, p, x, u, t, src=None):
        return flow_branch(x[..., 0])

    def derivatives(self, p, x, u, t, src=None):
        return ((u[..., 0] - u[..., 1]) / p["L"])[..., None]

    def dc_short(self):
        return True

    def initial_states(self, p, u, flows=None, x=None):
        # DC: the inductor is a short circuit; its flow is what the guess network sends through it.
        return (np.zeros(u.shape[:2]) if flows is None else flows[..., 0])[..., None]

    def observe(self, p, x, u, t, src=None):
        return {"q": x[..., 0]}
