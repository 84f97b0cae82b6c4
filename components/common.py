"""Shared pieces of the component types: the Block base, the nodal stamps every type builds on
(a conductance, a branch row, an imposed flow, a short), kernel declarations, and the
stenosis branch of the svZeroDSolver vessels (components/svzerod/).

Their vessels carry a flow-dependent stenosis resistance: pressure drop (R + S|q|) q
(svZeroDSolver src/model/BloodVessel.cpp, "stenosis_resistance = stenosis_coeff * fabs(q_in)").
In the nodal equations this is a branch row  P_a - P_b - f(q) = rhs, linearised at the
current iterate q0 (f'(q0) = R + 2 S |q0|).
"""
from __future__ import annotations

import sys

import numpy as np

from hemocircuit.component import Component, Observable
from hemocircuit.kernels import Kernel
from hemocircuit.kernels.jit import njit
from hemocircuit.kernels.stateless import no_derivs, no_observables

jit = njit(cache=True, nogil=True, error_model="numpy", _nrt=False)  # numba imported on first use

#: units of the blocks' parameters (the circuit's units: mmHg, mL, s)
R_UNIT = "mmHg*s/mL"
C_UNIT = "mL/mmHg"
L_UNIT = "mmHg*s**2/mL"
S_UNIT = "mmHg*s**2/mL**2"
E_UNIT = "mmHg/mL"


class Block(Component):
    """A component type whose structure does not depend on its options, declared as class
    attributes: INTERNAL_NODES, BRANCHES, STATES, STORAGES, OBSERVABLES and EDGES (None: from
    ``role``).  A subclass without a docstring takes its module's (a svZeroDSolver block's: its
    equations)."""

    INTERNAL_NODES = BRANCHES = STATES = STORAGES = OBSERVABLES = ()
    EDGES = None

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        if cls.__doc__ is None:
            cls.__doc__ = getattr(sys.modules.get(cls.__module__), "__doc__", None)

    def internal_nodes(self):
        return self.INTERNAL_NODES

    def branches(self):
        return self.BRANCHES

    def states(self):
        return self.STATES

    def storages(self):
        return self.STORAGES

    def observables(self):
        return self.OBSERVABLES

    def edges(self):
        return super().edges() if self.EDGES is None else self.EDGES


def kernel_method(stamp, derivs=no_derivs, observe=no_observables, observables=(), **optional):
    """A ``Component.kernel`` returning these kernel functions (``optional``: report, derivs_jac)."""
    k = Kernel(stamp=stamp, derivs=derivs, observe=observe, observables=observables, **optional)
    return lambda self: k


def flow_observables(into="the inlet", out="the outlet"):
    """The observables Q_in (flow into ``into``) and Q_out (flow out of ``out``) [mL/s]."""
    return (Observable("Q_in", "mL/s", f"flow into {into}"), Observable("Q_out", "mL/s", f"flow out of {out}"))


def short(A_loc, b_loc, G=1e6):
    """DC guess of an inductor from local node 0 to 1: a conductance G [mL/s/mmHg], no imposed flow
    (its local unknowns are the two pressures only, with no branch row for P_a = P_b)."""
    A_loc[..., 0, 0] += G
    A_loc[..., 0, 1] -= G
    A_loc[..., 1, 0] -= G
    A_loc[..., 1, 1] += G
    b_loc[..., :2] = 0.0
    return A_loc, b_loc


def batch_shape(p, *shapes):
    """(B, E) of an evaluation: the broadcast of every parameter's shape and ``shapes``."""
    return np.broadcast_shapes(*(np.shape(v) for v in p.values()), *shapes)


@jit
def branch(A, b, i, j, c, value, R=0.0):
    """Stamp branch c from local node i to j: its flow q (unknown c) leaves i and enters j, and
    row c says P_i - P_j - R q = value (R: a series resistance, or a linearisation's slope)."""
    A[i, c] = 1.0
    A[j, c] = -1.0
    A[c, i] = 1.0
    A[c, j] = -1.0
    A[c, c] -= R
    b[c] = value


@jit
def conductance(A, i, j, g):
    """Stamp a conductance g between local nodes i and j."""
    A[i, i] += g
    A[i, j] -= g
    A[j, i] -= g
    A[j, j] += g


@jit
def observe_first_state(p, x, iopt, out):
    """``observe`` of the types whose one state-only observable is their first state."""
    out[0] = x[0]


@jit
def imposed_flow(b, i, j, q):
    """Stamp a flow q imposed from local node i to j (an inductor's state, a wall's motion)."""
    b[i] = -q
    b[j] = q


def open_branches(A_loc, b_loc, rows, keep=None):
    """DC guess: the branches ``rows`` carry no flow, except in the elements ``keep`` (the
    stores that anchor a conservation law keep their stamp)."""
    sel = slice(None) if keep is None else ~np.asarray(keep, dtype=bool)
    for r in rows:
        A_loc[:, sel, r, :] = 0.0
        A_loc[:, sel, r, r] = 1.0
        b_loc[:, sel, r] = 0.0
    return A_loc, b_loc


def check_rmin_rmax(comp, p):
    """The valves' ``check`` method: Rmin <= Rmax."""
    bad = np.any(p["Rmax"] < p["Rmin"], axis=tuple(range(np.ndim(p["Rmin"]) - 1)))
    return [(int(i), "needs Rmin <= Rmax") for i in np.nonzero(np.atleast_1d(bad))[0]]


@jit
def stenosis_drop(R, S, q):
    """f(q) = (R + S|q|) q: the pressure drop of a resistance R with stenosis coefficient S."""
    return (R + S * abs(q)) * q


@jit
def stenosis_linearised(R, S, q0):
    """(slope, offset) of f(q) = (R + S|q|) q linearised at q0: f ~ slope q + offset."""
    a = abs(q0)
    return R + 2.0 * S * a, -S * a * q0


def per_element(fn, comp, p, *args):
    """``fn(p_e, *args_e, iopt)`` for every element of a batch, for the Python-side hooks that
    need a law the kernel functions define (an activation, an elastance): ``p`` {name: (1 or
    B, E)} stacked in ``comp.parameters`` order, ``args`` numbers or arrays broadcast with them,
    ``iopt`` the type's kernel options.  The kernel helper ``fn`` runs as Python (compiled
    where Python raises what numba's error model does not, as hemocircuit.elementwise).
    Returns (B, E) floats, or (B, E, k) for a k-tuple result."""
    names = list(comp.parameters)
    shape = np.broadcast_shapes(*(np.shape(p[n]) for n in names), *(np.shape(a) for a in args))
    P = np.stack([np.broadcast_to(np.asarray(p[n], float), shape) for n in names], axis=-1)
    A = [np.broadcast_to(np.asarray(a, float), shape) for a in args]
    iopt = comp.kernel_options()
    rows = []
    with np.errstate(all="ignore"):
        for idx in np.ndindex(shape):
            a = (P[idx], *(v[idx] for v in A), iopt)
            try:
                rows.append(fn(*a))
            except (OverflowError, ZeroDivisionError, ValueError):
                rows.append(fn.dispatcher(*a))
    return np.array(rows, dtype=float).reshape(shape + (np.shape(rows[0]) if rows else ()))
