"""From a parsed netlist to checked numbers: component lookup, options, units, bounds.

Produces :class:`ElementData` (numeric parameters in declared units, options, waveforms,
expressions) for every element; errors name the netlist file, element id and parameter.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

from . import limits
from .errors import NetlistError, did_you_mean, excerpt
from .expressions import Expression, Reference, constant_reference, is_expression
from .netlist import Netlist
from .registry import component_types, get_type
from .units import UnitError, parse_quantity
from .waveforms import Constant, parse_waveform
from .names import split_path


@dataclass
class ElementData:
    id: str
    cls: type
    nodes: list
    opts: dict
    values: dict  # param -> float (declared unit)
    file: str | None
    waveforms: dict = field(default_factory=dict)  # param -> Waveform (non-constant)
    expressions: dict = field(default_factory=dict)  # param -> Expression
    raw: dict = field(default_factory=dict)

    @property
    def where(self):
        return {"file": self.file, "element": self.id}

    def __deepcopy__(self, memo):
        # immutable once the circuit is assembled (parameter changes live in the circuit's
        # arrays), so copies of a circuit share it: copying thousands of elements cost ~0.6 s
        return self


def _option_value(cls, name, raw, where):
    """An option's value checked against its declaration (kind, choices, bounds)."""
    opt = cls.options[name]
    val = raw
    kinds = opt.kind if isinstance(opt.kind, tuple) else (opt.kind,)
    if bool in kinds and not isinstance(raw, bool):
        if isinstance(raw, str) and raw.lower() in ("true", "false", "yes", "no"):
            val = raw.lower() in ("true", "yes")
        else:
            raise NetlistError(f"option '{name}' must be true or false, got {excerpt(raw, 40)}", **where)
    elif int in kinds and float not in kinds and not isinstance(raw, bool):
        try:
            val = int(raw)
            if val != raw and str(val) != str(raw):
                raise ValueError
        except (TypeError, ValueError, OverflowError):
            raise NetlistError(f"option '{name}' must be an integer, got {excerpt(raw, 40)}", **where) from None
    elif float in kinds:
        try:  # YAML 1.1 reads 1e-20 (no dot) as a string
            if isinstance(raw, bool) or not isinstance(raw, (int, float, str)):
                raise ValueError
            val = float(raw)
        except (TypeError, ValueError, OverflowError):
            raise NetlistError(f"option '{name}' must be a number{f' [{opt.unit}]' if opt.unit else ''}, got "
                               f"{excerpt(raw, 40)}", **where) from None
    if opt.choices is not None and val not in opt.choices:
        raise NetlistError(f"option '{name}' must be one of {list(opt.choices)}, got {excerpt(raw, 40)}"
                           f"{did_you_mean(raw, opt.choices) if isinstance(raw, str) else ''}", **where)
    if isinstance(val, (int, float)) and not isinstance(val, bool) and opt.violates(np.array([float(val)])).any():
        raise NetlistError(f"option '{name}' = {val!r} is out of range: need {opt.bounds_text()}", **where)
    return val


