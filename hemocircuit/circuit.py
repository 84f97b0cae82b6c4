"""The assembled circuit: modified nodal analysis -> an ODE dx/dt = f(t, x).

At every right-hand-side evaluation the node pressures and the flows of pressure-defining
branches are found from the linear MNA system ``A u = b`` given the states (one batched dense
solve; the elements here are all affine in the pressures).  Elements are evaluated per *group*
(all elements of one type and options), vectorised over elements and over a batch of B
parameter sets, so there is no per-element Python in the hot path.

Parts that cannot change are kept apart (svZeroDSolver style): the matrix of groups whose
stamps do not depend on states or time is built once per parameter set; when every group is
like that, the inverse of A is cached and each evaluation is one matrix-vector product.

A Circuit is immutable: a :class:`CircuitStructure` (netlist, elements, groups, numbering,
conservation laws, constraints; made once, shared by every value variant) plus a
:class:`~hemocircuit.parameters.ParameterSet` (the values, batched).  Values change only by
making a new circuit: ``c.with_values({ID.PARAM: value})``, ``c.with_parameters(ps)``,
``c.batch(B)``, ``c.member(k)``, ``c.subset(members)``, ``c.with_options(...)``.  What a circuit
derives from its values (the constant nodal matrix, its inverse or factorisations, Jacobian
patterns, subset views) is cached privately on the object and dies with it.
Parameters are addressed as ``ID.PARAM`` everywhere (``--set``, sweeps, protocols, fitting).
A Circuit is plain data plus numpy arrays, so it pickles cheaply to worker processes (the
caches are dropped).
"""
from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .build import ElementData, parse_netlist
from .component import Component
from .errors import HemocircuitError, NetlistError, SolverError, TopologyError
from .graph import check_topology, local_node_map
from .linalg import solve_batched
from .names import split_path
from . import sparse as sparse_la
from .netlist import GROUND, Netlist, load_netlist
from .parameters import ParameterSchema, ParameterSet
from .units import UnitError, parse_quantity

#: outputs() of at least this many rows take the nodal solution from the compiled engine when
#: it is built (below, a call's fixed cost outweighs what it saves)
COMPILED_OUTPUT_ROWS = 64


def _scatter(ST, local):
    """Global contributions (rows, N) of local stamps (rows, ...) through a sparse scatter."""
    flat = local.reshape(local.shape[0], -1)
    return np.asarray((ST @ flat.T).T)


def _member_row(values, m):
    """Member m's row (1, ...) of a batch parameter array (B or 1, ...)."""
    v = np.asarray(values)
    return v if v.ndim == 0 or v.shape[0] == 1 else v[m:m + 1]


def _bincount_scatter(uidx, b_loc, Bx, N1):
    """Global right-hand-side contributions (Bx, N1) of local ones b_loc (1 or Bx, E, L), adding
    duplicates (the sparse path: cheaper per call than a scipy product for single rows)."""
    idx = uidx.reshape(-1)
    w = b_loc if b_loc.shape[0] == Bx else np.broadcast_to(b_loc, (Bx,) + uidx.shape)
    if Bx == 1:
        return np.bincount(idx, weights=w.reshape(-1), minlength=N1)[None]
    off = (idx[None, :] + N1 * np.arange(Bx)[:, None]).reshape(-1)
    return np.bincount(off, weights=w.reshape(-1), minlength=Bx * N1).reshape(Bx, N1)


class Group:
    """All elements of one component type with the same options."""

    def __init__(self, comp: Component, elements: list[ElementData], index: int = 0):
        self.comp = comp
        self.elements = elements
        self.ids = [e.id for e in elements]
        self.E = len(elements)
        self.states = comp.states()
        self.S = len(self.states)
        self.local_nodes = comp.local_nodes
        self.branches = comp.branches()
        self.K, self.M = len(self.local_nodes), len(self.branches)
        self.L = self.K + self.M
        self.observables = comp.observables()
        self.exprs = [(i, name, ex) for i, e in enumerate(elements) for name, ex in e.expressions.items()]
        # a parameter given as an expression or a waveform changes in time: A_loc may too
        self.constant = comp.matrix_constant([name for _, name, _ in self.exprs] +
                                             [name for e in elements for name in e.waveforms])
        self.index = index  # position in the structure's groups
        self.base = self  # the structural group (a bound group points at it; lazy scatters live there)

    def bound(self, p: dict, waves) -> "Group":
        """This group with values: ``p`` {name: (1 or B, E)} and ``waves`` [(i, name, waveform)]
        (a shallow copy: the structure is shared)."""
        g = copy.copy(self)
        g.p = dict(p)
        g.waves = list(waves)
        g.time_dependent = self.comp.time_dependent or bool(g.waves)
        return g

    @property
    def ST_A(self):
        """Scatter of local matrix stamps into the flattened dense (n+1)^2 system (dense path
        only; built on first use: its row pointer alone has (n+1)^2 entries)."""
        base = self.base
        st = base.__dict__.get("_ST_A")
        if st is None:
            nA = base.flat.size
            st = sp.csr_matrix((np.ones(nA), (base.flat, np.arange(nA))), shape=(base.N1 * base.N1, nA))
            base._ST_A = st
        return st

    def source_values(self, t, B):
        """Waveform contributions (B, E) at time t (scalar or (B,1) array); None if none."""
        if not self.waves:
            return None
        tt = np.asarray(t, dtype=float)
        src = np.zeros(np.broadcast_shapes(tt.shape[:1] if tt.ndim else (1,), (B,)) + (self.E,))
        for i, _, wf in self.waves:
            src[:, i] = wf.sample(tt) if tt.ndim else wf(float(tt))
        return src


@dataclass
class Column:
    name: str
    unit: str


