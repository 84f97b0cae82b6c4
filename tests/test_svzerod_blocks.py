"""The svZeroDSolver blocks added after the first import (BloodVesselRC, CORONARY_VAR_RES, the
closed-loop coronaries, the exponential elastance chamber, ChamberSphere, the fourier
activation, ValveTanh with Rmin = 0) against closed forms and their own definitions, read
through the importer from small JSON models built here (cgs numbers, as their cases)."""
from __future__ import annotations

import json
import math
import os

import numpy as np
import pytest

from paths import SHARED_SVZEROD as SHARED

from hemocircuit.errors import NetlistError
from hemocircuit.svzerod import import_svzerod

MMHG = 1333.22387415  # dyn/cm^2


def _sim(cycles=1, points=11, **more):
    return {"number_of_cardiac_cycles": cycles, "number_of_time_pts_per_cardiac_cycle": points,
            "steady_initial": False, **more}


def _run(cfg, tmp_path, t_end, dt, rtol=1e-8):
    """(model, circuit, result) from their initial condition (zeros where not given)."""
    from hemocircuit.analyses.transient import simulate
    from hemocircuit.circuit import load
    from hemocircuit.ic import apply_ic
    from hemocircuit.svzerod import write_netlist

    p = tmp_path / "m.json"
    p.write_text(json.dumps(cfg))
    model = import_svzerod(str(p))
    write_netlist(model.netlist, str(tmp_path / "m.yaml"))
    c = load(str(tmp_path / "m.yaml"))
    x0 = apply_ic(c, np.zeros(c.nx), model.initial)
    return model, c, simulate(c, t_end, dt=dt, x0=x0, rtol=rtol, progress=False)


def _vessel(name, typ, values, inlet=None, outlet=None, vid=0):
    bc = {k: v for k, v in (("inlet", inlet), ("outlet", outlet)) if v}
    return {"vessel_name": name, "vessel_id": vid, "zero_d_element_type": typ, "zero_d_element_values": values,
            "boundary_conditions": bc}


# --- BloodVesselRC ------------------------------------------------------------------------
def test_blood_vessel_rc_charges_its_inlet_capacitor(tmp_path):
    """FLOW Q into the RC, a zero PRESSURE after it (BloodVesselRC.cpp: Cp dP_in/dt =
    Q_in - (P_in - P_out)/Rpd, Q_in = Q_out): from rest P_in = Q Rpd (1 - exp(-t/(Rpd Cp))),
    while the whole inflow leaves at the outlet (a flow-through RC, not a CRL vessel whose
    outflow would be P_in/Rpd)."""
    Q, Rpd, Cp = 5.0, 100.0, 2e-3
    cfg = {"simulation_parameters": _sim(),
           "vessels": [_vessel("v", "BloodVesselRC", {"Rpd": Rpd, "Cp": Cp}, "IN", "OUT")],
           "boundary_conditions": [{"bc_name": "IN", "bc_type": "FLOW", "bc_values": {"Q": Q}},
                                   {"bc_name": "OUT", "bc_type": "PRESSURE", "bc_values": {"P": 0.0}}]}
    _, _, res = _run(cfg, tmp_path, 1.0, 0.05, rtol=1e-9)
    t = np.asarray(res.t)
    P = np.asarray(res["P(IN__v)"]) * MMHG
    exact = Q * Rpd * (1.0 - np.exp(-t / (Rpd * Cp)))
    assert np.max(np.abs(P - exact)) < 1e-5 * Q * Rpd
    assert np.allclose(np.asarray(res["v.Q_out"]), Q, rtol=1e-12) and np.allclose(np.asarray(res["Q(OUT)"]), Q)  # into the PRESSURE


def test_blood_vessel_rc_takes_only_its_two_values(tmp_path):
    cfg = {"simulation_parameters": _sim(),
           "vessels": [_vessel("v", "BloodVesselRC", {"Rpd": 1.0, "Cp": 1e-3, "L": 1.0}, "IN", "OUT")],
           "boundary_conditions": [{"bc_name": "IN", "bc_type": "FLOW", "bc_values": {"Q": 1.0}},
                                   {"bc_name": "OUT", "bc_type": "PRESSURE", "bc_values": {"P": 0.0}}]}
    with pytest.raises(NetlistError, match=r"'v'.*\['L'\].*Rpd, Cp"):
        import_svzerod(cfg)


