"""Import an svZeroDSolver JSON model as an ordinary hemocircuit netlist.

Their JSON carries no units; ``units`` names the system of the numbers (``cgs``: pressure
dyn/cm^2, flow mL/s, volume mL, time s, as in their cases; ``mmHg``: mmHg, mL/s, mL, s).
Every value is written with its unit, so the netlist converts to the circuit's mmHg once,
at load time.

Mapping (one element per block, named after it; blocks in components/svzerod/):
  vessels  BloodVessel -> blood_vessel, BloodVesselCRL -> blood_vessel_crl, BloodVesselRC
           (Rpd, Cp) -> blood_vessel_rc (a flow-through RC: Q_in = Q_out), ChamberSphere ->
           chamber_sphere
           (nodes [inlet, outlet, ground]; options capacitive/inductive from C, L != 0)
  junctions NORMAL_JUNCTION -> one node named after the junction (ideal: equal pressures,
           mass conservation); BloodVesselJunction -> one blood_vessel per outlet,
           ``J_outletname`` (their equations are exactly parallel R + stenosis + L branches)
  BCs      FLOW -> flow_source, PRESSURE -> pressure_source (their periodic time series as a
           ``periodic`` pwl waveform: one cycle), RESISTANCE -> resistance_bc,
           RCR -> rcr_bc, CORONARY -> coronary_bc, CORONARY_VAR_RES -> coronary_var_res_bc
Connection nodes are named ``A__B`` (upstream block, downstream block), a normal junction's
node after the junction.  ``SvzModel.columns`` maps their output names (``pressure:A:B``,
``flow:A:B`` and, per vessel, pressure_in/out, flow_in/out) to hemocircuit output columns.
"""
from __future__ import annotations

import json
import math
import os
import re
from dataclasses import dataclass, field

import numpy as np

from .. import limits
from ..errors import NetlistError, did_you_mean, excerpt
from ..units import parse_quantity

UNIT_SYSTEMS = {
    "cgs": {"P": "dyn/cm**2", "Q": "mL/s", "V": "mL", "t": "s", "L": "cm"},
    "mmHg": {"P": "mmHg", "Q": "mL/s", "V": "mL", "t": "s", "L": "cm"},
    "SI": {"P": "Pa", "Q": "m**3/s", "V": "m**3", "t": "s", "L": "m"},
}

SIM_DEFAULTS = {"steady_initial": True, "output_all_cycles": False, "output_variable_based": False,
                "output_mean_only": False, "output_derivative": False, "output_interval": 1,
                "absolute_tolerance": 1e-8}

SUPPORTED_BC = ("FLOW", "PRESSURE", "RESISTANCE", "RCR", "CORONARY", "CORONARY_VAR_RES", "ClosedLoopRCR",
                "ClosedLoopCoronaryLeft", "ClosedLoopCoronaryRight")
SUPPORTED_VALVES = ("ValveTanh", "PiecewiseValve")
SUPPORTED_CHAMBERS = ("ChamberElastanceInductor", "ChamberElastanceInductorExponential", "LinearElastanceChamber",
                      "ChamberSphere")
SUPPORTED_CLOSED_LOOP = ("ClosedLoopHeartAndPulmonary",)
#: their block names of the heart and its two junctions (SimulationParameters.cpp, create_closed_loop)
HEART, HEART_IN, HEART_OUT = "CLH", "J_heart_inlet", "J_heart_outlet"
#: closed-loop coronaries: their block type -> the heart's (pressure scale, elastance, unstressed
#: volume, ventricular volume) they read (ClosedLoopCoronaryLeftBC.cpp / RightBC.cpp)
CLOSED_LOOP_CORONARY = ("ClosedLoopCoronaryLeft", "ClosedLoopCoronaryRight")
_CORONARY_SIDE = {"ClosedLoopCoronaryLeft": ("iml", "Elv_s", "Vlv_u", "V_LV"),
                  "ClosedLoopCoronaryRight": ("imr", "Erv_s", "Vrv_u", "V_RV")}
SUPPORTED_VESSELS = ("BloodVessel", "BloodVesselCRL", "BloodVesselRC", "ChamberSphere")
SUPPORTED_JUNCTIONS = ("NORMAL_JUNCTION", "internal_junction", "BloodVesselJunction")
#: the model's lists of blocks, and the key naming a block in each
SECTIONS = {"vessels": "vessel_name", "junctions": "junction_name", "boundary_conditions": "bc_name",
            "valves": "name", "chambers": "name", "closed_loop_blocks": None}
#: their simulation settings that are true or false (SimulationParameters.cpp)
BOOL_SETTINGS = ("steady_initial", "output_all_cycles", "output_variable_based", "output_mean_only",
                 "output_derivative", "use_cycle_to_cycle_error")


@dataclass
class SvzModel:
    """An imported model: the netlist (a dict, YAML-ready), their simulation settings and the
    map from their output names to hemocircuit columns."""

    name: str
    netlist: dict
    period: float
    sim: dict
    columns: dict = field(default_factory=dict)  # their name -> our column
    factors: dict = field(default_factory=dict)  # their name -> factor from our column's unit to
    # theirs, for variables that are not pressures, flows or chamber volumes (ChamberSphere's)
    block_types: list = field(default_factory=list)
    vessels: list = field(default_factory=list)  # vessel names (their per-block output)
    units: dict = field(default_factory=dict)
    mean_netlist: dict | None = None  # time series at their means (their steady_initial)
    initial: dict = field(default_factory=dict)  # {ID.STATE: quantity}: their initial_condition
    closed: bool = False  # a closed loop (no boundary condition to ground): volume conserved
    initial_given: dict = field(default_factory=dict)  # the states their initial_condition sets

    @property
    def n_cycles(self):
        return int(self.sim["number_of_cardiac_cycles"])

    def with_sim(self, **changes) -> "SvzModel":
        """A copy with these simulation settings changed (this model is left as it is: runs
        derive the settings they used, e.g. their cycle count, without touching the caller's)."""
        import dataclasses

        return dataclasses.replace(self, sim={**self.sim, **changes})

    @property
    def points(self):
        return int(self.sim["number_of_time_pts_per_cardiac_cycle"])


def _err(msg, block=None, path=None):
    return NetlistError(msg, file=path, element=block)


def _ident(name, path):
    s = re.sub(r"[^A-Za-z0-9_]", "_", str(name))  # an element id: ASCII letters, digits, _
    if not s or s[0].isdigit():
        s = "b_" + s
    return s


def _show(v, limit=40) -> str:
    """A short, escaped excerpt of a value from the model, for an error message."""
    if isinstance(v, int) and not isinstance(v, bool) and v.bit_length() > 64:
        return f"an integer of {len(str(abs(v))) if v.bit_length() < 14000 else 'thousands of'} digits"
    if isinstance(v, (dict, list)):
        kind = "a mapping" if isinstance(v, dict) else "a list"
        try:
            return f"{kind} {excerpt(json.dumps(v, default=str, allow_nan=True), limit)}"
        except (ValueError, RecursionError):
            return kind
    return excerpt(v, limit) if isinstance(v, str) else repr(v)


def _as_float(v):
    """``v`` as a float when it is a finite JSON number (not true/false), else None."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return None
    try:
        f = float(v)
    except OverflowError:  # an integer beyond the float range
        return None
    return f if math.isfinite(f) else None


def _whole(v):
    """``v`` as an int when it is a whole JSON number (3 or 3.0; not true/false, not 2.5), else None."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return None
    if isinstance(v, float):
        return int(v) if math.isfinite(v) and v == int(v) else None
    return v


