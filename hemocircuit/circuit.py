"""The assembled circuit: an immutable pair (structure, values) and its value variants.

A Circuit is a :class:`~hemocircuit.structure.CircuitStructure` (netlist, elements, groups,
numbering, conservation laws, constraints; made once, shared by every value variant) plus a
:class:`~hemocircuit.parameters.ParameterSet` (the values, batched).  Values change only by
making a new circuit: ``c.with_values({ID.PARAM: value})``, ``c.with_parameters(ps)``,
``c.batch(B)``, ``c.member(k)``, ``c.subset(members)``, ``c.with_options(...)``.
Parameters are addressed as ``ID.PARAM`` everywhere (``--set``, sweeps, protocols, fitting).

Its equations with these values -- the nodal system, ``rhs``, Jacobians, outputs and the
choice of engine -- are its :class:`~hemocircuit.system.System` (``c.system``, made with the
circuit); ``c.rhs``, ``c.jacobian``, ``c.outputs`` ... are that system's.  What a circuit
derives from its values (the system's prepared matrices, subset views, memos) lives on the
object and dies with it.  A Circuit is plain data plus numpy arrays, so it pickles cheaply
to worker processes (the caches are dropped).
"""
from __future__ import annotations

import copy

import numpy as np

from .build import ElementData, parse_netlist
from .errors import HemocircuitError, NetlistError
from .names import split_path
from .netlist import Netlist, load_netlist
from .parameters import ParameterSet
from .structure import CircuitStructure, Column, remap_spec
from .system import SPARSE_MIN_UNKNOWNS, System

__all__ = ["Circuit", "CircuitStructure", "Column", "assemble", "load"]


def _member_row(values, m):
    """Member m's row (1, ...) of a batch parameter array (B or 1, ...)."""
    v = np.asarray(values)
    return v if v.ndim == 0 or v.shape[0] == 1 else v[m:m + 1]


