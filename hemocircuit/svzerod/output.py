"""svZeroDSolver's result layout as an output: a run with their simulation semantics written
as their ``pysvzerod.simulate`` DataFrame saved with pandas ``to_json`` (the files of their
test suite, ``results/result_NAME.json``), so their post-processing reads ours unchanged.

Their semantics (SimVascular/svZeroDSolver src/solve/Solver.cpp ``run_integration``,
SimulationParameters.cpp ``load_simulation_params``): N points per cardiac cycle T, step
dt = T/(N-1), ``number_of_cardiac_cycles`` n, steps i = 0 .. (N-1) n.  Rows are written every
``output_interval`` steps; without ``output_all_cycles`` only from the first step of the last
cycle, i0 = (N-1)(n-1), on (their counter restarts there), times shifted so that the first
written row is at 0.  ``output_mean_only``: one row per block/variable, the mean over the
written rows, time null.

Layouts (src/solve/csv_writer.cpp):
  per block (default): blocks BloodVessel, BloodVesselCRL, PiecewiseValve,
      LinearElastanceChamber (and ChamberSphere) in their creation order (vessels, valves,
      chambers), columns ``name, time, flow_in, flow_out, pressure_in, pressure_out`` from the
      block's inlet and outlet node, plus ``d_flow_in, d_flow_out, d_pressure_in,
      d_pressure_out`` with ``output_derivative``;
  per variable (``output_variable_based``): every variable of their DOF handler in its order
      (Model::finalize: the nodes ``flow:A:B``, ``pressure:A:B`` in connection order, then the
      blocks' internal variables ``NAME:block`` in block order), columns ``name, time, y``
      (and ``ydot``).
pandas ``to_json`` (orient ``columns``): ``{"name": {"0": ..., "1": ...}, "time": {...}, ...}``.

Units: theirs (the importer's unit system: dyn/cm^2, mL/s, mL for cgs), converted back from
the circuit's mmHg, mL/s, mL here, the one place the importer's conversion is undone.
Derivatives: the exact time derivative of each output along the trajectory,
dy/dt = dy/dx f(t, x) + dy/dt|_x, from a one-sided (left) second-order difference along the
tangent (their time series are piecewise linear: at a sample the slope of the interval ending
there, the side their implicit step sees); theirs is the generalized-alpha ydot, which differs by
their time-discretisation error.
"""
from __future__ import annotations

import json
import os

import numpy as np

from ..errors import HemocircuitError
from .model import HEART, HEART_IN, HEART_OUT, check_points, ident, read_model

#: their blocks written by to_vessel_csv (a dynamic_cast list in csv_writer.cpp)
VESSEL_OUTPUT_TYPES = ("BloodVessel", "BloodVesselCRL", "PiecewiseValve", "LinearElastanceChamber", "ChamberSphere",
                       "Resistance", "Capacitance", "Inductance")
VESSEL_COLUMNS = ("flow_in", "flow_out", "pressure_in", "pressure_out")
#: internal variables of the heart block (ClosedLoopHeartPulmonary.cpp setup_dofs), kind of each
HEART_VARIABLES = ("V_RA", "Q_RA", "P_RV", "V_RV", "Q_RV", "P_pul", "P_LA", "V_LA", "Q_LA", "P_LV", "V_LV", "Q_LV")


