"""Import an svZeroDSolver JSON model as an ordinary hemocircuit netlist.

Their JSON carries no units; ``units`` names the system of the numbers (``cgs``: pressure
dyn/cm^2, flow mL/s, volume mL, time s, as in their cases; ``mmHg``: mmHg, mL/s, mL, s).
Every value is written with its unit, so the netlist converts to the circuit's mmHg once,
at load time.

Mapping (one element per block, named after it; blocks in components/svzerod/):
  vessels  BloodVessel -> blood_vessel, BloodVesselCRL -> blood_vessel_crl
           (nodes [inlet, outlet, ground]; options capacitive/inductive from C, L != 0)
  junctions NORMAL_JUNCTION -> one node named after the junction (ideal: equal pressures,
           mass conservation); BloodVesselJunction -> one blood_vessel per outlet,
           ``J_outletname`` (their equations are exactly parallel R + stenosis + L branches)
  BCs      FLOW -> flow_source, PRESSURE -> pressure_source (their periodic time series as a
           pwl table repeated over the simulated cycles + 1), RESISTANCE -> resistance_bc,
           RCR -> rcr_bc, CORONARY -> coronary_bc
Connection nodes are named ``A__B`` (upstream block, downstream block), a normal junction's
node after the junction.  ``SvzModel.columns`` maps their output names (``pressure:A:B``,
``flow:A:B`` and, per vessel, pressure_in/out, flow_in/out) to hemocircuit output columns.
"""
from __future__ import annotations

import json
import os
import re
from dataclasses import dataclass, field

import numpy as np

from ..errors import NetlistError

UNIT_SYSTEMS = {
    "cgs": {"P": "dyn/cm**2", "Q": "mL/s", "V": "mL", "t": "s"},
    "mmHg": {"P": "mmHg", "Q": "mL/s", "V": "mL", "t": "s"},
}

SIM_DEFAULTS = {"steady_initial": True, "output_all_cycles": False, "output_variable_based": False,
                "output_mean_only": False, "output_derivative": False, "output_interval": 1,
                "absolute_tolerance": 1e-8}

SUPPORTED_BC = ("FLOW", "PRESSURE", "RESISTANCE", "RCR", "CORONARY")
SUPPORTED_VESSELS = ("BloodVessel", "BloodVesselCRL")


@dataclass
class SvzModel:
    """An imported model: the netlist (a dict, YAML-ready), their simulation settings and the
    map from their output names to hemocircuit columns."""

    name: str
    netlist: dict
    period: float
    sim: dict
    columns: dict = field(default_factory=dict)  # their name -> (our column, sign)
    block_types: list = field(default_factory=list)
    vessels: list = field(default_factory=list)  # vessel names (their per-block output)
    units: dict = field(default_factory=dict)
    mean_netlist: dict | None = None  # time series at their means (their steady_initial)

    @property
    def n_cycles(self):
        return int(self.sim["number_of_cardiac_cycles"])

    @property
    def points(self):
        return int(self.sim["number_of_time_pts_per_cardiac_cycle"])


def _err(msg, block=None, path=None):
    return NetlistError(msg, file=path, element=block)


def _ident(name, path):
    s = re.sub(r"\W", "_", str(name))
    if not s or s[0].isdigit():
        s = "b_" + s
    return s


def _fmt(x, unit):
    return f"{float(x)!r} {unit}"


