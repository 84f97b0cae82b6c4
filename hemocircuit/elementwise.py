"""A component's per-element functions evaluated over a batch: the numpy path's entry to the
one definition of each element's equations (its :class:`~hemocircuit.kernels.Kernel`).

The compiled engine runs a type's kernel functions inside numba; every other path (the
operating point, linearisation, the outputs, the batched integrator, a component check) calls
the same functions here over the (B, E) batch of a circuit's group.  From :data:`LOOP_CALLS`
element calls on, the group is one call of a compiled loop over its elements
(:mod:`hemocircuit.kernels.loops`).  Smaller batches call the functions element by element, as
Python (no numba import, no compile: ``op`` and ``check`` start at once) or compiled once numba
has compiled the function anyway.  A call that Python refuses where numba's numpy error model
gives inf or NaN (``math.exp`` overflowing, ``math.log(0)``) is run compiled, so both give the
same number.

Shapes as :mod:`hemocircuit.component`: ``p`` {name: (1 or B, E)}, ``x`` (B, E, S), ``u``
(B, E, L) or None, ``t`` a float or (B, 1) times, ``src`` (B, E) waveform values or None.
"""
from __future__ import annotations

import sys

import numpy as np

from .kernels.jit import LazyDispatcher
from .kernels.loops import loop, ready

#: element calls from which a group runs in one compiled loop (kernels.loops: ~0.01 us of
#: overhead an element against ~5 us for a call from Python, ~40 us for the arteriole's
#: equations run as Python; the loop's compile, ~0.1-0.5 s, is loaded from numba's cache after
#: the first run, ~50 ms)
LOOP_CALLS = 64
#: ... provided the loop is compiled or in numba's cache (kernels.loops.ready), or this process
#: has made this many calls of the function in groups that large: a first short run's outputs
#: (101 rows) take ~5 ms as Python against ~0.9 s of compiling their loops, while a large
#: circuit's right-hand side (a 3 000-element ladder) compiles its loops at its 4th evaluation
LOOP_COMPILE_CALLS = 10_000
_seen: dict = {}  # (kernel function, loop kind) -> [element calls so far, loop ready or None: not asked]


def _looped(fn, kind, calls) -> bool:
    """Run a group of ``calls`` element calls of ``fn`` as one compiled loop?  A cached loop is
    used once numba is loaded in this process anyway: loading numba for it (~0.3 s with its
    runtime) costs more than a short analysis's element calls as Python (a first batch
    operating point: 0.6 -> 0.2 s)."""
    if calls < LOOP_CALLS:
        return False
    seen = _seen.get((fn, kind))
    if seen is None:
        seen = _seen[(fn, kind)] = [0, None]
    seen[0] += calls
    if seen[1] is None and "numba" in sys.modules:
        seen[1] = ready(fn, kind)
    return bool(seen[1]) or seen[0] >= LOOP_COMPILE_CALLS

_PYTHON_REFUSES = (OverflowError, ZeroDivisionError, ValueError)


def _runner(fn):
    """The callable for element-by-element calls of kernel function ``fn``: a lazy dispatcher
    (hemocircuit.kernels.jit) runs as Python until numba has compiled it anyway."""
    if not isinstance(fn, LazyDispatcher):  # a plain numba dispatcher, or a plain Python function
        return fn
    return fn.dispatcher if fn.compiled else fn.py_func


def _call(fn, run, args):
    """run(*args), redone compiled where Python raises what numba's error model would not."""
    try:
        return run(*args)
    except _PYTHON_REFUSES:
        if not isinstance(fn, LazyDispatcher) or run is fn.dispatcher:
            raise
        return fn.dispatcher(*args)


def per_element(fn, comp, p, *args):
    """``fn(p_e, *args_e, iopt)`` for every element of a batch: how a Python-side hook (a DC
    guess, an initial state) reaches a law that only a kernel helper defines (an activation,
    an elastance).  ``p`` {name: (1 or B, E)} is stacked in ``comp.parameters`` order,
    ``args`` are numbers or arrays broadcast with it, ``iopt`` the type's kernel options.
    Returns (B, E) floats, or (B, E, k) for a k-tuple result."""
    names = list(comp.parameters)
    shape = np.broadcast_shapes(*(np.shape(p[n]) for n in names), *(np.shape(a) for a in args))
    P = np.stack([np.broadcast_to(np.asarray(p[n], float), shape) for n in names], axis=-1)
    A = [np.broadcast_to(np.asarray(a, float), shape) for a in args]
    iopt, run = comp.kernel_options(), _runner(fn)
    with np.errstate(all="ignore"):
        rows = [_call(fn, run, (P[idx], *(v[idx] for v in A), iopt)) for idx in np.ndindex(shape)]
    return np.array(rows, dtype=float).reshape(shape + (np.shape(rows[0]) if rows else ()))


def _contiguous(a, shape):
    """``a`` broadcast to ``shape`` as a C-contiguous array (``a`` itself when it is one)."""
    if a.shape == shape and a.flags.c_contiguous:
        return a
    return np.ascontiguousarray(np.broadcast_to(a, shape))


