"""One compiled call per group: a kernel function run over every (member, element) of a batch.

The numpy path (:mod:`hemocircuit.elementwise`) evaluates a group by calling the type's kernel
functions element by element; from Python that is one dispatch (~2 us) and one row of views
(~5 us) per element and call, which is most of a large circuit's right-hand side (a ladder of
3 000 elements: ~35 ms a right-hand side).  :func:`loop` returns the same function wrapped in a
compiled loop over the (B, E) batch, so a group costs one call.  The loops are numba closures
over the kernel function, cached on disk like the kernels (numba keys a closure's cache entry by
its captured values; the kernel's own file is hashed into ``salt`` so that an edited plug-in,
whose file :mod:`.freshness` does not watch, gets a new entry instead of stale machine code).

Arguments, as :class:`hemocircuit.elementwise.Batch` lays them out: ``P`` (B, E, n_params),
``X`` (B, E, S), ``U`` (B, E, L) or one shared (1, 1, L) row, ``T`` (B,), ``iopt`` the
component's int64 options, then the outputs (B, E, ...) the function fills element by element.
"""
from __future__ import annotations

import inspect
from pathlib import Path

from . import freshness

#: (kernel function, kind) -> compiled loop
_loops: dict = {}


def loop(fn, kind: str):
    """The compiled loop of kernel function ``fn``.  ``kind``: 'stamp' (fills A and b),
    'one' (derivs or report: one output), 'observe' (state-only observables: no u, no t)."""
    key = (fn, kind)
    if key not in _loops:
        _loops[key] = _make(fn, kind, _salt(fn))
    return _loops[key]


def ready(fn, kind: str) -> bool:
    """True when the compiled loop of ``fn`` runs without a compile worth waiting for: it is
    compiled in this process, or numba's cache holds loops of this kind (from an earlier run;
    a kernel whose own loop is not among them compiles it, ~0.3 s).  A process's first runs
    evaluate small groups as Python instead (hemocircuit.elementwise.LOOP_COMPILE_CALLS)."""
    from .prebuild import in_cache

    dispatcher = loop(fn, kind)
    return bool(dispatcher.signatures) or in_cache(dispatcher)


def _salt(fn) -> int:
    """A number from the text of the file that defines ``fn`` (see the module docstring)."""
    try:
        return int(freshness.key([Path(inspect.getsourcefile(getattr(fn, "py_func", fn)))])[:12], 16)
    except (OSError, TypeError):  # no source file (a function made at run time)
        return 0


def _make(fn, kind, salt):
    import numba

    opts = dict(cache=True, nogil=True, error_model="numpy")
    if kind == "stamp":
        def run(P, X, U, T, iopt, A, b):
            if salt < 0:  # never: puts the kernel file's hash into the cache key
                return
            for i in range(P.shape[0]):
                for e in range(P.shape[1]):
                    fn(P[i, e], X[i, e], U[min(i, U.shape[0] - 1), min(e, U.shape[1] - 1)], T[i], iopt,
                       A[i, e], b[i, e])
    elif kind == "one":
        def run(P, X, U, T, iopt, out):
            if salt < 0:
                return
            for i in range(P.shape[0]):
                for e in range(P.shape[1]):
                    fn(P[i, e], X[i, e], U[min(i, U.shape[0] - 1), min(e, U.shape[1] - 1)], T[i], iopt, out[i, e])
    elif kind == "observe":
        def run(P, X, iopt, out):
            if salt < 0:
                return
            for i in range(P.shape[0]):
                for e in range(P.shape[1]):
                    fn(P[i, e], X[i, e], iopt, out[i, e])
    else:
        raise ValueError(f"loop kind {kind!r}: choose 'stamp', 'one' or 'observe'")
    run.__qualname__ = f"loop_{kind}"
    return numba.njit(**opts)(run)
