"""Run svZeroDSolver test cases with their simulation semantics and compare with their results.

A case folder is laid out like ``../shared/svzerod/``: ``cases/NAME.json`` and
``results/result_NAME.json`` / ``converged/result_NAME.json`` (pandas ``to_json`` of their
output: per vessel ``name, time, flow_in, flow_out, pressure_in, pressure_out`` or, with
``output_variable_based``, ``name, time, y``).

Their semantics (src/solve/SimulationParameters.cpp, Solver.cpp): time step T/(N-1) for N
points per cardiac cycle T; ``number_of_cardiac_cycles`` cycles; by default only the last cycle
is written, its times shifted to start at 0 (``output_all_cycles`` writes every step from 0);
``output_mean_only`` writes the mean over the written rows; ``steady_initial`` (their default)
starts from a steady state with the time series at their means.  Here the start is the true
operating point of the model with the time series at their means (theirs is 31 pseudo-time
steps, so only rows after the first cycle are compared for all-cycles output), except for a
case whose run does not forget its start (:func:`keeps_its_start`), which starts by their
procedure.  With ``use_cycle_to_cycle_error`` the cycles are theirs (:func:`simulate_case`).

Error of a variable: max |ours - theirs| over the compared rows, divided by the range of theirs
over those rows (by max |theirs| when the range is below 1e-6 of it: steady and mean rows, and
the pressure of a PRESSURE boundary condition, which their Newton iteration holds only to ~1e-7
relative: chamber_sphere's constant 2150 moves by 0.002).
"""
from __future__ import annotations

import glob
import os
import re
import time
from dataclasses import dataclass, field

import numpy as np

from .. import inputs
from ..errors import HemocircuitError, NetlistError, did_you_mean, excerpt
from .importer import import_svzerod, write_netlist
from .model import as_float, show
from .tolerances import keeps_its_start, run_tolerances, tolerances

@dataclass
class CaseResult:
    name: str
    types: list = field(default_factory=list)
    err_p: float = float("nan")
    err_q: float = float("nan")
    tol_p: float = float("nan")
    tol_q: float = float("nan")
    ok: bool = False
    ours_s: float = float("nan")
    theirs: str = ""
    note: str = ""
    worst: str = ""


def their_times(readme, access=None):
    """{case: their time text} from the README's speed table, when present (read under the
    input policy: a README that is not a regular file, or too large, is an error naming it)."""
    out = {}
    if os.path.lexists(readme):
        text = inputs.read_text(readme, "svZeroDSolver cases README", access)
        for line in text.splitlines():
            m = re.match(r"\|\s*(\w+)\s*\|[^|]*\|\s*([^|]+?)\s*\|\s*$", line)
            if m and m.group(1) not in ("case",):
                out[m.group(1)] = m.group(2)[:40]
    return out


def read_result(path, access=None):
    """{their variable name: (times, values)} of a result file (read under the input policy,
    within the RESULT_MB limit; a malformed file is an error naming it and what is wrong)."""
    return parse_result(inputs.read_json(path, "svZeroDSolver result file", access, size_limit="RESULT_MB"), path)


RESULT_COLUMNS = ("flow_in", "flow_out", "pressure_in", "pressure_out")


