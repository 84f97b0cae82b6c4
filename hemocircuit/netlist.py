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


from . import inputs, limits
from .access import Access
from .errors import NetlistError, did_you_mean, excerpt

TOP_KEYS = {"name", "description", "parameters", "elements", "extends", "add", "remove", "change",
            "constraints", "outputs", "input", "derived", "ic", "instances", "ports"}
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
    #: a transient's starting perturbation {ID.STATE: value} (applied to the operating point
    #: like --ic, which overrides it state by state)
    ic: dict = field(default_factory=dict)
    #: the folders this netlist's files may be read from (hemocircuit.access), for protocol tables
    allowed: list = field(default_factory=list)
    #: the files read to load it (hemocircuit.inputs.Sources: extends chain, tables), for provenance
    sources: object = None

    def element(self, eid):
        for e in self.elements:
            if e.id == eid:
                return e
        raise KeyError(eid)


def resolve_files(value, base_dir, access, where):
    """Make ``{file: relative/path}`` entries (waveform tables) absolute against ``base_dir``,
    so a value keeps pointing at its own netlist's folder when another netlist extends it;
    a path outside the allowed folders is refused here, before anything reads it."""
    if isinstance(value, dict):
        out = {}
        for k, v in value.items():
            if k == "file" and isinstance(v, str) and v and "${" not in v:
                v = access.resolve(v, base_dir, "table file", where)
            else:
                v = resolve_files(v, base_dir, access, where)
            out[k] = v
        return out
    if isinstance(value, list):
        return [resolve_files(v, base_dir, access, where) for v in value]
    return value


def read_yaml_file(path, what="netlist", access=None):
    """A netlist or protocol YAML file under the input policy (hemocircuit.inputs: size, depth,
    alias and value limits, repeated keys refused); ``${name}`` may stand unquoted in flow
    mappings.  Errors quote at most a short excerpt of the file."""
    return inputs.read_yaml(path, what + " file", access, refs=True)


def read_json_file(path, what="netlist", access=None):
    """A JSON file under the input policy (hemocircuit.inputs)."""
    return inputs.read_json(path, what + " file", access)


def _read_yaml(path, svzerod=None, access=None):
    """The mapping of a netlist file; an svZeroDSolver JSON model through the importer, in
    ``svzerod['units']`` (None: the importer's guess, cgs unless the model says m^3; the dict
    records in 'used' that a model was read with it)."""
    if str(path).lower().endswith(".json"):
        data = read_json_file(path, access=access)
        from .svzerod.importer import is_svzerod_model, netlist_of

        if is_svzerod_model(data):  # an svZeroDSolver model: read through the importer
            if svzerod is not None:
                svzerod["used"] = True
            return netlist_of(data, path, (svzerod or {}).get("units"))
    data = read_yaml_file(path, access=access)  # a netlist (JSON is YAML; its ${name} references resolved)
    if not isinstance(data, dict):
        raise NetlistError("a netlist is a YAML mapping with at least 'elements' (or 'extends')", file=path)
    unknown = sorted(set(map(str, data)) - TOP_KEYS)
    if unknown:
        shown = ", ".join(excerpt(k, 40) for k in unknown[:5]) + (f" and {len(unknown) - 5} more"
                                                                  if len(unknown) > 5 else "")
        raise NetlistError(f"unknown top-level key(s) {shown}{did_you_mean(unknown[0], TOP_KEYS)}; allowed: "
                           f"{sorted(TOP_KEYS)}", file=path)
    return data


