"""The component interface: what every element type declares and the hooks it implements.

A component type is a subclass of :class:`Component` in a module of ``hemocircuit.components``
(found by scanning that package, like Myokit plug-ins) or registered by a third party through
the entry-point group ``hemocircuit.components``.  One instance serves *all* elements of that
type that share the same options (a "group"): every hook is vectorised over the batch of
parameter sets and over the elements of the group, so the hot path dispatches once per group,
never once per element.

Array shapes in the hooks (B = batch of parameter sets, E = elements in the group):
  ``p[name]``   parameter values, shape (B, E), in the parameter's declared unit
  ``x``         the group's states, shape (B, E, S) in the states' declared units
  ``u``         local unknowns of the nodal system, shape (B, E, K + M): pressures of the
                element's K local nodes (terminals then internal nodes, mmHg) followed by
                the flows of its M pressure-defining branches (mL/s)
  ``t``         time in s (float)

Modified nodal analysis (MNA) contract: an element contributes to the global linear system
``A u = b`` through ``stamp``, returning ``(A_loc, b_loc)`` of shapes (B, E, K+M, K+M) and
(B, E, K+M).  Row j < K is the flow *leaving* local node j into the element (Kirchhoff's
current law: the sum over elements is zero); row K+m is the constraint equation of branch m
(P_plus - P_minus = E).  ``A_loc @ u - b_loc`` evaluated at the solution gives the flow the
element draws from each of its nodes, which is how element flows are reported generically.
"""
from __future__ import annotations

import math
import sys
from dataclasses import dataclass
from typing import Any

import numpy as np

from .errors import SolverError
from .kernels import Kernel
from .kernels.stateless import no_derivs, no_observables


class _Bounded:
    """Bounds shared by parameters and numeric options: ``lower``/``upper`` in ``unit``,
    ``lower_open``/``upper_open`` make them strict (R > 0); non-finite values always violate."""

    def violates(self, value: np.ndarray) -> np.ndarray:
        bad = ~np.isfinite(value)
        if self.lower is not None:
            bad |= (value <= self.lower) if self.lower_open else (value < self.lower)
        if self.upper is not None:
            bad |= (value >= self.upper) if self.upper_open else (value > self.upper)
        return bad

    def bounds_text(self) -> str:
        lo = "" if self.lower is None else f"{self.lower:g} {'<' if self.lower_open else '<='} "
        hi = "" if self.upper is None else f" {'<' if self.upper_open else '<='} {self.upper:g}"
        return f"{lo}value{hi}" + (f" [{self.unit}]" if self.unit else "") + ", finite"


@dataclass(frozen=True)
class Param(_Bounded):
    """A numeric parameter: unit, default (a string with unit, or None = required), bounds.

    Bounds are in ``unit``; ``lower_open``/``upper_open`` make them strict (R > 0).
    """

    unit: str
    default: Any = None
    lower: float | None = None
    upper: float | None = None
    lower_open: bool = False
    upper_open: bool = False
    doc: str = ""


@dataclass(frozen=True)
class Option(_Bounded):
    """A structural, non-numeric setting (changes the equations or the state list).

    Options are fixed when the circuit is assembled; changing one re-assembles.  ``kind``
    bool, int or float is checked at load (a float option written as a YAML string such as
    ``1e-20`` is read as a number); numeric options also have bounds like parameters (in
    ``unit``, which is the option's fixed unit: options take plain numbers).
    """

    default: Any
    choices: tuple | None = None
    kind: type | tuple = object
    doc: str = ""
    lower: float | None = None
    upper: float | None = None
    lower_open: bool = False
    upper_open: bool = False
    unit: str = ""


@dataclass(frozen=True)
class State:
    """A dynamic state: name, unit, and a natural scale (used for solver tolerances)."""

    name: str
    unit: str
    scale: float
    doc: str = ""


@dataclass(frozen=True)
class Observable:
    """A quantity the element reports (name, unit).  ``state_only``: needs no pressures,
    so other elements' parameters may follow it (see netlist expressions)."""

    name: str
    unit: str
    doc: str = ""
    state_only: bool = False