# --- CORONARY_VAR_RES -----------------------------------------------------------------------
def test_var_res_follows_their_phases():
    """Ram(t) = (sqrt(Rmin) + (sqrt(Rmax) - sqrt(Rmin)) e(t))^2, e = 0 at the cycle start, 1 at
    the end of contraction T_vc, 1/2 mid-contraction and mid-relaxation, 0 at rest
    (OpenLoopCoronaryVarResBC.cpp get_Ram); periodic in T."""
    from hemocircuit.components.svzerod.coronary_var_res_bc import var_resistance

    Rmin, Rmax, Tvc, Tvr, T = 50.0, 200.0, 0.3, 0.4, 1.0
    half = ((math.sqrt(Rmin) + math.sqrt(Rmax)) / 2) ** 2  # 112.5
    for t, want in ((0.0, Rmin), (0.15, half), (0.3, Rmax), (0.5, half), (0.7, Rmin), (0.85, Rmin),
                    (1.15, half), (2.3, Rmax)):
        assert var_resistance(t, T, Rmin, Rmax, Tvc, Tvr) == pytest.approx(want, rel=1e-12), t


def test_var_res_coronary_is_quasi_static_with_tiny_capacitors(tmp_path):
    """With Ca, Cc -> 0 the bed is three resistors in series: P_in(t) = Q (R + Ra1 + Ram(t) +
    Rv1) + P_v at every time, so the inlet pressure traces Ram(t) (the block's time-varying
    resistance reaches the compiled right-hand side)."""
    from hemocircuit.components.svzerod.coronary_var_res_bc import var_resistance

    Q, R, Ra1, Rv1, Pv = 3.0, 20.0, 100.0, 100.0, 500.0
    bc = {"bc_name": "OUT", "bc_type": "CORONARY_VAR_RES",
          "bc_values": {"Ra1": Ra1, "Ra2_min": 50.0, "Ra2_max": 200.0, "Rv1": Rv1, "Ca": 1e-8, "Cc": 1e-8,
                        "P_v": Pv, "Pim": [0.0, 0.0], "t": [0.0, 1.0], "T_vc": 0.3, "T_vr": 0.4}}
    cfg = {"simulation_parameters": _sim(),
           "vessels": [_vessel("v", "BloodVessel", {"R_poiseuille": R}, "IN", "OUT")],
           "boundary_conditions": [{"bc_name": "IN", "bc_type": "FLOW", "bc_values": {"Q": Q}}, bc]}
    _, _, res = _run(cfg, tmp_path, 2.0, 0.01)
    t = np.asarray(res.t)
    sel = t > 0.01  # after the initial charging (time constant ~1e-6 s)
    ram = np.array([var_resistance(tt, 1.0, 50.0, 200.0, 0.3, 0.4) for tt in t[sel]])
    P = np.asarray(res["P(IN__v)"])[sel] * MMHG
    assert np.max(np.abs(P - (Q * (R + Ra1 + ram + Rv1) + Pv))) < 1e-3 * Q * 200.0


# --- closed-loop coronaries ----------------------------------------------------------------
def _heart_with_coronaries():
    """Their closedLoopHeart_singleVessel (shared case) with a left and a right closed-loop
    coronary on two more outlets of the heart."""
    path = os.path.join(SHARED, "cases", "closedLoopHeart_singleVessel.json")
    if not os.path.isfile(path):
        pytest.skip("svZeroDSolver shared cases not present")
    cfg = json.load(open(path))
    cfg["simulation_parameters"]["number_of_cardiac_cycles"] = 2
    for i, (bc, typ, vals) in enumerate((("LCA", "ClosedLoopCoronaryLeft", (10.0, 15.0, 30.0, 5e-4, 4e-3)),
                                         ("RCA", "ClosedLoopCoronaryRight", (6.0, 9.0, 20.0, 1e-3, 3.5e-3)))):
        name = f"cor{i}"
        cfg["vessels"].append(_vessel(name, "BloodVessel", {"R_poiseuille": 0.5, "L": 0.004}, outlet=bc, vid=10 + i))
        cfg["closed_loop_blocks"][0]["outlet_blocks"].append(name)
        cfg["boundary_conditions"].append({"bc_name": bc, "bc_type": typ,
                                           "bc_values": dict(zip(("Ra", "Ram", "Rv", "Ca", "Cim"), vals))})
    return cfg


