"""One finite-difference rule for every derivative the analyses take.

Step of state j: ``FD_REL * max(|x_j|, scale_j)`` (the state's natural scale from its
component), rounded so that x + h is representable; time: ``FD_REL * max(|t|, 1 s)``.  The
compiled engine uses the same rule (``FD_REL`` in kernels/engine_template.py).  Analytic
derivatives, where a component will provide them, belong here too.
"""
from __future__ import annotations

import numpy as np

FD_REL = 1e-7


def fd_steps(X, scales, rel=FD_REL):
    """Forward-difference steps (same shape as X) for states X (..., nx).  ``rel`` replaces
    FD_REL where the function differentiated is itself only accurate to a tolerance (a fit
    through an integrator with rtol: rel ~ sqrt(rtol), hemocircuit.fitting)."""
    X = np.asarray(X, dtype=float)
    h = rel * np.maximum(np.abs(X), scales)
    return (X + h) - X


def time_step(t):
    """Forward-difference step in time [s] (scalar or array)."""
    return FD_REL * np.maximum(np.abs(t), 1.0)


def dense_jacobian(fun, X, scales):
    """d fun / d x at every member of X (B, nx), all columns from ONE evaluation of the
    stacked rows (B * (nx + 1), nx).  ``fun`` maps rows (m, nx) -> (m, nx_out).
    Returns (J (B, nx_out, nx), fun(X) (B, nx_out))."""
    X = np.atleast_2d(np.asarray(X, dtype=float))
    B, nx = X.shape
    h = fd_steps(X, scales)
    stack = np.repeat(X[:, None, :], nx + 1, axis=1)
    idx = np.arange(nx)
    stack[:, idx + 1, idx] += h
    F = np.asarray(fun(stack.reshape(B * (nx + 1), nx)))
    F = F.reshape(B, nx + 1, -1)
    J = (F[:, 1:, :] - F[:, :1, :]) / h[:, :, None]  # (B, column, row)
    return np.swapaxes(J, 1, 2), F[:, 0, :]
