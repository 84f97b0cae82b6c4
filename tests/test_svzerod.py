"""svZeroDSolver interoperability: their blocks against closed forms, and the conformance runner
on their shared test cases (read from ../shared/svzerod when present; skipped otherwise)."""
from __future__ import annotations

import os

import numpy as np
import pytest

from paths import SHARED_SVZEROD as SHARED

from hemocircuit.errors import HemocircuitError, NetlistError
from hemocircuit.svzerod import import_svzerod, load_svzerod

have_cases = pytest.mark.skipif(not os.path.isdir(os.path.join(SHARED, "cases")),
                                reason="svZeroDSolver test cases not present")

SIM = {"number_of_cardiac_cycles": 2, "number_of_time_pts_per_cardiac_cycle": 5}


def _model(vessel_values, bc_out, bc_in=None):
    return {"simulation_parameters": SIM,
            "vessels": [{"vessel_name": "v", "vessel_id": 0, "zero_d_element_type": "BloodVessel",
                         "zero_d_element_values": vessel_values,
                         "boundary_conditions": {"inlet": "IN", "outlet": "OUT"}}],
            "boundary_conditions": [bc_in or {"bc_name": "IN", "bc_type": "FLOW", "bc_values": {"Q": 5.0}}, bc_out]}


def _op(cfg, tmp_path):
    import json
    p = tmp_path / "m.json"
    p.write_text(json.dumps(cfg))
    c = load_svzerod(str(p))
    return c, c.operating_point()


def test_stenosis_is_quadratic(tmp_path):
    """P_in = Pd + R_bc Q + (R + S|Q|) Q (BloodVessel.cpp), in dyn/cm^2 -> mmHg."""
    R, S, Rbc, Pd, Q = 100.0, 30.0, 1000.0, 500.0, 5.0
    cfg = _model({"R_poiseuille": R, "stenosis_coefficient": S},
                 {"bc_name": "OUT", "bc_type": "RESISTANCE", "bc_values": {"R": Rbc, "Pd": Pd}})
    c, op = _op(cfg, tmp_path)
    mmHg = 1333.22387415  # dyn/cm^2
    assert op["P(IN__v)"] * mmHg == pytest.approx(Pd + Rbc * Q + (R + S * Q) * Q, rel=1e-10)


def test_cli_reads_their_json_in_the_unit_system_given(tmp_path, capsys):
    """``--svzerod-units mmHg``: the model's numbers are mmHg, mL, s, so the operating point is
    the closed form of test_stenosis_is_quadratic in mmHg itself; the default (cgs) reads the
    same numbers as dyn/cm^2.  A hemocircuit netlist or an unknown system: a clear error."""
    import json

    from hemocircuit.cli import main

    R, S, Rbc, Pd, Q = 100.0, 30.0, 1000.0, 500.0, 5.0
    cfg = _model({"R_poiseuille": R, "stenosis_coefficient": S},
                 {"bc_name": "OUT", "bc_type": "RESISTANCE", "bc_values": {"R": Rbc, "Pd": Pd}})
    p = tmp_path / "m.json"
    p.write_text(json.dumps(cfg))
    out = tmp_path / "op.json"
    for units, scale in (("mmHg", 1.0), (None, 1333.22387415)):
        args = ["op", str(p), "--out", str(out)] + (["--svzerod-units", units] if units else [])
        assert main(args) in (0, None)
        vals = json.loads(out.read_text())["values"]
        assert vals["P(IN__v) [mmHg]"] * scale == pytest.approx(Pd + Rbc * Q + (R + S * Q) * Q, rel=1e-10)
    capsys.readouterr()
    for args, says in ((["op", str(p), "--svzerod-units", "furlong"], "unknown unit system 'furlong'"),
                       (["op", os.path.join(os.path.dirname(__file__), "..", "netlists", "payne06.yaml"),
                         "--svzerod-units", "mmHg"], "drop --svzerod-units")):
        assert main(args) == 2 and says in capsys.readouterr().err


def test_rcr_and_coronary_steady_states(tmp_path):
    """Steady: capacitors carry no flow, P = Q (Rp + Rd) + Pd and Q (Ra1 + Ra2 + Rv1) + P_v."""
    mmHg = 1333.22387415
    cfg = _model({"R_poiseuille": 0.0, "C": 1e-4, "L": 1.0},
                 {"bc_name": "OUT", "bc_type": "RCR", "bc_values": {"Rp": 100.0, "C": 1e-3, "Rd": 900.0, "Pd": 10.0}})
    _, op = _op(cfg, tmp_path)
    assert op["P(v__OUT)"] * mmHg == pytest.approx(5.0 * 1000.0 + 10.0, rel=1e-9)
    cfg = _model({"R_poiseuille": 50.0},
                 {"bc_name": "OUT", "bc_type": "CORONARY",
                  "bc_values": {"Ra1": 10.0, "Ra2": 20.0, "Rv1": 30.0, "Ca": 1e-4, "Cc": 1e-4, "Pim": 7.0, "P_v": 3.0}})
    _, op = _op(cfg, tmp_path)
    assert op["P(IN__v)"] * mmHg == pytest.approx(5.0 * (50.0 + 60.0) + 3.0, rel=1e-9)


