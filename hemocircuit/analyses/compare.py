"""Variant comparison: the same study on several netlists, side by side.

``hemocircuit compare A.yaml B.yaml ... --sweep Pa.value=20:200:2mmHg`` computes the steady
states of every netlist over the sweep; ``--tran --protocol P.yaml`` runs the same protocol
on each.  Output: one tidy CSV (netlist, x, quantity, value, unit) and one overlay plot per
quantity.  Quantities are every netlist's ``derived`` entries plus the columns they share.
"""
from __future__ import annotations

import csv
import os

import numpy as np

from ..derived import derived_units, evaluate_derived
from ..errors import HemocircuitError
from ..io import pyplot, save_figure


def compare_sweep(circuits, param, values):
    """{netlist name: (x, {quantity: array}, {quantity: unit})} for a DC sweep."""
    out = {}
    for c in circuits:
        res = c.dc_sweep(param, values)
        cols = {k: v for k, v in res.items() if k != param}
        d = evaluate_derived(c.netlist.derived, cols, c.file)
        units = {**res.units, **derived_units(c.netlist.derived)}
        out[c.netlist.name] = (np.asarray(res[param]), {**d, **cols}, units, res.failed)
    return out


def compare_transient(circuits, protocol, t_end=None, dt=None):
    out = {}
    for c in circuits:
        r = c.simulate(t_end, dt=dt, protocol=protocol)
        d = evaluate_derived(c.netlist.derived, r.columns, c.file)
        out[c.netlist.name] = (r.t, {**d, **r.columns}, {**r.units, **derived_units(c.netlist.derived)}, [])
    return out


def shared_quantities(results, derived_first=True):
    names = None
    for _, (_, q, _, _) in results.items():
        names = set(q) if names is None else names & set(q)
    names = names or set()
    return sorted(names)


def write_tidy(path, results, xname, xunit):
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["netlist", f"{xname} [{xunit}]", "quantity", "value", "unit"])
        for name, (x, q, units, _) in results.items():
            for k in sorted(q):
                v = np.asarray(q[k], dtype=float)
                for xi, vi in zip(x, v):
                    w.writerow([name, repr(float(xi)), k, repr(float(vi)), units.get(k, "")])


def plot_overlays(prefix, results, quantities, xlabel):
    plt = pyplot()

    files = []
    for k in quantities:
        fig, ax = plt.subplots(figsize=(6.4, 4))
        unit = ""
        for name, (x, q, units, _) in results.items():
            if k in q:
                ax.plot(x, q[k], label=name)
                unit = units.get(k, unit)
        ax.set_xlabel(xlabel)
        ax.set_ylabel(f"{k} [{unit}]" if unit else k)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
        safe = "".join(ch if ch.isalnum() or ch in "._-" else "_" for ch in k)
        f = f"{prefix}_{safe}.png"
        save_figure(fig, f, dpi=100)
        files.append(f)
    return files


def register_cli(sub, common):
    sp = sub.add_parser("compare", help="steady states (or a protocol) of several netlists side by side")
    sp.add_argument("netlists", nargs="+", help="netlist YAML files (--set and --protocol apply to every one)")
    common(sp, outputs=False, netlist=False)
    sp.add_argument("--sweep", help="ID.PARAM=START:STOP:STEP UNIT")
    sp.add_argument("--tran", action="store_true", help="run --protocol on each netlist instead of a sweep")
    sp.add_argument("--t-end", help="end time for --tran")
    sp.add_argument("--dt", help="output interval for --tran")
    sp.add_argument("--out", help="tidy CSV file")
    sp.add_argument("--plot", help="prefix of the overlay PNG files (one per quantity)")
    sp.add_argument("--show", action="append", help="quantity to print/plot (default: derived quantities)")
    sp.set_defaults(func=cmd_compare)


def cmd_compare(args):
    from ..cli import _range_spacing, _sets, _unit_to, events_only, load_circuit

    circuits, proto = [], None
    for path in args.netlists:
        c, proto = load_circuit(path, _sets(args.set), args.protocol, args.allow_path)
        circuits.append(c)
    if args.tran:
        if not args.protocol:
            raise HemocircuitError("compare --tran needs --protocol")
        t_end = float(_unit_to(args.t_end, "s")) if args.t_end else None
        dt = float(_unit_to(args.dt, "s")) if args.dt else None
        results = compare_transient(circuits, events_only(proto), t_end, dt)
        xname, xunit = "time", "s"
    else:
        if not args.sweep or "=" not in args.sweep:
            raise HemocircuitError("compare needs --sweep ID.PARAM=START:STOP:STEP UNIT (or --tran)")
        param, rng = args.sweep.split("=", 1)
        param = param.strip()
        results = compare_sweep(circuits, param, _range_spacing(rng))
        xname, xunit = param, circuits[0].param_unit(param)
    derived = []
    for c in circuits:
        derived += [k for k in c.netlist.derived if k not in derived]
    shown = args.show or [k for k in derived if all(k in q for _, q, _, _ in results.values())] or \
        shared_quantities(results)[:6]
    header = ["netlist", f"{xname} [{xunit}]"] + shown
    print("  ".join(f"{h:>16}" for h in header))
    for name, (x, q, units, failed) in results.items():
        step = max(1, len(x) // 10)
        for i in range(0, len(x), step):
            vals = [q[k][i] if k in q else np.nan for k in shown]
            print("  ".join([f"{name:>16}", f"{x[i]:>16.6g}"] + [f"{v:>16.6g}" for v in vals]))
        for v, why in failed:
            print(f"{name}: failed at {xname}={v:g}: {why}")
    if args.out:
        write_tidy(args.out, results, xname, xunit)
        print(f"wrote {args.out}")
    if args.plot:
        prefix = os.path.splitext(args.plot)[0]
        files = plot_overlays(prefix, results, shown, f"{xname} [{xunit}]")
        print("wrote " + ", ".join(files))
