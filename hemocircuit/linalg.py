"""Batched small dense linear solves for the nodal equations (the hot path).

``solve_batched(A, b)`` solves A[i] u[i] = b[i] for a stack of small matrices.  For many rows
it is a compiled Gaussian elimination with partial pivoting (numba, imported on first use),
several times faster than ``np.linalg.solve`` for the 8x8-ish systems of a circuit evaluated
for hundreds of batch rows; otherwise numpy.
"""
from __future__ import annotations

import numpy as np

from .kernels.jit import njit


@njit(cache=True, nogil=True)
def _solve_nb(A, b):
    m, n, _ = A.shape
    out = np.empty((m, n))
    a = np.empty((n, n))
    x = np.empty(n)
    for k in range(m):
        for i in range(n):
            x[i] = b[k, i]
            for j in range(n):
                a[i, j] = A[k, i, j]
        for c in range(n):
            p = c
            best = abs(a[c, c])
            for r in range(c + 1, n):
                v = abs(a[r, c])
                if v > best:
                    best, p = v, r
            if best == 0.0:
                for i in range(n):
                    out[k, i] = np.nan
                break
            if p != c:
                for j in range(n):
                    a[c, j], a[p, j] = a[p, j], a[c, j]
                x[c], x[p] = x[p], x[c]
            inv = 1.0 / a[c, c]
            for r in range(c + 1, n):
                f = a[r, c] * inv
                if f != 0.0:
                    for j in range(c, n):
                        a[r, j] -= f * a[c, j]
                    x[r] -= f * x[c]
        else:
            for i in range(n - 1, -1, -1):
                s = x[i]
                for j in range(i + 1, n):
                    s -= a[i, j] * out[k, j]
                out[k, i] = s / a[i, i]
    return out


#: below this many rows numpy's LAPACK is used: the first numba call of a process costs ~0.4 s
#: (numba's runtime start), more than a short analysis such as ``op`` spends in solves
NUMBA_MIN_ROWS = 64


def solve_batched(A, b):
    """u with A[i] @ u[i] = b[i]; A (m, n, n), b (m, n).  Singular rows give NaN."""
    if len(A) >= NUMBA_MIN_ROWS:
        return _solve_nb(np.ascontiguousarray(A, dtype=float), np.ascontiguousarray(b, dtype=float))
    try:
        return np.linalg.solve(A, b[..., None])[..., 0]
    except np.linalg.LinAlgError:
        return _solve_nb(np.ascontiguousarray(A, dtype=float), np.ascontiguousarray(b, dtype=float))
