"""Command line: ``hemocircuit check|op|dc|tran|graph|... NETLIST [options]``.

Every command gets its circuit from :func:`load_circuit` (netlist, ``--set``, ``--protocol``).

Errors the user can cause (netlist, units, topology, solver) print one clear message and
exit with status 2; they never show a traceback.
"""
from __future__ import annotations

import argparse
import sys

from . import io
from .errors import HemocircuitError


def _assignments(items, flag="--set", form="ID.PARAM=VALUE", example="Pa.value=90mmHg"):
    """['ID.NAME=VALUE', ...] -> {ID.NAME: VALUE} ('90mmHg' spaced to '90 mmHg')."""
    out = {}
    for it in items or []:
        if "=" not in it:
            raise HemocircuitError(f"{flag} {it!r}: expected {form} (e.g. {example})")
        k, v = it.split("=", 1)
        out[k.strip()] = _unit_spacing(v.strip())
    return out


def _sets(items):
    return _assignments(items, "--set", "ID.PARAM=VALUE", "Pa.value=90mmHg")


def _unit_spacing(v):
    """Accept '90mmHg' as well as '90 mmHg' (an exponent, '1e8', is part of the number)."""
    import re
    m = re.match(r"^([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)(?![eE][-+]?\d)\s*([A-Za-z].*)$", v)
    return f"{m.group(1)} {m.group(2)}" if m else v


def load_circuit(netlist, sets=None, protocol=None, allow_paths=None):
    """The one way every command gets its circuit: netlist, then ``--set``, then ``--protocol``.

    ``sets``: {ID.NAME: value} (``--set``): structural options (``art.ca_order``, values as YAML
    literals) re-assemble the circuit first, keeping every numeric value; then numeric
    parameters are set (strings with units).  ``protocol``: path of a protocol YAML (or None),
    checked against the circuit; its ``initial`` settings and its events at t = 0 are applied
    last (they win over ``--set``, as they would in ``simulate``).  ``allow_paths``: more
    folders the netlist may read files from (``--allow-path``, see hemocircuit.access).
    Returns (circuit, protocol or None).  The protocol's timed events are left to the commands
    that run them (tran, compare --tran), which pass it on stripped of ``initial`` (see
    :func:`events_only`).  Errors in ``--set`` name the ``--set`` option, with close matches.
    """
    import os

    from .build import path_problem
    from .circuit import load
    from .errors import NetlistError
    from .protocol import Protocol

    try:
        c = load(str(netlist), allow_paths=allow_paths)
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
    opts = {k: v for k, v in sets.items() if _is_option(c, k)}
    params = {k: v for k, v in sets.items() if k not in opts}
    try:
        if opts:
            c = c.with_options({k: _option_literal(v) for k, v in opts.items()})
        c.set_params(params)
    except NetlistError as exc:
        mine = [f"{k}={v}" for k, v in sets.items() if k.partition(".")[0] == exc.element] or \
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


def _is_option(c, path):
    eid, _, name = path.partition(".")
    return eid in c.elements and name in c.elements[eid].cls.options


def _load(args, uses_events=False):
    """load_circuit() from the parsed arguments (netlist, --set, --protocol, --allow-path) of any
    command; ``--show`` names are checked against the circuit's columns."""
    c, proto = load_circuit(args.netlist, _sets(getattr(args, "set", None)), getattr(args, "protocol", None),
                            getattr(args, "allow_path", None))
    later = [ev for ev in proto.events if ev.at > 0] if proto is not None else []
    if later and not uses_events:
        print(f"note: {args.command} applies the protocol's 'initial' settings and its events at t = 0; its "
              f"{len(later)} later event(s) are used by tran only", file=sys.stderr)
    _check_show(c, getattr(args, "show", None))
    return c, proto


def _check_show(c, show):
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


def _option_literal(v):
    import yaml
    return yaml.safe_load(v) if isinstance(v, str) else v


