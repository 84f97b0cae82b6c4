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

import numpy as np

from .. import inputs
from ..errors import FitSpecError
from ..spec_inputs import integer, number, read_spec, resolve, shown, spec_access, text, unknown_keys
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
    #: the folders the files it names may lie in (hemocircuit.spec_inputs.spec_access)
    access: object = None

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


def load_spec(path, access=None, named_by=None, key=None) -> FitSpec:
    """Read and validate a fit spec (structure only; values are checked against the circuit
    by :class:`~hemocircuit.fitting.problem.FitProblem`).  The spec is read under the input
    policy (:mod:`hemocircuit.spec_inputs`); the files it names must lie in ``access`` (default:
    the spec's project and the bundled netlists; :func:`~hemocircuit.fitting.load_problem` adds
    the netlist's project and ``allow_paths``).  ``named_by``/``key``: the spec naming this one
    (a sensitivity spec's ``fit_error``): then this file itself must lie in ``access`` too."""
    path = os.path.abspath(inputs.check_path(path, "fit spec"))
    data = read_spec(path, "fit spec", access if named_by else None, named_by, key)
    return parse_spec(data, path, access)


def check_settings(settings, path, flags=None):
    """Validate fit settings (the spec's, or merged with overrides: ``flags`` {key: '--starts'}
    names the command-line option that set a key).  Returns the settings with numbers as
    numbers."""
    flags = flags or {}
    out = dict(settings)

    def key(k):
        return f"settings.{k}"

    if out["bounds"] not in ("transform", "reflective"):
        raise FitSpecError(f"'bounds' must be transform or reflective, got {shown(out['bounds'])}", path,
                           key("bounds"))
    out["starts"] = integer(out["starts"], path, key("starts"), lo=0 if "starts" in flags else 1,
                            limit_name="FIT_STARTS", flag=flags.get("starts"))
    if out["starts"] == 0 and not out.get("start_current", True):
        raise FitSpecError("no start: 'starts' is 0 and 'start_current' is false; give starts >= 1", path,
                           key("starts"))
    out["seed"] = integer(out["seed"], path, key("seed"), lo=0, hi=2 ** 32 - 1, flag=flags.get("seed"))
    out["max_nfev"] = integer(out["max_nfev"], path, key("max_nfev"), lo=1, flag=flags.get("max_nfev"))
    if out["workers"] is not None:
        out["workers"] = integer(out["workers"], path, key("workers"), lo=1, flag=flags.get("workers"))
    if not isinstance(out["start_current"], bool):
        raise FitSpecError(f"'start_current' must be true or false, got {shown(out['start_current'])}", path,
                           key("start_current"))
    for k in ("ftol", "xtol", "gtol"):
        out[k] = number(out[k], path, key(k), lo=0.0, hi=1.0, lo_open=False, what="a tolerance (e.g. 1e-12)")
    if max(out["ftol"], out["xtol"], out["gtol"]) < 2.3e-16:
        raise FitSpecError("at least one of ftol, xtol, gtol must exceed the machine epsilon 2.2e-16 (scipy's "
                           "least_squares); e.g. ftol: 1e-12", path, "settings")
    return out