class CircuitStructure:
    """What a netlist fixes and parameter values cannot change (made once, then shared by
    every value variant of a circuit): the elements, groups and their topology, the
    numbering of nodes, branch flows and states, the conservation laws and constraints, and
    structural caches (the sparse nodal pattern, the incidence matrices).  Never mutated
    after construction except to fill those caches."""

    def __init__(self, netlist: Netlist, elements: list[ElementData]):
        self.netlist = netlist
        self.file = netlist.file
        self.elements = {e.id: e for e in elements}
        comps = [e.cls(e.opts) for e in elements]
        self.laws = check_topology(elements, comps, netlist.file)
        # --- nodes and unknowns -------------------------------------------------------
        nodes = []
        for e, c in zip(elements, comps):
            for n in local_node_map(e, c).values():
                if n != GROUND and n not in nodes:
                    nodes.append(n)
        self.nodes = nodes
        node_index = {n: i for i, n in enumerate(nodes)}
        # --- groups -------------------------------------------------------------------
        keyed: dict = {}
        for e, c in zip(elements, comps):
            key = (e.cls, tuple(sorted((k, repr(v)) for k, v in e.opts.items())))
            keyed.setdefault(key, (c, []))[1].append(e)
        self.groups = [Group(c, es, k) for k, (c, es) in enumerate(keyed.values())]
        n_branch = 0
        self.branch_names = []
        for g in self.groups:
            g.uidx = np.zeros((g.E, g.L), dtype=int)
            for i, e in enumerate(g.elements):
                m = local_node_map(e, g.comp)
                for j, ln in enumerate(g.local_nodes):
                    g.uidx[i, j] = -1 if m[ln] == GROUND else node_index[m[ln]]
                for j, _ in enumerate(g.branches):
                    g.uidx[i, g.K + j] = len(nodes) + n_branch
                    self.branch_names.append(f"{e.id}#{j}")
                    n_branch += 1
        self.n = len(nodes) + n_branch
        for g in self.groups:
            g.uidx[g.uidx < 0] = self.n  # ground slot, pressure fixed at 0
            ui = g.uidx
            g.rows = np.repeat(ui[:, :, None], g.L, axis=2)  # (E, L, L)
            g.cols = np.repeat(ui[:, None, :], g.L, axis=1)
            N1 = self.n + 1
            g.flat = (g.rows * N1 + g.cols).reshape(-1)
            g.N1 = N1
            # scatter of local stamps into the global system, as sparse 0/1 matrices (duplicates
            # add up); sparse products beat dense BLAS for these thin shapes by far.  g.ST_A
            # (matrix, dense path) is built on first use, g.SP_A (sparse path) by _sparse_pattern
            nb = g.E * g.L
            g.ST_b = sp.csr_matrix((np.ones(nb), (ui.reshape(-1), np.arange(nb))), shape=(N1, nb))
        # --- states -------------------------------------------------------------------
        names, units, scales, owners = [], [], [], []
        for g in self.groups:
            g.sidx = np.zeros((g.E, g.S), dtype=int)
            for i, e in enumerate(g.elements):
                for j, s in enumerate(g.states):
                    g.sidx[i, j] = len(names)
                    names.append(f"{e.id}.{s.name}")
                    units.append(s.unit)
                    scales.append(s.scale)
                    owners.append((e.id, s.name))
        self.state_names, self.state_units = names, units
        self.state_scales = np.array(scales, dtype=float)
        self.nx = len(names)
        self._locate = {e.id: (g, i) for g in self.groups for i, e in enumerate(g.elements)}
        self.schema = ParameterSchema(self.file, self.elements, [g.ids for g in self.groups])
        self._bind_constraints()
        self._steady = None
        self._memo = {}

    def __getstate__(self):
        return {**self.__dict__, "_memo": {}}

    # ------------------------------------------------------------------ parameters ----
    def cached(self, key, compute):
        """Memo of a pure function of this structure and ``key`` (the key must hold every
        input, e.g. a ParameterSet.fingerprint()); the 64 most recent entries are kept."""
        memo = self._memo
        if key in memo:
            memo[key] = memo.pop(key)  # most recent last
        else:
            memo[key] = compute()
            if len(memo) > 64:
                memo.pop(next(iter(memo)))
        return memo[key]

    def steady(self) -> "CircuitStructure":
        """This structure with each component's ``steady_opts`` applied (for steady-state
        solves; same topology and numbering); itself when no component has any."""
        if not any(g.comp.steady_opts for g in self.groups):
            return self
        if self._steady is None:
            s = copy.copy(self)
            s.groups = []
            for g in self.groups:
                ng = copy.copy(g)
                ng.base = ng
                if g.comp.steady_opts:
                    ng.comp = copy.copy(g.comp)
                    ng.comp.opts = {**g.comp.opts, **g.comp.steady_opts}
                s.groups.append(ng)
            s._locate = {eid: (s.groups[g.index], i) for eid, (g, i) in self._locate.items()}
            s.law_specs = [_remap_spec(spec, s.groups) for spec in self.law_specs]
            s._steady = s
            s._memo = {}
            self._steady = s
        return self._steady

    # --------------------------------------------------------------- constraints -------
    def _bind_constraints(self):
        self.law_specs = []
        specs = list(self.netlist.constraints)
        for law in self.laws:
            match = [c for c in specs if isinstance(c, dict) and c.get("node") in law.nodes]
            if not match:
                node = sorted(law.nodes)[0]
                raise TopologyError(
                    f"node(s) {sorted(law.nodes)} connect only through volume stores, so the stored volume "
                    f"{law.describe()} is conserved and the operating point is undefined until it is fixed: add "
                    f"'constraints: [{{node: {node}, volume: <total> mL}}]' or a calibration "
                    f"'{{node: {node}, pressure: <P> mmHg, when: {{<ID.PARAM>: <value with unit>}}}}'",
                    file=self.file, element=law.terms[0][0], node=node)
            c = match[0]
            specs.remove(c)
            self.law_specs.append(self._parse_constraint(c, law))
        for c in specs:
            node = c.get("node") if isinstance(c, dict) else None
            raise NetlistError(f"constraint {c!r} does not match a conservation law (only nodes connected "
                               "exclusively through volume stores need one)", file=self.file, node=node)

    def _parse_constraint(self, c, law):
        where = {"file": self.file, "node": c.get("node")}
        unknown = set(c) - {"node", "volume", "pressure", "when"}
        if unknown:
            raise NetlistError(f"unknown constraint key(s) {sorted(unknown)}", **where)
        # the state whose equation the law replaces (and, in the DC guess, the store kept
        # closed to anchor the group's pressure): preferably a store leading to ground
        row = anchor = None
        anchor_to_ground = False
        terms = []
        for eid, si, sign in law.terms:
            g, i = self._locate[eid]
            st = g.comp.storages()[si]
            terms.append((g, i, st.volume, sign))
            if st.state is None:
                continue
            m = local_node_map(self.elements[eid], g.comp)
            to_ground = GROUND in (m[st.plus], m[st.minus])
            if row is None or (to_ground and not anchor_to_ground):
                row = g.sidx[i, [s.name for s in g.states].index(st.state)]
                anchor, anchor_to_ground = (g, i), to_ground
        try:
            if "volume" in c:
                return {"kind": "volume", "volume": parse_quantity(c["volume"], "mL", "constraint volume"),
                        "terms": terms, "row": row, "law": law, "anchor": anchor}
            if "pressure" in c:
                when = c.get("when") or {}
                if not isinstance(when, dict):
                    raise NetlistError("'when' must be a mapping ID.PARAM: value", **where)
                for k in when:
                    self.schema.resolve(k)
                return {"kind": "calibration", "pressure": parse_quantity(c["pressure"], "mmHg", "constraint pressure"),
                        "node": c["node"], "when": when, "terms": terms, "row": row, "law": law, "anchor": anchor}
        except UnitError as exc:
            raise NetlistError(str(exc), **where) from None
        raise NetlistError("a constraint needs 'volume' (conserved total) or 'pressure' with 'when' "
                           "(calibration)", **where)
    def sparse_pattern(self):
        """The nodal matrix's CSC pattern: every element's whole local stamp block (ground
        rows and columns dropped), with each group's scatter onto its values (g.SP_A)."""
        pat = self.__dict__.get("_pattern")
        if pat is None:
            n = self.n
            rows = np.concatenate([g.rows.reshape(-1) for g in self.groups])
            cols = np.concatenate([g.cols.reshape(-1) for g in self.groups])
            inside = (rows < n) & (cols < n)
            pat = sparse_la.Pattern(n, rows[inside], cols[inside])
            for g in self.groups:
                r, c = g.rows.reshape(-1), g.cols.reshape(-1)
                k = np.nonzero((r < n) & (c < n))[0]
                g.SP_A = sp.csr_matrix((np.ones(k.size), (pat.position(r[k], c[k]), k)),
                                       shape=(pat.nnz, r.size))
            self._pattern = pat
        return pat

    def incidence(self):
        """Element-level incidence matrices (structure only, cached): own (nx, elements) state ->
        its element, unk (elements, n) element -> its nodal unknowns, infl (elements, nx) element
        -> the states it depends on (its own, and those of elements whose observables its
        parameter expressions read)."""
        inc = self.__dict__.get("_incidence_cache")
        if inc is None:
            n, nx = self.n, self.nx
            eidx, k = {}, 0
            for g in self.groups:
                for i, eid in enumerate(g.ids):
                    eidx[eid] = k
                    k += 1
            ne = k
            o_r, o_c, u_r, u_c, f_r, f_c = [], [], [], [], [], []
            for g in self.groups:
                e0 = eidx[g.ids[0]]
                el = e0 + np.arange(g.E)
                o_r.append(g.sidx.reshape(-1))
                o_c.append(np.repeat(el, g.S))
                ui = g.uidx.reshape(-1)
                inside = ui < n
                u_r.append(np.repeat(el, g.L)[inside])
                u_c.append(ui[inside])
                for i, _, ex in g.exprs:
                    for ref in ex.refs.values():
                        if ref.kind == "observable":
                            rg, ri = self._locate[ref.element]
                            f_r.append(np.full(rg.S, e0 + i))
                            f_c.append(rg.sidx[ri])
            own = sp.csr_matrix((np.ones(nx), (np.concatenate(o_r), np.concatenate(o_c))), shape=(nx, ne))
            unk = sp.csr_matrix((np.ones(sum(a.size for a in u_r)), (np.concatenate(u_r), np.concatenate(u_c))),
                                shape=(ne, n))
            infl = own.T.tocsr()
            if f_r:
                fr, fc = np.concatenate(f_r), np.concatenate(f_c)
                infl = infl + sp.csr_matrix((np.ones(fr.size), (fr, fc)), shape=(ne, nx))
            inc = (own, unk, infl.tocsr(), eidx)
            self._incidence_cache = inc
        return inc


