"""Drawing the circuit graph (nodes and labelled elements) to PNG."""
from __future__ import annotations

import networkx as nx

from .graph import local_node_map
from .netlist import GROUND
from .io import pyplot, save_figure

_COLORS = {"conductive": "tab:blue", "pressure": "tab:red", "flow": "tab:green"}


def draw_circuit(circuit, path):
    plt = pyplot()

    g = nx.MultiGraph()
    labels = {}
    for gr in circuit.groups:
        for e in gr.elements:
            m = local_node_map(e, gr.comp)
            for a, b, role in gr.comp.edges():
                g.add_edge(m[a], m[b], key=f"{e.id}:{a}-{b}", role=role)
                labels.setdefault((m[a], m[b]), []).append(f"{e.id} ({gr.comp.type_name})")
    pos = nx.kamada_kawai_layout(nx.Graph(g)) if g.number_of_nodes() > 2 else nx.spring_layout(g, seed=1)
    fig, ax = plt.subplots(figsize=(9, 6))
    colors = ["black" if n == GROUND else "lightgray" for n in g.nodes]
    nx.draw_networkx_nodes(g, pos, node_color=colors, node_size=500, ax=ax)
    nx.draw_networkx_labels(g, pos, font_size=8, ax=ax,
                            labels={n: n for n in g.nodes}, font_color="tab:purple")
    for (a, b, k, d) in g.edges(keys=True, data=True):
        nx.draw_networkx_edges(g, pos, edgelist=[(a, b)], edge_color=_COLORS.get(d["role"], "gray"), width=2, ax=ax)
    nx.draw_networkx_edge_labels(nx.Graph(g), pos, edge_labels={k: "\n".join(v) for k, v in labels.items()},
                                 font_size=7, ax=ax)
    ax.set_title(f"{circuit.netlist.name}  (blue: resistive, red: pressure-defining, green: flow-defining)",
                 fontsize=9)
    ax.axis("off")
    save_figure(fig, path)