class _Importer:
    def __init__(self, cfg, path, units, extra_cycles=1):
        self.cfg, self.path = cfg, path
        if units not in UNIT_SYSTEMS:
            raise _err(f"unknown unit system {units!r}; choose one of {sorted(UNIT_SYSTEMS)}", path=path)
        self.u = UNIT_SYSTEMS[units]
        P = self.u["P"]
        self.uR, self.uC, self.uL = f"{P}*s/mL", f"mL/({P})", f"{P}*s**2/mL"
        self.uS = f"{P}*s**2/mL**2"
        self.extra_cycles = extra_cycles
        self.elements, self.columns, self.types = [], {}, set()
        self.ids = {}

    # --- helpers ------------------------------------------------------------------------
    def id_of(self, name):
        ident = _ident(name, self.path)
        if ident in self.ids.values() and self.ids.get(name) != ident:
            raise _err(f"block names {name!r} and another one map to the same element id {ident!r}", name, self.path)
        self.ids[name] = ident
        return ident

    def value(self, block, values, key, default=None):
        if key not in values:
            if default is not None:
                return default
            raise _err(f"block '{block}': missing value '{key}'", block, self.path)
        v = values[key]
        if isinstance(v, bool) or not isinstance(v, (int, float, list)):
            raise _err(f"block '{block}': value '{key}' must be a number or a list, got {v!r}", block, self.path)
        return v

    def series(self, block, values, key, unit, steady=False):
        """A constant, or a periodic time series repeated over the simulated cycles."""
        v = self.value(block, values, key)
        if not isinstance(v, list):
            return _fmt(v, unit), float(v)
        if len(v) == 1:
            return _fmt(v[0], unit), float(v[0])
        t = values.get("t")
        if not isinstance(t, list) or len(t) != len(v):
            raise _err(f"block '{block}': time series '{key}' needs a list 't' of the same length "
                       f"({len(v)} values, {'no t' if not isinstance(t, list) else f'{len(t)} times'})",
                       block, self.path)
        t = np.asarray(t, float)
        vals = np.asarray(v, float)
        if np.any(np.diff(t) <= 0):
            raise _err(f"block '{block}': the times 't' must increase", block, self.path)
        period = float(t[-1] - t[0])
        self.note_period(period, block)
        mean = float(np.mean(vals))  # their Parameter::to_steady: mean of the samples
        if steady or np.all(vals == vals[0]):  # a constant series stays a constant
            return _fmt(mean, unit), mean
        rows = []
        for k in range(self.n_cycles + self.extra_cycles):
            for tt, vv in zip(t - t[0] + k * period, vals):
                rows.append([_fmt(tt, "s"), _fmt(vv, unit)])
        return {"pwl": rows}, mean

    def note_period(self, period, block):
        if self.period is None:
            self.period, self.period_block = period, block
        elif self.period != period:
            raise _err(f"block '{block}': its time series has period {period!r} s, but block "
                       f"'{self.period_block}' has {self.period!r} s (svZeroDSolver needs one cardiac period)",
                       block, self.path)

    def add(self, eid, typ, nodes, **vals):
        self.elements.append({"id": eid, "type": typ, "nodes": nodes, **vals})

    # --- the model ------------------------------------------------------------------------
    def run(self, steady=False):
        cfg, path = self.cfg, self.path
        if not isinstance(cfg, dict) or "simulation_parameters" not in cfg:
            raise _err("not an svZeroDSolver model: no 'simulation_parameters'", path=path)
        sim = {**SIM_DEFAULTS, **cfg["simulation_parameters"]}
        for key in ("number_of_cardiac_cycles", "number_of_time_pts_per_cardiac_cycle"):
            if key not in sim:
                raise _err(f"simulation_parameters: missing '{key}'", path=path)
        self.sim = sim
        self.n_cycles = int(sim["number_of_cardiac_cycles"])
        self.period, self.period_block = None, None
        if cfg.get("closed_loop_blocks"):
            b = cfg["closed_loop_blocks"][0]
            raise _err(f"block '{b.get('closed_loop_type', '?')}': closed-loop blocks are not supported yet",
                       b.get("closed_loop_type"), path)
        for key in ("chambers", "valves"):
            for b in cfg.get(key) or []:
                raise _err(f"block '{b.get('name', '?')}': type {b.get('type')!r} is not supported yet "
                           f"(supported: vessels {SUPPORTED_VESSELS}, junctions, BCs {SUPPORTED_BC})",
                           b.get("name"), path)

        vessels = cfg.get("vessels") or []
        by_id = {}
        for v in vessels:
            for key in ("vessel_name", "vessel_id", "zero_d_element_type", "zero_d_element_values"):
                if key not in v:
                    raise _err(f"vessel {v.get('vessel_name', v.get('vessel_id', '?'))!r}: missing '{key}'",
                               v.get("vessel_name"), path)
            by_id[v["vessel_id"]] = v["vessel_name"]
        bcs = {b.get("bc_name"): b for b in cfg.get("boundary_conditions") or []}

        # connections (upstream block, downstream block)
        conns = []
        for v in vessels:
            bc = v.get("boundary_conditions") or {}
            if "inlet" in bc:
                conns.append((bc["inlet"], v["vessel_name"]))
            if "outlet" in bc:
                conns.append((v["vessel_name"], bc["outlet"]))
        junctions = {}
        for j in cfg.get("junctions") or []:
            name = j.get("junction_name")
            jt = j.get("junction_type", "NORMAL_JUNCTION")
            if jt not in ("NORMAL_JUNCTION", "internal_junction", "BloodVesselJunction"):
                raise _err(f"junction '{name}': unknown junction_type {jt!r} "
                           "(NORMAL_JUNCTION, internal_junction, BloodVesselJunction)", name, path)
            ins = [by_id.get(i, i) for i in j.get("inlet_vessels", [])] + list(j.get("inlet_blocks", []))
            outs = [by_id.get(i, i) for i in j.get("outlet_vessels", [])] + list(j.get("outlet_blocks", []))
            for i in j.get("inlet_vessels", []) + j.get("outlet_vessels", []):
                if i not in by_id:
                    raise _err(f"junction '{name}': no vessel with id {i}", name, path)
            junctions[name] = (jt, ins, outs, j)
            conns += [(i, name) for i in ins] + [(name, o) for o in outs]
            self.types.add(jt if jt != "internal_junction" else "NORMAL_JUNCTION")

        def node(a, b):
            for x in (a, b):
                if x in junctions and junctions[x][0] != "BloodVesselJunction":
                    return _ident(x, path)
            return f"{_ident(a, path)}__{_ident(b, path)}"

        inlet, outlet = {}, {}
        for a, b in conns:
            outlet.setdefault(a, []).append(b)
            inlet.setdefault(b, []).append(a)
        known = set(by_id.values()) | set(bcs) | set(junctions)
        for a, b in conns:
            for x in (a, b):
                if x not in known:
                    raise _err(f"connection {a} -> {b}: no block named '{x}'", x, path)

        # vessels
        q_in, q_out = {}, {}
        for v in vessels:
            name, typ = v["vessel_name"], v["zero_d_element_type"]
            self.types.add(typ)
            if typ not in SUPPORTED_VESSELS:
                raise _err(f"vessel '{name}': unknown zero_d_element_type {typ!r} (supported: {SUPPORTED_VESSELS})",
                           name, path)
            vals = v["zero_d_element_values"]
            R = self.value(name, vals, "R_poiseuille")
            C, L = float(vals.get("C", 0.0)), float(vals.get("L", 0.0))
            S = float(vals.get("stenosis_coefficient", 0.0))
            ins, outs = inlet.get(name, []), outlet.get(name, [])
            if len(ins) != 1 or len(outs) != 1:
                raise _err(f"vessel '{name}': needs exactly one upstream and one downstream block, has "
                           f"{ins or 'none'} and {outs or 'none'}", name, path)
            eid = self.id_of(name)
            self.add(eid, "blood_vessel" if typ == "BloodVessel" else "blood_vessel_crl",
                     [node(ins[0], name), node(name, outs[0]), "ground"],
                     R_poiseuille=_fmt(R, self.uR), C=_fmt(C, self.uC), L=_fmt(L, self.uL),
                     stenosis_coefficient=_fmt(S, self.uS), capacitive=C != 0.0, inductive=L != 0.0)
            q_in[name], q_out[name] = f"{eid}.Q_in", f"{eid}.Q_out"

        # junctions with resistances: one vessel per outlet
        for name, (jt, ins, outs, j) in junctions.items():
            if jt != "BloodVesselJunction":
                continue
            if len(ins) != 1:
                raise _err(f"junction '{name}': a BloodVesselJunction has exactly one inlet", name, path)
            jv = j.get("junction_values") or {}
            Rs = self.value(name, jv, "R_poiseuille")
            Ls = jv.get("L", [0.0] * len(outs))
            Ss = jv.get("stenosis_coefficient", [0.0] * len(outs))
            for key, lst in (("R_poiseuille", Rs), ("L", Ls), ("stenosis_coefficient", Ss)):
                if not isinstance(lst, list) or len(lst) != len(outs):
                    raise _err(f"junction '{name}': '{key}' needs one value per outlet ({len(outs)})", name, path)
            for o, R, L, S in zip(outs, Rs, Ls, Ss):
                eid = self.id_of(f"{name}_{o}")
                self.add(eid, "blood_vessel", [node(ins[0], name), node(name, o), "ground"],
                         R_poiseuille=_fmt(R, self.uR), L=_fmt(L, self.uL), stenosis_coefficient=_fmt(S, self.uS),
                         inductive=float(L) != 0.0)
                q_in[name + "->" + o] = f"{eid}.Q_out"

        # boundary conditions
        flow_col = {}
        for name, b in bcs.items():
            typ = b.get("bc_type")
            self.types.add(typ)
            vals = b.get("bc_values")
            if not isinstance(vals, dict):
                raise _err(f"boundary condition '{name}': missing 'bc_values'", name, path)
            ins, outs = inlet.get(name, []), outlet.get(name, [])
            if len(ins) + len(outs) != 1:
                raise _err(f"boundary condition '{name}': connected to {len(ins) + len(outs)} blocks, needs 1",
                           name, path)
            nd = node(name, outs[0]) if outs else node(ins[0], name)
            eid = self.id_of(name)
            P = self.u["P"]
            if typ == "FLOW":
                q, _ = self.series(name, vals, "Q", "mL/s", steady)
                self.add(eid, "flow_source", ["ground", nd] if outs else [nd, "ground"], value=q)
                flow_col[name] = f"Q({eid})"
            elif typ == "PRESSURE":
                p_, _ = self.series(name, vals, "P", P, steady)
                self.add(eid, "pressure_source", [nd, "ground"], value=p_)
            elif typ == "RESISTANCE":
                pd, _ = self.series(name, vals, "Pd", P, steady)
                self.add(eid, "resistance_bc", [nd, "ground"], R=_fmt(self.value(name, vals, "R"), self.uR), Pd=pd)
            elif typ == "RCR":
                pd, _ = self.series(name, vals, "Pd", P, steady) if "Pd" in vals else (_fmt(0.0, P), 0.0)
                self.add(eid, "rcr_bc", [nd, "ground"], Rp=_fmt(self.value(name, vals, "Rp"), self.uR),
                         C=_fmt(self.value(name, vals, "C"), self.uC), Rd=_fmt(self.value(name, vals, "Rd"), self.uR),
                         Pd=pd)
            elif typ == "CORONARY":
                pim, _ = self.series(name, vals, "Pim", P, steady)
                self.add(eid, "coronary_bc", [nd, "ground"],
                         **{k: _fmt(self.value(name, vals, k), self.uR) for k in ("Ra1", "Ra2", "Rv1")},
                         **{k: _fmt(self.value(name, vals, k), self.uC) for k in ("Ca", "Cc")},
                         Pim=pim, P_v=_fmt(self.value(name, vals, "P_v"), P))
            else:
                raise _err(f"boundary condition '{name}': unknown or unsupported bc_type {typ!r} "
                           f"(supported: {', '.join(SUPPORTED_BC)})", name, path)

        # cardiac period: from the time series, else simulation_parameters, else 1 s (Solver.cpp)
        sp = sim.get("cardiac_period")
        if sp is not None and self.period is not None and float(sp) != self.period:
            raise _err(f"simulation_parameters: cardiac_period {sp!r} s differs from the period "
                       f"{self.period!r} s of block '{self.period_block}'s time series", self.period_block, path)
        period = self.period if self.period is not None else (float(sp) if sp is not None else 1.0)

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
        for v in vessels:
            name = v["vessel_name"]
            cols[f"{name}:flow_in"] = q_in[name]
            cols[f"{name}:flow_out"] = q_out[name]
            cols[f"{name}:pressure_in"] = f"P({node(inlet[name][0], name)})"
            cols[f"{name}:pressure_out"] = f"P({node(name, outlet[name][0])})"
        self.columns = cols
        self.period_value = period
        return [v["vessel_name"] for v in vessels]