def parse_element(spec, netlist_file=None) -> ElementData:
    where = {"file": spec.file or netlist_file, "element": spec.id}
    cls = get_type(spec.type) if isinstance(spec.type, str) else None
    if cls is None:
        types = component_types()
        raise NetlistError(f"unknown component type {excerpt(spec.type, 40)}{did_you_mean(spec.type, types)}; "
                           f"known types: {sorted(types)}", **where)
    if len(spec.nodes) != len(cls.terminals):
        raise NetlistError(f"type '{spec.type}' has {len(cls.terminals)} terminals {list(cls.terminals)}, "
                           f"got {len(spec.nodes)} node(s) {spec.nodes}", **where)
    opts = {}
    for name, raw in spec.values.items():
        if name in cls.options:
            opts[name] = _option_value(cls, name, raw, where)
    unknown = [k for k in spec.values if k not in cls.options and k not in cls.parameters]
    if unknown:
        raise NetlistError(f"unknown parameter(s) {[k[:40] for k in unknown[:5]]}"
                           f"{did_you_mean(unknown[0], list(cls.parameters) + list(cls.options))} for type "
                           f"'{spec.type}'; it takes "
                           f"{sorted(cls.parameters)}" + (f" and options {sorted(cls.options)}" if cls.options else ""),
                           **where)
    try:
        comp = cls(opts)
    except (ValueError, TypeError) as exc:  # a component's own check of its options
        raise NetlistError(f"options {opts}: {exc}", **where) from None
    defaults = comp.defaults()
    data = ElementData(spec.id, cls, list(spec.nodes), comp.opts, {}, where["file"], raw=dict(spec.values))
    base_dir = os.path.dirname(where["file"]) if where["file"] else None
    for name, par in cls.parameters.items():
        raw = spec.values.get(name, defaults.get(name, par.default))
        if raw is None:
            raise NetlistError(f"missing parameter '{name}' [{par.unit}] ({par.doc})", **where)
        if is_expression(raw):
            data.expressions[name] = raw  # compiled later, when all elements are known
            data.values[name] = np.nan
            continue
        if isinstance(raw, dict) and name in cls.waveform_params:
            wf = parse_waveform(raw, par.unit, base_dir, {**where})
            if isinstance(wf, Constant):
                data.values[name] = wf.value
            else:
                data.values[name] = 0.0
                data.waveforms[name] = wf
            continue
        if isinstance(raw, (int, float)) and not isinstance(raw, bool) and name in defaults and name not in spec.values:
            data.values[name] = float(raw)  # preset values are already numbers in the declared unit
            continue
        if isinstance(raw, str) and len(raw) > limits.limit("QUANTITY_CHARS"):
            raise NetlistError(f"parameter '{name}': a quantity of {len(raw):,} characters "
                               f"{limits.how_to_raise('QUANTITY_CHARS')}", **where)
        try:
            data.values[name] = parse_quantity(raw, par.unit, f"parameter '{name}'")
        except UnitError as exc:
            raise NetlistError(str(exc), **where) from None
    check_values(data)
    return data


def check_values(data: ElementData, values: dict | None = None, waveforms: dict | None = None,
                 relations: bool = True):
    """Bounds and cross-parameter checks (also used for --set and protocol events).
    ``waveforms``: {name: waveform or None} in effect with ``values`` where they differ from
    the netlist's (a value set with_values replaces its waveform; a waveform set replaces it).
    ``relations`` False: the bounds only (ParameterSet.with_values checks the relations once
    every value of its mapping is in, with :func:`check_relations`)."""
    values = data.values if values is None else values
    waveforms = {**data.waveforms, **(waveforms or {})}
    for name, val in values.items():
        if name in data.expressions:
            continue
        par = data.cls.parameters[name]
        arr = np.atleast_1d(np.asarray(val, dtype=float))
        wf = waveforms.get(name)
        if wf is not None and par.lower is not None or wf is not None and par.upper is not None:
            # the value in use is the slot plus the waveform: check the waveform's whole range
            lo, hi = wf.value_range()
            for edge, what in ((arr + lo, "lowest"), (arr + hi, "highest")):
                if par.violates(edge).any():
                    raise NetlistError(f"parameter '{name}': its waveform's {what} value {float(edge[0]):g} "
                                       f"{par.unit} is not physical: need {par.bounds_text()}", **data.where)
            continue
        if par.violates(arr).any():
            raise NetlistError(f"parameter '{name}' = {float(arr[par.violates(arr)][0]):g} {par.unit} is not "
                               f"physical: need {par.bounds_text()}", **data.where)
    if relations:
        merged = {**data.values, **values}
        check_relations(data, {k: np.atleast_2d(np.asarray(v, dtype=float)) for k, v in merged.items()
                               if k not in data.expressions})


def check_relations(data: ElementData, p: dict):
    """The element type's cross-parameter checks (Component.check) of its values ``p`` {name:
    (1 or B, 1 or E)}; the first failure is an error naming the element."""
    for _, msg in data.cls(data.opts).check(p):
        raise NetlistError(msg, **data.where)