def test_bad_models_name_the_block(tmp_path):
    cfg = _model({"R_poiseuille": 1.0}, {"bc_name": "OUT", "bc_type": "WEIRD", "bc_values": {}})
    with pytest.raises(NetlistError, match="'OUT'.*WEIRD"):
        import_svzerod(cfg)
    cfg = _model({"C": 1.0}, {"bc_name": "OUT", "bc_type": "RESISTANCE", "bc_values": {"R": 1.0, "Pd": 0.0}})
    with pytest.raises(NetlistError, match="'v'.*R_poiseuille"):
        import_svzerod(cfg)
    cfg = _model({"R_poiseuille": 1.0}, {"bc_name": "OUT", "bc_type": "RESISTANCE",
                                         "bc_values": {"R": 1.0, "Pd": [0.0, 1.0, 0.0], "t": [0.0, 0.5, 2.0]}},
                 {"bc_name": "IN", "bc_type": "FLOW", "bc_values": {"Q": [1.0, 2.0, 1.0], "t": [0.0, 0.5, 1.0]}})
    with pytest.raises(NetlistError, match="period"):
        import_svzerod(cfg)


def test_every_supported_block_has_a_component_and_a_missing_one_is_named(tmp_path, monkeypatch):
    """The importer writes a block as the component type that declares it
    (Component.svzerod_blocks): every block type it supports has exactly one; a block no
    component declares is an error naming the element and the block type."""
    from hemocircuit import registry
    from hemocircuit.svzerod import model as svz

    types = registry.svzerod_block_types()
    supported = (svz.SUPPORTED_VESSELS + svz.SUPPORTED_VALVES + svz.SUPPORTED_CHAMBERS + svz.SUPPORTED_BC
                 + svz.SUPPORTED_CLOSED_LOOP)
    assert sorted(set(supported) - set(types)) == []
    assert types["BloodVessel"] == "blood_vessel" and types["ClosedLoopCoronaryRight"] == "closed_loop_coronary"
    # a plug-in subclass of a source implements no block by inheriting (no "implemented twice")
    flow = registry.get_type("flow_source")
    sub = type("MyFlow", (flow,), {"type_name": "my_flow"})
    monkeypatch.setattr(registry, "component_types", lambda: {"flow_source": flow, "my_flow": sub})
    assert dict(registry.svzerod_block_types.__wrapped__()) == {"FLOW": "flow_source"}
    monkeypatch.setattr(registry, "svzerod_block_types", lambda: {k: v for k, v in types.items() if k != "RESISTANCE"})
    cfg = _model({"R_poiseuille": 1.0}, {"bc_name": "OUT", "bc_type": "RESISTANCE", "bc_values": {"R": 1.0, "Pd": 0.0}})
    with pytest.raises(NetlistError, match="'OUT'.*block type 'RESISTANCE'"):
        import_svzerod(cfg)


@have_cases
@pytest.mark.parametrize("case", ["steadyFlow_R_R", "steadyFlow_bifurcationR_R1", "steadyFlow_blood_vessel_junction",
                                  "steadyFlow_stenosis_R", "steadyFlow_RC_R"])
def test_conformance_steady_cases(case):
    from hemocircuit.svzerod.conformance import run_case

    r = run_case(os.path.join(SHARED, "cases", case + ".json"), "converged")
    assert not r.note, r.note
    assert r.err_p <= 1e-6 and r.err_q <= 1e-6, (r.err_p, r.err_q, r.worst)


@have_cases
def test_conformance_pulsatile_rcr():
    from hemocircuit.svzerod.conformance import run_case

    r = run_case(os.path.join(SHARED, "cases", "pulsatileFlow_R_RCR.json"), "converged")
    assert r.ok, (r.err_p, r.err_q, r.worst, r.note)


@have_cases
def test_import_write_reload_identical(tmp_path):
    """import -> YAML -> load gives the same operating point as loading the JSON directly."""
    from hemocircuit.circuit import load
    from hemocircuit.svzerod import write_netlist

    path = os.path.join(SHARED, "cases", "steadyFlow_blood_vessel_junction.json")
    out = tmp_path / "m.yaml"
    write_netlist(import_svzerod(path).netlist, str(out))
    a = dict(load(str(out)).operating_point().items())
    b = dict(load_svzerod(path).operating_point().items())
    assert a.keys() == b.keys() and all(np.array_equal(a[k], b[k]) for k in a)