def _read(path_or_cfg):
    if isinstance(path_or_cfg, dict):
        return path_or_cfg, None
    path = str(path_or_cfg)
    try:
        with open(path) as fh:
            return json.load(fh), path
    except OSError as exc:
        raise NetlistError(f"cannot read {path}: {exc.strerror}", file=path) from None
    except json.JSONDecodeError as exc:
        raise NetlistError(f"not valid JSON: {exc}", file=path) from None


def import_svzerod(path_or_cfg, units: str = "cgs", extra_cycles: int = 1) -> SvzModel:
    """Read an svZeroDSolver JSON model (a path or the parsed dict) into an :class:`SvzModel`."""
    cfg, path = _read(path_or_cfg)
    imp = _Importer(cfg, path, units, extra_cycles)
    vessels = imp.run()
    name = os.path.splitext(os.path.basename(path))[0] if path else "svzerod_model"
    sim = {k: v for k, v in imp.sim.items()}
    header = {
        "name": _ident(name, path),
        "description": (f"imported from svZeroDSolver model {os.path.basename(path) if path else '(dict)'} "
                        f"(units {units}: pressure {imp.u['P']}); cardiac period {imp.period_value!r} s; "
                        f"their simulation_parameters: {json.dumps(cfg['simulation_parameters'])}"),
        "parameters": {"cardiac_period": _fmt(imp.period_value, "s"),
                       "number_of_cardiac_cycles": imp.n_cycles,
                       "number_of_time_pts_per_cardiac_cycle": int(sim["number_of_time_pts_per_cardiac_cycle"])},
    }
    netlist = {**header, "elements": imp.elements}
    steady = _Importer(cfg, path, units, extra_cycles)
    steady.run(steady=True)
    mean_netlist = {**header, "name": header["name"] + "_mean", "elements": steady.elements}
    return SvzModel(name, netlist, imp.period_value, sim, imp.columns, sorted(imp.types), vessels,
                    imp.u, mean_netlist)


def write_netlist(netlist: dict, out_path: str):
    """Write a netlist dict as YAML (block style, one element per mapping)."""
    import yaml

    with open(out_path, "w") as fh:
        yaml.safe_dump(netlist, fh, sort_keys=False, default_flow_style=None, width=120)


def load_svzerod(path, units: str = "cgs", mean: bool = False):
    """The assembled Circuit of an svZeroDSolver JSON model (through a temporary netlist file,
    so it is exactly what ``import-svzerod`` writes).  ``mean``: time series at their means."""
    import tempfile

    from ..circuit import load

    model = import_svzerod(path, units)
    with tempfile.TemporaryDirectory(prefix="hemocircuit_svz_") as d:
        out = os.path.join(d, model.netlist["name"] + ".yaml")
        write_netlist(model.mean_netlist if mean else model.netlist, out)
        return load(out)
