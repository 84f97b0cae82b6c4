"""Physics against closed forms: RC, RLC, divider, log compliance, Payne06 operating point,
steady state as a fixed point, mass conservation at every node, source waveforms.

Circuit units: mmHg, mL, s (R in mmHg*s/mL, C in mL/mmHg, L in mmHg*s^2/mL).
"""
import math

import numpy as np
import pytest

import hemocircuit as hc
from hemocircuit.protocol import Protocol

from paths import PAYNE06

TIGHT = dict(rtol=1e-9)


def rel_err(got, ref):
    """Max error relative to the size of the reference signal."""
    got, ref = np.asarray(got, float), np.asarray(ref, float)
    return float(np.max(np.abs(got - ref)) / np.max(np.abs(ref)))


def pointwise_rel_err(got, ref, floor):
    got, ref = np.asarray(got, float), np.asarray(ref, float)
    return float(np.max(np.abs(got - ref) / np.maximum(np.abs(ref), floor)))


# ------------------------------------------------------------------------------ RC --------
RC_NET = """
name: rc
elements:
  - {id: Ps, type: pressure_source, nodes: [in, ground], value: {steps: [[0 s, 0 mmHg], [1 s, 50 mmHg]]}}
  - {id: R1, type: resistor,        nodes: [in, a],      R: 2 mmHg*s/mL}
  - {id: C1, type: compliance,      nodes: [a, ground],  C: 0.75 mL/mmHg, V0: 3 mL}
"""
TAU = 2 * 0.75  # R C [s]


def test_rc_charge_step_waveform(write):
    c = hc.load(write(RC_NET))
    res = c.simulate(1 + 8 * TAU, dt=0.05, **TIGHT)
    t = res.t
    after = t >= 1
    P_ref = np.where(after, 50 * (1 - np.exp(-(t - 1) / TAU)), 0.0)
    assert t[0] == 0 and t[-1] == pytest.approx(1 + 8 * TAU)
    assert rel_err(res["P(a)"], P_ref) <= 1e-4
    # charging: the early part, relative to the local value
    sel = after & (t > 1.04)
    assert pointwise_rel_err(res["P(a)"][sel], P_ref[sel], 1e-12) <= 1e-4
    # volume of the linear compliance V = V0 + C P, flow into it C dP/dt = (Ps - P)/R
    assert rel_err(res["V(C1)"], 3 + 0.75 * P_ref) <= 1e-4
    q_ref = np.where(after, 50 / 2 * np.exp(-(t - 1) / TAU), 0.0)
    assert rel_err(res["Q(C1)"][t > 1], q_ref[t > 1]) <= 1e-4
    assert rel_err(res["Q(R1)"][t > 1], q_ref[t > 1]) <= 1e-4
    # before the step nothing moves
    assert np.all(res["P(a)"][t < 1] == pytest.approx(0.0, abs=1e-9))


def test_rc_discharge_protocol_event(write, tmp_path):
    """Start charged at 50 mmHg (operating point), a protocol event drops the source to 0."""
    c = hc.load(write(RC_NET.replace("{steps: [[0 s, 0 mmHg], [1 s, 50 mmHg]]}", "50 mmHg")))
    proto_file = write("""
        t_end: 10 s
        events:
          - {at: 1 s, set: {Ps.value: 0 mmHg}}
        """, "discharge.yaml")
    res = c.simulate(None, dt=0.05, protocol=str(proto_file), **TIGHT)
    t = res.t
    assert t[-1] == pytest.approx(10.0)
    P_ref = np.where(t >= 1, 50 * np.exp(-(t - 1) / TAU), 50.0)
    assert pointwise_rel_err(res["P(a)"], P_ref, 1e-9) <= 1e-4
    assert rel_err(res["V(C1)"], 3 + 0.75 * P_ref) <= 1e-4
    # the source itself jumps at the event
    assert np.all(res["P(in)"][t < 1] == pytest.approx(50.0))
    assert np.all(res["P(in)"][t >= 1] == pytest.approx(0.0, abs=1e-12))


