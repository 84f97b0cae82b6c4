"""Transfer function analysis (hemocircuit.dca, `hemocircuit tfa`): closed forms of known linear
systems, the CARNet window count and coherence threshold, beat-to-beat averaging, and clear
errors for bad recordings."""
import csv

import numpy as np
import pytest
from scipy.signal import bilinear, butter, freqz, lfilter

from hemocircuit.cli import main
from hemocircuit.dca import read_series, spectrum, tfa, uniform_series
from hemocircuit.dca.series import Series, beat_means
from hemocircuit.results import Result

FS = 10.0


def _noise(seconds, seed=0, mean=90.0, sd=3.0):
    """Band-limited (0-0.5 Hz) pressure fluctuations around ``mean`` [mmHg], sampled at 10 Hz."""
    rng = np.random.default_rng(seed)
    t = np.arange(0, seconds, 1 / FS)
    return t, mean + sd * lfilter(*butter(2, 0.5, fs=FS), rng.standard_normal(t.size))


def _highpass(tau, k):
    """A first-order high-pass k * s tau / (1 + s tau) (autoregulation's shape), discretised at 10 Hz."""
    b, a = bilinear([tau, 0.0], [tau, 1.0], FS)
    return k * b, a


def test_gain_and_phase_of_a_first_order_high_pass_match_its_closed_form():
    t, x = _noise(600)
    b, a = _highpass(5.0, 0.8)
    y = 60.0 + lfilter(b, a, x - 90.0)
    res, sp = tfa(Series(t, x, y, FS, ("ABP", "CBFV"), ("mmHg", "cm/s")))
    _, h = freqz(b, a, worN=2 * np.pi * sp.f / FS)  # the filter's own response at the estimate's frequencies
    for k, (lo, hi) in enumerate(((0.02, 0.07), (0.07, 0.2), (0.2, 0.5))):
        band = (sp.f >= lo) & (sp.f < hi)
        assert res["points_used"][k] == band.sum()  # coherent everywhere: nothing left out
        assert res["gain"][k] == pytest.approx(np.mean(np.abs(h[band])), rel=0.02)
        assert res["phase"][k] == pytest.approx(np.degrees(np.mean(np.angle(h[band]))), abs=1.0)
        assert res["coherence"][k] > 0.95
        assert res["gain_norm"][k] == pytest.approx(res["gain"][k] / np.mean(y) * 100, rel=1e-12)
    # a high-pass: the gain grows and the phase lead falls from VLF to HF
    assert res["gain"][0] < res["gain"][1] < res["gain"][2] and res["phase"][0] > res["phase"][1] > res["phase"][2] > 0
    assert res.units["gain"] == "cm/s/mmHg" and res.units["gain_norm"] == "%/mmHg" and res.units["phase"] == "deg"


def test_a_proportional_output_has_its_gain_zero_phase_and_full_coherence():
    t, x = _noise(300, seed=1)
    sp = spectrum(x, 2.5 * x + 7.0, FS)
    band = (sp.f >= 0.02) & (sp.f < 0.5)
    np.testing.assert_allclose(sp.gain[band], 2.5, rtol=1e-9)
    np.testing.assert_allclose(sp.phase_deg[band], 0.0, atol=1e-7)
    np.testing.assert_allclose(sp.coherence[band], 1.0, rtol=1e-9)


def test_five_minutes_give_five_windows_and_the_carnet_threshold():
    t, x = _noise(300, seed=2)
    sp = spectrum(x, x, FS)
    assert sp.windows == 5 and sp.threshold == 0.34  # (3000 - 1000) / 500 + 1 windows of 100 s, 50 %


def test_incoherent_frequencies_are_left_out_of_gain_and_phase_but_not_of_coherence():
    t, x = _noise(300, seed=3)
    _, y = _noise(300, seed=4, mean=60.0)  # independent of x
    res, sp = tfa(Series(t, x, y, FS))
    left = ~sp.used & (sp.f > 0)
    wrapped = (sp.f < 0.1) & (np.angle(sp.H) < 0)  # the other reason to leave a frequency out
    assert np.all((sp.coherence[left] < 0.34) | wrapped[left])
    assert np.all(sp.coherence[sp.used] >= 0.34)
    assert sum(res["points_used"]) < sum(res["points"])  # the threshold bites
    for k in range(3):
        if res["points_used"][k] == 0:
            assert np.isnan(res["gain"][k]) and np.isnan(res["phase"][k])
        assert np.isfinite(res["coherence"][k]) and res["coherence"][k] < 0.6