def test_activation_functions_against_their_definitions():
    """half_cosine peaks at 1 mid-twitch; two_hill's normalisation (exact maximum) matches
    their 1e-5 s scan; piecewise_cosine is 0 before its first contraction (C fmod)."""
    from hemocircuit.components.svzerod.activation import ACT_PARAMS, activation

    names = [n for n, _ in ACT_PARAMS]

    def a(**kw):
        v = np.zeros(len(names))
        for k, x in kw.items():
            v[names.index(k)] = x
        return v

    T = 1.0
    p = a(t_active=0.2, t_twitch=0.3)
    assert activation(0, 0.35, T, p) == pytest.approx(1.0) and activation(0, 0.1, T, p) == 0.0
    p = a(t_shift=0.207, tau_1=0.1855, tau_2=0.3117, m1=1.32, m2=27.4)
    s = np.arange(0.0, T, 1e-5)
    g1, g2 = (s / 0.1855) ** 1.32, (s / 0.3117) ** 27.4
    scan = np.max(g1 / (1 + g1) / (1 + g2))
    peak = s[np.argmax(g1 / (1 + g1) / (1 + g2))]
    # their scan misses the exact maximum by O(h'' (5e-6 s)^2): about 1e-9 here
    assert scan > 0 and activation(2, 0.207 + peak, T, p) == pytest.approx(1.0, rel=1e-8)
    p = a(contract_start=0.3, relax_start=0.5, contract_duration=0.2, relax_duration=0.3)
    assert activation(1, 0.1, T, p) == 0.0 and activation(1, 1.6, T, p) == pytest.approx(0.5 * (1 + np.cos(np.pi * 0.1 / 0.3)))


@pytest.mark.parametrize("kind,values", [
    ("half_cosine", {"t_active": 0.2, "t_twitch": 0.3}),
    ("half_cosine", {"t_active": 0.3, "t_twitch": 0.6}),  # the twitch reaches past the period: a jump at nT
    ("piecewise_cosine", {"contract_start": 0.207, "relax_start": 0.29625, "contract_duration": 0.08925,
                          "relax_duration": 0.26975}),
    ("two_hill", {"t_shift": 0.207, "tau_1": 0.1855, "tau_2": 0.3117, "m1": 1.32, "m2": 27.4}),
    ("wrapping_cosine", {"Tsa": 0.40742, "tpwave": 8.976868}),
    ("fourier", {})])
def test_activation_breakpoints_cover_every_kink(kind, values):
    """Every point of (0, 3T) where A(t), its slope or its curvature jumps (found numerically:
    a third difference on a 1e-4 s grid 20x above its 99.5th percentile, which the smooth parts
    set) (the first of each run of flagged points) lies within 3 grid steps of a listed breakpoint (activation.activation_breakpoints,
    which the chambers declare)."""
    from hemocircuit.components.svzerod.activation import ACT_PARAMS, activation, activation_breakpoints

    T, h = 0.8, 1e-4
    a = np.array([values.get(n, 0.0) for n, _ in ACT_PARAMS])
    t = np.arange(h, 3 * T - h, h)
    A = np.array([activation(("half_cosine", "piecewise_cosine", "two_hill", "wrapping_cosine", "fourier").index(kind),
                             tt, T, a) for tt in t])
    d3 = np.abs(np.diff(A, 3))
    flagged = t[2:-1][d3 > 20 * np.percentile(d3, 99.5) + 1e-14]
    # a kink flags a few neighbours (two_hill's s^1.32 onset: a run of them): its first point
    starts = flagged[np.r_[True, np.diff(flagged) > 10 * h]] if flagged.size else flagged
    listed = np.array(activation_breakpoints(kind, {"period": T, **values}, 0.0, 3 * T))
    for k in starts:
        assert listed.size and np.min(np.abs(listed - k)) <= 3 * h, (kind, k, listed)
    if kind == "fourier":
        assert listed.size == 0


def test_piecewise_valve_steady_flow(tmp_path):
    """Forward: Q = P/(Rmin + R_bc); a backward pressure sees Rmax (PiecewiseValve.cpp)."""
    for P, Rv in ((1000.0, 10.0), (-1000.0, 1e4)):
        cfg = {"simulation_parameters": SIM,
               "vessels": [{"vessel_name": "v", "vessel_id": 0, "zero_d_element_type": "BloodVessel",
                            "zero_d_element_values": {"R_poiseuille": 0.0},
                            "boundary_conditions": {"outlet": "OUT"}}],
               "valves": [{"name": "valve", "type": "PiecewiseValve",
                           "params": {"Rmin": 10.0, "Rmax": 1e4, "upstream_block": "IN", "downstream_block": "v"}}],
               "boundary_conditions": [{"bc_name": "IN", "bc_type": "PRESSURE", "bc_values": {"P": P}},
                                       {"bc_name": "OUT", "bc_type": "RESISTANCE", "bc_values": {"R": 90.0, "Pd": 0.0}}]}
        _, op = _op(cfg, tmp_path)
        assert op["valve.Q"] == pytest.approx(P / (Rv + 90.0), rel=1e-9)


