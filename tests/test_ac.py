"""Small-signal AC analysis: closed forms (RC, RLC), the f -> 0 limit against DC sweeps,
conservation-law reduction, frequency parsing, speed, CLI."""
import time

import numpy as np
import pytest

import hemocircuit as hc
from hemocircuit.analyses.ac import ac_response, parse_freqs, transfer
from hemocircuit.analyses.linearize import linearize
from hemocircuit.cli import main

from paths import ROOT

NETS = ROOT / "netlists"

from circuits import C, L, R, RLC_NET  # noqa: E402

RC_NET = """
name: rc
elements:
  - {id: Ps, type: pressure_source, nodes: [in, ground], value: 40 mmHg}
  - {id: R1, type: resistor,        nodes: [in, a],      R: 2 mmHg*s/mL}
  - {id: C1, type: compliance,      nodes: [a, ground],  C: 0.75 mL/mmHg, V0: 3 mL}
"""


def rel(got, ref):
    return float(np.max(np.abs(np.asarray(got) - ref) / np.abs(ref)))


# ------------------------------------------------------------------ closed forms -----------
def test_rlc_transfer_functions_exact(write):
    c = hc.load(write(RLC_NET))
    f = np.logspace(-3, 2, 1000)
    res = ac_response(c, "Ps", ["P(b)", "Q(R1)", "P(a)", "Q(L1)"], f)
    s = 2j * np.pi * f
    Hq = 1 / (R + s * L + 1 / (s * C))  # series RLC admittance
    assert rel(res.H["Q(R1)"], Hq) <= 1e-6
    assert rel(res.H["Q(L1)"], Hq) <= 1e-6
    assert rel(res.H["P(b)"], Hq / (s * C)) <= 1e-6
    assert rel(res.H["P(a)"], 1 - R * Hq) <= 1e-6
    # phase convention: positive = output leads.  The capacitor pressure lags from 0 to -180,
    # the flow leads by 90 deg at low frequency and lags by 90 at high frequency.
    assert res.phase["P(b)"][0] == pytest.approx(0.0, abs=1.0)
    assert res.phase["P(b)"][-1] == pytest.approx(-180.0, abs=1.0)
    assert np.all(np.diff(res.phase["P(b)"]) < 0)  # unwrapped, monotone
    assert res.phase["Q(R1)"][0] == pytest.approx(90.0, abs=1.0)
    assert res.phase["Q(R1)"][-1] == pytest.approx(-90.0, abs=1.0)
    np.testing.assert_allclose(res.phase["Q(R1)"], np.degrees(np.angle(Hq)), atol=1e-5)
    # the resonance of the capacitor pressure is at 1/(2 pi sqrt(LC))
    f0 = 1 / (2 * np.pi * np.sqrt(L * C))
    k = np.argmin(np.abs(f - f0))
    assert res.phase["P(b)"][k] == pytest.approx(-90.0, abs=0.5)
    assert res.stable


def test_rc_low_pass_gain_phase_and_relative_gain(write):
    c = hc.load(write(RC_NET))
    tau = R * C
    fc = 1 / (2 * np.pi * tau)
    res = ac_response(c, "Ps", ["P(a)", "Q(R1)"], [0.0, fc, 10 * fc])
    assert res.gain["P(a)"] == pytest.approx([1.0, 1 / np.sqrt(2), 1 / np.sqrt(101)], rel=1e-7)
    assert res.phase["P(a)"] == pytest.approx([0.0, -45.0, -np.degrees(np.arctan(10))], abs=1e-5)
    # relative gain (dy/y0)/(dp/p0): P(a) = Ps at DC, so the relative gain is |H|
    assert res.rel_gain["P(a)"] == pytest.approx(res.gain["P(a)"], rel=1e-9)
    assert res.y0["P(a)"] == pytest.approx(40.0)
    assert res.p0 == pytest.approx(40.0)
    assert res.input == "Ps.value"
    assert res.input_unit == "mmHg" and res.units["gain(Q(R1)/Ps.value)"] == "mL/s/mmHg"
    # no flow at DC; the flow leads by 45 deg at the corner
    assert abs(res.H["Q(R1)"][0]) < 1e-9
    assert res.phase["Q(R1)"][1] == pytest.approx(45.0, abs=1e-5)