def parse_result(d, path=None):
    """{their variable name: (times, values)} of a result in their layout: pandas ``to_json`` of
    their DataFrame (a result file's content, or ``json.loads(df.to_json())`` of
    ``pysvzerod.simulate``'s): {"name": {row: name}, "time": {row: t or null}, and "y" (per
    variable) or flow_in, flow_out, pressure_in, pressure_out (per block): {row: number}}.
    ``path``: the file, for messages.  Anything else is an error saying what is wrong."""
    def bad(msg):
        return NetlistError(f"not an svZeroDSolver result: {msg} (their layout: pandas to_json of their output, "
                            '{"name": {"0": ...}, "time": {"0": ...}, "y": {"0": ...}} or per block flow_in, '
                            "flow_out, pressure_in, pressure_out)", file=None if path is None else str(path))

    if not isinstance(d, dict):
        raise bad(f"a JSON object is expected, got {show(d)}")
    cols = ("y",) if "y" in d else RESULT_COLUMNS
    for key in ("name", "time") + cols:
        if not isinstance(d.get(key), dict):
            raise bad(f"'{key}' " + ("is missing" if key not in d else f"must map rows to values, got {show(d[key])}"))
    def numbered(r):
        try:
            return int(r)
        except (TypeError, ValueError):
            raise bad(f"the rows of 'name' must be numbered (\"0\", \"1\", ...), got {show(r)}") from None

    rows = sorted(d["name"], key=numbered)
    names = []
    for r in rows:
        n = d["name"][r]
        if not isinstance(n, str):
            raise bad(f"name of row {excerpt(str(r), 20)[1:-1]} must be a variable or block name, got {show(n)}")
        names.append(n)

    def column(key, allow_null=False):
        out = np.empty(len(rows))
        col = d[key]
        for i, r in enumerate(rows):
            if r not in col:
                raise bad(f"'{key}' has no row {excerpt(str(r), 20)[1:-1]}")
            v = col[r]
            if v is None and allow_null:
                out[i] = np.nan  # their output_mean_only rows: time null
                continue
            f = as_float(v)
            if f is None:
                raise bad(f"'{key}' of row {excerpt(str(r), 20)[1:-1]} ({excerpt(names[i], 40)}) must be a finite "
                          f"number, got {show(v)}")
            out[i] = f
        return out

    times = column("time", allow_null=True)
    where = {}  # name -> its row positions, in order (one pass: linear in the rows)
    for i, n in enumerate(names):
        where.setdefault(n, []).append(i)
    out = {}
    for col in cols:
        values = column(col)
        for n, idx in where.items():
            out[n if col == "y" else f"{n}:{col}"] = (times[idx], values[idx])
    return out


def case_start(model, mean_circuit):
    """How the runner starts a case: 'initial' (their initial_condition: closed loops and
    steady_initial false), 'their-steady' (their procedure, for a case that keeps its start)
    or 'operating-point' (ours, the states their initial condition sets overridden)."""
    from ..analyses.op import steady_state

    if model.initial and (model.closed or not model.sim.get("steady_initial", True)):
        return "initial"
    if keeps_its_start(model, mean_circuit, steady_state(mean_circuit)):
        return "their-steady"
    return "operating-point"