@dataclass(frozen=True)
class Storage:
    """A volume store: flow through local nodes ``plus`` -> ``minus`` changes ``volume``.

    ``volume`` names a state_only observable (mL).  ``state`` names the state that holds the
    volume (None if the volume is derived, like an arteriolar bed's pi r^2 L n).  Used to find
    conservation laws (nodes reached only through stores) generically.
    """

    plus: str
    minus: str
    volume: str
    state: str | None = None


@dataclass(frozen=True)
class Drive:
    """How an input signal drives an element (a source): the names of the parameters involved.

    ``value``: the parameter an input drives (a source's value; the input of AC, linearisation
    and the frequency response, and what source stepping ramps).  ``amplitude``, ``frequency``,
    ``phase``, ``start``: the parameters of the element's built-in sine term
    ``amplitude sin(2 pi frequency (t - start) + phase)`` for t >= start, added to the value
    (what the frequency response and forced periodic orbits set), or None when it has none.
    """

    value: str
    amplitude: str | None = None
    frequency: str | None = None
    phase: str | None = None
    start: str | None = None

    @property
    def has_sine(self) -> bool:
        """True when all four parameters of a built-in sine term are declared."""
        return None not in (self.amplitude, self.frequency, self.phase, self.start)


class Component:
    """Base class of every element type.  Subclasses set the class attributes and hooks.

    A type whose structure does not depend on its options declares it as class attributes
    (INTERNAL_NODES, BRANCHES, STATES, STORAGES, OBSERVABLES, EDGES: None takes ``role``), which
    the structure hooks return; a type whose structure does overrides the hooks.  A subclass
    without a docstring takes its module's (a svZeroDSolver block's: its equations)."""

    INTERNAL_NODES: tuple = ()
    BRANCHES: tuple = ()
    STATES: tuple = ()
    STORAGES: tuple = ()
    OBSERVABLES: tuple = ()
    EDGES: tuple | None = None

    #: name used as ``type:`` in netlists
    type_name: str = ""
    #: svZeroDSolver block types (the names in their JSON) this type implements: the importer
    #: (hemocircuit.svzerod) writes such a block as an element of this type
    svzerod_blocks: tuple[str, ...] = ()
    #: (parameters, states) svZeroDSolver's steady_initial scales by 1e-9 for this type (their
    #: to_steady: a boundary condition's capacitances and the volumes they store); like
    #: svzerod_blocks, read from the class itself, not inherited
    svzerod_steady_zeroed: tuple[tuple[str, ...], tuple[str, ...]] = ((), ())
    #: terminal names, in netlist ``nodes:`` order
    terminals: tuple[str, ...] = ()
    #: numeric parameters
    parameters: dict[str, Param] = {}
    #: structural options
    options: dict[str, Option] = {}
    #: topology role of the element's terminal pairs (for the validation pass):
    #:   'conductive': a resistive path; 'pressure': fixes a pressure difference
    #:   (source, compliance); 'flow': fixes the flow (inductor, flow source).
    role: str = "conductive"
    #: True when A_loc does not depend on states or time (stamped once per parameter set)
    constant_matrix: bool = True
    #: the parameters A_loc reads (None: every parameter).  A parameter given as an expression
    #: of states (``L: "= ... art.r ..."``) varies with the states, so an element whose A_loc
    #: reads one is re-stamped at every evaluation; one outside this tuple leaves a
    #: ``constant_matrix`` element's A_loc constant (the inductor: A_loc = 0 whatever L is, so
    #: the nodal matrix stays constant with eq. inertia's L(r)).  Checked for every type by
    #: tests/test_component_contract.py.
    matrix_params: tuple[str, ...] | None = None
    #: True when stamp() is affine in the pressures (no Newton iteration needed)
    linear_in_pressure: bool = True
    #: True when the element drives its branch from a time-dependent source value
    time_dependent: bool = False
    #: a parameter whose value 0 makes a time-dependent type constant in time (a source's sine
    #: amplitude): the stamps of such values are static, and a circuit of them autonomous
    time_switch: str | None = None

    #: option overrides used while solving for a steady state (must not change the states)
    steady_opts: dict = {}
    #: parameters that accept a waveform mapping (``{pwl: ...}``, ``{sine: ...}``) in netlists
    waveform_params: tuple[str, ...] = ()
    #: the parameters an input signal drives (:class:`Drive`); None: the element is not a source
    drive: Drive | None = None

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        if cls.__doc__ is None:
            cls.__doc__ = getattr(sys.modules.get(cls.__module__), "__doc__", None)

    def __init__(self, opts: dict | None = None):
        self.opts = {k: o.default for k, o in self.options.items()}
        self.opts.update(opts or {})

    # --- structure (may depend on options) -------------------------------------------
    def internal_nodes(self) -> tuple[str, ...]:
        return self.INTERNAL_NODES

    def branches(self) -> tuple[tuple[str, str], ...]:
        """Pressure-defining branches (plus, minus) in local node names."""
        return self.BRANCHES

    def states(self) -> tuple[State, ...]:
        return self.STATES

    def observables(self) -> tuple[Observable, ...]:
        return self.OBSERVABLES

    def storages(self) -> tuple[Storage, ...]:
        return self.STORAGES

    def edges(self) -> tuple[tuple[str, str, str], ...]:
        """(local node a, local node b, role) for the topology pass."""
        if self.EDGES is not None:
            return self.EDGES
        t = self.terminals
        return ((t[0], t[1], self.role),)

    @property
    def local_nodes(self) -> tuple[str, ...]:
        return tuple(self.terminals) + tuple(self.internal_nodes())

    def matrix_reads(self, name: str) -> bool:
        """True when A_loc may depend on parameter ``name`` (:attr:`matrix_params`)."""
        return self.matrix_params is None or name in self.matrix_params

    def matrix_constant(self, expression_params) -> bool:
        """True when A_loc is stamped once per parameter set: a constant matrix, affine in the
        pressures, and none of ``expression_params`` (those given as expressions of states)
        read by A_loc.  The one rule for the circuit's groups and the compiled layout."""
        return (self.constant_matrix and self.linear_in_pressure
                and not any(self.matrix_reads(name) for name in expression_params))

    def varies_in_time(self, p) -> bool:
        """True if the stamps of these parameter values change with time: a time-dependent
        type, unless its :attr:`time_switch` is 0 for every element and member."""
        if not self.time_dependent or self.time_switch is None:
            return self.time_dependent
        return bool(np.any(np.asarray(p[self.time_switch]) != 0))

    # --- checks ------------------------------------------------------------------------
    def check(self, p: dict[str, np.ndarray]) -> list[tuple[int, str]]:
        """Cross-parameter physics checks beyond simple bounds: [(element index, message)]."""
        return []

    # --- numerical hooks (vectorised: see module docstring) -----------------------------
    # By default they run the type's kernel functions (hemocircuit.elementwise): the equations
    # are written once, as the kernel.  A legacy type without a kernel overrides them.
    def stamp(self, p, x, u, t, src=None):
        """(A_loc, b_loc): see the module docstring.  ``u`` is None for elements affine in the
        pressures; for ``linear_in_pressure = False`` it is the current Newton iterate of the
        local unknowns and the stamp is the linearisation there."""
        from . import elementwise
        return elementwise.stamp(self, p, x, u, t, src)

    def derivatives(self, p, x, u, t, src=None) -> np.ndarray:
        """dx/dt, shape (B, E, S)."""
        from . import elementwise
        return elementwise.derivatives(self, p, x, u, t, src)

    def observe(self, p, x, u, t, src=None) -> dict[str, np.ndarray]:
        """Observables (B, E) each.  ``u`` is None when only state_only ones are wanted."""
        from . import elementwise
        return elementwise.observe(self, p, x, u, t, src)

    def default_states(self, p) -> np.ndarray:
        """States to start the DC-guess iteration from, shape (B, E, S)."""
        return np.zeros(next(iter(p.values())).shape + (len(self.states()),)) if p else np.zeros((1, 1, 0))

    def initial_states(self, p, u, flows=None, x=None) -> np.ndarray:
        """A state guess consistent with local pressures/branch flows ``u`` and terminal flows.

        Used by the DC-guess iteration of the operating point; ``x`` is the previous guess.
        """
        return np.zeros(u.shape[:2] + (len(self.states()),))

    # --- DC guess of the operating point ----------------------------------------------
    def dc_stamp(self, p, A_loc, b_loc, keep):
        """The element's stamp in the DC-guess network of the operating point, from its normal
        stamp ``(A_loc, b_loc)`` (writable arrays, shapes as :meth:`stamp`; modify and return
        them).  ``keep`` (bool, (E,)) marks elements that must keep their normal stamp: one
        volume store per conservation law, which anchors the pressure of a node group joined
        to the rest of the circuit only through opened stores.  Default: the normal stamp.
        Volume stores open their branches (no flow); inductors short themselves."""
        return A_loc, b_loc

    def has_dc_stamp(self) -> bool:
        """True if :meth:`dc_stamp` changes the stamp (by default: the type overrides it)."""
        return type(self).dc_stamp is not Component.dc_stamp

    def dc_short(self) -> bool:
        """True if the element is a short circuit at steady state (inductors): the topology
        pass counts it in loops of pressure-defining elements (no operating point)."""
        return False

    # --- time structure ------------------------------------------------------------------
    def breakpoints(self, p, t0, t1) -> list[float]:
        """Times in (t0, t1) where the element's equations are discontinuous or not smooth in
        time (a sine term switching on; a periodic activation's kinks, listed for every cycle
        of the range), over every element of the group and every parameter set of ``p``: the
        compiled integrators end a step there, the scipy path restarts there.  Waveform
        breakpoints are found by the circuit itself."""
        return []

    def cycle_time_constants(self, p) -> np.ndarray | None:
        """Time constants [s] (1 or B, E) that set an up-front count of cardiac cycles for a periodic
        run, as svZeroDSolver's (Solver.cpp: ceil(-tau_max / T ln tol) over its RCR boundary
        conditions' Rd C; hemocircuit.svzerod.cycles), or None: the element sets none."""
        return None

    def hard_limits(self) -> tuple[tuple[str, float, str | None], ...]:
        """``((state, lower bound, state reset to 0 at the bound or None), ...)``: the integration
        stops when ``state`` reaches the bound, puts it on the bound and resets the rate state
        (the arteriole's second-order Ca: ``(("Ca", 1e-12, "dCa"),)``)."""
        return ()

    def limited_states(self, p, x, rtol=1e-6) -> np.ndarray:
        """Bool (B, E, S): states sitting at a hard limit of the element's dynamics (flagged by
        the stability analysis).  Default: the states within ``rtol`` of a :meth:`hard_limits`
        bound."""
        names = [s.name for s in self.states()]
        out = np.zeros(x.shape, dtype=bool)
        for name, bound, _ in self.hard_limits():
            j = names.index(name)
            out[..., j] = x[..., j] <= bound + rtol * max(abs(bound), 1e-300)
        return out

    def physical_limits(self) -> dict:
        """``{observable or state name: (lower, upper)}``: the range a physical solution stays
        in, in the quantity's declared unit (None: unbounded), e.g. a stored volume ``V >= 0``
        (``{"V": (0.0, None)}``).  :mod:`hemocircuit.plausibility` warns, naming the element,
        when an operating point or a run leaves it.  Default: none."""
        return {}

    # --- defaults and reporting -----------------------------------------------------------
    def defaults(self) -> dict:
        """Parameter values that replace the declared defaults for these options (a preset):
        ``{name: number in the declared unit}``."""
        return {}

    def drive_output(self, eid: str, nodes: list) -> str | None:
        """The output column that holds the driven quantity of element ``eid`` on ``nodes``
        (a pressure source to ground: ``P(node)``; a flow source: ``Q(eid)``), or None."""
        return None

    def outputs_of_interest(self) -> tuple[str, ...]:
        """Names of states/observables an analysis reports by default when the netlist declares
        no ``outputs:`` (columns ``ID.name``, or ``V(ID)`` for a volume), e.g. ``("r",)``."""
        return ()

    def volume_observables(self) -> tuple[str, ...]:
        """Observables reported as ``V(ID)`` rather than ``ID.name`` (stored volumes)."""
        return tuple(s.volume for s in self.storages())

    # --- compiled path (hemocircuit.kernels) --------------------------------------------
    def kernel(self):
        """The type's compiled equations (:class:`hemocircuit.kernels.Kernel`), or None when the
        type runs only on the numpy path (circuits containing it then run on that path)."""
        return None

    def kernel_options(self) -> np.ndarray:
        """This instance's structural options as an int64 array, read by the kernel's functions."""
        return np.zeros(0, dtype=np.int64)



