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

import os
from dataclasses import dataclass, field

import yaml

from ..errors import NetlistError

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

    @property
    def method_name(self):
        return self.method["name"]

    def path_of(self, relative):
        """A file named in the spec, relative to the spec's folder."""
        if relative is None or os.path.isabs(relative) or self.file is None:
            return relative
        return os.path.join(os.path.dirname(os.path.abspath(self.file)), relative)


def load_spec(path, overrides=None) -> Spec:
    """Read and check a spec file.  ``overrides``: method settings that win over the file's
    (the CLI's --method, --scheme, --range, --n, --seed)."""
    if not os.path.exists(path):
        raise NetlistError(f"sensitivity spec not found: {path}")
    try:
        with open(path) as fh:
            data = yaml.safe_load(fh)
    except yaml.YAMLError as exc:
        raise NetlistError(f"sensitivity spec is not valid YAML: {exc}", file=path) from None
    return parse_spec(data, path, overrides)


def parse_spec(data, file=None, overrides=None) -> Spec:
    def err(msg):
        return NetlistError(msg, file=file)

    if not isinstance(data, dict):
        raise err("a sensitivity spec is a mapping with 'parameters', 'method' and 'output'")
    unknown = set(data) - {"description", "seed", "method", "parameters", "ties", "output"}
    if unknown:
        raise err(f"unknown key(s) {sorted(unknown)}; allowed: description, seed, method, parameters, ties, output")
    overrides = {k: v for k, v in (overrides or {}).items() if v is not None}
    seed = overrides.pop("seed", data.get("seed", 1))
    if not isinstance(seed, int) or isinstance(seed, bool):
        raise err(f"seed must be an integer, got {seed!r}")
    method = _method(data.get("method"), overrides, err)
    output = data.get("output")
    if not isinstance(output, dict) or len(output) != 1 or next(iter(output)) not in OUTPUT_KINDS:
        raise err(f"'output' must be a mapping with exactly one of {list(OUTPUT_KINDS)} "
                  "(e.g. output: {op: {column: art.r}} or output: {fit_error: fit.yaml})")
    kind = next(iter(output))
    if kind == "dynamic" or (method["name"] == "dynamic" and kind != "tran" and kind != "function"):
        raise err(f"method 'dynamic' measures a transient: its output must be 'tran' (got {kind!r})")
    raw = data.get("parameters")
    if raw is None and kind != "fit_error":
        raise err("'parameters' is missing (a list of ID.PARAM or {path, lower, upper, centre, name, event})")
    params = [_parameter(p, i, err) for i, p in enumerate(raw or [])]
    names = [p.name for p in params]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise err(f"parameter name(s) {dup} appear twice; give one of them a distinct 'name'")
    keys = [p.key for p in params]
    dupk = sorted({k for k in keys if keys.count(k) > 1})
    if dupk:
        raise err(f"parameter(s) {dupk} appear twice (same path and event)")
    if method["scheme"] == "additive":
        for p in params:
            if p.lower is None or p.upper is None:
                raise err(f"parameter {p.name!r}: the additive scheme needs 'lower' and 'upper' "
                          "(or use scheme: multiplicative with a 'range' in percent)")
    ties = [_tie(t, i, err) for i, t in enumerate(data.get("ties") or [])]
    for t in ties:
        if t.source not in [p.key for p in params]:
            raise err(f"tie of {t.path}: scale_with {t.source!r} is not one of the varied parameters {keys}")
        if t.path in keys:
            raise err(f"tie of {t.path}: it is also a varied parameter; a parameter is either varied or tied")
    return Spec(params, method, output, ties, seed, str(data.get("description", "")), file)


