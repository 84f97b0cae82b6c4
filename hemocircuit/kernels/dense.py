"""Dense output of the compiled integrators: where a step's solution is between its ends.

* :func:`hermite_basis` -- the cubic Hermite basis of (x0, h f0) and (x1, h f1) at a fraction s
  of a step h; written once for both paths (``jit.equation``: compiled into the engine, run on
  numpy arrays from Python, where s and h may be arrays);
* :func:`hermite` -- that interpolant for a state vector (the engine's output between steps of a
  method without its own dense output, and a step cut at a hard limit);
* :func:`hermite_crossing` / :func:`hermite_root` -- the first fraction where the interpolant of
  a limited state minus its bound crosses zero (bisection; the hard-limit events);
* :func:`stage_dense` -- a Rosenbrock method's own dense output from its stages
  (hemocircuit.kernels.tableaus);
* :func:`bdf_dense` -- the BDF method's interpolating polynomial of a step.

An importable module (not part of the engine template): the generated engines import these
functions (kernels.codegen), so numba compiles and caches them once for every engine.  Each is
compiled without reference counting (no allocation) and with numpy's error model, as the
engine's own functions.
"""
from __future__ import annotations

from .jit import equation, njit, select

_COMPILED = dict(cache=True, nogil=True, error_model="numpy", _nrt=False)

#: bisection halvings of the engine's event location (hermite_root): 2^-50 of the step
ROOT_HALVINGS = 50


@equation(cache=True, nogil=True, inline="always")
def hermite_basis(s, h):
    """Weights (a, b, c, d) of the cubic Hermite interpolant a x0 + b f0 + c x1 + d f1 at the
    fraction s of a step h (the slopes f are per unit time, so b and d carry h)."""
    return (1 + 2 * s) * (1 - s) ** 2, s * (1 - s) ** 2 * h, s * s * (3 - 2 * s), s * s * (s - 1) * h


@njit(**_COMPILED)
def hermite(x0, f0, x1, f1, h, s, out):
    """The cubic Hermite interpolant of (x0, f0) and (x1, f1) at the fraction s of the step h,
    into out."""
    a, b, c, d = hermite_basis(s, h)
    for i in range(x0.shape[0]):
        out[i] = a * x0[i] + b * f0[i] + c * x1[i] + d * f1[i]


@equation(cache=True, nogil=True, inline="always")
def hermite_crossing(y0, d0, y1, d1, lo, hi, halvings):
    """The fraction in [lo, hi] where the cubic with values y0 > 0 >= y1 and scaled slopes d0, d1
    (h times the rates) first crosses zero, to ``halvings`` bisections: the upper end of the
    last bracket.  Scalars compiled; numpy arrays from Python (lo, hi arrays of y0's shape)."""
    for _ in range(halvings):
        m = 0.5 * (lo + hi)
        a, b, c, d = hermite_basis(m, 1.0)
        above = a * y0 + b * d0 + c * y1 + d * d1 > 0
        lo = select(above, m, lo)
        hi = select(above, hi, m)
    return hi


@njit(**_COMPILED)
def hermite_root(y0, d0, y1, d1):
    """First fraction s in [0, 1] where the cubic (values y0 > 0 >= y1, scaled slopes d0, d1)
    crosses zero (ROOT_HALVINGS bisections)."""
    return hermite_crossing(y0, d0, y1, d1, 0.0, 1.0, ROOT_HALVINGS)


@njit(**_COMPILED)
def stage_dense(x0, x1, D, nd, s, out):
    """The method's own dense output (tableaus module docstring): (1 - s) x0 +
    s (x1 + (1 - s) (D_0 + s (D_1 + s D_2))), rows of D past nd zero."""
    for i in range(x0.shape[0]):
        p = 0.0
        for m in range(nd - 1, -1, -1):
            p = D[m, i] + s * p
        out[i] = (1 - s) * x0[i] + s * (x1[i] + (1 - s) * p)


@njit(**_COMPILED)
def bdf_dense(D, order, t_new, h, tq, y, p):
    """The BDF step's interpolating polynomial at tq (scipy BdfDenseOutput) into y, from its
    difference array D (rows 0..order) at t_new with step h; p (order,) scratch."""
    acc = 1.0
    for k in range(order):
        acc *= (tq - (t_new - h * k)) / (h * (1 + k))
        p[k] = acc
    for c in range(y.shape[0]):
        v = D[0, c]
        for k in range(order):
            v += D[k + 1, c] * p[k]
        y[c] = v
