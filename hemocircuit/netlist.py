"""YAML netlists: reading, ``extends`` chains with add/remove/change, ``${name}`` parameters.

The result is a plain :class:`Netlist` of :class:`ElementSpec` (raw values, still strings with
units); turning values into numbers and checking them is the job of :mod:`hemocircuit.build`.
See docs/netlist.md for the format.
"""
from __future__ import annotations

import copy
import os
import re
from dataclasses import dataclass, field

import yaml

from .errors import NetlistError

TOP_KEYS = {"name", "description", "parameters", "elements", "extends", "add", "remove", "change",
            "constraints", "outputs", "input", "derived"}
ELEMENT_KEYS = {"id", "type", "nodes"}
GROUND = "ground"
_REF = re.compile(r"\$\{([A-Za-z_][A-Za-z0-9_]*)\}")


@dataclass
class ElementSpec:
    id: str
    type: str
    nodes: list
    values: dict  # parameter/option name -> raw value (str with unit, number, bool, mapping)
    file: str | None = None


@dataclass
class Netlist:
    name: str
    description: str
    elements: list
    parameters: dict
    constraints: list
    file: str | None = None
    base_dir: str | None = None
    #: outputs of interest {use: [column or derived name]} ('default' and hemocircuit.outputs.USES)
    outputs: dict = field(default_factory=dict)
    derived: dict = field(default_factory=dict)  # name -> {expr, unit}: quantities computed from columns
    input: str | None = None  # the default input: a source id or ID.PARAM
    outputs_file: str | None = None  # the files that declared outputs / input (for errors)
    input_file: str | None = None

    def element(self, eid):
        for e in self.elements:
            if e.id == eid:
                return e
        raise KeyError(eid)


class _UniqueKeys:
    """Rejects a key repeated in one mapping (PyYAML keeps the last one silently, so
    ``{R: 1 mmHg*s/mL, R: 2 mmHg*s/mL}`` would hide a typo)."""

    def construct_mapping(self, node, deep=False):
        seen = set()
        for key_node, _ in node.value:
            try:
                key = self.construct_object(key_node, deep=True)
                hash(key)
            except (TypeError, yaml.YAMLError):
                continue  # unhashable keys: PyYAML itself reports them
            if key in seen:
                raise yaml.constructor.ConstructorError(
                    "while constructing a mapping", node.start_mark, f"found duplicate key {key!r}",
                    key_node.start_mark)
            seen.add(key)
        return super().construct_mapping(node, deep=deep)


class UniqueKeyLoader(_UniqueKeys, yaml.SafeLoader):
    """A safe YAML loader that rejects a key repeated in one mapping."""


# libyaml's parser (about 5x faster on netlists of thousands of elements), same constructor
# and resolver; an invalid file is re-read with the pure-Python loader for its exact message
_FastUniqueKeyLoader = (type("_FastUniqueKeyLoader", (_UniqueKeys, yaml.CSafeLoader), {})
                        if getattr(yaml, "__with_libyaml__", False) else None)


def _absolutize(value, base_dir):
    """Make ``{file: relative/path}`` entries (waveform tables) absolute against ``base_dir``,
    so a value keeps pointing at its own netlist's folder when another netlist extends it."""
    if isinstance(value, dict):
        out = {}
        for k, v in value.items():
            if k == "file" and isinstance(v, str) and v and not os.path.isabs(v) and "${" not in v:
                v = os.path.normpath(os.path.join(base_dir, v))
            else:
                v = _absolutize(v, base_dir)
            out[k] = v
        return out
    if isinstance(value, list):
        return [_absolutize(v, base_dir) for v in value]
    return value


# ``value: ${Pic}`` inside a flow mapping ``{...}`` is not valid YAML (the braces are flow
# indicators), yet it is the documented netlist shape.  Before parsing, every ``${name}`` becomes
# ``$(name)`` (same length, so YAML error columns stay right), and back afterwards.
_REF_TEXT = re.compile(r"\$\{([A-Za-z_][A-Za-z0-9_]*)\}")
_REF_SAFE = re.compile(r"\$\(([A-Za-z_][A-Za-z0-9_]*)\)")


def _restore_refs(value):
    if isinstance(value, str):
        return _REF_SAFE.sub(lambda m: "${" + m.group(1) + "}", value)
    if isinstance(value, list):
        return [_restore_refs(v) for v in value]
    if isinstance(value, dict):
        return {_restore_refs(k): _restore_refs(v) for k, v in value.items()}
    return value