def kernel_method(stamp, derivs=None, observe=None, observables=(), **optional):
    """A ``Component.kernel`` returning these kernel functions (``optional``: report,
    derivs_jac); ``derivs`` and ``observe`` default to the stateless ones."""
    k = Kernel(stamp=stamp, derivs=derivs or no_derivs, observe=observe or no_observables,
               observables=observables, **optional)
    return lambda self: k


def batch_shape(p, *shapes):
    """(B, E) of an evaluation: the broadcast of every parameter's shape and ``shapes``."""
    return np.broadcast_shapes(*(np.shape(v) for v in p.values()), *shapes)


# --- DC-guess stamps (dc_stamp), on the batched (B, E, L, L) and (B, E, L) arrays ----------
def short(A_loc, b_loc, G=1e6):
    """An inductor from local node 0 to 1 as a conductance G [mL/s/mmHg], no imposed flow (its
    local unknowns are the two pressures only, with no branch row for P_a = P_b)."""
    A_loc[..., 0, 0] += G
    A_loc[..., 0, 1] -= G
    A_loc[..., 1, 0] -= G
    A_loc[..., 1, 1] += G
    b_loc[..., :2] = 0.0
    return A_loc, b_loc


def open_branches(A_loc, b_loc, rows, keep=None):
    """The branches ``rows`` carry no flow, except in the elements ``keep`` (the stores that
    anchor a conservation law keep their stamp)."""
    sel = slice(None) if keep is None else ~np.asarray(keep, dtype=bool)
    for r in rows:
        A_loc[:, sel, r, :] = 0.0
        A_loc[:, sel, r, r] = 1.0
        b_loc[:, sel, r] = 0.0
    return A_loc, b_loc


