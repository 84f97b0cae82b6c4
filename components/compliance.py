"""Compliances (vascular volume stores).  State: stored volume V [mL].

``compliance``      linear:       P(node) - P(ref) = (V - V0)/C
``log_compliance``  Payne06 (thesis eqs. Cv, P2; Payne 2006 eqs. 5-6):
                    V = Vn + ln(dP - P0)/k,  C = dV/d(dP) = 1/(k (dP - P0)),
                    i.e. dP = P0 + exp(k (V - Vn)), defined for every V (no log of a pressure).
Both are pressure-defining branches whose flow fills the store: dV/dt = flow node -> ref.
``clamp_at_zero`` (log law, default true; MODEL_NOTES "compartments collapse"): the volume
cannot fall below 0 -- at the limit its derivative is held at zero.
"""
from __future__ import annotations

import math

import numpy as np

from hemocircuit.component import Component, Observable, Option, Param, State, Storage, kernel_method, open_branches
from hemocircuit.kernels.jit import equation
from hemocircuit.kernels.stamps import branch

from .common import jit as _jit


# --- the equations (hemocircuit.kernels contract) -------------------------------------------
# Local unknowns [P_node, P_ref, q] (q: flow node -> ref through the store), state [V] (mL).
# p: compliance [C, V0]; log_compliance [k, P0, Vn].  iopt: [clamp_at_zero, extended].
# Observables (state-only, in order): V, C.
#: the log law is continued linearly below dP - P0 = EPS [mmHg] while solving for a steady state
EPS = 1e-3
_LOGEPS = float(np.log(EPS))  # compile-time constant of the kernels


@_jit
def store_derivs(p, x, u, t, iopt, dx):
    q = u[2]
    if iopt[0] != 0 and x[0] <= 0.0 and q < 0.0:
        q = 0.0
    dx[0] = q


@_jit
def _observed_volume(V, iopt):
    if (iopt[0] != 0 or iopt[1] != 0) and V < 0.0:  # np.maximum(V, 0): NaN stays NaN
        return 0.0
    return V


@_jit
def linear_stamp(p, x, u, t, iopt, A, b):
    branch(A, b, 0, 1, 2, (x[0] - p[1]) / p[0])  # P_node - P_ref = (V - V0)/C


@_jit
def linear_observe(p, x, iopt, out):
    V = x[0]
    out[0] = _observed_volume(V, iopt)
    out[1] = p[0] + 0.0 * V


@_jit
def _exp_clipped(a):
    if a > 700.0:  # np.minimum(a, 700): NaN stays NaN
        a = 700.0
    return math.exp(a)


@equation(cache=True, nogil=True, error_model="numpy", _nrt=False)
def linear_below(k, Vn):
    """V_eps = Vn + ln(EPS) / k [mL]: where dP - P0 = EPS, below which the log law is continued
    linearly (the extended law, the compliance's floor).  Compiled in the kernels, numpy arrays
    from Python (the inverse law)."""
    return Vn + _LOGEPS / k


@_jit
def log_pressure(k, P0, Vn, V, extended):
    """dP = P0 + exp(k (V - Vn)) (thesis eqs. Cv, P2), continued linearly below dP - P0 = EPS."""
    V_eps = linear_below(k, Vn)
    if not extended or V >= V_eps:  # extended: then np.maximum(V, V_eps) is V
        return P0 + _exp_clipped(k * (V - Vn))
    return P0 + EPS * (1 + k * (V - V_eps))


@_jit
def log_stamp(p, x, u, t, iopt, A, b):
    branch(A, b, 0, 1, 2, log_pressure(p[0], p[1], p[2], x[0], iopt[1] != 0))


@_jit
def log_observe(p, x, iopt, out):
    k, Vn = p[0], p[2]
    V = x[0]
    out[0] = _observed_volume(V, iopt)
    V_eps = linear_below(k, Vn)
    if V >= V_eps:
        out[1] = math.exp(-k * (V - Vn)) / k
    else:
        out[1] = 1.0 / (k * EPS)


