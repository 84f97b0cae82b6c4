"""Stability of equilibria: thesis readings (chapter 6 stability analysis, MODEL_NOTES),
hard limits without false eigenvalues, conservation-law zeros removed, Hopf points."""
import numpy as np
import pytest

import hemocircuit as hc
from hemocircuit.analyses.linearize import law_gradients, linearize, state_jacobian
from hemocircuit.analyses.stability import analyse_eigenvalues, analyse_point, equilibrium, stability_sweep
from hemocircuit.cli import main

from paths import ROOT

NETS = ROOT / "netlists"


@pytest.fixture(scope="module")
def artcomp_sweep():
    c = hc.load(NETS / "arterial_compliance.yaml")
    c = c.with_values({"art.tau_Ca": 1.0})
    return stability_sweep(c, "Pa.value", "20:200:10 mmHg")


@pytest.fixture(scope="module")
def vasomotion():
    return hc.load(NETS / "vasomotion.yaml")


# ------------------------------------------------------------------ classification ---------
def test_classification_of_synthetic_spectra():
    a = analyse_eigenvalues([-1.0, -2.0, -0.5])
    assert a["classification"] == "stable node" and a["n_pairs"] == 0 and a["pair"] is None
    a = analyse_eigenvalues([-1.0, -0.1 + 2j, -0.1 - 2j, -1 + 0.5j, -1 - 0.5j])
    assert a["classification"] == "stable focus" and a["n_pairs"] == 2
    # least damped = smallest damping ratio -Re/|lambda|
    assert a["pair"] == pytest.approx(-0.1 + 2j)
    assert a["pair_zeta"] == pytest.approx(0.1 / abs(-0.1 + 2j))
    assert a["pair_freq"] == pytest.approx(2 / (2 * np.pi))
    a = analyse_eigenvalues([0.3, -1.0, -0.2 + 1j, -0.2 - 1j])
    assert a["classification"] == "unstable node" and a["n_unstable"] == 1  # a saddle counts here
    a = analyse_eigenvalues([0.05 + 0.6j, 0.05 - 0.6j, -3.0])
    assert a["classification"] == "unstable focus" and a["n_unstable"] == 2
    assert a["eigenvalues"][0] == pytest.approx(0.05 + 0.6j)  # sorted: largest Re, +Im first


# ------------------------------------------------------------------ arterial compliance ----
def test_arterial_compliance_all_stable_complex_pair_40_to_150(artcomp_sweep):
    """Thesis: every equilibrium is stable for Pa = 20-200 mmHg (tau_Ca = 1 s); the eigenvalues
    are real below ~40 and above ~150 mmHg, with one complex pair in between.  Found: the pair
    exists for Pa in [39.6, 155.4] mmHg."""
    r = artcomp_sweep
    assert not r.failed
    assert r.stable.all()
    assert np.all(r.abscissa < 0)
    assert set(r.classification) == {"stable node", "stable focus"}
    ranges = r.complex_ranges()
    assert len(ranges) == 1
    lo, hi = ranges[0]
    assert abs(lo - 40) <= 10 and abs(hi - 150) <= 10
    assert lo == pytest.approx(39.62, abs=0.3) and hi == pytest.approx(155.43, abs=0.3)  # located by bisection
    inside = (r.values > lo) & (r.values < hi)
    assert np.all((r.n_pairs == 1) == inside)
    # damped oscillation in the middle: a slow focus
    i = int(np.argmin(np.abs(r.values - 80)))
    assert r.classification[i] == "stable focus"
    assert 0.03 < r.pair_freq[i] < 0.07 and 0.5 < r.pair_zeta[i] < 1
    assert not [e for e in r.events if e["kind"] in ("hopf", "real crossing")]


def test_hard_limit_gives_no_false_huge_eigenvalue(artcomp_sweep):
    """At low Pa the venous compartment collapses (V held at 0 in dynamics).  A one-sided
    difference across the clamp gives the thesis's false, huge eigenvalue; the linearisation of
    the smooth steady variant with central differences does not, and the state is flagged."""
    r = artcomp_sweep
    low = r.values <= 20
    assert low.any()
    for i in np.flatnonzero(low):
        assert r.at_limit[i] == ["Cv.V"]
        assert np.max(np.abs(r.eigenvalues[i])) < 1e3
        assert r.stable[i]
    assert all(a == [] for a, v in zip(r.at_limit, r.values) if v >= 40)
    # the artefact itself: the dynamic (clamped) circuit, V at its limit 0, forward difference
    c = hc.load(NETS / "arterial_compliance.yaml")
    c = c.with_values({"Pa.value": 20.0})
    x = r.x[np.flatnonzero(low)[0]].copy()
    x[c.state_names.index("Cv.V")] = 0.0
    lam_false = np.linalg.eigvals(c.jacobian(0.0, x))
    assert np.max(np.abs(lam_false)) > 1e5