def test_rc_ramp_pwl(write):
    """Ramp input s (t - 1) for t > 1: P(a) = s [(t-1) - tau (1 - exp(-(t-1)/tau))]."""
    c = hc.load(write(RC_NET.replace("{steps: [[0 s, 0 mmHg], [1 s, 50 mmHg]]}",
                                     "{pwl: [[0 s, 0 mmHg], [1 s, 0 mmHg], [11 s, 100 mmHg]]}")))
    res = c.simulate(11, dt=0.05, **TIGHT)
    t = res.t
    s = 10.0
    tt = np.clip(t - 1, 0, None)
    P_ref = s * (tt - TAU * (1 - np.exp(-tt / TAU)))
    assert rel_err(res["P(a)"], P_ref) <= 1e-4
    assert res["P(in)"][-1] == pytest.approx(100.0)


# ------------------------------------------------------------------------------ RLC -------
def test_rlc_underdamped_step(write):
    R, L, C, E = 0.5, 1.0, 0.25, 40.0
    c = hc.load(write(f"""
        name: rlc
        elements:
          - {{id: Ps, type: pressure_source, nodes: [in, ground], value: {{steps: [[0 s, 0 mmHg], [1 s, {E} mmHg]]}}}}
          - {{id: R1, type: resistor,   nodes: [in, a],     R: {R} mmHg*s/mL}}
          - {{id: L1, type: inductor,   nodes: [a, b],      L: {L} mmHg*s**2/mL}}
          - {{id: C1, type: compliance, nodes: [b, ground], C: {C} mL/mmHg}}
        """))
    res = c.simulate(16, dt=0.02, **TIGHT)
    t = res.t
    alpha, w0 = R / (2 * L), 1 / math.sqrt(L * C)
    assert alpha < w0  # underdamped
    wd = math.sqrt(w0 ** 2 - alpha ** 2)
    tau = np.clip(t - 1, 0, None)
    env = np.exp(-alpha * tau)
    Vc = E * (1 - env * (np.cos(wd * tau) + alpha / wd * np.sin(wd * tau)))
    q = C * E * env * w0 ** 2 / wd * np.sin(wd * tau)
    assert rel_err(res["P(b)"], Vc) <= 1e-4
    assert rel_err(res["V(C1)"], C * Vc) <= 1e-4
    assert rel_err(res["L1.q"], q) <= 1e-4
    assert rel_err(res["Q(L1)"], q) <= 1e-4
    # overshoot of an underdamped step: 1 + exp(-alpha pi / wd)
    assert res["P(b)"].max() == pytest.approx(E * (1 + math.exp(-alpha * math.pi / wd)), rel=1e-4)


# ------------------------------------------------------------------------- divider --------
DIVIDER = """
elements:
  - {id: Ps, type: pressure_source, nodes: [in, ground], value: 10 mmHg}
  - {id: R1, type: resistor, nodes: [in, m],     R: 3 mmHg*s/mL}
  - {id: R2, type: resistor, nodes: [m, ground], R: 7 mmHg*s/mL}
"""


