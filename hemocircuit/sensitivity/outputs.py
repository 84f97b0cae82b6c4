"""The quantity a sensitivity analysis measures: an *objective* evaluated for a whole batch of
parameter sets at once.

Output kinds (the spec's ``output:`` mapping, one key):

  op:        {column: art.r | [cols], at: [{Pup.value: 40 cmH2O, ...}, ...]}
             operating points at each ``at`` setting (structural options allowed), one batched
             solve of all parameter sets per setting
  dc:        {column, sweep: {Pup.value: "20:140:20 cmH2O", Pdown.value: "20:140:20 cmH2O"}}
             the points of a DC sweep (several paths swept together), solved as batched op
  tran:      {column, protocol: kuo91_A.yaml, times: "0:450:5 s", rtol: 1e-6}
             a protocol transient at the given times: batched operating point, then the batched
             integrator segment by segment between the protocol's events
  freq:      {column, frequency: 0.1 Hz, measure: gain | phase | rel_amplitude, step: 10, amplitude: 10}
  envelope:  {column, measure: amplitude | min | max | mean | period, t_end: 1000 s, dt: 0.1 s}
             (both through their analyses, which run the batch on execution.py's parallel runner)
  fit_error: FITSPEC.yaml   the rms error of a fit spec (hemocircuit.fitting.load_problem)

Every objective maps {key: (B,) array} -> (Y (B, m), [error or None] * B): a member whose model
fails, or gives a non-finite output, is reported with its reason and excluded, never fatal.
Every parameter change goes through :func:`_with_values`.
"""
from __future__ import annotations

import functools
import warnings

import numpy as np

from ..errors import FitSpecError, HemocircuitError, NetlistError
from ..execution import default_workers, run_chunks, split
from ..spec_inputs import check_limit, number, shown, unknown_keys
from ..units import UnitError, parse_quantity


# --------------------------------------------------------------------------- changes ----
def _with_values(circuit, mapping):
    """``circuit`` with parameters changed: {ID.PARAM: number | quantity string | array of B}.

    The one place where this package changes parameters (Circuit.with_values).  Arrays of
    length B > 1 on a single circuit make a batch of B members."""
    sizes = {np.size(v) for v in mapping.values() if not isinstance(v, str) and np.ndim(v) > 0}
    if len(sizes) > 1:
        raise HemocircuitError(f"parameter arrays of different lengths {sorted(sizes)}")
    B = sizes.pop() if sizes else circuit.B
    if circuit.B != B and circuit.B != 1:
        raise HemocircuitError(f"{B} values for a batch of {circuit.B} members")
    c = circuit if circuit.B == B else circuit.batch(B)
    return c.with_values({k: (np.asarray(v, dtype=float) if not isinstance(v, str) and np.ndim(v) > 0 else v)
                          for k, v in mapping.items()})


# ------------------------------------------------------------------------ objectives ----
class Objective:
    """Base: ``labels``/``units`` of the m output components, ``evaluate_batch``."""
    labels: list
    units: list
    parallel = True  # chunks may run in worker processes

    def parameter_info(self, path, event=None) -> dict:
        return {}

    def default_parameters(self):
        return []

    def check_value(self, path, value):
        """None if ``path`` may take ``value``, else the reason."""
        return None

    def evaluate_batch(self, values):  # -> (Y (B, m), errors)
        raise NotImplementedError


class FunctionObjective(Objective):
    """A plain function of the values (tests, user code): fn({key: (B,)}) -> (B,) or (B, m)."""

    def __init__(self, fn, labels=("f",), units=None, info=None):
        self.fn, self.labels = fn, list(labels)
        self.units = list(units or [""] * len(self.labels))
        self.info = info or {}

    def parameter_info(self, path, event=None):
        return dict(self.info.get(path, {}))

    def evaluate_batch(self, values):
        Y = np.asarray(self.fn(values), dtype=float)
        B = len(next(iter(values.values())))
        Y = Y.reshape(B, -1)
        return Y, _nonfinite(Y, [None] * B)


