"""Nested sweeps for every command: ``--grid ID.PARAM=V1,V2,...`` (repeatable, Cartesian
product, the first grid varying slowest; like SPICE ``.step``).

Values take units (``art.tau_Ca=1,10,100s``, ``Pa.value=60:120:20mmHg``); structural options
are allowed (``art.ca_order=1,2``).  Each member is the command's own computation on the
circuit with the member's values applied exactly as ``--set`` would apply them
(:func:`hemocircuit.loading.load_circuit`), run in worker processes
(:func:`hemocircuit.execution.run_chunks`), and the members' results are stacked into ONE
:class:`~hemocircuit.results.Result`: the grid columns first (numbers in the parameter's
unit, options as text), then the member's own columns; the index is the grid parameters
followed by the command's own index.  ``freq`` and ``envelope`` take ``--grid`` too but batch
their members in the vectorised integrator instead (same columns, same order).

A member that fails is a row of NaN with its reason in the ``error`` column (and in
``metadata['failed']``); the others are kept (the CLI exits with status 3).  An interrupted
grid (SIGINT/SIGTERM) keeps the finished members (written to NAME.partial.EXT, exit 130/143).
"""
from __future__ import annotations

import time

import numpy as np

from .errors import HemocircuitError
from .labels import label_value
from .names import split_path


def parse(circuit, grid_args):
    """``['ID.PARAM=V1,V2', ...]`` -> (paths, assignments): the members as {path: value} dicts,
    values in the parameter's unit (ranges resolved) or as given (options).  Unknown
    parameters are errors naming the element's parameters."""
    from .batch import expand_grid, parse_grid_arg, resolve_values

    grids = [parse_grid_arg(g) for g in grid_args or []]
    paths = [p for p, _ in grids]
    dup = {p for p in paths if paths.count(p) > 1}
    if dup:
        raise HemocircuitError(f"--grid names {sorted(dup)} more than once; give all its values in one --grid")
    for p in paths:
        _check_path(circuit, p)
    grids = resolve_values(circuit, grids)
    return paths, expand_grid(grids)


def _check_path(circuit, path):
    if circuit.is_option(path):
        return
    eid = split_path(path)[0]
    if eid not in circuit.elements:
        import difflib
        near = difflib.get_close_matches(eid, list(circuit.elements), n=3)
        raise HemocircuitError(f"--grid {path}: no element {eid!r}" +
                               (f"; did you mean {', '.join(near)}?" if near else f"; elements: {list(circuit.elements)}"))
    circuit.param_path(path)  # raises a NetlistError naming the element's parameters


def _as_set(v, unit=""):
    """A grid value as a --set value: a number (a range's value, in the parameter's ``unit``)
    with that unit, so it reads back as it was meant (a bare number is refused for a parameter
    with a unit); an option or a quantity as given."""
    if isinstance(v, (bool, np.bool_)):
        return "true" if v else "false"
    if isinstance(v, (int, float, np.integer, np.floating)):
        return f"{float(v)!r} {unit}" if unit and unit not in ("1", "dimensionless") else repr(float(v))
    return str(v)


def _unit_of(circuit, path):
    return "" if circuit.is_option(path) else circuit.param_unit(path)


def _member(job):
    """Worker: one member -> a plain Result (picklable), or {'error': reason}."""
    from .results import Result, jsonable

    compute, args, sets = job
    try:
        r = compute(args, sets)
    except HemocircuitError as exc:
        return {"error": str(exc)}
    return Result(r.data, r.units, r.index, jsonable(r.metadata))


def run(compute, args, circuit, base_sets, workers=None, scheduler=None, progress=None):
    """Run ``compute(args, sets)`` (a module-level function returning a Result) for every member
    of ``args.grid`` on ``circuit``'s netlist and stack the results (:func:`stack`).

    A member that raises is a failed row (``error`` column, ``metadata['failed']``; the CLI
    exits with status 3).  Interrupted (SIGINT/SIGTERM), it raises
    :class:`~hemocircuit.errors.Interrupted` whose ``partial`` stacks the finished members (the
    others: error 'not run (interrupted)'), or None when none had finished."""
    from .batch import grid_columns
    from .errors import Interrupted
    from .execution import NOT_RUN, ChunkFailed, run_chunks

    paths, assignments = parse(circuit, args.grid)
    grid_columns(circuit, paths, assignments)  # values and units checked before anything runs
    units = {p: _unit_of(circuit, p) for p in paths}
    jobs = [(compute, args, {**base_sets, **{p: _as_set(v, units[p]) for p, v in a.items()}}) for a in assignments]
    started = time.perf_counter()
    stopped = None
    try:
        parts = run_chunks(_member, jobs, scheduler=scheduler, workers=workers, progress=progress,
                           desc=f"{args.command} grid", failures="collect")
    except KeyboardInterrupt as exc:  # SIGINT/SIGTERM: keep the finished members
        stopped, parts = exc, getattr(exc, "chunk_results", None) or [None] * len(jobs)
    n_run = sum(r is not None for r in parts)
    parts = [{"error": NOT_RUN} if r is None else {"error": r.reason} if isinstance(r, ChunkFailed) else r
             for r in parts]
    if stopped is not None and all(isinstance(r, dict) for r in parts):
        raise Interrupted.of(stopped) from None  # nothing finished: nothing to keep
    res = stack(parts, circuit, paths, assignments)
    res.metadata.setdefault("provenance", {})["wall_time_s"] = round(time.perf_counter() - started, 6)
    if stopped is not None:
        res.metadata["status"] = "partial"
        res.metadata["members_done"] = f"{n_run} of {len(jobs)} grid members finished"
        raise Interrupted.of(stopped, partial=res) from None
    return res