def test_chamber_needs_a_known_activation(tmp_path):
    cfg = {"simulation_parameters": SIM, "boundary_conditions": [],
           "chambers": [{"name": "LV", "type": "LinearElastanceChamber", "values": {"Emax": 1.0, "Epass": 1.0, "Vrest": 1.0},
                         "activation_function": {"type": "sawtooth"}}]}
    with pytest.raises(NetlistError, match="'LV'.*sawtooth"):
        import_svzerod(cfg)


@have_cases
@pytest.mark.parametrize("case", ["valve_tanh", "closed_loop_two_hill"])
def test_conformance_valve_and_closed_loop(case):
    """A valve case and a closed loop (Regazzoni, SI units, their initial condition; the
    blood volume is a conservation law with their initial total)."""
    from hemocircuit.svzerod.conformance import run_case

    r = run_case(os.path.join(SHARED, "cases", case + ".json"), "converged")
    assert r.ok, (r.err_p, r.err_q, r.worst, r.note)


@have_cases
def test_closed_loop_conserves_volume():
    """Over 3 cycles of the closed loop the store volumes keep their initial total."""
    from hemocircuit.analyses.transient import simulate
    from hemocircuit.ic import apply_ic

    path = os.path.join(SHARED, "cases", "closed_loop_two_hill.json")
    m = import_svzerod(path, units="SI")
    c = load_svzerod(path, units="SI")
    assert len(c.law_specs) == 1
    x0 = apply_ic(c, np.zeros(c.nx), m.initial)
    res = simulate(c, 2 * m.period, dt=m.period / 50, x0=x0, rtol=1e-7, progress=False)
    tot = c.law_volumes(np.asarray(res.x))[0]
    assert np.ptp(tot) < 1e-6 * abs(tot[0]) and tot[0] == pytest.approx(float(m.netlist["constraints"][0]["volume"].split()[0]) * 1e6, rel=1e-9)


def test_periodic_waveform_repeats_one_cycle():
    """{periodic: {period, pwl}} is the table at t0 + (t - t0) mod period, compiled and in
    Python alike; its breakpoints are the table's times in every cycle of the range."""
    from hemocircuit.kernels.waveforms import encode, wave_value
    from hemocircuit.waveforms import parse_waveform

    rows = [["0.5 s", "1 mL/s"], ["0.8 s", "4 mL/s"], ["1.5 s", "1 mL/s"]]
    wf = parse_waveform({"periodic": {"period": "1 s", "pwl": rows}}, "mL/s")
    rec = encode(wf)
    for t in (-0.7, 0.0, 0.5, 0.65, 1.2, 3.8, 10.15):
        ph = 0.5 + (t - 0.5) % 1.0
        want = np.interp(ph, [0.5, 0.8, 1.5], [1.0, 4.0, 1.0])
        assert wf(t) == pytest.approx(want, abs=1e-12) and wave_value(rec, 0, t) == wf(t)
    assert wf.breakpoints(1.0, 3.0) == pytest.approx([1.5, 1.8, 2.5, 2.8])
    for bad, msg in (({"period": "0 s", "pwl": rows}, "must be > 0"), ({"period": "0.5 s", "pwl": rows}, "spans"),
                     ({"period": "1 s", "sine": {}}, "repeats a table"), ({"pwl": rows}, "period")):
        with pytest.raises(NetlistError, match=msg):
            parse_waveform({"periodic": bad}, "mL/s")


def test_their_time_series_are_one_periodic_cycle():
    """The importer writes one cycle (their fmod interpolation), not one per simulated cycle."""
    cfg = _model({"R_poiseuille": 1.0}, {"bc_name": "OUT", "bc_type": "RESISTANCE", "bc_values": {"R": 1.0, "Pd": 0.0}},
                 {"bc_name": "IN", "bc_type": "FLOW", "bc_values": {"Q": [1.0, 3.0, 1.0], "t": [0.0, 0.4, 1.0]}})
    src = next(e for e in import_svzerod(cfg).netlist["elements"] if e["id"] == "IN")
    assert list(src["value"]) == ["periodic"] and len(src["value"]["periodic"]["pwl"]) == 3


