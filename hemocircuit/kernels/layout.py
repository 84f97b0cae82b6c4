"""Flatten an assembled circuit into the arrays the compiled engine reads (see engine_nodal.py).

Everything that is structure (elements, their type codes, node and state numbering, options,
waveform records, expression programs) goes into the layout (:class:`EngineLayout`'s fields,
described in engine_nodal.py's header; passed to numba as a plain tuple, the functions unpack
it by name); parameter *values* go into
a separate matrix P (members x slots), so a batch or a new parameter value reuses the layout
and the compiled code.
"""
from __future__ import annotations

import functools
import os
from collections import namedtuple
from dataclasses import dataclass, field

import numpy as np

from . import expressions as kexpr
from . import waveforms as kwave

#: above this many nodal unknowns the dense in-kernel solve is not used (the sparse numpy path is)
MAX_DENSE_UNKNOWNS = 200


#: the structure arrays the compiled engine reads (engine_nodal.py's header describes each)
ENGINE_FIELDS = ("n", "nx", "et", "L", "S", "ep", "ex", "eu", "ui", "eo", "io", "eb", "ws", "w0", "wd", "xs", "xc", "xk",
                 "xcode", "xconst", "oe", "nonlin", "cm", "st", "td")
EngineLayout = namedtuple("EngineLayout", ENGINE_FIELDS)


@dataclass
class Layout:
    #: what the engine reads: EngineLayout's fields as a plain tuple (numba types a plain tuple
    #: argument on its fast path: 4 us a call against 11 us for the named tuple); by name: fields
    lay: tuple
    kernels: list          # Kernel objects; index = type code
    slots: dict            # (element id, parameter) -> column of P
    n_params: int
    #: (element index, column of P) of the elements static but for their type's time switch
    #: (Component.time_switch, a source's sine amplitude): with it 0 in every member they are
    #: static (CompiledSystem.lay_for); timed: every element of a time-dependent type
    switches: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), dtype=np.int64))
    timed: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    #: (element ids, parameter) -> their columns of P (param_matrix; filled on first use)
    columns: dict = field(default_factory=dict, repr=False)

    @property
    def fields(self) -> EngineLayout:
        """The layout's arrays by name (the same arrays as ``lay``)."""
        return EngineLayout(*self.lay)

    @property
    def autonomous(self) -> bool:
        """No waveform and no element of a time-dependent type: f does not depend on t."""
        return not len(self.fields.ws) and not len(self.timed)

    def lay_with(self, **arrays) -> tuple:
        """``lay`` with some of its arrays replaced (by field name), as the engine reads it."""
        return tuple(arrays.get(name, v) for name, v in zip(ENGINE_FIELDS, self.lay))


#: environment variable choosing the engine's types: "used" (default) or "all"
ENGINE_TYPES_VAR = "HEMOCIRCUIT_ENGINE_TYPES"


def engine_kernels(pairs) -> list:
    """The kernels the circuit's engine dispatches to, in a canonical order (by the functions'
    qualified names), so every circuit made of the same component types gets the same module.

    ``$HEMOCIRCUIT_ENGINE_TYPES`` = ``used`` (default): the circuit's distinct kernels -- the
    shortest first compilation, one engine per set of types.  ``all``: every registered
    type's kernels -- one engine for every netlist, longer to compile once, cheaper for a
    process that meets many sets of types (the test suite, tests/conftest.py).  Compile times:
    docs/performance.md."""
    from ..errors import HemocircuitError
    from .codegen import kernel_names

    mode = os.environ.get(ENGINE_TYPES_VAR, "used")
    if mode not in ("used", "all"):
        raise HemocircuitError(f"environment variable {ENGINE_TYPES_VAR}={mode!r}: expected 'used' or 'all'")
    distinct = {(k.stamp, k.derivs, k.observe): k for _, k in pairs}
    if mode == "all":
        for k in _registered_kernels():
            distinct.setdefault((k.stamp, k.derivs, k.observe), k)
    return sorted(distinct.values(), key=kernel_names)


@functools.lru_cache(maxsize=1)
def _registered_kernels() -> tuple:
    """The kernels of every registered component type (one option set each; the functions do
    not depend on options)."""
    from ..registry import component_types

    out = []
    for _, cls in sorted(component_types().items()):
        try:
            k = cls().kernel()
        except Exception:  # noqa: BLE001 - a plug-in that cannot build without options: numpy path
            k = None
        if k is not None:
            out.append(k)
    return tuple(out)


def kernels_of(circuit):
    """[(group, Kernel)] for every group, or None if some type has no compiled kernel."""
    out = []
    for g in circuit.groups:
        k = g.comp.kernel()
        if k is None:
            return None
        out.append((g, k))
    return out