def _nonfinite(Y, errors):
    bad = ~np.all(np.isfinite(Y), axis=1)
    return [e if e is not None or not b else "non-finite output" for e, b in zip(errors, bad)]


class CircuitObjective(Objective):
    """Shared by the circuit outputs: parameter units and centres from the circuit."""

    def check_value(self, path, value):
        try:
            _with_values(self.circuit, {path: float(value)})
        except HemocircuitError as exc:
            return getattr(exc, "bare_message", str(exc))
        return None

    def __init__(self, circuit, columns, events=()):
        self.circuit = circuit
        self.columns = [columns] if isinstance(columns, str) else list(columns or [])
        if not self.columns:
            raise NetlistError("the output needs 'column' (an output column such as art.r)")
        units = circuit.column_units()
        for col in self.columns:
            if col not in units:
                import difflib
                near = difflib.get_close_matches(col, list(units), n=3, cutoff=0.5)
                raise NetlistError(f"unknown output column {col!r}" + (f"; did you mean {near}?" if near else ""))
        self.col_units = [units[c] for c in self.columns]
        self.events = list(events)

    def parameter_info(self, path, event=None):
        unit = self.circuit.param_unit(path)
        if event is None:
            return {"unit": unit, "centre": self.circuit.parameters.constant(path, "sensitivity")}
        for ev in self.events:
            if abs(ev.at - event) <= 1e-9 * max(1.0, abs(event)) and path in ev.set:
                try:
                    return {"unit": unit, "centre": parse_quantity(ev.set[path], unit, path)}
                except UnitError as exc:
                    raise NetlistError(str(exc)) from None
        raise NetlistError(f"parameter {path} with event {event:g} s: the protocol has no event at {event:g} s "
                           f"that sets {path} (events: {[(e.at, sorted(e.set)) for e in self.events]})")


def _split_settings(circuit, at):
    """An ``at`` mapping -> (structural options, numeric settings)."""
    if not isinstance(at, dict):
        raise NetlistError(f"each 'at' entry must be a mapping ID.PARAM: value (got {at!r})")
    opts = {k: v for k, v in at.items() if circuit.is_option(k)}
    nums = {k: v for k, v in at.items() if k not in opts}
    for k in nums:
        circuit.param_unit(k)  # clear error for a wrong path
    return opts, nums


def operating_points(c):
    """Operating points of every member of batch circuit ``c``: (X (B, nx) with NaN rows,
    {column: (B,)}, [error or None] * B) -- :func:`hemocircuit.analyses.op.operating_points`
    (Newton on the whole batch, the fallbacks only on the members it did not solve)."""
    from ..analyses.op import operating_points as op_points

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return op_points(c)


class OpObjective(CircuitObjective):
    """Output columns at operating points, one batched solve per ``at`` setting."""

    def __init__(self, circuit, columns, at=None):
        super().__init__(circuit, columns)
        at = [{}] if at is None else at
        if isinstance(at, dict):
            at = [at]
        self.at = []
        for a in at:
            opts, nums = _split_settings(circuit, a)
            base = circuit.with_options(opts) if opts else circuit
            self.at.append((base, nums, a))
        self.labels = [f"{col} @ {_describe(a)}" if a else col for _, _, a in self.at for col in self.columns]
        self.units = [u for _ in self.at for u in self.col_units]

    def check_keys(self, keys):
        for _, nums, a in self.at:
            both = set(nums) & set(k.partition("@")[0] for k in keys)
            if both:
                raise NetlistError(f"{sorted(both)} are both varied and set by an 'at' entry ({_describe(a)})")

    def evaluate_batch(self, values):
        B = len(next(iter(values.values())))
        m = len(self.columns)
        Y = np.full((B, len(self.at) * m), np.nan)
        errors = [None] * B
        for j, (base, nums, a) in enumerate(self.at):
            c = _with_values(base, {**nums, **values})
            _, vals, errs = operating_points(c)
            for i, col in enumerate(self.columns):
                if col in vals:
                    Y[:, j * m + i] = vals[col]
            for k, e in enumerate(errs):
                if e is not None and errors[k] is None:
                    errors[k] = f"{e} ({_describe(a)})" if a else e
        return Y, _nonfinite(Y, errors)