def test_a_stenosis_needs_the_stenotic_option(tmp_path):
    """Without 'stenotic' a vessel is linear (constant matrix): a coefficient is an error."""
    from hemocircuit.circuit import load
    from hemocircuit.svzerod import write_netlist

    cfg = _model({"R_poiseuille": 1.0, "stenosis_coefficient": 2.0},
                 {"bc_name": "OUT", "bc_type": "RESISTANCE", "bc_values": {"R": 1.0, "Pd": 0.0}})
    nl = import_svzerod(cfg).netlist
    v = next(e for e in nl["elements"] if e["id"] == "v")
    assert v["stenotic"] is True
    v["stenotic"] = False
    write_netlist(nl, str(tmp_path / "m.yaml"))
    with pytest.raises(NetlistError, match="stenotic"):
        load(str(tmp_path / "m.yaml"))


def _sine_series(f, n=41, T=1.0):
    t = np.linspace(0.0, T, n)
    return t, f(t)


def test_capacitor_across_a_pressure_source_is_reduced():
    """PRESSURE P(t) -> BloodVesselCRL (C at the inlet) -> FLOW Q(t): the capacitor's volume
    is C P(t), so its flow is C dP/dt of their linear interpolation, and their flow_in is
    Q(t) + C dP/dt; P_out = P(t) - R Q(t)."""
    from hemocircuit.derived import evaluate_derived

    t, P = _sine_series(lambda t: 10.0 + 5.0 * np.sin(2 * np.pi * t))
    _, Q = _sine_series(lambda t: 2.0 + np.cos(2 * np.pi * t))
    R, C = 3.0, 0.2
    cfg = {"simulation_parameters": {**SIM, "number_of_time_pts_per_cardiac_cycle": 11},
           "vessels": [{"vessel_name": "v", "vessel_id": 0, "zero_d_element_type": "BloodVesselCRL",
                        "zero_d_element_values": {"R_poiseuille": R, "C": C},
                        "boundary_conditions": {"inlet": "IN", "outlet": "OUT"}}],
           "boundary_conditions": [{"bc_name": "IN", "bc_type": "PRESSURE", "bc_values": {"P": P.tolist(), "t": t.tolist()}},
                                   {"bc_name": "OUT", "bc_type": "FLOW", "bc_values": {"Q": Q.tolist(), "t": t.tolist()}}]}
    m = import_svzerod(cfg, units="mmHg")
    c = load_svzerod(cfg, units="mmHg")
    assert c.nx == 0  # no state left: everything follows the sources
    tt = np.array([0.13, 0.52, 1.77])  # inside table intervals (the slope is defined)
    res = c.outputs(tt, np.zeros((tt.size, 0)))
    cols = {**res, **evaluate_derived(m.netlist["derived"], res)}
    slope = np.diff(P) / np.diff(t)
    k = np.searchsorted(t, tt % 1.0, side="right") - 1
    q = np.interp(tt % 1.0, t, Q)
    assert cols[m.columns["v:flow_in"]] == pytest.approx(q + C * slope[k], rel=1e-12)
    assert cols[m.columns["v:pressure_out"]] == pytest.approx(np.interp(tt % 1.0, t, P) - R * q, rel=1e-12)


def test_inductor_in_series_with_a_flow_source_is_reduced():
    """FLOW Q(t) -> RL vessel -> RESISTANCE: the inductor's flow is Q(t), so P_in = Pd +
    (R_bc + R) Q + L dQ/dt with their interpolation's slope (BloodVessel.cpp)."""
    t, Q = _sine_series(lambda t: 5.0 + 2.0 * np.sin(2 * np.pi * t))
    R, L, Rbc, Pd = 4.0, 0.5, 10.0, 7.0
    cfg = _model({"R_poiseuille": R, "L": L}, {"bc_name": "OUT", "bc_type": "RESISTANCE", "bc_values": {"R": Rbc, "Pd": Pd}},
                 {"bc_name": "IN", "bc_type": "FLOW", "bc_values": {"Q": Q.tolist(), "t": t.tolist()}})
    m = import_svzerod(cfg, units="mmHg")
    c = load_svzerod(cfg, units="mmHg")
    assert c.nx == 0
    tt = np.array([0.07, 0.61, 2.33])
    res = c.outputs(tt, np.zeros((tt.size, 0)))
    q = np.interp(tt % 1.0, t, Q)
    dq = (np.diff(Q) / np.diff(t))[np.searchsorted(t, tt % 1.0, side="right") - 1]
    assert res[m.columns["v:pressure_in"]] == pytest.approx(Pd + (Rbc + R) * q + L * dq, rel=1e-12)
    assert res[m.columns["v:flow_out"]] == pytest.approx(q, rel=1e-12)


@have_cases
@pytest.mark.parametrize("case", ["pulsatileFlow_CRL", "pulsatileFlow_CStenosis_steadyPressure", "steadyFlow_RL_R"])
def test_conformance_reduced_cases(case):
    """The three cases with a capacitor across a PRESSURE or an inductor after a FLOW."""
    from hemocircuit.svzerod.conformance import run_case

    r = run_case(os.path.join(SHARED, "cases", case + ".json"), "converged")
    assert r.ok, (r.err_p, r.err_q, r.worst, r.note)


