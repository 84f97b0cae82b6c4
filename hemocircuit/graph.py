"""The circuit graph and the topology pass that runs before any solve.

Checks, each with an error naming the file, element and node:
  - an element whose terminals are all the same node;
  - a node touched by only one element terminal (dangling);
  - a sub-network with no path to ``ground`` (no pressure reference);
  - a loop made only of pressure-defining elements (sources, compliances);
  - a node reached only through flow-defining elements (inductors, flow sources);
and finds the conservation laws: groups of nodes joined to the rest of the circuit only
through volume stores (compliances), like the intracranial node of the thesis's ICP variant,
whose total stored volume is fixed and must be given by a ``constraints:`` entry.

Connectivity is a disjoint-set forest (:class:`_Components`), not networkx: importing networkx
costs ~0.2 s, half the budget of a whole ``op`` run, for three connected-component searches.
"""
from __future__ import annotations

from dataclasses import dataclass

from .errors import TopologyError
from .netlist import GROUND


@dataclass
class ConservationLaw:
    nodes: frozenset  # the group of nodes
    terms: list  # [(element id, storage index, sign)]: sum(sign * volume) is constant

    def describe(self):
        text = " ".join(f"{'+' if s > 0 else '-'} V({eid})" for eid, _, s in self.terms)
        return text[2:] if text.startswith("+ ") else text


def local_node_map(elem, comp):
    """Local node name -> global node name (internal nodes become 'ID:name')."""
    m = dict(zip(comp.terminals, elem.nodes))
    for n in comp.internal_nodes():
        m[n] = f"{elem.id}:{n}"
    return m


class _Components:
    """Connected components of a growing undirected graph (union-find with path halving).
    ``groups()`` lists them in the order of their first node, as networkx's
    connected_components does."""

    def __init__(self, nodes=()):
        self.parent = {}
        for n in nodes:
            self.add(n)

    def add(self, n):
        self.parent.setdefault(n, n)

    def find(self, n):
        parent = self.parent
        while parent[n] != n:
            parent[n] = parent[parent[n]]
            n = parent[n]
        return n

    def union(self, a, b):
        self.add(a)
        self.add(b)
        ra, rb = self.find(a), self.find(b)
        if ra != rb:
            self.parent[rb] = ra

    def joined(self, a, b):
        return a in self.parent and b in self.parent and self.find(a) == self.find(b)

    def groups(self):
        out = {}
        for n in self.parent:
            out.setdefault(self.find(n), set()).add(n)
        return list(out.values())


class _Edges:
    """The circuit's edges (element id, role, short at DC) by node, in the order they were added."""

    def __init__(self, elements, comps):
        self.adj = {}  # node -> {neighbour: [edge data]}, both in insertion order
        for elem, comp in zip(elements, comps):
            m = local_node_map(elem, comp)
            for n in m.values():
                self.adj.setdefault(n, {})
            for a, b, role in comp.edges():
                d = {"element": elem.id, "role": role, "short": comp.dc_short()}
                self.adj[m[a]].setdefault(m[b], []).append(d)
                if m[a] != m[b]:
                    self.adj[m[b]].setdefault(m[a], []).append(d)

    def __iter__(self):
        """(a, b, data) once per edge, node by node (the order networkx's MultiGraph.edges gives)."""
        seen = set()
        for n, nbrs in self.adj.items():
            for nbr, ds in nbrs.items():
                if nbr not in seen:
                    for d in ds:
                        yield n, nbr, d
            seen.add(n)

    def element_at(self, node):
        for ds in self.adj[node].values():
            return ds[0]["element"]
        return None