def test_negative_low_frequency_phase_is_left_out_unless_kept():
    t, x = _noise(600, seed=5)
    b, a = _highpass(5.0, 0.8)
    y = 60.0 - lfilter(b, a, x - 90.0)  # an inverted high-pass: phase near -180 + lead, negative in VLF
    kept = spectrum(x, y, FS, keep_negative_phase=True)
    dropped = spectrum(x, y, FS)
    low = (kept.f >= 0.02) & (kept.f < 0.1)
    assert kept.used[low].all() and not dropped.used[low & (np.angle(kept.H) < 0)].any()


def test_beat_means_recover_the_mean_pressure_of_each_beat():
    fs, period = 200.0, 0.9
    t = np.arange(0, 60, 1 / fs)
    mean = 90 + 5 * np.sin(2 * np.pi * 0.05 * t)
    phase = (t % period) / period
    # an arterial pulse: a sharp systolic rise over a tenth of the beat, then a diastolic run-off
    shape = lambda ph: np.where(ph < 0.1, ph / 0.1, np.exp(-(ph - 0.1) / 0.35))  # noqa: E731
    fine = (np.arange(100_000) + 0.5) / 100_000
    pulse = 40 * (shape(phase) - shape(fine).mean())  # zero mean over a beat
    abp = mean + pulse
    mids, xm, ym = beat_means(t, abp, 0.5 * abp)
    assert len(mids) == pytest.approx(60 / period - 2, abs=1.5)
    assert np.diff(mids) == pytest.approx(period, rel=1e-2)
    # the beat mean is the slow pressure at mid-beat (a 0.05 Hz sine averaged over 0.9 s: within 0.1 %)
    np.testing.assert_allclose(xm, 90 + 5 * np.sin(2 * np.pi * 0.05 * mids), rtol=2e-3)
    np.testing.assert_allclose(ym, 0.5 * xm, rtol=1e-12)
    s = uniform_series(t, abp, 0.5 * abp, beats=True)
    assert s.fs == 10.0 and np.allclose(np.diff(s.t), 0.1) and "beat-to-beat means" in s.notes[0]


def test_irregular_times_are_interpolated_and_regular_ones_kept():
    t = np.cumsum(np.full(400, 0.8) + 0.1 * np.sin(np.arange(400)))  # beat-to-beat times
    s = uniform_series(t, np.sin(t / 10), np.cos(t / 10))
    assert s.fs == 10.0 and s.notes == ["interpolated linearly at 10 Hz"]
    np.testing.assert_allclose(s.x, np.interp(s.t, t, np.sin(t / 10)))
    r = uniform_series(np.arange(100) * 0.25, np.zeros(100), np.zeros(100))
    assert r.fs == 4.0 and r.notes == []


@pytest.fixture
def recording(tmp_path):
    t, x = _noise(400, seed=6)
    b, a = _highpass(8.0, 0.7)
    y = 55.0 + lfilter(b, a, x - 90.0)
    path = tmp_path / "rec.csv"
    with open(path, "w", newline="") as fh:  # a user's own file: plain header, no metadata
        w = csv.writer(fh)
        w.writerow(["time", "ABP", "CBFV"])
        w.writerows(zip(t, x, y))
    return path, t, x, y


def test_cli_writes_a_row_per_band_and_a_plot(recording, tmp_path, capsys):
    path, t, x, y = recording
    out, fig = tmp_path / "tfa.csv", tmp_path / "tfa.png"
    assert main(["tfa", str(path), "--input", "ABP", "--output", "CBFV", "--out", str(out), "--plot", str(fig)]) == 0
    text = capsys.readouterr().out
    assert "7 windows of 100 s, coherence threshold 0.25" in text  # (4000 - 1000) / 500 + 1
    back = Result.load(out)
    assert list(back["band"]) == ["VLF", "LF", "HF"]
    direct, _ = tfa(uniform_series(*read_series(path, "ABP", "CBFV")[:3]))
    np.testing.assert_allclose(back["gain"], direct["gain"], rtol=1e-12)
    assert back.metadata["settings"]["windows"] == 7 and fig.stat().st_size > 10_000


@pytest.mark.parametrize("argv, message", [
    (["--input", "ABp", "--output", "CBFV"], "--input 'ABp': "),
    (["--input", "ABP", "--output", "CBFV", "--window", "500"], "shorter than one 500 s window"),
    (["--input", "ABP", "--output", "CBFV", "--overlap", "1"], "--overlap 1.0: must be in [0, 1)"),
    (["--input", "ABP", "--output", "CBFV", "--time", "clock"], "--time 'clock': "),
])
def test_cli_errors_name_the_option(recording, capsys, argv, message):
    path = recording[0]
    assert main(["tfa", str(path)] + argv) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    if "ABp" in message:
        assert "did you mean 'ABP'" in err


