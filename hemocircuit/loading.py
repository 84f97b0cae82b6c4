"""The one way every front end gets its circuit: :func:`load_circuit` (netlist, then
``--set``, then ``--protocol``).

Used by the command line (every command and every ``--grid`` member), by fitting
(:func:`hemocircuit.fitting.load_problem`) and by any program that wants a circuit exactly as
a command would build it.
"""
from __future__ import annotations

import os

from .errors import HemocircuitError
from .names import split_path


def load_circuit(netlist, sets=None, protocol=None, allow_paths=None, svzerod_units=None):
    """The one way every command gets its circuit: netlist, then ``--set``, then ``--protocol``.

    ``sets``: {ID.NAME: value} (``--set``): structural options (``art.ca_order``, values as YAML
    literals) re-assemble the circuit first, keeping every numeric value; then numeric
    parameters are set (strings with units).  ``protocol``: path of a protocol YAML (or None),
    checked against the circuit; its ``initial`` settings and its events at t = 0 are applied
    last (they win over ``--set``, as they would in ``simulate``).  ``allow_paths``: more
    folders the netlist may read files from (``--allow-path``, see hemocircuit.access).
    ``svzerod_units`` (``--svzerod-units``): the unit system of an svZeroDSolver JSON model.
    Returns (circuit, protocol or None).  The protocol's timed events are left to the commands
    that run them (tran, compare --tran), which pass it on stripped of ``initial`` (see
    :func:`events_only`).  Errors in ``--set`` name the ``--set`` option, with close matches.
    """
    from .build import path_problem
    from .circuit import load
    from .errors import NetlistError
    from .protocol import Protocol

    try:
        c = load(str(netlist), allow_paths=allow_paths, svzerod_units=svzerod_units)
    except NetlistError as exc:
        given = os.path.abspath(str(netlist))
        if exc.file and os.path.abspath(str(exc.file)) != given:  # an error in a base netlist: say which
            exc.args = (f"{exc} (in the extends chain of {given})",)
        raise
    sets = dict(sets or {})
    for k, v in sets.items():
        problem = path_problem(c, k)
        if problem:
            raise HemocircuitError(f"--set {k}={v}: {problem}")
    opts = {k: v for k, v in sets.items() if c.is_option(k)}
    params = {k: v for k, v in sets.items() if k not in opts}
    try:
        if opts:
            c = c.with_options({k: _option_literal(v) for k, v in opts.items()})
        c = c.with_values(params)
    except NetlistError as exc:
        mine = [f"{k}={v}" for k, v in sets.items() if split_path(k)[0] == exc.element] or \
            [f"{k}={v}" for k, v in sets.items()]
        raise HemocircuitError(f"--set {', --set '.join(mine)}: "
                               + (f"element '{exc.element}': " if exc.element else "") + exc.bare_message) from None
    proto = None
    if protocol:
        proto = Protocol.load(str(protocol), c)
        c = proto.apply_initial(c)
    return c, proto


def events_only(proto):
    """The protocol without its ``initial`` settings (already applied by :func:`load_circuit`)."""
    import dataclasses
    return None if proto is None else dataclasses.replace(proto, initial={})


def _option_literal(v):
    import yaml
    return yaml.safe_load(v) if isinstance(v, str) else v