# ------------------------------------------------------------------ ICP / vasomotion -------
def test_icp_structural_zero_is_removed():
    c = hc.load(NETS / "icp.yaml")
    x = equilibrium(c)
    lin = linearize(c, x)
    full = np.linalg.eigvals(lin.A)
    assert np.min(np.abs(full)) < 1e-8  # the conserved V_a + V_v - V_ic: a zero eigenvalue
    cvec = law_gradients(c.steady_variant(), x)
    assert cvec.shape == (1, c.nx)
    assert np.abs(cvec @ lin.A).max() < 1e-9 * np.abs(lin.A).max()  # c^T J = 0
    p = analyse_point(c, x)
    assert len(p["eigenvalues"]) == c.nx - 1
    assert np.min(np.abs(p["eigenvalues"])) > 1e-3
    assert p["classification"] == "stable focus"
    # the other eigenvalues are unchanged by the reduction
    kept = sorted(full, key=abs)[1:]
    np.testing.assert_allclose(np.sort_complex(np.array(kept)), np.sort_complex(p["eigenvalues"]), rtol=1e-8)


def test_vasomotion_unstable_focus_at_80(vasomotion):
    """Thesis section analInst: omega_n = pi/5 rad/s, zeta = 0.1, Pa = 80 mmHg oscillates:
    an unstable focus near 0.1 Hz (found: lambda = 0.067 +- 0.662j /s, 0.105 Hz)."""
    x = equilibrium(vasomotion)
    p = analyse_point(vasomotion, x)
    assert p["classification"] == "unstable focus"
    assert p["n_unstable"] == 2
    assert 0.08 < p["pair_freq"] < 0.13
    assert p["pair"].real > 0 and p["pair_zeta"] < 0
    lam = p["eigenvalues"]
    assert len(lam) == vasomotion.nx - 1  # ICP law: structural zero not reported
    assert np.min(np.abs(lam)) > 1e-3
    assert p["at_limit"] == []


def test_vasomotion_hopf_points_in_pa(vasomotion):
    """Found: Hopf points at Pa = 43.52 and 170.03 mmHg (frequency ~0.10 Hz); unstable between."""
    r = stability_sweep(vasomotion, "Pa.value", "30:190:20 mmHg")
    hopf = [e for e in r.events if e["kind"] == "hopf"]
    assert [round(e["value"], 1) for e in hopf] == pytest.approx([43.5, 170.0], abs=0.6)
    assert hopf[0]["direction"] == "unstable above" and hopf[1]["direction"] == "unstable below"
    for e in hopf:
        assert abs(e["eigenvalue"].real) < 1e-6
        assert 0.09 < e["frequency"] < 0.12
    unst = ~r.stable
    assert np.all(unst == ((r.values > hopf[0]["value"]) & (r.values < hopf[1]["value"])))
    assert 170.0 in r.values and not r.stable[list(r.values).index(170.0)]  # just below 170.03


def test_vasomotion_hopf_in_zeta_and_omega_n(vasomotion):
    """At Pa = 80 the oscillation disappears as zeta or omega_n grow (thesis: near 0.2 and near
    0.2 Hz = 1.26 rad/s).  Found: zeta_H = 0.2275; omega_n,H = 1.463 rad/s (0.233 Hz) -- at
    omega_n = 2 pi 0.2 the equilibrium is still (weakly) unstable, Re = 0.020 /s."""
    rz = stability_sweep(vasomotion, "art.zeta", [0.1, 0.15, 0.2, 0.25, 0.3])
    assert rz.hopf == [pytest.approx(0.2275, abs=0.005)]
    assert list(rz.stable) == [False, False, False, True, True]
    rw = stability_sweep(vasomotion, "art.omega_n", [0.6, 1.0, 1.4, 1.8])
    assert rw.hopf == [pytest.approx(1.463, abs=0.01)]
    (e,) = [e for e in rw.events if e["kind"] == "hopf"]
    assert e["direction"] == "unstable below"
    assert e["frequency"] == pytest.approx(1.463 / (2 * np.pi), rel=0.02)


# ------------------------------------------------------------------ internals, CLI ---------
def test_central_difference_jacobian_matches_forward_on_smooth_point():
    c = hc.load(NETS / "arterial_compliance.yaml")
    x = equilibrium(c)
    sv = c.steady_variant()
    Jc = state_jacobian(sv, x)
    Jf = sv.jacobian(0.0, x)
    np.testing.assert_allclose(Jc, Jf, rtol=1e-4, atol=1e-6 * np.abs(Jc).max())


def test_cli_stability(tmp_path, capsys):
    out, png = tmp_path / "stab.csv", tmp_path / "stab.png"
    rc = main(["stability", str(NETS / "arterial_compliance.yaml"), "--sweep", "Pa.value=30:170:35mmHg",
               "--set", "art.tau_Ca=1s", "--out", str(out), "--plot", str(png)])
    assert rc == 0
    text = capsys.readouterr().out
    assert "complex pair for Pa.value in [" in text
    lines = [ln for ln in out.read_text().splitlines() if not ln.startswith("#")]  # provenance header
    head = lines[0].split(",")
    assert head[:3] == ["Pa.value [mmHg]", "classification", "n_unstable [1]"]
    assert "frequency(pair) [Hz]" in head and "re(lambda5) [1/s]" in head and "re(lambda6) [1/s]" not in head
    assert len(lines) == 1 + 5
    assert png.stat().st_size > 10_000
    assert main(["stability", str(NETS / "arterial_compliance.yaml")]) == 2