class Circuit:
    """An assembled, validated, immutable circuit: a shared :class:`CircuitStructure` plus a
    :class:`ParameterSet`.  Build with :func:`assemble` or ``hemocircuit.load``; make value
    variants with :meth:`with_values` / :meth:`with_parameters` (and batch, member, subset,
    with_options, steady_variant)."""

    #: structural attributes, shared with the structure
    _SHARED = ("netlist", "file", "elements", "laws", "nodes", "branch_names", "n", "state_names",
               "state_units", "state_scales", "nx")
    #: private caches: derived from this object's structure and values, dropped when pickled
    _CACHES = ("_subset_cache", "_memo", "_steady")

    def __init__(self, netlist: Netlist, elements: list[ElementData]):
        structure = CircuitStructure(netlist, elements)
        self._bind(structure, ParameterSet.from_elements(structure.schema), None)
        self.system = System(self)

    @classmethod
    def _of(cls, structure, parameters, threshold=None) -> "Circuit":
        c = cls.__new__(cls)
        c._bind(structure, parameters, threshold)
        c.system = System(c)
        return c

    def _bind(self, structure, parameters, threshold):
        """Attach the structure and the values (groups bound to this set's arrays)."""
        if parameters.schema is not structure.schema:
            raise HemocircuitError("these parameters belong to another circuit structure")
        self.structure = structure
        for a in self._SHARED:
            setattr(self, a, getattr(structure, a))
        self.parameters = parameters
        self.B = parameters.B
        self._threshold = threshold
        self.groups = [t.bound(parameters.group_arrays(k), parameters.group_waves(k))
                       for k, t in enumerate(structure.groups)]
        self._locate = {eid: (self.groups[g.index], i) for eid, (g, i) in structure._locate.items()}
        self.law_specs = [remap_spec(s, self.groups) for s in structure.law_specs]
        self._subset_cache, self._memo, self._steady = {}, {}, None

    def __getstate__(self):
        state = dict(self.__dict__)
        for k in self._CACHES:
            state.pop(k, None)
        return state

    def __setstate__(self, state):
        self.__dict__.update(state)
        self._subset_cache, self._memo, self._steady = {}, {}, None

    # ------------------------------------------------------------- sparse path ---------
    #: the sparse path (splu factorisations, coloured sparse Jacobians) is taken when the
    #: nodal system has more unknowns than this; a circuit with another threshold:
    #: with_sparse_threshold
    sparse_threshold = SPARSE_MIN_UNKNOWNS

    @property
    def sparse(self) -> bool:
        """True when this circuit runs on the sparse path (n > its sparse threshold)."""
        return self.n > (self.sparse_threshold if self._threshold is None else self._threshold)

    def with_sparse_threshold(self, n_unknowns) -> "Circuit":
        """This circuit taking the sparse path above ``n_unknowns`` nodal unknowns (None: the
        default, ``hemocircuit.system.SPARSE_MIN_UNKNOWNS``; 0 forces it, a huge number forbids it)."""
        return Circuit._of(self.structure, self.parameters, None if n_unknowns is None else int(n_unknowns))

    # ------------------------------------------------------------ structure, values ----
    def element_group(self, eid):
        """(group, index in the group) of element ``eid``."""
        return self._locate[eid]

    def param_path(self, path: str):
        """Split 'ID.PARAM' and check it names a parameter.  Returns (element data, group, index, name)."""
        e, gi, i, name = self.structure.schema.resolve(path)
        return e, self.groups[gi], i, name

    def is_option(self, path) -> bool:
        """Whether ID.NAME names a structural option (not a parameter) of an element."""
        eid, name = split_path(str(path))
        return eid in self.elements and name in self.elements[eid].cls.options

    def param_unit(self, path):
        return self.parameters.unit(path)

    @property
    def law_totals(self):
        """Conserved totals the constraints give directly (a 'volume' constraint; shape (1,)),
        None for a calibration (computed by the operating point)."""
        return [np.full(1, s["volume"]) if s["kind"] == "volume" else None for s in self.law_specs]

    def cached(self, key, compute):
        """A value derived from this circuit alone (structure and values), computed once per
        circuit object by ``compute()`` and kept under ``key`` (e.g. the operating point's
        calibrated conserved totals).  Circuits are immutable, so it never goes stale."""
        if key not in self._memo:
            self._memo[key] = compute()
        return self._memo[key]


    # ------------------------------------------------------------ value variants -------
    def with_parameters(self, parameters: ParameterSet) -> "Circuit":
        """This circuit's structure with the values ``parameters`` (a set of this structure)."""
        if parameters is self.parameters:
            return self
        return Circuit._of(self.structure, parameters, self._threshold)

    def with_values(self, mapping: dict) -> "Circuit":
        """A new circuit with ``{ID.PARAM: value}`` applied (see ParameterSet.with_values: a
        number in the declared unit, a quantity string '5 s', a pint quantity, a waveform
        mapping, or an array of B numbers).  Checked against the bounds; this circuit is
        unchanged."""
        if not mapping:
            return self
        return self.with_parameters(self.parameters.with_values(mapping))

    def with_options(self, changes: dict) -> "Circuit":
        """A re-assembled circuit with structural options changed ({ID.OPTION: value}).

        A structural option changes the equations (states, nodes), not the numbers: every
        numeric value this circuit holds is kept, on the elements whose options change as on
        the others - the netlist's values, and every value changed since assembly (``--set``,
        :meth:`with_values`, a protocol's ``initial``, a batch's per-member values), waveforms
        set with ``with_values`` included.  Parameters that follow an expression are
        re-evaluated in the new circuit, not copied.

        Options that change an element's *defaults* (the arteriole's ``preset``, a named
        parameter set) are the one case where values are replaced: on that element the values
        that came from the old defaults take the new preset's values, while the values set
        explicitly stay - those written in the netlist, and those changed since assembly.  A
        value counts as changed since assembly when it differs from the assembled one, so a
        value set to exactly the old preset's number follows the new preset like an untouched
        one.
        """
        if not changes:
            return self
        nl = copy.deepcopy(self.netlist)
        for path, v in changes.items():
            eid, name = split_path(path)
            try:
                nl.element(eid).values[name] = v
            except KeyError:
                raise NetlistError(f"no element '{eid}' (elements: {sorted(self.elements)})", file=self.file,
                                   element=eid) from None
        new = assemble(nl)
        if self._threshold is not None:
            new = new.with_sparse_threshold(self._threshold)
        if self.B > 1:
            new = new.batch(self.B)
        # The new assembly reproduces the netlist's values and the (possibly new) defaults;
        # on top of them, carry every value (and waveform) changed on this circuit since its
        # assembly.
        schema, ps = new.structure.schema, new.parameters
        updates = []
        for g in self.groups:
            waves = {(i, name): wf for i, name, wf in g.waves}
            for i, eid in enumerate(g.ids):
                e, ne = self.elements[eid], new.elements[eid]
                ngi, ni = schema.locate[eid]
                for name, arr in g.p.items():
                    if name in e.expressions or name in ne.expressions or name not in ps.group_arrays(ngi):
                        continue
                    wf = waves.get((i, name))
                    if np.all(arr[:, i] == e.values[name]) and wf is e.waveforms.get(name):
                        continue  # as assembled: the new assembly has the right value
                    updates.append((ngi, ni, name, arr[:, i], wf))
        return new.with_parameters(ps.with_columns(updates)) if updates else new

    def steady_variant(self) -> "Circuit":
        """This circuit with each component's ``steady_opts`` applied (for steady-state solves:
        log compliances continued below their domain, clamps off); same values.  Itself when
        no component has steady options."""
        if self._steady is None:
            s = self.structure.steady()
            self._steady = self if s is self.structure else Circuit._of(s, self.parameters, self._threshold)
        return self._steady

    def batch(self, B: int) -> "Circuit":
        """This single circuit as a batch of B identical members (vary them with
        :meth:`with_values` and arrays of B values)."""
        if self.B != 1:
            if B == self.B:
                return self
            raise HemocircuitError(f"batch({B}) of a circuit that already has {self.B} members; "
                                   "use subset() or parameters[...] to choose members")
        return self.with_parameters(self.parameters[np.zeros(int(B), dtype=int)])

    def subset(self, members) -> "Circuit":
        """Batch members ``members`` as a circuit (shares the structure, slices the values and
        the prepared matrices; kept in a private cache, so asking again is free).

        Used inside batch integration, where members finish at different times."""
        members = np.asarray(members, dtype=int).reshape(-1)
        if self.B == 1:
            return self
        if len(members) == self.B and np.all(members == np.arange(self.B)):
            return self
        key = members.tobytes()
        cache = self._subset_cache
        if key in cache:
            return cache[key]
        c = Circuit.__new__(Circuit)
        c._bind(self.structure, self.parameters[members], self._threshold)
        c.system = self.system.subset(c, members)  # the prepared matrices sliced, not made again
        if len(cache) > 256:
            cache.pop(next(iter(cache)))
        cache[key] = c
        return c

    def member(self, k: int) -> "Circuit":
        """Batch member k as a single circuit."""
        if self.B == 1 and k in (0, -1):
            return self
        return self.with_parameters(self.parameters[k])


    # --------------------------------------------- equations: this circuit's System ----
    # (one-line delegations: the API of tests, docs and examples; hemocircuit.system has them)
    def evaluate(self, t, x, dc=False, want="rhs"):
        """dx/dt of a stacked batch x (Bx, nx) (System.evaluate)."""
        return self.system.evaluate(t, x, dc, want)

    def rhs(self, t, x):
        """dx/dt for a single run (x of shape (nx,)) or a batch (B, nx)."""
        return self.system.rhs(t, x)

    def jacobian(self, t, x):
        """d(dx/dt)/dx at x (nx,) or (B, nx): dense, or sparse matrices on the sparse path
        (System.jacobian)."""
        return self.system.jacobian(t, x)

    def sparse_jacobian(self, t, x):
        """([csc_matrix (nx, nx)] per member, dx/dt (B, nx)) (System.sparse_jacobian)."""
        return self.system.sparse_jacobian(t, x)

    def jacobian_plan(self, key, fun, X, t=0.0, row_reads=None, how="auto"):
        """The Jacobian pattern and colouring of ``fun`` (System.jacobian_plan)."""
        return self.system.jacobian_plan(key, fun, X, t, row_reads, how)

    def outputs(self, t, x, engine="auto") -> dict:
        """{column name: (T,) array} for states x (T, nx) at times t (System.outputs)."""
        return self.system.outputs(t, x, engine)

    def group_params(self, rows=None):
        """Per-group parameter dicts laid out for ``rows`` state rows (System.group_params)."""
        return self.system.group_params(rows)

    def dc_unknowns(self, t, X):
        """(u, bound parameters, stamps) of the DC network at states X (System.dc_unknowns)."""
        return self.system.dc_unknowns(t, X)

    def nodal_matrix(self, t, X):
        """The nodal matrix (Bx, n, n) at states X, dense path (System.nodal_matrix)."""
        return self.system.nodal_matrix(t, X)

    def law_volumes(self, x):
        """Conserved combinations sum(sign * V) for states x (System.law_volumes)."""
        return self.system.law_volumes(x)

    @property
    def nonlinear(self):
        """True if some element is nonlinear in the pressures (Newton on the nodal equations)."""
        return self.system.nonlinear

    # ------------------------------------------------------------------ outputs --------

    def columns(self) -> list[Column]:
        """Every output column, in a stable order."""
        cols = [Column(f"P({n})", "mmHg") for n in self.nodes if ":" not in n]
        cols += [Column(f"Q({e})", "mL/s") for g in self.groups for e in g.ids]
        for g in self.groups:
            store_vols = set(g.comp.volume_observables())
            obs_names = [o.name for o in g.observables]
            for e in g.ids:
                for s in g.states:
                    if s.name not in obs_names:
                        cols.append(Column(f"{e}.{s.name}", s.unit))
                for o in g.observables:
                    cols.append(Column(f"V({e})" if o.name in store_vols else f"{e}.{o.name}", o.unit))
        return cols


    def column_units(self):
        return {c.name: c.unit for c in self.columns()}

    def state_dict(self, x):
        return dict(zip(self.state_names, np.asarray(x, dtype=float).reshape(-1)))

    def hard_limits(self):
        """[(state index, lower bound, index of a state reset to 0 at the bound or None)]."""
        out = []
        for g in self.groups:
            for name, bound, reset in g.comp.hard_limits():
                names = [s.name for s in g.states]
                for i in range(g.E):
                    out.append((g.sidx[i, names.index(name)], bound,
                                None if reset is None else g.sidx[i, names.index(reset)]))
        return out

    def breakpoints(self, t0, t1, kinks=True, members=False):
        """Scheduled discontinuities in (t0, t1): waveform breakpoints and the elements' own
        (Component.breakpoints, e.g. a source's sine term switching on).  ``kinks=False``
        leaves out the waveforms' slope-only kinks (Waveform.jumps: where the value may jump).
        The union over the batch's members, or with ``members`` one list per member, each with
        its own parameter values only (so that no member steps on another's kinks)."""
        union = self._breakpoints(t0, t1, kinks, None)
        if not members:
            return union
        if not union or self.B == 1:  # nothing to tell apart (e.g. every block of a frequency response)
            return [list(union) for _ in range(self.B)]
        return [self._breakpoints(t0, t1, kinks, m) for m in range(self.B)]

    def jumps_and_kinks(self, t0, t1, members=False):
        """(jumps, kinks) in (t0, t1), what the integrators take as ``breaks`` and ``kinks``:
        where a source may jump (f is evaluated again there), and the other breakpoints, where
        only a slope changes.  With ``members``: one list of each per member.  The last
        window's are kept on this (immutable) circuit: a shooting run asks for the same period
        at every iteration (0.2 ms each for the heart's activation), a transient for a new
        window each time (one entry, so a long-lived circuit does not grow); callers get their
        own lists."""
        key = (float(t0), float(t1), bool(members))
        last = self._memo.get("jumps_and_kinks")
        if last is None or last[0] != key:
            last = self._memo["jumps_and_kinks"] = (key, self._jumps_and_kinks(t0, t1, members))
        jumps, kinks = last[1]
        if not members:
            return list(jumps), list(kinks)
        return [list(j) for j in jumps], [list(k) for k in kinks]

    def _jumps_and_kinks(self, t0, t1, members):
        jumps = self.breakpoints(t0, t1, kinks=False, members=members)
        every = self.breakpoints(t0, t1, members=members)
        if not members:
            return jumps, sorted(set(every) - set(jumps))
        return jumps, [sorted(set(a) - set(j)) for a, j in zip(every, jumps)]

    def _breakpoints(self, t0, t1, kinks, member):
        pts = set()
        for g in self.groups:
            for _, _, wf in g.waves:  # one waveform per element, common to every member
                pts.update(b for b in (wf.breakpoints(t0, t1) if kinks else wf.jumps(t0, t1)) if t0 < b < t1)
            p = g.p if member is None else {k: _member_row(v, member) for k, v in g.p.items()}
            pts.update(float(b) for b in g.comp.breakpoints(p, t0, t1) if t0 < b < t1)
        return sorted(pts)

    def describe(self) -> str:
        lines = [f"circuit '{self.netlist.name}' ({self.file})",
                 f"  {len(self.elements)} elements, {len(self.nodes)} nodes, {self.nx} states, {self.n} unknowns"]
        for g in self.groups:
            lines.append(f"  {g.comp.type_name}: {', '.join(g.ids)}")
        for s in self.law_specs:
            lines.append(f"  conserved: {s['law'].describe()} ({s['kind']})")
        return "\n".join(lines)


def assemble(netlist: Netlist) -> Circuit:
    from .outputs import check as check_outputs

    c = Circuit(netlist, parse_netlist(netlist))
    check_outputs(c)  # the netlist's outputs: and input: name columns and sources of this circuit
    return c


def load(path: str, values: dict | None = None, allow_paths=None, svzerod_units=None) -> Circuit:
    """Load, validate and assemble a netlist file; optionally apply {ID.PARAM: value}.
    ``allow_paths``: more folders its files may read (see hemocircuit.access);
    ``svzerod_units``: the unit system of an svZeroDSolver JSON model (netlist.load_netlist)."""
    from .inputs import recording

    with recording() as sources:  # every file the load reads (netlist, extends chain, tables)
        netlist = load_netlist(path, allow_paths, svzerod_units)
        c = assemble(netlist)
    netlist.sources = sources
    return c.with_values(values or {})


# the common analyses as methods (c.simulate(), c.operating_point(), ...)
from .analyses import attach as _attach  # noqa: E402

_attach(Circuit)
