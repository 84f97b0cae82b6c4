"""Fit specification (YAML) for ``hemocircuit fit NETLIST SPEC.yaml``: parse and validate.

    name: kuo91 stage 1 - passive curve
    start_from: output/kuo91_0/fitted.yaml   # optional: a previous stage's fitted fragment
    options: {art.preset: kuo91}             # optional structural options for every dataset
    fixed: {art.tau_Ca: 1 s}                 # optional values held fixed
    tied: {art.f1: "9.0694e-05 / art.v"}     # optional: PATH = expression of other parameters
    parameters:                              # the parameters to estimate
      art.q1: {bounds: [5e-9 N, 2e-7 N], log: true, start: 4e-8 N}
      art.q2: {bounds: [2, 20]}
      art.tau_Ca@239s: {bounds: [0.1 s, 20 s], log: true}   # a protocol epoch's value
    datasets:
      - name: passive
        file: data/kuo91_passive.csv         # relative to this spec file
        experiment: {type: op, options: {art.passive: true},
                     inputs: {Pup.value: Pup, Pdown.value: Pdown}}   # parameter: data column
        observe: art.r                       # an output column or a derived quantity
        column: r                            # the data column it is compared with
        sigma: 1 um                          # or a column name, or weight: <number>
        normalise: none                      # none | first | {row: k} | {dataset: NAME, row: k}
    settings: {starts: 4, seed: 1, max_nfev: 200, workers: 2, start_current: true}

Experiments: ``op`` (operating points at the data rows' inputs), ``dc`` (a sweep of one
parameter over a data column: ``sweep: Pa.value, column: Pa``), ``tran`` (a protocol run,
compared at the data's times: ``protocol: FILE, time: t``).  Every value with a dimension is
written with its unit (as in netlists); bare numbers only for dimensionless parameters.
Errors name the spec file and the key (``datasets[0].experiment.inputs``).
"""
from __future__ import annotations

import os
import re
from dataclasses import dataclass, field

import yaml

from ..errors import FitSpecError
from ..units import UnitError, parse_quantity

TOP_KEYS = {"name", "description", "start_from", "options", "fixed", "tied", "parameters", "datasets",
            "settings"}
PARAM_KEYS = {"bounds", "log", "start"}
DATASET_KEYS = {"name", "file", "experiment", "observe", "column", "sigma", "weight", "normalise"}
EXPERIMENT_KEYS = {"op": {"type", "options", "inputs", "set"},
                   "dc": {"type", "options", "sweep", "column", "set"},
                   "tran": {"type", "options", "protocol", "time", "set", "rtol"}}
SETTINGS = {"starts": 4, "seed": 1, "max_nfev": 200, "workers": None, "start_current": True,
            "ftol": 1e-12, "xtol": 1e-12, "gtol": 1e-12, "bounds": "transform"}
_EPOCH = re.compile(r"^([A-Za-z_]\w*\.[A-Za-z_]\w*)@(.+)$")


@dataclass
class ParamSpec:
    path: str                 # as written: ID.PARAM or ID.PARAM@TIME
    bounds: tuple             # raw (lower, upper) as written
    log: bool = False
    start: object = None      # raw value as written, or None

    @property
    def base_path(self) -> str:
        """ID.PARAM (without an epoch)."""
        m = _EPOCH.match(self.path)
        return m.group(1) if m else self.path

    @property
    def epoch(self):
        """The protocol time [s] of an epoch parameter (``@239s``), else None."""
        m = _EPOCH.match(self.path)
        return None if m is None else parse_quantity(_spaced(m.group(2)), "s", self.path)


@dataclass
class DatasetSpec:
    name: str
    file: str                 # absolute path
    experiment: dict          # validated, type in EXPERIMENT_KEYS; protocol path absolute
    observe: str
    column: str
    sigma: object = None      # raw quantity, column name, or None
    weight: float = 1.0
    normalise: dict = field(default_factory=dict)   # {} or {'row': k, 'dataset': name or None}
    key: str = ""             # 'datasets[i]' for messages


@dataclass
class FitSpec:
    file: str
    name: str
    description: str
    start_from: str | None
    options: dict
    fixed: dict
    tied: dict
    parameters: list
    datasets: list
    settings: dict

    def dataset(self, name):
        return next(d for d in self.datasets if d.name == name)


def _spaced(v):
    """'239s' -> '239 s' (a number glued to its unit); strings with a space are left alone."""
    if " " in str(v).strip():
        return str(v)
    try:  # '10e-3' (YAML reads it as a string): a plain number
        float(v)
        return str(v)
    except ValueError:
        pass
    m = re.match(r"^([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*([A-Za-z].*)$", str(v).strip())
    return f"{m.group(1)} {m.group(2)}" if m else str(v)


