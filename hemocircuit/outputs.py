"""Outputs of interest and the default input: what an analysis uses when it is not told.

Both come from the netlist (docs/netlist.md, "Outputs of interest and the default input") or
from the components, never from names built into the analyses:

* ``outputs:`` a list of output columns or ``derived`` names for every analysis, or a mapping
  with a list per use (:data:`USES`) and a ``default`` list for the others.  Without it, the
  components' :meth:`~hemocircuit.component.Component.outputs_of_interest` (in netlist order).
* ``input:`` the default input: a source element (its drive parameter,
  :attr:`~hemocircuit.component.Component.drive`) or any ``ID.PARAM``.  Without it, the only
  element of the circuit that has a drive, if there is exactly one.

Both are checked when the circuit is assembled; an unknown name is an error that names the
netlist file and the closest known names.
"""
from __future__ import annotations

import difflib

from .errors import HemocircuitError, NetlistError
from .names import split_path

#: the uses an ``outputs:`` mapping may name, and what each one sets
USES = {
    "default": "every use without its own entry",
    "ac": "AC transfer functions (hemocircuit ac, ac_response)",
    "freq": "nonlinear frequency response (hemocircuit freq, frequency_response)",
    "envelope": "oscillation envelopes (hemocircuit envelope; the first output gives the period)",
    "periodic": "periodic orbits (hemocircuit periodic: the first output finds the period, all are plotted)",
    "phase_plane": "the two columns (x, y) of envelope --phase-plot",
}


def _close(name, known):
    near = difflib.get_close_matches(name, list(known), n=3, cutoff=0.5)
    return f"; did you mean {' or '.join(repr(n) for n in near)}?" if near else ""


def available(circuit) -> list[str]:
    """Every name an output may take: the circuit's columns, then the netlist's derived names."""
    return [c.name for c in circuit.columns()] + [n for n in (circuit.netlist.derived or {})]


def check(circuit):
    """Check the netlist's ``outputs:`` and ``input:`` against the assembled circuit."""
    nl = circuit.netlist
    if nl.derived:
        from .derived import check_derived
        check_derived(nl.derived, [c.name for c in circuit.columns()], circuit.file)
    if nl.outputs:
        known = set(available(circuit))
        inherited = nl.outputs_file and circuit.file and nl.outputs_file != circuit.file
        for use, names in nl.outputs.items():
            for name in names:
                if name not in known:
                    raise NetlistError(
                        f"outputs{'' if use == 'default' else '.' + use}: unknown column {name!r}{_close(name, known)}"
                        + (f" (the 'outputs:' inherited from {nl.outputs_file}; a variant that removes or renames "
                           "an element named there declares its own 'outputs:')" if inherited else ""),
                        file=circuit.file or nl.outputs_file)
    if nl.input is not None:
        try:
            input_path(circuit, nl.input)
        except NetlistError as exc:
            inherited = nl.input_file and circuit.file and nl.input_file != circuit.file
            raise NetlistError(f"input: {exc.bare_message}" + (f" (the 'input:' inherited from {nl.input_file})"
                                                               if inherited else ""),
                               file=circuit.file or nl.input_file, element=exc.element) from None


def default_outputs(circuit, use="default", required=True) -> list[str]:
    """The outputs of interest for ``use`` (a key of :data:`USES`): the netlist's
    ``outputs[use]``, else its ``outputs.default``, else the components' outputs of interest.
    ``required``: raise if there are none (else return [])."""
    if use not in USES:
        raise ValueError(f"unknown output use {use!r}; known: {sorted(USES)}")
    declared = circuit.netlist.outputs or {}
    if use in declared:
        return list(declared[use])
    if "default" in declared:
        return list(declared["default"])
    out = []
    for eid, e in circuit.elements.items():
        g, _ = circuit.element_group(eid)
        vols = set(g.comp.volume_observables())
        out += [f"V({eid})" if n in vols else f"{eid}.{n}" for n in g.comp.outputs_of_interest()]
    if not out and required:
        raise HemocircuitError("no outputs given and none declared: name them (--output COLUMN) or add "
                               f"'outputs: [...]' to the netlist {circuit.file or ''}".rstrip())
    return out


def drive_of(circuit, eid):
    """The component instance of element ``eid`` and its :class:`~hemocircuit.component.Drive`
    (None if the element is not a source)."""
    g, _ = circuit.element_group(eid)
    return g.comp, g.comp.drive


def driven_elements(circuit) -> list[str]:
    """Ids of the elements that have a drive (sources), in netlist order."""
    return [eid for eid in circuit.elements if drive_of(circuit, eid)[1] is not None]


def default_input(circuit) -> str:
    """The netlist's ``input:``, else the only driven element; an error if neither applies."""
    if circuit.netlist.input is not None:
        return circuit.netlist.input
    srcs = driven_elements(circuit)
    if len(srcs) == 1:
        return srcs[0]
    raise HemocircuitError(f"which input? the circuit has {'no' if not srcs else len(srcs)} sources"
                           + (f" {srcs}" if srcs else "") + ": name one (--input ID or ID.PARAM) or add "
                           f"'input: ID' to the netlist {circuit.file or ''}".rstrip())


def input_element(circuit, name) -> str:
    """The element id of an input given as ``ID`` (a source) or ``ID.PARAM`` of a source whose
    drive value PARAM is; an error naming the sources otherwise."""
    eid, param = split_path(str(name))
    if eid not in circuit.elements:
        srcs = driven_elements(circuit)
        raise NetlistError(f"no element {eid!r}{_close(eid, circuit.elements)} (sources: {srcs})", file=circuit.file)
    _, drive = drive_of(circuit, eid)
    if drive is None or (param and param != drive.value):
        raise NetlistError(f"{name!r} is not a source's drive (sources: {driven_elements(circuit)})",
                           file=circuit.file, element=eid)
    return eid


def input_path(circuit, name) -> str:
    """'ID' (a source) -> 'ID.<its drive parameter>'; 'ID.PARAM' is taken as it is (and checked)."""
    if "." in str(name):
        eid = split_path(name)[0]
        if eid not in circuit.elements:
            raise NetlistError(f"no element {eid!r}{_close(eid, circuit.elements)}", file=circuit.file)
        circuit.param_path(name)  # raises a NetlistError naming the parameters when wrong
        return name
    eid = input_element(circuit, name)
    return f"{eid}.{drive_of(circuit, eid)[1].value}"


def interest_of(circuit):
    """{'outputs': [...], 'derived': {name: {expr, unit}}}: what the default plots draw
    (stored by :func:`hemocircuit.provenance.stamp` in ``metadata['interest']``)."""
    try:
        outs = default_outputs(circuit, "default", required=False)
    except Exception:  # noqa: BLE001 - a plot preference must never fail an analysis
        outs = []
    derived = {k: {"expr": str(v.get("expr", "")), "unit": str(v.get("unit", ""))}
               for k, v in (getattr(circuit.netlist, "derived", None) or {}).items()}
    return {"outputs": list(outs), "derived": derived}
