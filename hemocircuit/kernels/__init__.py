"""Compiled kernels: the hot path (element equations, nodal solve, right-hand side, Jacobian,
stiff integration with events) as numba nopython code with an on-disk cache.

The contract a component type fulfils to run compiled is :class:`Kernel` (returned by
``Component.kernel()``): three numba ``@njit(cache=True)`` functions defined at module level
(``hemocircuit.kernels.jit.njit``, which imports numba only on first use, is what the built-in
types use; plain ``numba.njit`` works the same), each working on ONE element (the circuit kernel loops over elements, so no per-call Python):

``stamp(p, x, u, t, iopt, A, b)``
    Fill the element's local MNA stamp in place (see ``hemocircuit.component``): ``A`` (L, L)
    and ``b`` (L,) arrive zeroed.  Row j < K is the flow leaving local node j into the element
    [mL/s], row K+m the constraint of branch m.  ``u`` is the current iterate of the local
    unknowns (only meaningful for elements with ``linear_in_pressure = False``; others ignore it).
``derivs(p, x, u, t, iopt, dx)``
    dx/dt of the element's states into ``dx`` (S,), in the states' declared units per second,
    given the solved local unknowns ``u`` (L,): pressures [mmHg] of the K local nodes, then the
    M branch flows [mL/s].
``observe(p, x, iopt, out)``
    The element's *state-only* observables (those with ``Observable.state_only``), in the order
    of ``Kernel.observables``, into ``out`` -- what parameter expressions of other elements read.
``report(p, x, u, t, iopt, out)`` (optional)
    Every observable of the element, in ``Component.observables()`` order, into ``out``, given
    the solved local unknowns ``u`` (flows, stresses: what needs the pressures).  Read by the
    outputs of every analysis (hemocircuit.elementwise); without it the type's observables are
    its state-only ones.
``derivs_jac(p, x, u, t, iopt, dx, Jx, Ju) -> int`` (optional)
    ``derivs`` plus its exact partial derivatives, ``Jx[i, k]`` = d dx_i / d x_k (S, S) and
    ``Ju[i, k]`` = d dx_i / d u_k (S, L, per mmHg or mL/s); returns 1, or 0 when it does not
    apply to these options.  The engine's element-local Jacobian then uses them instead of
    differencing ``derivs`` once per state and local unknown (for the arteriole: 8 evaluations
    of its equations per Jacobian become one).  Without it, or when it returns 0, the engine
    differences ``derivs``.  Where ``derivs`` is not differentiable in a state (a clip, a
    switch), give what the engine's forward difference would take: the one-sided derivative
    towards increasing x at a kink, the forward quotient at the engine's step
    ``FD_REL * max(|x|, scale)`` across a jump (a closed heart valve's flow on its bound); the
    contract test checks this wherever its samples fall on such a point.

The arrays may be LONGER than the element needs (the engine passes reusable scratch buffers,
not slices, because a slice costs more than a small element's equations): read and write
only the first P, S, L entries (``A`` only its leading L x L block).

Arguments: ``p`` float64 (P,) the element's parameters in the order of ``Component.parameters``,
in their declared units, with waveforms and expressions already applied; ``x`` float64 (S,) the
element's states in ``Component.states()`` order; ``t`` float time [s]; ``iopt`` int64 array
from ``Component.kernel_options()`` (the structural options as integers, so one compiled kernel
serves every option combination of the type).  Shapes follow the Python-side component (L =
len(local_nodes) + len(branches), S = len(states)); a kernel reads the options to know them.

The built-in kernels are compiled with numba's ``_nrt=False`` (no reference counting of the
arrays passed: they never allocate), as are the engine's functions that call them.

These functions are the ONE definition of a type's equations: the compiled engine runs them
compiled, and every other path (operating point, linearisation, outputs, the batched numpy
integrator) calls the same functions through hemocircuit.elementwise, as Python for a few
elements (no compile) and compiled for large batches.  A legacy type without a kernel
(``kernel()`` returns None) that overrides the vectorised numpy hooks still runs, on the numpy
path only (circuits that contain one fall back to it as a whole, saying so once).
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Kernel:
    """Compiled equations of one component type (see the module docstring)."""

    stamp: object
    derivs: object
    observe: object
    #: names of the state-only observables ``observe`` writes, in order
    observables: tuple = ()
    #: optional analytic partials of ``derivs`` (see the module docstring), or None
    derivs_jac: object = None
    #: optional: every observable, given the local unknowns (see the module docstring), or None
    report: object = None