def test_transfer_batched_solve_matches_loop():
    rng = np.random.default_rng(1)
    A = rng.normal(size=(6, 6)) - 4 * np.eye(6)
    B, Cm, D = rng.normal(size=6), rng.normal(size=(2, 6)), rng.normal(size=2)
    s = 2j * np.pi * np.logspace(-2, 1, 7)
    H = transfer(A, B, Cm, D, s)
    ref = np.array([[Cm[k] @ np.linalg.solve(sk * np.eye(6) - A, B) + D[k] for sk in s] for k in range(2)])
    np.testing.assert_allclose(H, ref, rtol=1e-12)


# ------------------------------------------------------------------ whole-brain models -----
def _dc_slope(c, names, Pa, h=0.01):
    vals = {}
    for sgn in (1, -1):
        c2 = c.with_values({"Pa.value": Pa + sgn * h})
        vals[sgn] = c2.operating_point().values
    return {n: (vals[1][n] - vals[-1][n]) / (2 * h) for n in names}


@pytest.mark.parametrize("net", ["arterial_compliance", "icp"])
def test_low_frequency_gain_equals_dc_sweep_slope(net):
    """At f -> 0 the AC gain is the slope dq/dPa of the DC sweep (finite differences of
    operating points).  For the ICP variant the conserved blood + intracranial volume is held,
    as in the DC sweep, and the law's structural zero eigenvalue is projected out."""
    c = hc.load(NETS / f"{net}.yaml")
    c = c.with_values({"art.tau_Ca": 1.0})
    names = ["Q(Rla)", "Q(Rsv)", "art.r"]
    for Pa in (30.0, 80.0):
        c = c.with_values({"Pa.value": Pa})
        res = ac_response(c, "Pa", names, [0.0, 1e-7])
        slope = _dc_slope(c, names, Pa)
        for n in names:
            assert np.all(np.isfinite(res.H[n]))
            assert abs(res.H[n][0] - slope[n]) <= 1e-4 * abs(slope[n]), (net, Pa, n)
            assert abs(res.H[n][1] - slope[n]) <= 1e-4 * abs(slope[n]), (net, Pa, n)
            assert res.rel_gain[n][0] == pytest.approx(abs(slope[n]) * Pa / abs(res.y0[n]), rel=1e-4)


def test_arterial_compliance_resonance_and_lead():
    """Linear counterparts of the thesis's section-artComp readings (Pa = 80, tau_Ca = 1 s):
    q2 resonates between 0.08 and 0.14 Hz, flow leads Pa at 0.1 Hz, and slowing Ca
    (tau_Ca = 10 s) moves the peak lower and makes it larger."""
    c = hc.load(NETS / "arterial_compliance.yaml")
    c = c.with_values({"art.tau_Ca": 1.0})
    f = np.logspace(np.log10(0.005), 0, 400)
    res = ac_response(c, "Pa", ["Q(Rla)", "Q(Rsv)"], f)
    g = res.rel_gain["Q(Rsv)"]
    k = int(np.argmax(g))
    assert 0.08 <= f[k] <= 0.14
    i = int(np.argmin(np.abs(f - 0.1)))
    assert 20.0 <= res.phase["Q(Rla)"][i] <= 35.0
    assert 55.0 <= res.phase["Q(Rla)"].max() <= 75.0
    c = c.with_values({"art.tau_Ca": 10.0})
    slow = ac_response(c, "Pa", ["Q(Rsv)"], f)
    k10 = int(np.argmax(slow.rel_gain["Q(Rsv)"]))
    assert f[k10] < f[k]
    assert slow.rel_gain["Q(Rsv)"][k10] > g[k]