def connections(cfg):
    """(upstream, downstream) block pairs in their order (SimulationParameters.cpp
    load_simulation_model: vessels, junctions, the closed-loop heart, valves; chambers add none)."""
    out = []
    by_id = {}
    for v in cfg.get("vessels") or []:
        by_id[v["vessel_id"]] = v["vessel_name"]
        bc = v.get("boundary_conditions") or {}
        if "inlet" in bc:
            out.append((bc["inlet"], v["vessel_name"]))
        if "outlet" in bc:
            out.append((v["vessel_name"], bc["outlet"]))
    for j in cfg.get("junctions") or []:
        name = j["junction_name"]
        if "inlet_vessels" in j and "outlet_vessels" in j:
            out += [(by_id[i], name) for i in j["inlet_vessels"]] + [(name, by_id[i]) for i in j["outlet_vessels"]]
        elif "inlet_blocks" in j and "outlet_blocks" in j:
            out += [(b, name) for b in j["inlet_blocks"]] + [(name, b) for b in j["outlet_blocks"]]
    for b in cfg.get("closed_loop_blocks") or []:
        if b.get("closed_loop_type") == "ClosedLoopHeartAndPulmonary":
            out.append((HEART_IN, HEART))
            out += [(bc["bc_name"], HEART_IN) for bc in cfg.get("boundary_conditions") or []
                    if bc.get("bc_type") == "ClosedLoopRCR" and (bc.get("bc_values") or {}).get("closed_loop_outlet")]
            out.append((HEART, HEART_OUT))
            out += [(HEART_OUT, o) for o in b.get("outlet_blocks") or []]
    for v in cfg.get("valves") or []:
        prm = v.get("params") or {}
        out += [(prm.get("upstream_block"), v["name"]), (v["name"], prm.get("downstream_block"))]
    return out


def internal_variables(cfg):
    """[(their variable name, our column, kind P/Q/V/1, offset)] of the blocks' internal
    variables in their block order (vessels, boundary conditions, junctions, closed loop,
    valves, chambers).  ``offset``: 'start' when theirs is relative to its value at t = 0."""
    out = []
    for b in cfg.get("boundary_conditions") or []:
        name, typ, eid = b["bc_name"], b.get("bc_type"), ident(b["bc_name"])
        if typ == "RCR":  # WindkesselBC.cpp: pressure_c
            out.append((f"pressure_c:{name}", f"{eid}.P_c", "P", None))
        elif typ == "ClosedLoopRCR":  # ClosedLoopRCRBC.cpp: P_c
            out.append((f"P_c:{name}", f"{eid}.P_c", "P", None))
        elif typ == "CORONARY":  # OpenLoopCoronaryBC.cpp: volume_im, Cc (P_im - Pim) minus its start
            out.append((f"volume_im:{name}", f"{eid}.V_im", "V", "start"))
    for b in cfg.get("closed_loop_blocks") or []:
        if b.get("closed_loop_type") == "ClosedLoopHeartAndPulmonary":
            out += [(f"{v}:{HEART}", f"{HEART}.{v}", v[0], None) for v in HEART_VARIABLES]
    for b in cfg.get("valves") or []:
        if b.get("type") == "ValveTanh":
            out.append((f"valve_status:{b['name']}", f"{ident(b['name'])}.status", "1", None))
    for b in cfg.get("chambers") or []:
        if b.get("type") in ("ChamberElastanceInductor", "LinearElastanceChamber"):
            out.append((f"Vc:{b['name']}", f"V({ident(b['name'])})", "V", None))
    return out


def variables(cfg, model):
    """[(their name, our column, kind, offset)] of every variable they write (per-variable layout)."""
    out = []
    for a, b in connections(cfg):
        for kind, what in (("Q", "flow"), ("P", "pressure")):
            name = f"{what}:{a}:{b}"
            if name not in model.columns:
                raise HemocircuitError(f"svZeroDSolver output: no hemocircuit column for their variable {name!r} "
                                       f"(model {model.name})")
            out.append((name, model.columns[name], kind, None))
    return out + internal_variables(cfg)


def vessel_blocks(cfg, model):
    """[(block name, {flow_in: column, ...})] of the per-block layout, in their block order."""
    out = []
    conns = connections(cfg)
    for v in cfg.get("vessels") or []:
        if v.get("zero_d_element_type") in VESSEL_OUTPUT_TYPES:
            n = v["vessel_name"]
            out.append((n, {c: model.columns[f"{n}:{c}"] for c in VESSEL_COLUMNS}))
    for kind, typ_key in (("valves", "type"), ("chambers", "type")):
        for b in cfg.get(kind) or []:
            if b.get(typ_key) not in VESSEL_OUTPUT_TYPES:
                continue
            n = b["name"]
            up = next(a for a, d in conns if d == n)
            down = next(d for a, d in conns if a == n)
            out.append((n, {"flow_in": model.columns[f"flow:{up}:{n}"], "flow_out": model.columns[f"flow:{n}:{down}"],
                            "pressure_in": model.columns[f"pressure:{up}:{n}"],
                            "pressure_out": model.columns[f"pressure:{n}:{down}"]}))
    return out