def _element_list(items, path, access, what="elements"):
    if items is None:
        return []
    if not isinstance(items, list):
        raise NetlistError(f"'{what}' must be a list of element mappings", file=path)
    limits.check_elements(len(items), path)
    out = []
    for i, item in enumerate(items):
        if not isinstance(item, dict):
            raise NetlistError(f"{what}[{i}] is not a mapping: {excerpt(item)}", file=path)
        eid = item.get("id")
        if not isinstance(eid, str) or not eid or not re.match(r"^[A-Za-z_][A-Za-z0-9_]*$", eid):
            raise NetlistError(f"{what}[{i}] needs an 'id' (letters, digits, _; not starting with a digit), "
                               f"got {excerpt(eid, 40)}", file=path)
        etype = item.get("type")
        if not isinstance(etype, str):
            raise NetlistError("needs a 'type'", file=path, element=eid)
        nodes = item.get("nodes")
        if not isinstance(nodes, list) or not all(isinstance(n, (str, int)) and not isinstance(n, bool)
                                                  for n in nodes):
            raise NetlistError("'nodes' must be a list of node names", file=path, element=eid)
        values = {str(k): resolve_files(v, os.path.dirname(path), access, {"file": path, "element": eid})
                  for k, v in item.items() if k not in ELEMENT_KEYS}
        out.append(ElementSpec(eid, etype, [str(n) for n in nodes], values, path))
    return out


def _edit(elements, remove, change, path, of, access):
    """``remove: [ID]`` and ``change: {ID: {param: value}}`` of the netlist at ``path``, applied to
    the ``elements`` of ``of`` (the netlist it extends, or an instance's netlist)."""
    base_dir = os.path.dirname(path)
    ids = [e.id for e in elements]
    if not isinstance(remove, list):
        raise NetlistError("'remove' must be a list of element ids", file=path)
    for rid in remove:
        if rid not in ids:
            raise NetlistError(f"cannot remove '{rid}': no such element in {of}{did_you_mean(rid, ids)}",
                               file=path, element=str(rid))
    elements = [e for e in elements if e.id not in set(remove)]
    if not isinstance(change, dict):
        raise NetlistError("'change' must be a mapping {ID: {param: value}}", file=path)
    for cid, kv in change.items():
        match = [e for e in elements if e.id == cid]
        if not match:
            raise NetlistError(f"cannot change '{cid}': no such element{did_you_mean(cid, ids)}", file=path,
                               element=str(cid))
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
                match[0].values[str(k)] = resolve_files(v, base_dir, access, {"file": path, "element": cid})
            match[0].file = path
    return elements