def _read_yaml(path):
    if not os.path.exists(path):
        raise NetlistError(f"netlist file not found: {path}")
    try:
        with open(path) as fh:
            text = _REF_TEXT.sub(lambda m: "$(" + m.group(1) + ")", fh.read())
        try:
            data = yaml.load(text, Loader=_FastUniqueKeyLoader or UniqueKeyLoader)
        except yaml.YAMLError:
            data = yaml.load(text, Loader=UniqueKeyLoader)  # raises again, with the snippet
        data = _restore_refs(data)
    except yaml.YAMLError as exc:
        raise NetlistError(f"not valid YAML: {exc}", file=path) from None
    except (UnicodeDecodeError, OSError) as exc:
        raise NetlistError(f"cannot read: {exc}", file=path) from None
    if not isinstance(data, dict):
        raise NetlistError("a netlist is a YAML mapping with at least 'elements' (or 'extends')", file=path)
    unknown = set(map(str, data)) - TOP_KEYS
    if unknown:
        raise NetlistError(f"unknown top-level key(s) {sorted(unknown)}; allowed: {sorted(TOP_KEYS)}", file=path)
    return data


def _element_list(items, path, what="elements"):
    if items is None:
        return []
    if not isinstance(items, list):
        raise NetlistError(f"'{what}' must be a list of element mappings", file=path)
    out = []
    for i, item in enumerate(items):
        if not isinstance(item, dict):
            raise NetlistError(f"{what}[{i}] is not a mapping: {item!r}", file=path)
        eid = item.get("id")
        if not isinstance(eid, str) or not eid or not re.match(r"^[A-Za-z_][A-Za-z0-9_]*$", eid):
            raise NetlistError(f"{what}[{i}] needs an 'id' (letters, digits, _; not starting with a digit), "
                               f"got {eid!r}", file=path)
        etype = item.get("type")
        if not isinstance(etype, str):
            raise NetlistError("needs a 'type'", file=path, element=eid)
        nodes = item.get("nodes")
        if not isinstance(nodes, list) or not all(isinstance(n, (str, int)) and not isinstance(n, bool)
                                                  for n in nodes):
            raise NetlistError("'nodes' must be a list of node names", file=path, element=eid)
        values = {str(k): _absolutize(v, os.path.dirname(path)) for k, v in item.items() if k not in ELEMENT_KEYS}
        out.append(ElementSpec(eid, etype, [str(n) for n in nodes], values, path))
    return out


def _load_raw(path, chain):
    path = os.path.abspath(path)
    if path in chain:
        raise NetlistError(f"'extends' cycle: {' -> '.join(chain + [path])}", file=path)
    data = _read_yaml(path)
    base_dir = os.path.dirname(path)
    params = data.get("parameters") or {}
    if not isinstance(params, dict):
        raise NetlistError("'parameters' must be a mapping name -> quantity", file=path)
    constraints = data.get("constraints") or []
    if not isinstance(constraints, list):
        raise NetlistError("'constraints' must be a list", file=path)
    if "extends" in data:
        parent = data["extends"]
        if not isinstance(parent, str):
            raise NetlistError("'extends' must be a file name", file=path)
        ppath = parent if os.path.isabs(parent) else os.path.join(base_dir, parent)
        base = _load_raw(ppath, chain + [path])
        elements = copy.deepcopy(base["elements"])
        merged_params = {**base["parameters"], **params}
        constraints = base["constraints"] + constraints
        if "elements" in data:
            raise NetlistError("a netlist that 'extends' another states its difference with add/remove/change, "
                               "not 'elements'", file=path)
        ids = [e.id for e in elements]
        remove = data.get("remove") or []
        if not isinstance(remove, list):
            raise NetlistError("'remove' must be a list of element ids", file=path)
        for rid in remove:
            if rid not in ids:
                raise NetlistError(f"cannot remove '{rid}': no such element in {ppath}", file=path, element=rid)
        elements = [e for e in elements if e.id not in set(remove)]
        change = data.get("change") or {}
        if not isinstance(change, dict):
            raise NetlistError("'change' must be a mapping {ID: {param: value}}", file=path)
        for cid, kv in change.items():
            match = [e for e in elements if e.id == cid]
            if not match:
                raise NetlistError(f"cannot change '{cid}': no such element", file=path, element=str(cid))
            if not isinstance(kv, dict):
                raise NetlistError("'change' entries must be mappings {param: value}", file=path, element=cid)
            for k, v in kv.items():
                if k == "id":
                    raise NetlistError("cannot change an element's id", file=path, element=cid)
                if k == "type":
                    match[0].type = v if isinstance(v, str) else str(v)
                elif k == "nodes":
                    if not isinstance(v, list) or not all(isinstance(n, (str, int)) and not isinstance(n, bool)
                                                          for n in v):
                        raise NetlistError("'nodes' must be a list of node names", file=path, element=cid)
                    match[0].nodes = [str(n) for n in v]
                else:
                    match[0].values[str(k)] = _absolutize(v, base_dir)
                match[0].file = path
        elements += _element_list(data.get("add"), path, "add")
        name = data.get("name", base["name"])
        description = data.get("description", "")
        outputs, outputs_file = (_outputs(data["outputs"], path), path) if "outputs" in data else \
            (base["outputs"], base["outputs_file"])
        inp, input_file = (_input(data["input"], path), path) if "input" in data else (base["input"], base["input_file"])
    else:
        for key in ("add", "remove", "change"):
            if key in data:
                raise NetlistError(f"'{key}' needs 'extends' (it edits a base netlist)", file=path)
        if "elements" not in data:
            raise NetlistError("a netlist needs 'elements' (or 'extends')", file=path)
        elements = _element_list(data["elements"], path)
        merged_params = dict(params)
        name = data.get("name", os.path.splitext(os.path.basename(path))[0])
        description = data.get("description", "")
        outputs, outputs_file = (_outputs(data["outputs"], path), path) if "outputs" in data else ({}, None)
        inp, input_file = (_input(data["input"], path), path) if "input" in data else (None, None)
    derived = data.get("derived") or {}
    if not isinstance(derived, dict) or not all(isinstance(v, dict) and "expr" in v for v in derived.values()):
        raise NetlistError("'derived' must be a mapping name -> {expr: '<expression of columns>', unit: ...}",
                           file=path)
    derived = {**(base["derived"] if "extends" in data else {}), **derived}
    return {"elements": elements, "parameters": merged_params, "constraints": constraints, "name": name,
            "description": description, "outputs": outputs, "base_dir": base_dir, "derived": derived,
            "outputs_file": outputs_file, "input": inp, "input_file": input_file}