def _describe(a):
    return ", ".join(f"{k}={v}" for k, v in a.items())


def dc_points(circuit, sweep):
    """{path: range string or list} (swept together) -> list of ``at`` mappings."""
    from ..analyses.dc import parse_range

    if not isinstance(sweep, dict) or not sweep:
        raise NetlistError("'sweep' must map ID.PARAM to a range, e.g. "
                           "{Pup.value: '20:140:20 cmH2O', Pdown.value: '20:140:20 cmH2O'}")
    cols = {}
    for path, spec in sweep.items():
        unit = circuit.param_unit(path)
        vals = parse_range(spec, unit) if isinstance(spec, str) else np.array(
            [parse_quantity(v, unit, path) for v in spec])
        cols[path] = (vals, unit)
    n = {len(v) for v, _ in cols.values()}
    if len(n) != 1:
        raise NetlistError(f"the swept paths have different numbers of points {sorted(n)}")
    N = n.pop()
    from .. import limits
    if N > limits.limit("SENS_OUTPUTS"):
        raise NetlistError(f"sweep: {N:,} points, more than allowed {limits.how_to_raise('SENS_OUTPUTS')}")
    return [{p: f"{float(v[i])!r} {u}" for p, (v, u) in cols.items()} for i in range(N)]


class TranObjective(CircuitObjective):
    """Output columns of a protocol transient at given times (thesis: Kuo91 A).

    Batched operating point after the protocol's ``initial``, then the batched integrator
    (compiled engine where available) between consecutive events; the event's settings, then
    the members' own values for parameters tied to that event (``event:`` in the spec)."""

    def __init__(self, circuit, protocol, columns, times, rtol=1e-6):
        from ..analyses.dc import parse_range
        from ..protocol import Protocol

        proto = Protocol.load(protocol, circuit) if isinstance(protocol, str) else protocol
        opts = {k: v for k, v in proto.initial.items() if circuit.is_option(k)}
        c0 = circuit.with_options(opts) if opts else circuit
        c0 = _with_values(c0, {k: v for k, v in proto.initial.items() if k not in opts})
        super().__init__(c0, columns, proto.events)
        try:
            t = parse_range(times, "s") if isinstance(times, str) else np.array(
                [parse_quantity(v, "s", "time") for v in times], dtype=float)
        except (UnitError, TypeError) as exc:
            raise NetlistError(f"times {times!r}: {exc}") from None
        if t.size == 0 or np.any(np.diff(t) <= 0) or t[0] < 0:
            raise NetlistError(f"times must be increasing and >= 0 (got {times!r})")
        self.times = t
        self.rtol = float(rtol)
        self.labels = [f"{col} @ t={tt:g} s" for tt in t for col in self.columns]
        self.units = [u for _ in t for u in self.col_units]

    def evaluate_batch(self, values):
        from ..batch_integrator import integrate

        B = len(next(iter(values.values())))
        m, T = len(self.columns), len(self.times)
        Y = np.full((B, T, m), np.nan)
        initial = {k: v for k, v in values.items() if "@" not in k}
        at_event = {}
        for k, v in values.items():
            if "@" in k:
                path, _, t = k.partition("@")
                at_event.setdefault(float(t), {})[path] = v
        c = _with_values(self.circuit, initial)
        if c.B != B:  # only event-bound values vary
            c = c.batch(B)
        X0, _, errors = operating_points(c)
        alive = np.array([e is None for e in errors])
        x = X0
        t_end = self.times[-1]
        evs = [e for e in self.events if 0 < e.at < t_end]
        bounds = [0.0] + [e.at for e in evs] + [t_end]
        for k in range(len(bounds) - 1):
            t_a, t_b = bounds[k], bounds[k + 1]
            if k > 0:
                ev = evs[k - 1]
                c = _with_values(c, ev.set)
                own = {p: v for tt, d in at_event.items() if abs(tt - ev.at) <= 1e-9 * max(1.0, ev.at)
                       for p, v in d.items()}
                if own:
                    c = _with_values(c, own)
            last = k == len(bounds) - 2
            want = (self.times >= t_a) & ((self.times < t_b) | (last & (self.times <= t_b)))
            if t_b <= t_a or not alive.any():
                continue
            idx = np.nonzero(alive)[0]
            sub = c.subset(idx) if len(idx) < c.B else c
            inner = self.times[(self.times > t_a) & (self.times < t_b)]
            grid = np.concatenate([[t_a], inner, [t_b]])
            r = integrate(sub, x[idx], grid, rtol=self.rtol)
            for j, mbr in enumerate(idx):
                if not r.ok[j]:
                    errors[mbr] = f"transient: {r.message[j]}"
                    alive[mbr] = False
            ok = np.asarray(r.ok, bool)
            if want.any() and ok.any():
                sel = np.searchsorted(grid, self.times[want])
                good = idx[ok]
                S = r.x[ok][:, sel, :]  # (n_ok, n_t, nx)
                subc = c.subset(good) if len(good) < c.B else c
                tq = np.tile(self.times[want], len(good))
                try:
                    cols = subc.outputs(tq, S.reshape(-1, S.shape[-1]))
                    for i, col in enumerate(self.columns):
                        Y[good[:, None], np.nonzero(want)[0][None, :], i] = np.asarray(cols[col]).reshape(len(good), -1)
                except HemocircuitError as exc:
                    for mbr in good:
                        errors[mbr] = f"transient outputs: {exc}"
                        alive[mbr] = False
            x = x.copy()
            x[idx[ok]] = r.x[ok][:, -1, :]
        Y = Y.reshape(B, T * m)
        return Y, _nonfinite(Y, errors)


