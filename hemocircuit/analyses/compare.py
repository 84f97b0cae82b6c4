"""Variant comparison: the same study on several netlists, side by side.

``hemocircuit compare A.yaml B.yaml ... --sweep Pa.value=20:200:2mmHg`` computes the steady
states of every netlist over the sweep; ``--tran --protocol P.yaml`` runs the same protocol
on each.  Output: one CSV, a row per (netlist, x) and a column per quantity (``name [unit]``),
and one overlay plot per quantity.  Quantities are every netlist's ``derived`` entries plus the columns they share.
"""
from __future__ import annotations

import os
import sys

import numpy as np

from ..derived import derived_units, evaluate_derived
from ..errors import HemocircuitError, Interrupted
from ..io import pyplot, save_figure
from ..provenance import clock, stamp
from ..results import Result


def compare_sweep(circuits, param, values):
    """Steady states of every circuit over ``param`` = ``values`` -> :class:`CompareResult`."""
    started = clock()
    parts, warnings, stopped = {}, [], None
    for c in circuits:
        try:
            res = c.dc_sweep(param, values)
        except KeyboardInterrupt as exc:  # SIGINT/SIGTERM: the netlists done and this one's points
            stopped, res = exc, getattr(exc, "partial", None)
            if res is None:
                break
        cols = {k: v for k, v in res.columns.items() if k != "error"}
        d = evaluate_derived(c.netlist.derived, cols, c.file)
        units = {**res.units, **derived_units(c.netlist.derived)}
        parts[c.netlist.name] = (np.asarray(res[param]), {**d, **cols}, units, res.failed)
        warnings += [f"{c.netlist.name}: {w}" for w in res.metadata.get("warnings", [])]
        if stopped is not None:
            break
    if not parts:
        raise Interrupted.of(stopped)
    res = CompareResult(parts, param, circuits[0].param_unit(param))
    if warnings:
        res.metadata["warnings"] = warnings
    if stopped is not None:
        res.metadata["status"] = "partial"
        res.metadata["members_done"] = f"{len(parts)} of {len(circuits)} netlists (the last one in part)"
        raise Interrupted.of(stopped, partial=stamp(res, "compare", circuits[0], {"mode": "sweep", "param": param},
                                                    started, status="partial"))
    if res.metadata["failed"]:
        res.metadata["status"] = "partial"
    return stamp(res, "compare", circuits[0], {"mode": "sweep", "param": param,
                                               "values": values if isinstance(values, str) else None,
                                               "netlists": [c.file for c in circuits]}, started)


def compare_transient(circuits, protocol, t_end=None, dt=None):
    """The same protocol on every circuit -> :class:`CompareResult` indexed by netlist and time."""
    started = clock()
    parts = {}
    for c in circuits:
        failed = []
        try:
            r = c.simulate(t_end, dt=dt, protocol=protocol)
        except HemocircuitError as exc:  # this netlist only: its computed part (if any) is kept
            r = getattr(exc, "partial", None)
            failed = [(float(r.t[-1]) if r is not None and r.n_rows else float("nan"), str(exc))]
            if r is None or not r.n_rows:
                parts[c.netlist.name] = (np.array([np.nan]), {}, {}, failed)
                continue
        d = evaluate_derived(c.netlist.derived, r.columns, c.file)
        parts[c.netlist.name] = (r.t, {**d, **r.columns}, {**r.units, **derived_units(c.netlist.derived)}, failed)
    res = CompareResult(parts, "time", "s")
    if res.metadata["failed"]:
        res.metadata["status"] = "partial"
    return stamp(res, "compare", circuits[0], {"mode": "tran", "protocol": protocol if isinstance(protocol, str)
                                               else getattr(protocol, "file", None), "t_end": t_end, "dt": dt,
                                               "netlists": [c.file for c in circuits]}, started)