def simulate_case(model, rtol=None, timed_runs=1, atol=None, cfg=None, between=None):
    """Our run with their semantics: (result, mask of the rows they write, those rows' times
    in their convention, times (timed_runs, 2): wall and CPU time of each in-process solve [s]:
    the start (operating point, or their steady_initial procedure for a case that keeps its
    start) and integration, not loading nor compiling).  ``rtol`` None: :func:`run_tolerances`
    (``atol`` kept unless the case keeps its start).  The chosen start, rtol and
    atol are in ``result.metadata['conformance']``.

    With ``use_cycle_to_cycle_error`` (``cfg``: their JSON configuration, for their vessel
    caps) the cycles are theirs (Solver.cpp): with an RCR the count of their eq. 21
    (output.their_cycles); otherwise the given cycles, then one
    more at a time until their criterion holds at the caps (cycles.cycle_means/cycle_errors
    on the last two cycles), and with ``output_all_cycles`` the rows of those extra cycles are
    written as theirs are: times i dt, i = 1 .. N-1, in each (their extra-cycle loop restarts
    its step counter), so the result may hold repeated times; compare matches such rows by
    position.

    ``between``: called (untimed) after each timed run: a benchmark's run of another solver
    in the same rounds, so that a host whose speed drifts slows both alike."""
    import tempfile

    from ..analyses.op import steady_state
    from ..analyses.transient import simulate
    from ..circuit import load
    from ..ic import apply_ic
    from .steady_initial import their_steady_initial

    T, N, ncyc = model.period, model.points, model.n_cycles
    dt = T / (N - 1)
    with tempfile.TemporaryDirectory(prefix="hemocircuit_svz_") as d:
        write_netlist(model.netlist, os.path.join(d, "m.yaml"))
        write_netlist(model.mean_netlist, os.path.join(d, "mean.yaml"))
        c = load(os.path.join(d, "m.yaml"))
        cm = load(os.path.join(d, "mean.yaml"))
    from .output import runs_extra_cycles, their_cycles

    model = their_cycles(model, c)  # a copy with their cycle count: the caller's model is left as it is
    extra_rule = runs_extra_cycles(model, c)
    if extra_rule and cfg is None:
        raise HemocircuitError(f"{model.name}: use_cycle_to_cycle_error needs the model's configuration (cfg) "
                               "for their vessel caps")
    T, N, ncyc = model.period, model.points, model.n_cycles
    start = case_start(model, cm) if c.nx else "operating-point"  # a choice of procedure: not timed
    if rtol is None:
        rtol, atol_run = run_tolerances(model, cm, c)
        atol = atol if atol_run is None else atol_run
    t_end = ncyc * T
    times = []
    for _ in range(max(1, timed_runs)):
        t0, c0 = time.perf_counter(), time.process_time()
        if start == "initial":
            # their start: the initial condition (0 where not given); a closed loop keeps the
            # blood volume of that start whatever their steady_initial does
            x0 = apply_ic(c, np.zeros(c.nx), model.initial)
        elif start == "their-steady":
            x0 = their_steady_initial(model, cm)
        else:  # our operating point for their steady_initial, with the states they set
            x0 = apply_ic(c, steady_state(cm), model.initial_given)
        if c.nx == 0:  # no states: the outputs are algebraic functions of time
            t = np.arange(0, (N - 1) * ncyc + 1) * dt
            res = c.outputs(t, np.zeros((t.size, 0)))
        else:
            # rows of the last cycle only, unless they write all (as their output)
            res = simulate(c, t_end, dt=dt, x0=x0, rtol=rtol, atol=atol, progress=False,
                           output_from=None if model.sim.get("output_all_cycles")
                           else max(0, ncyc - (2 if extra_rule else 1)) * T)  # their criterion: 2 cycles
            res.metadata["conformance"] = {"start": start, "rtol": rtol, "atol": atol}
            t = np.asarray(res.t)
            if extra_rule:
                res = _with_their_extra_cycles(model, cfg, c, res, rtol, atol)
        times.append((time.perf_counter() - t0, time.process_time() - c0))
        if between is not None:
            between()
    if isinstance(res, dict) and "_their_times" in res:  # extra cycles: their row times
        t_out = res.pop("_their_times")
        return res, np.ones(t_out.size, bool), t_out, np.array(times)
    k = np.rint(t / dt).astype(int)
    if model.sim.get("output_all_cycles"):
        keep = np.ones(t.size, bool)
        t_out = k * dt
    else:
        first = (ncyc - 1) * (N - 1)
        keep = k >= first
        t_out = (k - first) * dt
    return res, keep, t_out[keep], np.array(times)


def _with_their_extra_cycles(model, cfg, c, res, rtol, atol):
    """``res`` with their extra cycles (output.their_extra_cycles: while their criterion fails
    on the last two cycles, one more).  With output_all_cycles their rows of those cycles are
    written too, times restarting at dt in each: returned as a columns dict of every row with
    '_their_times' their times.  Otherwise their rows are those of the given last cycle (their
    extra-cycle loop writes none), so ``res`` is kept (its metadata says how many ran)."""
    from .output import their_extra_cycles

    ext, extra = their_extra_cycles(model, cfg, c, res, rtol, atol)
    res.metadata["conformance"]["extra_cycles"] = extra
    if not (extra and model.sim.get("output_all_cycles")):
        return res
    N = model.points
    dt = model.period / (N - 1)
    n_given = ext.t.size - extra * (N - 1)  # the rows before the extra cycles
    out = dict(ext.columns)
    out["_their_times"] = np.concatenate([np.rint(ext.t[:n_given] / dt) * dt] + [np.arange(1, N) * dt] * extra)
    return out