def build_layout(circuit) -> Layout | None:
    """The layout of ``circuit``, or None when it cannot run compiled (a type without a kernel,
    or more nodal unknowns than the dense in-kernel solve is meant for)."""
    pairs = kernels_of(circuit)
    if pairs is None or circuit.n > MAX_DENSE_UNKNOWNS:
        return None
    kernels = engine_kernels(pairs)
    codes = {(k.stamp, k.derivs, k.observe): i for i, k in enumerate(kernels)}
    et, L, S, cm, st, td, timed, switches = [], [], [], [], [], [], [], []
    ep, ex, eu, eo, eb = [0], [0], [0], [0], [0]
    ui, io = [], []
    slots, obs_index, elem_index = {}, {}, {}
    for g, k in pairs:
        names = list(g.comp.parameters)
        iopt = np.asarray(g.comp.kernel_options(), dtype=np.int64)
        for i, eid in enumerate(g.ids):
            elem_index[eid] = len(et)
            et.append(codes[(k.stamp, k.derivs, k.observe)])
            own = {name for j, name, _ in g.waves if j == i} | {name for j, name, _ in g.exprs if j == i}
            const = g.comp.matrix_constant(own)  # expressions and waveforms change in time
            cm.append(int(const))
            # 1 static, 2 stamped at every Newton iterate, 0 once per nodal solve (engine_nodal)
            static = g.comp.linear_in_pressure and const and g.S == 0 and not own
            st.append(2 if not g.comp.linear_in_pressure
                      else (1 if (static and not g.comp.time_dependent) else 0))
            td.append(int(bool(own) or g.comp.time_dependent))
            if g.comp.time_dependent:
                timed.append(len(et) - 1)
                if static and g.comp.time_switch is not None:
                    switches.append((len(et) - 1, ep[-1] + names.index(g.comp.time_switch)))
            L.append(g.L)
            S.append(g.S)
            for name in names:
                slots[(eid, name)] = ep[-1] + names.index(name)
            ep.append(ep[-1] + len(names))
            sidx = g.sidx[i]
            if g.S and not np.array_equal(sidx, np.arange(sidx[0], sidx[0] + g.S)):
                return None  # states of an element must be contiguous
            if g.S and sidx[0] != ex[-1]:
                return None  # and numbered in element order
            ex.append(ex[-1] + g.S)
            ui.extend(int(v) for v in g.uidx[i])
            eu.append(len(ui))
            io.extend(int(v) for v in iopt)
            eo.append(len(io))
            for j, oname in enumerate(k.observables):
                obs_index[(eid, oname)] = eb[-1] + j
            eb.append(eb[-1] + len(k.observables))
    # waveforms: their value is added to the parameter slot (sources keep value = 0 then)
    ws, w0, wd = [], [], []
    for g in circuit.groups:
        for i, name, wf in g.waves:
            ws.append(slots[(g.ids[i], name)])
            w0.append(len(wd))
            wd.extend(kwave.encode(wf).tolist())
    # expressions: programs for the stack machine; observables they read are evaluated first
    xs, xc, xk, code, const, oe = [], [], [], [], [], set()

    def slot(ref):
        if ref.kind == "param":
            return "param", slots[(ref.element, ref.name)]
        if ref.kind == "observable":
            if (ref.element, ref.name) not in obs_index:
                raise KeyError(ref)
            oe.add(elem_index[ref.element])
            return "obs", obs_index[(ref.element, ref.name)]
        raise KeyError(ref)

    for g in circuit.groups:
        for i, name, ex_ in g.exprs:
            try:
                c_, k_ = kexpr.encode(ex_, slot)
            except KeyError:
                return None  # reads something the kernels do not provide: numpy path
            xs.append(slots[(g.ids[i], name)])
            xc.append(len(code))
            xk.append(len(const))
            code.extend(int(v) for v in c_)
            const.extend(float(v) for v in k_)
    i64 = lambda a: np.asarray(a, dtype=np.int64)  # noqa: E731
    f64 = lambda a: np.asarray(a, dtype=np.float64)  # noqa: E731
    nonlin = int(any(not g.comp.linear_in_pressure for g in circuit.groups))
    lay = EngineLayout(n=int(circuit.n), nx=int(circuit.nx), et=i64(et), L=i64(L), S=i64(S), ep=i64(ep), ex=i64(ex),
                       eu=i64(eu), ui=i64(ui), eo=i64(eo), io=i64(io), eb=i64(eb), ws=i64(ws), w0=i64(w0), wd=f64(wd),
                       xs=i64(xs), xc=i64(xc), xk=i64(xk), xcode=i64(code), xconst=f64(const), oe=i64(sorted(oe)),
                       nonlin=nonlin, cm=i64(cm), st=i64(st), td=i64(td))
    lay = tuple(lay)  # Layout.lay: a plain tuple for numba
    return Layout(lay, kernels, slots, ep[-1], switches=np.array(switches, dtype=np.int64).reshape(-1, 2),
                  timed=i64(timed))


def param_matrix(circuit, layout: Layout) -> np.ndarray:
    """P (B, n_params): the circuit's parameter values per member, in layout slot order."""
    P = np.zeros((circuit.B, layout.n_params))
    for g in circuit.groups:
        for name, arr in g.p.items():
            P[:, _columns(layout, g.ids, name)] = arr  # (1 or B, E) into the group's E columns
    return np.nan_to_num(P, nan=0.0)  # expression slots are filled at run time


def _columns(layout: Layout, ids, name) -> np.ndarray:
    """Columns of P of parameter ``name`` of elements ``ids`` (kept on the layout: a batch
    integration asks for the matrix at every call, ~60 columns for the vasomotion circuit)."""
    key = (tuple(ids), name)
    cols = layout.columns.get(key)
    if cols is None:
        cols = layout.columns[key] = np.array([layout.slots[(eid, name)] for eid in ids], dtype=np.int64)
    return cols
