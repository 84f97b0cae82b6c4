"""Sensitivity spec (YAML): the parameters and their space, ties, the method and the output.

    description: pCa bounds and f2 on the arteriole radius
    seed: 1
    method: {name: constellation, scheme: multiplicative, range: 10, n: 1000, designs: 10}
    parameters:
      - art.pCa_L                                   # centre: the netlist's value
      - {path: art.f2, lower: 0.1 N*s/m, upper: 1 N*s/m, centre: 0.5 N*s/m}
      - {name: tau_Ca2, path: art.tau_Ca, event: 239 s}   # the value a protocol event sets
    ties:
      - {path: art.f1, scale_with: art.v, power: -1}    # f1 = f1_c (v / v_c)^-1 (thesis, Kuo91 A)
    output:
      op: {column: art.r, at: [{Pup.value: 40 cmH2O, Pdown.value: 40 cmH2O}]}

Methods (``method.name``) and their settings (defaults in :data:`METHODS`):
constellation (thesis sec. "A Novel Method"), morris, sobol (SALib), local, dynamic.
``scheme``: ``additive`` (every parameter needs lower and upper) or ``multiplicative``
(``range`` percent either side of each centre, thesis's +/-10 % and +/-50 % schemes).
Output kinds: see :mod:`hemocircuit.sensitivity.outputs`.

This module only reads and checks the YAML; units and centres are resolved against a
circuit by :func:`hemocircuit.sensitivity.space.resolve`.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field

from .. import inputs, limits
from ..errors import FitSpecError
from ..spec_inputs import integer, number, read_spec, shown, spec_access, unknown_keys

TOP_KEYS = {"description", "seed", "method", "parameters", "ties", "output"}

#: method name -> its settings with their defaults
METHODS = {
    "constellation": {"scheme": "multiplicative", "range": 10.0, "n": 100, "designs": 10, "step": None},
    "dynamic": {"scheme": "multiplicative", "range": 50.0, "n": 100, "designs": 10, "step": None},
    "morris": {"scheme": "additive", "range": 10.0, "trajectories": 20, "levels": 4},
    "sobol": {"scheme": "additive", "range": 10.0, "n": 256, "conf_level": 0.95, "resamples": 100},
    "local": {"scheme": "multiplicative", "range": 10.0},
}
SCHEMES = ("additive", "multiplicative")
OUTPUT_KINDS = ("op", "dc", "tran", "freq", "envelope", "fit_error", "function")


@dataclass
class Parameter:
    """One varied parameter.  ``key`` names it in value mappings: the path, or
    ``path@<event time>`` for the value a protocol event sets."""
    name: str
    path: str
    lower: object = None  # number in the parameter's unit, or a quantity string (resolved later)
    upper: object = None
    centre: object = None
    event: float | None = None  # s
    unit: str = ""

    @property
    def key(self):
        return self.path if self.event is None else f"{self.path}@{self.event:g}"


@dataclass
class Tie:
    """``path`` follows ``source``: value = centre(path) * (source / centre(source)) ** power."""
    path: str
    source: str
    power: float = 1.0


@dataclass
class Spec:
    parameters: list
    method: dict
    output: dict
    ties: list = field(default_factory=list)
    seed: int = 1
    description: str = ""
    file: str | None = None
    #: the folders the files it names may lie in (hemocircuit.spec_inputs.spec_access)
    access: object = None

    @property
    def method_name(self):
        return self.method["name"]

    def path_of(self, relative, what="file", key=None):
        """A file named in the spec: relative to the spec's folder, inside the allowed folders
        (:attr:`access`).  A spec built in Python without a file names files of the caller's
        own choice (relative to the current folder), as a path given on the command line."""
        from ..spec_inputs import resolve
        access = self.access or (spec_access(self.file) if self.file else None)
        return resolve(relative, self.file, access, what, key)


def load_spec(path, overrides=None, access=None) -> Spec:
    """Read and check a spec file (under the input policy: hemocircuit.spec_inputs).
    ``overrides``: method settings that win over the file's (the CLI's --method, --scheme,
    --range, --n, --trajectories, --seed).  ``access``: the folders the files it names may lie
    in (default: the spec's project and the bundled netlists; the command adds the netlist's
    project and --allow-path)."""
    path = os.path.abspath(inputs.check_path(path, "sensitivity spec"))
    data = read_spec(path, "sensitivity spec")
    spec = parse_spec(data, path, overrides)
    spec.access = access or spec_access(path)
    return spec


#: the command-line options that override the spec's settings (for the messages)
FLAGS = {"name": "--method", "scheme": "--scheme", "range": "--range", "n": "--n", "trajectories": "--trajectories",
         "seed": "--seed"}


def parse_spec(data, file=None, overrides=None) -> Spec:
    def err(msg, key=None):
        return FitSpecError(msg, file=file, key=key)

    if not isinstance(data, dict):
        raise err("a sensitivity spec is a mapping with 'parameters', 'method' and 'output'")
    unknown_keys(data, TOP_KEYS, file)
    overrides = {k: v for k, v in (overrides or {}).items() if v is not None}
    given = {k for k in overrides}
    seed = overrides.pop("seed", data.get("seed", 1))
    seed = integer(seed, file, "seed", lo=0, hi=2 ** 32 - 1, flag="--seed" if "seed" in given else None)
    method = _method(data.get("method"), overrides, err, file, given)
    output = data.get("output")
    if not isinstance(output, dict) or len(output) != 1 or next(iter(output)) not in OUTPUT_KINDS:
        raise err(f"'output' must be a mapping with exactly one of {list(OUTPUT_KINDS)} "
                  "(e.g. output: {op: {column: art.r}} or output: {fit_error: fit.yaml})", "output")
    kind = next(iter(output))
    if kind == "dynamic" or (method["name"] == "dynamic" and kind != "tran" and kind != "function"):
        raise err(f"method 'dynamic' measures a transient: its output must be 'tran' (got {kind!r})", "output")
    raw = data.get("parameters")
    if raw is None and kind != "fit_error":
        raise err("'parameters' is missing (a list of ID.PARAM or {path, lower, upper, centre, name, event})",
                  "parameters")
    if raw is not None and not isinstance(raw, list):
        raise err("expected a list of ID.PARAM or {path, lower, upper, centre, name, event}", "parameters")
    params = [_parameter(p, i, err) for i, p in enumerate(raw or [])]
    names = [p.name for p in params]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise err(f"parameter name(s) {shown(dup)} appear twice; give one of them a distinct 'name'", "parameters")
    keys = [p.key for p in params]
    dupk = sorted({k for k in keys if keys.count(k) > 1})
    if dupk:
        raise err(f"parameter(s) {shown(dupk)} appear twice (same path and event)", "parameters")
    if method["scheme"] == "additive":
        for i, p in enumerate(params):
            if p.lower is None or p.upper is None:
                raise err(f"parameter {shown(p.name)}: the additive scheme needs 'lower' and 'upper' "
                          "(or use scheme: multiplicative with a 'range' in percent)", f"parameters[{i}]")
    ties = data.get("ties") or []
    if not isinstance(ties, list):
        raise err("expected a list of {path: ID.PARAM, scale_with: ID.PARAM, power: -1}", "ties")
    ties = [_tie(t, i, err) for i, t in enumerate(ties)]
    for i, t in enumerate(ties):
        if params and t.source not in keys:
            raise err(f"tie of {shown(t.path)}: scale_with {shown(t.source)} is not one of the varied parameters "
                      f"{shown(keys)}", f"ties[{i}].scale_with")
        if t.path in keys:
            raise err(f"tie of {shown(t.path)}: it is also a varied parameter; a parameter is either varied or tied",
                      f"ties[{i}].path")
        if t.path == t.source:
            raise err(f"{shown(t.path)} is tied to itself", f"ties[{i}]")
    tied = [t.path for t in ties]
    if len(set(tied)) < len(tied):
        raise err(f"a parameter is tied twice ({shown(sorted({p for p in tied if tied.count(p) > 1}))})", "ties")
    if params:
        check_runs(method, len(params), file, given)
    description = data.get("description", "")
    return Spec(params, method, output, ties, seed, description if isinstance(description, str) else "", file)


def check_runs(method, k, file, given=()):
    """The model evaluations the method will make for k parameters, within SENS_RUNS."""
    name = method["name"]
    runs = {"constellation": lambda: method["n"] * (k + 1), "dynamic": lambda: method["n"] * (k + 1),
            "morris": lambda: method["trajectories"] * (k + 1), "sobol": lambda: method["n"] * (k + 2),
            "local": lambda: k + 1}[name]()
    if runs > limits.limit("SENS_RUNS"):
        key = {"morris": "trajectories", "local": None}.get(name, "n")
        what = ("k + 1" if name == "local" else f"{method['trajectories']:,} trajectories x (k + 1)"
                if name == "morris" else f"n = {method['n']:,} x (k + {2 if name == 'sobol' else 1})")
        flag = FLAGS.get(key) if key in given else None
        raise FitSpecError(f"{what} = {runs:,} model evaluations for k = {k} parameters, more than allowed "
                           f"{limits.how_to_raise('SENS_RUNS')}" + (f" (set by {flag})" if flag else ""), file=file,
                           key=f"method.{key}" if key else "parameters")
    return runs


def _method(raw, overrides, err, file=None, given=()):
    if raw is None:
        raw = {}
    if isinstance(raw, str):
        raw = {"name": raw}
    if not isinstance(raw, dict):
        raise err("'method' must be a name or a mapping {name: constellation, ...}", "method")
    name = overrides.get("name", raw.get("name", "constellation"))
    if not isinstance(name, str) or name not in METHODS:
        raise err(f"unknown method {shown(name)}; choose one of {sorted(METHODS)}",
                  "--method" if "name" in given else "method.name")
    allowed = METHODS[name]
    if name != raw.get("name", "constellation"):  # another method asked for: keep what applies
        raw = {k: v for k, v in raw.items() if k in allowed}
    raw = {**raw, **{k: v for k, v in overrides.items() if k in allowed or k == "name"}}
    unknown_keys([k for k in raw if k != "name"], set(allowed), file, "method", f"setting(s) of method {name}:")
    m = {"name": name, **allowed, **{k: v for k, v in raw.items() if k != "name"}}

    def key(k):
        return f"method.{k}"

    def flag(k):
        return FLAGS.get(k) if k in given else None

    if not isinstance(m["scheme"], str) or m["scheme"] not in SCHEMES:
        raise err(f"method {name}: scheme {shown(m['scheme'])}; choose 'additive' or 'multiplicative'", key("scheme"))
    rng = m["range"]
    if isinstance(rng, str):
        rng = rng.replace("%", "").strip()
    try:
        m["range"] = float(rng)
    except (TypeError, ValueError, OverflowError):
        raise err(f"method {name}: range {shown(m['range'])} must be a percentage (e.g. 10 or '10 %')",
                  key("range")) from None
    if not 0 < m["range"] < 100:
        raise err(f"method {name}: range {m['range']} % must lie between 0 and 100 (exclusive)", key("range"))
    for k in ("n", "designs", "trajectories", "levels", "resamples"):
        if k in m:
            m[k] = integer(m[k], file, key(k), lo=1, flag=flag(k))
    runs_limit = limits.limit("SENS_RUNS")
    for k in ("n", "trajectories"):  # at least 2 runs each, whatever k: a first bound before k is known
        if k in m and 2 * m[k] > runs_limit:
            raise FitSpecError(f"{k} = {m[k]:,}{' (' + flag(k) + ')' if flag(k) else ''} means at least "
                               f"{2 * m[k]:,} model evaluations, more than allowed {limits.how_to_raise('SENS_RUNS')}",
                               file=file, key=key(k))
    if "designs" in m and m["designs"] > limits.limit("SENS_DESIGNS"):
        raise FitSpecError(f"{m['designs']:,} designs, more than allowed {limits.how_to_raise('SENS_DESIGNS')}",
                           file=file, key=key("designs"))
    if "designs" in m and m["designs"] * m["n"] > limits.limit("SENS_DESIGN_POINTS"):
        raise FitSpecError(f"designs x n = {m['designs']:,} x {m['n']:,} Latin-hypercube points, more than allowed "
                           f"{limits.how_to_raise('SENS_DESIGN_POINTS')}", file=file, key=key("designs"))
    if name == "morris" and (m["levels"] < 2 or m["levels"] % 2 or m["levels"] > 1000):
        raise err(f"method morris: levels must be even, >= 2 and <= 1000 (SALib), got {m['levels']}", key("levels"))
    if name == "sobol" and m["n"] & (m["n"] - 1):
        raise err(f"method sobol: n must be a power of 2 (Sobol' sequence), got {m['n']}", key("n"))
    if name == "sobol":
        if m["resamples"] > limits.limit("SENS_RESAMPLES"):
            raise FitSpecError(f"{m['resamples']:,} bootstrap resamples, more than allowed "
                               f"{limits.how_to_raise('SENS_RESAMPLES')}", file=file, key=key("resamples"))
        if m["n"] * m["resamples"] > limits.limit("SENS_VALUES"):
            raise FitSpecError(f"n x resamples = {m['n']:,} x {m['resamples']:,} bootstrap values, more than "
                               f"allowed {limits.how_to_raise('SENS_VALUES')}", file=file, key=key("resamples"))
        m["conf_level"] = number(m["conf_level"], file, key("conf_level"), lo=0.0, hi=1.0,
                                 what="a confidence level between 0 and 1 (e.g. 0.95)")
    if m.get("step") is not None:
        m["step"] = number(m["step"], file, key("step"), lo=0.0, hi=0.5, what="a step (a fraction, e.g. 1e-3)")
    return m


def _parameter(p, i, err):
    key = f"parameters[{i}]"
    if isinstance(p, str):
        p = {"path": p}
    if not isinstance(p, dict) or "path" not in p:
        raise err(f"expected ID.PARAM or a mapping with 'path' (got {shown(p)})", key)
    path = p["path"]
    if not isinstance(path, str) or not path.strip() or len(path) > 200:
        raise err(f"path {shown(path)} must be ID.PARAM", f"{key}.path")
    unknown = [k for k in p if k not in {"path", "name", "lower", "upper", "centre", "event"}]
    if unknown:
        raise err(f"({shown(path)}): unknown key(s) {shown(unknown)}; allowed: path, name, lower, upper, centre, "
                  "event", key)
    for k in ("lower", "upper", "centre"):
        v = p.get(k)
        if v is not None and (isinstance(v, bool) or not isinstance(v, (str, int, float))):
            raise err(f"expected a number or a quantity with its unit, got {shown(v)}", f"{key}.{k}")
    event = p.get("event")
    if event is not None:
        from ..units import UnitError, parse_quantity
        if isinstance(event, bool) or not isinstance(event, (str, int, float)):
            raise err(f"expected a time (e.g. 239 s), got {shown(event)}", f"{key}.event")
        try:
            event = parse_quantity(event, "s", f"parameter {path} event")
        except UnitError as exc:
            raise err(str(exc)[:300], f"{key}.event") from None
        if not (math.isfinite(event) and event >= 0):
            raise err(f"the event time must be finite and >= 0, got {event:g} s", f"{key}.event")
    name = p.get("name", path if event is None else f"{path}@{event:g}s")
    if isinstance(name, bool) or not isinstance(name, (str, int, float)) or not str(name).strip() or len(str(name)) > 200:
        raise err(f"'name' must be a short text, got {shown(name)}", f"{key}.name")
    return Parameter(str(name), path, p.get("lower"), p.get("upper"), p.get("centre"), event)


def _tie(t, i, err):
    key = f"ties[{i}]"
    if not isinstance(t, dict) or "path" not in t or "scale_with" not in t:
        raise err(f"expected {{path: ID.PARAM, scale_with: ID.PARAM, power: -1}} (got {shown(t)})", key)
    unknown = [k for k in t if k not in {"path", "scale_with", "power"}]
    if unknown:
        raise err(f"unknown key(s) {shown(unknown)}; allowed: path, scale_with, power", key)
    for k in ("path", "scale_with"):
        if not isinstance(t[k], str) or not t[k].strip() or len(t[k]) > 200:
            raise err(f"expected ID.PARAM, got {shown(t[k])}", f"{key}.{k}")
    power = t.get("power", 1.0)
    if isinstance(power, bool) or not isinstance(power, (int, float, str)):
        raise err(f"power {shown(power)} must be a number", f"{key}.power")
    try:
        power = float(power)
    except (TypeError, ValueError, OverflowError):
        raise err(f"power {shown(t.get('power'))} must be a number", f"{key}.power") from None
    if not math.isfinite(power):
        raise err(f"power {power} must be finite", f"{key}.power")
    return Tie(t["path"], t["scale_with"], power)