def test_batch_circuit_and_derived_output():
    c = hc.load(NETS / "arterial_compliance.yaml")
    f = np.array([0.01, 0.1, 1.0])
    cb = c.batch(2)
    cb = cb.with_values({"Pa.value": np.array([30.0, 80.0])})
    rb = ac_response(cb, "Pa", ["Q(Rsv)", "V_a"], f)
    assert rb.H["Q(Rsv)"].shape == (2, 3)
    for k, Pa in enumerate((30.0, 80.0)):
        c = c.with_values({"Pa.value": Pa})
        r1 = ac_response(c, "Pa", ["Q(Rsv)", "V_a"], f)
        for n in ("Q(Rsv)", "V_a"):
            np.testing.assert_allclose(rb.H[n][k], r1.H[n], rtol=1e-6)
    # V_a = V(Ca) + V(art) (derived quantity): its transfer function is the sum
    r = ac_response(c, "Pa", ["V_a", "V(Ca)", "V(art)"], f)
    np.testing.assert_allclose(r.H["V_a"], r.H["V(Ca)"] + r.H["V(art)"], rtol=1e-9)


def test_thousand_frequencies_in_milliseconds():
    c = hc.load(NETS / "vasomotion.yaml")
    op = c.operating_point()
    f = np.logspace(-3, 1, 1000)
    ac_response(c, "Pa", ["Q(Rla)", "Q(Rsv)"], f, op=op)  # warm-up
    t0 = time.perf_counter()
    res = ac_response(c, "Pa", ["Q(Rla)", "Q(Rsv)"], f, op=op)
    elapsed = time.perf_counter() - t0
    assert elapsed < 0.25, elapsed  # measured ~10 ms (linearisation included)
    assert not res.stable  # the vasomotion equilibrium at Pa = 80 is unstable: flagged
    lin = linearize(c, op.x)
    assert lin.A_red.shape == (7, 7)


# ------------------------------------------------------------------ parsing, CLI -----------
def test_parse_freqs():
    f = parse_freqs("0.001:10Hz", per_decade=20)
    assert len(f) == 81 and f[0] == pytest.approx(0.001) and f[-1] == pytest.approx(10.0)
    assert np.allclose(np.diff(np.log10(f)), 0.05)
    assert parse_freqs("1:3:1 Hz") == pytest.approx([1, 2, 3])
    assert parse_freqs("10,100 mHz") == pytest.approx([0.01, 0.1])
    assert parse_freqs([0.1, 1]) == pytest.approx([0.1, 1])
    with pytest.raises(hc.NetlistError):
        parse_freqs("10:1Hz")


def test_cli_ac(tmp_path, capsys):
    out, png = tmp_path / "ac.csv", tmp_path / "bode.png"
    rc = main(["ac", str(NETS / "arterial_compliance.yaml"), "--input", "Pa", "--output", "Q(Rla)",
               "--output", "Q(Rsv)", "--freq", "0.001:10Hz", "--per-decade", "5", "--set", "art.tau_Ca=1s",
               "--out", str(out), "--plot", str(png)])
    assert rc == 0
    lines = [ln for ln in out.read_text().splitlines() if not ln.startswith("#")]  # provenance header
    assert lines[0].split(",")[:4] == ["frequency [Hz]", "gain(Q(Rla)/Pa.value) [mL/s/mmHg]",
                                       "rel_gain(Q(Rla)/Pa.value) [1]", "phase(Q(Rla)/Pa.value) [deg]"]
    assert len(lines) == 1 + 21
    assert png.stat().st_size > 10_000
    capsys.readouterr()
    assert main(["ac", str(NETS / "arterial_compliance.yaml"), "--output", "Q(nope)"]) == 2
    assert "unknown output" in capsys.readouterr().err
    assert main(["ac", str(NETS / "arterial_compliance.yaml"), "--input", "Px"]) == 2


def test_frequency_specs_with_prefixes_and_exponents():
    """One parser for ac and freq: unit prefixes and exponents ('1e-3' is a number, not 1 e)."""
    from hemocircuit.analyses.ac import parse_freqs
    np.testing.assert_allclose(parse_freqs("10:100 mHz", 1), [0.01, 0.1])
    np.testing.assert_allclose(parse_freqs("1e-3:1Hz", 1), [1e-3, 1e-2, 1e-1, 1.0])
    np.testing.assert_allclose(parse_freqs("0.05,0.2Hz"), [0.05, 0.2])
