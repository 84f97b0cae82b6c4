"""What every command does around its computation, shared by the command line
(:mod:`hemocircuit.cli`) and the analyses' own commands (``register_cli`` in
``hemocircuit/analyses``): the circuit from the parsed arguments, ``--grid``, and the
outputs (``--measure``, ``--out``, ``--plot``, provenance).

``args`` is the ``argparse.Namespace`` of a command built with the CLI's ``common`` options
(netlist, ``--set``, ``--protocol``, ``--allow-path``, ``--svzerod-units``, and, where the
command has them, ``--grid``, ``--workers``, ``--measure``, ``--out``, ``--plot``, ``--show``).
"""
from __future__ import annotations

import sys

from .arguments import parse_sets
from .errors import HemocircuitError
from .loading import load_circuit


def circuit_of_args(args, sets, netlist=None):
    """load_circuit() of ``netlist`` (default the command's) with the loader options of the
    parsed arguments (--protocol, --allow-path, --svzerod-units) and ``sets``: the one way
    every command and every --grid member gets its circuit.  Returns (circuit, protocol)."""
    return load_circuit(netlist if netlist is not None else args.netlist, sets, getattr(args, "protocol", None),
                        getattr(args, "allow_path", None), getattr(args, "svzerod_units", None))


def load_args(args, uses_events=False):
    """load_circuit() from the parsed arguments (netlist, --set, --protocol, --allow-path,
    --svzerod-units) of any command; ``--show`` names are checked against the circuit's columns.
    ``uses_events``: the command runs the protocol's later events (else a note says it does not)."""
    c, proto = circuit_of_args(args, parse_sets(getattr(args, "set", None)))
    later = [ev for ev in proto.events if ev.at > 0] if proto is not None else []
    if later and not uses_events:
        print(f"note: {args.command} applies the protocol's 'initial' settings and its events at t = 0; its "
              f"{len(later)} later event(s) are used by tran only", file=sys.stderr)
    check_show(c, getattr(args, "show", None))
    return c, proto


def check_show(c, show):
    """Every ``--show`` name must be a column of the circuit (with close matches if not)."""
    from .errors import did_you_mean

    if not show:
        return
    columns = [col.name for col in c.columns()]
    known = set(columns)
    for name in show:
        if name not in known:
            derived = " (a derived quantity: compare shows those)" if name in (c.netlist.derived or {}) else ""
            raise HemocircuitError(f"--show {name!r}: no such column{derived}{did_you_mean(name, columns)}; "
                                   f"columns: {columns[:40]}{' ...' if len(columns) > 40 else ''}")


def record(args, res):
    """Add this invocation's provenance (command line, --set, --protocol) to a result."""
    from .provenance import add_invocation
    netlists = getattr(args, "netlists", None) or [getattr(args, "netlist", None)]
    add_invocation(res.metadata, getattr(args, "argv", sys.argv[1:]), parse_sets(getattr(args, "set", None)),
                   getattr(args, "protocol", None), netlists=[n for n in netlists if n])
    args.computed_result = res  # main() reports its warnings and failed members (exit status)
    return res


def save_outputs(args, res, plot=None):
    """Compute and print ``--measure`` (saved in ``metadata['measures']``), then write ``--out``
    (the result, with provenance) and ``--plot`` (``plot(path)``, default ``res.plot``); both
    files were checked before the computation (the CLI's output check)."""
    record(args, res)  # first: its warnings are reported even if a measure fails
    apply_measures(args, res)
    if getattr(args, "out", None):
        print(f"wrote {res.save(args.out)}")
    if getattr(args, "plot", None):
        (plot or (lambda path: res.plot(path, select=getattr(args, "show", None))))(args.plot)
        print(f"wrote {args.plot}")


def apply_measures(args, res):
    """``--measure SPEC`` (repeatable): :mod:`hemocircuit.measures`, printed and stored."""
    specs = getattr(args, "measure", None)
    if not specs:
        return
    from .measures import measure_all
    for line in measure_all(res, specs):
        print(line)


def computed(args, compute):
    """The command's result: ``compute(args, sets)`` on the netlist with ``--set`` applied, or,
    with ``--grid``, every member of the grid run in parallel and stacked into one result
    (:mod:`hemocircuit.grid`)."""
    sets = parse_sets(getattr(args, "set", None))
    if not getattr(args, "grid", None):
        return compute(args, sets)
    from . import grid
    first = getattr(args, "netlist", None) or args.netlists[0]
    circuit, _ = circuit_of_args(args, sets, first)
    return grid.run(compute, args, circuit, sets, workers=getattr(args, "workers", None))


def report_grid(args, res, show=None):
    """What every command prints for a --grid result: the table (grid columns first), the
    failed members, then --measure, --out and --plot."""
    if show:
        show = [k for k in show if k in res.data]
    print(res.summary(show=getattr(args, "show", None) or show or None, max_rows=24, where=getattr(args, "out", None)))
    for where, why in res.metadata.get("failed", []):
        print(f"failed: {where}: {why}", file=sys.stderr)
    save_outputs(args, res)