def test_cli_refuses_non_finite_values_and_unordered_times(tmp_path, capsys):
    bad = tmp_path / "bad.csv"
    bad.write_text("time,ABP,CBFV\n0,90,60\n0.1,nan,60\n0.2,91,61\n")
    assert main(["tfa", str(bad), "--input", "ABP", "--output", "CBFV"]) == 2
    assert "--input 'ABP': 1 value(s) of" in capsys.readouterr().err
    back = tmp_path / "back.csv"
    back.write_text("time,ABP,CBFV\n0,90,60\n0.2,90,60\n0.1,91,61\n")
    assert main(["tfa", str(back), "--input", "ABP", "--output", "CBFV"]) == 2
    assert "must increase strictly (data row 3)" in capsys.readouterr().err


# ------------------------------------------------------------------ ARI (Tiecks) and Mx -------
def _cuff_release(fs=10.0, drop=20.0, t_rel=40.0):
    t = np.arange(0, 90, 1 / fs)
    return t, np.where(t < t_rel, 100.0, 100 - drop * np.exp(-(t - t_rel) / 8))


def test_tiecks_model_settles_at_its_closed_form_and_ari_0_is_passive():
    from hemocircuit.dca.ari import TIECKS, model_velocity
    dP = np.full(3000, -0.2)  # a held step, 300 s at 10 Hz
    for ari, (T, D, K) in TIECKS.items():
        v = model_velocity(dP, 10.0, ari, V0=60.0)
        # at rest x2 = dP, x1 = 2 D dP, so V = V0 (1 + (1 - K) dP)
        assert v[-1] == pytest.approx(60.0 * (1 - 0.2 * (1 - K)), rel=1e-9)
    np.testing.assert_allclose(model_velocity(dP, 10.0, 0), 0.8, rtol=1e-12)  # ARI 0: flow follows pressure


@pytest.mark.parametrize("true", [0.0, 2.0, 5.0, 7.3, 9.0])
def test_ari_recovers_the_model_that_made_the_response(true):
    from hemocircuit.dca.ari import fit_ari, model_velocity, release_time
    t, P = _cuff_release()
    V = model_velocity((P - 100.0) / (100.0 - 12.0), 10.0, true, 60.0)
    ari, grid, errors, _, _ = fit_ari(t, P, V, release_time(t, P))
    assert ari == pytest.approx(true, abs=1e-9) and errors.min() < 1e-20
    assert release_time(t, P) == pytest.approx(40.0, abs=0.5)


def test_mx_is_one_when_flow_follows_pressure_and_small_when_it_does_not():
    from hemocircuit.dca.mx import block_means, moving_correlation
    t, P = _noise(900, seed=7)
    starts, r = moving_correlation(t, P, 2.0 * P + 5.0)
    assert len(r) == 1 + (90 - 30) // 6 and np.allclose(r, 1.0)  # 90 blocks of 10 s, windows of 30, step 6
    _, other = _noise(900, seed=8, mean=60.0)
    _, r0 = moving_correlation(t, P, other)
    assert abs(np.mean(r0)) < 0.3
    s, m = block_means(np.arange(0, 30, 0.1), np.arange(300.0), 10.0)
    np.testing.assert_allclose(m, [49.5, 149.5, 249.5]) and np.testing.assert_allclose(s, [0, 10, 20])


def test_ari_and_mx_commands(tmp_path, capsys):
    from hemocircuit.dca.ari import model_velocity
    t, P = _cuff_release()
    V = model_velocity((P - 100.0) / (100.0 - 12.0), 10.0, 6.0, 55.0)
    path = tmp_path / "cuff.csv"
    Result({"time": t, "ABP": P, "CBFV": V}, {"time": "s", "ABP": "mmHg", "CBFV": "cm/s"}, index=["time"]).save(path)
    assert main(["ari", str(path), "--input", "ABP", "--output", "CBFV", "--out", str(tmp_path / "ari.json"),
                 "--plot", str(tmp_path / "ari.png")]) == 0
    assert "ARI 6.0 (release at 39.6 s, found" in capsys.readouterr().out
    assert Result.load(tmp_path / "ari.json").metadata["ari"] == 6.0
    assert main(["ari", str(path), "--input", "ABP", "--output", "CBFV", "--release", "85"]) == 2
    assert "needs 10 s before the release and 30 s after it" in capsys.readouterr().err
    t, P = _noise(600, seed=9)
    Result({"time": t, "ABP": P, "CBFV": 0.5 * P}, {}, index=["time"]).save(tmp_path / "mx.csv")
    assert main(["mx", str(tmp_path / "mx.csv"), "--input", "ABP", "--output", "CBFV"]) == 0
    assert "Mx 1.000 (6 windows of 300 s" in capsys.readouterr().out