def test_closed_loop_coronaries_follow_their_ventricles(tmp_path):
    """P_im of ClosedLoopCoronaryLeft is iml * P_LV of the heart, of the right one imr * P_RV
    (ClosedLoopCoronaryLeftBC.cpp / RightBC.cpp), at every output time; the flow through each
    bed is (P_a - P_m)/Ram with P_a = V_a/Ca, P_m = V_im/Cim + P_im; and the closed loop keeps
    its blood volume (the coronary volumes are stores)."""
    cfg = _heart_with_coronaries()
    T = cfg["closed_loop_blocks"][0]["cardiac_cycle_period"]
    prm = cfg["closed_loop_blocks"][0]["parameters"]
    model, c, res = _run(cfg, tmp_path, 2 * T, T / 99, rtol=1e-7)
    assert model.closed
    col = lambda k: np.asarray(res[k])  # noqa: E731
    assert np.allclose(col("LCA.P_im"), prm["iml"] * col("CLH.P_LV"), rtol=1e-12, atol=1e-12)
    assert np.allclose(col("RCA.P_im"), prm["imr"] * col("CLH.P_RV"), rtol=1e-12, atol=1e-12)
    assert np.ptp(col("LCA.P_im")) * MMHG > 10.0  # the left ventricle's pressure does vary (theirs: mmHg)
    # the bed's flows from its states: Q_in - Q_out = dV_a/dt + dV_im/dt, and the outflow
    # Q_out = (P_m - P_RA)/Rv with P_m = V_im/Cim + P_im
    Pm = col("LCA.V_im") / (4e-3 * MMHG) + col("LCA.P_im")  # Cim, Rv in mmHg units
    assert np.allclose(col("LCA.Q_out"), (Pm - col("P(J_heart_inlet)")) / (30.0 / MMHG), rtol=1e-9, atol=1e-9)
    stores = ["V(CLH)", "CLH.V_ao", "V(RCR_aorta)", "LCA.V_a", "LCA.V_im", "RCA.V_a", "RCA.V_im"] + [
        k for k in res.columns if k.startswith("V(") and k not in ("V(CLH)", "V(RCR_aorta)")]
    total = sum(col(k) for k in stores)
    assert np.ptp(total) < 1e-6 * total[0], stores
    assert np.ptp(col("LCA.V_im")) > 1e-3  # the intramyocardial volume moves


def test_closed_loop_coronary_needs_the_heart():
    cfg = {"simulation_parameters": _sim(),
           "vessels": [_vessel("v", "BloodVessel", {"R_poiseuille": 1.0}, "IN", "COR")],
           "boundary_conditions": [{"bc_name": "IN", "bc_type": "FLOW", "bc_values": {"Q": 1.0}},
                                   {"bc_name": "COR", "bc_type": "ClosedLoopCoronaryLeft",
                                    "bc_values": {"Ra": 1.0, "Ram": 1.0, "Rv": 1.0, "Ca": 1e-3, "Cim": 1e-3}}]}
    with pytest.raises(NetlistError, match="'COR'.*ClosedLoopHeartAndPulmonary"):
        import_svzerod(cfg)


# --- ChamberElastanceInductorExponential and the fourier activation -------------------------
def _wrapping_cosine(t, T, Tsa, tpwave):
    """Their WrappingCosineActivation::compute, written out again for the check."""
    Tsa, tp, tc = T * Tsa, T / tpwave, math.fmod(t, T)
    if tc <= tp:
        return 0.5 * (1.0 - math.cos(2.0 * math.pi * (tc - tp + Tsa) / Tsa))
    if (T - Tsa) + tp <= tc < T:
        return 0.5 * (1.0 - math.cos(2.0 * math.pi * (tc - tp - (T - Tsa)) / Tsa))
    return 0.0