@have_cases
def test_commands_read_their_json(tmp_path, capsys):
    """A .json svZeroDSolver model loads like a netlist (the same circuit as the importer's
    YAML) and a command runs on it directly."""
    from hemocircuit.circuit import load
    from hemocircuit.cli import main
    from hemocircuit.svzerod import write_netlist

    path = os.path.join(SHARED, "cases", "steadyFlow_R_coronary.json")
    write_netlist(import_svzerod(path).netlist, str(tmp_path / "m.yaml"))
    a = dict(load(str(tmp_path / "m.yaml")).operating_point().items())
    b = dict(load(path).operating_point().items())
    assert a.keys() == b.keys() and all(np.array_equal(a[k], b[k]) for k in a)
    assert main(["op", path, "--quiet"]) == 0
    assert "P(INFLOW__branch0_seg0)" in capsys.readouterr().out


@have_cases
def test_their_json_numbers_are_numbers_when_loaded_as_a_netlist():
    """A .json model is read as JSON: YAML 1.1 (PyYAML) would take 9.0219259e7 (no sign in
    the exponent, closed_loop_two_hill's R_poiseuille of AR_SYS) for a string, and the
    importer refused the file.  Loaded as a netlist it is the importer's circuit."""
    from hemocircuit.circuit import load

    path = os.path.join(SHARED, "cases", "closed_loop_two_hill.json")
    a = load(path)
    b = load_svzerod(path, units="SI")  # their Regazzoni model is in SI
    assert a.parameters.values["AR_SYS.R_poiseuille"][0] == b.parameters.values["AR_SYS.R_poiseuille"][0] > 0


def test_their_rows_beyond_our_run_are_a_failed_case_not_a_crash(tmp_path):
    """Their result may hold more cycles than the case asks for (their cycle-to-cycle
    criterion adds some): the runner reports the case as failed with the reason instead of
    stopping with an IndexError."""
    import json
    import shutil

    from hemocircuit.svzerod.conformance import run_case

    (tmp_path / "cases").mkdir()
    (tmp_path / "results").mkdir()
    case = tmp_path / "cases" / "steadyFlow_R_RCR.json"
    shutil.copy(os.path.join(SHARED, "cases", "steadyFlow_R_RCR.json"), case)
    with open(os.path.join(SHARED, "converged", "result_steadyFlow_R_RCR.json")) as fh:
        d = json.load(fh)
    last = max(d["name"], key=int)
    d["time"][last] = d["time"][last] + 50.0  # a row 50 s after the end of our run
    (tmp_path / "results" / "result_steadyFlow_R_RCR.json").write_text(json.dumps(d))
    r = run_case(str(case), against="results")
    assert not r.ok and "beyond our output" in r.note


@have_cases
def test_heart_valves_close_without_creeping():
    """closedLoopHeart_singleVessel's 10 cycles at the conformance tolerance (rtol 1e-7): with
    their valve switch v(Q <= 0) inside the right-hand side, the steps crept below Q_RA ~1e-7
    mL/s near t = 6.0195 s (300 000 steps reached t = 6.019459 s); with the open valve continued
    below the bound, each valve closure is a hard-limit event (5 per cycle at most: one per
    valve and the aortic valve's reopening transient) and the run takes < 10 000 steps.  On
    the way every valve flow stays >= 0, a closed valve holds exactly 0, and the blood volume
    (a conservation law) keeps its initial total."""
    from hemocircuit.ic import apply_ic
    from hemocircuit.kernels.system import CompiledSystem

    path = os.path.join(SHARED, "cases", "closedLoopHeart_singleVessel.json")
    m = import_svzerod(path)
    c = load_svzerod(path)
    x0 = apply_ic(c, np.zeros(c.nx), m.initial)
    system = CompiledSystem.of(c)
    t = np.linspace(0.0, m.n_cycles * m.period, 2001)
    X, st = system.integrate(t, x0, system.params(c)[0], rtol=1e-7, max_steps=100_000)
    assert st["status"] == 0 and st["steps"] < 10_000, st
    assert 4 * m.n_cycles <= st["limit_events"] <= 6 * m.n_cycles, st
    q = X[:, [c.state_names.index(f"CLH.{k}") for k in ("Q_RA", "Q_RV", "Q_LA", "Q_LV")]]
    assert q.min() >= 0.0 and (q == 0.0).mean() > 0.3  # each valve closed for part of the cycle
    tot = c.law_volumes(X)[0]
    assert np.ptp(tot) < 1e-6 * abs(tot[0])