class FitErrorObjective(Objective):
    """The rms error of a fit spec (thesis sec. sensitivity: rms between model radius and the
    Kuo flow and no-flow data), through the fit package's problem interface:
    ``load_problem(netlist, fitspec)``, ``.parameters``, ``.bounds``, ``.rms_error(values)``."""

    def __init__(self, circuit, netlist_path, fit_spec_path, allow_paths=None, named_by=None, key=None):
        from ..fitting import load_problem
        self.circuit = circuit
        # the circuit as given (with --set and --protocol), the fit spec's files in its folders
        self.problem = load_problem(netlist_path or circuit.file, fit_spec_path, circuit=circuit,
                                    allow_paths=allow_paths, named_by=named_by, key=key)
        self.labels, self.units = ["rms error"], [getattr(self.problem, "rms_unit", "")]
        self._bounds = _bounds_map(self.problem)

    def default_parameters(self):
        from .spec import Parameter
        return [Parameter(p, p) for p in self.problem.parameters]

    check_value = CircuitObjective.check_value

    def parameter_info(self, path, event=None):
        if event is not None:
            raise NetlistError(f"parameter {path}: 'event' applies to a tran output only")
        info = {"unit": self.circuit.param_unit(path), "centre": self.circuit.parameters.constant(path, "sensitivity")}
        if path in self._bounds:
            info["lower"], info["upper"] = self._bounds[path]
        return info

    def evaluate_batch(self, values):
        B = len(next(iter(values.values())))
        try:
            y = np.asarray(self.problem.rms_error(values), dtype=float).reshape(B, 1)
        except HemocircuitError as exc:
            return np.full((B, 1), np.nan), [f"fit error: {exc}"] * B
        return y, _nonfinite(y, [None] * B)


def _bounds_map(problem):
    """problem.bounds as {path: (lower, upper)}: accepts a mapping, a (lower, upper) pair of
    sequences aligned with problem.parameters, or a list of pairs."""
    b = problem.bounds
    params = list(problem.parameters)
    if isinstance(b, dict):
        return {k: (float(v[0]), float(v[1])) for k, v in b.items()}
    b = np.asarray(b, dtype=float)
    if b.shape == (2, len(params)):
        return {p: (b[0, i], b[1, i]) for i, p in enumerate(params)}
    if b.shape == (len(params), 2):
        return {p: (b[i, 0], b[i, 1]) for i, p in enumerate(params)}
    raise HemocircuitError(f"fit problem bounds of shape {b.shape} for {len(params)} parameters")