def compare(model, res, keep, t_out, theirs):
    """(max pressure error, max flow error, worst variable, note) against their rows."""
    all_cycles = bool(model.sim.get("output_all_cycles"))
    mean_only = bool(model.sim.get("output_mean_only"))
    errs = {"P": (0.0, ""), "Q": (0.0, "")}
    missing = []
    columns = dict(getattr(res, "columns", res))
    if model.netlist.get("derived"):  # their flows that include a reduced capacitor's
        from ..derived import evaluate_derived

        columns.update(evaluate_derived(model.netlist["derived"], columns))
    for name, (tt, yy) in theirs.items():
        col = model.columns.get(name)
        if col is None:
            if not name.startswith("valve_status"):
                missing.append(name)
            continue
        ours = np.asarray(columns[col], float)[keep]
        kind = "Q" if ("flow" in name) else "P"  # chamber volumes count with the pressures
        factor = model.factors.get(name)
        if factor is None:
            factor = _unit_factor(model, "Q" if kind == "Q" else ("V" if name.startswith("Vc:") else "P"))
        ours = ours * factor
        if mean_only:
            o, y = np.array([ours.mean()]), yy
        else:
            idx = np.rint(tt / (t_out[1] - t_out[0]) if t_out.size > 1 else 0).astype(int)
            if tt.size > 1 and np.any(np.diff(tt) <= 0):  # their extra cycles restart the times:
                if tt.size != ours.size:  # rows in order, as written
                    raise HemocircuitError(f"their result has {tt.size} rows of {name}, ours {ours.size}")
                idx = np.arange(tt.size)
            if idx.size and (idx.max() >= ours.size or idx.min() < 0):
                extra = (" (use_cycle_to_cycle_error: their criterion ran more cycles than "
                         "number_of_cardiac_cycles; not reproduced by this runner)"
                         if model.sim.get("use_cycle_to_cycle_error") else "")
                raise HemocircuitError(f"their result has rows of {name} at t = {np.nanmax(tt):g} s, beyond our "
                                       f"output ({t_out[-1] if t_out.size else 0:g} s){extra}")
            o = ours[idx]
            y = yy
            if all_cycles:
                # steady start: compare after the first cycle (their steady start differs from
                # ours); from their initial condition both start alike, so every row after t = 0
                # counts (their t = 0 row is the raw initial vector: 0 for every variable it
                # does not set, pressures included, not a consistent state)
                sel = tt >= model.period * (1 - 1e-9) if model.sim.get("steady_initial", True) else tt > 0
                o, y = o[sel], y[sel]
        e = range_error(o, y)
        if e > errs[kind][0] or not np.isfinite(e):
            errs[kind] = (e, name)
    note = f"no column for {len(missing)} of their variables ({missing[0]}, ...)" if missing else ""
    worst = max(errs.values(), key=lambda v: v[0])[1]
    return errs["P"][0], errs["Q"][0], worst, note


def range_error(o, y):
    """max |o - y| relative to the range of y (to its magnitude where y is constant to 1e-6 of
    it; 1 where y is 0): the conformance runner's measure of a variable's difference."""
    if not np.size(y):
        return 0.0
    rng, big = np.ptp(y), np.max(np.abs(y))
    scale = rng if rng > 1e-6 * big else (big if big > 0 else 1.0)
    return float(np.max(np.abs(np.asarray(o) - y)) / scale)


def compare_their_rows(model, mine, ref):
    """(max pressure error, max flow error) of a result in their layout ``mine`` (parse_result:
    e.g. their solver at a finer step) against ``ref`` (their converged rows), on the rows of
    ``ref`` (matched by time; ``mine`` may hold more) and by :func:`compare`'s rules: valve
    status excluded, chamber volumes with the pressures, errors relative to the range, with
    ``output_all_cycles`` and a steady start the first cycle left out."""
    all_cycles = bool(model.sim.get("output_all_cycles"))
    errs = {"P": 0.0, "Q": 0.0}
    for name, (tt, yy) in ref.items():
        if name.startswith("valve_status") or name not in mine:
            continue
        tm, ym = mine[name]
        idx = np.searchsorted(tm, tt - 1e-9 * model.period)
        idx = np.minimum(idx, tm.size - 1)
        if np.any(np.abs(tm[idx] - tt) > 1e-6 * model.period):
            raise HemocircuitError(f"{name}: rows at t = {tt[np.argmax(np.abs(tm[idx] - tt))]:g} s missing")
        o, y = ym[idx], yy
        if all_cycles and model.sim.get("steady_initial", True):
            sel = tt >= model.period * (1 - 1e-9)
            o, y = o[sel], y[sel]
        kind = "Q" if "flow" in name else "P"
        errs[kind] = max(errs[kind], range_error(o, y))
    return errs["P"], errs["Q"]


def _unit_factor(model, kind):
    """Factor from our unit (mmHg, mL/s, mL) to the model's (theirs) for P, Q or V."""
    from ..units import parse_quantity

    return parse_quantity({"P": "1 mmHg", "Q": "1 mL/s", "V": "1 mL"}[kind], model.units[kind])