def _remap_spec(spec, groups):
    """A conservation-law spec with its group references pointing at ``groups`` (by index)."""
    ns = dict(spec)
    ns["terms"] = [(groups[g.index], i, vol, sign) for g, i, vol, sign in spec["terms"]]
    ns["anchor"] = (groups[spec["anchor"][0].index], spec["anchor"][1])
    return ns


class Circuit:
    """An assembled, validated, immutable circuit: a shared :class:`CircuitStructure` plus a
    :class:`ParameterSet`.  Build with :func:`assemble` or ``hemocircuit.load``; make value
    variants with :meth:`with_values` / :meth:`with_parameters` (and batch, member, subset,
    with_options, steady_variant)."""

    #: structural attributes, shared with the structure
    _SHARED = ("netlist", "file", "elements", "laws", "nodes", "branch_names", "n", "state_names",
               "state_units", "state_scales", "nx")
    #: private caches: derived from this object's structure and values, dropped when pickled
    _CACHES = ("_subset_cache", "_memo", "_steady", "_jac_plans", "_rep_cache")

    def __init__(self, netlist: Netlist, elements: list[ElementData]):
        structure = CircuitStructure(netlist, elements)
        self._bind(structure, ParameterSet.from_elements(structure.schema), None)
        self._prepare()

    @classmethod
    def _of(cls, structure, parameters, threshold=None) -> "Circuit":
        c = cls.__new__(cls)
        c._bind(structure, parameters, threshold)
        c._prepare()
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
        self.law_specs = [_remap_spec(s, self.groups) for s in structure.law_specs]
        self._subset_cache, self._memo, self._steady = {}, {}, None

    def __getstate__(self):
        state = dict(self.__dict__)
        for k in self._CACHES:
            state.pop(k, None)
        return state

    def __setstate__(self, state):
        self.__dict__.update(state)
        self._subset_cache, self._memo, self._steady = {}, {}, None
        self._jac_plans, self._rep_cache = {}, {}

    def _prepare(self):
        """Everything that depends only on the structure and the values (once per object).

        Groups whose stamps depend neither on states nor on time ("static": resistors,
        constant sources) are stamped here once, into A_const and b_const, and skipped by
        every right-hand-side evaluation.
        """
        N1 = self.n + 1
        self._jac_plans = {}  # Jacobian sparsity patterns (sparse path) for these parameters
        sparse = self.sparse
        # dense path: the flattened (n+1)^2 matrix; sparse path: its values on the CSC pattern
        self.A_const = np.zeros((self.B, self.structure.sparse_pattern().nnz if sparse else N1 * N1))
        self.b_const = np.zeros((self.B, N1))
        self.all_constant = True
        self.dynamic_groups = []
        for g in self.groups:
            g.static = (g.constant and g.S == 0 and not g.waves
                        and not g.comp.varies_in_time(g.p))
            if g.constant:
                A_loc, b_loc = g.comp.stamp(g.p, np.zeros((1, g.E, g.S)), None, 0.0, None)
                A_loc = np.broadcast_to(A_loc, (A_loc.shape[0], g.E, g.L, g.L))
                self.A_const = self.A_const + _scatter(self._scatter_A(g), A_loc)
                if g.static:
                    b_loc = np.broadcast_to(b_loc, (b_loc.shape[0], g.E, g.L))
                    self.b_const = self.b_const + _scatter(g.ST_b, b_loc)
            else:
                self.all_constant = False
            if not g.static:
                self.dynamic_groups.append(g)
        n = self.n
        self._Ainv = None
        self._lu = sparse_la.Factors()
        if self.all_constant and sparse:
            self._lu = sparse_la.Factors(self._factor_const())
        elif self.all_constant:
            A = self.A_const.reshape(-1, N1, N1)[:, :n, :n]
            try:
                self._Ainv = np.linalg.inv(A)
            except np.linalg.LinAlgError:
                raise TopologyError("the nodal equations are singular (a pressure is undefined)",
                                    file=self.file) from None
        self._rep_cache = {}

    # ------------------------------------------------------------- sparse path ---------
    #: the sparse path (splu factorisations, coloured sparse Jacobians) is taken when the
    #: nodal system has more unknowns than this; a circuit with another threshold:
    #: with_sparse_threshold
    sparse_threshold = sparse_la.SPARSE_MIN_UNKNOWNS

    @property
    def sparse(self) -> bool:
        """True when this circuit runs on the sparse path (n > its sparse threshold)."""
        return self.n > (self.sparse_threshold if self._threshold is None else self._threshold)

    def with_sparse_threshold(self, n_unknowns) -> "Circuit":
        """This circuit taking the sparse path above ``n_unknowns`` nodal unknowns (None: the
        default, ``hemocircuit.sparse.SPARSE_MIN_UNKNOWNS``; 0 forces it, a huge number forbids it)."""
        return Circuit._of(self.structure, self.parameters, None if n_unknowns is None else int(n_unknowns))

    def _sparse_pattern(self):
        return self.structure.sparse_pattern()

    def _outputs_sparse(self, t, x):
        """outputs() for large circuits: the same columns, in the same order, filled group by
        group (no per-element Python) into one (columns, T) array, time chunk by time chunk so
        that one evaluation's arrays stay under about OUTPUT_ELEMENTS numbers.  Checked against
        the general path on the first time point (names, order, values): None if they differ
        (then outputs() takes its general path)."""
        keys = [f"P({n})" for n in self.nodes if ":" not in n]
        p_nodes = np.array([j for j, n in enumerate(self.nodes) if ":" not in n], dtype=int)
        lay = []
        for g in self.groups:
            store_vols = set(g.comp.volume_observables())  # volumes are V(id)
            obs_names = [o.name for o in g.observables]
            st_j = [j for j, s in enumerate(g.states) if s.name not in obs_names]
            lay.append((len(keys), 1 + len(st_j) + len(g.observables), st_j))
            for e in g.ids:
                keys.append(f"Q({e})")
                keys += [f"{e}.{g.states[j].name}" for j in st_j]
                keys += [f"V({e})" if o.name in store_vols else f"{e}.{o.name}" for o in g.observables]
        if len(set(keys)) != len(keys):
            return None
        T = x.shape[0]
        width = self.n + 1 + sum(g.E * g.L * (g.L + 2) for g in self.groups)
        chunk = max(1, sparse_la.OUTPUT_ELEMENTS // width)
        M = np.empty((len(keys), T))  # column-major result: each column a contiguous row
        for i0 in range(0, T, chunk):
            i1 = min(T, i0 + chunk)
            Tc = i1 - i0
            xc = x[i0:i1]
            tt = np.broadcast_to(np.asarray(t, dtype=float), (T,))[i0:i1].reshape(Tc, 1) if np.ndim(t) else float(t)
            u, plist, stamps = self.evaluate(tt, xc, want="u")
            buf = np.empty((Tc, len(keys)))  # time-major chunk (contiguous writes), transposed once
            buf[:, :len(p_nodes)] = u[:, p_nodes]
            for g, p, st, (base, w, st_j) in zip(self.groups, plist, stamps, lay):
                if st is None:  # static group: stamp it for the flows
                    st = g.comp.stamp(p, xc[:, g.sidx], None, tt, None) + (None,)
                A_loc, b_loc, src = st
                ul = u[:, g.uidx]
                Bg = buf[:, base:base + w * g.E].reshape(Tc, g.E, w)  # (time, element, slot)
                if g.K:  # flow leaving the first terminal into the element
                    A0 = np.broadcast_to(A_loc, (Tc,) + A_loc.shape[1:])[:, :, 0, :]
                    Bg[:, :, 0] = (np.einsum("bej,bej->be", A0, ul)
                                   - np.broadcast_to(b_loc, (Tc,) + b_loc.shape[1:])[:, :, 0])
                else:
                    Bg[:, :, 0] = 0.0
                xl = xc[:, g.sidx]
                for k, j in enumerate(st_j):
                    Bg[:, :, 1 + k] = xl[:, :, j]
                obs = g.comp.observe(p, xl, ul, tt, src)
                for k, o in enumerate(g.observables):
                    v = obs[o.name]
                    Bg[:, :, 1 + len(st_j) + k] = (v if np.ndim(v) == 2 else np.broadcast_to(v, (Tc,))[:, None])
            M[:, i0:i1] = buf.T
        ref = self.outputs(np.ravel(t)[:1] if np.ndim(t) else t, x[:1])
        if list(ref) != keys:
            return None
        ref = np.array([np.ravel(ref[k])[0] for k in keys], dtype=float)
        big = np.max(np.abs(ref[np.isfinite(ref)]), initial=0.0)
        if not np.all(np.isclose(M[:, 0], ref, rtol=1e-6, atol=1e-12 * big, equal_nan=True)):
            return None
        return {k: M[r] for r, k in enumerate(keys)}

    def _scatter_A(self, g):
        return g.base.SP_A if self.sparse else g.ST_A

    def _factor_const(self):
        """Factorisations of the constant nodal matrix (per member), solved through the explicit
        sparse inverse where it is sparser than a few times the LU factors."""
        lus = self._factor(self.A_const, "the nodal equations are singular (a pressure is undefined)")
        pat = self._sparse_pattern()
        nz = np.any(self.A_const != 0, axis=0)
        S = sp.csr_matrix((np.ones(int(nz.sum())), (pat.indices[nz], pat.cols[nz])), shape=(self.n, self.n))
        return sparse_la.with_inverses(lus, S, 3 * max(lu.nnz for lu in lus))

    def _factor(self, data, message):
        """splu factorisations of the matrix rows ``data`` (rows, nnz) on the pattern."""
        try:
            lus = sparse_la.factor_rows(self._sparse_pattern(), data)
        except RuntimeError:  # SuperLU: "Factor is exactly singular"
            raise TopologyError(message, file=self.file) from None
        return lus

    def _rep(self, arr, Bx):
        """Parameter-batch array (B, ...) laid out for a stacked batch of Bx rows."""
        if arr.shape[0] == Bx or arr.shape[0] == 1:
            return arr
        return np.repeat(arr, Bx // arr.shape[0], axis=0)

    # --- public services for analyses (they use these, never the private helpers) -----
    # --- public services for analyses (they use these, never the private helpers) -----
    def group_params(self, rows=None):
        """Per-group parameter dicts laid out for ``rows`` state rows (a multiple of the batch
        size B; default B)."""
        return self._params(1) if rows is None or rows == self.B else self._params_for(rows)

    def element_group(self, eid):
        """(group, index in the group) of element ``eid``."""
        return self._locate[eid]

    def dc_unknowns(self, t, X):
        """Nodal unknowns of the DC network (stores open, inductors shorted: each component's
        ``dc_stamp``) for states X (B, nx).  Returns (u (B, n+1), bound parameters, stamps)."""
        plist = self._bound_params(X, self._params(1), t)
        A, b, stamps = self._assemble(t, X, plist, dc=True)
        return self._solve(A, b), plist, stamps

    def nodal_matrix(self, t, X):
        """The nodal matrix A (Bx, n, n) of A u = b at states X (Bx, nx) (dense path; for
        hemocircuit.derivatives)."""
        X = np.atleast_2d(np.asarray(X, dtype=float))
        Bx, n, N1 = X.shape[0], self.n, self.n + 1
        if self.sparse:
            raise HemocircuitError("nodal_matrix: this circuit runs on the sparse path")
        if self.all_constant:
            A = self._rep(self.A_const, Bx).reshape(-1, N1, N1)[:, :n, :n]
            return np.broadcast_to(A, (Bx, n, n))
        A, _, _ = self._assemble(t, X, self._bound_params(X, self._params_for(Bx), t))
        return A

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
        return new.with_parameters(ps._with_columns(updates)) if updates else new

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
        for ng, g in zip(c.groups, self.groups):  # prepared from the whole batch: same flags
            ng.static = g.static
        c.all_constant = self.all_constant
        c.dynamic_groups = [c.groups[g.index] for g in self.dynamic_groups]
        c.A_const = self.A_const[members] if self.A_const.shape[0] > 1 else self.A_const
        c.b_const = self.b_const[members] if self.b_const.shape[0] > 1 else self.b_const
        c._Ainv = None if self._Ainv is None else (self._Ainv[members] if self._Ainv.shape[0] > 1 else self._Ainv)
        c._lu = self._lu.subset(members)
        c._jac_plans = {}
        c._rep_cache = {}
        if len(cache) > 256:
            cache.pop(next(iter(cache)))
        cache[key] = c
        return c

    def member(self, k: int) -> "Circuit":
        """Batch member k as a single circuit."""
        if self.B == 1 and k in (0, -1):
            return self
        return self.with_parameters(self.parameters[k])

    def _params(self, rep):
        """Parameter dicts for a stacked batch in which each member appears ``rep`` times."""
        if rep == 1:
            return [g.p for g in self.groups]
        if rep not in self._rep_cache:
            self._rep_cache[rep] = [{k: (np.repeat(v, rep, axis=0) if v.shape[0] > 1 else v) for k, v in g.p.items()}
                                    for g in self.groups]
        return self._rep_cache[rep]

    def law_volumes(self, x):
        """Conserved combinations sum(sign * V) for states x (B', nx) -> list of (B',) arrays."""
        out = []
        if not self.law_specs:
            return out
        obs = self._state_observables(np.atleast_2d(x), self._params(1) if np.atleast_2d(x).shape[0] == self.B
                                      else self._params_for(np.atleast_2d(x).shape[0]))
        for s in self.law_specs:
            total = 0.0
            for g, i, vol, sign in s["terms"]:
                total = total + sign * obs[id(g)][vol][:, i]
            out.append(total)
        return out

    def _params_for(self, Bx):
        if Bx % self.B:
            raise HemocircuitError(f"state batch {Bx} is not a multiple of the parameter batch {self.B}")
        return self._params(Bx // self.B)

    # ------------------------------------------------------------------ evaluation -----
    def _state_observables(self, x, plist, t=0.0):
        out = {}
        for g, p in zip(self.groups, plist):
            xl = x[:, g.sidx]
            out[id(g)] = g.comp.observe(p, xl, None, t)
        return out

    def _bound_params(self, x, plist, t):
        """Parameters with expression-bound values filled in for states x."""
        if not any(g.exprs for g in self.groups):
            return plist
        Bx = x.shape[0]
        need = {}
        for g in self.groups:
            for _, _, ex in g.exprs:
                for key, ref in ex.refs.items():
                    if ref.kind == "observable":
                        need[ref.element] = True
        obs = {}
        for eid in need:
            g, i = self._locate[eid]
            p = plist[self.groups.index(g)]
            obs[eid] = (g.comp.observe(p, x[:, g.sidx], None, t), i)
        out = []
        for g, p in zip(self.groups, plist):
            if not g.exprs:
                out.append(p)
                continue
            p = dict(p)
            for i, name, ex in g.exprs:
                vals = {}
                for key, ref in ex.refs.items():
                    if ref.kind == "param":
                        og, oi = self._locate[ref.element]
                        vals[key] = plist[self.groups.index(og)][ref.name][:, oi]
                    elif ref.kind == "observable":
                        o, oi = obs[ref.element]
                        vals[key] = o[ref.name][:, oi]
                v = np.broadcast_to(ex.evaluate(vals), (Bx,))
                arr = np.array(np.broadcast_to(p[name], (Bx, g.E)))
                arr[:, i] = v
                p[name] = arr
            out.append(p)
        return out

    def _assemble(self, t, x, plist, dc=False, u=None):
        """Stamp the non-static groups onto the cached static part.

        Returns (A (Bx,n,n), or None when the cached inverse applies; b (Bx,n); per-group
        stamps (None for static groups)).
        """
        Bx = x.shape[0]
        N1 = self.n + 1
        b = np.array(np.broadcast_to(self._rep(self.b_const, Bx), (Bx, N1)))
        need_A = dc or not self.all_constant
        sparse = self.sparse
        if sparse:  # values on the pattern, one row, or one per batch row (never copied per row)
            A = self._rep(self.A_const, Bx) if need_A else None
        else:
            A = np.array(np.broadcast_to(self._rep(self.A_const, Bx), (Bx, N1 * N1))) if need_A else None
        stamps = [None] * len(self.groups)
        for k, (g, p) in enumerate(zip(self.groups, plist)):
            if g.static and not dc:
                continue
            xl = x[:, g.sidx]
            src = g.source_values(t, Bx) if g.waves else None
            # u: the current pressure iterate, for elements that are nonlinear in the pressures
            ul = None if (u is None or g.comp.linear_in_pressure) else u[:, g.uidx]
            A_loc, b_loc = g.comp.stamp(p, xl, ul, t, src)
            if A_loc.ndim != 4 or A_loc.shape[1] != g.E:
                A_loc = np.broadcast_to(A_loc, (A_loc.shape[0], g.E, g.L, g.L))
            if b_loc.shape[1:] != (g.E, g.L):
                b_loc = np.broadcast_to(b_loc, (b_loc.shape[0], g.E, g.L))
            if dc and g.comp.has_dc_stamp():
                A_loc, b_loc = self._dc_stamp(g, p, A_loc, b_loc)
                A = A + _scatter(self._scatter_A(g), A_loc)
                if g.constant:
                    A = A - self._const_part(g, Bx)
            elif need_A and not g.constant:
                A = A + _scatter(self._scatter_A(g), A_loc)
            if not g.static:  # static groups are already in b_const
                if sparse:
                    b += _bincount_scatter(g.uidx, b_loc, Bx, N1)
                else:
                    b = b + _scatter(g.ST_b, b_loc)
            stamps[k] = (A_loc, b_loc, src)
        n = self.n
        if A is not None and not sparse:
            A = A.reshape(Bx, N1, N1)[:, :n, :n]
        return A, b[:, :n], stamps

    @property
    def nonlinear(self):
        """True if some element is nonlinear in the pressures (Newton on the nodal equations)."""
        return any(not g.comp.linear_in_pressure for g in self.groups)

    def _newton_pressures(self, t, x, plist, dc, u, tol=1e-12, max_iter=50):
        """Newton on the nodal equations: such elements stamp their linearisation at the
        current pressures (A_loc = d flow/d P, b_loc so that A_loc u - b_loc = flow(u))."""
        for _ in range(max_iter):
            A, b, stamps = self._assemble(t, x, plist, dc=dc, u=u)
            u_new = self._solve(A, b)
            done = np.max(np.abs(u_new - u) / (1.0 + np.abs(u_new))) < tol
            u = u_new
            if done:
                return u, stamps
        raise SolverError(f"the nodal equations did not converge in {max_iter} Newton iterations "
                          "(an element nonlinear in the pressures)", time=float(np.ravel(t)[0]) if np.ndim(t) else t)

    def _const_part(self, g, Bx):
        A_loc, _ = g.comp.stamp(g.p, np.zeros((1, g.E, g.S)), None, 0.0, None)
        A_loc = np.broadcast_to(A_loc, (A_loc.shape[0], g.E, g.L, g.L))
        return self._rep(_scatter(self._scatter_A(g), A_loc), Bx)

    def _dc_stamp(self, g, p, A_loc, b_loc):
        """The group's stamp in the DC-guess network (Component.dc_stamp, on writable copies).
        One store per conservation law keeps its stamp: it anchors the pressure of a node
        group that is otherwise joined to the circuit only through open stores."""
        keep = np.zeros(g.E, dtype=bool)
        for s in self.law_specs:
            gg, i = s["anchor"]
            if gg is g:
                keep[i] = True
        return g.comp.dc_stamp(p, np.array(A_loc), np.array(b_loc), keep)

    def _solve(self, A, b):
        """Node pressures and branch flows (Bx, n + 1; the ground slot last) from the assembled
        system: A None (the cached inverse / factorisation applies), a dense stack (Bx, n, n),
        or on the sparse path the values (1 or Bx, nnz) on the pattern."""
        if self.sparse:
            u = self._solve_sparse(A, b)
        elif A is None:
            Ainv = self._Ainv
            if Ainv.shape[0] != b.shape[0]:
                Ainv = np.repeat(Ainv, b.shape[0] // Ainv.shape[0], axis=0)
            u = np.einsum("bij,bj->bi", Ainv, b)
        else:
            try:
                u = solve_batched(A, b)
            except np.linalg.LinAlgError:
                u = np.full(b.shape, np.nan)
            if not np.all(np.isfinite(u)):
                raise TopologyError("the nodal equations are singular at this state (a pressure is undefined)",
                                    file=self.file)
        return np.concatenate([u, np.zeros((u.shape[0], 1))], axis=1)  # + ground slot

    def _solve_sparse(self, A, b):
        """The batch rows of b are the columns of one solve per factorisation."""
        if A is None:
            if self._lu.lus is None:  # unpickled: factorise again
                self._lu = sparse_la.Factors(self._factor_const())
            lus = self._lu.lus
        else:
            lus = self._factor(A, "the nodal equations are singular at this state (a pressure is undefined)")
        u = sparse_la.solve_rows(lus, b)
        if not np.all(np.isfinite(u)):
            raise TopologyError("the nodal equations are singular at this state (a pressure is undefined)",
                                file=self.file)
        return u

    def evaluate(self, t, x, dc=False, want="rhs"):
        """Core evaluation for a stacked batch x (Bx, nx).

        Returns dx/dt (Bx, nx) for want='rhs', or the intermediate pieces for outputs.
        """
        x = np.asarray(x, dtype=float)
        if x.ndim == 1:
            x = x[None, :]
        Bx = x.shape[0]
        plist = self._bound_params(x, self._params_for(Bx), t)
        A, b, stamps = self._assemble(t, x, plist, dc=dc)
        u = self._solve(A, b)
        if self.nonlinear:
            u, stamps = self._newton_pressures(t, x, plist, dc, u)
        if want == "u":
            return u, plist, stamps
        dx = np.empty((Bx, self.nx))
        for g, p, st in zip(self.groups, plist, stamps):
            if g.S == 0:
                continue
            dx[:, g.sidx] = g.comp.derivatives(p, x[:, g.sidx], u[:, g.uidx], t, st[2])
        return dx

    def rhs(self, t, x):
        """dx/dt for a single run (x of shape (nx,)) or a batch (B, nx)."""
        if np.ndim(x) == 1:
            return self.evaluate(t, x)[0]
        return self.evaluate(t, x)

    def jacobian(self, t, x):
        """Finite-difference Jacobian d(dx/dt)/dx, all columns from one batched evaluation.

        x: (nx,) -> (nx, nx); or (B, nx) -> (B, nx, nx).
        On the sparse path (see :attr:`sparse`): a ``scipy.sparse.csc_matrix`` (nx, nx), or a
        list of B of them, by coloured finite differences (see :meth:`sparse_jacobian`).
        """
        if self.sparse:
            Js = self.sparse_jacobian(t, x)[0]
            return Js[0] if np.ndim(x) == 1 else Js
        from .derivatives import dense_jacobian

        single = np.ndim(x) == 1
        J, _ = dense_jacobian(lambda rows: self.evaluate(t, rows), x, self.state_scales)
        return J[0] if single else J

    def jacobian_plan(self, key, fun, X, t=0.0, row_reads=None, how="auto"):
        """The Jacobian sparsity pattern and column colouring of ``fun`` (rows (m, nx) ->
        (m, nx), the right-hand side or the operating point's residual), once per parameter
        set and structural option set under ``key``.

        Structural (how='auto' or 'structural'): from the elements' incidence and the generic
        structure of the nodal matrix's inverse (:func:`hemocircuit.sparse.structural_pattern`),
        valid at every state.  ``row_reads`` {state row: (element ids whose states it reads,
        nodal unknowns it reads)} replaces rows that are not the element's own equation (the
        operating point's conservation-law rows).  Numerical (how='numerical', or when the
        nodal matrix is structurally singular): finite differences at X in column blocks.
        """
        key = (key, how, tuple(tuple(sorted((k, repr(v)) for k, v in g.comp.opts.items())) for g in self.groups))
        plans = self._jac_plans
        if key not in plans:
            X = np.atleast_2d(np.asarray(X, dtype=float))
            rc = self._structural_pattern(t, X, row_reads) if how != "numerical" else None
            if rc is None:
                width = self.n + 1 + sum(g.E * g.L * (g.L + 1) for g in self.groups)
                plans[key] = sparse_la.detect_pattern(fun, X, self.state_scales, width)
            else:
                diag = np.arange(self.nx)
                plans[key] = sparse_la.JacobianPlan(self.nx, np.concatenate([rc[0], diag]),
                                                    np.concatenate([rc[1], diag]), "structural")
        return plans[key]

    def _structural_pattern(self, t, X, row_reads=None):
        """(rows, cols) of the structural Jacobian pattern (see jacobian_plan) or None."""
        n, nx = self.n, self.nx
        pat = self._sparse_pattern()
        # nonzero structure of the nodal matrix: the constant part's values, and each other
        # group's local nonzeros (at these states, any element) at every element of the group
        A_const = self.A_const if self.sparse else None
        if A_const is not None:
            nzc = np.any(A_const != 0, axis=0)
            rows, cols = [pat.indices[nzc]], [pat.cols[nzc]]
        else:  # dense layout (n+1)^2
            flat = np.nonzero(np.any(self.A_const != 0, axis=0))[0]
            rows, cols = [flat // (n + 1)], [flat % (n + 1)]
        _, _, stamps = self.evaluate(t, X, want="u")
        for g, st in zip(self.groups, stamps):
            if st is None or g.constant:
                continue
            m = np.any(np.asarray(st[0]) != 0, axis=tuple(range(np.ndim(st[0]) - 2)))  # (L, L)
            rows.append(g.rows[:, m].reshape(-1))
            cols.append(g.cols[:, m].reshape(-1))
        r, c = np.concatenate(rows), np.concatenate(cols)
        inside = (r < n) & (c < n)
        S = sp.csr_matrix((np.ones(int(inside.sum())), (r[inside], c[inside])), shape=(n, n))
        own, unk, infl, eidx = self.structure.incidence()
        read = own @ unk  # (nx, n)
        infl_rows = unk.T @ infl  # (n, nx)
        direct = own @ infl  # (nx, nx)
        if row_reads:
            keep = np.ones(nx)
            keep[list(row_reads)] = 0.0
            K = sp.diags(keep)
            rr, rc_, dr, dc_ = [], [], [], []
            for row, (eids, unknowns) in row_reads.items():
                for eid in eids:
                    st = infl[eidx[eid]].indices
                    dr += [row] * st.size
                    dc_ += list(st)
                rr += [row] * len(unknowns)
                rc_ += list(unknowns)
            read = K @ read + sp.csr_matrix((np.ones(len(rr)), (rr, rc_)), shape=(nx, n))
            direct = K @ direct + sp.csr_matrix((np.ones(len(dr)), (dr, dc_)), shape=(nx, nx))
        return sparse_la.structural_pattern(S, read, infl_rows, direct)

    def sparse_jacobian(self, t, x):
        """Coloured finite-difference Jacobians d(dx/dt)/dx at x (nx,) or (B, nx): returns
        ([csc_matrix (nx, nx)] per member, dx/dt (B, nx)).  Same steps as :meth:`jacobian`."""
        X = np.atleast_2d(np.asarray(x, dtype=float))

        def fun(rows):
            return self.evaluate(t, rows)

        plan = self.jacobian_plan("rhs", fun, X, t)
        return sparse_la.coloured_jacobian(fun, X, self.state_scales, plan)

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

    def outputs(self, t, x, engine="auto") -> dict:
        """All outputs for states x (T, nx) at times t (T,) -> {column name: (T,) array}.

        Evaluated for all times at once (the time series is treated as a batch).  ``engine``
        'auto': from COMPILED_OUTPUT_ROWS rows on, the nodal solution and flows come from the
        compiled engine when this process already runs compiled code and the function is compiled
        (kernels.system.CompiledSystem.nodal_outputs; the same values to rounding, vasomotion's
        10 001 rows in 17 ms instead of 30 ms); 'numpy': always the numpy evaluation.
        """
        x = np.atleast_2d(np.asarray(x, dtype=float))
        T = x.shape[0]
        if self.sparse and self.B == 1 and T > 1:  # large circuits: vectorised, in bounded chunks
            out = self._outputs_sparse(t, x)
            if out is not None:
                return out
        tt = np.broadcast_to(np.asarray(t, dtype=float), (T,)).reshape(T, 1) if np.ndim(t) else float(t)
        if self.B != 1 and T % self.B:
            raise HemocircuitError("outputs() of a batch circuit needs one member's parameters: use member(k)")
        if engine not in ("auto", "numpy"):
            raise ValueError(f"engine {engine!r}: choose 'auto' or 'numpy'")
        nodal = self._compiled_nodal(tt, x) if engine == "auto" and T >= COMPILED_OUTPUT_ROWS else None
        if nodal is None:
            u, plist, stamps = self.evaluate(tt, x, want="u")
        else:  # the same u and flows from the compiled engine
            u, F = nodal
            plist, stamps = self._bound_params(x, self._params_for(T), tt), [None] * len(self.groups)
        out = {}
        for j, n in enumerate(self.nodes):
            if ":" not in n:
                out[f"P({n})"] = u[:, j]
        e0 = 0  # the group's first element in the compiled engine's numbering (group order)
        for g, p, st in zip(self.groups, plist, stamps):
            ul = u[:, g.uidx]
            if nodal is not None:
                flows, src = nodal[1][:, e0:e0 + g.E], (g.source_values(tt, T) if g.waves else None)
            else:
                if st is None:  # static group: stamp it for the flows
                    st = g.comp.stamp(p, x[:, g.sidx], None, tt, None) + (None,)
                A_loc, b_loc, src = st
                # the branch flow: the first row of the local residual A u - b (only it is reported)
                flows = None
                if g.K:
                    A_row = A_loc[:, :, 0, :]
                    flows = (np.einsum("bej,bej->be", np.broadcast_to(A_row, (T,) + A_row.shape[1:]), ul)
                             - b_loc[..., 0])
            e0 += g.E
            xl = x[:, g.sidx]
            obs = g.comp.observe(p, xl, ul, tt, src)
            store_vols = set(g.comp.volume_observables())  # volumes are V(id)
            obs_names = [o.name for o in g.observables]
            for i, e in enumerate(g.ids):
                out[f"Q({e})"] = flows[:, i] if g.K else np.zeros(T)
                for j, s in enumerate(g.states):
                    if s.name not in obs_names:
                        out[f"{e}.{s.name}"] = xl[:, i, j]
                for o in g.observables:
                    key = f"V({e})" if o.name in store_vols else f"{e}.{o.name}"
                    out[key] = np.broadcast_to(obs[o.name][:, i] if np.ndim(obs[o.name]) == 2 else obs[o.name], (T,))
        return out

    def _compiled_nodal(self, tt, x):
        """(u, element flows) for outputs() from the compiled engine, or None: a sparse circuit,
        no engine for its types, or an engine this process would have to compile first (outputs
        never wait for a compilation)."""
        import sys

        # only where compiled engines are in use already: never import numba or write an
        # engine module for outputs alone (codegen keeps the engine modules this process loaded;
        # a lookup, not a scan of sys.modules: a frequency response asks once per block)
        codegen = sys.modules.get("hemocircuit.kernels.codegen")
        if self.sparse or codegen is None or not codegen.loaded_any():
            return None
        from .kernels.system import CompiledSystem

        system = CompiledSystem.of(self)
        if system is None or not system.nodal_outputs_ready():
            return None
        return system.nodal_outputs(tt, x, system.params(self))

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