def check_topology(elements, comps, file=None):
    """Run every check; return the conservation laws.  Raises TopologyError."""
    for elem, comp in zip(elements, comps):
        if len(set(elem.nodes)) < len(elem.nodes) and len(elem.nodes) == 2:
            raise TopologyError(f"both terminals are on node '{elem.nodes[0]}' (the element is shorted out)",
                                file=elem.file, element=elem.id, node=elem.nodes[0])
        if len(elem.nodes) > 2 and elem.nodes[0] == elem.nodes[1]:
            raise TopologyError(f"terminals '{comp.terminals[0]}' and '{comp.terminals[1]}' are the same node",
                                file=elem.file, element=elem.id, node=elem.nodes[0])
    touches = {}
    for elem in elements:
        for n in elem.nodes:
            touches.setdefault(n, []).append(elem.id)
    for node, ids in touches.items():
        if node != GROUND and len(ids) == 1:
            raise TopologyError("the node is touched by only one element terminal (dangling)",
                                file=_file_of(elements, ids[0]) or file, element=ids[0], node=node)
    g = _Edges(elements, comps)
    if GROUND not in g.adj:
        first = elements[0] if elements else None
        raise TopologyError(f"no element connects to '{GROUND}': the circuit has no pressure reference",
                            file=(first.file if first else None) or file, element=first.id if first else None,
                            node=first.nodes[0] if first and first.nodes else None)
    edges = list(g)
    whole = _Components(g.adj)
    for a, b, _ in edges:
        whole.union(a, b)
    for comp_nodes in whole.groups():
        if GROUND not in comp_nodes:
            node = sorted(comp_nodes)[0]
            eid = g.element_at(node)
            raise TopologyError(f"this sub-network {sorted(comp_nodes)} has no path to '{GROUND}' "
                                "(no pressure reference)", file=_file_of(elements, eid) or file, element=eid, node=node)
    # a loop of pressure-defining elements over-determines pressures (singular MNA); with
    # inductors in it (a short at DC, as SPICE counts them) there is no steady state
    pg, tree = _Components(), {}  # the pressure-defining forest so far, and its edges by node
    shorts = set()
    for a, b, d in sorted(edges, key=lambda e: bool(e[2].get("short"))):
        if d["role"] == "pressure" or d.get("short"):
            if d.get("short"):
                shorts.add(d["element"])
            if pg.joined(a, b):
                loop = _tree_path(tree, a, b) + [d["element"]]
                if any(e in shorts for e in loop):
                    msg = (f"a loop of pressure-defining elements and inductors {loop}: an inductor is a short "
                           "circuit at steady state, so the loop's pressures over-determine each other and "
                           "there is no operating point")
                else:
                    msg = (f"a loop made only of pressure-defining elements {loop}: their pressures "
                           "over-determine each other")
                raise TopologyError(msg, file=_file_of(elements, d["element"]) or file, element=d["element"], node=a)
            pg.union(a, b)
            tree.setdefault(a, {})[b] = d["element"]
            tree.setdefault(b, {})[a] = d["element"]
    # nodes reached only through flow-defining elements have no defined pressure
    ng = _Components(g.adj)
    for a, b, d in edges:
        if d["role"] != "flow":
            ng.union(a, b)
    for comp_nodes in ng.groups():
        if GROUND not in comp_nodes:
            node = sorted(comp_nodes)[0]
            eid = g.element_at(node)
            raise TopologyError(f"node(s) {sorted(comp_nodes)} are reached only through flow-defining elements "
                                "(inductors, flow sources): their pressure is undefined",
                                file=_file_of(elements, eid) or file, element=eid, node=node)
    return conservation_laws(elements, comps)


def _tree_path(tree, a, b):
    """The elements on the path from a to b in a forest ({node: {neighbour: element}}; a and b
    joined), in order from a."""
    if a == b:
        return []
    back, frontier = {a: None}, [a]
    while b not in back:
        nxt = []
        for n in frontier:
            for m in tree.get(n, {}):
                if m not in back:
                    back[m] = n
                    nxt.append(m)
        frontier = nxt
    path, n = [], b
    while back[n] is not None:
        path.append(tree[n][back[n]])
        n = back[n]
    return path[::-1]


def conservation_laws(elements, comps):
    """Groups of nodes connected to the rest only through volume stores."""
    g = _Components()
    store_edges = []
    for elem, comp in zip(elements, comps):
        m = local_node_map(elem, comp)
        for n in m.values():
            g.add(n)
        stored = {(s.plus, s.minus) for s in comp.storages()}
        for a, b, role in comp.edges():
            if (a, b) not in stored and (b, a) not in stored:
                g.union(m[a], m[b])
        for i, s in enumerate(comp.storages()):
            store_edges.append((elem.id, i, m[s.plus], m[s.minus]))
            # a store's own internal node is joined to its element (arteriole midpoint)
    laws = []
    for group in g.groups():
        if GROUND in group:
            continue
        terms = []
        for eid, i, plus, minus in store_edges:
            if minus in group and plus not in group:
                terms.append((eid, i, +1))
            elif plus in group and minus not in group:
                terms.append((eid, i, -1))
        if terms and all(sign < 0 for _, _, sign in terms):
            # a closed loop of stores to ground: state the total as a positive sum
            terms = [(eid, i, +1) for eid, i, _ in terms]
        if terms:
            laws.append(ConservationLaw(frozenset(group), terms))
    return laws


def _file_of(elements, eid):
    for e in elements:
        if e.id == eid:
            return e.file
    return None
