"""The circuit graph (networkx) and the topology pass that runs before any solve.

Checks, each with an error naming the file, element and node:
  - an element whose terminals are all the same node;
  - a node touched by only one element terminal (dangling);
  - a sub-network with no path to ``ground`` (no pressure reference);
  - a loop made only of pressure-defining elements (sources, compliances);
  - a node reached only through flow-defining elements (inductors, flow sources);
and finds the conservation laws: groups of nodes joined to the rest of the circuit only
through volume stores (compliances), like the intracranial node of the thesis's ICP variant,
whose total stored volume is fixed and must be given by a ``constraints:`` entry.
"""
from __future__ import annotations

from dataclasses import dataclass

import networkx as nx

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


def circuit_graph(elements, comps):
    """MultiGraph of global nodes; edges carry element id and role."""
    g = nx.MultiGraph()
    for elem, comp in zip(elements, comps):
        m = local_node_map(elem, comp)
        g.add_nodes_from(m.values())
        for a, b, role in comp.edges():
            g.add_edge(m[a], m[b], element=elem.id, role=role, short=comp.dc_short())
    return g


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
    g = circuit_graph(elements, comps)
    if GROUND not in g:
        first = elements[0] if elements else None
        raise TopologyError(f"no element connects to '{GROUND}': the circuit has no pressure reference",
                            file=(first.file if first else None) or file, element=first.id if first else None,
                            node=first.nodes[0] if first and first.nodes else None)
    for comp_nodes in nx.connected_components(g):
        if GROUND not in comp_nodes:
            node = sorted(comp_nodes)[0]
            eid = _element_at(g, node)
            raise TopologyError(f"this sub-network {sorted(comp_nodes)} has no path to '{GROUND}' "
                                "(no pressure reference)", file=_file_of(elements, eid) or file, element=eid, node=node)
    # a loop of pressure-defining elements over-determines pressures (singular MNA); with
    # inductors in it (a short at DC, as SPICE counts them) there is no steady state
    pg = nx.Graph()
    shorts = set()
    for a, b, d in sorted(g.edges(data=True), key=lambda e: bool(e[2].get("short"))):
        if d["role"] == "pressure" or d.get("short"):
            if d.get("short"):
                shorts.add(d["element"])
            if pg.has_edge(a, b) or (a in pg and b in pg and nx.has_path(pg, a, b)):
                path = nx.shortest_path(pg, a, b) if (a in pg and b in pg and nx.has_path(pg, a, b)) else [a, b]
                loop = [pg.edges[u, v]["element"] for u, v in zip(path, path[1:])] + [d["element"]]
                if any(e in shorts for e in loop):
                    msg = (f"a loop of pressure-defining elements and inductors {loop}: an inductor is a short "
                           "circuit at steady state, so the loop's pressures over-determine each other and "
                           "there is no operating point")
                else:
                    msg = (f"a loop made only of pressure-defining elements {loop}: their pressures "
                           "over-determine each other")
                raise TopologyError(msg, file=_file_of(elements, d["element"]) or file, element=d["element"], node=a)
            pg.add_edge(a, b, element=d["element"])
    # nodes reached only through flow-defining elements have no defined pressure
    ng = nx.Graph()
    ng.add_nodes_from(g.nodes)
    ng.add_edges_from((a, b) for a, b, d in g.edges(data=True) if d["role"] != "flow")
    for comp_nodes in nx.connected_components(ng):
        if GROUND not in comp_nodes:
            node = sorted(comp_nodes)[0]
            eid = _element_at(g, node)
            raise TopologyError(f"node(s) {sorted(comp_nodes)} are reached only through flow-defining elements "
                                "(inductors, flow sources): their pressure is undefined",
                                file=_file_of(elements, eid) or file, element=eid, node=node)
    return conservation_laws(elements, comps)


def conservation_laws(elements, comps):
    """Groups of nodes connected to the rest only through volume stores."""
    g = nx.Graph()
    store_edges = []
    for elem, comp in zip(elements, comps):
        m = local_node_map(elem, comp)
        g.add_nodes_from(m.values())
        stored = {(s.plus, s.minus) for s in comp.storages()}
        for a, b, role in comp.edges():
            if (a, b) not in stored and (b, a) not in stored:
                g.add_edge(m[a], m[b])
        for i, s in enumerate(comp.storages()):
            store_edges.append((elem.id, i, m[s.plus], m[s.minus]))
            # a store's own internal node is joined to its element (arteriole midpoint)
    laws = []
    for group in nx.connected_components(g):
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


def _element_at(g, node):
    for _, _, d in g.edges(node, data=True):
        return d["element"]
    return None


def _file_of(elements, eid):
    for e in elements:
        if e.id == eid:
            return e.file
    return None
