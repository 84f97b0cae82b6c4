"""The framework's own exceptions.

Every error a user can cause (netlist, units, topology, solver) is a HemocircuitError
whose message names the netlist file, the element id and the node where that applies.
The CLI prints the message and exits non-zero; it never shows a traceback for these.
"""
from __future__ import annotations


class HemocircuitError(Exception):
    """Base class of every error the framework raises on purpose."""


class NetlistError(HemocircuitError):
    """A netlist (or protocol, or --set value) is malformed or unphysical."""

    def __init__(self, message: str, file=None, element=None, node=None):
        self.file, self.element, self.node = file, element, node
        where = []
        if file:
            where.append(f"{file}")
        if element:
            where.append(f"element '{element}'")
        if node:
            where.append(f"node '{node}'")
        super().__init__((": ".join([", ".join(where), message])) if where else message)
        self.bare_message = message


class TopologyError(NetlistError):
    """The circuit graph has no consistent solution (floating node, source loop, ...)."""


class SolverError(HemocircuitError):
    """A numerical solve failed.  Keeps what had been computed.

    Attributes: ``time`` (s, or None for static solves), ``state`` (dict name -> value),
    ``partial`` (the result object up to the failure, or None), ``where`` (text).
    """

    def __init__(self, message: str, time=None, state=None, partial=None, where=None):
        self.time, self.state, self.partial, self.where = time, state, partial, where
        parts = [message]
        if where:
            parts.append(f"while {where}")
        if time is not None:
            parts.append(f"at t = {time:.6g} s")
        if state:
            shown = ", ".join(f"{k}={v:.6g}" for k, v in list(state.items())[:12])
            parts.append(f"state: {shown}")
        super().__init__("; ".join(parts))


class FitSpecError(NetlistError):
    """A fit specification (hemocircuit fit) or one of its data files is malformed.  The message
    names the spec file and the key (``datasets[1].sigma``), or the data file and its column."""

    def __init__(self, message: str, file=None, key=None):
        self.key = key
        super().__init__(f"{key}: {message}" if key else message, file=file)
