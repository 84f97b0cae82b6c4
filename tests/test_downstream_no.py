"""Downstream NO transport (thesis section "Downstream Transport of NO", eqs. dcvdt, dctdt, cinv).

netlists/payne06_no_transport.yaml adds a venous-blood NO pool (``tracer_pool``, metering the
flow q2 into the venous compartment) and a tissue NO pool (``tissue_pool``) to payne06.
Checked here: the thesis's numbers in its compatibility reading (MODEL_NOTES "Downstream NO"),
the thesis's closed-form steady states, the pools' own dynamics, tracer mass balance, and that
the hydraulics of payne06 are untouched.  The consistent model's values are pinned as well.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import hemocircuit as hc
from hemocircuit.analyses.op import operating_point
from hemocircuit.analyses.transient import simulate
from hemocircuit.components.arteriole.equations import no_rates
from hemocircuit.errors import NetlistError

ROOT = Path(__file__).resolve().parents[1]
NETLISTS = ROOT / "netlists"
CONSISTENT = str(NETLISTS / "payne06_no_transport.yaml")
THESIS = str(NETLISTS / "payne06_no_transport_thesis.yaml")
BASE = str(NETLISTS / "payne06.yaml")
ML = 1e-6  # m^3 per mL
H_SCALE = 3 ** (1 / 3)  # h_wv = h_w 3^(1/3)


def _rdb_to_rdw(c):
    """The thesis's second case: blood decay rate reduced to the wall's (scaled) r_dw."""
    c = c.with_values({"art.r_db": float(c.parameters.values["art.r_dw"][0] * c.parameters.values["art.no_speed"][0])})
    return c


@pytest.fixture(scope="module")
def ops():
    """Operating points at Pa = 80 mmHg: {(reading, case): (circuit, op)}."""
    out = {}
    for reading, path in (("consistent", CONSISTENT), ("thesis", THESIS)):
        c = hc.load(path)
        out[reading, "base"] = (c, operating_point(c))
        c2 = _rdb_to_rdw(c)
        out[reading, "rdb=rdw"] = (c2, operating_point(c2))
    return out


def _art_params(circuit):
    """The arteriole's parameters (SI) as plain floats, h_w, r_dw, s_w and k_tau with no_speed applied
    (equations.no_rates)."""
    g, i = circuit.element_group("art")
    p = {k: float(v[0, i]) for k, v in g.p.items()}
    vec = np.array([p[k] for k in g.comp.parameters])
    p.update(zip(("h_w", "r_dw", "s_w", "k_tau"), no_rates(vec)))
    return p


# --- the thesis's numbers (compatibility reading) -------------------------------------------------
@pytest.mark.parametrize("case, venous, tissue", [("base", 1.4e-20, 1.6e-29), ("rdb=rdw", 2.7e-17, 3.1e-26)])
def test_thesis_numbers_at_80_mmHg(ops, case, venous, tissue):
    _, op = ops["thesis", case]
    assert op["P(in)"] == pytest.approx(80.0)
    assert op["NOv.C"] == pytest.approx(venous, rel=0.05)
    assert op["NOt.C"] == pytest.approx(tissue, rel=0.05)


def test_wall_no_is_the_thesis_value(ops):
    """The feed: wall NO 4.9e-6 M at Pa = 80 (the thesis's 'initial level of NO in the arteriole wall')."""
    for key in ops:
        assert ops[key][1]["art.Cw"] == pytest.approx(4.9e-6, rel=0.03)


def test_option_switch_equals_thesis_netlist(ops):
    """units_reading is an ordinary structural option: switching it reproduces the thesis variant."""
    c = hc.load(CONSISTENT).with_options({"NOv.units_reading": "thesis", "NOt.units_reading": "thesis",
                                          "NOv.scale": 1e-20, "NOt.scale": 1e-29})
    op = operating_point(c)
    ref = ops["thesis", "base"][1]
    assert op["NOv.C"] == pytest.approx(ref["NOv.C"], rel=1e-9)
    assert op["NOt.C"] == pytest.approx(ref["NOt.C"], rel=1e-9)


# --- the consistent model --------------------------------------------------------------------------
def test_consistent_model_values(ops):
    """Dimensionally consistent model at Pa = 80 mmHg (reported beside the thesis's numbers).

    venous 3.94e-14 M, tissue 1.40e-17 M; with r_db = r_dw 2.14e-9 / 7.63e-13 M.  Both far
    below the wall's 4.9e-6 M: the thesis's conclusion (no downstream NO signal) stands.
    """
    _, op = ops["consistent", "base"]
    assert op["NOv.C"] == pytest.approx(3.94e-14, rel=0.01)
    assert op["NOt.C"] == pytest.approx(1.40e-17, rel=0.01)
    _, op2 = ops["consistent", "rdb=rdw"]
    assert op2["NOv.C"] == pytest.approx(2.14e-9, rel=0.01)
    assert op2["NOt.C"] == pytest.approx(7.63e-13, rel=0.01)
    for o in (op, op2):
        assert o["NOt.C"] < o["NOv.C"] < o["NOv.C_feed"] < o["art.Cw"]
    # with n = 16000 tubes the feeding bed is long (x ~ 180): its outlet is at C_inf (eq. cinv)
    assert op["NOv.C_feed"] == pytest.approx(op["art.Cb_inf"], rel=1e-12)


# --- steady states are the thesis's closed forms ---------------------------------------------------
@pytest.mark.parametrize("reading", ["consistent", "thesis"])
@pytest.mark.parametrize("case", ["base", "rdb=rdw"])
def test_steady_state_equals_closed_forms(ops, reading, case):
    """C_v0 = q2 C_in,v / (q3 + r_db + h_wv (1 - h_wv/(h_wv + r_dw))), C_T0 = h_wv C_v0/(h_wv + r_dw)
    (thesis), with C_in,v from the arteriole's eq. cinv (written out here); in the
    consistent model the decay terms carry their volumes and the exchange the length n L."""
    c, op = ops[reading, case]
    p = _art_params(c)
    q2, q3 = op["Q(Rsv)"] * ML, op["Q(Rlv)"] * ML  # m^3/s
    assert q2 == pytest.approx(q3, rel=1e-9)
    assert op["Q(NOv)"] == pytest.approx(op["Q(Rsv)"], rel=1e-12)  # the meter carries q2
    r, Cw = op["art.r"] * 1e-6, op["art.Cw"]
    h_wv = H_SCALE * p["h_w"]
    V_v = op["V(Cv)"] * ML
    V_T = 97 / 3 * 4 / 3 * 60 * ML
    if reading == "thesis":
        Q = 0.5 * (op["Q(Rla)"] + op["Q(Rsv)"]) * ML  # (q1 + q2)/2, whole brain, as if one vessel
        G, D_v, D_T = h_wv, p["r_db"], p["r_dw"]
    else:
        Q = op["Q(Rsv)"] * ML / p["n"]  # one tube's flow
        G, D_v, D_T = h_wv * p["n"] * p["L"], p["r_db"] * V_v, p["r_dw"] * V_T
    # eq. cinv: C_b(L) = (h_w C_w/gamma_wb / k - C_in)(1 - exp(-k L/|Q|)) + C_in, k = h_w + r_db pi r^2
    k = p["h_w"] + p["r_db"] * np.pi * r ** 2
    C_inv = (p["h_w"] * Cw / p["gamma_wb"] / k - p["C_in"]) * (-np.expm1(-k * p["L"] / abs(Q))) + p["C_in"]
    assert op["NOv.C_feed"] == pytest.approx(C_inv, rel=1e-9)
    C_v0 = q2 * C_inv / (q3 + D_v + G * (1 - G / (G + D_T)))
    C_T0 = G * C_v0 / (G + D_T)
    assert op["NOv.C"] == pytest.approx(C_v0, rel=1e-8)
    assert op["NOt.C"] == pytest.approx(C_T0, rel=1e-8)


# --- the pools are fixed points of their own dynamics ----------------------------------------------
@pytest.mark.parametrize("reading", ["consistent", "thesis"])
def test_pools_are_fixed_points(ops, reading):
    c, op = ops[reading, "base"]
    dx = c.rhs(0.0, op.x)
    # the thesis reading's venous pool responds in ~0.4 us (volumes in m^3): float rounding of
    # the state alone gives |dC/dt| ~ 1e-16 C / 0.4 us, so the rate is judged on that time scale
    t_scale = 1e-6 if reading == "thesis" else 100.0
    for name in ("NOv.C", "NOt.C"):
        j = c.state_names.index(name)
        # rate times the pool's time scale is negligible against its value
        assert abs(dx[j]) * t_scale < 1e-9 * abs(op.x[j])
    res = simulate(c, 5.0, dt=1.0, x0=op.x)
    for name in ("NOv.C", "NOt.C"):
        assert np.allclose(res[name], op[name], rtol=1e-6, atol=0)


@pytest.mark.parametrize("reading", ["consistent", "thesis"])
def test_pools_relax_back_to_the_steady_state(ops, reading):
    """Start both pools at twice their steady value: they return to it (the pools are stable)."""
    c, op = ops[reading, "base"]
    x0 = op.x.copy()
    for name in ("NOv.C", "NOt.C"):
        x0[c.state_names.index(name)] *= 2.0
    # slowest pool time scale: tissue V_T/(r_dw V_T + G) ~ 21 s (consistent), ~0.05 s (thesis)
    res = simulate(c, 400.0, dt=100.0, x0=x0)
    assert res["NOv.C"][-1] == pytest.approx(op["NOv.C"], rel=1e-4)
    assert res["NOt.C"][-1] == pytest.approx(op["NOt.C"], rel=1e-4)


# --- the pools do not touch the hydraulics ---------------------------------------------------------
HYDRAULIC = ["P(in)", "P(alpha)", "P(beta)", "P(v)", "P(ic)", "P(out)", "Q(Rla)", "Q(Rsv)", "Q(Rlv)",
             "Q(Cv)", "V(Cv)", "art.r", "art.Cw", "art.Ca", "art.lambda", "V(art)", "art.q_out"]


@pytest.mark.parametrize("Pa", [50.0, 80.0, 130.0])
def test_hydraulic_steady_state_unchanged(Pa):
    base = hc.load(BASE)
    base = base.with_values({"Pa.value": Pa})
    ref = operating_point(base)
    for path in (CONSISTENT, THESIS):
        c = hc.load(path)
        c = c.with_values({"Pa.value": Pa})
        op = operating_point(c)
        assert op["P(v_in)"] == pytest.approx(op["P(v)"], abs=1e-12)  # the meter has no pressure drop
        for k in HYDRAULIC:
            assert op[k] == pytest.approx(ref[k], rel=1e-9, abs=1e-12), k


@pytest.mark.parametrize("path", [CONSISTENT, THESIS])
def test_hydraulic_transient_unchanged(path):
    """The thesis's 10 % step 80 -> 72 mmHg: flows, pressures, radius as in payne06."""
    def step(c):
        x0 = operating_point(c).x
        c = c.with_values({"Pa.value": 72.0})
        return simulate(c, 30.0, dt=0.5, x0=x0)

    ref, res = step(hc.load(BASE)), step(hc.load(path))
    for k in ("Q(Rla)", "Q(Rsv)", "Q(Rlv)", "P(v)", "P(beta)", "art.r", "V(Cv)"):
        scale = np.max(np.abs(ref[k]))
        assert np.max(np.abs(res[k] - ref[k])) < 1e-5 * scale, k
    assert np.max(np.abs(res["Q(NOv)"] - res["Q(Rsv)"])) < 1e-9 * np.max(np.abs(res["Q(Rsv)"]))


# --- tracer mass balance in a transient ------------------------------------------------------------
@pytest.mark.parametrize("reading", ["consistent", "thesis"])
def test_venous_tracer_mass_balance(ops, reading):
    """eq. dcvdt as written, with q3 and dV_v/dt explicit, holds along a transient although the
    pool meters only q2:  V dC/dt + C dV/dt = q2 C_in,v - q3 C - D_v C - G (C - C_T)."""
    c, op = ops[reading, "base"]
    c72 = c.with_values({"Pa.value": 72.0})
    res = simulate(c72, 3.0, dt=0.25, x0=op.x)
    p = _art_params(c)
    h_wv = H_SCALE * p["h_w"]
    jv, jt = c.state_names.index("NOv.C"), c.state_names.index("NOt.C")
    checked = 0
    for k in range(1, len(res.t)):
        x = res.x[k]
        col = {n: v[k] for n, v in res.columns.items()}
        q2, q3, dV = col["Q(Rsv)"] * ML, col["Q(Rlv)"] * ML, col["Q(Cv)"] * ML
        assert abs(q2 - q3) > 1e-4 * q2  # a genuinely unsteady state
        V, C, C_T = col["V(Cv)"] * ML, x[jv], x[jt]
        if reading == "thesis":
            G, D = h_wv, p["r_db"]
        else:
            G, D = h_wv * p["n"] * p["L"], p["r_db"] * V
        rhs = q2 * col["NOv.C_feed"] - q3 * C - D * C - G * (C - C_T)
        dC = c72.rhs(res.t[k], x)[jv]
        size = abs(q2 * col["NOv.C_feed"]) + abs(q3 * C) + abs(D * C) + abs(G * C)  # terms cancel closely
        assert V * dC + C * dV == pytest.approx(rhs, rel=0, abs=1e-12 * size)
        checked += 1
    assert checked > 5


# --- the components on their own -------------------------------------------------------------------
def _write(tmp_path, text):
    f = tmp_path / "pool.yaml"
    f.write_text(text)
    return str(f)


POOL_NETLIST = """
name: pool-alone
parameters: {Cfeed: 2e-9 M}
elements:
  - {id: P, type: pressure_source, nodes: [in, ground], value: 10 mmHg}
  - {id: R, type: resistor, nodes: [in, m], R: 2 mmHg*s/mL}
  - {id: pool, type: tracer_pool, nodes: [m, ground], V: 50 mL, k_d: 0.5 1/s, h: 1e-6 m**2/s, l: 2 m,
     C_x: "= tis.C", C_0: "= Cfeed", C_inf: "= Cfeed", scale: 1.0e-9}
  - {id: tis, type: tissue_pool, nodes: [], V: 200 mL, k_d: 0.01 1/s, h: 1e-6 m**2/s, l: 2 m, scale: 1.0e-9,
     C_x: "= pool.C"}
"""


def test_tracer_pool_alone_matches_the_analytic_solution(tmp_path):
    """Meter flow = 5 mL/s, constant volumes: a linear 2x2 system with a known solution."""
    c = hc.load(_write(tmp_path, POOL_NETLIST))
    op = operating_point(c)
    assert op["Q(pool)"] == pytest.approx(5.0)
    assert op["P(m)"] == pytest.approx(0.0, abs=1e-12)
    q, V, VT, G = 5e-6, 50e-6, 200e-6, 2e-6
    A = np.array([[-(q + 0.5 * V + G) / V, G / V], [G / VT, -(0.01 * VT + G) / VT]])
    b = np.array([q * 2e-9 / V, 0.0])
    xs = np.linalg.solve(A, -b)
    assert op["pool.C"] == pytest.approx(xs[0], rel=1e-9)
    assert op["tis.C"] == pytest.approx(xs[1], rel=1e-9)
    # transient from empty pools: x(t) = xs + expm(A t)(x0 - xs)
    x0 = op.x.copy()
    jp, jt = c.state_names.index("pool.C"), c.state_names.index("tis.C")
    x0[jp] = x0[jt] = 0.0
    res = simulate(c, 60.0, dt=5.0, x0=x0, rtol=1e-8)
    w, U = np.linalg.eig(A)
    for k, t in enumerate(res.t):
        exact = xs + (U @ np.diag(np.exp(w * t)) @ np.linalg.solve(U, -xs)).real
        assert res["pool.C"][k] == pytest.approx(exact[0], rel=1e-5, abs=1e-6 * xs[0])
        assert res["tis.C"][k] == pytest.approx(exact[1], rel=1e-5, abs=1e-6 * xs[1])


def test_exchange_without_length_is_rejected(tmp_path):
    bad = POOL_NETLIST.replace("h: 1e-6 m**2/s, l: 2 m, scale: 1.0e-9,\n", "h: 1e-6 m**2/s, scale: 1.0e-9,\n")
    with pytest.raises(NetlistError, match="length l"):
        hc.load(_write(tmp_path, bad))


def test_netlists_pass_check():
    for path in (CONSISTENT, THESIS):
        c = hc.load(path)
        types = {g.comp.type_name for g in c.groups}
        assert {"tracer_pool", "tissue_pool", "arteriole"} <= types
