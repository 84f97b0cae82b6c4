"""Well-mixed tracer pools: dissolved species (NO) carried by the blood, exchanged and decaying.

Thesis section "Downstream Transport of NO" (eqs. dcvdt, dctdt, cinv); the model, its two
unit readings and their steady states are in docs/downstream_no.md.  Neither type changes the
hydraulics:

``tracer_pool``  nodes [a, b]: a perfused pool (venous blood) whose terminals are an ideal flow
                 meter in its inflow path (a branch with P_a - P_b = 0 carrying q [mL/s]).
``tissue_pool``  no nodes: a stagnant pool (the tissue), coupled only through its wall.

State C [M], also the state-only observable C (pools follow each other through expressions,
``C_x: "= NOt.C"``).  SI inside: q [m^3/s] = flow [mL/s] * 1e-6, V [m^3]; q+ = max(q, 0).
``units_reading: consistent`` (default):
  perfused:  V dC/dt = q+ (C_feed - C) - k_d V C - h l (C - C_x)
  tissue:    V dC/dt =                   - k_d V C - h l (C - C_x)
  C_feed = (C_inf - C_0) (1 - exp(-x)) + C_0,   x = k_feed L_feed n_feed / q  (eq. cinv; inf at q <= 0)
``units_reading: thesis`` (MODEL_NOTES "Downstream NO"): eqs. dcvdt/dctdt as printed, every
quantity read as its SI number: no V on the decay (k_d C), no l on the exchange (h (C - C_x)),
and x = k_feed L_feed / q.  Option ``scale`` [M]: C's natural size (solver tolerances).
"""
from __future__ import annotations

import math

import numpy as np

from hemocircuit.component import Component, Observable, Option, Param, State, kernel_method
from hemocircuit.elementwise import per_element
from hemocircuit.kernels.stamps import branch
from hemocircuit.kernels.stateless import no_stamp
from hemocircuit.units import M3_PER_ML

from .arteriole.equations import outlet_concentration
from .common import jit as _jit, observe_first_state

#: smallest pool volume used as a divisor [m^3] (a collapsed compliance reports V = 0)
_V_FLOOR = 1e-15


#: the parameters of both pools
_COMMON_PARAMETERS = {
    "V": Param("mL", lower=0.0, doc="pool volume (e.g. '= Cv.V', or a constant)"),
    "k_d": Param("1/s", default="0 1/s", lower=0.0, doc="first-order decay rate of the tracer in the pool"),
    "h": Param("m**2/s", default="0 m**2/s", lower=0.0,
               doc="wall transfer coefficient per unit vessel length (thesis h_wv)"),
    "l": Param("m", default="0 m", lower=0.0,
               doc="length of exchanging vessel (consistent reading only): conductance h*l"),
    "C_x": Param("M", default="0 M", lower=0.0, doc="concentration across the wall (e.g. '= NOt.C')"),
}


# --- the equations (hemocircuit.kernels contract): iopt = [thesis]; p in the ``parameters``
# order (the last five tracer_pool's); tracer_pool's local unknowns [P_a, P_b, q] (q: a -> b)
_V, _K_D, _H, _L, _C_X, _C_0, _C_INF, _K_FEED, _L_FEED, _N_FEED = range(10)


@_jit
def _pool_volume(p):
    """The pool volume [m^3], at least _V_FLOOR (NaN stays NaN)."""
    v = p[_V] * M3_PER_ML
    if v < _V_FLOOR:
        v = _V_FLOOR
    return v


@_jit
def _pool_loss(p, vol, thesis):
    """(D, G): decay and wall conductances [m^3/s] (thesis reading: the bare k_d, h)."""
    if thesis:
        return p[_K_D], p[_H]
    return p[_K_D] * vol, p[_H] * p[_L]


@_jit
def tracer_feed(p, q, thesis):
    """C_feed [M] (eq. cinv) for the metered flow q [mL/s]."""
    qs = q * M3_PER_ML
    K = p[_K_FEED] * p[_L_FEED] * (1.0 if thesis else p[_N_FEED])
    x = K / qs if qs > 0 else math.inf
    return outlet_concentration(p[_C_INF], p[_C_0], x)


@_jit
def tracer_balance(p, q, iopt):
    """(a, b, V): V dC/dt = a - b C [mol/s per (mol/L)] of the perfused pool at flow q [mL/s]."""
    thesis = iopt[0] != 0
    qp = q
    if qp < 0.0:  # q+ = max(q, 0): NaN stays NaN
        qp = 0.0
    qp = qp * M3_PER_ML
    vol = _pool_volume(p)
    D, G = _pool_loss(p, vol, thesis)
    return qp * tracer_feed(p, q, thesis) + G * p[_C_X], qp + D + G, vol


@_jit
def tracer_stamp(p, x, u, t, iopt, A, b):
    branch(A, b, 0, 1, 2, 0.0)  # ideal meter: P_a - P_b = 0


