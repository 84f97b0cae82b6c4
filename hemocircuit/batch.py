"""Batches of parameter sets: grids, and turning them into vectorised batch circuits.

A batch is a list of assignments ``{ID.PARAM: value}``.  Members that differ only in numeric
parameters share one assembled circuit whose parameter arrays hold one row per member;
members that differ in a structural option (``art.volume_flow``, ``art.ca_order``) are
assembled separately (they have other states).
"""
from __future__ import annotations

import itertools
import re

import numpy as np
import yaml

from .errors import HemocircuitError, NetlistError
from .units import UnitError, parse_quantity


def parse_grid_arg(text: str):
    """'art.tau_Ca=1s,10s' -> ('art.tau_Ca', ['1 s', '10 s']); also ranges '20:200:10mmHg'."""
    if "=" not in text:
        raise HemocircuitError(f"grid {text!r}: expected ID.PARAM=V1,V2,... (e.g. art.tau_Ca=1s,10s)")
    path, vals = text.split("=", 1)
    vals = vals.strip()
    if re.match(r"^[-+0-9.eE]+:[-+0-9.eE]+:[-+0-9.eE]+", vals):
        return path.strip(), ("range", re.sub(r"(\d)([A-Za-z])", r"\1 \2", vals, count=1))
    items = [v.strip() for v in vals.split(",") if v.strip()]
    tail = ""
    last = re.match(r"^[-+0-9.eE]+\s*([A-Za-z].*)$", items[-1]) if items else None
    if last:
        tail = last.group(1)
    out = []
    for it in items:
        m = re.match(r"^([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*([A-Za-z].*)?$", it)
        if m and m.group(2):
            out.append(f"{m.group(1)} {m.group(2)}")
        elif m and tail:
            out.append(f"{m.group(1)} {tail}")
        else:
            out.append(yaml.safe_load(it) if it.lower() in ("true", "false") else it)
    return path.strip(), out


def expand_grid(grids):
    """[(path, values), ...] -> list of assignment dicts (cartesian product, first varies slowest)."""
    if not grids:
        return [{}]
    paths = [p for p, _ in grids]
    return [dict(zip(paths, combo)) for combo in itertools.product(*[v for _, v in grids])]


def resolve_values(circuit, grids):
    """Expand 'range' entries of parse_grid_arg against the circuit's units."""
    from .analyses.dc import parse_range
    out = []
    for path, vals in grids:
        if isinstance(vals, tuple) and vals[0] == "range":
            vals = list(parse_range(vals[1], circuit.param_unit(path)))
        out.append((path, list(vals)))
    return out


def build_batches(circuit, assignments):
    """[(batch circuit, [member indices])]: one batch per distinct set of structural options."""
    groups, group_opts = {}, {}
    for k, a in enumerate(assignments):
        opts = {p: (yaml.safe_load(v) if isinstance(v, str) else v) for p, v in a.items() if circuit.is_option(p)}
        key = tuple(sorted((p, repr(v)) for p, v in opts.items()))
        groups.setdefault(key, []).append(k)
        group_opts[key] = opts
    out = []
    for key, members in groups.items():
        base = circuit.with_options(group_opts[key]) if key else circuit
        b = base.batch(len(members))
        params = sorted({p for k in members for p in assignments[k] if not circuit.is_option(p)})
        columns = {}
        for p in params:
            unit = b.param_unit(p)
            vals = []
            for k in members:
                v = assignments[k].get(p, None)
                if v is None:
                    vals.append(float(base.parameters.values[p][0]))
                else:
                    try:
                        vals.append(float(v) if isinstance(v, (int, float, np.floating)) else parse_quantity(v, unit, p))
                    except UnitError as exc:
                        raise NetlistError(str(exc)) from None
            columns[p] = np.array(vals)
        out.append((b.with_values(columns), members))
    return out


def grid_columns(circuit, paths, assignments):
    """Result columns for the grid values of each member: numeric parameters as numbers in the
    parameter's declared unit ('1 s' -> 1.0, unit 's'), structural options as they are (no unit).
    Returns ({path: array}, {path: unit})."""
    cols, units = {}, {}
    for p in paths:
        vals = [a.get(p) for a in assignments]
        if circuit.is_option(p):
            cols[p] = np.array([yaml.safe_load(v) if isinstance(v, str) else v for v in vals], dtype=object)
            if all(isinstance(v, (bool, np.bool_)) for v in cols[p]):
                cols[p] = cols[p].astype(bool)
            units[p] = ""
            continue
        unit = circuit.param_unit(p)
        out = []
        for v in vals:
            try:
                out.append(float(v) if isinstance(v, (int, float, np.floating)) else parse_quantity(v, unit, p))
            except UnitError as exc:
                raise NetlistError(str(exc)) from None
        cols[p], units[p] = np.array(out, dtype=float), unit
    return cols, units


def distinct_members(circuit):
    """(first, inverse): ``first`` the index of one member of each distinct parameter set of a
    batch circuit (members whose every fixed parameter value is equal), ``inverse[k]`` the
    position in ``first`` of member k's set.  Waveforms and options are common to a batch."""
    vals = circuit.parameters.values
    cols = []
    for path in vals:
        try:
            cols.append(np.asarray(vals[path], dtype=float))
        except NetlistError:  # follows an expression: no fixed value
            continue
    if circuit.B == 1 or not cols:
        return np.zeros(min(circuit.B, 1), int), np.zeros(circuit.B, int)
    rows = np.ascontiguousarray(np.stack(cols, axis=1))
    _, first, inverse = np.unique(rows.view(np.dtype((np.void, rows.dtype.itemsize * rows.shape[1]))).ravel(),
                                  return_index=True, return_inverse=True)
    order = np.argsort(first)  # keep the members' order
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    return first[order], rank[inverse.ravel()]


def member_operating_points(circuit):
    """:func:`hemocircuit.analyses.op.operating_points` of a batch circuit, solved once per
    distinct parameter set (:func:`distinct_members`; e.g. the frequencies of a frequency
    response share the operating point of their grid point) and given to every member."""
    from .analyses.op import operating_points

    first, inverse = distinct_members(circuit)
    # a member beyond floating-point range fails with its reason (no warnings meanwhile)
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        if len(first) == circuit.B:
            return operating_points(circuit)
        X, vals, errors = operating_points(circuit.subset(first))
    return X[inverse], {k: np.asarray(v)[inverse] for k, v in vals.items()}, [errors[i] for i in inverse]
