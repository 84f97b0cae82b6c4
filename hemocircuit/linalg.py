"""Small dense linear algebra, compiled: the one LU of the project.

``lu_factor`` / ``lu_factor_at`` / ``lu_apply`` are Gaussian elimination with partial pivoting
on the leading m x m block of a matrix, in place.  The compiled engine (hemocircuit.kernels:
the nodal solve, its static condensation, the element-local Jacobian, the Rosenbrock and BDF
iteration matrices) calls them, and so does :func:`solve_batched` below: one definition.  They
are compiled (``kernels.jit.njit``: numba imported when a compiled caller needs them) without
reference counting (they never allocate) and with numpy's error model (a division by zero gives
inf/nan); called from Python before that, they run as the Python functions they are.

``solve_batched(A, b)`` solves A[i] u[i] = b[i] for a stack of small matrices (the nodal
equations of the batched numpy path).  For many rows it runs compiled once numba is loaded (or
enough rows pay for loading it: NUMBA_AMORTISED_ROWS), about twice as fast as
``np.linalg.solve`` for the 13x13-ish systems of a circuit evaluated for hundreds of batch
rows; otherwise numpy.
"""
from __future__ import annotations

import sys

import numpy as np

from .kernels.jit import njit

#: how the LU functions are compiled: no allocation (no reference counting), numpy's error
#: model (as the engine's functions)
_COMPILED = dict(cache=True, nogil=True, error_model="numpy", _nrt=False)


@njit(**_COMPILED)
def lu_factor_at(W, piv, m):
    """In-place LU with partial pivoting of the leading m x m block of W (multipliers below the
    diagonal, rows swapped as they go, pivot rows in ``piv``).  Returns -1 on success or the
    column where no nonzero pivot was left."""
    for c in range(m):
        p = c
        best = abs(W[c, c])
        for r in range(c + 1, m):
            v = abs(W[r, c])
            if v > best:
                best, p = v, r
        piv[c] = p
        if best == 0.0:
            return c
        if p != c:
            for j in range(m):
                tmp = W[c, j]
                W[c, j] = W[p, j]
                W[p, j] = tmp
        inv = 1.0 / W[c, c]
        for r in range(c + 1, m):
            W[r, c] *= inv
            f = W[r, c]
            if f != 0.0:
                for j in range(c + 1, m):
                    W[r, j] -= f * W[c, j]
    return -1


@njit(**_COMPILED)
def lu_factor(W, piv, m):
    """:func:`lu_factor_at`, True when W is regular.  (The nodal system uses it with m = n,
    leaving out the ground slot; the integrators' iteration matrices with m = nx.)"""
    return lu_factor_at(W, piv, m) < 0


@njit(**_COMPILED)
def lu_apply(W, piv, v, m):
    """Solve with the factors of :func:`lu_factor` (size m), in place on v[:m]."""
    for c in range(m):
        p = piv[c]
        if p != c:
            tmp = v[c]
            v[c] = v[p]
            v[p] = tmp
    for i in range(m):
        s = v[i]
        for j in range(i):
            s -= W[i, j] * v[j]
        v[i] = s
    for i in range(m - 1, -1, -1):
        s = v[i]
        for j in range(i + 1, m):
            s -= W[i, j] * v[j]
        v[i] = s / W[i, i]


@njit(cache=True, nogil=True)
def _solve_nb(A, b):
    """u[k] with A[k] u[k] = b[k] for every k (:func:`lu_factor`, :func:`lu_apply`); NaN rows
    where A[k] is singular."""
    m, n, _ = A.shape
    out = np.empty((m, n))
    a = np.empty((n, n))
    x = np.empty(n)
    piv = np.empty(n, dtype=np.int64)
    for k in range(m):
        for i in range(n):
            x[i] = b[k, i]
            for j in range(n):
                a[i, j] = A[k, i, j]
        if lu_factor(a, piv, n):
            lu_apply(a, piv, x, n)
            for i in range(n):
                out[k, i] = x[i]
        else:
            for i in range(n):
                out[k, i] = np.nan
    return out


#: below this many rows numpy's LAPACK is used
NUMBA_MIN_ROWS = 64
#: ... and above it too until numba is loaded in this process anyway or this many rows have
#: been solved: the first numba call costs ~0.4 s (its import and runtime start), which the
#: compiled solve (~0.7 us a row faster than LAPACK's for n ~ 13) pays back after ~5e5 rows,
#: more than a short analysis such as a batch ``op`` solves
NUMBA_AMORTISED_ROWS = 500_000
_rows = [0]  # rows solved in this process


def solve_batched(A, b):
    """u with A[i] @ u[i] = b[i]; A (m, n, n), b (m, n).  Singular rows give NaN."""
    _rows[0] += len(A)
    if len(A) >= NUMBA_MIN_ROWS and ("numba" in sys.modules or _rows[0] >= NUMBA_AMORTISED_ROWS):
        return _solve_compiled(A, b)
    try:
        return np.linalg.solve(A, b[..., None])[..., 0]
    except np.linalg.LinAlgError:
        return _solve_compiled(A, b)


def _solve_compiled(A, b):
    # the numba dispatcher itself: a lazy one called from Python would run the Python function
    return _solve_nb.dispatcher(np.ascontiguousarray(A, dtype=float), np.ascontiguousarray(b, dtype=float))