def written_steps(model):
    """Step numbers i of the rows they write and those rows' times [s] (their convention)."""
    N, n = model.points, model.n_cycles
    interval = model.sim.get("output_interval", 1)
    if isinstance(interval, bool) or not isinstance(interval, int) or interval < 1:
        raise HemocircuitError(f"simulation_parameters: output_interval = {interval}; it must be >= 1")
    steps = (N - 1) * n + 1
    dt = model.period / (N - 1)
    first = 0 if model.sim.get("output_all_cycles") else (N - 1) * (n - 1)
    i = np.arange(first, steps, interval)
    times = (i - first) * dt
    extra = int(model.sim.get("_extra_cycles", 0))
    if extra and model.sim.get("output_all_cycles"):
        # their extra-cycle loop (run_integration): its output counter goes on, its step
        # counter restarts, so step g of it is written when g % interval == 0, at time
        # ((g - steps) mod (N-1) + 1) dt
        g = np.arange(steps, steps + extra * (N - 1))
        g = g[g % interval == 0]
        i = np.concatenate([i, g])
        times = np.concatenate([times, ((g - steps) % (N - 1) + 1) * dt])
    return i, times


def unit_factors(model):
    """{kind: factor from our unit to theirs} for P (mmHg), Q (mL/s), V (mL); '1' dimensionless."""
    from ..units import parse_quantity

    f = {k: parse_quantity(f"1 {u}", model.units[k]) for k, u in (("P", "mmHg"), ("Q", "mL/s"), ("V", "mL"))}
    f["1"] = 1.0
    return f


def _columns(model, circuit, t, x):
    cols = dict(circuit.outputs(t, x))
    if model.netlist.get("derived"):  # their flows that include a reduced capacitor's
        from ..derived import evaluate_derived

        cols.update(evaluate_derived(model.netlist["derived"], cols))
    return cols


def _rates(model, circuit, t, x, t_start):
    """{column: d/dt} along the trajectory at (t, x) rows: left second-order difference along
    the tangent f(t-, x) (right-sided where the left side would leave the run)."""
    h = 1e-7 * max(model.period, 1e-300)
    side = np.where(t - 2 * h >= t_start, -1.0, 1.0)  # -1: left (the default)
    f = (np.array([circuit.rhs(float(tt + 0.5 * s * h), xx) for tt, xx, s in zip(t, x, side)]).reshape(x.shape)
         if circuit.nx else np.zeros_like(x))
    g = [_columns(model, circuit, t + k * s * h, x + (k * h * side)[:, None] * f)
         for k, s in ((0, 0), (1, side), (2, side))]
    return {k: side * (-3 * g[0][k] + 4 * g[1][k] - g[2][k]) / (2 * h) for k in g[0]}


def ran_model(model, res):
    """``model`` with the cycles the run ``res`` of :func:`simulate_svzerod` made (their rule's
    count, their extra cycles: ``res.metadata['svzerod_run']``), whose rows are written."""
    run = res.metadata.get("svzerod_run") if hasattr(res, "metadata") else None
    if not run:
        return model
    return model.with_sim(number_of_cardiac_cycles=run["cycles"], _extra_cycles=run["extra_cycles"])


