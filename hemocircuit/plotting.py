"""Default plots: series (dc, tran, periodic, op --grid and any result with an independent
variable) and the circuit drawing.  The analyses' own plots (Bode, eigenvalues, envelopes)
are in their modules and share the helpers here.

Series plot rules (docs/analyses.md, "Plots"):

* the columns drawn are the netlist's outputs of interest -- its ``outputs:``, else the
  components' ``outputs_of_interest`` -- plus its ``derived:`` quantities (evaluated from the
  columns), recorded in ``result.metadata['interest']`` when the analysis ran, so that a
  reloaded file re-plots the same way; ``select`` (``--show``) overrides;
* one panel per unit (at most :data:`MAX_PANELS`), the y axis reading "quantity [unit]";
* a log axis where the data span more than two decades (all positive);
* one line per column and grid member; lines that coincide stay visible (dashed over solid).
"""
from __future__ import annotations

import numpy as np

MAX_PANELS = 5
MAX_LINES = 12
_KIND = {"P": "pressure", "Q": "flow", "V": "volume"}
_UNIT_QUANTITY = {"mmHg": "pressure", "Pa": "stress", "mL/s": "flow", "mL": "volume", "s": "time", "Hz": "frequency",
                  "deg": "phase", "um": "radius", "M": "concentration", "N": "force", "1": "ratio",
                  "mL/mmHg": "compliance", "mmHg*s/mL": "resistance"}
_STYLES = ["-", "--", ":", "-."]


def quantity(names, unit):
    """A y-axis quantity for columns ``names`` sharing ``unit``: the column's name if one,
    'pressure'/'flow'/'volume' for P()/Q()/V() columns, else a name for the unit."""
    if len(names) == 1:
        return names[0]
    kinds = {n[0] for n in names if len(n) > 2 and n[1] == "(" and n[0] in _KIND}
    if len(kinds) == 1 and all(n[1:2] == "(" for n in names):
        return _KIND[kinds.pop()]
    return _UNIT_QUANTITY.get(unit, ", ".join(names[:3]) + ("..." if len(names) > 3 else ""))


def axis_label(name_or_quantity, unit):
    return f"{name_or_quantity} [{unit}]" if unit else name_or_quantity


def spans_decades(values, decades=2.0):
    """True when every finite value is positive and max/min exceeds 10**decades."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    return v.size > 1 and np.all(v > 0) and v.max() / v.min() > 10 ** decades


def default_columns(res):
    """{name: (values, unit)} the default series plot draws (see the module docstring)."""
    from .derived import evaluate_derived

    numeric = {k: v for k, v in res.columns.items() if v.dtype.kind in "iuf" and k not in res.index}
    interest = res.metadata.get("interest") or {}
    out = {}
    for n in interest.get("outputs", []):
        if n in numeric:
            out[n] = (numeric[n], res.units.get(n, ""))
    derived = {k: v for k, v in (interest.get("derived") or {}).items() if k not in out}
    if derived:
        if all(k in numeric for k in derived):  # already columns (compare)
            out.update({k: (numeric[k], res.units.get(k, d.get("unit", ""))) for k, d in derived.items()})
        else:
            try:
                vals = evaluate_derived(derived, numeric)
                out.update({k: (np.broadcast_to(np.asarray(v, dtype=float), (res.n_rows,)),
                                str(derived[k].get("unit", "")) or "1") for k, v in vals.items()})
            except Exception:  # noqa: BLE001 - a derived name the result lacks: plot the others
                pass
    if not out:  # nothing declared: pressures and flows, then whatever else fits
        for prefix in ("P(", "Q(", "V("):
            out.update({k: (v, res.units.get(k, "")) for k, v in numeric.items() if k.startswith(prefix)})
        if not out:
            out = {k: (v, res.units.get(k, "")) for k, v in list(numeric.items())[:MAX_LINES]}
    return out


def _dedupe(columns):
    """Drop columns identical to an earlier one (e.g. the same flow through elements in
    series), naming them in the kept column's legend entry: 'Q(Rla) = Q(Rsv)'."""
    kept, names = {}, {}
    for n, (v, u) in columns.items():
        twin = next((k for k, (w, wu) in kept.items() if wu == u and w.shape == v.shape and
                     np.allclose(w, v, rtol=1e-9, atol=0, equal_nan=True)), None)
        if twin is None:
            kept[n] = (v, u)
            names[n] = [n]
        else:
            names[twin].append(n)
    return kept, {k: " = ".join(v) for k, v in names.items()}


