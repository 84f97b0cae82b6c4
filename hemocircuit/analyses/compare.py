"""Variant comparison: the same study on several netlists, side by side.

``hemocircuit compare A.yaml B.yaml ... --sweep Pa.value=20:200:2mmHg`` computes the steady
states of every netlist over the sweep; ``--tran --protocol P.yaml`` runs the same protocol
on each.  Output: one CSV, a row per (netlist, x) and a column per quantity (``name [unit]``),
and one plot (a panel per unit, a line per netlist).  Quantities are every netlist's ``derived`` entries plus the columns they share.
"""
from __future__ import annotations

import sys

import numpy as np

from ..derived import derived_units, evaluate_derived
from ..errors import HemocircuitError, Interrupted
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
        name = _name(c, parts)
        parts[name] = (np.asarray(res[param]), {**d, **cols}, units, res.failed)
        warnings += [f"{name}: {w}" for w in res.metadata.get("warnings", [])]
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
        raise Interrupted.of(stopped, partial=stamp(res, "compare", circuits[0], {
            "mode": "sweep", "param": param, "values": values if isinstance(values, str) else None,
            "netlists": [c.file for c in circuits], "derived": _derived_names(circuits)}, started, status="partial"))
    if res.metadata["failed"]:
        res.metadata["status"] = "partial"
    return stamp(res, "compare", circuits[0], {"mode": "sweep", "param": param,
                                               "values": values if isinstance(values, str) else None,
                                               "netlists": [c.file for c in circuits],
                                               "derived": _derived_names(circuits)}, started)


def _name(c, parts):
    """The netlist's name, made unique (two netlists of one name must not merge their rows)."""
    name, k = c.netlist.name, 2
    while name in parts:
        name, k = f"{c.netlist.name} ({k})", k + 1
    return name


def _derived_names(circuits):
    names = []
    for c in circuits:
        names += [k for k in c.netlist.derived if k not in names]
    return names


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
                parts[_name(c, parts)] = (np.array([np.nan]), {}, {}, failed)
                continue
        d = evaluate_derived(c.netlist.derived, r.columns, c.file)
        parts[_name(c, parts)] = (r.t, {**d, **r.columns}, {**r.units, **derived_units(c.netlist.derived)}, failed)
    res = CompareResult(parts, "time", "s")
    if res.metadata["failed"]:
        res.metadata["status"] = "partial"
    return stamp(res, "compare", circuits[0], {"mode": "tran", "protocol": protocol if isinstance(protocol, str)
                                               else getattr(protocol, "file", None), "t_end": t_end, "dt": dt,
                                               "netlists": [c.file for c in circuits],
                                               "derived": _derived_names(circuits)}, started)


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


def register_cli(sub, common):
    sp = sub.add_parser("compare", help="steady states (or a protocol) of several netlists side by side")
    sp.add_argument("netlists", nargs="+", help="netlist YAML files (--set and --protocol apply to every one)")
    common(sp, outputs=False, netlist=False)
    sp.add_argument("--sweep", help="ID.PARAM=START:STOP:STEP UNIT")
    sp.add_argument("--tran", action="store_true", help="run --protocol on each netlist instead of a sweep")
    sp.add_argument("--t-end", help="end time for --tran")
    sp.add_argument("--dt", help="output interval for --tran")
    sp.add_argument("--out", help="result CSV (a row per netlist and x; or .json)")
    sp.add_argument("--plot", help="PNG: the quantities of interest, a panel per unit, a line per netlist")
    sp.add_argument("--show", action="append", help="quantity to print/plot (default: derived quantities)")
    sp.set_defaults(func=cmd_compare)


def compute_compare(args, sets):
    """The comparison on the netlists with ``sets`` applied (also one --grid member)."""
    from ..arguments import quantity_to, range_spacing
    from ..commands import circuit_of_args
    from ..loading import events_only

    circuits, proto = [], None
    for path in args.netlists:
        c, proto = circuit_of_args(args, sets, path)
        circuits.append(c)
    if args.tran:
        t_end = float(quantity_to(args.t_end, "s")) if args.t_end else None
        dt = float(quantity_to(args.dt, "s")) if args.dt else None
        return compare_transient(circuits, events_only(proto), t_end, dt)
    param, rng = args.sweep.split("=", 1)
    return compare_sweep(circuits, param.strip(), range_spacing(rng))


def cmd_compare(args):
    from ..commands import apply_measures, computed, record

    if args.tran and not args.protocol:
        raise HemocircuitError("compare --tran needs --protocol")
    if not args.tran and (not args.sweep or "=" not in args.sweep):
        raise HemocircuitError("compare needs --sweep ID.PARAM=START:STOP:STEP UNIT (or --tran)")
    res = computed(args, compute_compare)
    derived = res.metadata.get("settings", {}).get("derived", [])
    shown = args.show or [k for k in derived if k in res.data and _in_every_netlist(res, k)] or \
        [k for k in res.columns if _in_every_netlist(res, k)][:6]
    print(res.summary(show=shown, max_rows=24, where=args.out))
    for item in res.metadata.get("failed", []):
        if len(item) == 3:  # a netlist's point: [name, x, reason]
            name, v, why = item
            print(f"{name}: failed at {res.index[-1]}={v:g}: {why}", file=sys.stderr)
        else:  # a --grid member: [{param: value}, reason]
            print(f"failed: {item[0]}: {item[1]}", file=sys.stderr)
    apply_measures(args, res)
    record(args, res)
    if args.out:
        print(f"wrote {res.save(args.out)}")
    if args.plot:
        res.plot(args.plot, select=args.show)
        print(f"wrote {args.plot}")


def _in_every_netlist(res, k):
    """Whether every netlist of a comparison has quantity ``k`` (some finite value)."""
    try:
        v = np.asarray(res[k], dtype=float)
    except (TypeError, ValueError):
        return False
    return all(np.any(np.isfinite(v[res["netlist"] == n])) for n in dict.fromkeys(res["netlist"]))