def test_beat_means_of_a_steady_pulse_do_not_ripple():
    """A periodic pulse (period 0.857 s, not a multiple of the 10 ms sampling) has one mean; cut
    at the diastolic feet the beat means spread by 0.17 mmHg (0.2 %), where cutting at the
    upstrokes spread them by 0.79 mmHg, a ripple that shows in a cuff-release response."""
    period, t = 0.857, np.arange(0, 60, 0.01)
    shape = lambda ph: np.where(ph < 0.1, ph / 0.1, np.exp(-(ph - 0.1) / 0.35))  # noqa: E731
    abp = 90 + 40 * (shape((t % period) / period) - shape((np.arange(100_000) + 0.5) / 100_000).mean())
    _, xm, _ = beat_means(t, abp, abp)
    assert np.ptp(xm) < 0.25 and np.mean(xm) == pytest.approx(90.0, abs=0.1)


# ------------------------------------------------------------------ acceptance: known filters -
def _series_at(fs, seconds, seed, sd=3.0):
    rng = np.random.default_rng(seed)
    t = np.arange(0, seconds, 1 / fs)
    return t, 90 + sd * lfilter(*butter(2, min(0.5, 0.45 * fs / 2), fs=fs), rng.standard_normal(t.size))


@pytest.mark.parametrize("fs", [4.0, 10.0, 25.0, 100.0])
def test_high_pass_and_delay_recovered_at_every_sampling_rate(fs):
    """A first-order high-pass (tau 2 s, corner 0.08 Hz, gain 0.8) followed by a pure delay of
    0.6 s: band gain within 2 % and phase within 2 deg of the filter's own response, at 4-100 Hz
    (measured: 1.2 %, 1.2 deg at worst).  A windowed estimate is biased by about the system's
    time constant over the window: tau 3 s gives 1.6 %, tau 5 s 2.1 % in VLF with 100 s windows."""
    t, x = _series_at(fs, 900, seed=11)
    b, a = bilinear([2.0, 0.0], [2.0, 1.0], fs)
    d = int(round(0.6 * fs))
    y = 60 + np.concatenate([np.zeros(d), 0.8 * lfilter(b, a, x - 90)[:-d]])
    sp = spectrum(x[d:], y[d:], fs)
    _, h = freqz(0.8 * b, a, worN=2 * np.pi * sp.f / fs)
    h = h * np.exp(-2j * np.pi * sp.f * d / fs)
    for lo, hi in ((0.02, 0.07), (0.07, 0.2), (0.2, 0.5)):
        band = (sp.f >= lo) & (sp.f < hi) & sp.used
        assert band.sum() >= 3
        assert np.mean(sp.gain[band]) == pytest.approx(np.mean(np.abs(h[band])), rel=0.02)
        assert np.degrees(np.mean(np.angle(sp.H[band]))) == pytest.approx(np.degrees(np.mean(np.angle(h[band]))),
                                                                         abs=2.0)


@pytest.mark.parametrize("coherence", [0.5, 0.8])
def test_output_noise_at_a_chosen_coherence(coherence):
    """y = x + e, e independent with the spectrum of x scaled so that the true coherence is
    the chosen one in every band: estimated coherence within 0.05, gain within 2 % of 1."""
    fs = 10.0
    t, x = _series_at(fs, 3600, seed=12)
    _, e = _series_at(fs, 3600, seed=13)
    y = 60 + (x - 90) + np.sqrt(1 / coherence - 1) * (e - 90)
    res, sp = tfa(Series(t, x, y, fs), smoothing=1)
    for k in range(3):
        assert res["coherence"][k] == pytest.approx(coherence, abs=0.05)
        assert res["gain"][k] == pytest.approx(1.0, rel=0.02 if coherence > 0.6 else 0.05)


@pytest.mark.parametrize("text, message", [
    ("time;ABP;CBFV\n0;90;60\n0.1;91;61\n", "separate the columns with commas"),
    ("time,ABP,ABP\n0,90,60\n0.1,91,61\n", "column 'ABP' appears twice in the header"),
    ("time,ABP,CBFV\n0,90,60\n0.1,91\n", "data row 2 has 2 cells, the header 3"),
    ("", "no table"),
])
def test_odd_recordings_get_clear_errors(tmp_path, capsys, text, message):
    path = tmp_path / "rec.csv"
    path.write_text(text)
    assert main(["tfa", str(path), "--input", "ABP", "--output", "CBFV"]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err


def test_a_header_with_spaces_and_units_is_read(tmp_path):
    path = tmp_path / "rec.csv"
    t, x = _series_at(10.0, 300, seed=14)
    with open(path, "w") as fh:
        fh.write("Time [s], ABP [mmHg] , CBFV [cm/s]\n")
        fh.writelines(f"{a},{b},{0.5 * b}\n" for a, b in zip(t, x))
    t2, x2, y2, names, units = read_series(path, "ABP", "CBFV", time="Time")
    assert units == ("mmHg", "cm/s") and np.allclose(y2, 0.5 * x2) and len(t2) == len(t)
