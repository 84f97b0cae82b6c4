"""The whole-body netlists (netlists/body/): a closed-loop heart with two autoregulating cerebral
hemispheres as subcircuit instances.  Resting state within the documented physiological
ranges, blood volume conserved, and the impaired variant's flow following the pressure."""
import numpy as np
import pytest

import hemocircuit as hc

from paths import ROOT

BODY = ROOT / "netlists" / "body"
PERIOD = 0.857  # s: 70 beats /min


@pytest.fixture(scope="module")
def runs():
    """Each netlist at its resting systemic resistance (Rd 0.95) and at a lower one (0.7 mmHg*s/mL),
    40 s from the operating point (the arteriole settles within it)."""
    out = {}
    for name in ("body", "body_impaired"):
        for rd in (0.95, 0.7):
            c = hc.load(str(BODY / f"{name}.yaml")).with_values({"systemic.Rd": f"{rd} mmHg*s/mL"})
            out[name, rd] = (c, c.simulate(40.0, dt=0.01))
    return out


def _last_beats(res, n=2):
    return res.t > res.t[-1] - n * PERIOD


def test_resting_state_is_an_adult_at_rest(runs):
    c, r = runs["body", 0.95]
    m = _last_beats(r)
    mean = {k: float(np.mean(r[k][m])) for k in ("P(art)", "P(vc)", "Q(systemic)", "Q(left.Rla)", "Q(right.Rla)",
                                                  "P(left.ic)")}
    cbf = mean["Q(left.Rla)"] + mean["Q(right.Rla)"]
    co = mean["Q(systemic)"] + cbf
    assert c.parameters.values["heart.period"][0] == pytest.approx(PERIOD)
    assert 85 < mean["P(art)"] < 95                     # MAP ~90 mmHg
    assert 110 < r["P(art)"][m].max() < 140 and 55 < r["P(art)"][m].min() < 80  # systolic / diastolic
    assert 4.5 < co * 60 / 1000 < 6.5                   # cardiac output ~5 L/min
    assert 0.10 < cbf / co < 0.18                       # cerebral share ~12-15 % (two Payne06 beds: 16 %)
    assert 7 < mean["P(left.ic)"] < 12 and 3 < mean["P(vc)"] < 9
    # the two hemispheres are the same bed at the same pressures
    assert mean["Q(left.Rla)"] == pytest.approx(mean["Q(right.Rla)"], rel=1e-6)


def test_blood_volume_is_conserved_through_the_beats(runs):
    c, r = runs["body", 0.95]
    # the closed loop's law: every volume store of the loop (the brains' compliances included)
    k = [s["kind"] for s in c.law_specs].index("volume")
    vols = np.array([c.law_volumes(x[None, :])[k][0] for x in r.x[::100]])
    assert np.max(np.abs(vols - 545.0)) <= 1e-9 * 545.0


def test_impaired_autoregulation_lets_flow_follow_pressure(runs):
    """Lowering the systemic resistance lowers the MAP by 10-13 %; the intact beds keep their
    flow (relative change under half the pressure's, measured 0.43), the passive beds' flow
    follows the pressure (measured 1.3: a dilated bed's resistance also falls with pressure)."""
    def ratio(name):
        (_, hi), (_, lo) = runs[name, 0.95], runs[name, 0.7]
        m = _last_beats(hi)
        mean = {k: (np.mean(hi[k][m]), np.mean(lo[k][m])) for k in ("P(art)", "Q(left.Rla)")}
        rel = {k: (a - b) / a for k, (a, b) in mean.items()}
        assert rel["P(art)"] > 0.08
        return rel["Q(left.Rla)"] / rel["P(art)"]
    assert ratio("body") < 0.6
    assert ratio("body_impaired") > 0.9
    _, intact = runs["body", 0.95]
    _, impaired = runs["body_impaired", 0.95]
    m = _last_beats(intact)
    assert np.mean(impaired["left.art.r"][m]) > np.mean(intact["left.art.r"][m])  # dilated without tone


def test_spontaneous_tone_leaves_pressure_and_flow_coherent_only_where_autoregulation_lets_pressure_through():
    """fluctuations.yaml: the arterial pressure fluctuates (the systemic resistance) and so does
    each hemisphere's arteriolar tone (slow noise on art.pCa_shift, standing for CO2 and neural
    influences).  TFA with the white paper's settings (330 s, the last 300 s, 100 s windows):
    the intact beds high-pass the pressure, so at very low frequencies the tone dominates the
    flow and the coherence is low (healthy adults: < 0.5, Zhang et al. 1998); at LF the pressure
    gets through (coherence > 0.5) with the phase lead of docs/body.md.  Passive beds have no
    tone to fluctuate (Ca = 0) and follow the pressure at every frequency (coherence ~1).
    Without the tone noise the intact VLF coherence is 0.99."""
    from hemocircuit.dca.series import uniform_series
    from hemocircuit.dca.tfa import tfa

    out = {}
    for name in ("fluctuations", "fluctuations_impaired"):
        r = hc.load(str(BODY / f"{name}.yaml")).simulate(330.0, dt=0.01)
        keep = r.t >= 30.0  # the start from the operating point, left out
        series = uniform_series(r.t[keep], r["P(art)"][keep], r["Q(left.Rla)"][keep], beats=True)
        res, _ = tfa(series, window=100.0)
        out[name] = {b: (res["phase"][k], res["coherence"][k]) for k, b in enumerate(res["band"])}
    intact, passive = out["fluctuations"], out["fluctuations_impaired"]
    assert intact["VLF"][1] < 0.5 < intact["LF"][1]
    assert 30.0 <= intact["LF"][0] <= 60.0
    assert passive["VLF"][1] > 0.9 and passive["LF"][1] > 0.9
    assert abs(passive["LF"][0]) < 15.0


def test_the_right_hemisphere_follows_the_left_arterioles_dynamics():
    """body.yaml sets tau_Ca and f2 on left.art; right.art follows by expressions that name an
    instance's element (``= left.art.tau_Ca``), so one --set or --grid value moves both
    hemispheres, and setting the follower is refused with the reason."""
    base = hc.load(str(BODY / "body.yaml"))
    slow = base.with_values({"left.art.tau_Ca": "3 s", "left.art.f2": "0.5 N*s/m"})
    runs = {name: c.simulate(6.0, dt=0.01) for name, c in (("base", base), ("slow", slow))}
    for r in runs.values():
        np.testing.assert_allclose(r["Q(right.Rla)"], r["Q(left.Rla)"], rtol=1e-8, atol=1e-9)
    assert np.max(np.abs(runs["slow"]["Q(right.Rla)"] - runs["base"]["Q(right.Rla)"])) > 0.1
    with pytest.raises(hc.NetlistError, match=r"right\.art.*follows an expression \(left\.art\.tau_Ca\); it cannot be set"):
        base.with_values({"right.art.tau_Ca": "3 s"})