class Batch:
    """The (B, E) element arguments of one group, laid out for the kernel functions."""

    def __init__(self, comp, p, x, u=None, t=0.0, src=None):
        names = comp.parameters
        x = np.asarray(x, dtype=float)
        shapes = {np.shape(p[n]) for n in names}
        shapes.add(x.shape[:2])
        if u is not None:
            shapes.add(np.shape(u)[:2])
        if src is not None:
            shapes.add(np.shape(src))
        tt = np.asarray(t, dtype=float)
        if tt.ndim:
            shapes.add((tt.size, 1))
        B, E = shapes.pop() if len(shapes) == 1 else np.broadcast_shapes(*shapes)
        self.B, self.E = B, E
        P = np.empty((B, E, max(len(names), 1)))
        for j, n in enumerate(names):
            P[:, :, j] = p[n]
        if src is not None:
            # a waveform's value adds to the parameter it is given on (Component.waveform_params:
            # one per element), as the engine does before it calls the kernel
            P[:, :, list(names).index(comp.waveform_params[0])] += src
        self.P = P
        S = len(comp.states())
        self.X = _contiguous(x, (B, E, S))
        self.L = len(comp.local_nodes) + len(comp.branches())
        # no local unknowns (elements affine in the pressures): one zero row serves every call
        self.U = np.zeros((1, 1, self.L)) if u is None else _contiguous(np.asarray(u, dtype=float), (B, E, self.L))
        self.u_given = u is not None
        self.T = _contiguous(tt.reshape(-1), (B,)) if tt.ndim else np.full(B, float(tt))
        self.iopt = comp.kernel_options()
        self.S = S

    def members(self, *outs):
        """(p, x, u, t, out rows...) of every element call, element by element: rows taken by
        iterating the arrays (C speed: ~1 us a call less than indexing, 10 001 rows x 6 groups
        of a transient's outputs took 0.3 s)."""
        U, given = self.U, self.u_given
        T = self.T.tolist()
        for e in range(self.E):
            us = U[:, e] if given else [U[0, 0]] * self.B
            yield from zip(self.P[:, e], self.X[:, e], us, T, *(o[:, e] for o in outs))


def kernel_of(comp):
    """The component's kernel, or a clear error naming the type (a type without one must keep
    its own numpy hooks: hemocircuit.component)."""
    k = comp.kernel()
    if k is None:
        from .errors import HemocircuitError
        raise HemocircuitError(f"component type '{comp.type_name}' has no kernel (Component.kernel): write its "
                               "equations as kernel functions (docs/components.md), or override the numpy hooks")
    return k


def stamp(comp, p, x, u, t, src=None):
    """(A_loc (B, E, L, L), b_loc (B, E, L)) from the kernel's ``stamp``."""
    k = kernel_of(comp)
    bt = Batch(comp, p, x, u, t, src)
    L = bt.L
    A = np.zeros((bt.B, bt.E, L, L))
    b = np.zeros((bt.B, bt.E, L))
    if _looped(k.stamp, "stamp", bt.B * bt.E):
        loop(k.stamp, "stamp")(bt.P, bt.X, bt.U, bt.T, bt.iopt, A, b)
        return A, b
    run = _runner(k.stamp)
    with np.errstate(all="ignore"):
        for pe, xe, ue, te, Ae, be in bt.members(A, b):
            _call(k.stamp, run, (pe, xe, ue, te, bt.iopt, Ae, be))
    return A, b


def derivatives(comp, p, x, u, t, src=None):
    """dx/dt (B, E, S) from the kernel's ``derivs`` (zeros for a legacy type without states)."""
    if not comp.states():
        return np.zeros(np.shape(x))
    k = kernel_of(comp)
    bt = Batch(comp, p, x, u, t, src)
    dx = np.zeros((bt.B, bt.E, bt.S))
    if _looped(k.derivs, "one", bt.B * bt.E):
        loop(k.derivs, "one")(bt.P, bt.X, bt.U, bt.T, bt.iopt, dx)
        return dx
    run = _runner(k.derivs)
    with np.errstate(all="ignore"):
        for pe, xe, ue, te, dxe in bt.members(dx):
            _call(k.derivs, run, (pe, xe, ue, te, bt.iopt, dxe))
    return dx


def observe(comp, p, x, u, t, src=None):
    """{observable: (B, E)}: the state-only ones from the kernel's ``observe`` when ``u`` is
    None, every observable from its ``report`` otherwise (``observe`` when it has none)."""
    if not comp.observables():
        return {}
    k = kernel_of(comp)
    full = u is not None and k.report is not None
    names = [o.name for o in comp.observables()] if full else list(k.observables)
    if not names:
        return {}
    bt = Batch(comp, p, x, u, t, src)
    out = np.zeros((bt.B, bt.E, len(names)))
    fn = k.report if full else k.observe
    if _looped(fn, "one" if full else "observe", bt.B * bt.E):
        if full:
            loop(fn, "one")(bt.P, bt.X, bt.U, bt.T, bt.iopt, out)
        else:
            loop(fn, "observe")(bt.P, bt.X, bt.iopt, out)
        return {n: out[..., j] for j, n in enumerate(names)}
    run = _runner(fn)
    with np.errstate(all="ignore"):
        for pe, xe, ue, te, oe in bt.members(out):
            _call(fn, run, (pe, xe, ue, te, bt.iopt, oe) if full else (pe, xe, bt.iopt, oe))
    return {n: out[..., j] for j, n in enumerate(names)}