#: most kinks periodic_breakpoints lists in one call, over all phases and parameter sets
MAX_BREAKPOINTS = 4_000_000


def periodic_breakpoints(phases_of, p, names, t0, t1):
    """Times in (t0, t1) of ``phases_of(T, {name: value}) + n T`` (n >= 0) over every
    parameter set and element of ``p`` (arrays; ``p['period']`` is T, ``names`` the others
    the phases need): the scheduled kinks of a periodic function of time, where the
    integrators end a step."""
    names = tuple(names)
    arrs = np.broadcast_arrays(*(np.asarray(p[n], float) for n in ("period",) + names))
    out, count = [], 0
    for vals in set(zip(*(v.reshape(-1).tolist() for v in arrs))):
        T = vals[0]
        for ph in phases_of(T, dict(zip(names, vals[1:]))):
            n0, n1 = max(0, math.floor((t0 - ph) / T)), math.ceil((t1 - ph) / T)
            count += max(0, n1 - n0 + 1)
            if count > MAX_BREAKPOINTS:
                raise SolverError(f"more than {MAX_BREAKPOINTS} scheduled kinks of a periodic function "
                                  f"(period {T:g} s) in ({t0:g}, {t1:g}) s: integrate over fewer cycles at a time")
            out.append(ph + T * np.arange(n0, n1 + 1, dtype=float))
    pts = np.unique(np.concatenate(out)) if out else np.empty(0)
    return [float(v) for v in pts[(pts > t0) & (pts < t1)]]