class AnalysisObjective(CircuitObjective):
    """freq / envelope: a measure per member from the analysis's own batched, parallel run."""
    parallel = False  # the analysis parallelises itself

    def __init__(self, circuit, kind, cfg, scheduler=None, workers=None):
        super().__init__(circuit, cfg.get("column"))
        self.kind, self.cfg = kind, cfg
        self.scheduler, self.workers = scheduler, workers
        self.measure = cfg.get("measure", "gain" if kind == "freq" else "amplitude")
        allowed = {"freq": ("rel_gain", "gain", "phase", "rel_amplitude"),
                   "envelope": ("amplitude", "min", "max", "mean", "period")}[kind]
        if self.measure not in allowed:
            raise NetlistError(f"{kind} output: measure {self.measure!r}; choose one of {list(allowed)}")
        self.labels = [f"{self.measure} of {c}" for c in self.columns]
        self.units = [{"phase": "deg", "period": "s", "rel_gain": "1", "rel_amplitude": "1"}.get(self.measure, u)
                      for u in self.col_units]

    def evaluate_batch(self, values):
        B = len(next(iter(values.values())))
        members = [{k: float(v[i]) for k, v in values.items()} for i in range(B)]
        cfg = self.cfg
        if self.kind == "freq":  # one frequency: row i is member i
            from ..analyses.freq import frequency_response
            f = parse_quantity(cfg.get("frequency", "0.1 Hz"), "Hz", "frequency")
            res = frequency_response(self.circuit, [f], self.columns, cfg.get("input"),
                                     float(cfg.get("step", 10)) / 100, float(cfg.get("amplitude", 10)) / 100,
                                     members=members, scheduler=self.scheduler, workers=self.workers)
            if self.measure == "rel_amplitude":
                names = [f"rel_amplitude({c})" for c in self.columns]
            else:
                names = [f"{self.measure}({c}/{res.input})" for c in self.columns]
            self.units = [res.units.get(n, u) for n, u in zip(names, self.units)]
            Y = np.column_stack([res[n] for n in names])
        else:
            from ..analyses.envelope import envelope
            res = envelope(self.circuit, None, None, self.columns,
                           t_end=parse_quantity(cfg.get("t_end", "1000 s"), "s", "t_end"),
                           dt=parse_quantity(cfg.get("dt", "0.1 s"), "s", "dt"), members=members,
                           scheduler=self.scheduler, workers=self.workers)
            if self.measure == "amplitude":
                Y = np.column_stack([res[f"max({c})"] - res[f"min({c})"] for c in self.columns])
            elif self.measure == "period":
                Y = np.column_stack([res["period"]] * len(self.columns))
            else:
                Y = np.column_stack([res[f"{self.measure}({c})"] for c in self.columns])
        Y = np.array(Y, dtype=float)
        errors = [e or None for e in res["error"]]
        Y[[e is not None for e in errors]] = np.nan
        return Y, _nonfinite(Y, errors)