def load_spec(path) -> FitSpec:
    """Read and validate a fit spec (structure only; values are checked against the circuit
    by :func:`resolve_values`)."""
    path = os.path.abspath(str(path))
    if not os.path.exists(path):
        raise FitSpecError(f"fit spec not found: {path}")
    try:
        with open(path) as fh:
            data = yaml.safe_load(fh)
    except yaml.YAMLError as exc:
        raise FitSpecError(f"not valid YAML: {exc}", file=path) from None
    return parse_spec(data, path)


def parse_spec(data, path) -> FitSpec:
    def err(msg, key=None):
        return FitSpecError(msg, file=path, key=key)

    here = os.path.dirname(path)
    if not isinstance(data, dict):
        raise err("a fit spec is a mapping with 'parameters' and 'datasets'")
    unknown = set(data) - TOP_KEYS
    if unknown:
        raise err(f"unknown key(s) {sorted(unknown)}; allowed: {sorted(TOP_KEYS)}")
    for k in ("parameters", "datasets"):
        if not data.get(k):
            raise err(f"'{k}' is missing or empty", k)

    def mapping(key, value):
        if value is None:
            return {}
        if not isinstance(value, dict) or not all(isinstance(k, str) and "." in k for k in value):
            raise err("expected a mapping {ID.PARAM: value}", key)
        return dict(value)

    options = mapping("options", data.get("options"))
    fixed = mapping("fixed", data.get("fixed"))
    tied = mapping("tied", data.get("tied"))
    for k, v in tied.items():
        if not isinstance(v, str):
            raise err(f"expected an expression string of other parameters (e.g. \"2 * art.f1\"), got {v!r}",
                      f"tied.{k}")
    # ---- parameters -------------------------------------------------------------------
    if not isinstance(data["parameters"], dict):
        raise err("expected a mapping {ID.PARAM: {bounds: [lower, upper], log: false, start: value}}",
                  "parameters")
    params = []
    for p, body in data["parameters"].items():
        key = f"parameters.{p}"
        if not isinstance(p, str) or "." not in p:
            raise err(f"{p!r} is not an ID.PARAM path", "parameters")
        if not isinstance(body, dict):
            raise err("expected {bounds: [lower, upper], log: true|false, start: value}", key)
        unknown = set(body) - PARAM_KEYS
        if unknown:
            raise err(f"unknown key(s) {sorted(unknown)}; allowed: {sorted(PARAM_KEYS)}", key)
        b = body.get("bounds")
        if not isinstance(b, (list, tuple)) or len(b) != 2:
            raise err("'bounds' must be [lower, upper] (with units, e.g. [5e-9 N, 2e-7 N])", key)
        if not isinstance(body.get("log", False), bool):
            raise err("'log' must be true or false", key)
        ps = ParamSpec(p, tuple(b), bool(body.get("log", False)), body.get("start"))
        if _EPOCH.match(p):
            try:
                ps.epoch
            except UnitError as exc:
                raise err(f"the epoch time after '@' is not a time: {exc}", key) from None
        for where in (fixed, tied):
            if ps.base_path in where and ps.epoch is None:
                raise err(f"{p} is estimated and also listed under "
                          f"'{'fixed' if where is fixed else 'tied'}'", key)
        params.append(ps)
    # ---- datasets ---------------------------------------------------------------------
    if not isinstance(data["datasets"], list):
        raise err("expected a list of datasets", "datasets")
    datasets, names = [], set()
    for i, d in enumerate(data["datasets"]):
        key = f"datasets[{i}]"
        if not isinstance(d, dict):
            raise err("expected a mapping with file, experiment, observe, column", key)
        unknown = set(d) - DATASET_KEYS
        if unknown:
            raise err(f"unknown key(s) {sorted(unknown)}; allowed: {sorted(DATASET_KEYS)}", key)
        for k in ("file", "experiment", "observe", "column"):
            if k not in d:
                raise err(f"'{k}' is missing", key)
        name = str(d.get("name", f"dataset{i}"))
        if name in names:
            raise err(f"the name {name!r} is used twice", key)
        names.add(name)
        exp = d["experiment"]
        if not isinstance(exp, dict) or exp.get("type") not in EXPERIMENT_KEYS:
            raise err(f"'experiment' needs a type, one of {sorted(EXPERIMENT_KEYS)}", f"{key}.experiment")
        exp = dict(exp)
        unknown = set(exp) - EXPERIMENT_KEYS[exp["type"]]
        if unknown:
            raise err(f"unknown key(s) {sorted(unknown)} for type {exp['type']}; allowed: "
                      f"{sorted(EXPERIMENT_KEYS[exp['type']])}", f"{key}.experiment")
        exp["options"] = mapping(f"{key}.experiment.options", exp.get("options"))
        exp["set"] = mapping(f"{key}.experiment.set", exp.get("set"))
        if exp["type"] == "op":
            exp["inputs"] = mapping(f"{key}.experiment.inputs", exp.get("inputs"))
            if not exp["inputs"]:
                raise err("an op experiment needs inputs {ID.PARAM: data column}", f"{key}.experiment.inputs")
        elif exp["type"] == "dc":
            if not isinstance(exp.get("sweep"), str) or not isinstance(exp.get("column"), str):
                raise err("a dc experiment needs 'sweep: ID.PARAM' and 'column: NAME' (the swept values)",
                          f"{key}.experiment")
            exp["inputs"] = {exp["sweep"]: exp["column"]}
        else:
            if not isinstance(exp.get("protocol"), str) or not isinstance(exp.get("time"), str):
                raise err("a tran experiment needs 'protocol: FILE' and 'time: COLUMN' (the data's times)",
                          f"{key}.experiment")
            exp["protocol"] = os.path.normpath(os.path.join(here, exp["protocol"]))
            if not os.path.exists(exp["protocol"]):
                raise err(f"protocol file not found: {exp['protocol']}", f"{key}.experiment.protocol")
            try:
                exp["rtol"] = float(exp.get("rtol", 1e-8))
            except (TypeError, ValueError):
                raise err("'rtol' must be a number", f"{key}.experiment.rtol") from None
        weight = d.get("weight", 1.0)
        if isinstance(weight, bool) or not isinstance(weight, (int, float)) or not weight > 0:
            raise err(f"'weight' must be a positive number, got {weight!r}", f"{key}.weight")
        if "sigma" in d and "weight" in d:
            raise err("give either 'sigma' (standard deviation) or 'weight', not both", key)
        datasets.append(DatasetSpec(name, os.path.normpath(os.path.join(here, str(d["file"]))), exp,
                                    str(d["observe"]), str(d["column"]), d.get("sigma"), float(weight),
                                    _normalise(d.get("normalise"), err, f"{key}.normalise"), key))
    for d in datasets:
        ref = d.normalise.get("dataset")
        if ref is not None and ref not in names:
            raise err(f"refers to the dataset {ref!r}, which does not exist (datasets: {sorted(names)})",
                      f"{d.key}.normalise")
    # ---- settings ---------------------------------------------------------------------
    settings = dict(SETTINGS)
    s = data.get("settings") or {}
    if not isinstance(s, dict):
        raise err("expected a mapping", "settings")
    unknown = set(s) - set(SETTINGS)
    if unknown:
        raise err(f"unknown key(s) {sorted(unknown)}; allowed: {sorted(SETTINGS)}", "settings")
    settings.update(s)
    if settings["bounds"] not in ("transform", "reflective"):
        raise err(f"'bounds' must be transform or reflective, got {settings['bounds']!r}", "settings.bounds")
    for k in ("starts", "seed", "max_nfev"):
        if isinstance(settings[k], bool) or not isinstance(settings[k], int) or settings[k] < (0 if k == "seed" else 1):
            raise err(f"'{k}' must be a positive integer, got {settings[k]!r}", f"settings.{k}")
    start_from = data.get("start_from")
    if start_from is not None:
        start_from = os.path.normpath(os.path.join(here, str(start_from)))
    return FitSpec(path, str(data.get("name", os.path.splitext(os.path.basename(path))[0])),
                   str(data.get("description", "")), start_from, options, fixed, tied, params, datasets, settings)


def _normalise(v, err, key):
    """none | first | {row: k} | {dataset: NAME, row: k} -> {} or {'row': k, 'dataset': NAME|None}."""
    if v is None or v == "none":
        return {}
    if v == "first":
        return {"row": 0, "dataset": None}
    if isinstance(v, dict) and set(v) <= {"row", "dataset"} and isinstance(v.get("row", 0), int):
        return {"row": int(v.get("row", 0)), "dataset": v.get("dataset")}
    raise err(f"expected none, first, {{row: k}} or {{dataset: NAME, row: k}}, got {v!r}", key)


def parse_value(value, unit, spec_file, key):
    """A value written in the spec (quantity string, or bare number if dimensionless) in ``unit``."""
    try:
        return parse_quantity(_spaced(value) if isinstance(value, str) else value, unit, key)
    except UnitError as exc:
        raise FitSpecError(str(exc), file=spec_file, key=key) from None