class _Store(Component):
    terminals = ("node", "ref")
    role = "pressure"
    options = {"clamp_at_zero": Option(False, kind=bool, doc="hold V >= 0 (dV/dt = 0 at the limit)")}
    BRANCHES = (("node", "ref"),)
    STATES = (State("V", "mL", 1.0, "stored volume"),)
    STORAGES = (Storage("node", "ref", "V", state="V"),)
    OBSERVABLES = (Observable("V", "mL", "stored volume", state_only=True),
                   Observable("C", "mL/mmHg", "compliance dV/dP", state_only=True))

    def physical_limits(self):
        """A stored volume is not negative (mL)."""
        return {"V": (0.0, None)}

    def dc_stamp(self, p, A_loc, b_loc, keep):
        """Open: the branch flow is 0 (except on the stores in ``keep``)."""
        return open_branches(A_loc, b_loc, (2,), keep)

    def limited_states(self, p, x, rtol=1e-6):
        """A clamped store collapsed to V <= 0 (the steady variant continues it below 0)."""
        out = super().limited_states(p, x, rtol)
        if self.opts["clamp_at_zero"]:
            out[..., 0] |= x[..., 0] <= 0.0
        return out

    def initial_states(self, p, u, flows=None, x=None):
        return self.volume(p, u[..., 0] - u[..., 1])[..., None]

    def kernel_options(self):
        """[clamp_at_zero (0|1), extended (0|1)] (``extended`` is always 0 for the linear law)."""
        return np.array([int(bool(self.opts["clamp_at_zero"])), int(bool(self.opts.get("extended", False)))],
                        dtype=np.int64)


class LinearCompliance(_Store):
    """Linear compliance C [mL/mmHg] with unstressed volume V0 [mL]."""

    type_name = "compliance"
    parameters = {"C": Param("mL/mmHg", lower=0.0, lower_open=True, doc="compliance"),
                  "V0": Param("mL", default="0 mL", doc="unstressed volume")}
    kernel = kernel_method(linear_stamp, store_derivs, linear_observe, ("V", "C"))

    def volume(self, p, dP):
        """The inverse law V(dP) (the DC guess's state): V0 + C dP."""
        return p["V0"] + p["C"] * dP


class LogCompliance(_Store):
    """Payne06 logarithmic compliance: V = Vn + ln(dP - P0)/k, k [1/mL] > 0."""

    type_name = "log_compliance"
    parameters = {"k": Param("1/mL", lower=0.0, lower_open=True, doc="stiffness coefficient"),
                  "P0": Param("mmHg", doc="pressure offset (P_v1, P_a1)"),
                  "Vn": Param("mL", doc="volume offset (V_vn, V_an)")}
    options = {"clamp_at_zero": Option(True, kind=bool, doc="hold V >= 0 (dV/dt = 0 at the limit)"),
               "extended": Option(False, kind=bool, doc="continue the law linearly below dP - P0 = EPS")}
    #: steady states follow the thesis (section brainSS): pressures from the resistive network
    #: even where dP <= P0 (a collapsed compartment, reported with V = 0), so the law is
    #: continued linearly below dP - P0 = EPS while solving, and the clamp is off
    steady_opts = {"clamp_at_zero": False, "extended": True}
    kernel = kernel_method(log_stamp, store_derivs, log_observe, ("V", "C"))

    def volume(self, p, dP):
        """The inverse law V(dP) (the DC guess's state), continued linearly below EPS as log_pressure."""
        k, P0, Vn = p["k"], p["P0"], p["Vn"]
        e = dP - P0
        V_eps = linear_below(k, Vn)
        return np.where(e >= EPS, Vn + np.log(np.maximum(e, EPS)) / k, V_eps + (e / EPS - 1) / k)
