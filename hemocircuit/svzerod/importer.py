"""Import an svZeroDSolver JSON model as an ordinary hemocircuit netlist.

Their JSON carries no units; ``units`` names the system of the numbers (``cgs``: pressure
dyn/cm^2, flow mL/s, volume mL, time s, as in their cases; ``mmHg``: mmHg, mL/s, mL, s).
Every value is written with its unit, so the netlist converts to the circuit's mmHg once,
at load time.

The model's shape is checked first (structure.py), then each block becomes an element named
after it (blocks.py, with the mapping of their blocks to component types), then the index
reduction of ideal sources (index_reduction.py).  This module holds the importer's state (the
value readers, the connections, the initial condition) and the public API.
Connection nodes are named ``A__B`` (upstream block, downstream block), a normal junction's
node after the junction.  ``SvzModel.columns`` maps their output names (``pressure:A:B``,
``flow:A:B`` and, per vessel, pressure_in/out, flow_in/out) to hemocircuit output columns.
"""
from __future__ import annotations

import json
import math
import os
import re

import numpy as np

from ..errors import did_you_mean
from ..units import parse_quantity
from . import blocks as translate
from .index_reduction import reduce_ideal_sources
from .model import (CLOSED_LOOP_CORONARY, HEART, HEART_IN, HEART_OUT, UNIT_SYSTEMS, SvzModel, as_float,
                    check_period, ident, model_error, read_model, show, shown_keys, simulation_settings)
from .model import quantity_text as fmt
from .structure import check_structure

__all__ = ["Importer", "SvzModel", "guess_units", "import_svzerod", "is_svzerod_model", "netlist_of",
           "write_netlist"]