def test_chamber_case_keeps_its_start_and_passes():
    """chamber_elastance_inductor: both valves closed most of the cycle make its slowest mode
    far slower than its 30 s run, so the runner starts it by their steady_initial procedure,
    which gives their start (their solver's t = 0 row with output_all_cycles: Vc 96.06182131 mL,
    Q_out -9.2214539e-4 mL/s in their cgs units), its drift tolerances are tight on the chamber
    volume only, and the case passes against converged/; an RCR case forgets its start (tau 0.1 s)."""
    import json

    from hemocircuit.analyses.op import operating_point
    from hemocircuit.svzerod.conformance import run_case
    from hemocircuit.svzerod.tolerances import DRIFT_ATOL, DRIFT_ATOL_OTHERS, drift_atol, keeps_its_start
    from hemocircuit.svzerod.importer import guess_units
    from hemocircuit.svzerod.output import _circuits
    from hemocircuit.svzerod.steady_initial import their_steady_initial

    def model_of(name):
        path = os.path.join(SHARED, "cases", name + ".json")
        with open(path) as fh:
            m = import_svzerod(path, units=guess_units(json.load(fh)))
        return m, _circuits(m, None)

    m, (c, cm) = model_of("chamber_elastance_inductor")
    assert keeps_its_start(m, cm, operating_point(cm).x)
    # the tight absolute tolerance on the state the slow mode moves only (the chamber volume)
    atol = drift_atol(m, cm, operating_point(cm).x, c)
    assert len(atol) == c.nx
    tight = [n for n, a in zip(c.state_names, atol) if a == DRIFT_ATOL]
    assert tight == ["ventricle.Vc"] and set(atol) == {DRIFT_ATOL, DRIFT_ATOL_OTHERS}, atol
    x = their_steady_initial(m, cm)
    assert x[c.state_names.index("ventricle.Vc")] == pytest.approx(96.06182131239247, abs=1e-7)
    assert x[c.state_names.index("ventricle.Q_out")] == pytest.approx(-9.221453883781882e-4, rel=1e-6)
    r = run_case(os.path.join(SHARED, "cases", "chamber_elastance_inductor.json"), "converged")
    assert r.ok, (r.err_p, r.err_q, r.worst, r.note)
    m, (c, cm) = model_of("pulsatileFlow_R_RCR")
    assert not keeps_its_start(m, cm, operating_point(cm).x)
    with pytest.raises(HemocircuitError, match="forgets it"):  # no drift to keep
        drift_atol(m, cm, operating_point(cm).x, c)


@have_cases
def test_chamber_outflow_jacobian_resolves_the_valve():
    """One cycle of chamber_elastance_inductor at rtol 1e-7 from their start: with Q_out's
    finite-difference step (1e-7 x its scale) below the width 1/(k Rmax) = 1e-7 mL/s over
    which valve 1 switches, RODAS5P needs a few hundred steps (it took 21 703 with scale 10,
    whose step 1e-6 mL/s made the Jacobian wrong at each opening and closing)."""
    import json

    from hemocircuit.kernels.system import CompiledSystem
    from hemocircuit.svzerod.importer import guess_units
    from hemocircuit.svzerod.output import _circuits

    path = os.path.join(SHARED, "cases", "chamber_elastance_inductor.json")
    with open(path) as fh:
        m = import_svzerod(path, units=guess_units(json.load(fh)))
    c, _ = _circuits(m, None)
    s = CompiledSystem.of(c)
    x0 = np.array([6.34375125e-03, 96.06182131239247, -9.221453883781882e-04])  # their start
    br, kinks = c.jumps_and_kinks(0.0, 1.0)
    X, st = s.integrate(np.linspace(0.0, 1.0, 101), x0, s.params(c)[0], rtol=1e-7, breaks=br,
                        kinks=kinks)
    assert st["status"] == 0 and st["steps"] < 1500, st
    assert X[-1, 1] == pytest.approx(96.06181015, abs=5e-6)  # their dt/1000 solution after one cycle


def _cycle_error_model(tmp_path, n_cycles, all_cycles=True):
    """FLOW 1 + 0.5 sin -> vessel (R 100, C 1e-2) -> RESISTANCE 1000 from zero, with their
    use_cycle_to_cycle_error: tau = C (R + Rd) = 11 s, 10 points per cycle of 1 s."""
    import json

    t = np.linspace(0.0, 1.0, 11)
    cfg = {"simulation_parameters": {"number_of_cardiac_cycles": n_cycles, "number_of_time_pts_per_cardiac_cycle": 11,
                                     "output_all_cycles": all_cycles, "use_cycle_to_cycle_error": True,
                                     "sim_cycle_to_cycle_percent_error": 1.0, "steady_initial": False},
           "vessels": [{"vessel_name": "v", "vessel_id": 0, "zero_d_element_type": "BloodVessel",
                        "zero_d_element_values": {"R_poiseuille": 100.0, "C": 1e-2},
                        "boundary_conditions": {"inlet": "IN", "outlet": "OUT"}}],
           "boundary_conditions": [{"bc_name": "IN", "bc_type": "FLOW",
                                    "bc_values": {"Q": list(1.0 + 0.5 * np.sin(2 * np.pi * t)), "t": list(t)}},
                                   {"bc_name": "OUT", "bc_type": "RESISTANCE", "bc_values": {"R": 1000.0, "Pd": 0.0}}],
           "initial_condition": {}}
    p = tmp_path / "m.json"
    p.write_text(json.dumps(cfg))
    return str(p), cfg