def test_exponential_chamber_pressure_volume_law(tmp_path):
    """P_in = A Emax (Vc - Vaso) + (1 - A) Kxp (exp(Kxv (Vc - Vaso)) - 1) at every output time
    (ChamberElastanceInductorExponential.cpp), A the wrapping cosine; the outflow inductor
    holds the mass balance dVc/dt = Q_in - Q_out."""
    Emax, Kxp, Kxv, Vaso, L = 300.0, 9000.0, 0.01, 10.0, 0.5
    Tsa, tpwave, T = 0.4, 9.0, 1.0
    Q = [2.0 + 2.0 * math.sin(2 * math.pi * k / 20) for k in range(21)]
    cfg = {"simulation_parameters": _sim(cycles=2, points=21, cardiac_period=T),
           "vessels": [_vessel("v0", "BloodVessel", {"R_poiseuille": 10.0}, inlet="IN"),
                       _vessel("v1", "BloodVessel", {"R_poiseuille": 1000.0}, outlet="OUT", vid=1)],
           "junctions": [{"junction_name": "J0", "junction_type": "NORMAL_JUNCTION", "inlet_vessels": [0],
                          "outlet_blocks": ["A"]},
                         {"junction_name": "J1", "junction_type": "NORMAL_JUNCTION", "inlet_blocks": ["A"],
                          "outlet_vessels": [1]}],
           "chambers": [{"name": "A", "type": "ChamberElastanceInductorExponential",
                         "values": {"Emax": Emax, "Kxp": Kxp, "Kxv": Kxv, "Vaso": Vaso, "Impedance": L},
                         "activation_function": {"type": "wrapping_cosine", "Tsa": Tsa, "tpwave": tpwave}}],
           "boundary_conditions": [{"bc_name": "IN", "bc_type": "FLOW", "bc_values": {"Q": Q, "t": list(np.linspace(0, T, 21))}},
                                   {"bc_name": "OUT", "bc_type": "RESISTANCE", "bc_values": {"R": 100.0, "Pd": 0.0}}],
           "initial_condition": {"Vc:A": 20.0}}
    _, _, res = _run(cfg, tmp_path, 2 * T, T / 50)
    t, Vc = np.asarray(res.t), np.asarray(res["V(A)"])
    A = np.array([_wrapping_cosine(tt, T, Tsa, tpwave) for tt in t])
    want = A * Emax * (Vc - Vaso) + (1 - A) * Kxp * (np.exp(Kxv * (Vc - Vaso)) - 1)
    P = np.asarray(res["P(J0)"]) * MMHG
    assert np.max(np.abs(P - want)) < 1e-9 * np.max(np.abs(want))
    assert np.ptp(A) > 0.9 and np.ptp(Vc) > 0.1  # both terms of the law are exercised
    q = np.asarray(res["A.Q_in"]) - np.asarray(res["A.Q_out"])
    dV = np.gradient(Vc, t)
    assert np.max(np.abs(q - dV)[2:-2]) < 0.05 * np.max(np.abs(dV))  # finite differences of the output


def test_fourier_activation_is_their_normalised_series():
    """A(t) = (F(t) - min F)/(max F - min F), F their 25-mode series of the phase t/T: 0 and 1
    at the extremes of their 10000-point scan, F(0) = sum of the cosine coefficients, and a
    function of t/T only (FourierActivation in ActivationFunction.cpp)."""
    from hemocircuit.components.svzerod.activation import ACT_PARAMS, FT_ELAST, KINDS, activation

    k = KINDS.index("fourier")
    a = np.zeros(len(ACT_PARAMS))
    scan = np.array([activation(k, i / 10000, 1.0, a) for i in range(10000)])
    assert scan.min() == pytest.approx(0.0, abs=1e-14) and scan.max() == pytest.approx(1.0, abs=1e-14)
    F = 2.0 * math.pi * np.arange(10000)[:, None] * np.arange(25) / 10000
    raw = np.cos(F) @ FT_ELAST[:, 0] - np.sin(F) @ FT_ELAST[:, 1]
    assert activation(k, 0.0, 1.0, a) == pytest.approx((FT_ELAST[:, 0].sum() - raw.min()) / np.ptp(raw), rel=1e-12)
    for t in (0.1, 0.37, 0.8):
        assert activation(k, t * 0.8, 0.8, a) == pytest.approx(activation(k, t, 1.0, a), abs=1e-13)
        assert activation(k, t + 3.0, 1.0, a) == pytest.approx(activation(k, t, 1.0, a), abs=1e-12)