class Importer:
    """The state of one import: the elements, columns and initial values it collects, the
    readers of the model's values (errors naming the block and key), and the connections of
    its blocks (:meth:`run`)."""

    def __init__(self, cfg, path, units):
        self.cfg, self.path = cfg, path
        if units not in UNIT_SYSTEMS:
            raise model_error(f"unknown unit system {units!r}; choose one of {sorted(UNIT_SYSTEMS)}", path=path)
        self.u = UNIT_SYSTEMS[units]
        P = self.u["P"]
        V, Q = self.u["V"], self.u["Q"]
        self.uR, self.uC, self.uL = f"({P})/({Q})", f"({V})/({P})", f"({P})/({Q})*s"
        self.uS = f"({P})/({Q})**2"
        self.uE = f"({P})/({V})"
        self.elements, self.columns, self.types = [], {}, set()
        self.chamber_elements = []
        self.timed_elements = []  # elements (not chambers) whose 'period' is the model's
        self.element_block = {}  # element id -> the block type whose component it is (add)
        self.extra_columns = {}  # their internal variable -> (our column, factor from its unit to theirs)
        self.factors = {}  # their name -> factor from our column's unit to theirs (not P, Q, Vc)
        self.ids = {}  # block name -> element id
        self.owner = {}  # element id -> block name (both ways: a model of many blocks imports in linear time)
        self.raw = {}  # (block, key) -> (times from 0, values, period) of a time series
        self.means = {}  # id(waveform) -> (waveform, the constant of the steady variant)
        self.pinned_p, self.pinned_q = {}, {}  # node -> (BC name, its value key) of PRESSURE / FLOW

    # --- the model's values -------------------------------------------------------------
    def id_of(self, name):
        eid = ident(name)
        other = self.owner.get(eid)
        if other is not None and other != name:
            raise model_error(f"block names {show(name)} and {show(other)} map to the same element id {show(eid)} "
                              "(characters other than letters, digits and _ become _); rename one", name, self.path)
        self.ids[name] = eid
        self.owner[eid] = name
        return eid

    def value(self, block, values, key, default=None):
        """The number ``values[key]`` of block ``block`` (a float), or ``default`` when missing
        and a default is given; anything but a finite number is an error naming the key."""
        if key not in values:
            if default is not None:
                return float(default)
            raise model_error(f"block '{block}': missing value '{key}'", block, self.path)
        v = values[key]
        f = as_float(v)
        if f is None:
            raise model_error(f"block '{block}': value '{key}' must be a finite number, got {show(v)}", block,
                              self.path)
        return f

    def numbers(self, block, items, key):
        """The list ``items`` (value ``key`` of ``block``) as floats: each a finite number."""
        out = []
        for i, x in enumerate(items):
            f = as_float(x)
            if f is None:
                raise model_error(f"block '{block}': '{key}[{i}]' must be a finite number, got {show(x)}", block,
                                  self.path)
            out.append(f)
        return out

    def series(self, block, values, key, unit, steady=False):
        """A constant, or their periodic time series (one cycle, a ``periodic`` pwl waveform)."""
        if key not in values:
            raise model_error(f"block '{block}': missing value '{key}'", block, self.path)
        v = values[key]
        if not isinstance(v, list):
            f = self.value(block, values, key)
            return fmt(f, unit), f
        if not v:
            raise model_error(f"block '{block}': time series '{key}' is an empty list; give a number, or values with a "
                              "list 't' of their times", block, self.path)
        vals = np.asarray(self.numbers(block, v, key))
        if len(v) == 1:
            return fmt(vals[0], unit), float(vals[0])
        t = values.get("t")
        if not isinstance(t, list) or len(t) != len(v):
            raise model_error(f"block '{block}': time series '{key}' needs a list 't' of the same length "
                              f"({len(v)} values, {'no t' if not isinstance(t, list) else f'{len(t)} times'})",
                              block, self.path)
        t = np.asarray(self.numbers(block, t, "t"))
        with np.errstate(over="ignore", invalid="ignore"):
            if not np.all(np.diff(t) > 0):
                raise model_error(f"block '{block}': the times 't' must increase", block, self.path)
            period = float(t[-1] - t[0])
            mean = float(np.mean(vals))  # their Parameter::to_steady: mean of the samples
        check_period(period, f"block '{block}': its time series 't'", block, self.path)
        if not math.isfinite(mean):
            raise model_error(f"block '{block}': the values of '{key}' are too large (their mean overflows)", block,
                              self.path)
        self.note_period(period, block)
        if steady or np.all(vals == vals[0]):  # a constant series stays a constant
            return fmt(mean, unit), mean
        self.raw[(block, key)] = (t - t[0], vals, period)
        # their Parameter::get: linear interpolation at fmod(t, period), i.e. one cycle repeated
        rows = [[fmt(tt, "s"), fmt(vv, unit)] for tt, vv in zip(t - t[0], vals)]
        wave = {"periodic": {"period": fmt(period, "s"), "pwl": rows}}
        self.means[id(wave)] = (wave, fmt(mean, unit))
        return wave, mean

    def note_period(self, period, block):
        if self.period is None:
            self.period, self.period_block = period, block
        elif self.period != period:
            raise model_error(f"block '{block}': its time series has period {period!r} s, but block "
                              f"'{self.period_block}' has {self.period!r} s (svZeroDSolver needs one cardiac period)",
                              block, self.path)

    def slope(self, block, key, factor, unit):
        """factor * d/dt of a block's series: their linear interpolation's slopes as a periodic
        ``steps`` waveform (0 for a constant or the steady variant)."""
        if (block, key) not in self.raw:
            return fmt(0.0, unit)
        t, v, period = self.raw[(block, key)]
        with np.errstate(over="ignore", invalid="ignore"):
            d = factor * (np.diff(v) / np.diff(t))
        if not np.all(np.isfinite(d)):
            raise model_error(f"block '{block}': the slopes of its time series '{key}' (times the vessel's C or L it "
                              "carries) overflow; check the values and times of the series", block, self.path)
        rows = [[fmt(tt, "s"), fmt(dd, unit)] for tt, dd in zip(t[:-1], d)]
        wave = {"periodic": {"period": fmt(period, "s"), "steps": rows}}
        self.means[id(wave)] = (wave, fmt(0.0, unit))
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
            raise model_error(f"block '{block}': unknown value(s) {shown_keys(unknown)}"
                              f"{did_you_mean(unknown[0], keys)} (it takes {', '.join(keys)})", block, self.path)

    def add(self, eid, block, nodes, **vals):
        """Element ``eid`` for their block type ``block``, of the component type that declares it
        (Component.svzerod_blocks)."""
        from ..registry import svzerod_block_types

        typ = svzerod_block_types().get(block)
        if typ is None:
            raise model_error(f"element '{eid}': no component type implements svZeroDSolver block type '{block}' "
                              "(a component declares the blocks it implements in svzerod_blocks)", eid, self.path)
        self.elements.append({"id": eid, "type": typ, "nodes": nodes, **vals})
        self.element_block[eid] = block


    def drop_initial(self, eid, state):
        """A state the index reduction removed has no initial value (theirs is fixed by the source)."""
        self.initial.pop(f"{eid}.{state}", None)
        self.initial_given.pop(f"{eid}.{state}", None)

    def block_of(self, eid):
        return self.owner[eid]

    # --- connections and initial values (set by run) ----------------------------------------
    def node(self, a, b):
        """The node between blocks ``a`` (upstream) and ``b``: a normal junction's own node, else ``A__B``."""
        for x in (a, b):
            if x in self.junctions and self.junctions[x][0] != "BloodVesselJunction":
                return ident(x)
        return f"{ident(a)}__{ident(b)}"

    def two_port(self, kind, name):
        """(inlet node, outlet node) of a block with exactly one upstream and one downstream block."""
        ins, outs = self.inlet.get(name, []), self.outlet.get(name, [])
        if len(ins) != 1 or len(outs) != 1:
            def few(lst):
                return (", ".join(map(show, lst[:3])) + (f" and {len(lst) - 3} more" if len(lst) > 3 else "")
                        if lst else "none")
            raise model_error(f"{kind} '{name}': needs exactly one upstream and one downstream block, has "
                              f"{few(ins)} and {few(outs)}", name, self.path)
        return self.node(ins[0], name), self.node(name, outs[0])

    def ic(self, name, default=0.0):
        """Their initial_condition's value of variable ``name`` (pressure_all / flow_all the
        defaults of pressures and flows), else ``default``."""
        if name in self.ic_cfg:
            self.hits.append(name)
            return float(self.ic_cfg[name])
        if name.startswith(("pressure:", "P_c:")) and "pressure_all" in self.ic_cfg:
            return float(self.ic_cfg["pressure_all"])
        if name.startswith("flow:") and "flow_all" in self.ic_cfg:
            return float(self.ic_cfg["flow_all"])
        return default

    def start(self, eid, state, value, unit, store=False):
        """The initial value of state ``eid.state`` (given by their initial_condition when a
        value read since the last start came from it; ``store``: a volume the closed loop conserves)."""
        self.initial[f"{eid}.{state}"] = fmt(value, unit)
        if self.hits:
            self.initial_given[f"{eid}.{state}"] = fmt(value, unit)
            self.hits.clear()
        if store:
            self.store_volume += value

    def connect(self, blocks, bcs, valves, chambers, heart):
        """The connections (upstream block, downstream block), as their SimulationParameters.cpp
        builds them; sets the junctions {name: (type, inlets, outlets, block)} (the heart's two
        among them) and each block's upstream (``inlet``) and downstream (``outlet``) blocks."""
        path = self.path
        vessels = blocks["vessels"]
        by_id = {v["vessel_id"]: v["vessel_name"] for v in vessels}
        conns = []
        for v in vessels:
            bc = v.get("boundary_conditions") or {}
            if "inlet" in bc:
                conns.append((bc["inlet"], v["vessel_name"]))
            if "outlet" in bc:
                conns.append((v["vessel_name"], bc["outlet"]))
        junctions = self.junctions = {}
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
            for jn, ins, outs in ((HEART_IN, closed_bcs, [HEART]),
                                  (HEART_OUT, [HEART], list(heart.get("outlet_blocks") or []))):
                junctions[jn] = ("NORMAL_JUNCTION", ins, outs, {})
                conns += [(i, jn) for i in ins] + [(jn, o) for o in outs]
        elif closed_bcs:
            raise model_error(f"boundary condition '{closed_bcs[0]}': closed_loop_outlet needs a "
                              "ClosedLoopHeartAndPulmonary block in 'closed_loop_blocks'", closed_bcs[0], path)
        self.inlet, self.outlet = {}, {}
        for a, b in conns:
            self.outlet.setdefault(a, []).append(b)
            self.inlet.setdefault(b, []).append(a)
        known = set(by_id.values()) | set(bcs) | set(junctions) | set(valves) | set(chambers) | (
            {HEART} if heart is not None else set())
        for a, b in conns:
            for x in (a, b):
                if x not in known:
                    raise model_error(f"connection {show(a)} -> {show(b)}: no block named {show(x)}"
                                      f"{did_you_mean(x, known)}", x, path)
        return conns

    # --- the model ------------------------------------------------------------------------
    def run(self, steady=False):
        """Import the model (``steady``: every time series at its mean); returns the names of
        its vessels."""
        cfg, path = self.cfg, self.path
        if not isinstance(cfg, dict) or "simulation_parameters" not in cfg:
            raise model_error("not an svZeroDSolver model: no 'simulation_parameters'", path=path)
        self.sim = sim = simulation_settings(cfg["simulation_parameters"], path)
        self.n_cycles = sim["number_of_cardiac_cycles"]
        self.period, self.period_block = None, None
        blocks = check_structure(cfg, path)

        vessels = blocks["vessels"]
        bcs = {b["bc_name"]: b for b in blocks["boundary_conditions"]}
        valves = {b["name"]: b for b in blocks["valves"]}
        chambers = {b["name"]: b for b in blocks["chambers"]}
        heart = blocks["closed_loop_blocks"][0] if blocks["closed_loop_blocks"] else None
        conns = self.connect(blocks, bcs, valves, chambers, heart)

        # their initial_condition: values by variable name (pressure_all / flow_all defaults)
        self.ic_cfg = cfg.get("initial_condition") or {}  # checked by check_structure: numbers
        self.hits = []  # set when a value comes from their initial_condition (not a default)
        self.initial, self.initial_given, self.store_volume = {}, {}, 0.0
        self.q_in, self.q_out = {}, {}  # block -> the column of its inlet / outlet flow
        self.flow_col = {}  # FLOW boundary condition -> the column of its flow

        translate.vessels(self, vessels)
        translate.vessel_junctions(self)
        translate.valves(self, valves)
        translate.chambers(self, chambers)
        if heart is not None:
            translate.closed_loop_heart(self, heart)
        translate.boundary_conditions(self, bcs, heart, steady)

        # cardiac period: from the time series or the heart, else simulation_parameters, else 1 s
        sp = sim.get("cardiac_period")  # a finite number > 0 (simulation_settings)
        if sp is not None and self.period is not None and float(sp) != self.period:
            raise model_error(f"simulation_parameters: cardiac_period {sp!r} s differs from the period "
                              f"{self.period!r} s of block '{self.period_block}'", self.period_block, path)
        period = self.period if self.period is not None else (float(sp) if sp is not None else 1.0)
        timed = {eid for eid, _ in self.chamber_elements} | set(self.timed_elements)
        for e in self.elements:  # activation functions and Ram(t) use the model's period
            if e["id"] in timed:
                e["period"] = fmt(period, "s")

        self.derived = {}
        reduce_ideal_sources(self)
        self.columns = self.output_columns(conns, vessels, bcs, chambers)
        self.period_value = period
        self.law_node = self.node(HEART_IN, HEART) if heart is not None else (
            self.elements[0]["nodes"][0] if self.elements else None)
        return [v["vessel_name"] for v in vessels]

    def output_columns(self, conns, vessels, bcs, chambers):
        """Their output names -> our columns (and the factors of their internal variables)."""
        cols = {}
        for a, b in conns:
            nd = self.node(a, b)
            cols[f"pressure:{a}:{b}"] = f"P({nd})"
            if a in self.q_out:
                fc = self.q_out[a]
            elif b in self.q_in:
                fc = self.q_in[b]
            elif a in self.junctions and (a + "->" + b) in self.q_in:
                fc = self.q_in[a + "->" + b]
            elif a in self.flow_col:
                fc = self.flow_col[a]
            elif b in self.flow_col:
                fc = self.flow_col[b]
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
            cols[f"{name}:flow_in"] = self.q_in[name]
            cols[f"{name}:flow_out"] = self.q_out[name]
            cols[f"{name}:pressure_in"] = f"P({self.node(self.inlet[name][0], name)})"
            cols[f"{name}:pressure_out"] = f"P({self.node(name, self.outlet[name][0])})"
        for their, (col, factor) in self.extra_columns.items():
            cols[their], self.factors[their] = col, factor
        return cols


