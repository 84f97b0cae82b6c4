"""Command line: ``hemocircuit check|op|dc|tran|graph NETLIST [options]``.

Errors the user can cause (netlist, units, topology, solver) print one clear message and
exit with status 2; they never show a traceback.
"""
from __future__ import annotations

import argparse
import sys

from . import io
from .errors import HemocircuitError


def _sets(items):
    out = {}
    for it in items or []:
        if "=" not in it:
            raise HemocircuitError(f"--set {it!r}: expected ID.PARAM=VALUE (e.g. Pa.value=90mmHg)")
        k, v = it.split("=", 1)
        out[k.strip()] = _unit_spacing(v.strip())
    return out


def _unit_spacing(v):
    """Accept '90mmHg' as well as '90 mmHg'."""
    import re
    m = re.match(r"^([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*([A-Za-z].*)$", v)
    return f"{m.group(1)} {m.group(2)}" if m else v


def _load(args):
    from .circuit import load
    from .protocol import Protocol

    c = load(args.netlist)
    sets = _sets(getattr(args, "set", None))
    opts = {k: v for k, v in sets.items() if k.partition(".")[0] in c.elements
            and k.partition(".")[2] in c.elements[k.partition(".")[0]].cls.options}
    if opts:
        c = c.with_options({k: _option_literal(v) for k, v in opts.items()})
    c.set_params({k: v for k, v in sets.items() if k not in opts})
    proto = Protocol.load(args.protocol, c) if getattr(args, "protocol", None) else None
    return c, proto


def _option_literal(v):
    import yaml
    return yaml.safe_load(v)


def cmd_check(args):
    c, proto = _load(args)
    print(c.describe())
    print("ok: the netlist is valid" + (" and so is the protocol" if proto else ""))


def cmd_op(args):
    c, proto = _load(args)
    if proto:
        c = proto.apply_initial(c)
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
    import re
    return re.sub(r"(\d)([A-Za-z])", r"\1 \2", r, count=1)


def cmd_tran(args):
    c, proto = _load(args)
    t_end = float(_unit_to(args.t_end, "s")) if args.t_end else None
    dt = float(_unit_to(args.dt, "s")) if args.dt else None
    res = c.simulate(t_end, dt=dt, protocol=proto, method=args.method)
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

    def common(sp):
        sp.add_argument("netlist", help="netlist YAML file")
        sp.add_argument("--set", action="append", metavar="ID.PARAM=VALUE", help="override a parameter (units allowed)")
        sp.add_argument("--protocol", help="protocol YAML (timed events)")
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
    sp.set_defaults(func=cmd_tran)
    common(sub.add_parser("graph", help="draw the circuit graph to PNG")).set_defaults(func=cmd_graph)
    for register in _extra_commands():
        register(sub, common)
    return p


def _extra_commands():
    """Commands contributed by analysis modules (each module exposes register_cli)."""
    import importlib
    out = []
    for mod in ("compare", "ac", "freq", "stability", "envelope", "periodic"):
        try:
            m = importlib.import_module(f".analyses.{mod}", __package__)
        except ModuleNotFoundError:
            continue
        if hasattr(m, "register_cli"):
            out.append(m.register_cli)
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
    return 0


if __name__ == "__main__":
    sys.exit(main())
