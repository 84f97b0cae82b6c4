"""A fit problem: a circuit, the parameters to estimate and the datasets they are fitted to.

    from hemocircuit.fitting import load_problem
    problem = load_problem("netlists/isolated_arteriole.yaml", "examples/fitting/kuo91_1_passive.yaml")
    problem.parameters            # ['art.q1', 'art.q2', ...]  (ID.PARAM or ID.PARAM@TIME)
    problem.bounds                # (lower, upper) arrays in the parameters' declared units
    problem.residuals(values)     # {path: (B,) values} -> (B, n_residuals), one batched evaluation
    problem.rms_error(values)     # -> (B,) the thesis's rms error (sum over datasets of each rms)

Residual of data row i of dataset d: ``sqrt(w_d) (model_i - data_i) / sigma_i`` (sigma in the
observed quantity's unit, 1 if not given), so the objective ``sum(residuals**2)`` is weighted
least squares.  The thesis's error (sections sspassivefit, activefitting) is the rms
``sqrt(mean((model - data)^2))`` of a dataset in the observed unit; with several datasets it
minimised "the sum of the rms errors" of the flow and no-flow cases, which is
:meth:`FitProblem.rms_error`.

Every parameter change of the fitting code goes through :func:`hemocircuit.fitting.experiments.with_values` (Circuit.with_values).
"""
from __future__ import annotations

import os
import re

import numpy as np

from .. import inputs
from ..errors import FitSpecError, HemocircuitError, NetlistError
from ..spec_inputs import check_limit, read, shown
from .datasets import read_table
from .experiments import SteadyExperiment, TransientExperiment, observed_unit, with_values
from .spec import load_spec, parse_value

_PATH = re.compile(r"(?<![\w.])([A-Za-z_]\w*\.[A-Za-z_]\w*)(?![\w(])")


def _options_and_values(circuit, mapping):
    opts = {k: v for k, v in mapping.items() if circuit.is_option(k)}
    return opts, {k: v for k, v in mapping.items() if k not in opts}


def read_fragment(path, spec_file=None, access=None):
    """The ``change:`` block of a fitted netlist fragment as {ID.PARAM: value} (read under the
    input policy, inside ``access`` if given)."""
    key = "start_from"
    if not os.path.exists(path):
        raise FitSpecError(f"the fragment {path} does not exist (run the previous stage first)", spec_file, key)
    data = read("yaml", path, "fitted fragment", access, spec_file or path, key)
    change = data.get("change") if isinstance(data, dict) else None
    if not isinstance(change, dict) or not all(isinstance(e, str) and (b is None or isinstance(b, dict))
                                               for e, b in change.items()):
        raise FitSpecError(f"{path} has no 'change:' block {{ID: {{param: value}}}} (a fitted fragment written "
                           "by hemocircuit fit)", spec_file, key)
    out = {}
    for eid, body in change.items():
        for k, v in (body or {}).items():
            if not isinstance(k, str) or not isinstance(v, (str, int, float, bool)):
                raise FitSpecError(f"{path}: change.{shown(eid, 40)}.{shown(k, 40)} is not a value (a quantity, "
                                   "number or option)", spec_file, key)
            out[f"{eid}.{k}"] = v
    return out


class Dataset:
    """One dataset: its experiment, the data (observed unit), sigma, weight and normalisation."""

    def __init__(self, spec, experiment, y, sigma, unit, table, x_label, x):
        self.spec, self.experiment, self.y, self.sigma, self.unit = spec, experiment, y, sigma, unit
        self.table, self.x_label, self.x = table, x_label, x   # x: abscissa for plots
        self.name, self.n = spec.name, len(y)