def _method(raw, overrides, err):
    if raw is None:
        raw = {}
    if isinstance(raw, str):
        raw = {"name": raw}
    if not isinstance(raw, dict):
        raise err("'method' must be a name or a mapping {name: constellation, ...}")
    name = overrides.get("name", raw.get("name", "constellation"))
    if name not in METHODS:
        raise err(f"unknown method {name!r}; choose one of {sorted(METHODS)}")
    allowed = METHODS[name]
    if name != raw.get("name", "constellation"):  # another method asked for: keep what applies
        raw = {k: v for k, v in raw.items() if k in allowed}
    raw = {**raw, **{k: v for k, v in overrides.items() if k in allowed or k == "name"}}
    unknown = set(raw) - set(allowed) - {"name"}
    if unknown:
        raise err(f"method {name}: unknown setting(s) {sorted(unknown)}; allowed: {sorted(allowed)}")
    m = {"name": name, **allowed, **{k: v for k, v in raw.items() if k != "name"}}
    if m["scheme"] not in SCHEMES:
        raise err(f"method {name}: scheme {m['scheme']!r}; choose 'additive' or 'multiplicative'")
    rng = m["range"]
    if isinstance(rng, str):
        rng = rng.replace("%", "").strip()
    try:
        m["range"] = float(rng)
    except (TypeError, ValueError):
        raise err(f"method {name}: range {m['range']!r} must be a percentage (e.g. 10 or '10 %')") from None
    if not 0 < m["range"] < 100:
        raise err(f"method {name}: range {m['range']} % must lie between 0 and 100 (exclusive)")
    for k in ("n", "designs", "trajectories", "levels", "resamples"):
        if k in m and (not isinstance(m[k], int) or isinstance(m[k], bool) or m[k] < 1):
            raise err(f"method {name}: {k} must be a positive integer, got {m[k]!r}")
    if name == "morris" and (m["levels"] < 2 or m["levels"] % 2):
        raise err(f"method morris: levels must be even and >= 2 (SALib), got {m['levels']}")
    if name == "sobol" and m["n"] & (m["n"] - 1):
        raise err(f"method sobol: n must be a power of 2 (Sobol' sequence), got {m['n']}")
    if m.get("step") is not None:
        try:
            m["step"] = float(m["step"])
        except (TypeError, ValueError):
            raise err(f"method {name}: step {m['step']!r} must be a number") from None
        if not 0 < m["step"] < 0.5:
            raise err(f"method {name}: step {m['step']} must lie in (0, 0.5) (a fraction of the range)")
    if "conf_level" in m and not 0 < float(m["conf_level"]) < 1:
        raise err(f"method sobol: conf_level {m['conf_level']} must lie in (0, 1)")
    return m


def _parameter(p, i, err):
    if isinstance(p, str):
        p = {"path": p}
    if not isinstance(p, dict) or "path" not in p:
        raise err(f"parameter {i}: expected ID.PARAM or a mapping with 'path' (got {p!r})")
    unknown = set(p) - {"path", "name", "lower", "upper", "centre", "event"}
    if unknown:
        raise err(f"parameter {i} ({p['path']}): unknown key(s) {sorted(unknown)}; "
                  "allowed: path, name, lower, upper, centre, event")
    path = p["path"]
    if not isinstance(path, str) or not path.strip():
        raise err(f"parameter {i}: path {path!r} must be ID.PARAM")
    event = p.get("event")
    if event is not None:
        from ..units import UnitError, parse_quantity
        try:
            event = parse_quantity(event, "s", f"parameter {path} event")
        except UnitError as exc:
            raise err(str(exc)) from None
    name = str(p.get("name", path if event is None else f"{path}@{event:g}s"))
    return Parameter(name, path, p.get("lower"), p.get("upper"), p.get("centre"), event)


def _tie(t, i, err):
    if not isinstance(t, dict) or "path" not in t or "scale_with" not in t:
        raise err(f"tie {i}: expected {{path: ID.PARAM, scale_with: ID.PARAM, power: -1}} (got {t!r})")
    unknown = set(t) - {"path", "scale_with", "power"}
    if unknown:
        raise err(f"tie {i}: unknown key(s) {sorted(unknown)}; allowed: path, scale_with, power")
    try:
        power = float(t.get("power", 1.0))
    except (TypeError, ValueError):
        raise err(f"tie {i}: power {t.get('power')!r} must be a number") from None
    return Tie(str(t["path"]), str(t["scale_with"]), power)