def make_objective(spec, circuit=None, netlist_path=None, scheduler=None, workers=None, allow_paths=None):
    """The objective named by ``spec.output`` for ``circuit``.  Files the output names (a tran
    ``protocol``, a ``fit_error`` spec) are read relative to the spec, inside its allowed
    folders (``spec.access``); ``allow_paths``: more folders for the fit spec's own files."""
    kind, cfg = next(iter(spec.output.items()))
    key = f"output.{kind}"

    def err(msg, k=None):
        return FitSpecError(msg, file=spec.file, key=f"{key}.{k}" if k else key)

    if kind == "function":
        raise err("output 'function' is for the Python API: pass objective=FunctionObjective(...)")
    if kind == "fit_error":
        if not isinstance(cfg, str):
            raise err("give the fit spec's path (fit_error: fit.yaml)")
        path = spec.path_of(cfg, "fit spec", key)
        return FitErrorObjective(circuit, netlist_path, path, allow_paths, spec.file, key)
    if not isinstance(cfg, dict):
        raise err(f"expected a mapping of settings, got {shown(cfg)}")
    allowed = {"op": {"column", "at"}, "dc": {"column", "sweep"}, "tran": {"column", "protocol", "times", "rtol"},
               "freq": {"column", "frequency", "measure", "input", "step", "amplitude"},
               "envelope": {"column", "measure", "t_end", "dt"}}[kind]
    unknown_keys(cfg, allowed, spec.file, key, "setting(s)")
    cfg = _checked_settings(kind, cfg, spec, key, err)
    try:
        if kind == "op":
            obj = OpObjective(circuit, cfg.get("column"), cfg.get("at"))
        elif kind == "dc":
            obj = OpObjective(circuit, cfg.get("column"), dc_points(circuit, cfg.get("sweep")))
        elif kind == "tran":
            if "protocol" not in cfg or "times" not in cfg:
                raise err("output tran needs 'protocol' (a protocol YAML) and 'times' (e.g. '0:450:5 s')")
            obj = TranObjective(circuit, spec.path_of(cfg["protocol"], "protocol file", f"{key}.protocol"),
                                cfg.get("column"), cfg["times"], cfg.get("rtol", 1e-6))
        else:
            obj = AnalysisObjective(circuit, kind, cfg, scheduler, workers)
    except FitSpecError:
        raise
    except NetlistError as exc:
        msg = exc.bare_message if not exc.file or exc.file == spec.file else str(exc)
        raise err(msg[:1000]) from None
    check_limit(len(obj.labels), "SENS_OUTPUTS", spec.file, key, "output components (columns x settings x times)")
    for i, p in enumerate(spec.parameters):
        if p.event is not None and kind != "tran":
            raise FitSpecError(f"parameter {shown(p.name)}: 'event' applies to a tran output only", file=spec.file,
                               key=f"parameters[{i}].event")
    if isinstance(obj, OpObjective):
        try:
            obj.check_keys([p.key for p in spec.parameters] + [t.path for t in spec.ties])
        except NetlistError as exc:
            raise err(exc.bare_message) from None
    return obj