def cmd_check(args):
    c, proto = _load(args, uses_events=True)
    print(c.describe())
    print("ok: the netlist is valid" + (" and so is the protocol" if proto else ""))


def cmd_op(args):
    c, _ = _load(args)
    op = c.operating_point()
    flat = op.as_flat_dict()
    width = max(len(k) for k in flat)
    for k, v in flat.items():
        print(f"{k:<{width}}  {v:.8g}")
    if args.out:
        io.write_json(args.out, flat)
        print(f"wrote {args.out}")


def cmd_dc(args):
    c, _ = _load(args)
    if not args.sweep or "=" not in args.sweep:
        raise HemocircuitError("dc needs --sweep ID.PARAM=START:STOP:STEP UNIT (e.g. Pa.value=20:200:5mmHg)")
    param, rng = args.sweep.split("=", 1)
    res = c.dc_sweep(param.strip(), _range_spacing(rng))
    cols = {k: v for k, v in res.items() if k != param.strip()}
    show = args.show or [k for k in cols if k.startswith("Q(")][:1] + [k for k in cols if k.startswith("P(")][:3]
    print("  ".join(f"{h:>14}" for h in [io.labelled(param, res.units)] + [io.labelled(s, res.units) for s in show]))
    for i in range(len(res[param.strip()])):
        print("  ".join(f"{v:>14.6g}" for v in [res[param.strip()][i]] + [cols[s][i] for s in show]))
    for v, why in res.failed:
        print(f"failed at {param}={v:g}: {why}", file=sys.stderr)
    if args.out:
        io.write_csv(args.out, cols, res.units, first=(param.strip(), res[param.strip()], res.units[param.strip()]))
        print(f"wrote {args.out}")
    if args.plot:
        io.plot_series(args.plot, res[param.strip()], io.labelled(param.strip(), res.units), cols, res.units,
                       title=f"{c.netlist.name}: DC sweep", select=args.show)
        print(f"wrote {args.plot}")


def _range_spacing(r):
    """'20:200:5mmHg' -> '20:200:5 mmHg'; exponents ('1e8') stay part of their number."""
    import re
    return re.sub(r"(\d)(?![eE][-+]?\d)([A-Za-z])", r"\1 \2", r, count=1)


def cmd_tran(args):
    c, proto = _load(args, uses_events=True)
    t_end = float(_unit_to(args.t_end, "s")) if args.t_end else None
    dt = float(_unit_to(args.dt, "s")) if args.dt else None
    ic = _assignments(args.ic, "--ic", "ID.STATE=VALUE", "Cv.V=20mL")
    res = c.simulate(t_end, dt=dt, protocol=events_only(proto), method=args.method, ic=ic)
    print(f"{len(res.t)} points, t = {res.t[0]:g} .. {res.t[-1]:g} s; solver {res.stats}")
    last = {k: v[-1] for k, v in res.columns.items()}
    for k in (args.show or list(last)[:12]):
        print(f"  {io.labelled(k, res.units)} at end: {last[k]:.6g}")
    if args.out:
        io.write_csv(args.out, res.columns, res.units, first=("time", res.t, "s"))
        print(f"wrote {args.out}")
    if args.plot:
        io.plot_series(args.plot, res.t, "time [s]", res.columns, res.units, title=c.netlist.name, select=args.show)
        print(f"wrote {args.plot}")


def _unit_to(text, unit):
    from .units import parse_quantity
    return parse_quantity(_unit_spacing(str(text)) if not str(text).replace(".", "").isdigit() else f"{text} {unit}",
                          unit)


def cmd_graph(args):
    c, _ = _load(args)
    from .plotting import draw_circuit
    out = args.out or args.plot or "circuit.png"
    draw_circuit(c, out)
    print(f"wrote {out}")