def result_table(model, circuit, res, cfg):
    """Their DataFrame as {column: list} (row order theirs) from our run ``res`` (on their
    step grid from t = 0; the cycles it made, :func:`ran_model`)."""
    model = ran_model(model, res)
    steps, t_rows = written_steps(model)
    dt = model.period / (model.points - 1)
    k = np.rint(np.asarray(res.t) / dt).astype(int)
    where = {int(s): j for j, s in enumerate(k)}
    missing = [int(s) for s in steps if int(s) not in where]
    if missing:
        raise HemocircuitError(f"svZeroDSolver output: the run has no point at step {missing[0]} "
                               f"(t = {missing[0] * dt:g} s); run it on their grid (dt = T/(N-1))")
    rows = np.array([where[int(s)] for s in steps])
    x = np.asarray(res.x)[rows]
    t = np.asarray(res.t)[rows]
    cols = _columns(model, circuit, t, x)
    deriv = bool(model.sim.get("output_derivative"))
    rates = _rates(model, circuit, t, x, float(res.t[0])) if deriv else {}
    start = _columns(model, circuit, np.asarray(res.t[:1]), np.asarray(res.x[:1])) if model.sim.get(
        "output_variable_based") else {}
    fac = unit_factors(model)
    mean = bool(model.sim.get("output_mean_only"))
    table = {}

    def emit(name, values):
        n = 1 if mean else len(t_rows)
        table.setdefault("name", []).extend([name] * n)
        table.setdefault("time", []).extend([None] * n if mean else [float(v) for v in t_rows])
        for key, v in values.items():
            v = np.asarray(v, float)
            if not np.all(np.isfinite(v)):
                raise HemocircuitError(f"svZeroDSolver output: {name} {key} is not finite")
            table.setdefault(key, []).extend([float(v.mean())] if mean else [float(y) for y in v])

    if model.sim.get("output_variable_based"):
        for name, col, kind, offset in variables(cfg, model):
            if col not in cols:
                raise HemocircuitError(f"svZeroDSolver output: no hemocircuit column {col!r} for their variable "
                                       f"{name!r} (model {model.name})")
            y = cols[col] - (start[col][0] if offset == "start" else 0.0)
            vals = {"y": y * fac[kind]}
            if deriv:
                vals["ydot"] = rates[col] * fac[kind]
            emit(name, vals)
    else:
        for name, m in vessel_blocks(cfg, model):
            vals = {c: cols[m[c]] * fac["Q" if c.startswith("flow") else "P"] for c in VESSEL_COLUMNS}
            if deriv:
                vals.update({f"d_{c}": rates[m[c]] * fac["Q" if c.startswith("flow") else "P"]
                             for c in VESSEL_COLUMNS})
            emit(name, vals)
    return table


def to_pandas_json(table) -> str:
    """pandas ``DataFrame.to_json()`` layout (orient 'columns'): {column: {row: value}}."""
    return json.dumps({key: {str(i): v for i, v in enumerate(vals)} for key, vals in table.items()},
                      allow_nan=False, separators=(",", ":"))


def _circuits(model, sets=None):
    """(circuit, its time-averaged variant) of an imported model, ``sets`` applied to both."""
    import tempfile

    from ..circuit import load
    from .importer import write_netlist

    with tempfile.TemporaryDirectory(prefix="hemocircuit_svz_") as d:
        write_netlist(model.netlist, os.path.join(d, "m.yaml"))
        write_netlist(model.mean_netlist, os.path.join(d, "mean.yaml"))
        c, cm = load(os.path.join(d, "m.yaml")), load(os.path.join(d, "mean.yaml"))
    if sets:
        c, cm = c.with_values(dict(sets)), cm.with_values(dict(sets))
    return c, cm


def start_state(model, circuit, start="operating-point", sets=None, mean_circuit=None):
    """The state their run starts from, for ``circuit`` (the model's, maybe with ``sets``):
    'operating-point' (the default: the true steady state of the circuit with the time series
    at their means, the states their initial_condition gives overridden, as the conformance
    runner) or 'their-steady' (their steady_initial procedure,
    :mod:`hemocircuit.svzerod.steady_initial`).  A closed loop, or steady_initial false,
    starts from their initial_condition (0 where not given), as theirs."""
    from ..analyses.op import steady_state
    from ..ic import apply_ic

    if start not in ("operating-point", "their-steady"):
        raise HemocircuitError(f"start {start!r}: choose 'operating-point' or 'their-steady'")
    if model.closed or not model.sim.get("steady_initial", True):
        from .steady_initial import their_initial

        return apply_ic(circuit, np.zeros(circuit.nx), their_initial(model, circuit))
    cm = mean_circuit if mean_circuit is not None else _circuits(model, sets)[1]
    if start == "their-steady":
        from .steady_initial import their_steady_initial

        return their_steady_initial(model, cm)
    return apply_ic(circuit, steady_state(cm), model.initial_given)