def stack(parts, circuit, paths, assignments):
    """Members' results (or {'error': reason}) -> one Result, grid columns first."""
    from .batch import grid_columns
    from .results import Result

    ok = [r for r in parts if not isinstance(r, dict)]
    if not ok:
        reasons = list(dict.fromkeys(r["error"] for r in parts))
        raise HemocircuitError(f"every member of the grid failed: {'; '.join(reasons[:3])}"
                               + (f" (and {len(reasons) - 3} other reasons)" if len(reasons) > 3 else ""))
    first = ok[0]
    gcols, gunits = grid_columns(circuit, paths, assignments)
    names, units = [], {}
    for r in ok:
        for k in r.data:
            if k not in names and k not in gcols and k != "error":
                names.append(k)
                units.setdefault(k, r.units.get(k, ""))
    failed = any(isinstance(r, dict) for r in parts)
    n_rows = [1 if isinstance(r, dict) else r.n_rows for r in parts]
    cols = {p: np.concatenate([np.repeat(gcols[p][k:k + 1], n) for k, n in enumerate(n_rows)]) for p in paths}
    for name in names:
        proto = next(r.data[name] for r in ok if name in r.data)
        text = proto.dtype.kind not in "iufb"
        chunks = []
        for r, n in zip(parts, n_rows):
            if not isinstance(r, dict) and name in r.data:
                chunks.append(r.data[name].astype(object) if text else r.data[name].astype(float))
            else:
                chunks.append(np.array([""] * n, dtype=object) if text else np.full(n, np.nan))
        cols[name] = np.concatenate(chunks)
        if proto.dtype.kind == "b" and not failed:
            cols[name] = cols[name].astype(bool)
    if failed or any("error" in r.data for r in ok):  # a failed member's reason, or a member's own
        cols["error"] = np.concatenate([np.array([r["error"]] * n, dtype=object) if isinstance(r, dict)
                                        else r.data["error"].astype(object) if "error" in r.data
                                        else np.array([""] * n, dtype=object) for r, n in zip(parts, n_rows)])
    md = dict(first.metadata)
    md["settings"] = {**md.get("settings", {}), "grid": {p: [_as_set(a[p]) for a in assignments] for p in paths}}
    md["grid"] = list(paths)
    member_measures = [None if isinstance(r, dict) else r.metadata.get("measures") for r in parts]
    if any(member_measures):
        md["measures"] = {"members": [{**{p: _as_set(a[p]) for p in paths}, **(m or {})}
                                      for a, m in zip(assignments, member_measures)]}
    else:
        md.pop("measures", None)
    md["failed"] = [[_where(a), r["error"]] for a, r in zip(assignments, parts) if isinstance(r, dict)]
    # a member's own failed points (a dc sweep's, a comparison's) and warnings, named by member
    md["failed"] += [[_where(a), _point(r, item)] for a, r in zip(assignments, parts) if not isinstance(r, dict)
                     for item in r.metadata.get("failed") or []]
    warnings = [f"{_label(a)}: {w}" for a, r in zip(assignments, parts) if not isinstance(r, dict)
                for w in r.metadata.get("warnings") or []]
    md.pop("warnings", None)
    md.pop("members_done", None)
    if warnings:
        md["warnings"] = warnings
    md["status"] = "partial" if md["failed"] else "complete"
    res = Result(cols, {**gunits, **units}, index=list(paths) + [i for i in first.index if i not in paths],
                 metadata=md)
    return res


def _where(a):
    return {p: _as_set(v) for p, v in a.items()}


def _label(a):
    return ", ".join(f"{p}={v}" for p, v in _where(a).items())


def _point(r, item):
    """A member's failed entry [index values..., reason] as 'at PARAM=V: reason'."""
    *at, why = item
    names = r.index if len(r.index) == len(at) else [""] * len(at)
    return f"at {', '.join(f'{n}={label_value(v)}' if n else label_value(v) for n, v in zip(names, at))}: {why}"