def plot_series(res, path, select=None, title=None):
    """The default plot of a result with an independent variable (the last index column):
    one panel per unit, a line per column and grid member (module docstring)."""
    from .errors import HemocircuitError
    from .labels import members
    from .io import pyplot, save_figure

    if not res.index:
        raise HemocircuitError(f"a {res.analysis or 'point'} result has no independent variable to plot against")
    x_name = res.index[-1]
    if select:
        res.check_columns(select)
        columns = {k: (np.asarray(res[k], dtype=float), res.units.get(k, "")) for k in select
                   if res[k].dtype.kind in "iuf"}
    else:
        columns = default_columns(res)
    columns, legend = _dedupe(columns)
    by_unit = {}
    for n, (v, u) in columns.items():
        by_unit.setdefault(u, []).append(n)
    omitted = list(by_unit)[MAX_PANELS:]
    by_unit = dict(list(by_unit.items())[:MAX_PANELS])
    groups = members(res, [i for i in res.index if i != x_name])
    x_all = np.asarray(res[x_name], dtype=float)
    k = max(len(by_unit), 1)
    plt = pyplot()
    fig, axes = plt.subplots(k, 1, figsize=(8, min(2.6 * k + 1.0, 12)), sharex=True, squeeze=False)
    for ax, (u, names) in zip(axes[:, 0], by_unit.items()):
        n_lines = 0
        for j, n in enumerate(names[:MAX_LINES]):
            v = columns[n][0]
            for g, (glab, mask) in enumerate(groups):
                x, y = x_all[mask], np.asarray(v)[mask]
                order = np.argsort(x, kind="stable") if res.analysis != "tran" else slice(None)
                # a colour per column; with members, a dash pattern per member (and thinner
                # lines for later members), so members that coincide stay visible
                style = _STYLES[(j if len(groups) == 1 else g) % len(_STYLES)]
                color = f"C{(j if len(groups) == 1 or len(names) > 1 else g) % 10}"
                lab = legend[n] + (f" ({glab})" if glab else "")
                ax.plot(x[order], y[order], style, color=color, lw=max(2.2 - 0.4 * g, 1.0), label=lab)
                n_lines += 1
        ax.set_ylabel(axis_label(quantity(names, u), u))
        if spans_decades(np.concatenate([np.asarray(columns[n][0], dtype=float) for n in names])):
            ax.set_yscale("log")
        ax.grid(alpha=0.3, which="both")
        if len(groups) > 1 and len(names) > 1:  # compact: a colour per column, a dash per member
            from matplotlib.lines import Line2D
            handles = [Line2D([], [], color=f"C{j % 10}", lw=2, label=legend[n]) for j, n in enumerate(names[:MAX_LINES])]
            handles += [Line2D([], [], color="0.3", ls=_STYLES[g % len(_STYLES)], lw=max(2.2 - 0.4 * g, 1.0),
                               label=glab) for g, (glab, _) in enumerate(groups)]
            ax.legend(handles=handles, fontsize=8, loc="best", ncol=2, framealpha=0.8)
        else:
            ax.legend(fontsize=8, loc="best", ncol=1 if n_lines <= 4 else 2, framealpha=0.8)
        if len(names) > MAX_LINES:
            ax.text(0.01, 0.02, f"(first {MAX_LINES} of {len(names)} columns)", transform=ax.transAxes, fontsize=7)
    ax0 = axes[-1, 0]
    ax0.set_xlabel(res.label(x_name))
    if spans_decades(x_all, 1.5) and x_name in ("frequency",):
        ax0.set_xscale("log")
    head = title or res.figure_title()
    if omitted:
        head += f"\n(panels for {', '.join(omitted)} left out; choose columns with --show)"
    axes[0, 0].set_title(head, fontsize=10)
    save_figure(fig, path)
    return str(path)


def draw_circuit(circuit, path):
    """The circuit graph: nodes (ground drawn as a white-on-black 'gnd' node), elements as
    coloured edges labelled with their id and type."""
    import networkx as nx

    from .graph import local_node_map
    from .io import pyplot, save_figure
    from .netlist import GROUND

    plt = pyplot()
    colors_by_role = {"conductive": "tab:blue", "pressure": "tab:red", "flow": "tab:green"}
    g = nx.MultiGraph()
    labels = {}
    for gr in circuit.groups:
        for e in gr.elements:
            m = local_node_map(e, gr.comp)
            for a, b, role in gr.comp.edges():
                g.add_edge(m[a], m[b], key=f"{e.id}:{a}-{b}", role=role)
                labels.setdefault((m[a], m[b]), []).append(f"{e.id} ({gr.comp.type_name})")
    pos = nx.kamada_kawai_layout(nx.Graph(g)) if g.number_of_nodes() > 2 else nx.spring_layout(g, seed=1)
    fig, ax = plt.subplots(figsize=(10, 7))
    for (a, b, k, d) in g.edges(keys=True, data=True):
        nx.draw_networkx_edges(g, pos, edgelist=[(a, b)], edge_color=colors_by_role.get(d["role"], "gray"),
                               width=2.5, ax=ax)
    nodes = [n for n in g.nodes if n != GROUND]
    nx.draw_networkx_nodes(g, pos, nodelist=nodes, node_color="white", edgecolors="black", node_size=900, ax=ax)
    if GROUND in g.nodes:
        nx.draw_networkx_nodes(g, pos, nodelist=[GROUND], node_color="black", node_size=900, node_shape="s", ax=ax)
        nx.draw_networkx_labels(g, pos, labels={GROUND: "ground"}, font_size=8, font_color="white",
                                font_weight="bold", ax=ax)
    nx.draw_networkx_labels(g, pos, labels={n: n for n in nodes}, font_size=9, font_color="black", ax=ax)
    nx.draw_networkx_edge_labels(nx.Graph(g), pos, edge_labels={k: "\n".join(v) for k, v in labels.items()},
                                 font_size=8, ax=ax, bbox=dict(boxstyle="round,pad=0.2", fc="white", ec="none",
                                                               alpha=0.85))
    from matplotlib.lines import Line2D
    handles = [Line2D([], [], color=c, lw=2.5, label=t) for t, c in
               (("resistive (conductive)", "tab:blue"), ("pressure-defining", "tab:red"),
                ("flow-defining", "tab:green"))]
    ax.legend(handles=handles, loc="lower right", fontsize=8, framealpha=0.9)
    ax.set_title(f"circuit {circuit.netlist.name}: {len(nodes)} nodes + ground, "
                 f"{sum(len(gr.elements) for gr in circuit.groups)} elements", fontsize=10)
    ax.margins(0.12)
    ax.axis("off")
    save_figure(fig, path)
    return str(path)