@_jit
def pool_rate(a, b, vol, C):
    """dC/dt [M/s] of a pool's balance V dC/dt = a - b C (both pools)."""
    return (a - b * C) / vol


@_jit
def tracer_derivs(p, x, u, t, iopt, dx):
    a, bb, vol = tracer_balance(p, u[2], iopt)
    dx[0] = pool_rate(a, bb, vol, x[0])


@_jit
def tracer_report(p, x, u, t, iopt, out):
    out[0] = x[0]  # C
    out[1] = tracer_feed(p, u[2], iopt[0] != 0)  # C_feed


@_jit
def tissue_balance(p, iopt):
    """(a, b, V): V dC/dt = a - b C of the stagnant pool."""
    vol = _pool_volume(p)
    D, G = _pool_loss(p, vol, iopt[0] != 0)
    return G * p[_C_X], D + G, vol


@_jit
def tissue_derivs(p, x, u, t, iopt, dx):
    a, bb, vol = tissue_balance(p, iopt)
    dx[0] = pool_rate(a, bb, vol, x[0])


class _Pool(Component):
    """Shared part: state C, wall exchange and decay, the two unit readings."""

    options = {
        "units_reading": Option("consistent", choices=("consistent", "thesis"),
                                doc="'consistent' (SI, default) or 'thesis' (its numbers; MODEL_NOTES)"),
        "scale": Option(1e-12, kind=float, lower=0.0, lower_open=True, upper=1e3, unit="M",
                        doc="natural size of C [M] (solver tolerances); a number, 0 < scale <= 1e3"),
    }
    OBSERVABLES = (Observable("C", "M", "tracer concentration in the pool", state_only=True),)

    def states(self):
        return (State("C", "M", self.opts["scale"], "tracer concentration in the pool"),)

    def _thesis(self):
        return self.opts["units_reading"] == "thesis"

    def kernel_options(self):
        """[units_reading 'thesis' (0|1)]; ``scale`` only sets tolerances, the kernel ignores it."""
        return np.array([int(self._thesis())], dtype=np.int64)

    def check(self, p):
        if self._thesis() or "h" not in p or "l" not in p:
            return []
        if np.any((p["h"] > 0) & (p["l"] <= 0)):
            return [(0, "wall exchange h > 0 needs the exchanging vessel length l > 0 "
                        "(conductance h*l; units_reading: consistent)")]
        return []


class TracerPool(_Pool):
    """Perfused well-mixed pool (venous blood, thesis eq. dcvdt) fed through a flow meter a -> b.

    Flows [mL/s], volume [mL], concentrations [M]; see the module docstring for the equations.
    """

    type_name = "tracer_pool"
    terminals = ("a", "b")
    role = "pressure"
    parameters = {
        **_COMMON_PARAMETERS,
        "C_0": Param("M", default="0 M", lower=0.0, doc="concentration entering the feeding bed (eq. cinv C_in)"),
        "C_inf": Param("M", default="0 M", lower=0.0, doc="far-downstream limit of the feeding bed (e.g. '= art.Cb_inf')"),
        "k_feed": Param("m**2/s", default="0 m**2/s", lower=0.0,
                        doc="loss per unit length in the feeding bed (e.g. '= art.k_NO')"),
        "L_feed": Param("m", default="0 m", lower=0.0, doc="length of the feeding tubes (e.g. '= art.L')"),
        "n_feed": Param("dimensionless", default="1", lower=0.0, lower_open=True,
                        doc="number of feeding tubes in parallel (e.g. '= art.n'; consistent reading only)"),
    }
    kernel = kernel_method(tracer_stamp, tracer_derivs, observe_first_state, ("C",), report=tracer_report)
    BRANCHES = (("a", "b"),)
    EDGES = (("a", "b", "pressure"),)
    OBSERVABLES = (*_Pool.OBSERVABLES, Observable("C_feed", "M", "concentration of the inflow (eq. cinv, C_in,v)"))

    def initial_states(self, p, u, flows=None, x=None):
        return _steady(per_element(tracer_balance, self, p, u[..., 2]))


class TissuePool(_Pool):
    """Stagnant well-mixed pool (tissue around the veins, thesis eq. dctdt); no nodes.

    Volume [mL], concentrations [M]; see the module docstring for the equations.
    """

    type_name = "tissue_pool"
    terminals = ()
    parameters = dict(_COMMON_PARAMETERS)
    kernel = kernel_method(no_stamp, tissue_derivs, observe_first_state, ("C",))
    EDGES = ()

    def initial_states(self, p, u, flows=None, x=None):
        return np.broadcast_to(_steady(per_element(tissue_balance, self, p)), u.shape[:2] + (1,))


def _steady(balance):
    """The steady concentration a/b (0 where b <= 0) of V dC/dt = a - b C from the kernel's
    balance [a, b, V] of every element, as the states (B, E, 1)."""
    a, b = balance[..., 0], balance[..., 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        c = np.where(b > 0, a / np.where(b > 0, b, 1.0), 0.0)
    return np.nan_to_num(c)[..., None]