def test_fourier_series_by_recurrence_is_the_direct_sum():
    """fourier_raw takes mode i's cos and sin by angle addition from mode 1: the same series
    as the 25 cos/sin terms written out (their ActivationFunction.cpp), to rounding."""
    from hemocircuit.components.svzerod.activation import FT_ELAST, fourier_raw

    for T in (1.0, 1.0169, 0.8):
        for tc in np.linspace(0.0, T, 97):
            w = 2.0 * math.pi * np.arange(25) * tc / T
            direct = float(np.cos(w) @ FT_ELAST[:, 0] - np.sin(w) @ FT_ELAST[:, 1])
            assert abs(fourier_raw(tc, T) - direct) < 2e-15


def test_fourier_chamber_reproduces_the_heart_elastance(tmp_path):
    """Their note: a ChamberElastanceInductor with the fourier activation, Emax = max F E_s and
    Emin = min F E_s gives E(t) = F(t) E_s, the ClosedLoopHeartAndPulmonary ventricle's."""
    from hemocircuit.components.svzerod.activation import FOURIER_MIN, FOURIER_RANGE, fourier_raw

    Es, Vu = 3.0, 5.0
    cfg = {"simulation_parameters": _sim(cycles=1, points=51, cardiac_period=1.0),
           "vessels": [_vessel("v0", "BloodVessel", {"R_poiseuille": 0.05}, inlet="IN"),
                       _vessel("v1", "BloodVessel", {"R_poiseuille": 1.0}, outlet="OUT", vid=1)],
           "junctions": [{"junction_name": "J0", "junction_type": "NORMAL_JUNCTION", "inlet_vessels": [0],
                          "outlet_blocks": ["LV"]},
                         {"junction_name": "J1", "junction_type": "NORMAL_JUNCTION", "inlet_blocks": ["LV"],
                          "outlet_vessels": [1]}],
           "chambers": [{"name": "LV", "type": "ChamberElastanceInductor",
                         "values": {"Emax": (FOURIER_MIN + FOURIER_RANGE) * Es, "Emin": FOURIER_MIN * Es,
                                    "Vrd": Vu, "Vrs": Vu, "Impedance": 1e-3},
                         "activation_function": {"type": "fourier"}}],
           "boundary_conditions": [{"bc_name": "IN", "bc_type": "PRESSURE", "bc_values": {"P": 8.0}},
                                   {"bc_name": "OUT", "bc_type": "PRESSURE", "bc_values": {"P": 5.0}}],
           "initial_condition": {"Vc:LV": 100.0}}
    _, _, res = _run(cfg, tmp_path, 1.0, 0.02)
    t, Vc = np.asarray(res.t), np.asarray(res["V(LV)"])
    F = np.array([fourier_raw(tt, 1.0) for tt in t])
    assert np.allclose(np.asarray(res["P(J0)"]) * MMHG, Es * F * (Vc - Vu), rtol=1e-9, atol=1e-9)
    assert np.ptp(F) > 0.5 and np.ptp(Vc) > 10.0


def test_unknown_activation_parameters_are_named():
    cfg = {"simulation_parameters": _sim(),
           "chambers": [{"name": "LV", "type": "ChamberElastanceInductor",
                         "values": {"Emax": 1.0, "Emin": 0.1, "Vrd": 1.0, "Vrs": 1.0, "Impedance": 1e-3},
                         "activation_function": {"type": "fourier", "t_active": 0.2}}],
           "boundary_conditions": []}
    with pytest.raises(NetlistError, match=r"'LV'.*t_active.*none"):
        import_svzerod(cfg)