def _outputs(value, path):
    """``outputs:`` -> {use: [names]}: a list (the 'default' use) or a mapping use -> list."""
    from .outputs import USES

    if value is None:
        return {}
    if isinstance(value, list):
        value = {"default": value}
    if not isinstance(value, dict):
        raise NetlistError("'outputs' must be a list of column names, or a mapping {use: [column names]} "
                           f"with uses {sorted(USES)}", file=path)
    out = {}
    for use, names in value.items():
        if use not in USES:
            import difflib
            near = difflib.get_close_matches(str(use), list(USES), n=1)
            raise NetlistError(f"outputs: unknown use {use!r}" + (f" (did you mean {near[0]!r}?)" if near else "")
                               + f"; uses: {sorted(USES)}", file=path)
        if not isinstance(names, list) or not all(isinstance(n, str) and n for n in names):
            raise NetlistError(f"outputs{'' if use == 'default' else '.' + str(use)} must be a list of column names",
                               file=path)
        out[use] = list(names)
    return out


def _input(value, path):
    if not isinstance(value, str) or not value:
        raise NetlistError("'input' must be a source element id (or ID.PARAM)", file=path)
    return value


def _substitute(value, params, where):
    """Replace ${name} references (recursively through lists and mappings)."""
    if isinstance(value, str):
        full = _REF.fullmatch(value.strip())
        if full:
            name = full.group(1)
            if name not in params:
                raise NetlistError(f"unknown parameter ${{{name}}}; defined: {sorted(params)}", **where)
            return params[name]
        def repl(m):
            if m.group(1) not in params:
                raise NetlistError(f"unknown parameter ${{{m.group(1)}}}; defined: {sorted(params)}", **where)
            return f"({params[m.group(1)]})"
        return _REF.sub(repl, value)
    if isinstance(value, list):
        return [_substitute(v, params, where) for v in value]
    if isinstance(value, dict):
        return {k: _substitute(v, params, where) for k, v in value.items()}
    return value


def load_netlist(path: str) -> Netlist:
    """Read a netlist file (following ``extends``), substitute parameters, check ids are unique."""
    raw = _load_raw(path, [])
    params = dict(raw["parameters"])
    # parameters may reference earlier parameters
    for _ in range(len(params) + 1):
        changed = False
        for k, v in params.items():
            nv = _substitute(v, {kk: vv for kk, vv in params.items() if kk != k}, {"file": path})
            if nv != v:
                params[k], changed = nv, True
        if not changed:
            break
    seen = {}
    for e in raw["elements"]:
        if e.id in seen:
            raise NetlistError(f"duplicate element id '{e.id}' (also in {seen[e.id]})", file=e.file, element=e.id)
        seen[e.id] = e.file
        e.values = _substitute(e.values, params, {"file": e.file, "element": e.id})
    return Netlist(name=str(raw["name"]), description=str(raw["description"] or ""), elements=raw["elements"],
                   parameters=params, constraints=raw["constraints"], file=os.path.abspath(path),
                   base_dir=raw["base_dir"], outputs=dict(raw["outputs"] or {}), derived=dict(raw["derived"]),
                   input=raw["input"], outputs_file=raw["outputs_file"], input_file=raw["input_file"])
