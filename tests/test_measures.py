"""--measure (hemocircuit.measures) against closed forms and independent computations."""
import numpy as np
import pytest
from scipy.optimize import brentq

import hemocircuit as hc
from hemocircuit.errors import HemocircuitError
from hemocircuit.measures import measure, measure_all, plateau, settling_time
from hemocircuit.results import Result

from paths import ROOT

from circuits import C, L, R, RLC_NET  # noqa: E402


def _series(t, y, unit="mmHg"):
    return Result({"time": t, "y": y}, {"time": "s", "y": unit}, index=["time"], metadata={"analysis": "tran"})


def test_resonance_of_series_rlc_is_closed_form(write):
    # series RLC admittance Q/P = 1/(R + sL + 1/sC): peak 1/R at f0 = 1/(2 pi sqrt(LC))
    c = hc.load(write(RLC_NET))
    res = c.ac_response("Ps", ["Q(R1)", "P(b)"], "0.01:2Hz", per_decade=40)
    (m, vals), = measure(res, "resonance Q(R1)")
    f0 = 1 / (2 * np.pi * np.sqrt(L * C))
    assert vals["frequency [Hz]"] == pytest.approx(f0, rel=2e-3)
    assert vals["peak_gain [mL/s/mmHg]"] == pytest.approx(1 / R, rel=1e-3)
    assert not vals["at_edge"]


def test_gain_and_phase_at_a_frequency(write):
    c = hc.load(write(RLC_NET))
    res = c.ac_response("Ps", ["Q(R1)"], "0.01:2Hz", per_decade=100)
    fa = 0.3
    H = 1 / (R + 2j * np.pi * fa * L + 1 / (2j * np.pi * fa * C))
    lines = measure_all(res, ["gain Q(R1) at=0.3Hz", "phase Q(R1) at=300mHz"])
    g = res.metadata["measures"]["gain Q(R1) at=0.3Hz"]
    assert g["gain [mL/s/mmHg]"] == pytest.approx(abs(H), rel=2e-3)
    ph = res.metadata["measures"]["phase Q(R1) at=300mHz"]["phase [deg]"]
    assert ph == pytest.approx(np.degrees(np.angle(H)), abs=0.3)
    assert lines[0].startswith("gain Q(R1) at=0.3Hz: gain = ")


def test_time_average_mean_min_max_and_period_of_a_sine():
    # y = 3 + 2 sin(2 pi t / 4): over [0.5, 7.3] s the time average is
    # 3 + (2/(T w)) (cos(w a) - cos(w b)) / 1 with w = pi/2 -- not the sample mean of a
    # non-uniform grid
    t = np.sort(np.concatenate([np.linspace(0, 10, 2001), np.linspace(0.5, 1.0, 3000)]))
    w = 2 * np.pi / 4
    y = 3 + 2 * np.sin(w * t)
    res = _series(t, y)
    a, b = 0.5, 7.3
    exact = 3 + 2 * (np.cos(w * a) - np.cos(w * b)) / (w * (b - a))
    (_, avg), = measure(res, "average y from=0.5s to=7.3s")
    assert avg["average [mmHg]"] == pytest.approx(exact, rel=1e-6)
    (_, mean), = measure(res, "mean y from=0.5s to=7.3s")
    assert abs(mean["mean [mmHg]"] - exact) > 0.05  # the sample mean is biased by the dense part
    (_, mx), = measure(res, "max y")
    assert mx["max [mmHg]"] == pytest.approx(5.0, abs=1e-5) and mx["at [s]"] == pytest.approx(1.0, abs=0.01)
    (_, mn), = measure(res, "min y to=5s")
    assert mn["min [mmHg]"] == pytest.approx(1.0, abs=1e-5) and mn["at [s]"] == pytest.approx(3.0, abs=0.01)
    (_, per), = measure(res, "period y")
    assert per["period [s]"] == pytest.approx(4.0, rel=1e-4)


def test_settling_time_of_a_first_order_step():
    # y = 10 (1 - exp(-(t - 2)/tau)) after t = 2: within 2 % of 10 from tau ln(50) on
    tau = 1.5
    t = np.linspace(0, 20, 20001)
    y = np.where(t < 2, 0.0, 10 * (1 - np.exp(-(t - 2) / tau)))
    (_, v), = measure(_series(t, y, "mL/s"), "settle y tol=2% after=2s")
    assert v["settling_time [s]"] == pytest.approx(tau * np.log(50), rel=1e-3)
    assert settling_time(t, y, 2.0, 0.02)[1] == pytest.approx(10 * (1 - np.exp(-18 / tau)))


def test_plateau_matches_an_independent_root_search_on_payne06():
    # the plateau's ends found by root finding on the operating point itself, not from the sweep
    c = hc.load(ROOT / "netlists" / "payne06.yaml")
    sweep = c.dc_sweep("Pa.value", "40:160:2 mmHg")
    (_, v), = measure(sweep, "plateau Q(Rla) 10% ref=100mmHg")

    def q(p):
        return c.with_values({"Pa.value": p}).operating_point()["Q(Rla)"]

    q_ref = q(100.0)
    assert v["Q(Rla) at ref [mL/s]"] == pytest.approx(q_ref, rel=1e-9)
    low = brentq(lambda p: q(p) / q_ref - 0.9, 40, 100, xtol=1e-3)
    high = brentq(lambda p: q(p) / q_ref - 1.1, 100, 160, xtol=1e-3)
    assert v["low [mmHg]"] == pytest.approx(low, abs=0.15)   # linear interpolation on a 2 mmHg grid
    assert v["high [mmHg]"] == pytest.approx(high, abs=0.15)
    assert 45 < low < 75 and 120 < high < 150  # the autoregulation plateau of the thesis's model


def test_plateau_edges_at_the_sweep_ends_and_interpolated():
    x = np.linspace(0, 10, 11)
    y = np.where(x < 4, 1 + 0.1 * (4 - x), 1.0)  # leaves the 5 % band halfway between 3 and 4... at 3.5
    low, high, yref = plateau(x, y, 6.0, 0.05)
    assert (low, high, yref) == (pytest.approx(3.5), 10.0, 1.0)


def test_measure_errors_are_clear(write):
    res = _series(np.linspace(0, 1, 11), np.zeros(11))
    with pytest.raises(HemocircuitError, match="did you mean plateau"):
        measure(res, "platau y 10% ref=1s")
    with pytest.raises(HemocircuitError, match="no column 'yy'.*did you mean y"):
        measure(res, "max yy")
    with pytest.raises(HemocircuitError, match="needs an ac or freq result"):
        measure(res, "resonance y")
    with pytest.raises(HemocircuitError, match="no oscillation"):
        measure(res, "period y")


def test_cli_measure_is_printed_and_saved(write, tmp_path, capsys):
    from hemocircuit.cli import main
    out = tmp_path / "ac.csv"
    assert main(["ac", str(write(RLC_NET)), "--input", "Ps", "--output", "Q(R1)", "--freq", "0.01:2Hz",
                 "--per-decade", "40", "--quiet", "--measure", "resonance Q(R1)", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "resonance Q(R1): frequency = 0.3" in printed
    back = Result.load(out)
    f = back.metadata["measures"]["resonance Q(R1)"]["frequency [Hz]"]
    assert f == pytest.approx(1 / (2 * np.pi * np.sqrt(L * C)), rel=2e-3)
