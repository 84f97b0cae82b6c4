"""The shape of an svZeroDSolver model, checked before anything is built (:func:`check_structure`):
what the importer may then take for granted (block names unique strings, values mappings, junctions
naming vessels that exist, the initial condition a mapping of numbers)."""
from __future__ import annotations

from .. import limits
from ..errors import did_you_mean, excerpt
from .model import (HEART, HEART_IN, HEART_OUT, SECTIONS, SUPPORTED_BC, SUPPORTED_CHAMBERS, SUPPORTED_CLOSED_LOOP,
                    SUPPORTED_JUNCTIONS, SUPPORTED_VALVES, SUPPORTED_VESSELS, as_float, model_error, show)


def check_structure(cfg, path=None):
    """Check the shape of the model before anything is built: each list of blocks a list of
    mappings; each block named by a short printable string used by no other block, with its
    type a string and its values a mapping; connections naming blocks by string, junctions
    naming vessels by their ids; the initial condition a mapping of numbers.  Errors name the
    block (or its place, ``vessels[3]``) and the key.  Returns {section: its blocks}."""
    max_chars = limits.limit("SVZEROD_NAME_CHARS")
    names = {}  # block name -> where it is defined

    def fail(where, msg, block=None):
        return model_error(f"{where}: {msg}", block, path)

    def named(where, v, what, block=None):
        if not isinstance(v, str) or not v:
            raise fail(where, f"{what} must be a block name (a non-empty string), got {show(v)}", block)
        if len(v) > max_chars:
            raise fail(where, f"{what} {show(v)} is {len(v):,} characters long, longer than allowed "
                              f"{limits.how_to_raise('SVZEROD_NAME_CHARS')}", block)
        if not v.isprintable():
            raise fail(where, f"{what} {show(v)} contains control characters; use letters, digits and _", block)
        return v

    def mapping(where, b, key, block, required=True):
        v = b.get(key)
        if v is None and not required:
            return {}
        if not isinstance(v, dict):
            raise fail(where, (f"missing '{key}'" if key not in b else f"'{key}' must be a mapping ({{...}}), got "
                               f"{show(v)}"), block)
        return v

    def name_list(where, b, key, block):
        v = b.get(key, [])
        if not isinstance(v, list):
            raise fail(where, f"'{key}' must be a list of block names, got {show(v)}", block)
        return [named(where, x, f"'{key}[{i}]'", block) for i, x in enumerate(v)]

    def kind(where, b, key, block, choices, default=None):
        v = b.get(key, default)
        if not isinstance(v, str) or v not in choices:
            what = (f"missing '{key}'" if key not in b else f"unknown or unsupported '{key}' {show(v)}"
                    + (did_you_mean(v, choices) if isinstance(v, str) else ""))
            raise fail(where, f"{what} (supported: {', '.join(choices)})", block)
        return v

    out = {}
    for key, name_key in SECTIONS.items():
        items = cfg.get(key)
        if items is None:
            out[key] = []
            continue
        if not isinstance(items, list):
            raise model_error(f"'{key}' must be a list of blocks ([{{...}}, ...]), got {show(items)}", path=path)
        for i, b in enumerate(items):
            if not isinstance(b, dict):
                raise model_error(f"{key}[{i}] must be a block (a mapping {{...}}), got {show(b)}", path=path)
            if name_key is None:
                continue
            if name_key not in b:
                raise model_error(f"{key}[{i}]: missing '{name_key}' (the block's name)", path=path)
            name = named(f"{key}[{i}]", b[name_key], f"'{name_key}'")
            if name in names:
                raise model_error(f"{key}[{i}]: the block name {show(name)} is used twice (also by {names[name]}); "
                                  "every block needs its own name", name, path)
            names[name] = f"{key}[{i}]"
        out[key] = items

    ids = {}
    for i, v in enumerate(out["vessels"]):
        name = v["vessel_name"]
        where = f"vessel '{name}'"
        if "vessel_id" not in v:
            raise fail(where, "missing 'vessel_id'", name)
        vid = v["vessel_id"]
        if isinstance(vid, bool) or not isinstance(vid, (int, str)):
            raise fail(where, f"'vessel_id' must be a whole number (junctions name vessels by it), got "
                              f"{show(vid)}", name)
        if vid in ids:
            raise fail(where, f"'vessel_id' {show(vid)} is also the id of vessel {show(ids[vid])}; every vessel "
                              "needs its own id", name)
        ids[vid] = name
        if not isinstance(v.get("zero_d_element_type"), str):
            kind(where, v, "zero_d_element_type", name, SUPPORTED_VESSELS)
        mapping(where, v, "zero_d_element_values", name)
        bc = mapping(where, v, "boundary_conditions", name, required=False)
        for end in ("inlet", "outlet"):
            if end in bc:
                named(where, bc[end], f"'boundary_conditions.{end}'", name)
    for j in out["junctions"]:
        name = j["junction_name"]
        where = f"junction '{name}'"
        kind(where, j, "junction_type", name, SUPPORTED_JUNCTIONS, "NORMAL_JUNCTION")
        for key in ("inlet_vessels", "outlet_vessels"):
            lst = j.get(key, [])
            if not isinstance(lst, list):
                raise fail(where, f"'{key}' must be a list of vessel ids, got {show(lst)}", name)
            for k, vid in enumerate(lst):
                if isinstance(vid, bool) or not isinstance(vid, (int, str)) or vid not in ids:
                    raise fail(where, f"'{key}[{k}]': no vessel with id {show(vid)}", name)
        for key in ("inlet_blocks", "outlet_blocks"):
            name_list(where, j, key, name)
        mapping(where, j, "junction_values", name, required=False)
    for b in out["boundary_conditions"]:
        name = b["bc_name"]
        where = f"boundary condition '{name}'"
        if not isinstance(b.get("bc_type"), str):
            kind(where, b, "bc_type", name, SUPPORTED_BC)
        mapping(where, b, "bc_values", name)
    for b in out["valves"]:
        name = b["name"]
        where = f"valve '{name}'"
        kind(where, b, "type", name, SUPPORTED_VALVES)
        prm = mapping(where, b, "params", name)
        for key in ("upstream_block", "downstream_block"):
            if key not in prm:
                raise fail(where, f"missing params.{key}", name)
            named(where, prm[key], f"'params.{key}'", name)
    for b in out["chambers"]:
        name = b["name"]
        where = f"chamber '{name}'"
        kind(where, b, "type", name, SUPPORTED_CHAMBERS)
        mapping(where, b, "values", name, required=False)
    for i, b in enumerate(out["closed_loop_blocks"]):
        where = f"closed_loop_blocks[{i}]"
        kind(where, b, "closed_loop_type", HEART, SUPPORTED_CLOSED_LOOP)
        if i:
            raise model_error("only one ClosedLoopHeartAndPulmonary block is allowed (as in svZeroDSolver)", HEART,
                              path)
        mapping(where, b, "parameters", HEART, required=False)
        name_list(where, b, "outlet_blocks", HEART)
        for reserved in (HEART, HEART_IN, HEART_OUT):
            if reserved in names:
                raise model_error(f"{names[reserved]}: the block name '{reserved}' is the closed-loop heart's own "
                                  "(svZeroDSolver names the heart and its junctions so); rename the block", reserved,
                                  path)
    ic = cfg.get("initial_condition")
    if ic is not None:
        if not isinstance(ic, dict):
            raise model_error(f"'initial_condition' must be a mapping variable name -> value, got {show(ic)}",
                              path=path)
        for k, v in ic.items():
            if as_float(v) is None:
                raise model_error(f"initial_condition: '{excerpt(k, 60)[1:-1]}' must be a finite number, got "
                                  f"{show(v)}", path=path)
    return out