class FitProblem:
    """See the module docstring.  Build with :func:`load_problem`."""

    def __init__(self, spec, circuit, netlist_path):
        self.spec, self.netlist_path = spec, os.path.abspath(str(netlist_path))
        self.base_circuit = circuit  # as given (netlist, --set, --protocol): what fitted.yaml extends
        err = lambda msg, key=None: FitSpecError(msg, file=spec.file, key=key)  # noqa: E731
        c = circuit
        # 1. global structural options, the previous stage's values, fixed values
        if spec.options:
            c = self._options(c, spec.options, "options")
        self.start_from = read_fragment(spec.start_from, spec.file, spec.access) if spec.start_from else {}
        opts, vals = _options_and_values(c, self.start_from)
        if opts:
            c = self._options(c, opts, "start_from")
        c = self._set(c, vals, "start_from")
        fixed = {}
        for p, v in spec.fixed.items():
            fixed[p] = parse_value(v, self._unit(c, p, f"fixed.{p}"), spec.file, f"fixed.{p}")
        c = self._set(c, fixed, "fixed")
        self.fixed = fixed
        self.circuit = c
        # 2. parameters to estimate
        self.parameters = [p.path for p in spec.parameters]
        self.units, lo, hi, self.log = [], [], [], []
        for p in spec.parameters:
            key = f"parameters.{p.path}"
            unit = self._unit(c, p.base_path, key)
            a, b = (parse_value(v, unit, spec.file, f"{key}.bounds") for v in p.bounds)
            if not (np.isfinite(a) and np.isfinite(b)):
                raise err(f"the bounds must be finite numbers, got [{a:g}, {b:g}] {unit}", f"{key}.bounds")
            if not a < b:
                raise err(f"lower bound {shown(p.bounds[0])} is not below the upper bound {shown(p.bounds[1])}",
                          f"{key}.bounds")
            if p.log and a <= 0:
                raise err("a log-scaled parameter needs a positive lower bound", f"{key}.bounds")
            for v, side in ((a, "lower"), (b, "upper")):
                if p.epoch is None:
                    try:
                        with_values(c, {p.base_path: v})
                    except NetlistError as exc:
                        raise err(f"the {side} bound {v:.6g} {unit} is not a value {p.base_path} may take "
                                  f"({exc.bare_message}); narrow the bounds", f"{key}.bounds") from None
            self.units.append(unit)
            lo.append(a)
            hi.append(b)
            self.log.append(p.log)
        self.lower, self.upper, self.log = np.array(lo), np.array(hi), np.array(self.log, bool)
        self.tied = {}
        for p, expr in spec.tied.items():
            key = f"tied.{p}"
            self._unit(c, p, key)
            refs = _PATH.findall(expr)
            if p in refs:
                raise err(f"{p} is tied to itself ({shown(expr)}); write it in terms of estimated or fixed "
                          "parameters", key)
            for q in refs:
                if q in spec.tied:
                    raise err(f"the expression refers to {q}, which is tied too; write {p} in terms of estimated "
                              "or fixed parameters", key)
                if q not in self.parameters:
                    self._unit(c, q, key)
            self.tied[p] = expr.lstrip("= ").strip()
        # 3. datasets
        self.datasets = [self._dataset(d) for d in spec.datasets]
        self._check_epochs()
        rows = sum(d.n for d in self.datasets)
        check_limit(rows, "FIT_ROWS", spec.file, "datasets", "data rows in all datasets")
        if rows < len(self.parameters):
            raise err(f"{rows} data row(s) in all, fewer than the {len(self.parameters)} estimated parameters: "
                      "the fit is not determined; add data or estimate fewer parameters", "datasets")
        # 4. start values: the spec's 'start', else the current value (netlist, start_from)
        self.start = np.array([self._start_value(p, u, a, b) for p, u, a, b in
                               zip(spec.parameters, self.units, self.lower, self.upper)])
        self._check_tied()
        names = {d.name: i for i, d in enumerate(self.datasets)}
        self._norm_ref = [None if not d.spec.normalise else
                          (names.get(d.spec.normalise.get("dataset"), i), d.spec.normalise["row"])
                          for i, d in enumerate(self.datasets)]
        for i, ref in enumerate(self._norm_ref):
            if ref is not None and not 0 <= ref[1] < self.datasets[ref[0]].n:
                raise err(f"row {ref[1]} does not exist in dataset {shown(self.datasets[ref[0]].name)} "
                          f"({self.datasets[ref[0]].n} rows)", f"{self.datasets[i].spec.key}.normalise")
            if ref is not None and self.datasets[ref[0]].y[ref[1]] == 0:
                raise err(f"the data are normalised by row {ref[1]} of dataset {shown(self.datasets[ref[0]].name)}, "
                          "whose value is 0; choose another row", f"{self.datasets[i].spec.key}.normalise")

    # ------------------------------------------------------------------ building ----
    def _unit(self, c, path, key):
        try:
            return c.param_unit(path)
        except NetlistError as exc:
            raise FitSpecError(exc.bare_message, file=self.spec.file, key=key) from None

    def _set(self, c, mapping, key):
        try:
            return with_values(c, mapping)
        except NetlistError as exc:
            raise FitSpecError(exc.bare_message, file=self.spec.file, key=key) from None

    def _options(self, c, mapping, key):
        """``c`` with structural options (values as YAML literals), errors naming ``key``."""
        try:
            return c.with_options({k: _yaml_literal(v, self.spec.file) for k, v in mapping.items()})
        except NetlistError as exc:
            raise FitSpecError(exc.bare_message, file=self.spec.file, key=key) from None

    def _check_tied(self):
        """Every tied expression evaluates, at the start values, to a value its parameter may take."""
        if not self.tied:
            return
        values = self.values_from_array(self.start)
        try:
            B, assign, _ = self._split(values)
        except HemocircuitError as exc:
            raise FitSpecError(getattr(exc, "bare_message", str(exc)), file=self.spec.file, key="tied") from None
        for p in self.tied:
            v = float(assign[p][0])
            if not np.isfinite(v):
                raise FitSpecError(f"the expression {shown(self.tied[p])} is {v} at the start values; write one "
                                   "that is finite over the bounds", file=self.spec.file, key=f"tied.{p}")
            self._set(self.circuit, {p: v}, f"tied.{p}")

    def _dataset(self, d):
        spec_file = self.spec.file
        key = d.key
        table = read_table(d.file, spec_file, f"{key}.file", self.spec.access)
        exp = d.experiment
        c = self.circuit
        if exp["options"]:
            c = self._options(c, exp["options"], f"{key}.experiment.options")
        c = self._set(c, {p: parse_value(v, self._unit(c, p, f"{key}.experiment.set"), spec_file,
                                         f"{key}.experiment.set.{p}") for p, v in exp["set"].items()},
                      f"{key}.experiment.set")
        if exp["type"] in ("op", "dc"):
            inputs = {}
            for p, col in exp["inputs"].items():
                ikey = f"{key}.experiment.inputs.{p}"
                if p in self.parameters:
                    raise FitSpecError(f"{p} is estimated; it cannot also be an input", spec_file, ikey)
                inputs[p] = table.column(str(col), self._unit(c, p, ikey), ikey, spec_file)
            experiment = SteadyExperiment(c, inputs, d.observe, spec_file, f"{key}.observe")
            first = next(iter(exp["inputs"]))
            x_label = f"{exp['inputs'][first]} [{table.units[str(exp['inputs'][first])]}]"
            x = table.columns[str(exp["inputs"][first])]
        else:
            from ..protocol import Protocol
            try:
                proto = Protocol.load(exp["protocol"], c)
            except NetlistError as exc:
                raise FitSpecError(str(exc), spec_file, f"{key}.experiment.protocol") from None
            opts, vals = _options_and_values(c, proto.initial)
            if opts:
                c = self._options(c, opts, f"{key}.experiment.protocol")
            c = self._set(c, vals, f"{key}.experiment.protocol")
            times = table.column(exp["time"], "s", f"{key}.experiment.time", spec_file)
            if np.any(np.diff(times) < 0) or times[0] < 0:
                raise FitSpecError(f"the times in column {exp['time']!r} must be >= 0 and increasing",
                                   spec_file, f"{key}.experiment.time")
            for ev in proto.events:
                for p in ev.set:
                    if p in self.parameters or p in self.tied:
                        raise FitSpecError(f"{p} is estimated (or tied) but the protocol sets it at {ev.at:g} s, "
                                           f"which would override it; estimate that epoch's value as "
                                           f"'{p}@{ev.at:g}s' instead", spec_file, f"parameters.{p}")
            experiment = TransientExperiment(c, proto, times, d.observe, exp["rtol"], spec_file, f"{key}.observe")
            x_label, x = "time [s]", times
        unit = observed_unit(c, d.observe)
        if unit is None:
            raise FitSpecError(f"{d.observe!r} is neither an output column nor a derived quantity of the netlist "
                               f"(e.g. {', '.join(sorted(c.column_units())[:12])} ...)", spec_file, f"{key}.observe")
        y = table.column(d.column, unit, f"{key}.column", spec_file)
        if d.sigma is None:
            sigma = np.ones(len(y))
        elif isinstance(d.sigma, str) and d.sigma in table.columns:
            sigma = table.column(d.sigma, unit, f"{key}.sigma", spec_file)
        else:
            sigma = np.full(len(y), parse_value(d.sigma, unit, spec_file, f"{key}.sigma"))
        if not np.all((sigma > 0) & np.isfinite(sigma)):
            raise FitSpecError("standard deviations must be positive and finite", spec_file, f"{key}.sigma")
        sigma = sigma / np.sqrt(d.weight)
        return Dataset(d, experiment, y, sigma, unit, table, x_label, x)

    def _check_epochs(self):
        trans = [d.experiment for d in self.datasets if isinstance(d.experiment, TransientExperiment)]
        for p in self.spec.parameters:
            if p.epoch is None:
                continue
            sets = sorted({t for e in trans for t in e.epoch_times().get(p.base_path, [])})
            if p.epoch not in sets:
                where = (f"the protocols set {p.base_path} at {', '.join(f'{t:g} s' for t in sets)}" if sets
                         else f"no tran dataset's protocol sets {p.base_path}")
                raise FitSpecError(f"an epoch parameter must name a time at which a protocol sets it; {where}",
                                   self.spec.file, f"parameters.{p.path}")

    def _start_value(self, p, unit, lower, upper):
        key = f"parameters.{p.path}"
        # a number replaces a waveform: its parameter is not fitted (the error says so), whatever the start
        centre = self.circuit.parameters.constant(p.base_path, "fit") if p.epoch is None else None
        if p.start is not None:
            v = parse_value(p.start, unit, self.spec.file, f"{key}.start")
            if not lower <= v <= upper:
                raise FitSpecError(f"the start {shown(p.start)} is outside the bounds [{lower:.6g}, {upper:.6g}] "
                                   f"{unit}; give a start within them (or widen the bounds)", self.spec.file,
                                   f"{key}.start")
        elif p.epoch is not None:
            v = self._protocol_value(p, unit)
        else:
            v = centre
        return v

    def _protocol_value(self, p, unit):
        for d in self.datasets:
            e = d.experiment
            if isinstance(e, TransientExperiment):
                sets = e.protocol.initial if p.epoch == 0.0 else next(
                    (ev.set for ev in e.protocol.events if float(ev.at) == p.epoch), {})
                if p.base_path in sets:
                    return parse_value(sets[p.base_path], unit, e.protocol.file, p.path)
        return self.circuit.parameters.constant(p.base_path, "fit")

    # ---------------------------------------------------------------- evaluation ----
    @property
    def bounds(self):
        """(lower, upper) arrays in the parameters' declared units."""
        return self.lower.copy(), self.upper.copy()

    @property
    def n_residuals(self):
        return sum(d.n for d in self.datasets)

    def values_from_array(self, P):
        """(B, p) or (p,) array in declared units -> {path: (B,) values}."""
        P = np.atleast_2d(np.asarray(P, float))
        return {p: P[:, j] for j, p in enumerate(self.parameters)}

    def _split(self, values):
        unknown = set(values) - set(self.parameters)
        missing = set(self.parameters) - set(values)
        if unknown or missing:
            raise HemocircuitError(f"values must give exactly the estimated parameters {self.parameters}"
                                   + (f"; unknown: {sorted(unknown)}" if unknown else "")
                                   + (f"; missing: {sorted(missing)}" if missing else ""))
        B = max(int(np.size(v)) for v in values.values())
        assign, epochs = {}, {}
        for p in self.spec.parameters:
            v = np.broadcast_to(np.asarray(values[p.path], float).reshape(-1), (B,)).copy()
            if p.epoch is None:
                assign[p.base_path] = v
            else:
                epochs[(p.base_path, p.epoch)] = v
        if self.tied:
            assign.update(self._tied_values(assign, B))
        return B, assign, epochs

    def _tied_values(self, assign, B):
        from ..derived import evaluate_derived
        cols = {}
        for expr in self.tied.values():
            for q in _PATH.findall(expr):
                cols[q] = assign[q] if q in assign else np.full(B, float(self.circuit.parameters.values[q][0]))
        out = evaluate_derived({p: {"expr": e} for p, e in self.tied.items()}, cols, self.spec.file)
        return {p: np.broadcast_to(np.asarray(v, float), (B,)).copy() for p, v in out.items()}

    def tied_values(self, values):
        """{tied path: (B,) values} for the given estimated values."""
        B, assign, _ = self._split(values)
        return {p: assign[p] for p in self.tied}

    def predict(self, values):
        """The model's counterpart of every dataset: [(B, n_d) arrays] (NaN where a member failed)."""
        B, assign, epochs = self._split(values)
        return [d.experiment.evaluate(assign, epochs, B) for d in self.datasets]

    def targets(self, predictions):
        """The data each prediction is compared with, after normalisation: [(B, n_d)].
        Normalised data are scaled so that the data equal the model at the reference row
        (the thesis normalises data radii to the model's initial radius)."""
        out = []
        for d, ref in zip(self.datasets, self._norm_ref):
            B = predictions[0].shape[0]
            if ref is None:
                out.append(np.broadcast_to(d.y, (B, d.n)))
            else:
                j, row = ref
                scale = predictions[j][:, row] / self.datasets[j].y[row]
                out.append(d.y[None, :] * scale[:, None])
        return out

    def residuals_of(self, predictions):
        """(B, n_residuals) weighted residuals from predictions."""
        tg = self.targets(predictions)
        return np.concatenate([(m - t) / d.sigma for m, t, d in zip(predictions, tg, self.datasets)], axis=1)

    def rms_of(self, predictions):
        """(B, n_datasets): each dataset's rms error in its observed unit."""
        tg = self.targets(predictions)
        return np.stack([np.sqrt(np.mean((m - t) ** 2, axis=1)) for m, t in zip(predictions, tg)], axis=1)

    def residuals(self, values):
        """(B, n_residuals) weighted residuals, all B parameter sets in one batched evaluation."""
        return self.residuals_of(self.predict(values))

    def rms_per_dataset(self, values):
        return self.rms_of(self.predict(values))

    def rms_error(self, values):
        """(B,) the thesis's rms error: the sum over datasets of each dataset's rms (NaN if a
        member failed)."""
        return self.rms_per_dataset(values).sum(axis=1)


