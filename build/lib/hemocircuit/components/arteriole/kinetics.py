"""4-state cross-bridge kinetics of Hai & Murphy (thesis sec. 4stateKM, eqs 4state, 4stateCons,
phos, dephos, 4stateSS).  States alpha = [M, Mp, AMp, AM] are fractions [-]; rate constants
K1..K7 in 1/s (the Hill expressions of eqs phos/dephos are read as 1/s); [Ca], [cGMP] in M.
"""
from __future__ import annotations

import numpy as np

from .myogenic import CA_FLOOR

STATES = ("M", "Mp", "AMp", "AM")


def rate_constants(Ca, cGMP, p, passive=False):
    """(K1, K2, K3, K4, K5, K6, K7) [1/s].

    K1 = K6 = Ca^nCa1 / (Ca^nCa1 + kCa1^nCa1)                                     (eq phos)
    K2 = K5 = 0.55 + 2 cGMP^ncG/(cGMP^ncG + kcG^ncG) * kCa2^nCa2/(Ca^nCa2 + kCa2^nCa2) (eq dephos)
    Ca is clipped at CA_FLOOR (never NaN for Ca <= 0); ``passive``: Ca = 0 exactly (K1 = 0)."""
    Ca = np.maximum(Ca, CA_FLOOR)
    # Hill terms written as 1/(1 + (k/x)^n): no overflow, exact for tiny x
    K1 = 1.0 / (1.0 + (p["k_Ca1"] / Ca) ** p["n_Ca1"])
    if passive:
        K1 = np.zeros_like(K1)
    ca_inhib = 1.0 / (1.0 + (Ca / p["k_Ca2"]) ** p["n_Ca2"])
    if passive:
        ca_inhib = np.ones_like(ca_inhib)
    cg = np.maximum(cGMP, 0.0)
    with np.errstate(divide="ignore"):
        cg_act = 1.0 / (1.0 + (p["k_cGMP"] / cg) ** p["n_cGMP"])  # cGMP = 0 -> 0
    K2 = 0.55 + 2.0 * cg_act * ca_inhib
    K3, K4, K7 = p["K3"], p["K4"], p["K7"]
    return K1, K2, K3, K4, K2, K1, K7


def k_matrix(K):
    """The 4x4 rate matrix of eq 4state, shape (..., 4, 4), from K = (K1..K7)."""
    K1, K2, K3, K4, K5, K6, K7 = np.broadcast_arrays(*K)
    z = np.zeros_like(K1)
    rows = [[-K1, K2, z, K7],
            [K1, -K2 - K3, K4, z],
            [z, K3, -K4 - K5, K6],
            [z, z, K5, -K6 - K7]]
    return np.stack([np.stack(r, axis=-1) for r in rows], axis=-2)


def derivative(alpha, K):
    """d alpha/dt [1/s] (eq 4state) for alpha = (M, Mp, AMp, AM) arrays and K = (K1..K7)."""
    M, Mp, AMp, AM = alpha
    K1, K2, K3, K4, K5, K6, K7 = K
    return (-K1 * M + K2 * Mp + K7 * AM,
            K1 * M - (K2 + K3) * Mp + K4 * AMp,
            K3 * Mp - (K4 + K5) * AMp + K6 * AM,
            K5 * AMp - (K6 + K7) * AM)


def quasi_steady(K):
    """Null vector of eq 4stateSS with sum 1 (eq 4stateCons), closed form, (M, Mp, AMp, AM).

    With a = K1 = K6 and b = K2 = K5 (eqs phos, dephos), the matrix-tree theorem (spanning trees
    of the M-Mp-AMp-AM cycle, AM -> M only) gives the unnormalised components
        M   = b (a K4 + K3 K7 + b K7 + K4 K7)
        Mp  = a (a K4 + b K7 + K4 K7)
        AMp = a K3 (a + K7)
        AM  = a b K3
    Passive (a = 0, b > 0): exactly [1, 0, 0, 0]."""
    a, b, K3, K4, K5, K6, K7 = K
    M = b * (a * K4 + K3 * K7 + b * K7 + K4 * K7)
    Mp = a * (a * K4 + b * K7 + K4 * K7)
    AMp = a * K3 * (a + K7)
    AM = a * b * K3
    s = M + Mp + AMp + AM
    return M / s, Mp / s, AMp / s, AM / s


def quasi_steady_solve(K):
    """Reference: eq 4stateSS solved as in the thesis (last row replaced by eq 4stateCons),
    batched np.linalg.solve.  Returns an array (..., 4)."""
    A = k_matrix(K).copy()
    A[..., 3, :] = 1.0
    rhs = np.zeros(A.shape[:-1])
    rhs[..., 3] = 1.0
    return np.linalg.solve(A, rhs[..., None])[..., 0]


def relative_phosphorylation(Ca, cGMP, p):
    """Mp + AMp [-] at kinetic steady state (figure figrPhospCa), for [Ca], [cGMP] in M."""
    _, Mp, AMp, _ = quasi_steady(rate_constants(Ca, cGMP, p))
    return Mp + AMp