def check_points(cycles, points, path=None, what="simulation_parameters"):
    """Refuse a run of more time points ((points - 1) cycles + 1) than the SVZEROD_POINTS limit:
    their output has one row per point (per block or variable), our run one state per point."""
    total = (points - 1) * cycles + 1
    if total > limits.limit("SVZEROD_POINTS"):
        def shown(n):
            return f"{n:,}" if n < 10 ** 15 else f"about 10^{len(str(n)) - 1 if n < 10 ** 4000 else 'thousands'}"
        raise _err(f"{what}: {shown(cycles)} cycles of {shown(points)} points per cycle are {shown(total)} time "
                   f"points, more than allowed {limits.how_to_raise('SVZEROD_POINTS')}; lower "
                   "number_of_cardiac_cycles or number_of_time_pts_per_cardiac_cycle", path=path)
    return total


def check_period(period, where, block=None, path=None):
    """A cardiac period [s] must be a finite number > 0 and at most the SVZEROD_PERIOD_S limit
    (``where``: what gives it, for the message)."""
    if period is None or not (math.isfinite(period) and period > 0):
        raise _err(f"{where}: the cardiac period is {period!r} s; it must be a finite number > 0", block, path)
    if period > limits.limit("SVZEROD_PERIOD_S"):
        raise _err(f"{where}: a cardiac period of {period:g} s is longer than allowed "
                   f"{limits.how_to_raise('SVZEROD_PERIOD_S')}; give it in seconds", block, path)
    return period


def simulation_settings(raw, path=None) -> dict:
    """Their ``simulation_parameters`` checked (with SIM_DEFAULTS): whole numbers of cycles (>= 1)
    and points per cycle (>= 2) within the SVZEROD_POINTS limit, true/false flags, a positive
    period, output interval and tolerances; errors name the key and say how to fix it."""
    def bad(key, v, want):
        return _err(f"simulation_parameters: '{key}' must be {want}, got {_show(v)}", path=path)

    if not isinstance(raw, dict):
        raise _err(f"'simulation_parameters' must be a mapping, got {_show(raw)}; e.g. "
                   '{"number_of_cardiac_cycles": 10, "number_of_time_pts_per_cardiac_cycle": 101}', path=path)
    sim = {**SIM_DEFAULTS, **raw}
    for key, low, example in (("number_of_cardiac_cycles", 1, 10), ("number_of_time_pts_per_cardiac_cycle", 2, 101)):
        if key not in raw:
            raise _err(f"simulation_parameters: missing '{key}' (e.g. \"{key}\": {example})", path=path)
        n = _whole(raw[key])
        if n is None or n < low:
            extra = " (not a whole number)" if _as_float(raw[key]) is not None and n is None else ""
            raise bad(key, raw[key], f"a whole number >= {low}{extra}, e.g. {example}")
        sim[key] = n
    check_points(sim["number_of_cardiac_cycles"], sim["number_of_time_pts_per_cardiac_cycle"], path)
    for key in BOOL_SETTINGS:
        if not isinstance(sim[key] if key in sim else False, bool):
            raise bad(key, sim[key], "true or false")
    n = _whole(sim["output_interval"])
    if n is None or n < 1:
        raise bad("output_interval", sim["output_interval"], "a whole number >= 1 (write every n-th step)")
    sim["output_interval"] = n
    for key in ("absolute_tolerance", "cardiac_period", "sim_cycle_to_cycle_percent_error"):
        if sim.get(key) is None and key != "absolute_tolerance":
            sim.pop(key, None)  # not given (null): their default
            continue
        v = _as_float(sim[key])
        if v is None or v <= 0 or (key == "sim_cycle_to_cycle_percent_error" and v >= 100):
            raise bad(key, sim[key], "a number between 0 and 100 (percent)" if key.startswith("sim_cycle")
                      else "a finite number > 0" + (" [s]" if key == "cardiac_period" else ""))
        if key == "cardiac_period":
            check_period(v, "simulation_parameters: 'cardiac_period'", path=path)
    return sim


def _fmt(x, unit):
    return f"{float(x)!r} {unit}"


