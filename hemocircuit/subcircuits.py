"""Subcircuits: a netlist instantiates another netlist as a named block (SPICE's ``.subckt``).

    instances:
      - id: brain
        netlist: payne06.yaml           # relative to this netlist's folder (same folder policy as extends)
        ports: {in: carotid, out: jugular}   # the child's node -> this netlist's node
        remove: [Pa, Pv]                # the child's own drivers, replaced by this circuit
        change: {art: {tau_Ca: 10 s}}   # as in extends
        parameters: {R_la: 0.5 mmHg*s/mL}    # the child's ${} parameters, overridden
        constraints: [{node: ic, volume: 120 mL}]   # replace the child's (its node names)

Every element of the child becomes ``brain.ID`` (parameters ``brain.art.tau_Ca`` in the one
namespace of ``--set``, ``--grid``, fit and sensitivity); its nodes become ``brain.NODE``
except the ports, which are this netlist's nodes, and ground, which stays ground.  The child's
expressions read the instance's own elements (``= art.r`` becomes ``= brain.art.r``) and
parameters (``rho_b`` becomes ``brain__rho_b``, carried by this netlist); its
constraints (nodes renamed; a calibration's ``when: {Pa.value: 80 mmHg}`` becomes
``brain.Pa.value``, and must name an element the instance keeps, else give the instance its own
``constraints``) and ``ic`` (``brain.ID.STATE``) come along; its ``outputs``,
``input`` and ``derived`` stay the child's own.  A child may declare ``ports: [in, out]``;
then exactly those are its ports.  Instances nest; an instance chain that comes back to a
file is an error naming the chain.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field

from .errors import NetlistError, did_you_mean, excerpt
from .expressions import instance_references, is_expression

INSTANCE_KEYS = {"id", "netlist", "ports", "remove", "change", "parameters", "constraints"}
_ID = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


@dataclass
class Expanded:
    elements: list = field(default_factory=list)
    constraints: list = field(default_factory=list)
    ic: dict = field(default_factory=dict)
    #: the children's netlist parameters their expressions read, as ``INSTANCE__NAME``
    parameters: dict = field(default_factory=dict)


def expand(items, path, load_child, ground="ground") -> Expanded:
    """The elements, constraints and ``ic`` of the ``instances`` of the netlist at ``path``.

    ``load_child(netlist_name, overrides, where)`` returns the child as a mapping with
    ``elements`` (ElementSpec, ``${}`` already substituted), ``constraints``, ``ic``, ``ports``
    (its declared ports or None), ``file``, and ``edit(elements, remove, change)`` applying
    extends-style edits; it raises for missing files and instance cycles."""
    if not isinstance(items, list):
        raise NetlistError("'instances' must be a list of {id, netlist, ports} mappings", file=path)
    out, seen = Expanded(), set()
    for i, item in enumerate(items):
        where = {"file": path}
        if not isinstance(item, dict):
            raise NetlistError(f"instances[{i}] is not a mapping: {excerpt(item)}", **where)
        iid = item.get("id")
        if not isinstance(iid, str) or not _ID.match(iid):
            raise NetlistError(f"instances[{i}] needs an 'id' (letters, digits, _; not starting with a digit), got "
                               f"{excerpt(iid, 40)}", **where)
        where = {"file": path, "element": iid}
        if iid in seen:
            raise NetlistError(f"duplicate instance id '{iid}'", **where)
        seen.add(iid)
        unknown = set(item) - INSTANCE_KEYS
        if unknown:
            first = sorted(map(str, unknown))[0]
            raise NetlistError(f"instance '{iid}': unknown key(s) {sorted(map(str, unknown))}"
                               f"{did_you_mean(first, INSTANCE_KEYS)}; an instance has {sorted(INSTANCE_KEYS)}",
                               **where)
        if not isinstance(item.get("netlist"), str):
            raise NetlistError(f"instance '{iid}' needs 'netlist: FILE.yaml'", **where)
        ports = item.get("ports") or {}
        if not isinstance(ports, dict) or not all(isinstance(v, (str, int)) and not isinstance(v, bool)
                                                  for v in ports.values()):
            raise NetlistError(f"instance '{iid}': 'ports' must map the child's nodes to this netlist's nodes, "
                               f"e.g. {{in: carotid}}; got {excerpt(ports)}", **where)
        overrides = item.get("parameters") or {}
        if not isinstance(overrides, dict):
            raise NetlistError(f"instance '{iid}': 'parameters' must be a mapping name -> value", **where)
        child = load_child(item["netlist"], overrides, where)
        # the child's own expressions read the child's elements and parameters: this instance's
        # copies of them (the instance's 'change' below is written in this netlist's names)
        ids, consts = {e.id for e in child["elements"]}, child["parameters"]
        reads = {}  # (element, parameter) -> (the child's elements its expression reads, its text)
        for e in child["elements"]:
            for key, value in list(e.values.items()):
                if is_expression(value):
                    e.values[key], used, read = instance_references(value, ids, iid, consts)
                    reads[(e.id, key)] = (read, value, e.values[key])
                    out.parameters.update({f"{iid}__{k}": consts[k] for k in used})
        elements = child["edit"](child["elements"], item.get("remove") or [], item.get("change") or {})
        kept = {e.id for e in elements}
        for e in elements:
            for key, value in e.values.items():
                read, text, renamed = reads.get((e.id, key), ((), "", None))
                gone = sorted(r for r in read if r not in kept)
                if gone and value == renamed:  # the child's expression, not replaced by 'change'
                    raise NetlistError(f"instance '{iid}': {child['file']}'s {e.id}.{key} is the expression "
                                       f"{excerpt(text, 60)}, which reads '{gone[0]}', an "
                                       f"element the instance removes; keep '{gone[0]}', or give the instance "
                                       f"change: {{{e.id}: {{{key}: VALUE}}}}", **where)
        nodes = {n for e in elements for n in e.nodes}
        declared = child["ports"]
        ports = {str(k): str(v) for k, v in ports.items()}
        for k in ports:
            if declared is not None and k not in declared:
                raise NetlistError(f"instance '{iid}': {child['file']} has no port '{k}'{did_you_mean(k, declared)}; "
                                   f"its ports: {list(declared)}", **where)
            if declared is None and k not in nodes:
                raise NetlistError(f"instance '{iid}': {child['file']} has no node '{k}'{did_you_mean(k, sorted(nodes))}"
                                   f"; its nodes: {sorted(nodes)[:30]}", **where)
            if k == ground:
                raise NetlistError(f"instance '{iid}': ground is shared by every circuit and is not a port", **where)
        if declared is not None:
            missing = [p for p in declared if p not in ports]
            if missing:
                raise NetlistError(f"instance '{iid}': port(s) {missing} of {child['file']} are not connected "
                                   "(ports: {child_node: node})", **where)

        def node(n, iid=iid, ports=ports):
            return ports[n] if n in ports else (n if n == ground else f"{iid}.{n}")

        kept_ids = [e.id for e in elements]
        for e in elements:
            e.id, e.nodes = f"{iid}.{e.id}", [node(n) for n in e.nodes]
            out.elements.append(e)
        kept = set(kept_ids)
        own = item.get("constraints")
        if own is not None and (not isinstance(own, list) or not all(isinstance(c, dict) and "node" in c for c in own)):
            raise NetlistError(f"instance '{iid}': 'constraints' must be a list of {{node: NAME, ...}} mappings "
                               "(the child's node names)", **where)
        for c in (own if own is not None else child["constraints"]):
            c = {**c, "node": node(str(c["node"]))}
            if own is None and isinstance(c.get("when"), dict):
                for key in c["when"]:
                    eid = str(key).rpartition(".")[0]
                    if eid not in kept:
                        raise NetlistError(f"instance '{iid}': the constraint on node {c['node']} of {child['file']} "
                                           f"is calibrated at {key}, but the instance has no element '{eid}'; give "
                                           "the instance its own 'constraints:' (e.g. {node: ic, volume: 120 mL})",
                                           **where)
                c["when"] = {f"{iid}.{k}": v for k, v in c["when"].items()}
            out.constraints.append(c)
        out.ic.update({f"{iid}.{k}": v for k, v in child["ic"].items()})
    return out
