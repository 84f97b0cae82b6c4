"""What an svZeroDSolver JSON model is, below the importer: their unit systems, simulation
settings and block names (the constants), the imported model (:class:`SvzModel`), the checks of
their settings, and the helpers that read and quote their values (a finite number, a whole
number, an element id, a short excerpt for an error message)."""
from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass, field

from .. import limits
from ..errors import NetlistError, excerpt

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
CORONARY_SIDE = {"ClosedLoopCoronaryLeft": ("iml", "Elv_s", "Vlv_u", "V_LV"),
                 "ClosedLoopCoronaryRight": ("imr", "Erv_s", "Vrv_u", "V_RV")}
SUPPORTED_VESSELS = ("BloodVessel", "BloodVesselCRL", "BloodVesselRC", "ChamberSphere", "Resistance", "Capacitance",
                     "Inductance")
#: their one-element vessels (Resistance.cpp, Capacitance.cpp, Inductance.cpp): a BloodVessel with
#: the other two of R, C, L at 0 -> (their value's key, the BloodVessel parameter it sets)
ONE_ELEMENT_VESSELS = {"Resistance": ("R", "R_poiseuille"), "Capacitance": ("C", "C"), "Inductance": ("L", "L")}
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


def read_model(path_or_cfg):
    """(the parsed model, its path): a dict is taken as it is (path None); a path is read as
    JSON under the input policy."""
    if isinstance(path_or_cfg, dict):
        return path_or_cfg, None
    from ..inputs import read_json

    path = str(path_or_cfg)
    return read_json(path, "svZeroDSolver model file"), path


def model_error(msg, block=None, path=None):
    """The error for a model: a NetlistError naming the file and the block."""
    return NetlistError(msg, file=path, element=block)


def ident(name):
    """A block name as an element id: ASCII letters, digits and _ (any other character becomes
    _; ``b_`` before a leading digit or an empty name)."""
    s = re.sub(r"[^A-Za-z0-9_]", "_", str(name))
    if not s or s[0].isdigit():
        s = "b_" + s
    return s


def show(v, limit=40) -> str:
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


def shown_keys(keys):
    """The first five of ``keys`` (sorted strings) as short excerpts, for an error message."""
    return [excerpt(k, 40)[1:-1] for k in keys[:5]] + (["..."] if len(keys) > 5 else [])


def as_float(v):
    """``v`` as a float when it is a finite JSON number (not true/false), else None."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return None
    try:
        f = float(v)
    except OverflowError:  # an integer beyond the float range
        return None
    return f if math.isfinite(f) else None


def whole(v):
    """``v`` as an int when it is a whole JSON number (3 or 3.0; not true/false, not 2.5), else None."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return None
    if isinstance(v, float):
        return int(v) if math.isfinite(v) and v == int(v) else None
    return v


def quantity_text(x, unit):
    """A netlist value: the number ``x`` (exactly, as its repr) with its unit."""
    return f"{float(x)!r} {unit}"


def check_points(cycles, points, path=None, what="simulation_parameters"):
    """Refuse a run of more time points ((points - 1) cycles + 1) than the SVZEROD_POINTS limit:
    their output has one row per point (per block or variable), our run one state per point."""
    total = (points - 1) * cycles + 1
    if total > limits.limit("SVZEROD_POINTS"):
        def shown(n):
            return f"{n:,}" if n < 10 ** 15 else f"about 10^{len(str(n)) - 1 if n < 10 ** 4000 else 'thousands'}"
        raise model_error(f"{what}: {shown(cycles)} cycles of {shown(points)} points per cycle are {shown(total)} "
                          f"time points, more than allowed {limits.how_to_raise('SVZEROD_POINTS')}; lower "
                          "number_of_cardiac_cycles or number_of_time_pts_per_cardiac_cycle", path=path)
    return total


def check_period(period, where, block=None, path=None):
    """A cardiac period [s] must be a finite number > 0 and at most the SVZEROD_PERIOD_S limit
    (``where``: what gives it, for the message)."""
    if period is None or not (math.isfinite(period) and period > 0):
        raise model_error(f"{where}: the cardiac period is {period!r} s; it must be a finite number > 0", block, path)
    if period > limits.limit("SVZEROD_PERIOD_S"):
        raise model_error(f"{where}: a cardiac period of {period:g} s is longer than allowed "
                          f"{limits.how_to_raise('SVZEROD_PERIOD_S')}; give it in seconds", block, path)
    return period


def simulation_settings(raw, path=None) -> dict:
    """Their ``simulation_parameters`` checked (with SIM_DEFAULTS): whole numbers of cycles (>= 1)
    and points per cycle (>= 2) within the SVZEROD_POINTS limit, true/false flags, a positive
    period, output interval and tolerances; errors name the key and say how to fix it."""
    def bad(key, v, want):
        return model_error(f"simulation_parameters: '{key}' must be {want}, got {show(v)}", path=path)

    if not isinstance(raw, dict):
        raise model_error(f"'simulation_parameters' must be a mapping, got {show(raw)}; e.g. "
                          '{"number_of_cardiac_cycles": 10, "number_of_time_pts_per_cardiac_cycle": 101}', path=path)
    sim = {**SIM_DEFAULTS, **raw}
    for key, low, example in (("number_of_cardiac_cycles", 1, 10), ("number_of_time_pts_per_cardiac_cycle", 2, 101)):
        if key not in raw:
            raise model_error(f"simulation_parameters: missing '{key}' (e.g. \"{key}\": {example})", path=path)
        n = whole(raw[key])
        if n is None or n < low:
            extra = " (not a whole number)" if as_float(raw[key]) is not None and n is None else ""
            raise bad(key, raw[key], f"a whole number >= {low}{extra}, e.g. {example}")
        sim[key] = n
    check_points(sim["number_of_cardiac_cycles"], sim["number_of_time_pts_per_cardiac_cycle"], path)
    for key in BOOL_SETTINGS:
        if not isinstance(sim[key] if key in sim else False, bool):
            raise bad(key, sim[key], "true or false")
    n = whole(sim["output_interval"])
    if n is None or n < 1:
        raise bad("output_interval", sim["output_interval"], "a whole number >= 1 (write every n-th step)")
    sim["output_interval"] = n
    for key in ("absolute_tolerance", "cardiac_period", "sim_cycle_to_cycle_percent_error"):
        if sim.get(key) is None and key != "absolute_tolerance":
            sim.pop(key, None)  # not given (null): their default
            continue
        v = as_float(sim[key])
        if v is None or v <= 0 or (key == "sim_cycle_to_cycle_percent_error" and v >= 100):
            raise bad(key, sim[key], "a number between 0 and 100 (percent)" if key.startswith("sim_cycle")
                      else "a finite number > 0" + (" [s]" if key == "cardiac_period" else ""))
        if key == "cardiac_period":
            check_period(v, "simulation_parameters: 'cardiac_period'", path=path)
    return sim