class _Importer:
    def __init__(self, cfg, path, units):
        self.cfg, self.path = cfg, path
        if units not in UNIT_SYSTEMS:
            raise _err(f"unknown unit system {units!r}; choose one of {sorted(UNIT_SYSTEMS)}", path=path)
        self.u = UNIT_SYSTEMS[units]
        P = self.u["P"]
        V, Q = self.u["V"], self.u["Q"]
        self.uR, self.uC, self.uL = f"({P})/({Q})", f"({V})/({P})", f"({P})/({Q})*s"
        self.uS = f"({P})/({Q})**2"
        self.uE = f"({P})/({V})"
        self.elements, self.columns, self.types = [], {}, set()
        self.chamber_elements = []
        self.timed_elements = []  # elements (not chambers) whose 'period' is the model's
        self.element_block = {}  # element id -> the block type whose component it is (importer.add)
        self.extra_columns = {}  # their internal variable -> (our column, factor from its unit to theirs)
        self.factors = {}  # their name -> factor from our column's unit to theirs (not P, Q, Vc)
        self.ids = {}  # block name -> element id
        self.owner = {}  # element id -> block name (both ways: a model of many blocks imports in linear time)
        self.raw = {}  # (block, key) -> (times from 0, values, period) of a time series
        self.means = {}  # id(waveform) -> (waveform, the constant of the steady variant)
        self.pinned_p, self.pinned_q = {}, {}  # node -> (BC name, its value key) of PRESSURE / FLOW

    # --- helpers ------------------------------------------------------------------------
    def id_of(self, name):
        ident = _ident(name, self.path)
        other = self.owner.get(ident)
        if other is not None and other != name:
            raise _err(f"block names {_show(name)} and {_show(other)} map to the same element id {_show(ident)} "
                       "(characters other than letters, digits and _ become _); rename one", name, self.path)
        self.ids[name] = ident
        self.owner[ident] = name
        return ident

    def value(self, block, values, key, default=None):
        """The number ``values[key]`` of block ``block`` (a float), or ``default`` when missing
        and a default is given; anything but a finite number is an error naming the key."""
        if key not in values:
            if default is not None:
                return float(default)
            raise _err(f"block '{block}': missing value '{key}'", block, self.path)
        v = values[key]
        f = _as_float(v)
        if f is None:
            raise _err(f"block '{block}': value '{key}' must be a finite number, got {_show(v)}", block, self.path)
        return f

    def numbers(self, block, items, key):
        """The list ``items`` (value ``key`` of ``block``) as floats: each a finite number."""
        out = []
        for i, x in enumerate(items):
            f = _as_float(x)
            if f is None:
                raise _err(f"block '{block}': '{key}[{i}]' must be a finite number, got {_show(x)}", block, self.path)
            out.append(f)
        return out

    def series(self, block, values, key, unit, steady=False):
        """A constant, or their periodic time series (one cycle, a ``periodic`` pwl waveform)."""
        if key not in values:
            raise _err(f"block '{block}': missing value '{key}'", block, self.path)
        v = values[key]
        if not isinstance(v, list):
            f = self.value(block, values, key)
            return _fmt(f, unit), f
        if not v:
            raise _err(f"block '{block}': time series '{key}' is an empty list; give a number, or values with a "
                       "list 't' of their times", block, self.path)
        vals = np.asarray(self.numbers(block, v, key))
        if len(v) == 1:
            return _fmt(vals[0], unit), float(vals[0])
        t = values.get("t")
        if not isinstance(t, list) or len(t) != len(v):
            raise _err(f"block '{block}': time series '{key}' needs a list 't' of the same length "
                       f"({len(v)} values, {'no t' if not isinstance(t, list) else f'{len(t)} times'})",
                       block, self.path)
        t = np.asarray(self.numbers(block, t, "t"))
        with np.errstate(over="ignore", invalid="ignore"):
            if not np.all(np.diff(t) > 0):
                raise _err(f"block '{block}': the times 't' must increase", block, self.path)
            period = float(t[-1] - t[0])
            mean = float(np.mean(vals))  # their Parameter::to_steady: mean of the samples
        check_period(period, f"block '{block}': its time series 't'", block, self.path)
        if not math.isfinite(mean):
            raise _err(f"block '{block}': the values of '{key}' are too large (their mean overflows)", block,
                       self.path)
        self.note_period(period, block)
        if steady or np.all(vals == vals[0]):  # a constant series stays a constant
            return _fmt(mean, unit), mean
        self.raw[(block, key)] = (t - t[0], vals, period)
        # their Parameter::get: linear interpolation at fmod(t, period), i.e. one cycle repeated
        rows = [[_fmt(tt, "s"), _fmt(vv, unit)] for tt, vv in zip(t - t[0], vals)]
        wave = {"periodic": {"period": _fmt(period, "s"), "pwl": rows}}
        self.means[id(wave)] = (wave, _fmt(mean, unit))
        return wave, mean

    def note_period(self, period, block):
        if self.period is None:
            self.period, self.period_block = period, block
        elif self.period != period:
            raise _err(f"block '{block}': its time series has period {period!r} s, but block "
                       f"'{self.period_block}' has {self.period!r} s (svZeroDSolver needs one cardiac period)",
                       block, self.path)

    def slope(self, block, key, factor, unit):
        """factor * d/dt of a block's series: their linear interpolation's slopes as a periodic
        ``steps`` waveform (0 for a constant or the steady variant)."""
        if (block, key) not in self.raw:
            return _fmt(0.0, unit)
        t, v, period = self.raw[(block, key)]
        with np.errstate(over="ignore", invalid="ignore"):
            d = factor * (np.diff(v) / np.diff(t))
        if not np.all(np.isfinite(d)):
            raise _err(f"block '{block}': the slopes of its time series '{key}' (times the vessel's C or L it "
                       "carries) overflow; check the values and times of the series", block, self.path)
        rows = [[_fmt(tt, "s"), _fmt(dd, unit)] for tt, dd in zip(t[:-1], d)]
        wave = {"periodic": {"period": _fmt(period, "s"), "steps": rows}}
        self.means[id(wave)] = (wave, _fmt(0.0, unit))
        return wave

    def mean_elements(self):
        """The elements of the model with every time series at its mean (their steady_initial's
        model): what run(steady=True) builds, from this run's elements (the waveforms replaced by
        their means, the slopes of the index reduction by 0), without importing the model again."""
        return [{k: self.means[id(v)][1] if isinstance(v, dict) and id(v) in self.means else
                 (list(v) if isinstance(v, list) else v) for k, v in e.items()} for e in self.elements]

    def only_keys(self, block, values, keys):
        """A block's values may hold only ``keys`` (and ``_comment`` entries)."""
        unknown = sorted(str(k) for k in values if not str(k).startswith("_") and k not in keys)
        if unknown:
            shown = [excerpt(k, 40)[1:-1] for k in unknown[:5]] + (["..."] if len(unknown) > 5 else [])
            raise _err(f"block '{block}': unknown value(s) {shown}{did_you_mean(unknown[0], keys)} (it takes "
                       f"{', '.join(keys)})", block, self.path)

    def add(self, eid, block, nodes, **vals):
        """Element ``eid`` for their block type ``block``, of the component type that declares it
        (Component.svzerod_blocks)."""
        from ..registry import svzerod_block_types

        typ = svzerod_block_types().get(block)
        if typ is None:
            raise _err(f"element '{eid}': no component type implements svZeroDSolver block type '{block}' "
                       "(a component declares the blocks it implements in svzerod_blocks)", eid, self.path)
        self.elements.append({"id": eid, "type": typ, "nodes": nodes, **vals})
        self.element_block[eid] = block

    # --- the model ------------------------------------------------------------------------
    def structure(self):
        """Check the shape of the model before anything is built: each list of blocks a list of
        mappings; each block named by a short printable string used by no other block, with its
        type a string and its values a mapping; connections naming blocks by string, junctions
        naming vessels by their ids; the initial condition a mapping of numbers.  Errors name the
        block (or its place, ``vessels[3]``) and the key.  Returns {section: its blocks}."""
        cfg, path = self.cfg, self.path
        max_chars = limits.limit("SVZEROD_NAME_CHARS")
        names = {}  # block name -> where it is defined

        def fail(where, msg, block=None):
            return _err(f"{where}: {msg}", block, path)

        def named(where, v, what, block=None):
            if not isinstance(v, str) or not v:
                raise fail(where, f"{what} must be a block name (a non-empty string), got {_show(v)}", block)
            if len(v) > max_chars:
                raise fail(where, f"{what} {_show(v)} is {len(v):,} characters long, longer than allowed "
                                  f"{limits.how_to_raise('SVZEROD_NAME_CHARS')}", block)
            if not v.isprintable():
                raise fail(where, f"{what} {_show(v)} contains control characters; use letters, digits and _", block)
            return v

        def mapping(where, b, key, block, required=True):
            v = b.get(key)
            if v is None and not required:
                return {}
            if not isinstance(v, dict):
                raise fail(where, (f"missing '{key}'" if key not in b else f"'{key}' must be a mapping ({{...}}), got "
                                   f"{_show(v)}"), block)
            return v

        def name_list(where, b, key, block):
            v = b.get(key, [])
            if not isinstance(v, list):
                raise fail(where, f"'{key}' must be a list of block names, got {_show(v)}", block)
            return [named(where, x, f"'{key}[{i}]'", block) for i, x in enumerate(v)]

        def kind(where, b, key, block, choices, default=None):
            v = b.get(key, default)
            if not isinstance(v, str) or v not in choices:
                what = (f"missing '{key}'" if key not in b else f"unknown or unsupported '{key}' {_show(v)}"
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
                raise _err(f"'{key}' must be a list of blocks ([{{...}}, ...]), got {_show(items)}", path=path)
            for i, b in enumerate(items):
                if not isinstance(b, dict):
                    raise _err(f"{key}[{i}] must be a block (a mapping {{...}}), got {_show(b)}", path=path)
                if name_key is None:
                    continue
                if name_key not in b:
                    raise _err(f"{key}[{i}]: missing '{name_key}' (the block's name)", path=path)
                name = named(f"{key}[{i}]", b[name_key], f"'{name_key}'")
                if name in names:
                    raise _err(f"{key}[{i}]: the block name {_show(name)} is used twice (also by {names[name]}); every "
                               "block needs its own name", name, path)
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
                                  f"{_show(vid)}", name)
            if vid in ids:
                raise fail(where, f"'vessel_id' {_show(vid)} is also the id of vessel {_show(ids[vid])}; every vessel "
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
                    raise fail(where, f"'{key}' must be a list of vessel ids, got {_show(lst)}", name)
                for k, vid in enumerate(lst):
                    if isinstance(vid, bool) or not isinstance(vid, (int, str)) or vid not in ids:
                        raise fail(where, f"'{key}[{k}]': no vessel with id {_show(vid)}", name)
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
                raise _err("only one ClosedLoopHeartAndPulmonary block is allowed (as in svZeroDSolver)", HEART, path)
            mapping(where, b, "parameters", HEART, required=False)
            name_list(where, b, "outlet_blocks", HEART)
            for reserved in (HEART, HEART_IN, HEART_OUT):
                if reserved in names:
                    raise _err(f"{names[reserved]}: the block name '{reserved}' is the closed-loop heart's own "
                               "(svZeroDSolver names the heart and its junctions so); rename the block", reserved, path)
        ic = cfg.get("initial_condition")
        if ic is not None:
            if not isinstance(ic, dict):
                raise _err(f"'initial_condition' must be a mapping variable name -> value, got {_show(ic)}", path=path)
            for k, v in ic.items():
                if _as_float(v) is None:
                    raise _err(f"initial_condition: '{excerpt(k, 60)[1:-1]}' must be a finite number, got {_show(v)}",
                               path=path)
        return out

    def run(self, steady=False):
        cfg, path = self.cfg, self.path
        if not isinstance(cfg, dict) or "simulation_parameters" not in cfg:
            raise _err("not an svZeroDSolver model: no 'simulation_parameters'", path=path)
        self.sim = sim = simulation_settings(cfg["simulation_parameters"], path)
        self.n_cycles = sim["number_of_cardiac_cycles"]
        self.period, self.period_block = None, None
        P = self.u["P"]
        blocks = self.structure()

        vessels = blocks["vessels"]
        by_id = {v["vessel_id"]: v["vessel_name"] for v in vessels}
        bcs = {b["bc_name"]: b for b in blocks["boundary_conditions"]}
        valves = {b["name"]: b for b in blocks["valves"]}
        chambers = {b["name"]: b for b in blocks["chambers"]}
        heart = blocks["closed_loop_blocks"][0] if blocks["closed_loop_blocks"] else None

        # connections (upstream block, downstream block), as their SimulationParameters.cpp builds them
        conns = []
        for v in vessels:
            bc = v.get("boundary_conditions") or {}
            if "inlet" in bc:
                conns.append((bc["inlet"], v["vessel_name"]))
            if "outlet" in bc:
                conns.append((v["vessel_name"], bc["outlet"]))
        junctions = {}
        for j in blocks["junctions"]:
            name = j["junction_name"]
            jt = j.get("junction_type", "NORMAL_JUNCTION")
            ins = [by_id[i] for i in j.get("inlet_vessels", [])] + list(j.get("inlet_blocks", []))
            outs = [by_id[i] for i in j.get("outlet_vessels", [])] + list(j.get("outlet_blocks", []))
            junctions[name] = (jt, ins, outs, j)
            conns += [(i, name) for i in ins] + [(name, o) for o in outs]
            self.types.add(jt if jt != "internal_junction" else "NORMAL_JUNCTION")
        for name, b in valves.items():
            prm = b["params"]
            conns += [(prm["upstream_block"], name), (name, prm["downstream_block"])]
        # blocks that drain into the heart: ClosedLoopRCR with closed_loop_outlet, and always the
        # closed-loop coronaries (their SimulationParameters.cpp, create_boundary_conditions)
        closed_bcs = [n for n, b in bcs.items() if (b.get("bc_type") == "ClosedLoopRCR"
                      and b["bc_values"].get("closed_loop_outlet") is True)
                      or b.get("bc_type") in CLOSED_LOOP_CORONARY]
        if heart is not None:
            self.types.add("ClosedLoopHeartAndPulmonary")
            for jn, ins, outs in ((HEART_IN, closed_bcs, [HEART]), (HEART_OUT, [HEART], list(heart.get("outlet_blocks") or []))):
                junctions[jn] = ("NORMAL_JUNCTION", ins, outs, {})
                conns += [(i, jn) for i in ins] + [(jn, o) for o in outs]
        elif closed_bcs:
            raise _err(f"boundary condition '{closed_bcs[0]}': closed_loop_outlet needs a ClosedLoopHeartAndPulmonary "
                       "block in 'closed_loop_blocks'", closed_bcs[0], path)

        def node(a, b):
            for x in (a, b):
                if x in junctions and junctions[x][0] != "BloodVesselJunction":
                    return _ident(x, path)
            return f"{_ident(a, path)}__{_ident(b, path)}"

        inlet, outlet = {}, {}
        for a, b in conns:
            outlet.setdefault(a, []).append(b)
            inlet.setdefault(b, []).append(a)
        self.inlet_of = {k: v[0] for k, v in inlet.items()}
        known = set(by_id.values()) | set(bcs) | set(junctions) | set(valves) | set(chambers) | (
            {HEART} if heart is not None else set())
        for a, b in conns:
            for x in (a, b):
                if x not in known:
                    raise _err(f"connection {_show(a)} -> {_show(b)}: no block named {_show(x)}"
                               f"{did_you_mean(x, known)}", x, path)

        def two_port(kind, name):
            ins, outs = inlet.get(name, []), outlet.get(name, [])
            if len(ins) != 1 or len(outs) != 1:
                def few(lst):
                    return (", ".join(map(_show, lst[:3])) + (f" and {len(lst) - 3} more" if len(lst) > 3 else "")
                            if lst else "none")
                raise _err(f"{kind} '{name}': needs exactly one upstream and one downstream block, has "
                           f"{few(ins)} and {few(outs)}", name, path)
            return node(ins[0], name), node(name, outs[0])

        # their initial_condition: values by variable name (pressure_all / flow_all defaults)
        ic_cfg = cfg.get("initial_condition") or {}  # checked by structure(): numbers

        hits = []  # set when a value comes from their initial_condition (not a default)

        def ic(name, default=0.0):
            if name in ic_cfg:
                hits.append(name)
                return float(ic_cfg[name])
            if name.startswith(("pressure:", "P_c:")) and "pressure_all" in ic_cfg:
                return float(ic_cfg["pressure_all"])
            if name.startswith("flow:") and "flow_all" in ic_cfg:
                return float(ic_cfg["flow_all"])
            return default

        V, Q = self.u["V"], self.u["Q"]
        self.initial, self.initial_given, self.store_volume = {}, {}, 0.0

        def start(eid, state, value, unit, store=False):
            self.initial[f"{eid}.{state}"] = _fmt(value, unit)
            if hits:
                self.initial_given[f"{eid}.{state}"] = _fmt(value, unit)
                hits.clear()
            if store:
                self.store_volume += value

        # vessels
        q_in, q_out = {}, {}
        for v in vessels:
            name, typ = v["vessel_name"], v["zero_d_element_type"]
            self.types.add(typ)
            if typ not in SUPPORTED_VESSELS:
                raise _err(f"vessel '{name}': unknown zero_d_element_type {_show(typ)}"
                           f"{did_you_mean(typ, SUPPORTED_VESSELS)} (supported: {', '.join(SUPPORTED_VESSELS)})", name, path)
            vals = v["zero_d_element_values"]
            if typ == "ChamberSphere":  # a chamber listed among their vessels
                self.chamber_sphere(name, vals, two_port("vessel", name), ic, start)
                q_in[name], q_out[name] = f"{self.ids[name]}.Q_in", f"{self.ids[name]}.Q_out"
                continue
            if typ == "BloodVesselRC":  # a flow-through RC (Q_in = Q_out), not a CRL without L
                self.only_keys(name, vals, ("Rpd", "Cp"))
                eid = self.id_of(name)
                Cp = float(self.value(name, vals, "Cp"))
                self.add(eid, "BloodVesselRC", list(two_port("vessel", name)) + ["ground"],
                         Rpd=_fmt(self.value(name, vals, "Rpd"), self.uR), Cp=_fmt(Cp, self.uC))
                q_in[name], q_out[name] = f"{eid}.Q_in", f"{eid}.Q_out"
                start(eid, "X", Cp * ic(f"pressure:{inlet[name][0]}:{name}"), V)
                continue
            R = self.value(name, vals, "R_poiseuille")
            C, L = self.value(name, vals, "C", 0.0), self.value(name, vals, "L", 0.0)
            S = self.value(name, vals, "stenosis_coefficient", 0.0)
            n_in, n_out = two_port("vessel", name)
            up, down = inlet[name][0], outlet[name][0]
            eid = self.id_of(name)
            self.add(eid, typ, [n_in, n_out, "ground"],
                     R_poiseuille=_fmt(R, self.uR), C=_fmt(C, self.uC), L=_fmt(L, self.uL),
                     stenosis_coefficient=_fmt(S, self.uS), capacitive=C != 0.0, inductive=L != 0.0,
                     stenotic=S != 0.0)
            q_in[name], q_out[name] = f"{eid}.Q_in", f"{eid}.Q_out"
            p0, qi, qo = ic(f"pressure:{up}:{name}"), ic(f"flow:{up}:{name}"), ic(f"flow:{name}:{down}")
            if C != 0.0:  # their capacitor pressure: P_in (CRL), P_in - (R + S|Q_in|) Q_in (BloodVessel)
                pc = p0 if typ == "BloodVesselCRL" else p0 - (float(R) + S * abs(qi)) * qi
                start(eid, "V", C * pc, V, store=True)
            if L != 0.0:
                start(eid, "Q_out", qo, Q)

        # junctions with resistances: one vessel per outlet
        for name, (jt, ins, outs, j) in junctions.items():
            if jt != "BloodVesselJunction":
                continue
            if len(ins) != 1:
                raise _err(f"junction '{name}': a BloodVesselJunction has exactly one inlet", name, path)
            jv = j.get("junction_values") or {}
            lists = []
            for key in ("R_poiseuille", "L", "stenosis_coefficient"):
                if key == "R_poiseuille" and key not in jv:
                    raise _err(f"junction '{name}': missing junction_values.R_poiseuille (one value per outlet)",
                               name, path)
                lst = jv.get(key, [0.0] * len(outs))
                if not isinstance(lst, list) or len(lst) != len(outs):
                    raise _err(f"junction '{name}': '{key}' needs a list of one value per outlet ({len(outs)}), got "
                               f"{_show(lst)}", name, path)
                lists.append(self.numbers(name, lst, key))
            for o, R, L, S in zip(outs, *lists):
                eid = self.id_of(f"{name}_{o}")
                self.add(eid, "BloodVessel", [node(ins[0], name), node(name, o), "ground"],
                         R_poiseuille=_fmt(R, self.uR), L=_fmt(L, self.uL), stenosis_coefficient=_fmt(S, self.uS),
                         inductive=L != 0.0, stenotic=S != 0.0)
                q_in[name + "->" + o] = f"{eid}.Q_out"
                if L != 0.0:
                    start(eid, "Q_out", ic(f"flow:{name}:{o}"), Q)

        # valves
        for name, b in valves.items():
            typ, prm = b["type"], b["params"]
            self.types.add(typ)
            eid = self.id_of(name)
            kw = {k: _fmt(self.value(name, prm, k), self.uR) for k in ("Rmin", "Rmax")}
            if typ == "ValveTanh":
                kw["steepness"] = _fmt(self.value(name, prm, "Steepness"), f"1/({P})")
            self.add(eid, typ, list(two_port("valve", name)), **kw)
            q_in[name] = q_out[name] = f"{eid}.Q"

        # chambers
        for name, b in chambers.items():
            typ, vals = b["type"], b.get("values") or {}
            self.types.add(typ)
            if typ == "ChamberSphere":  # its own activation, no activation_function
                self.chamber_sphere(name, vals, two_port("chamber", name), ic, start)
                q_in[name], q_out[name] = f"{self.ids[name]}.Q_in", f"{self.ids[name]}.Q_out"
                continue
            eid = self.id_of(name)
            act = self.activation(name, b.get("activation_function"))
            if typ == "ChamberElastanceInductor":
                kw = {k: _fmt(self.value(name, vals, k), self.uE) for k in ("Emax", "Emin")}
                kw.update({k: _fmt(self.value(name, vals, k), V) for k in ("Vrd", "Vrs")})
                kw["Impedance"] = _fmt(self.value(name, vals, "Impedance"), self.uL)
            elif typ == "ChamberElastanceInductorExponential":
                self.only_keys(name, vals, ("Emax", "Kxp", "Kxv", "Vaso", "Impedance"))
                kw = {"Emax": _fmt(self.value(name, vals, "Emax"), self.uE),
                      "Kxp": _fmt(self.value(name, vals, "Kxp"), P),
                      "Kxv": _fmt(self.value(name, vals, "Kxv"), f"1/({V})"),
                      "Vaso": _fmt(self.value(name, vals, "Vaso"), V),
                      "Impedance": _fmt(self.value(name, vals, "Impedance"), self.uL)}
            else:
                kw = {k: _fmt(self.value(name, vals, k), self.uE) for k in ("Emax", "Epass")}
                kw["Vrest"] = _fmt(self.value(name, vals, "Vrest"), V)
            self.chamber_elements.append((eid, act))
            self.add(eid, typ, list(two_port("chamber", name)) + ["ground"], **kw, **act)
            q_in[name], q_out[name] = f"{eid}.Q_in", f"{eid}.Q_out"
            start(eid, "Vc", ic(f"Vc:{name}"), V, store=True)
            if typ != "LinearElastanceChamber":  # the inductor's flow
                start(eid, "Q_out", ic(f"flow:{name}:{outlet[name][0]}"), Q)

        # the closed-loop heart
        if heart is not None:
            prm = heart.get("parameters") or {}
            eid = self.id_of(HEART)
            hp = self.heart_values(prm)
            period = _as_float(heart.get("cardiac_cycle_period"))
            if period is None or period <= 0:
                raise _err(f"ClosedLoopHeartAndPulmonary: 'cardiac_cycle_period' must be a finite number > 0 [s], got "
                           f"{_show(heart.get('cardiac_cycle_period'))}", HEART, path)
            check_period(period, "ClosedLoopHeartAndPulmonary: 'cardiac_cycle_period'", HEART, path)
            self.note_period(period, HEART)
            self.add(eid, "ClosedLoopHeartAndPulmonary", [node(HEART_IN, HEART), node(HEART, HEART_OUT), "ground"],
                     period=_fmt(period, "s"), **hp)
            q_in[HEART], q_out[HEART] = f"{eid}.Q_in", f"{eid}.Q_out"
            for st in ("V_RA", "V_RV", "V_LA", "V_LV"):
                start(eid, st, ic(f"{st}:{HEART}"), V, store=True)
            for st in ("Q_RA", "Q_RV", "Q_LA", "Q_LV"):
                start(eid, st, ic(f"{st}:{HEART}"), Q)
            start(eid, "V_pul", self.value(HEART, prm, "Cp") * ic(f"P_pul:{HEART}"), V)
            start(eid, "V_ao", self.value(HEART, prm, "Cpa") * ic(f"pressure:{HEART}:{HEART_OUT}"), V, store=True)

        # boundary conditions
        flow_col = {}
        self.closed = not any(b.get("bc_type") not in ("ClosedLoopRCR",) + CLOSED_LOOP_CORONARY for b in bcs.values())
        for name, b in bcs.items():
            typ = b.get("bc_type")
            if typ not in SUPPORTED_BC:
                raise _err(f"boundary condition '{name}': unknown or unsupported bc_type {_show(typ)}"
                           f"{did_you_mean(typ, SUPPORTED_BC)} (supported: {', '.join(SUPPORTED_BC)})", name, path)
            self.types.add(typ)
            vals = b["bc_values"]  # a mapping (structure())
            eid = self.id_of(name)
            if typ == "ClosedLoopRCR":
                n_in, n_out = two_port("boundary condition", name)
                C = self.value(name, vals, "C")
                self.add(eid, "ClosedLoopRCR", [n_in, n_out, "ground"], Rp=_fmt(self.value(name, vals, "Rp"), self.uR),
                         C=_fmt(C, self.uC), Rd=_fmt(self.value(name, vals, "Rd"), self.uR))
                q_in[name], q_out[name] = f"{eid}.Q_in", f"{eid}.Q_out"
                start(eid, "V", float(C) * ic(f"P_c:{name}"), V, store=True)
                continue
            if typ in CLOSED_LOOP_CORONARY:
                self.closed_loop_coronary(name, typ, vals, two_port("boundary condition", name), ic, start, heart)
                q_in[name], q_out[name] = f"{eid}.Q_in", f"{eid}.Q_out"
                continue
            ins, outs = inlet.get(name, []), outlet.get(name, [])
            if len(ins) + len(outs) != 1:
                raise _err(f"boundary condition '{name}': connected to {len(ins) + len(outs)} blocks, needs 1 (a "
                           "boundary condition is the inlet or the outlet of one block)", name, path)
            nd = node(name, outs[0]) if outs else node(ins[0], name)
            if typ == "FLOW":
                q, _ = self.series(name, vals, "Q", Q, steady)
                self.add(eid, "FLOW", ["ground", nd] if outs else [nd, "ground"], value=q)
                flow_col[name] = f"Q({eid})"
                self.pinned_q[nd] = (name, "Q")
            elif typ == "PRESSURE":
                p_, _ = self.series(name, vals, "P", P, steady)
                self.add(eid, "PRESSURE", [nd, "ground"], value=p_)
                self.pinned_p[nd] = (name, "P")
            elif typ == "RESISTANCE":
                pd, _ = self.series(name, vals, "Pd", P, steady)
                self.add(eid, "RESISTANCE", [nd, "ground"], R=_fmt(self.value(name, vals, "R"), self.uR), Pd=pd)
            elif typ == "RCR":
                pd, _ = self.series(name, vals, "Pd", P, steady) if "Pd" in vals else (_fmt(0.0, P), 0.0)
                C = self.value(name, vals, "C")
                self.add(eid, "RCR", [nd, "ground"], Rp=_fmt(self.value(name, vals, "Rp"), self.uR),
                         C=_fmt(C, self.uC), Rd=_fmt(self.value(name, vals, "Rd"), self.uR), Pd=pd)
                start(eid, "V", float(C) * ic(f"pressure_c:{name}"), V)  # their WindkesselBC's name
            elif typ == "CORONARY":
                pim, _ = self.series(name, vals, "Pim", P, steady)
                self.add(eid, "CORONARY", [nd, "ground"],
                         **{k: _fmt(self.value(name, vals, k), self.uR) for k in ("Ra1", "Ra2", "Rv1")},
                         **{k: _fmt(self.value(name, vals, k), self.uC) for k in ("Ca", "Cc")},
                         Pim=pim, P_v=_fmt(self.value(name, vals, "P_v"), P))
                self.coronary_start(name, eid, vals, float(self.value(name, vals, "Ra2")), ins, outs, ic, start)
            elif typ == "CORONARY_VAR_RES":
                pim, _ = self.series(name, vals, "Pim", P, steady)
                self.add(eid, "CORONARY_VAR_RES", [nd, "ground"],
                         **{k: _fmt(self.value(name, vals, k), self.uR) for k in ("Ra1", "Ra2_min", "Rv1", "Ra2_max")},
                         **{k: _fmt(self.value(name, vals, k), self.uC) for k in ("Ca", "Cc")},
                         **{k: _fmt(self.value(name, vals, k), "s") for k in ("T_vc", "T_vr")},
                         Pim=pim, P_v=_fmt(self.value(name, vals, "P_v"), P))
                self.timed_elements.append(eid)  # Ram(t) uses the model's cardiac period
                self.coronary_start(name, eid, vals, float(self.value(name, vals, "Ra2_min")), ins, outs, ic, start)

        # cardiac period: from the time series or the heart, else simulation_parameters, else 1 s
        sp = sim.get("cardiac_period")  # a finite number > 0 (simulation_settings)
        if sp is not None and self.period is not None and float(sp) != self.period:
            raise _err(f"simulation_parameters: cardiac_period {sp!r} s differs from the period "
                       f"{self.period!r} s of block '{self.period_block}'", self.period_block, path)
        period = self.period if self.period is not None else (float(sp) if sp is not None else 1.0)
        timed = {eid for eid, _ in self.chamber_elements} | set(self.timed_elements)
        for e in self.elements:  # activation functions and Ram(t) use the model's period
            if e["id"] in timed:
                e["period"] = _fmt(period, "s")

        self.derived = {}
        self.reduce_ideal_sources(q_in, q_out)

        # their output names -> our columns
        cols = {}
        for a, b in conns:
            nd = node(a, b)
            cols[f"pressure:{a}:{b}"] = f"P({nd})"
            if a in q_out:
                fc = q_out[a]
            elif b in q_in:
                fc = q_in[b]
            elif a in junctions and (a + "->" + b) in q_in:
                fc = q_in[a + "->" + b]
            elif a in flow_col:
                fc = flow_col[a]
            elif b in flow_col:
                fc = flow_col[b]
            else:
                fc = None
            if fc is not None:
                cols[f"flow:{a}:{b}"] = fc
        for name in chambers:
            cols[f"Vc:{name}"] = f"V({self.ids[name]})"  # a volume store
        for name, b in bcs.items():
            # internal variables (their setup_dofs names): WindkesselBC pressure_c,
            # ClosedLoopRCRBC P_c, ClosedLoopCoronaryBC volume_im (no offset, as ours)
            if b.get("bc_type") == "RCR":
                cols[f"pressure_c:{name}"] = f"{self.ids[name]}.P_c"
            elif b.get("bc_type") == "ClosedLoopRCR":
                cols[f"P_c:{name}"] = f"{self.ids[name]}.P_c"
            elif b.get("bc_type") in CLOSED_LOOP_CORONARY:
                cols[f"volume_im:{name}"] = f"{self.ids[name]}.V_im"
                self.factors[f"volume_im:{name}"] = parse_quantity("1 mL", self.u["V"])
        for v in vessels:
            name = v["vessel_name"]
            cols[f"{name}:flow_in"] = q_in[name]
            cols[f"{name}:flow_out"] = q_out[name]
            cols[f"{name}:pressure_in"] = f"P({node(inlet[name][0], name)})"
            cols[f"{name}:pressure_out"] = f"P({node(name, outlet[name][0])})"
        for their, (col, factor) in self.extra_columns.items():
            cols[their], self.factors[their] = col, factor
        self.columns = cols
        self.period_value = period
        self.law_node = node(HEART_IN, HEART) if heart is not None else (
            self.elements[0]["nodes"][0] if self.elements else None)
        return [v["vessel_name"] for v in vessels]

    def reduce_ideal_sources(self, q_in, q_out):
        """Vessel capacitors across an ideal pressure source, vessel inductors in series with an
        ideal flow source.

        Their solver integrates the DAE with a mass matrix, so such a capacitor (pulsatileFlow_CRL:
        a PRESSURE inlet on a BloodVesselCRL) or inductor (steadyFlow_RL_R: a FLOW inlet on an RL
        vessel), whose state the source fixes (a higher-index DAE), is no special case for it.
        Our states must be free (the topology
        pass rejects a loop of pressure-defining elements and a node reached only through
        flow-defining ones), so the importer does the index reduction where it can do it
        exactly: the constrained state is a known function of time.
          - capacitor C from node n to ground, P(n) = P(t) imposed: V = C P(t) is not a state;
            the vessel loses its capacitor and a flow source C dP/dt from n to ground (the slopes
            of their linear interpolation, a periodic steps waveform) carries its flow;
          - inductor L whose end node is joined only to it and flow sources Q(t): its flow is
            not a state; the vessel loses its inductor and a pressure source L dQ/dt in series
            (between a new node ``ID_L`` and the end node) keeps its pressure drop.
        Detection is generic, from the components' own edges (the capacitor's store edge on a
        pinned node; a node whose every edge is flow-defining); only the reduction knows the
        vessel's structure.  Their outputs that include the removed flow become derived
        quantities (``derived:`` in the netlist)."""
        from hemocircuit.registry import get_type

        comps = [get_type(e["type"])({k: e[k] for k in get_type(e["type"]).options if k in e})
                 for e in self.elements]
        roles = {}  # node -> [(element index, role)]
        for i, (e, c) in enumerate(zip(self.elements, comps)):
            m = dict(zip(c.terminals, e["nodes"]))
            for a, b, role in c.edges():
                for t in (a, b):
                    if t in m:
                        roles.setdefault(m[t], []).append((i, role))
        Q, P = self.u["Q"], self.u["P"]
        for i, (e, c) in enumerate(list(zip(self.elements, comps))):
            if self.element_block[e["id"]] not in ("BloodVessel", "BloodVesselCRL"):
                continue
            m = dict(zip(c.terminals, e["nodes"]))
            eid, block = e["id"], self.block_of(e["id"])
            stores = c.storages()
            if stores and m.get(stores[0].plus) in self.pinned_p and m.get(stores[0].minus) == "ground":
                node = m[stores[0].plus]
                bc, key = self.pinned_p[node]
                Cv = float(e["C"].split()[0])
                e["capacitive"] = False
                self.drop_initial(eid, "V")
                cid = self.id_of(f"{block}_C")
                self.add(cid, "FLOW", [node, "ground"], value=self.slope(bc, key, Cv, Q))
                if stores[0].plus == "in":  # their flow_in includes the capacitor's flow
                    self.derived[f"{eid}_Q_in"] = {"expr": f"{eid}.Q_in + Q({cid})", "unit": "mL/s"}
                    q_in[block] = f"{eid}_Q_in"
                else:
                    self.derived[f"{eid}_Q_out"] = {"expr": f"{eid}.Q_out - Q({cid})", "unit": "mL/s"}
                    q_out[block] = f"{eid}_Q_out"
                continue
            if not e.get("inductive"):
                continue
            for end in ("out", "in"):
                node = m[end]
                others = [j for j, _ in roles.get(node, []) if j != i]
                if node in self.pinned_q and all(r == "flow" for _, r in roles[node]) and all(
                        self.element_block[self.elements[j]["id"]] == "FLOW" for j in others):
                    bc, key = self.pinned_q[node]
                    Lv = float(e["L"].split()[0])
                    e["inductive"] = False
                    self.drop_initial(eid, "Q_out")
                    mid = f"{eid}_L"
                    e["nodes"] = [mid, e["nodes"][1], e["nodes"][2]] if end == "in" else [e["nodes"][0], mid, e["nodes"][2]]
                    pid = self.id_of(f"{block}_L")
                    # P(mid) - P(node) = L dQ/dt at the outlet; P(node) - P(mid) at the inlet
                    sign = 1.0 if end == "out" else -1.0
                    self.add(pid, "PRESSURE", [mid, node], value=self.slope(bc, key, sign * Lv, P))
                    break

    def coronary_start(self, name, eid, vals, Ram0, ins, outs, ic, start):
        """Physical volumes of an open-loop coronary at their initial condition: their
        volume_im is Cc (P_im - Pim + Pim_0 - P_Cim_0), offset by its value at the start
        (OpenLoopCoronaryBC.cpp setup_initial_state_dependent_params: P_Cim_0 = P_a - Ram Q_am,
        P_a = P_in - Ra1 Q_in, Q_am = Q_in - Ca dP_a/dt with dP_a/dt = 0, Pim_0 = Pim(0))."""
        other = ins[0] if ins else outs[0]
        var = f"{other}:{name}" if ins else f"{name}:{other}"
        p_in, q_in = ic(f"pressure:{var}"), ic(f"flow:{var}")
        Pa = p_in - float(self.value(name, vals, "Ra1")) * q_in
        pim = vals["Pim"]
        pim0 = float(pim[0] if isinstance(pim, list) else pim)
        Cc, V = float(self.value(name, vals, "Cc")), self.u["V"]
        start(eid, "V_a", float(self.value(name, vals, "Ca")) * Pa, V)
        start(eid, "V_im", ic(f"volume_im:{name}") + Cc * ((Pa - Ram0 * q_in) - pim0), V)

    def chamber_sphere(self, name, vals, nodes, ic, start):
        """A ChamberSphere: parameters in this unit system's pressure, length and time (their
        case is SI read as numbers: any consistent system gives the same numbers); their
        internal variables radius, velo, stress, tau, volume as output columns with the factors
        from ours (cm, mmHg, mL)."""
        from hemocircuit.components.svzerod.chamber_sphere import PARAMS as _P

        P, Lu, V = self.u["P"], self.u["L"], self.u["V"]
        ours = {"mmHg*s**2/cm**2": f"({P})*s**2/({Lu})**2", "cm": Lu, "mmHg": P, "mmHg*s": f"({P})*s",
                "1/s": "1/s", "s": "s"}
        self.only_keys(name, vals, tuple(k for k in _P if k != "period"))
        eid = self.id_of(name)
        kw = {k: _fmt(self.value(name, vals, k), ours[u]) for k, (u, _, _) in _P.items() if k != "period"}
        self.add(eid, "ChamberSphere", [nodes[0], nodes[1], "ground"], **kw)
        self.timed_elements.append(eid)
        for their, ours_, unit, mine, state in (
                ("radius", f"{eid}.r", Lu, "cm", "r"), ("velo", f"{eid}.v", f"({Lu})/s", "cm/s", "v"),
                ("tau", f"{eid}.tau", P, "mmHg", "tau"), ("volume", f"V({eid})", V, "mL", "V"),
                ("stress", f"{eid}.S", P, "mmHg", None)):
            self.extra_columns[f"{their}:{name}"] = (ours_, parse_quantity(f"1 {mine}", unit))
            if state is not None:
                start(eid, state, ic(f"{their}:{name}"), unit, store=state == "V")

    def closed_loop_coronary(self, name, typ, vals, nodes, ic, start, heart):
        """A ClosedLoopCoronaryLeft/Right: a ``closed_loop_coronary`` whose intramyocardial
        pressure follows the heart's ventricle through expressions of the heart's parameters
        and of its state-only observable V_LV / V_RV."""
        if heart is None:
            raise _err(f"boundary condition '{name}': {typ} needs a ClosedLoopHeartAndPulmonary block in "
                       "'closed_loop_blocks' (it reads the ventricular pressure of block CLH)", name, self.path)
        self.only_keys(name, vals, ("Ra", "Ram", "Rv", "Ca", "Cim"))
        im, E, Vu, Vv = _CORONARY_SIDE[typ]
        h = self.ids.get(HEART) or _ident(HEART, self.path)
        eid = self.ids[name]
        Ra, Ca = float(self.value(name, vals, "Ra")), float(self.value(name, vals, "Ca"))
        self.add(eid, typ, [nodes[0], nodes[1], "ground"],
                 **{k: _fmt(self.value(name, vals, k), self.uR) for k in ("Ra", "Ram", "Rv")},
                 **{k: _fmt(self.value(name, vals, k), self.uC) for k in ("Ca", "Cim")},
                 im=f"= {h}.{im}", E_s=f"= {h}.{E}", V_u=f"= {h}.{Vu}", V_vent=f"= {h}.{Vv}",
                 period=f"= {h}.period")
        up = self.inlet_of[name]
        p_in, q_in = ic(f"pressure:{up}:{name}"), ic(f"flow:{up}:{name}")
        start(eid, "V_a", Ca * (p_in - Ra * q_in), self.u["V"], store=True)
        start(eid, "V_im", ic(f"volume_im:{name}"), self.u["V"], store=True)

    def drop_initial(self, eid, state):
        """A state the index reduction removed has no initial value (theirs is fixed by the source)."""
        self.initial.pop(f"{eid}.{state}", None)
        self.initial_given.pop(f"{eid}.{state}", None)

    def block_of(self, eid):
        return self.owner[eid]

    def activation(self, name, af):
        """Their activation_function mapping -> the chamber's option and parameters."""
        from hemocircuit.components.svzerod.activation import ACT_PARAMS, KINDS, USED

        if not isinstance(af, dict) or not isinstance(af.get("type"), str):
            raise _err(f"chamber '{name}': needs 'activation_function' with a 'type' ({', '.join(KINDS)})",
                       name, self.path)
        kind = af["type"]
        if kind not in KINDS:
            raise _err(f"chamber '{name}': activation function {_show(kind)} is not supported"
                       f"{did_you_mean(kind, KINDS)} (supported: {', '.join(KINDS)})", name, self.path)
        unknown = sorted(str(k) for k in af if k != "type" and not str(k).startswith("_") and k not in USED[kind])
        if unknown:
            shown = [excerpt(k, 40)[1:-1] for k in unknown[:5]] + (["..."] if len(unknown) > 5 else [])
            raise _err(f"chamber '{name}': unknown parameter(s) {shown} for activation {kind}"
                       f"{did_you_mean(unknown[0], USED[kind])} (it takes {', '.join(USED[kind]) or 'none'})",
                       name, self.path)
        units = dict(ACT_PARAMS)
        out = {"activation": kind}
        for k in USED[kind]:
            v = self.value(name, af, k)
            out[k] = _fmt(v, "s") if units[k] == "s" else float(v)
        return out

    def heart_values(self, prm):
        """Their ClosedLoopHeartAndPulmonary parameters with units of this unit system."""
        from hemocircuit.components.svzerod.closed_loop_heart_pulmonary import PARAMS as _P

        P, V = self.u["P"], self.u["V"]
        ours = {"mmHg*s/mL": self.uR, "mmHg*s**2/mL": self.uL, "mL/mmHg": self.uC, "mmHg/mL": self.uE,
                "mmHg": P, "mL": V, "1/mL": f"1/({V})"}
        out = {}
        for k, (unit, _) in _P.items():
            if k == "period":
                continue
            v = self.value(HEART, prm, k)
            out[k] = float(v) if unit == "dimensionless" else _fmt(v, ours[unit])
        unknown = sorted(str(k) for k in prm if not str(k).startswith("_") and k not in _P)
        if unknown:
            shown = [excerpt(k, 40)[1:-1] for k in unknown[:5]] + (["..."] if len(unknown) > 5 else [])
            raise _err(f"ClosedLoopHeartAndPulmonary: unknown parameter(s) {shown}{did_you_mean(unknown[0], _P)}",
                       HEART, self.path)
        return out


def _read(path_or_cfg):
    if isinstance(path_or_cfg, dict):
        return path_or_cfg, None
    from ..inputs import read_json

    path = str(path_or_cfg)
    return read_json(path, "svZeroDSolver model file"), path


def import_svzerod(path_or_cfg, units: str | None = None, name=None, source=None) -> SvzModel:
    """Read an svZeroDSolver JSON model (a path or the parsed dict) into an :class:`SvzModel`.
    ``units``: a key of UNIT_SYSTEMS, or None for the one :func:`guess_units` finds (cgs, their
    convention, unless the model says m^3).  ``name``/``source``: the model's name and file
    when a parsed dict is given."""
    cfg, path = _read(path_or_cfg)
    path = path or source
    if not isinstance(cfg, dict):
        raise _err(f"not an svZeroDSolver model: a JSON object {{\"simulation_parameters\": ..., \"vessels\": ...}} "
                   f"is expected, got {_show(cfg)}", path=path)
    units = units or guess_units(cfg)
    imp = _Importer(cfg, path, units)
    vessels = imp.run()
    name = name or (os.path.splitext(os.path.basename(path))[0] if path else "svzerod_model")
    sim = {k: v for k, v in imp.sim.items()}
    header = {
        "name": _ident(name, path),
        "description": (f"imported from svZeroDSolver model {os.path.basename(path) if path else '(dict)'} "
                        f"(units {units}: pressure {imp.u['P']}); cardiac period {imp.period_value!r} s; "
                        f"their simulation_parameters: {_settings_text(cfg['simulation_parameters'])}"),
        "parameters": {"cardiac_period": _fmt(imp.period_value, "s"),
                       "number_of_cardiac_cycles": imp.n_cycles,
                       "number_of_time_pts_per_cardiac_cycle": int(sim["number_of_time_pts_per_cardiac_cycle"])},
    }
    netlist = {**header, "elements": imp.elements}
    if imp.derived:
        netlist["derived"] = imp.derived
    if imp.closed:  # the conserved blood volume is that of their initial condition
        netlist["constraints"] = [{"node": imp.law_node, "volume": _fmt(imp.store_volume, imp.u["V"])}]
    mean_netlist = {**header, "name": header["name"] + "_mean", "elements": imp.mean_elements()}
    if imp.derived:
        mean_netlist["derived"] = {k: dict(v) for k, v in imp.derived.items()}
    if imp.closed:
        mean_netlist["constraints"] = netlist["constraints"]
    return SvzModel(name, netlist, imp.period_value, sim, imp.columns, imp.factors, sorted(imp.types), vessels,
                    imp.u, mean_netlist, imp.initial, imp.closed, imp.initial_given)


def _settings_text(raw, limit=2000) -> str:
    """Their simulation_parameters as JSON for the netlist's description (at most ``limit``
    characters: the description is a netlist value)."""
    try:
        text = json.dumps(raw, default=str)
    except ValueError:  # an integer of thousands of digits
        text = "{...}"
    return text if len(text) <= limit else text[:limit] + "...}"


def is_svzerod_model(data) -> bool:
    """True for a parsed svZeroDSolver JSON model (simulation_parameters and blocks, no
    hemocircuit 'elements')."""
    return (isinstance(data, dict) and isinstance(data.get("simulation_parameters"), dict)
            and "elements" not in data and any(k in data for k in ("vessels", "boundary_conditions",
                                                                  "closed_loop_blocks", "chambers")))


def guess_units(cfg) -> str:
    """Unit system of a model: 'SI' when its top-level comments say m^3 (their Regazzoni
    models), else 'cgs' (their convention).  Models in mmHg need no special case: every
    pressure-carrying parameter scales together, so 'cgs' gives the same numbers."""
    text = " ".join(v if isinstance(v, str) else " ".join(x for x in v if isinstance(x, str))
                    for k, v in cfg.items() if str(k).startswith("_") and isinstance(v, (str, list)))
    return "SI" if re.search(r"m\^3|m\*\*3", text) else "cgs"


def netlist_of(cfg: dict, path=None, units=None) -> dict:
    """The hemocircuit netlist (dict) of a parsed svZeroDSolver model, in ``units``
    (:func:`import_svzerod`'s): what netlist loading uses for a ``.json`` model, so every
    command accepts their JSON directly (``--svzerod-units``)."""
    name = os.path.splitext(os.path.basename(path))[0] if path else None
    model = import_svzerod(cfg, units=units, name=name, source=path)
    return model.netlist


def write_netlist(netlist: dict, out_path: str):
    """Write a netlist dict as YAML (block style, one element per mapping), atomically
    (:func:`hemocircuit.io.atomic_write`: a temporary file renamed over the target; only a
    regular file, or a link to one in the same folder, is replaced)."""
    import yaml

    from ..io import atomic_write

    dumper = getattr(yaml, "CSafeDumper", yaml.SafeDumper)
    return atomic_write(out_path, yaml.dump(netlist, Dumper=dumper, sort_keys=False, default_flow_style=None,
                                            width=120, allow_unicode=False))