# --- ChamberSphere ------------------------------------------------------------------------
def test_chamber_sphere_active_stress_and_static_equilibrium(tmp_path):
    """A constant activation rate a (alpha_max = alpha_min) gives tau = sigma_max (1 - e^-a t)
    (their active-stress equation); under a constant pressure P the damped wall settles where
    P R = S d0 with S = tau + 4 (1 - (r0/R)^6)(W1 + W2 (R/r0)^2) (balance of momentum at rest,
    ChamberSphere.cpp), and the volume state has grown by 4/3 pi (R^3 - r0^3)."""
    from scipy.optimize import brentq

    P, rho, d0, r0, W1, W2, eta, smax, alpha = 1e4, 1.0, 1.0, 5.0, 1e5, 100.0, 2e4, 2e4, 20.0
    vals = {"rho": rho, "thick0": d0, "radius0": r0, "W1": W1, "W2": W2, "eta": eta, "sigma_max": smax,
            "alpha_max": alpha, "alpha_min": alpha, "tsys": 0.2, "tdias": 0.5, "steepness": 0.005}
    cfg = {"simulation_parameters": _sim(cycles=1, points=11),
           "vessels": [_vessel("ch", "ChamberSphere", vals, "IN", "OUT")],
           "boundary_conditions": [{"bc_name": "IN", "bc_type": "PRESSURE", "bc_values": {"P": P}},
                                   {"bc_name": "OUT", "bc_type": "RESISTANCE", "bc_values": {"R": 1e3, "Pd": 0.0}}]}
    model, _, res = _run(cfg, tmp_path, 2.0, 0.05, rtol=1e-9)
    t = np.asarray(res.t)
    tau = np.asarray(res["ch.tau"]) * MMHG
    assert np.allclose(tau, smax * (1 - np.exp(-alpha * t)), rtol=1e-6, atol=1e-6 * smax)
    ts = smax * (1 - math.exp(-alpha * t[-1]))
    R = brentq(lambda R: P * R - d0 * (ts + 4 * (1 - (r0 / R) ** 6) * (W1 + W2 * (R / r0) ** 2)), r0, 2 * r0)
    assert np.asarray(res["ch.r"])[-1] == pytest.approx(R - r0, rel=1e-6)
    assert np.asarray(res["V(ch)"])[-1] == pytest.approx(4 / 3 * math.pi * (R ** 3 - r0 ** 3), rel=1e-6)
    assert np.asarray(res["ch.S"])[-1] * MMHG == pytest.approx(P * R / d0, rel=1e-6)
    assert abs(np.asarray(res["ch.v"])[-1]) < 1e-6  # at rest
    assert model.columns["radius:ch"] == "ch.r" and model.factors["radius:ch"] == 1.0  # cgs: cm


# --- ValveTanh with Rmin = 0 ----------------------------------------------------------------
def test_valve_tanh_without_open_resistance(tmp_path):
    """Rmin = 0 (their chamber_sphere case): R = Rmax (1 + tanh(k (P_out - P_in)))/2 stays
    positive; the operating point between two pressures solves dP = Q R(dP) with
    Q = (P1 - P2 - dP)/(2 r) through the two vessels."""
    from scipy.optimize import brentq

    P1, P2, r, Rmax, k = 2000.0, 1000.0, 10.0, 1e6, 0.01
    cfg = {"simulation_parameters": _sim(),
           "vessels": [_vessel("v0", "BloodVessel", {"R_poiseuille": r}, inlet="IN"),
                       _vessel("v1", "BloodVessel", {"R_poiseuille": r}, outlet="OUT", vid=1)],
           "valves": [{"type": "ValveTanh", "name": "V",
                       "params": {"Rmin": 0.0, "Rmax": Rmax, "Steepness": k, "upstream_block": "v0",
                                  "downstream_block": "v1"}}],
           "boundary_conditions": [{"bc_name": "IN", "bc_type": "PRESSURE", "bc_values": {"P": P1}},
                                   {"bc_name": "OUT", "bc_type": "PRESSURE", "bc_values": {"P": P2}}]}
    from hemocircuit.svzerod import load_svzerod

    p = tmp_path / "v.json"
    p.write_text(json.dumps(cfg))
    op = load_svzerod(str(p)).operating_point()
    dp = brentq(lambda d: d - (P1 - P2 - d) / (2 * r) * Rmax * 0.5 * (1 + math.tanh(-k * d)), 0.0, P1 - P2)
    assert (op["P(v0__V)"] - op["P(V__v1)"]) * MMHG == pytest.approx(dp, rel=1e-8)
    assert op["Q(V)"] == pytest.approx((P1 - P2 - dp) / (2 * r), rel=1e-8)


# --- their one-element vessels: Resistance, Capacitance, Inductance -----------------------
_T = np.linspace(0.0, 1.0, 101)
_Q_SINE = (2.5 * np.sin(2 * np.pi * _T) + 2.2).tolist()  # a sine inflow [cm^3/s], period 1 s