def parse_spec(data, path, access=None) -> FitSpec:
    def err(msg, key=None):
        return FitSpecError(msg, file=path, key=key)

    path = os.path.abspath(str(path))
    if access is None:
        access = spec_access(path)
    if not isinstance(data, dict):
        raise err("a fit spec is a mapping with 'parameters' and 'datasets'")
    unknown_keys(data, TOP_KEYS, path)
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
        if not isinstance(v, str) or not v.lstrip("= ").strip():
            raise err(f"expected an expression string of other parameters (e.g. \"2 * art.f1\"), got {shown(v)}",
                      f"tied.{k}")
    for k in tied:
        if k in fixed:
            raise err(f"{k} is both tied and fixed; keep one", f"tied.{k}")
    # ---- parameters -------------------------------------------------------------------
    if not isinstance(data["parameters"], dict):
        raise err("expected a mapping {ID.PARAM: {bounds: [lower, upper], log: false, start: value}}",
                  "parameters")
    params = []
    for p, body in data["parameters"].items():
        if not isinstance(p, str) or "." not in p or len(p) > 200:
            raise err(f"{shown(p)} is not an ID.PARAM path", "parameters")
        key = f"parameters.{p}"
        if not isinstance(body, dict):
            raise err("expected {bounds: [lower, upper], log: true|false, start: value}", key)
        unknown_keys(body, PARAM_KEYS, path, key)
        b = body.get("bounds")
        if not isinstance(b, (list, tuple)) or len(b) != 2:
            raise err("'bounds' must be [lower, upper] (with units, e.g. [5e-9 N, 2e-7 N])", key)
        if not isinstance(body.get("log", False), bool):
            raise err("'log' must be true or false", key)
        ps = ParamSpec(p, tuple(b), bool(body.get("log", False)), body.get("start"))
        if _EPOCH.match(p):
            try:
                t = ps.epoch
            except UnitError as exc:
                raise err(f"the epoch time after '@' is not a time: {exc}", key) from None
            if not (np.isfinite(t) and t >= 0):
                raise err(f"the epoch time after '@' must be finite and >= 0, got {t:g} s", key)
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
        unknown_keys(d, DATASET_KEYS, path, key)
        for k in ("file", "experiment", "observe", "column"):
            if k not in d:
                raise err(f"'{k}' is missing", key)
        name = text(d.get("name", f"dataset{i}"), path, f"{key}.name")
        if name in names:
            raise err(f"the name {shown(name)} is used twice", key)
        names.add(name)
        exp = d["experiment"]
        if not isinstance(exp, dict) or not isinstance(exp.get("type"), str) or exp["type"] not in EXPERIMENT_KEYS:
            raise err(f"'experiment' needs a type, one of {sorted(EXPERIMENT_KEYS)}", f"{key}.experiment")
        exp = dict(exp)
        unknown_keys(exp, EXPERIMENT_KEYS[exp["type"]], path, f"{key}.experiment",
                     f"key(s) for type {exp['type']}:")
        exp["options"] = mapping(f"{key}.experiment.options", exp.get("options"))
        exp["set"] = mapping(f"{key}.experiment.set", exp.get("set"))
        if exp["type"] == "op":
            exp["inputs"] = mapping(f"{key}.experiment.inputs", exp.get("inputs"))
            if not exp["inputs"]:
                raise err("an op experiment needs inputs {ID.PARAM: data column}", f"{key}.experiment.inputs")
            exp["inputs"] = {p: text(c, path, f"{key}.experiment.inputs.{p}", "a data column name")
                             for p, c in exp["inputs"].items()}
        elif exp["type"] == "dc":
            if not isinstance(exp.get("sweep"), str) or not isinstance(exp.get("column"), str):
                raise err("a dc experiment needs 'sweep: ID.PARAM' and 'column: NAME' (the swept values)",
                          f"{key}.experiment")
            exp["inputs"] = {exp["sweep"]: exp["column"]}
        else:
            if not isinstance(exp.get("protocol"), str) or not isinstance(exp.get("time"), str):
                raise err("a tran experiment needs 'protocol: FILE' and 'time: COLUMN' (the data's times)",
                          f"{key}.experiment")
            exp["protocol"] = resolve(exp["protocol"], path, access, "protocol file", f"{key}.experiment.protocol")
            if not os.path.exists(exp["protocol"]):
                raise err(f"protocol file not found: {exp['protocol']}", f"{key}.experiment.protocol")
            exp["rtol"] = number(exp.get("rtol", 1e-8), path, f"{key}.experiment.rtol", lo=0.0, hi=0.1,
                                 hi_open=False, what="a relative tolerance (e.g. 1e-8)")
        weight = d.get("weight", 1.0)
        if isinstance(weight, bool) or not isinstance(weight, (int, float)) or not weight > 0 or \
                not np.isfinite(weight):
            raise err(f"'weight' must be a positive finite number, got {shown(weight)}", f"{key}.weight")
        if "sigma" in d and "weight" in d:
            raise err("give either 'sigma' (standard deviation) or 'weight', not both", key)
        if d.get("sigma") is not None and (isinstance(d["sigma"], bool)
                                           or not isinstance(d["sigma"], (str, int, float))):
            raise err(f"'sigma' must be a quantity (e.g. 1 um) or a data column name, got {shown(d['sigma'])}",
                      f"{key}.sigma")
        file = resolve(d["file"], path, access, "data file", f"{key}.file")
        datasets.append(DatasetSpec(name, file, exp, text(d["observe"], path, f"{key}.observe",
                                                          "an output column or a derived quantity"),
                                    text(d["column"], path, f"{key}.column", "a data column name"), d.get("sigma"),
                                    float(weight), _normalise(d.get("normalise"), err, f"{key}.normalise"), key))
    for d in datasets:
        ref = d.normalise.get("dataset")
        if ref is not None and ref not in names:
            raise err(f"refers to the dataset {shown(ref)}, which does not exist (datasets: {sorted(names)})",
                      f"{d.key}.normalise")
    # ---- settings ---------------------------------------------------------------------
    s = data.get("settings") or {}
    if not isinstance(s, dict):
        raise err("expected a mapping", "settings")
    unknown_keys(s, SETTINGS, path, "settings")
    settings = check_settings({**SETTINGS, **s}, path)
    start_from = data.get("start_from")
    if start_from is not None:
        start_from = resolve(start_from, path, access, "fitted fragment", "start_from")
    name = data.get("name", os.path.splitext(os.path.basename(path))[0])
    description = data.get("description", "")
    return FitSpec(path, text(name, path, "name"), description if isinstance(description, str) else shown(description),
                   start_from, options, fixed, tied, params, datasets, settings, access)


def _normalise(v, err, key):
    """none | first | {row: k} | {dataset: NAME, row: k} -> {} or {'row': k, 'dataset': NAME|None}."""
    if v is None or v == "none":
        return {}
    if v == "first":
        return {"row": 0, "dataset": None}
    if isinstance(v, dict) and set(v) <= {"row", "dataset"} and isinstance(v.get("row", 0), int) \
            and not isinstance(v.get("row", 0), bool) and (v.get("dataset") is None or isinstance(v["dataset"], str)):
        return {"row": int(v.get("row", 0)), "dataset": v.get("dataset")}
    raise err(f"expected none, first, {{row: k}} or {{dataset: NAME, row: k}}, got {shown(v)}", key)


def parse_value(value, unit, spec_file, key):
    """A value written in the spec (quantity string, or bare number if dimensionless) in ``unit``."""
    if isinstance(value, bool) or not isinstance(value, (str, int, float)):
        raise FitSpecError(f"expected a quantity in {unit or 'dimensionless units'} (a number with its unit), got "
                           f"{shown(value)}", file=spec_file, key=key)
    if isinstance(value, str) and len(value) > 1000:
        raise FitSpecError(f"a quantity of {len(value):,} characters; write a number and its unit", file=spec_file,
                           key=key)
    try:
        return parse_quantity(_spaced(value) if isinstance(value, str) else value, unit, key)
    except UnitError as exc:
        msg = str(exc)
        msg = msg[len(key) + 2:] if msg.startswith(f"{key}: ") else msg  # the key is named once
        raise FitSpecError(_cut(msg), file=spec_file, key=key) from None


def _cut(message, n=300):
    return message if len(message) <= n else message[:n] + "..."