def _checked_settings(kind, cfg, spec, key, err):
    """The output's settings checked for their types and ranges (before any model run)."""
    cfg = dict(cfg)
    col = cfg.get("column")
    cols = col if isinstance(col, list) else [col]
    if col is None or not cols or not all(isinstance(c, str) and c.strip() and len(c) <= 200 for c in cols):
        raise err(f"'column' must be an output column (e.g. art.r) or a list of them, got {shown(col)}", "column")
    if kind == "op":
        at = cfg.get("at")
        if at is not None and not (isinstance(at, dict) or (isinstance(at, list) and at
                                                            and all(isinstance(a, dict) for a in at))):
            raise err("'at' must be a mapping {ID.PARAM: value} or a non-empty list of them, got " + shown(at), "at")
    elif kind == "dc":
        sweep = cfg.get("sweep")
        if not isinstance(sweep, dict) or not sweep or not all(
                isinstance(k, str) and (isinstance(v, str) or (isinstance(v, list) and v)) for k, v in sweep.items()):
            raise err("'sweep' must map ID.PARAM to a range or a list of values, e.g. "
                      "{Pup.value: '20:140:20 cmH2O', Pdown.value: '20:140:20 cmH2O'}", "sweep")
    elif kind == "tran":
        times = cfg.get("times")
        if not (isinstance(times, str) or (isinstance(times, list) and times and all(
                isinstance(t, (str, int, float)) and not isinstance(t, bool) for t in times))):
            raise err(f"'times' must be a range ('0:450:5 s') or a list of times, got {shown(times)}", "times")
        if isinstance(times, list):
            check_limit(len(times), "SENS_OUTPUTS", spec.file, f"{key}.times", "times")
        cfg["rtol"] = number(cfg.get("rtol", 1e-6), spec.file, f"{key}.rtol", lo=0.0, hi=0.1, hi_open=False,
                             what="a relative tolerance (e.g. 1e-6)")
    elif kind == "freq":
        f = _quantity(cfg.get("frequency", "0.1 Hz"), "Hz", spec, f"{key}.frequency")
        if not f > 0:
            raise err(f"the frequency must be > 0, got {f:g} Hz", "frequency")
        for k, default in (("step", 10), ("amplitude", 10)):
            cfg[k] = number(cfg.get(k, default), spec.file, f"{key}.{k}", lo=0.0, hi=100.0, hi_open=False,
                            what="a percentage (e.g. 10)")
        if cfg.get("input") is not None and not isinstance(cfg["input"], str):
            raise err(f"'input' must be a source id or ID.PARAM, got {shown(cfg['input'])}", "input")
    elif kind == "envelope":
        t_end = _quantity(cfg.get("t_end", "1000 s"), "s", spec, f"{key}.t_end")
        dt = _quantity(cfg.get("dt", "0.1 s"), "s", spec, f"{key}.dt")
        if not (t_end > 0 and dt > 0):
            raise err(f"t_end and dt must be > 0, got {t_end:g} s and {dt:g} s", "t_end" if not t_end > 0 else "dt")
        check_limit(int(min(t_end / dt, 1e18)), "SENS_TIME_POINTS", spec.file, f"{key}.dt",
                    "time points of each run (t_end / dt)")
    if kind in ("freq", "envelope") and not isinstance(cfg.get("measure", ""), str):
        raise err(f"'measure' must be a name, got {shown(cfg['measure'])}", "measure")
    return cfg


def _quantity(value, unit, spec, key):
    """A quantity of the spec in ``unit``, finite."""
    if isinstance(value, bool) or not isinstance(value, (str, int, float)):
        raise FitSpecError(f"expected a quantity in {unit}, got {shown(value)}", file=spec.file, key=key)
    try:
        v = parse_quantity(value, unit, key)
    except UnitError as exc:
        raise FitSpecError(str(exc)[:300], file=spec.file, key=key) from None
    if not np.isfinite(v):
        raise FitSpecError(f"expected a finite quantity in {unit}, got {shown(value)}", file=spec.file, key=key)
    return v


# ------------------------------------------------------------------------ the runner ----
class _Members(list):
    """A chunk: member indices (its length is the number of model runs, for the progress bar)
    and their values."""
    values: dict


def _run_chunk(objective, chunk):
    return objective.evaluate_batch(chunk.values)


def evaluate(objective, values, scheduler=None, workers=None, progress=False, max_chunk=500):
    """Evaluate ``objective`` for every member of ``values`` ({key: (B,)}): chunks of at most
    ``max_chunk`` members, on execution.py's runner (worker processes unless 'serial').

    Returns (Y (B, m), errors: [str or None] * B)."""
    B = len(next(iter(values.values())))
    serial = scheduler == "serial" or not objective.parallel
    n_workers = 1 if serial else max(1, min(workers or default_workers(), B))  # no idle workers
    n_chunks = max(n_workers, -(-B // max_chunk))
    chunks = []
    for idx in split(list(range(B)), n_chunks):
        ch = _Members(idx)
        ch.values = {k: np.asarray(v)[idx] for k, v in values.items()}
        chunks.append(ch)
    fn = functools.partial(_run_chunk, objective)
    # the bar counts model evaluations (parameter sets), not chunks
    results = run_chunks(fn, chunks, scheduler="serial" if serial else scheduler, workers=n_workers,
                         progress=progress, desc="model evaluations", sizes=[len(ch) for ch in chunks])
    Y = np.full((B, len(objective.labels)), np.nan)
    errors = [None] * B
    for ch, (y, e) in zip(chunks, results):
        Y[ch] = y
        for i, err in zip(ch, e):
            errors[i] = err
    return Y, errors