def compile_expressions(elements: list[ElementData], netlist: Netlist):
    """Turn expression strings into Expression objects, resolving references."""
    by_id = {e.id: e for e in elements}
    for e in elements:
        for name, text in list(e.expressions.items()):
            if isinstance(text, Expression):
                continue

            def resolve(elem, attr, e=e):
                if elem is None:
                    if attr not in netlist.parameters:
                        raise NetlistError(f"expression for '{name}': unknown name '{attr}' (netlist parameters: "
                                           f"{sorted(netlist.parameters)})", **e.where)
                    return constant_reference(attr, netlist.parameters[attr], e.where)
                other = by_id.get(elem)
                if other is None:
                    raise NetlistError(f"expression for '{name}': no element '{elem}'", **e.where)
                if elem == e.id:
                    raise NetlistError(f"expression for '{name}' refers to its own element", **e.where)
                if attr in other.cls.parameters:
                    if attr in other.expressions:
                        raise NetlistError(f"expression for '{name}': {elem}.{attr} is itself an expression",
                                           **e.where)
                    return Reference(elem, attr, other.cls.parameters[attr].unit, "param")
                obs = {o.name: o for o in other.cls(other.opts).observables()}
                if attr in obs and obs[attr].state_only:
                    return Reference(elem, attr, obs[attr].unit, "observable")
                raise NetlistError(f"expression for '{name}': '{elem}' has no parameter or state-only observable "
                                   f"'{attr}' (observables: {sorted(k for k, o in obs.items() if o.state_only)})",
                                   **e.where)

            e.expressions[name] = Expression(text, e.cls.parameters[name].unit, resolve, e.where)


def check_expression_values(elements: list[ElementData]):
    """Bounds of expression parameters that follow only constants and other parameters
    (those that follow states are checked by nothing but the solve)."""
    by_id = {e.id: e for e in elements}
    for e in elements:
        for name, ex in e.expressions.items():
            if any(r.kind == "observable" for r in ex.refs.values()):
                continue
            vals = {k: np.asarray(by_id[r.element].values[r.name], dtype=float)
                    for k, r in ex.refs.items() if r.kind == "param"}
            try:
                with np.errstate(all="ignore"):
                    v = float(np.asarray(ex.evaluate(vals), dtype=float).reshape(-1)[0])
            except (ArithmeticError, ValueError, TypeError) as exc:
                raise NetlistError(f"expression for '{name}' ({ex.text}) cannot be evaluated: {exc}",
                                   **e.where) from None
            par = e.cls.parameters[name]
            if par.violates(np.array([v])).any():
                raise NetlistError(f"parameter '{name}' = {ex.text} = {v:g} {par.unit} is not physical: "
                                   f"need {par.bounds_text()}", **e.where)


def parse_netlist(netlist: Netlist) -> list[ElementData]:
    elements = [parse_element(spec, netlist.file) for spec in netlist.elements]
    compile_expressions(elements, netlist)
    check_expression_values(elements)
    return elements


def path_problem(circuit, path, options=True) -> str | None:
    """What is wrong with the parameter path ``path`` (ID.PARAM, or ID.OPTION when ``options``)
    of ``circuit``, with the close matches ("did you mean 'art.tau_Ca'?"), or None if it is fine."""
    if not isinstance(path, str) or "." not in path:
        return f"{excerpt(path, 60)} is not an ID.PARAM path (e.g. Pa.value)"
    eid, name = split_path(path)
    e = circuit.elements.get(eid)
    if e is None:
        return f"no element {excerpt(eid, 40)}{did_you_mean(eid, circuit.elements)}"
    names = list(e.cls.parameters) + (list(e.cls.options) if options else [])
    if name not in names:
        full = [f"{eid}.{n}" for n in names]
        opts = f" and options {sorted(e.cls.options)}" if options and e.cls.options else ""
        return (f"element '{eid}' ({e.cls.type_name}) has no parameter {excerpt(name, 40)}"
                f"{did_you_mean(path, full)}; its parameters: {sorted(e.cls.parameters)}{opts}")
    return None