def import_svzerod(path_or_cfg, units: str | None = None, name=None, source=None) -> SvzModel:
    """Read an svZeroDSolver JSON model (a path or the parsed dict) into an :class:`SvzModel`.
    ``units``: a key of UNIT_SYSTEMS, or None for the one :func:`guess_units` finds (cgs, their
    convention, unless the model says m^3).  ``name``/``source``: the model's name and file
    when a parsed dict is given."""
    cfg, path = read_model(path_or_cfg)
    path = path or source
    if not isinstance(cfg, dict):
        raise model_error("not an svZeroDSolver model: a JSON object {\"simulation_parameters\": ..., \"vessels\": "
                          f"...}} is expected, got {show(cfg)}", path=path)
    units = units or guess_units(cfg)
    imp = Importer(cfg, path, units)
    vessels = imp.run()
    name = name or (os.path.splitext(os.path.basename(path))[0] if path else "svzerod_model")
    sim = {k: v for k, v in imp.sim.items()}
    header = {
        "name": ident(name),
        "description": (f"imported from svZeroDSolver model {os.path.basename(path) if path else '(dict)'} "
                        f"(units {units}: pressure {imp.u['P']}); cardiac period {imp.period_value!r} s; "
                        f"their simulation_parameters: {_settings_text(cfg['simulation_parameters'])}"),
        "parameters": {"cardiac_period": fmt(imp.period_value, "s"),
                       "number_of_cardiac_cycles": imp.n_cycles,
                       "number_of_time_pts_per_cardiac_cycle": int(sim["number_of_time_pts_per_cardiac_cycle"])},
    }
    netlist = {**header, "elements": imp.elements}
    if imp.derived:
        netlist["derived"] = imp.derived
    if imp.closed:  # the conserved blood volume is that of their initial condition ...
        netlist["constraints"] = [{"node": imp.law_node, "volume": fmt(imp.store_volume, imp.u["V"])}]
        # ... and a run starts there, as theirs (the time-averaged loop's operating point has no
        # pump: every valve at zero flow, on its kink, where a PiecewiseValve's Newton cycles)
        netlist["ic"] = dict(imp.initial)
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