def _load_raw(path, chain, access, svzerod=None):
    path = os.path.abspath(path)
    if path in chain:
        raise NetlistError(f"'extends' cycle: {' -> '.join(chain + [path])}", file=path)
    data = _read_yaml(path, svzerod, access if chain else None)  # the first file: the user's choice
    base_dir = os.path.dirname(path)
    params = data.get("parameters") or {}
    if not isinstance(params, dict):
        raise NetlistError("'parameters' must be a mapping name -> quantity", file=path)
    constraints = data.get("constraints") or []
    if not isinstance(constraints, list):
        raise NetlistError("'constraints' must be a list", file=path)
    for c in constraints:
        if not isinstance(c, dict) or not isinstance(c.get("node"), (str, int)) or isinstance(c.get("node"), bool):
            raise NetlistError(f"each constraint is a mapping {{node: NAME, volume: ...}} or {{node: NAME, pressure: "
                               f"..., when: {{...}}}}; got {excerpt(c)}", file=path)
    constraints = resolve_files(constraints, base_dir, access, {"file": path})  # tables in 'when:'
    params = resolve_files(params, base_dir, access, {"file": path})
    if "extends" in data:
        parent = data["extends"]
        if not isinstance(parent, str):
            raise NetlistError("'extends' must be a file name", file=path)
        ppath = access.resolve(parent, base_dir, "'extends'", {"file": path})
        base = _load_raw(ppath, chain + [path], access, svzerod)
        elements = copy.deepcopy(base["elements"])
        merged_params = {**base["parameters"], **params}
        constraints = base["constraints"] + constraints
        if "elements" in data:
            raise NetlistError("a netlist that 'extends' another states its difference with add/remove/change, "
                               "not 'elements'", file=path)
        elements = _edit(elements, data.get("remove") or [], data.get("change") or {}, path, ppath, access)
        elements += _element_list(data.get("add"), path, access, "add")
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
        elements = _element_list(data["elements"], path, access)
        merged_params = dict(params)
        name = data.get("name", os.path.splitext(os.path.basename(path))[0])
        description = data.get("description", "")
        outputs, outputs_file = (_outputs(data["outputs"], path), path) if "outputs" in data else ({}, None)
        inp, input_file = (_input(data["input"], path), path) if "input" in data else (None, None)
    if "instances" in data:
        from .subcircuits import expand
        inst = expand(data["instances"], path, lambda name, overrides, where:
                      _load_child(name, overrides, where, path, chain, access, svzerod))
        elements = elements + inst.elements
        constraints = constraints + inst.constraints
        clash = sorted(set(inst.parameters) & set(merged_params))
        if clash:
            raise NetlistError(f"parameter '{clash[0]}' is also the name under which an instance carries its "
                               "netlist's parameter of that name (INSTANCE__NAME); rename this one", file=path)
        merged_params = {**merged_params, **inst.parameters}
    derived = data.get("derived") or {}
    if not isinstance(derived, dict) or not all(isinstance(v, dict) and "expr" in v for v in derived.values()):
        raise NetlistError("'derived' must be a mapping name -> {expr: '<expression of columns>', unit: ...}",
                           file=path)
    derived = {**(base["derived"] if "extends" in data else {}), **derived}
    ic = data.get("ic") or {}
    if not isinstance(ic, dict) or not all(isinstance(k, str) and isinstance(v, (str, int, float))
                                           and not isinstance(v, bool) for k, v in ic.items()):
        raise NetlistError("'ic' must be a mapping ID.STATE -> value with its unit (a transient's starting "
                           "perturbation, e.g. {art.dCa: 1e-9 M/s})", file=path)
    ic = {**(base["ic"] if "extends" in data else {}), **(inst.ic if "instances" in data else {}), **ic}
    ports = data.get("ports")
    if ports is not None and (not isinstance(ports, list) or not all(isinstance(p, (str, int)) and
                                                                     not isinstance(p, bool) for p in ports)):
        raise NetlistError("'ports' must be a list of node names (the nodes an instance of this netlist connects)",
                           file=path)
    ports = [str(p) for p in ports] if ports is not None else (base.get("ports") if "extends" in data else None)
    return {"ports": ports, "elements": elements, "parameters": merged_params, "constraints": constraints, "name": name,
            "description": description, "outputs": outputs, "base_dir": base_dir, "derived": derived,
            "outputs_file": outputs_file, "input": inp, "input_file": input_file, "ic": ic}


def _load_child(name, overrides, where, path, chain, access, svzerod):
    """An instance's netlist, its ${} parameters (with the instance's overrides) substituted."""
    child = access.resolve(name, os.path.dirname(path), f"instance '{where['element']}': netlist", where)
    if not os.path.isfile(child):
        raise NetlistError(f"instance '{where['element']}': netlist file not found: {child}", **where)
    if os.path.abspath(child) in chain + [path]:
        raise NetlistError(f"instances form a cycle: {' -> '.join(chain + [path, os.path.abspath(child)])}", **where)
    raw = _load_raw(child, chain + [path], access, svzerod)
    unknown = [k for k in overrides if k not in raw["parameters"]]
    if unknown:
        raise NetlistError(f"{child} has no parameter '{unknown[0]}'{did_you_mean(unknown[0], raw['parameters'])}",
                           **where)
    params = _resolve_parameters({**raw["parameters"], **overrides}, child)
    for e in raw["elements"]:
        if any(_refs(v) for v in e.values.values()):
            e.values = resolve_files(_substitute(e.values, params, {"file": e.file, "element": e.id}),
                                     os.path.dirname(e.file), access, {"file": e.file, "element": e.id})
    return {"elements": raw["elements"], "constraints": raw["constraints"], "ic": raw["ic"], "ports": raw["ports"],
            "parameters": params, "file": child,
            "edit": lambda elements, remove, change: _edit(elements, remove, change, path, child, access)}


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
    """Replace ${name} references (recursively through lists and mappings); the result may
    not grow beyond the VALUE_CHARS limit (references that double at each level)."""
    if isinstance(value, str):
        full = _REF.fullmatch(value.strip())
        if full:
            return params[_known(full.group(1), params, where)]

        def repl(m):
            return f"({params[_known(m.group(1), params, where)]})"
        out = _REF.sub(repl, value)
        limits.check_value_length(out, where, f"the value {excerpt(value, 40)} after ${{}} substitution")
        return out
    if isinstance(value, list):
        return [_substitute(v, params, where) for v in value]
    if isinstance(value, dict):
        return {k: _substitute(v, params, where) for k, v in value.items()}
    return value