def _yaml_literal(v, file=None):
    """An option value written as text ('true', '2') as its YAML value (within the input limits)."""
    return inputs.parse_yaml(v, file or "option value") if isinstance(v, str) else v


def load_problem(netlist_path, spec_path, sets=None, protocol=None, svzerod_units=None, allow_paths=None,
                 circuit=None, named_by=None, key=None) -> FitProblem:
    """The fit problem of a netlist and a fit spec.  ``sets`` ({ID.PARAM: value}), ``protocol``
    (its 'initial' settings) and ``svzerod_units`` (an svZeroDSolver JSON's unit system) are
    applied to the netlist as in every command (hemocircuit.loading.load_circuit); ``circuit``: the
    circuit already loaded (then those three are not used).  The files the spec names must lie
    in the spec's project, the netlist's project, the bundled netlists or ``allow_paths``
    (``--allow-path``); ``named_by``/``key``: the spec naming this fit spec (a sensitivity
    spec's ``fit_error``, which has checked the path against its own folders), for messages."""
    from ..loading import load_circuit
    from ..spec_inputs import spec_access

    access = spec_access(spec_path, netlist_path, allow_paths)
    spec = load_spec(spec_path, access, named_by, key)
    if circuit is None:
        circuit, _ = load_circuit(str(netlist_path), sets, protocol, allow_paths=allow_paths,
                                  svzerod_units=svzerod_units)
    return FitProblem(spec, circuit, netlist_path)
