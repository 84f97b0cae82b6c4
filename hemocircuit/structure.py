"""What a netlist fixes and parameter values cannot change: the groups of elements (one
component type and option set each) with their index arrays into the nodal system and the
state vector, the numbering of nodes, branch flows and states, the conservation laws and
their constraints, and the structural caches (the sparse nodal pattern, incidence matrices).

Made once per netlist and structural option set (:class:`CircuitStructure`), then shared by
every value variant of a :class:`hemocircuit.circuit.Circuit`.  Local stamps reach the global
nodal system through index arrays (``flat``, ``uidx``) that :mod:`hemocircuit.system` scatters
with ``np.bincount``; scipy is imported only by the sparse path (``sparse_pattern``,
``incidence``), so that a small circuit's operating point never loads it.
"""
from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np

from .build import ElementData
from .component import Component
from .errors import NetlistError, TopologyError
from .graph import check_topology, local_node_map
from .netlist import GROUND, Netlist
from .parameters import ParameterSchema
from .units import UnitError, parse_quantity


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
            # where each local stamp entry lands: g.flat in the flattened dense (n+1)^2 matrix,
            # g.uidx in the right-hand side (duplicates add up: hemocircuit.system.scatter_add);
            # g.SP_A, the scatter onto the sparse path's pattern, is made by sparse_pattern
            g.flat = (g.rows * N1 + g.cols).reshape(-1)
            g.N1 = N1
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

    def recall(self, key, default=None):
        """The memo of ``key`` if :meth:`cached` holds one, else ``default`` (nothing stored)."""
        return self._memo.get(key, default)

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
            s.law_specs = [remap_spec(spec, s.groups) for spec in self.law_specs]
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

    # ------------------------------------------------------------ structural caches -----
    def sparse_pattern(self):
        """The nodal matrix's CSC pattern: every element's whole local stamp block (ground
        rows and columns dropped), with each group's scatter onto its values (g.SP_A)."""
        pat = self.__dict__.get("_pattern")
        if pat is None:
            import scipy.sparse as sp

            from . import sparse as sparse_la

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
            import scipy.sparse as sp

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


def remap_spec(spec, groups):
    """A conservation-law spec with its group references pointing at ``groups`` (by index)."""
    ns = dict(spec)
    ns["terms"] = [(groups[g.index], i, vol, sign) for g, i, vol, sign in spec["terms"]]
    ns["anchor"] = (groups[spec["anchor"][0].index], spec["anchor"][1])
    return ns