def simulate_svzerod(model, sets=None, rtol=None, start="operating-point", cfg=None):
    """(circuit, result) of a run with their semantics: t = 0 .. n T on their step grid, from
    :func:`start_state` ``start``.  ``sets``: {ID.PARAM: value} changed in the circuit and in
    its time-averaged variant (``--set``).  ``rtol``: the integrator's, by default the
    conformance runner's for the model (tolerances.run_tolerances).  With ``use_cycle_to_cycle_error``,
    no RCR and ``cfg`` (their configuration, for their vessel caps) the run goes on one cycle
    at a time until their criterion holds (:func:`their_extra_cycles`)."""
    from ..analyses.transient import TransientResult, simulate
    from .tolerances import run_tolerances

    c, cm = _circuits(model, sets)
    model = their_cycles(model, c)  # a copy: the caller's model keeps its settings
    x0 = start_state(model, c, start, mean_circuit=cm)
    dt = model.period / (model.points - 1)
    if c.nx == 0:  # no states: the outputs are algebraic functions of time
        t = np.arange(0, (model.points - 1) * model.n_cycles + 1) * dt
        x = np.zeros((t.size, 0))
        res = TransientResult(t, x, c.outputs(t, x), c.column_units(), c.state_names)
        res.metadata["svzerod_run"] = {"cycles": model.n_cycles, "extra_cycles": 0}
        return c, res
    atol = None
    if rtol is None:  # the conformance runner's: drift tolerances for a run that keeps its start
        rtol, atol = run_tolerances(model, cm, c)
    res = simulate(c, model.n_cycles * model.period, dt=dt, x0=x0, rtol=rtol, atol=atol, progress=False)
    extra = 0
    if cfg is not None and runs_extra_cycles(model, c):
        res, extra = their_extra_cycles(model, cfg, c, res, rtol, atol)
    res.metadata["svzerod_run"] = {"cycles": model.n_cycles, "extra_cycles": extra}
    return c, res


def runs_extra_cycles(model, circuit):
    """True when their solver runs extra cycles until its criterion holds: with
    ``use_cycle_to_cycle_error`` and no RCR boundary condition (with one it runs the count of
    :func:`their_cycles` instead), and states to integrate."""
    from .cycles import rcr_time_constants

    return bool(model.sim.get("use_cycle_to_cycle_error")) and circuit.nx > 0 and not rcr_time_constants(circuit)


