"""Shared pieces of the svZeroDSolver blocks (components/svzerod/).

Their vessels carry a flow-dependent stenosis resistance: pressure drop (R + S|q|) q
(svZeroDSolver src/model/BloodVessel.cpp, "stenosis_resistance = stenosis_coeff * fabs(q_in)").
In the nodal equations this is a branch row  P_a - P_b - f(q) = rhs, linearised at the
current iterate q0 (f'(q0) = R + 2 S |q0|).
"""
from __future__ import annotations

import numpy as np

from hemocircuit.kernels.jit import njit

jit = njit(cache=True, nogil=True, error_model="numpy", _nrt=False)  # numba imported on first use

#: units of the blocks' parameters (the circuit's units: mmHg, mL, s)
R_UNIT = "mmHg*s/mL"
C_UNIT = "mL/mmHg"
L_UNIT = "mmHg*s**2/mL"
S_UNIT = "mmHg*s**2/mL**2"
E_UNIT = "mmHg/mL"


def batch_shape(p, *shapes):
    """(B, E) of an evaluation: the broadcast of every parameter's shape and ``shapes`` (a
    batch may vary one parameter only, e.g. a sweep or a fit's perturbation)."""
    return np.broadcast_shapes(*(np.shape(v) for v in p.values()), *shapes)


def stenosis_linearised(R, S, q0):
    """(slope, offset) of f(q) = (R + S|q|) q linearised at q0: f ~ slope q + offset."""
    a = np.abs(q0)
    return R + 2.0 * S * a, -S * a * q0


@jit
def k_stenosis_linearised(R, S, q0):
    a = abs(q0)
    return R + 2.0 * S * a, -S * a * q0


def each_element(p, names, x, t, *more):
    """Parameters ``names`` stacked (..., len(names)), states, times and ``more`` arrays
    broadcast to one (B, E) shape: (shape, P, X, T, *more), for blocks whose numpy hooks call
    their compiled per-element functions."""
    shape = batch_shape(p, x.shape[:-1], np.shape(t), *(m.shape[:-1] for m in more))
    P = np.stack([np.broadcast_to(np.asarray(p[k], float), shape) for k in names], axis=-1)
    X = np.broadcast_to(x, shape + x.shape[-1:])
    T = np.broadcast_to(np.asarray(t, float), shape)
    return (shape, P, X, T) + tuple(np.broadcast_to(m, shape + m.shape[-1:]) for m in more)


def kernel_derivatives(derivs, p, names, x, u, t):
    """dx/dt (B, E, S) from a compiled per-element ``derivs(p, x, u, t, iopt, dx)``."""
    shape, P, X, T, U = each_element(p, names, x, t, u)
    dx = np.zeros(shape + x.shape[-1:])
    for idx in np.ndindex(shape):
        derivs(np.ascontiguousarray(P[idx]), np.ascontiguousarray(X[idx]), np.ascontiguousarray(U[idx]),
               float(T[idx]), None, dx[idx])
    return dx