def _one_element(typ, values, outlet):
    return {"simulation_parameters": _sim(points=101),
            "vessels": [_vessel("v", typ, values, "IN", "OUT")],
            "boundary_conditions": [{"bc_name": "IN", "bc_type": "FLOW", "bc_values": {"Q": _Q_SINE, "t": _T.tolist()}},
                                    outlet]}


def test_resistance_vessel_drops_r_times_the_flow(tmp_path):
    """Resistance.cpp: P_in - P_out = R Q_in, Q_in = Q_out.  FLOW Q(t) into it, P_out = 0:
    P_in = R Q(t) at every row (their pwl inflow, so at its sample times exactly)."""
    R = 100.0
    cfg = _one_element("Resistance", {"R": R}, {"bc_name": "OUT", "bc_type": "PRESSURE", "bc_values": {"P": 0.0}})
    model, _, res = _run(cfg, tmp_path, 1.0, 0.01)
    P = np.asarray(res["P(IN__v)"]) * MMHG
    np.testing.assert_allclose(P, R * np.asarray(_Q_SINE), rtol=1e-9, atol=1e-9 * R)
    np.testing.assert_allclose(np.asarray(res["v.Q_out"]), _Q_SINE, rtol=1e-12, atol=1e-12)
    assert model.netlist["elements"][0]["type"] == "blood_vessel"


def test_capacitance_vessel_integrates_the_net_inflow(tmp_path):
    """Capacitance.cpp: Q_in - Q_out = C dP_in/dt, P_in = P_out.  Q_in = 10, Q_out = 0 (a FLOW
    outlet), from P = 0: P_in = P_out = Q t / C (their pulsatileFlow_capacitance's closed form)."""
    C, Q = 1e-3, 10.0
    cfg = {"simulation_parameters": _sim(cycles=2),
           "vessels": [_vessel("v", "Capacitance", {"C": C}, "IN", "OUT")],
           "boundary_conditions": [{"bc_name": "IN", "bc_type": "FLOW", "bc_values": {"Q": [Q, Q], "t": [0.0, 1.0]}},
                                   {"bc_name": "OUT", "bc_type": "FLOW", "bc_values": {"Q": [0.0, 0.0], "t": [0.0, 1.0]}}]}
    _, c, res = _run(cfg, tmp_path, 2.0, 0.1)
    t = np.asarray(res.t)
    for node in ("IN__v", "v__OUT"):
        np.testing.assert_allclose(np.asarray(res[f"P({node})"]) * MMHG, Q * t / C, rtol=1e-9, atol=1e-9 * Q / C)
    assert c.state_names == ["v.V"]  # the one state: the capacitor's volume


def test_inductance_vessel_drops_l_times_the_flow_rate(tmp_path):
    """Inductance.cpp: P_in - P_out = L dQ_out/dt, Q_in = Q_out.  FLOW Q(t) into it, P_out = 0:
    the source fixes the inductor's flow (index reduction), and P_in = L dQ/dt, the slope of
    their pwl inflow on each interval (their pulsatileFlow_inductance: ~ L 2 pi 2.5 cos(2 pi t))."""
    L = 1.0
    cfg = _one_element("Inductance", {"L": L}, {"bc_name": "OUT", "bc_type": "PRESSURE", "bc_values": {"P": 0.0}})
    _, c, res = _run(cfg, tmp_path, 1.0, 0.005)
    slope = np.diff(_Q_SINE) / np.diff(_T)
    t = np.asarray(res.t)
    inside = np.abs(t * 100 - np.round(t * 100)) > 0.25  # rows inside an interval of their inflow
    P = np.asarray(res["P(IN__v)"])[inside] * MMHG
    np.testing.assert_allclose(P, L * slope[np.floor(t[inside] * 100).astype(int)], rtol=1e-9, atol=1e-9)
    assert abs(np.max(P) - L * 2 * np.pi * 2.5) < 0.02 * L * 2 * np.pi * 2.5
    assert c.nx == 0  # no state left: the source fixes the flow


def test_one_element_vessels_take_only_their_own_value():
    cfg = _one_element("Resistance", {"R": 1.0, "C": 1e-3},
                       {"bc_name": "OUT", "bc_type": "PRESSURE", "bc_values": {"P": 0.0}})
    with pytest.raises(NetlistError, match=r"'v'.*unknown value\(s\) \['C'\] \(it takes R\)"):
        import_svzerod(cfg)