def _block_types(cfg):
    """The block types a (maybe malformed) model names, for the table of a case that failed."""
    if not isinstance(cfg, dict):
        return []
    found = set()
    for k in ("vessels", "junctions", "boundary_conditions", "chambers", "valves", "closed_loop_blocks"):
        blocks = cfg.get(k)
        for b in blocks if isinstance(blocks, list) else []:
            if isinstance(b, dict):
                t = next((b.get(key) for key in ("zero_d_element_type", "junction_type", "bc_type", "type",
                                                  "closed_loop_type") if isinstance(b.get(key), str)), "?")
                found.add(t[:40])
    return sorted(found)


def run_case(case_path, against="converged", timed_runs=1, rtol=None):
    """Run one case (``FOLDER/cases/NAME.json``) and compare it with ``FOLDER/AGAINST/result_NAME.json``.
    Every file is read under the input policy, inside FOLDER (a link leading out of it is
    refused); an error of the case or of its result is the case's note (the row fails)."""
    name = os.path.splitext(os.path.basename(case_path))[0]
    folder = os.path.dirname(os.path.dirname(os.path.abspath(case_path)))
    access = inputs_access(folder)
    r = CaseResult(name)
    r.theirs = their_times(os.path.join(folder, "README.md"), access).get(name, "")
    cfg = None
    try:
        cfg = inputs.read_json(case_path, "svZeroDSolver model file", access)
        model = import_svzerod(cfg, name=name, source=case_path)
        r.types = model.block_types
        r.tol_p, r.tol_q = tolerances(name, model)
        res, keep, t_out, times = simulate_case(model, rtol=rtol, timed_runs=timed_runs, cfg=cfg)
        r.ours_s = float(times[:, 0].min())
        theirs = read_result(os.path.join(folder, against, f"result_{name}.json"), access)
        r.err_p, r.err_q, r.worst, r.note = compare(model, res, keep, t_out, theirs)
        r.ok = r.err_p <= r.tol_p and r.err_q <= r.tol_q and not r.note
    except HemocircuitError as exc:
        r.note = f"{type(exc).__name__}: {exc}"
        r.types = r.types or _block_types(cfg)
    return r


def inputs_access(folder):
    """The allowed folders of a conformance run: the case folder itself."""
    from ..access import Access

    return Access([folder])


def case_names(folder):
    """The names of the cases in ``folder``/cases (``NAME.json``), sorted."""
    return [os.path.splitext(os.path.basename(p))[0] for p in sorted(glob.glob(os.path.join(glob.escape(folder),
                                                                                            "cases", "*.json")))]


def run_folder(folder, against="converged", cases=None, timed_runs=1, rtol=None):
    """Run the cases of ``folder`` (``cases``: only these names; each must exist: a typo is an
    error listing the known cases, not a run of nothing)."""
    known = case_names(folder)
    if not known:
        raise NetlistError(f"{folder}: no svZeroDSolver cases (cases/*.json) to run")
    if cases:
        unknown = [c for c in dict.fromkeys(cases) if c not in known]
        if unknown:
            raise NetlistError(f"--case {show(unknown[0])}: no such case in {os.path.join(folder, 'cases')}"
                               f"{did_you_mean(unknown[0], known)}; the cases are: {', '.join(known)}")
        known = [k for k in known if k in cases]
    return [run_case(os.path.join(folder, "cases", k + ".json"), against, timed_runs, rtol) for k in known]


def format_table(rows):
    head = f"{'case':40s} {'blocks':48s} {'err P':>9s} {'err Q':>9s} {'tol P/Q':>13s} {'ok':4s} {'ours':>9s} {'theirs':>12s}"
    lines = [head, "-" * len(head)]
    for r in rows:
        lines.append(f"{r.name:40s} {','.join(r.types)[:48]:48s} {r.err_p:9.2e} {r.err_q:9.2e} "
                     f"{r.tol_p:6.0e}/{r.tol_q:<6.0e} {'pass' if r.ok else 'FAIL':4s} "
                     f"{r.ours_s * 1e3:7.1f}ms {r.theirs:>12s}")
        if r.note:
            lines.append(f"    {r.note}")
    n_ok = sum(r.ok for r in rows)
    lines.append(f"{n_ok} of {len(rows)} cases pass")
    return "\n".join(lines)