def their_extra_cycles(model, cfg, c, res, rtol=None, atol=None, max_extra=1000):
    """Their extra cycles without an RCR (Solver.cpp run_integration): while their criterion
    fails on the last two cycles (cycles.cycle_means, cycle_errors at their vessel caps), one
    more cycle from the state reached.  Returns (the run extended by them, t continuing; how
    many), so that :func:`written_steps` of ``model.with_sim(_extra_cycles=...)`` writes their
    rows of them (with output_all_cycles: times restarting at dt in each, as theirs)."""
    from ..analyses.transient import TransientResult, simulate
    from .cycles import cycle_errors, cycle_means, their_tolerance, vessel_caps

    T, N, n = model.period, model.points, model.n_cycles
    dt = T / (N - 1)
    tol = their_tolerance(model.sim)
    quantities = [q for _, fq, pq in vessel_caps(cfg, model) for q in (fq, pq)]
    t0 = np.asarray(res.t)
    k = np.rint(t0 / dt).astype(int)
    _, first = np.unique(k, return_index=True)  # one row per step of their grid
    first = first[np.abs(t0[first] - k[first] * dt) < 1e-9 * T]
    ts, xs = [t0[first]], [np.asarray(res.x)[first]]
    cols = {q: [np.asarray(res.columns[q])[first]] for q in quantities}
    extra = 0
    while True:
        tail = [np.concatenate(cols[q])[-(2 * (N - 1) + 1):] for q in quantities]
        if all(v.size == 2 * (N - 1) + 1 for v in tail) and all(
                cycle_errors(cycle_means(v, N))[0, -1] <= tol for v in tail):
            break
        if extra >= max_extra:
            raise HemocircuitError(f"{model.name}: their cycle-to-cycle criterion not met in {max_extra} extra cycles")
        check_points(n + extra + 1, N, what=f"{model.name}: use_cycle_to_cycle_error: {extra + 1} extra cycle(s) "
                                             f"after {n}")
        t_a = (n + extra) * T
        r = simulate(c, t_a + T, t0=t_a, dt=dt, x0=xs[-1][-1], rtol=rtol, atol=atol, progress=False)
        kr = np.rint(np.asarray(r.t) / dt).astype(int)
        _, fr = np.unique(kr, return_index=True)
        fr = fr[kr[fr] > kr[0]]
        ts.append(np.asarray(r.t)[fr])
        xs.append(np.asarray(r.x)[fr])
        for q in quantities:
            cols[q].append(np.asarray(r.columns[q])[fr])
        extra += 1
    if not extra:
        return res, 0
    t, x = np.concatenate(ts), np.concatenate(xs)
    out = TransientResult(t, x, c.outputs(t, x), c.column_units(), c.state_names, stats=res.stats)
    out.metadata.update({k: v for k, v in res.metadata.items() if k != "solver"})
    return out, extra


def their_cycles(model, circuit):
    """With ``use_cycle_to_cycle_error`` and an RCR boundary condition their solver replaces
    the number of cycles by ceil(-tau_max/T ln tol) (Solver.cpp constructor, their eq. 21):
    returns ``model`` with that count (a copy; ``model`` itself unchanged), so the written
    rows are theirs.  Without an RCR they run extra cycles until their criterion holds
    (:func:`their_extra_cycles`; their rows of them only with output_all_cycles)."""
    from .cycles import pfaller_cycles, rcr_time_constants, their_tolerance

    if model.sim.get("use_cycle_to_cycle_error"):
        n = pfaller_cycles(rcr_time_constants(circuit), model.period, their_tolerance(model.sim))
        if n is not None:
            check_points(n, model.points, what=f"{model.name}: use_cycle_to_cycle_error: their cycle count "
                                               "ceil(-tau/T ln tol) of the RCR's time constant tau")
            return model.with_sim(number_of_cardiac_cycles=n)
    return model


def write_svzerod_output(path, model, circuit, res, cfg=None):
    """Write ``res`` (a run on their grid from t = 0, :func:`simulate_svzerod`) to ``path`` in
    their result layout, atomically; returns the path."""
    from ..io import atomic_write

    if cfg is None:
        raise HemocircuitError("write_svzerod_output needs the model's svZeroDSolver configuration (cfg)")
    return atomic_write(path, to_pandas_json(result_table(model, circuit, res, cfg)))


def svzerod_output(model_path, out_path, rtol=None, start="operating-point", units=None, sets=None):
    """Import ``model_path`` (their JSON), run it with their semantics and write their result
    layout to ``out_path``.  Returns (the model with the cycles the run made, circuit, result)."""
    from .importer import import_svzerod

    cfg, _ = read_model(model_path)  # read once, under the input policy
    model = import_svzerod(cfg, units=units, name=os.path.splitext(os.path.basename(str(model_path)))[0],
                           source=str(model_path))
    c, res = simulate_svzerod(model, sets=sets, rtol=rtol, start=start, cfg=cfg)
    write_svzerod_output(out_path, model, c, res, cfg)
    return ran_model(model, res), c, res