def test_runner_adds_their_extra_cycles(tmp_path):
    """Without an RCR their criterion runs one more cycle at a time after the given ones until
    the mean pressure and flow at the vessel caps change by <= 1 % (Solver.cpp): the rows of
    those cycles follow, times restarting at dt; the criterion fails between the two cycles
    before the last and holds between the last two.  Only the last cycle written: the given
    last cycle's rows, whatever was run after."""
    from hemocircuit.svzerod.conformance import simulate_case
    from hemocircuit.svzerod.cycles import cycle_errors, cycle_means

    path, cfg = _cycle_error_model(tmp_path, 3)
    m = import_svzerod(path)
    res, keep, t_out, _ = simulate_case(m, cfg=cfg)
    n = (t_out.size - 1) // 10
    assert n > 3 and t_out.size == 10 * n + 1  # extra cycles were run and written
    np.testing.assert_allclose(t_out[:31], np.arange(31) * 0.1, atol=1e-12)
    np.testing.assert_allclose(t_out[31:41], np.arange(1, 11) * 0.1, atol=1e-12)
    cols = [m.columns["v:pressure_in"], m.columns["v:flow_in"]]
    errs = np.max([cycle_errors(cycle_means(np.asarray(res[k])[keep], 11))[0] for k in cols], axis=0)
    assert errs[-1] <= 0.01 < errs[-2], errs
    path, cfg = _cycle_error_model(tmp_path, 3, all_cycles=False)
    m = import_svzerod(path)
    res, keep, t_out, _ = simulate_case(m, cfg=cfg)
    assert t_out.size == 11 and np.asarray(res.t)[keep][0] == pytest.approx(2.0)


def test_runner_calls_between_after_each_timed_run_untimed(tmp_path):
    """simulate_case(between=...) (a benchmark's run of their solver in the same rounds): called
    once after each timed run, and its time is in none of the runs' times."""
    import time

    from hemocircuit.svzerod.conformance import simulate_case

    path, cfg = _cycle_error_model(tmp_path, 3, all_cycles=False)
    m = import_svzerod(path)
    simulate_case(m, cfg=cfg)  # compiles the engine, if this test runs first
    calls = []
    _, _, _, times = simulate_case(m, cfg=cfg, timed_runs=3, between=lambda: (calls.append(1), time.sleep(1.0)))
    assert len(calls) == 3 and times.shape == (3, 2)
    assert np.all(times[:, 0] < 1.0), times  # a run takes ~0.05 s; with the sleep it would be > 1 s


@have_cases
def test_their_own_step_is_off_their_converged_result_on_the_chamber_case():
    """compare_their_rows (the accuracy-matched benchmark's measure) on their stored result at
    the case's own step against the dt/10 one: the README's 0.2-30 % for chambers; a known
    offset of a tenth of a pressure's range reads as 0.1 of it, and the first cycle of an
    all-cycles output with a steady start is left out as compare() leaves it out."""
    from hemocircuit.svzerod.conformance import compare_their_rows, read_result

    name = "chamber_elastance_inductor"
    model = import_svzerod(os.path.join(SHARED, "cases", f"{name}.json"))
    conv = read_result(os.path.join(SHARED, "converged", f"result_{name}.json"))
    stored = read_result(os.path.join(SHARED, "results", f"result_{name}.json"))
    e_p, e_q = compare_their_rows(model, stored, conv)
    assert 0.2 < e_p < 0.3 and 0.05 < e_q < 0.1  # Vc: 2.9e-1, flows 8.4e-2 (measured)
    key = "pressure:valve0:ventricle"
    t, y = conv[key]
    shifted = dict(conv)
    shifted[key] = (t, y + 0.1 * np.ptp(y))
    assert compare_their_rows(model, shifted, conv) == pytest.approx((0.1, 0.0), abs=1e-12)
    model.sim["output_all_cycles"] = True  # then rows before t = T do not count
    early = dict(conv)
    early[key] = (t, np.where(t < model.period * 0.999, y + 5 * np.ptp(y), y))
    assert compare_their_rows(model, early, conv)[0] == 0.0
