"""Protocol files: timed parameter changes for transients (YAML).

    description: Kuo91 fig. 2A
    t_end: 450 s
    initial: {art.ca_order: 2, Pup.value: 60 cmH2O}     # before the starting operating point
    events:
      - {at: 51 s, set: {Pup.value: 80 cmH2O, Pdown.value: 80 cmH2O}}
      - {at: 239 s, set: {art.tau_Ca: 1 s}}

Paths are ID.PARAM (the same namespace as --set and sweeps).  Structural options (such as
``art.ca_order``) may only be set in ``initial``: they change the state vector.  Events at
``at: 0 s`` (or earlier than the start) apply before the start, after ``initial``: the
starting operating point is computed with them.  Table files named in a protocol are read
relative to the protocol's folder, inside the allowed folders (hemocircuit.access).
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

from .access import Access
from .build import path_problem
from .errors import NetlistError, excerpt
from .units import UnitError, parse_quantity
from .names import split_path


@dataclass
class Event:
    at: float
    set: dict

    def apply(self, circuit):
        """The circuit with this event's values (a new circuit; ``circuit`` is unchanged)."""
        return circuit.with_values(self.set)


@dataclass
class Protocol:
    t_end: float | None
    initial: dict = field(default_factory=dict)
    events: list = field(default_factory=list)
    description: str = ""
    file: str | None = None
    #: the files it was read from (hemocircuit.inputs.Sources: the protocol, the tables it names)
    sources: object = None

    @classmethod
    def load(cls, path, circuit=None):
        from .inputs import read_bytes, recording
        from .netlist import read_yaml_file

        with recording() as sources:
            data = read_yaml_file(str(path), "protocol")
            proto = cls.from_dict(data, str(path), circuit)
            for table in _table_files([proto.initial] + [ev.set for ev in proto.events]):
                read_bytes(table, "table file", where={"file": str(path)})  # the events read them later
        proto.sources = sources
        return proto

    @classmethod
    def from_dict(cls, data, path=None, circuit=None):
        where = {"file": path}
        if not isinstance(data, dict):
            raise NetlistError("a protocol is a mapping with 'events' (and optional t_end, initial)", **where)
        unknown = set(data) - {"description", "t_end", "initial", "events"}
        if unknown:
            raise NetlistError(f"unknown protocol key(s) {sorted(unknown)}", **where)
        try:
            t_end = parse_quantity(data["t_end"], "s", "t_end") if "t_end" in data else None
        except UnitError as exc:
            raise NetlistError(str(exc), **where) from None
        initial = data.get("initial") or {}
        if not isinstance(initial, dict):
            raise NetlistError("'initial' must be a mapping ID.PARAM: value", **where)
        events = []
        if not isinstance(data.get("events") or [], list):
            raise NetlistError("'events' must be a list of {at: <time>, set: {ID.PARAM: value}}", **where)
        if t_end is not None and not (np.isfinite(t_end) and t_end > 0):
            raise NetlistError(f"t_end = {t_end:g} s: must be finite and > 0", **where)
        for i, ev in enumerate(data.get("events") or []):
            if not isinstance(ev, dict) or "at" not in ev or not isinstance(ev.get("set"), dict):
                raise NetlistError(f"event {i} must be {{at: <time>, set: {{ID.PARAM: value}}}}", **where)
            unknown = set(map(str, ev)) - {"at", "set"}
            if unknown:
                raise NetlistError(f"event {i}: unknown key(s) {excerpt(sorted(unknown))} (an event has 'at' and "
                                   "'set')", **where)
            try:
                at = parse_quantity(ev["at"], "s", f"event {i} time")
            except UnitError as exc:
                raise NetlistError(str(exc), **where) from None
            if not (np.isfinite(at) and at >= 0):
                raise NetlistError(f"event {i} time = {at:g} s: must be finite and >= 0", **where)
            events.append(Event(at, dict(ev["set"])))
        if circuit is not None or path is not None:
            # table files: relative to the protocol's folder, inside the allowed folders
            folders = list(getattr(getattr(circuit, "netlist", None), "allowed", None) or [])
            base = os.path.dirname(os.path.abspath(path)) if path else os.getcwd()
            access = Access(folders + [base])
            from .netlist import resolve_files
            initial = resolve_files(dict(initial), base, access, where)
            for ev in events:
                ev.set = resolve_files(ev.set, base, access, where)
        proto = cls(t_end, dict(initial), sorted(events, key=lambda e: e.at), str(data.get("description", "")), path)
        if circuit is not None:
            proto.check(circuit)
        return proto

    def check(self, circuit):
        """Validate every path and value against the circuit (before any simulation)."""
        for what, mapping in [("initial", self.initial)] + [(f"event at {ev.at:g} s", ev.set) for ev in self.events]:
            _reject_bare_numbers(circuit, mapping, what, self.file)
        for what, mapping in [("initial", self.initial)] + [(f"event at {ev.at:g} s", ev.set) for ev in self.events]:
            for path in mapping:
                problem = path_problem(circuit, path)
                if problem:
                    raise NetlistError(f"{what}: {problem}", file=self.file,
                                       element=split_path(path)[0] if isinstance(path, str) else None)
        for ev in self.events:
            for path in ev.set:
                eid, name = split_path(path)
                if eid in circuit.elements and name in circuit.elements[eid].cls.options:
                    raise NetlistError(f"event at {ev.at:g} s sets the structural option '{path}'; options may only "
                                       "be set in 'initial'", file=self.file, element=eid)
        c = self.apply_initial(circuit, t0=-np.inf)
        for ev in self.events:
            for path in ev.set:
                eid, name = split_path(path)
                if eid in c.elements and name in c.elements[eid].cls.options:
                    raise NetlistError(f"event at {ev.at:g} s sets the structural option '{path}'; options may only "
                                       "be set in 'initial'", file=self.file, element=eid)
            try:
                c = ev.apply(c)
            except NetlistError as exc:
                raise NetlistError(f"event at {ev.at:g} s: {exc.bare_message}", file=self.file,
                                   element=exc.element) from None
        return True

    def apply_initial(self, circuit, t0=0.0):
        """A copy of ``circuit`` with the ``initial`` settings, then the events at or before
        ``t0`` (the start: they hold from the start, so the starting operating point uses them)."""
        opts = {k: v for k, v in self.initial.items() if circuit.is_option(k)}
        c = circuit.with_options(opts) if opts else circuit
        try:
            c = c.with_values({k: v for k, v in self.initial.items() if k not in opts})
        except NetlistError as exc:
            raise NetlistError(f"initial: {exc.bare_message}", file=self.file, element=exc.element) from None
        for ev in self.events_before(t0):
            try:
                c = ev.apply(c)
            except NetlistError as exc:
                raise NetlistError(f"event at {ev.at:g} s: {exc.bare_message}", file=self.file,
                                   element=exc.element) from None
        return c

    def events_before(self, t0=0.0):
        """The events at or before ``t0`` (applied before the start)."""
        return [ev for ev in self.events if ev.at <= t0]


def _reject_bare_numbers(circuit, mapping, what, file):
    """A protocol file writes every dimensional value with its unit (like a netlist)."""
    for path, value in mapping.items():
        if not isinstance(path, str):
            raise NetlistError(f"{what}: {path!r} is not an ID.PARAM path", file=file)
        if circuit.is_option(path):
            continue
        if not isinstance(value, (str, int, float, dict)) or isinstance(value, bool):
            raise NetlistError(f"{what}: {path} = {value!r} is not a quantity with a unit (or a waveform)",
                               file=file, element=split_path(path)[0])
        if not isinstance(value, (int, float)):
            continue
        try:
            unit = circuit.param_unit(path)
        except NetlistError:
            continue  # reported with the event by the full check below
        try:
            parse_quantity(value, unit, path)
        except UnitError as exc:
            raise NetlistError(f"{what}: {exc}", file=file, element=split_path(path)[0]) from None


def _table_files(value):
    """The table files ({file: PATH}, already resolved) named anywhere in ``value``."""
    if isinstance(value, dict):
        if isinstance(value.get("file"), str):
            return [value["file"]]
        return [f for v in value.values() for f in _table_files(v)]
    if isinstance(value, list):
        return [f for v in value for f in _table_files(v)]
    return []