class CompareResult(Result):
    """Several netlists side by side: one row per (netlist, x), indexed by ``netlist`` and the
    swept parameter (or ``time``); every quantity any netlist has is a column, NaN for the
    netlists without it.  ``parts`` {netlist name: (x, {quantity: array}, units, failed)}."""

    def __init__(self, parts, xname, xunit):
        self.parts = parts
        names = []
        for _, (_, q, _, _) in parts.items():
            names += [k for k in q if k not in names]
        units = {xname: xunit}
        for _, (_, q, u, _) in parts.items():
            for k in q:
                units.setdefault(k, u.get(k, ""))
        cols = {"netlist": np.concatenate([np.array([n] * len(x), dtype=object) for n, (x, _, _, _) in parts.items()]),
                xname: np.concatenate([np.asarray(x, dtype=float) for x, _, _, _ in parts.values()])}
        for k in names:
            cols[k] = np.concatenate([np.asarray(q[k], dtype=float) if k in q else np.full(len(x), np.nan)
                                      for x, q, _, _ in parts.values()])
        super().__init__(cols, units, index=["netlist", xname])
        self.metadata["failed"] = [[n, v, why] for n, (_, _, _, failed) in parts.items() for v, why in failed]
        if self.metadata["failed"]:  # a failed sweep point: its row; a failed run: its last row
            err = []
            for _, (x, _, _, failed) in parts.items():
                e = np.array([""] * len(x), dtype=object)
                for v, why in failed:
                    hit = np.nonzero(np.asarray(x, dtype=float) == v)[0]
                    e[hit[-1] if hit.size else -1] = why
                err.append(e)
            self.data["error"] = np.concatenate(err)
            self.units["error"] = ""

    def shared_quantities(self):
        """Quantities every netlist has, sorted."""
        names = None
        for _, (_, q, _, _) in self.parts.items():
            names = set(q) if names is None else names & set(q)
        return sorted(names or set())


def plot_overlays(prefix, res, quantities, xlabel=None):
    """One PNG per quantity, ``PREFIX_QUANTITY.png``, every netlist a line; returns the files."""
    plt = pyplot()

    xname = res.index[1]
    files = []
    for k in quantities:
        fig, ax = plt.subplots(figsize=(6.4, 4))
        for name in dict.fromkeys(res["netlist"]):
            sel = res["netlist"] == name
            if np.any(np.isfinite(res[k][sel])):
                ax.plot(res[xname][sel], res[k][sel], label=name)
        ax.set_xlabel(xlabel or res.label(xname))
        ax.set_ylabel(res.label(k))
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
    sp.add_argument("--out", help="result CSV (a row per netlist and x; or .json)")
    sp.add_argument("--plot", help="prefix of the overlay PNG files (one per quantity)")
    sp.add_argument("--show", action="append", help="quantity to print/plot (default: derived quantities)")
    sp.set_defaults(func=cmd_compare)


def cmd_compare(args):
    from ..cli import _range_spacing, _sets, _unit_to, events_only, load_circuit, record

    circuits, proto = [], None
    for path in args.netlists:
        c, proto = load_circuit(path, _sets(args.set), args.protocol)
        circuits.append(c)
    if args.tran:
        if not args.protocol:
            raise HemocircuitError("compare --tran needs --protocol")
        t_end = float(_unit_to(args.t_end, "s")) if args.t_end else None
        dt = float(_unit_to(args.dt, "s")) if args.dt else None
        res = compare_transient(circuits, events_only(proto), t_end, dt)
    else:
        if not args.sweep or "=" not in args.sweep:
            raise HemocircuitError("compare needs --sweep ID.PARAM=START:STOP:STEP UNIT (or --tran)")
        param, rng = args.sweep.split("=", 1)
        res = compare_sweep(circuits, param.strip(), _range_spacing(rng))
    derived = []
    for c in circuits:
        derived += [k for k in c.netlist.derived if k not in derived]
    shown = args.show or [k for k in derived if all(k in q for _, q, _, _ in res.parts.values())] or \
        res.shared_quantities()[:6]
    print(res.summary(show=shown, max_rows=24, where=args.out))
    for name, v, why in res.metadata["failed"]:
        print(f"{name}: failed at {res.index[1]}={v:g}: {why}", file=sys.stderr)
    record(args, res)
    if args.out:
        print(f"wrote {res.save(args.out)}")
    if args.plot:
        files = plot_overlays(os.path.splitext(args.plot)[0], res, shown)
        print("wrote " + ", ".join(files))
