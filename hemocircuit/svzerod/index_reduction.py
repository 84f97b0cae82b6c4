"""The importer's index reduction (:func:`reduce_ideal_sources`): vessel capacitors across an
ideal pressure source and vessel inductors in series with an ideal flow source, whose state the
source fixes, written as sources of the known function of time instead."""
from __future__ import annotations

from .model import ONE_ELEMENT_VESSELS


def reduce_ideal_sources(imp):
    """Vessel capacitors across an ideal pressure source, vessel inductors in series with an
    ideal flow source, in the elements of ``imp`` (the importer's state, after every block).

    Their solver integrates the DAE with a mass matrix, so such a capacitor (pulsatileFlow_CRL:
    a PRESSURE inlet on a BloodVesselCRL) or inductor (steadyFlow_RL_R: a FLOW inlet on an RL
    vessel), whose state the source fixes (a higher-index DAE), is no special case for it.
    Our states must be free (the topology
    pass rejects a loop of pressure-defining elements and a node reached only through
    flow-defining ones), so the importer does the index reduction where it can do it
    exactly: the constrained state is a known function of time.
      - capacitor C from node n to ground, P(n) = P(t) imposed: V = C P(t) is not a state;
        the vessel loses its capacitor and a flow source C dP/dt from n to ground (the slopes
        of their linear interpolation, a periodic steps waveform) carries its flow;
      - inductor L whose end node is joined only to it and flow sources Q(t): its flow is
        not a state; the vessel loses its inductor and a pressure source L dQ/dt in series
        (between a new node ``ID_L`` and the end node) keeps its pressure drop.
    Detection is generic, from the components' own edges (the capacitor's store edge on a
    pinned node; a node whose every edge is flow-defining); only the reduction knows the
    vessel's structure.  Their outputs that include the removed flow become derived
    quantities (``derived:`` in the netlist; ``imp.q_in``/``imp.q_out`` name them)."""
    from hemocircuit.registry import get_type

    comps = [get_type(e["type"])({k: e[k] for k in get_type(e["type"]).options if k in e})
             for e in imp.elements]
    roles = {}  # node -> [(element index, role)]
    for i, (e, c) in enumerate(zip(imp.elements, comps)):
        m = dict(zip(c.terminals, e["nodes"]))
        for a, b, role in c.edges():
            for t in (a, b):
                if t in m:
                    roles.setdefault(m[t], []).append((i, role))
    Q, P = imp.u["Q"], imp.u["P"]
    for i, (e, c) in enumerate(list(zip(imp.elements, comps))):
        if imp.element_block[e["id"]] not in ("BloodVessel", "BloodVesselCRL", *ONE_ELEMENT_VESSELS):
            continue
        m = dict(zip(c.terminals, e["nodes"]))
        eid, block = e["id"], imp.block_of(e["id"])
        stores = c.storages()
        if stores and m.get(stores[0].plus) in imp.pinned_p and m.get(stores[0].minus) == "ground":
            node = m[stores[0].plus]
            bc, key = imp.pinned_p[node]
            Cv = float(e["C"].split()[0])
            e["capacitive"] = False
            imp.drop_initial(eid, "V")
            cid = imp.id_of(f"{block}_C")
            imp.add(cid, "FLOW", [node, "ground"], value=imp.slope(bc, key, Cv, Q))
            if stores[0].plus == "in":  # their flow_in includes the capacitor's flow
                imp.derived[f"{eid}_Q_in"] = {"expr": f"{eid}.Q_in + Q({cid})", "unit": "mL/s"}
                imp.q_in[block] = f"{eid}_Q_in"
            else:
                imp.derived[f"{eid}_Q_out"] = {"expr": f"{eid}.Q_out - Q({cid})", "unit": "mL/s"}
                imp.q_out[block] = f"{eid}_Q_out"
            continue
        if not e.get("inductive"):
            continue
        for end in ("out", "in"):
            node = m[end]
            others = [j for j, _ in roles.get(node, []) if j != i]
            if node in imp.pinned_q and all(r == "flow" for _, r in roles[node]) and all(
                    imp.element_block[imp.elements[j]["id"]] == "FLOW" for j in others):
                bc, key = imp.pinned_q[node]
                Lv = float(e["L"].split()[0])
                e["inductive"] = False
                imp.drop_initial(eid, "Q_out")
                mid = f"{eid}_L"
                e["nodes"] = [mid, e["nodes"][1], e["nodes"][2]] if end == "in" else [e["nodes"][0], mid, e["nodes"][2]]
                pid = imp.id_of(f"{block}_L")
                # P(mid) - P(node) = L dQ/dt at the outlet; P(node) - P(mid) at the inlet
                sign = 1.0 if end == "out" else -1.0
                imp.add(pid, "PRESSURE", [mid, node], value=imp.slope(bc, key, sign * Lv, P))
                break