def _known(name, params, where):
    if name not in params:
        raise NetlistError(f"unknown parameter ${{{name}}}{did_you_mean(name, params)}; defined: "
                           f"{sorted(params)[:50]}", **where)
    return name


def _refs(value):
    if isinstance(value, str):
        return _REF.findall(value)
    if isinstance(value, list):
        return [r for v in value for r in _refs(v)]
    if isinstance(value, dict):
        return [r for v in value.values() for r in _refs(v)]
    return []


def _resolve_parameters(params, path):
    """Substitute the parameters into each other (a parameter may reference others, in any
    order); a cycle of references is an error naming it."""
    done: dict = {}

    def resolve(name, stack):
        if name in done:
            return done[name]
        if name in stack:
            cycle = " -> ".join(stack[stack.index(name):] + [name])
            raise NetlistError(f"parameters refer to each other in a cycle: {cycle}", file=path)
        stack.append(name)
        where = {"file": path}
        for ref in _refs(params[name]):
            if ref in params:
                resolve(ref, stack)
        try:
            done[name] = _substitute(params[name], done, where)
        except NetlistError as exc:
            raise NetlistError(f"parameter '{name}': {exc.bare_message}", file=path) from None
        stack.pop()
        return done[name]

    for name in params:
        resolve(name, [])
    return done


def load_netlist(path: str, allow_paths=None, svzerod_units=None) -> Netlist:
    """Read a netlist file (following ``extends``), substitute parameters, check ids are unique.

    Files named inside (``extends``, table ``file:``) must lie in the allowed folders (see
    :mod:`hemocircuit.access`); ``allow_paths`` adds folders.  ``svzerod_units``: the unit
    system of an svZeroDSolver JSON model's numbers (hemocircuit.svzerod.model.UNIT_SYSTEMS;
    an error for a hemocircuit netlist)."""
    path = inputs.check_path(path, "netlist file")
    access = Access.for_netlist(path, allow_paths)
    svzerod = None if svzerod_units is None else {"units": svzerod_units, "used": False}
    raw = _load_raw(path, [], access, svzerod)
    if svzerod is not None and not svzerod["used"]:
        raise NetlistError(f"a unit system for svZeroDSolver numbers ({svzerod_units!r}) was given, but neither "
                           "this netlist nor a netlist it extends is an svZeroDSolver JSON model (hemocircuit "
                           "quantities carry their units): drop --svzerod-units", file=path)
    limits.check_elements(len(raw["elements"]), path)
    params = _resolve_parameters(dict(raw["parameters"]), path)
    seen = {}
    for e in raw["elements"]:
        if e.id in seen:
            raise NetlistError(f"duplicate element id '{e.id}' (also in {seen[e.id]})", file=e.file, element=e.id)
        seen[e.id] = e.file
        where = {"file": e.file, "element": e.id}
        if any(_refs(v) for v in e.values.values()):
            e.values = _substitute(e.values, params, where)
            # table file names that came from ${} parameters: resolved and checked now
            e.values = resolve_files(e.values, os.path.dirname(e.file), access, where)
    return Netlist(name=str(raw["name"]), description=str(raw["description"] or ""), elements=raw["elements"],
                   parameters=params, constraints=raw["constraints"], file=os.path.abspath(path),
                   base_dir=raw["base_dir"], outputs=dict(raw["outputs"] or {}), derived=dict(raw["derived"]),
                   input=raw["input"], outputs_file=raw["outputs_file"], input_file=raw["input_file"], ic=raw["ic"],
                   allowed=list(access.folders))