def build_parser():
    p = argparse.ArgumentParser(prog="hemocircuit", description="Lumped-parameter hemodynamic circuits.")
    sub = p.add_subparsers(dest="command", required=True)

    def common(sp, outputs=True, netlist=True):
        """The loader's arguments (netlist, --set, --protocol: see load_circuit), shared by every
        command; with ``outputs`` also --out, --plot, --show."""
        if netlist:
            sp.add_argument("netlist", help="netlist YAML file")
        sp.add_argument("--set", action="append", metavar="ID.PARAM=VALUE",
                        help="set a parameter (units allowed, e.g. Pa.value=90mmHg) or a structural option "
                             "(e.g. art.ca_order=2); repeatable")
        sp.add_argument("--protocol", help="protocol YAML: its 'initial' settings (and events at t = 0) apply "
                                           "to every command, its later events to tran")
        sp.add_argument("--allow-path", action="append", metavar="DIR",
                        help="let the netlist read files (extends, tables) in DIR too; by default only its "
                             "project folder and the bundled netlists (repeatable)")
        if outputs:
            sp.add_argument("--out", help="output file (CSV for series/sweeps, JSON for op, PNG for graph)")
            sp.add_argument("--plot", help="PNG plot file")
            sp.add_argument("--show", action="append", help="column to print/plot (repeatable)")
        return sp

    common(sub.add_parser("check", help="validate a netlist (and protocol)")).set_defaults(func=cmd_check)
    common(sub.add_parser("op", help="operating point (steady state)")).set_defaults(func=cmd_op)
    sp = common(sub.add_parser("dc", help="DC sweep of a parameter"))
    sp.add_argument("--sweep", help="ID.PARAM=START:STOP:STEP UNIT, e.g. Pa.value=20:200:5mmHg")
    sp.set_defaults(func=cmd_dc)
    sp = common(sub.add_parser("tran", help="transient simulation"))
    sp.add_argument("--t-end", help="end time (e.g. 100 or '100 s')")
    sp.add_argument("--dt", help="output interval (e.g. 0.1 s)")
    sp.add_argument("--method", default="BDF", help="solve_ivp method (BDF, Radau, LSODA)")
    sp.add_argument("--ic", action="append", metavar="ID.STATE=VALUE",
                    help="start with this state overridden (units allowed, e.g. Cv.V=20mL, art.Ca=1e-7M); "
                         "the others at the operating point; repeatable")
    sp.set_defaults(func=cmd_tran)
    common(sub.add_parser("graph", help="draw the circuit graph to PNG")).set_defaults(func=cmd_graph)
    for register in _extra_commands():
        register(sub, common)
    return p


def _extra_commands():
    """Commands contributed by analysis modules: every module of ``hemocircuit.analyses`` that
    defines ``register_cli(subparsers, common)`` (found by scanning the package, like the
    components), then third-party ones registered under the entry-point group
    ``hemocircuit.analyses`` (the entry point names such a module or function)."""
    import importlib
    import pkgutil
    from importlib import metadata

    from . import analyses

    out = []
    for info in sorted(pkgutil.iter_modules(analyses.__path__), key=lambda i: i.name):
        spec = info.module_finder.find_spec(info.name)
        origin = getattr(spec, "origin", None)
        if origin and origin.endswith(".py"):
            with open(origin, encoding="utf-8") as fh:  # import only the modules that add a command:
                if "def register_cli" not in fh.read():  # the others pull in scipy for nothing
                    continue
        m = importlib.import_module(f"{analyses.__name__}.{info.name}")
        if callable(getattr(m, "register_cli", None)):
            out.append(m.register_cli)
    for ep in metadata.entry_points(group="hemocircuit.analyses"):
        try:
            obj = ep.load()
            out.append(obj if callable(obj) and not hasattr(obj, "register_cli") else obj.register_cli)
        except Exception as exc:  # noqa: BLE001 - one broken plug-in must not take the CLI down
            print(f"warning: analysis plug-in {ep.name!r} ({ep.value}) could not be loaded: {exc}",
                  file=sys.stderr)
    return out


def main(argv=None):
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        args.func(args)
    except HemocircuitError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:  # output piped into a command that stopped reading (| head)
        import os
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