def test_resistor_divider_dc_sweep_exact(write):
    # a compliance on the divider node carries no flow at DC (and gives the circuit a state)
    c = hc.load(write(DIVIDER + "  - {id: Cm, type: compliance, nodes: [m, ground], C: 0.1 mL/mmHg}\n"))
    sw = c.dc_sweep("Ps.value", "0:100:12.5 mmHg")
    v = sw["Ps.value"]
    np.testing.assert_array_equal(v, np.arange(9) * 12.5)
    np.testing.assert_allclose(sw["P(m)"], v * 7 / 10, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(sw["Q(R1)"], v / 10, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(sw["Q(R2)"], v / 10, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(sw["Q(Ps)"], -v / 10, rtol=1e-12, atol=1e-12)
    assert sw.units["Ps.value"] == "mmHg" and not sw.failed
    # sweeping a resistance, given in another unit
    sw = c.dc_sweep("R2.R", [1.0, 2.0, 5.0, 17.0])
    R2 = np.array([1.0, 2.0, 5.0, 17.0])
    np.testing.assert_allclose(sw["P(m)"], 10 * R2 / (3 + R2), rtol=1e-12)
    # the circuit the sweep came from is unchanged
    assert c.parameters.values["R2.R"][0] == 7.0


def test_operating_point_and_sweep_of_a_circuit_without_states(write):
    c = hc.load(write(DIVIDER))
    assert c.nx == 0
    assert c.operating_point()["P(m)"] == pytest.approx(7.0, rel=1e-12)
    sw = c.dc_sweep("Ps.value", "0:100:50 mmHg")
    np.testing.assert_allclose(sw["P(m)"], [0.0, 35.0, 70.0], rtol=1e-12, atol=1e-12)


# ----------------------------------------------------------------- log compliance ---------
LOGC = """
elements:
  - {id: Ps,  type: pressure_source, nodes: [in, ground], value: 20 mmHg}
  - {id: Rx,  type: resistor,        nodes: [in, v],      R: 1 mmHg*s/mL}
  - {id: Cv,  type: log_compliance,  nodes: [v, ic],      k: 0.186 1/mL, P0: -2.25 mmHg, Vn: 28 mL}
  - {id: Pic, type: pressure_source, nodes: [ic, ground], value: 10 mmHg}
"""


def test_log_compliance_pv_and_compliance_by_hand(write):
    c = hc.load(write(LOGC))
    op = c.operating_point()
    # dP - P0 = 20 - 10 + 2.25 = 12.25 mmHg
    # V = 28 + ln(12.25)/0.186 = 28 + 2.50552593699074/0.186 = 41.4705695537136 mL
    # C = 1/(0.186 * 12.25) = 1/2.2785 = 0.438885231512 mL/mmHg
    assert op["P(v)"] == pytest.approx(20.0, rel=1e-12)
    assert op["V(Cv)"] == pytest.approx(41.4705695537136, rel=1e-10)
    assert op["Cv.C"] == pytest.approx(0.438885231512, rel=1e-10)
    assert op.units["V(Cv)"] == "mL" and op.units["Cv.C"] == "mL/mmHg"


def test_log_compliance_pressure_from_volume(write):
    """The state is the volume; the node pressure follows P = Pic + P0 + exp(k (V - Vn))."""
    c = hc.load(write(LOGC))
    V = np.array([[20.0], [28.0], [35.5], [45.0]])
    out = c.outputs(0.0, V)
    # hand values: exp(0.186*(V-28)) = exp(-1.488), 1, exp(1.395), exp(3.162)
    expected_dP = np.array([0.225823851896476, 1.0, 4.03497457263220, 23.6177842935613])
    np.testing.assert_allclose(out["P(v)"] - 10 + 2.25, expected_dP, rtol=1e-12)
    np.testing.assert_allclose(out["P(v)"], 10 - 2.25 + np.exp(0.186 * (V[:, 0] - 28)), rtol=1e-12)
    np.testing.assert_allclose(out["Cv.C"], [23.8076892271157, 1 / 0.186, 1.33243567939370, 0.227639647275770],
                               rtol=1e-12)
    # dV/dt is the flow through Rx into the compliance
    for Vi in V[:, 0]:
        dP = 10 - 2.25 + math.exp(0.186 * (Vi - 28))
        assert c.rhs(0.0, np.array([Vi]))[0] == pytest.approx((20 - dP) / 1.0, rel=1e-12)


def test_log_compliance_sweep_follows_law(write):
    c = hc.load(write(LOGC))
    sw = c.dc_sweep("Ps.value", "8:60:4 mmHg")
    e = sw["Ps.value"] - 10 + 2.25
    np.testing.assert_allclose(sw["V(Cv)"], 28 + np.log(e) / 0.186, rtol=1e-10)
    np.testing.assert_allclose(sw["Cv.C"], 1 / (0.186 * e), rtol=1e-10)


# ----------------------------------------------------------------------- Payne06 ----------
def test_payne06_operating_point_by_hand():
    c = hc.load(str(PAYNE06))
    op = c.operating_point()
    q = (80 - 6) / (0.4 + 20 + 1.32 + 0.56)  # 3.32136445242370 mL/s
    assert q == pytest.approx(3.3213644524237, rel=1e-12)
    for rid in ("Rla", "Rsa", "Rsv", "Rlv"):
        assert op[f"Q({rid})"] == pytest.approx(q, rel=1e-10)
    assert op["Q(Pa)"] == pytest.approx(-q, rel=1e-10)  # flow in -> source -> ground
    assert op["Q(Pv)"] == pytest.approx(q, rel=1e-10)
    assert op["P(alpha)"] == pytest.approx(80 - 0.4 * q, rel=1e-10)  # 78.6714542190305
    assert op["P(alpha)"] == pytest.approx(78.6714542190305, rel=1e-10)
    assert op["P(beta)"] == pytest.approx(6 + (1.32 + 0.56) * q, rel=1e-10)
    Pv = 6 + 0.56 * q  # 7.85996409335727 mmHg
    assert op["P(v)"] == pytest.approx(Pv, rel=1e-10)
    # V(Cv) = 28 + ln(P(v) - 10 + 2.25)/0.186 = 28 + ln(0.10996409335727)/0.186
    assert op["V(Cv)"] == pytest.approx(28 + math.log(Pv - 10 + 2.25) / 0.186, rel=1e-9)
    assert op["V(Cv)"] == pytest.approx(16.1311753199, rel=1e-9)
    assert op["Q(Cv)"] == pytest.approx(0.0, abs=1e-9)
    assert op["P(ic)"] == 10.0 and op["P(out)"] == 6.0


def test_payne06_steady_state_is_a_fixed_point():
    c = hc.load(str(PAYNE06))
    op = c.operating_point()
    f = c.rhs(0.0, op.x)
    assert np.max(np.abs(f)) <= 1e-9 * 3.32
    # and not for another state: with 1 mL more in Cv, P(v) rises and the excess drains
    Pv = 10 - 2.25 + math.exp(0.186 * (op.x[0] + 1.0 - 28))
    f2 = c.rhs(0.0, op.x + 1.0)
    assert f2[0] == pytest.approx((80 - Pv) / (0.4 + 20 + 1.32) - (Pv - 6) / 0.56, rel=1e-9)
    assert f2[0] < -0.04


def test_steady_state_is_the_operating_points_states_and_fails_as_it_does():
    """analyses.op.steady_state (the states only, for a run's start): the fixed point of
    payne06, equal to the operating point's states, f(x) = 0; a member without an operating
    point (the log compliance's P0 = 1e300 mmHg) raises the same SolverError, naming it."""
    from hemocircuit.analyses.op import steady_state
    from hemocircuit.errors import SolverError

    c = hc.load(str(PAYNE06))
    x = steady_state(c)
    assert x.shape == (c.nx,)
    assert np.array_equal(x, c.operating_point().x)
    assert np.max(np.abs(c.rhs(0.0, x))) <= 1e-9 * 3.32
    bad = c.batch(2).with_values({"Cv.P0": np.array([-2.25, 1e300])})
    with pytest.raises(SolverError, match=r"no operating point found.* in batch member 1 \(1 of 2 members failed: 1\)"):
        steady_state(bad)
    with pytest.raises(SolverError, match=r"in batch member 1 \(1 of 2"):
        bad.operating_point()


# ------------------------------------------------------------- mass conservation ----------
MASS = """
name: mass-conservation
elements:
  - {id: Pa,  type: pressure_source, nodes: [in, ground],
     value: {sine: {offset: 80 mmHg, amplitude: 15 mmHg, frequency: 1.2 Hz, phase: 30 deg}}}
  - {id: R1,  type: resistor,       nodes: [in, a],      R: 0.5 mmHg*s/mL}
  - {id: Ca,  type: compliance,     nodes: [a, ground],  C: 0.3 mL/mmHg, V0: 5 mL}
  - {id: L1,  type: inductor,       nodes: [a, b],       L: 0.05 mmHg*s**2/mL}
  - {id: R2,  type: resistor,       nodes: [b, c],       R: 1.0 mmHg*s/mL}
  - {id: Cc,  type: compliance,     nodes: [c, ground],  C: 0.2 mL/mmHg, V0: 2 mL}
  - {id: Qs,  type: flow_source,    nodes: [ground, c],  value: {pwl: [[0 s, 0 mL/s], [2 s, 3 mL/s], [4 s, 1 mL/s]]}}
  - {id: R3,  type: resistor,       nodes: [c, v],       R: 2.0 mmHg*s/mL}
  - {id: Cv,  type: log_compliance, nodes: [v, icn],     k: 0.186 1/mL, P0: -2.25 mmHg, Vn: 28 mL}
  - {id: Pic, type: pressure_source, nodes: [icn, ground], value: 10 mmHg}
  - {id: R4,  type: resistor,       nodes: [v, out],     R: 0.56 mmHg*s/mL}
  - {id: Pv,  type: pressure_source, nodes: [out, ground], value: 6 mmHg}
"""


def test_mass_conservation_every_node(write):
    c = hc.load(write(MASS))
    res = c.simulate(5.0, dt=0.01, rtol=1e-8)
    col = res.columns
    P = lambda n: col[f"P({n})"] if n != "ground" else 0.0  # noqa: E731
    idx = {name: i for i, name in enumerate(c.state_names)}
    dVdt = np.array([c.rhs(t, x) for t, x in zip(res.t, res.x)])
    dV = {e: dVdt[:, idx[f"{e}.V"]] for e in ("Ca", "Cc", "Cv")}
    q_L = res.x[:, idx["L1.q"]]
    tt = res.t
    Qs = np.interp(tt, [0, 2, 4], [0, 3, 1])
    # element laws, computed independently of the flow outputs
    flow = {"R1": (P("in") - P("a")) / 0.5, "R2": (P("b") - P("c")) / 1.0, "R3": (P("c") - P("v")) / 2.0,
            "R4": (P("v") - P("out")) / 0.56, "L1": q_L, "Qs": Qs, **dV}
    for eid, f in flow.items():
        np.testing.assert_allclose(col[f"Q({eid})"], f, rtol=1e-9, atol=1e-9 * np.max(np.abs(f)),
                                   err_msg=f"Q({eid})")
    # the sine source really drives the circuit
    assert np.ptp(P("a")) > 5 and np.ptp(dV["Ca"]) > 1
    # node balances: flow in = flow out + dV/dt (sources: their Q is flow node -> source -> ref)
    balances = {
        "in": ([-col["Q(Pa)"]], [flow["R1"]]),
        "a": ([flow["R1"]], [flow["L1"], dV["Ca"]]),
        "b": ([flow["L1"]], [flow["R2"]]),
        "c": ([flow["R2"], flow["Qs"]], [flow["R3"], dV["Cc"]]),
        "v": ([flow["R3"]], [flow["R4"], dV["Cv"]]),
        "icn": ([dV["Cv"]], [col["Q(Pic)"]]),
        "out": ([flow["R4"]], [col["Q(Pv)"]]),
    }
    assert set(balances) == set(c.nodes)
    for node, (ins, outs) in balances.items():
        fin, fout = sum(ins), sum(outs)
        scale = np.max([np.max(np.abs(f)) for f in ins + outs])
        assert np.max(np.abs(fin - fout)) <= 1e-9 * scale, node
    # generic Kirchhoff check on the outputs: sum of Q entering elements at their first terminal
    # minus Q leaving at their second terminal is zero at every node
    for node in c.nodes:
        s = sum(col[f"Q({e.id})"] * ((e.nodes[0] == node) - (e.nodes[1] == node)) for e in c.elements.values())
        assert np.max(np.abs(s)) <= 1e-9 * np.max(np.abs(col["Q(R1)"])), node


def test_steady_state_fixed_point_with_inductor_and_stores(write):
    c = hc.load(write(MASS))
    op = c.operating_point()
    f = c.rhs(0.0, op.x)
    assert np.max(np.abs(f) / c.state_scales) <= 1e-9
    # hand values: at t = 0 Pa = 80 + 15 sin(30 deg) = 87.5 mmHg, Qs = 0, stores carry no flow
    q = (87.5 - 6) / (0.5 + 1 + 2 + 0.56)
    assert op["Q(L1)"] == pytest.approx(q, rel=1e-9)
    assert op["P(a)"] == pytest.approx(87.5 - 0.5 * q, rel=1e-9)
    assert op["V(Ca)"] == pytest.approx(5 + 0.3 * (87.5 - 0.5 * q), rel=1e-9)
    assert op["V(Cc)"] == pytest.approx(2 + 0.2 * (6 + 2.56 * q), rel=1e-9)
    assert op["V(Cv)"] == pytest.approx(28 + math.log(6 + 0.56 * q - 10 + 2.25) / 0.186, rel=1e-9)


# ------------------------------------------------------------------ waveforms -------------
def _source_net(value):
    return f"""
        elements:
          - {{id: Ps, type: pressure_source, nodes: [in, ground], value: {value}}}
          - {{id: R1, type: resistor, nodes: [in, ground], R: 2 mmHg*s/mL}}
          - {{id: R9, type: resistor, nodes: [in, x], R: 1 mmHg*s/mL}}
          - {{id: Cx, type: compliance, nodes: [x, ground], C: 0.01 mL/mmHg}}
        """


def _away(t, points, eps=1e-9):
    return np.all(np.abs(t[:, None] - np.asarray(points)[None, :]) > eps, axis=1)


@pytest.mark.parametrize("value, expected, jumps", [
    ("{steps: [[0 s, 10 mmHg], [1 s, 20 mmHg], [2.5 s, 5 mmHg]]}",
     lambda t: np.where(t < 1, 10, np.where(t < 2.5, 20, 5)), [1, 2.5]),
    ("{pwc: [[0 s, 10 mmHg], [1.5 s, 30 mmHg]]}", lambda t: np.where(t < 1.5, 10, 30), [1.5]),
    # a drop written as two rows at the same time keeps its order
    ("{pwl: [[0 s, 0 mmHg], [1 s, 40 mmHg], [2 s, 40 mmHg], [2 s, 10 mmHg], [3 s, 10 mmHg]]}",
     lambda t: np.interp(t, [0, 1, 2, 2 + 1e-12, 3], [0, 40, 40, 10, 10]), [2]),
    ("{pwl: [[0.5 s, 10 mmHg], [2.5 s, 50 mmHg]]}", lambda t: np.interp(t, [0.5, 2.5], [10, 50]), []),
    ("{sine: {offset: 80 mmHg, amplitude: 10 mmHg, frequency: 0.5 Hz, phase: 90 deg, start: 1 s}}",
     lambda t: np.where(t < 1, 80, 80 + 10 * np.cos(np.pi * (t - 1))), [1]),
    ("{sine: {offset: 4 cmH2O, amplitude: 1 kPa, frequency: 60 1/min}}",
     lambda t: 4 * 98.0665 / 133.322387415 + 1000 / 133.322387415 * np.sin(2 * np.pi * t), []),
    ("{sum: [{steps: [[0 s, 10 mmHg], [2 s, 20 mmHg]]}, {pwl: [[0 s, 0 mmHg], [3 s, 3 mmHg]]}, "
     "{sine: {amplitude: 2 mmHg, frequency: 1 Hz}}]}",
     lambda t: np.where(t < 2, 10, 20) + t + 2 * np.sin(2 * np.pi * t), [2]),
])
def test_source_waveforms(write, value, expected, jumps):
    c = hc.load(write(_source_net(value)))
    res = c.simulate(3.0, dt=0.05)
    t = res.t
    ok = _away(t, jumps) if jumps else np.ones(t.shape, bool)
    ref = expected(t)
    np.testing.assert_allclose(res["P(in)"][ok], ref[ok], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(res["Q(R1)"][ok], ref[ok] / 2, rtol=1e-12, atol=1e-12)
    # every jump is a restart point: the output holds both sides of it
    for tj in jumps:
        assert np.any(np.isclose(t, tj, rtol=0, atol=1e-12))


def test_builtin_sine_term_of_sources(write):
    c = hc.load(write("""
        elements:
          - {id: Ps, type: pressure_source, nodes: [in, ground], value: 50 mmHg,
             amplitude: 5 mmHg, frequency: 2 Hz, phase: 0 rad, start: 0.5 s}
          - {id: R1, type: resistor,    nodes: [in, a],     R: 1 mmHg*s/mL}
          - {id: Qf, type: flow_source, nodes: [a, ground], value: 3 mL/s, amplitude: 1 mL/s, frequency: 1 Hz}
          - {id: R9, type: resistor,    nodes: [in, x],     R: 1 mmHg*s/mL}
          - {id: Cx, type: compliance,  nodes: [x, ground], C: 0.01 mL/mmHg}
        """))
    res = c.simulate(2.0, dt=0.01)
    t = res.t
    Ps = 50 + np.where(t >= 0.5, 5 * np.sin(4 * np.pi * (t - 0.5)), 0.0)
    Qf = 3 + np.sin(2 * np.pi * t)
    np.testing.assert_allclose(res["P(in)"], Ps, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(res["Q(Qf)"], Qf, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(res["P(a)"], Ps - Qf * 1.0, rtol=1e-12, atol=1e-11)


def test_table_file_relative_to_netlist_folder(write, tmp_path, monkeypatch):
    # minutes and cmH2O in the file are converted to s and mmHg
    write("""
        # a comment line
        time [min],value [cmH2O]
        0,10
        0.02,30
        0.05,30
        """, "models/data/wave.csv")
    net = write(_source_net("{pwl: {file: data/wave.csv}}"), "models/net.yaml")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    c = hc.load("../models/net.yaml")
    assert c.file == str(net)
    res = c.simulate(4.0, dt=0.1)
    cm = 98.0665 / 133.322387415
    ref = np.interp(res.t, [0, 1.2, 3.0], [10 * cm, 30 * cm, 30 * cm])
    np.testing.assert_allclose(res["P(in)"], ref, rtol=1e-12)
    # the same file as a piecewise-constant table
    c = hc.load(write(_source_net("{steps: {file: data/wave.csv}}"), "models/net2.yaml"))
    res = c.simulate(2.0, dt=0.1)
    ok = _away(res.t, [1.2])
    np.testing.assert_allclose(res["P(in)"][ok], np.where(res.t < 1.2, 10 * cm, 30 * cm)[ok], rtol=1e-12)


def test_noise_waveform_has_its_mean_sd_band_and_seed(write):
    """{noise: ...}: over one period its mean and standard deviation are the given ones exactly,
    its spectrum lies inside the band, the same seed gives the same series and another seed
    another; a source carries it through a run unchanged (P(in) = the waveform)."""
    from hemocircuit.waveforms import parse_waveform
    spec = {"noise": {"mean": "90 mmHg", "sd": "5 mmHg", "band": ["0.05 Hz", "0.2 Hz"], "period": "100 s", "seed": 4}}
    w = parse_waveform(spec, "mmHg")
    t = np.arange(0, 100, 0.1)
    v = w.sample(t)
    assert v.mean() == pytest.approx(90.0, abs=1e-9) and v.std() == pytest.approx(5.0, rel=1e-9)
    power = np.abs(np.fft.rfft(v - 90.0)) ** 2
    f = np.fft.rfftfreq(t.size, 0.1)
    inside = (f >= 0.05 - 1e-9) & (f <= 0.2 + 1e-9)
    assert power[~inside].sum() < 1e-18 * power.sum() and np.count_nonzero(inside) == 16  # 5/100 .. 20/100 Hz
    np.testing.assert_allclose(parse_waveform(spec, "mmHg").sample(t), v, rtol=0, atol=0)
    other = parse_waveform({"noise": {**spec["noise"], "seed": 5}}, "mmHg").sample(t)
    assert np.max(np.abs(other - v)) > 1.0
    np.testing.assert_allclose(w.sample(t + 100.0), v, atol=1e-9)  # it repeats after its period
    c = hc.load(write(_source_net("{noise: {mean: 90 mmHg, sd: 5 mmHg, band: [0.05 Hz, 0.2 Hz], period: 100 s, "
                                  "seed: 4}}")))
    res = c.simulate(20.0, dt=0.1)
    np.testing.assert_allclose(res["P(in)"], w.sample(res.t), rtol=1e-12)


@pytest.mark.parametrize("body, message", [
    ("{sd: 5 mmHg}", "noise needs a mapping {sd: <value>, band:"),
    ("{sd: 5 mmHg, band: [0.2 Hz, 0.1 Hz]}", "0 <= low < high"),
    ("{sd: 5 mmHg, band: [0.001 Hz, 0.0012 Hz], period: 100 s}", "holds no frequency k/period"),
    ("{sd: 5 mmHg, band: [0 Hz, 50 Hz], period: 1000 s}", "gives 50,000 sines"),
    ("{sd: 5 mmHg, band: [0.02 Hz, 0.5 Hz], sed: 1}", "(did you mean 'seed' or 'sd'?)"),
    ("{sd: 5 mmHg, band: [0.02 Hz, 0.5 Hz], seed: -1}", "noise seed must be a whole number >= 0"),
])
def test_noise_waveform_errors(write, body, message):
    with pytest.raises(hc.NetlistError) as exc:
        hc.load(write(_source_net("{noise: " + body + "}")))
    assert message in str(exc.value)


def test_waveform_value_ranges_bound_what_they_take():
    from hemocircuit.waveforms import parse_waveform
    assert parse_waveform({"sine": {"offset": "5 mmHg", "amplitude": "-2 mmHg"}}, "mmHg").value_range() == (3.0, 7.0)
    assert parse_waveform({"pwl": [["0 s", "4 mmHg"], ["1 s", "-1 mmHg"]]}, "mmHg").value_range() == (-1.0, 4.0)
    both = parse_waveform({"sum": [{"sine": {"amplitude": "1 mmHg", "frequency": "1 Hz"}}, {"steps": [["0 s", "2 mmHg"]]}]},
                          "mmHg")
    assert both.value_range() == (1.0, 3.0)
    noise = parse_waveform({"noise": {"mean": "1 mmHg", "sd": "0.1 mmHg", "band": ["0.02 Hz", "0.2 Hz"],
                                      "period": "100 s", "seed": 2}}, "mmHg")
    lo, hi = noise.value_range()
    fine = noise.sample(np.arange(0, 100, 0.01))
    assert lo <= fine.min() and hi >= fine.max()  # a bound of what it takes
    assert fine.min() - lo < 0.05 * (hi - lo) and hi - fine.max() < 0.05 * (hi - lo)  # and a close one
    assert 1 - 5 * 0.1 < lo < 1 - 0.1 and 1 + 0.1 < hi < 1 + 5 * 0.1


def test_a_time_varying_distal_resistance_acts_in_the_kernel(write):
    """ClosedLoopRCR's Rd takes a waveform: Q_out = (P_c - P_out) / Rd(t) at every output time,
    and a waveform that would reach Rd <= 0 is refused with its lowest value."""
    net = """
        elements:
          - {id: Pa, type: pressure_source, nodes: [in, ground], value: 100 mmHg}
          - {id: bed, type: closed_loop_rcr, nodes: [in, out, ground], Rp: 0.1 mmHg*s/mL, C: 0.5 mL/mmHg,
             Rd: {sine: {offset: 1 mmHg*s/mL, amplitude: 0.3 mmHg*s/mL, frequency: 0.2 Hz}}}
          - {id: Pv, type: pressure_source, nodes: [out, ground], value: 5 mmHg}
        """
    res = hc.load(write(net)).simulate(10.0, dt=0.05)
    rd = 1 + 0.3 * np.sin(2 * np.pi * 0.2 * res.t)
    np.testing.assert_allclose(res["bed.Q_out"], (res["bed.P_c"] - 5.0) / rd, rtol=1e-10)
    with pytest.raises(hc.NetlistError, match=r"Rd': its waveform's lowest value -0.2 mmHg\*s/mL is not physical"):
        hc.load(write(net.replace("amplitude: 0.3", "amplitude: 1.2"), "bad.yaml"))
