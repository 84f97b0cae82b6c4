"""The 4-state cross-bridge kinetics of Hai & Murphy as a rate matrix (thesis sec. 4stateKM,
eqs 4state, 4stateCons): the thesis's way of solving eq 4stateSS, kept as the reference the
closed form (equations.quasi_steady) is checked against, and the phosphorylation curves of
figure figrPhospCa.  Fractions [-], rates [1/s], concentrations [M]."""
from __future__ import annotations

import numpy as np

from . import equations as eq


def k_matrix(K1, K2, p):
    """The 4x4 rate matrix of eq 4state, shape (..., 4, 4), for K1 = K6, K2 = K5 and the
    parameter vector p (equations.vector): its rows are equations.kinetics's coefficients."""
    K1, K2 = np.broadcast_arrays(np.asarray(K1, dtype=float), np.asarray(K2, dtype=float))
    cols = [eq.kinetics(K1, K2, *(np.full(K1.shape, float(i == k)) for i in range(4)), p) for k in range(4)]
    return np.stack([np.stack(np.broadcast_arrays(*c), axis=-1) for c in cols], axis=-1)


def quasi_steady_solve(K1, K2, p):
    """Eq 4stateSS solved as in the thesis (last row replaced by eq 4stateCons), batched
    np.linalg.solve: (..., 4) fractions (M, Mp, AMp, AM)."""
    A = k_matrix(K1, K2, p).copy()
    A[..., 3, :] = 1.0
    rhs = np.zeros(A.shape[:-1])
    rhs[..., 3] = 1.0
    return np.linalg.solve(A, rhs[..., None])[..., 0]


def relative_phosphorylation(Ca, cGMP, params):
    """Mp + AMp [-] at kinetic steady state (figure figrPhospCa), for [Ca], [cGMP] in M."""
    p = eq.vector(params)
    with np.errstate(divide="ignore"):
        _, Mp, AMp, _ = eq.quasi_steady(*eq.rates(np.asarray(Ca, dtype=float), np.asarray(cGMP, dtype=float),
                                                  p, False), p)
    return Mp + AMp
