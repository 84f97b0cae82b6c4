"""Acceptance tests of issue 5's dynamics analyses: AC against the nonlinear frequency response,
the thesis's frequency-response numbers (arterial_compliance), identical results on every
executor, per-member failure recording, the vasomotion envelope, limit cycles and forced
periodic steady states by shooting.

Kept cheap (the machine has 2 shared cores): small frequency sets, short runs, module fixtures
shared between tests, scheduler='serial' except where executors are under test.  Measured
values (for the record; see the asserts for the accepted bands):

  AC vs nonlinear (1 % sine, no step), 0.005-1 Hz: gain within 0.01 %, phase within 0.06 deg.
  Nonlinear 10 % + 10 %, Pa = 80, tau_Ca = 1 s: q2 relative amplitude peaks at 0.12 Hz on the
    grid 0.01..1 Hz (0.1436; 0.1425 at 0.1 Hz); at 0.1 Hz q1 leads by 25.9 deg, q2 by 20.6 deg;
    maximum lead (low band) q1 63.9 deg, q2 62.3 deg, at 0.02 Hz.
  tau_Ca = 10 s: the peak moves to ~0.03 Hz and grows to 0.314.
  Pa = 30 mmHg: q2 flat (0.135..0.152 over 0.01..1 Hz, max/min 1.12; AC 1.38..1.51).
  |q1| at 1 Hz: 0.398 (Pa = 30) / 0.180 (Pa = 80) = 2.21 (AC: 4.43 / 1.99 = 2.22).
  Vasomotion, Pa = 80: r 60.68..101.95-102.07 um (sampled at dt = 0.1 s; the orbit's true max,
    at a 2 ms jump when Ca leaves its floor, is 102.17 um) around 76.46 um, period 7.71 s,
    mean Q 9.3-9.6 > steady 7.47 mL/s; zeta = 0.5: steady.  Shooting: period 7.7126 s,
    non-trivial Floquet multipliers |mu| <= 0.688.
"""
from __future__ import annotations

import os

import numpy as np
import pytest

import hemocircuit as hc
from hemocircuit.analyses.ac import ac_response
from hemocircuit.analyses.envelope import envelope
from hemocircuit.analyses.freq import _dft, frequency_response
from hemocircuit.analyses.op import operating_point
from hemocircuit.analyses.periodic import guess_from_run, shoot
from hemocircuit.batch_integrator import integrate
from hemocircuit.execution import run_chunks, split

from paths import ROOT

NETS = ROOT / "netlists"
Q1, Q2 = "Q(Rla)", "Q(Rsv)"

pytestmark = pytest.mark.filterwarnings("ignore::RuntimeWarning")


@pytest.fixture(scope="module")
def artc():
    return hc.load(NETS / "arterial_compliance.yaml")


@pytest.fixture(scope="module")
def vaso():
    return hc.load(NETS / "vasomotion.yaml")


def pick(res, output, f=None, **grid):
    """Runs of one output (and grid point) of a FreqResult, sorted by frequency, as dicts
    {rel_amplitude, rel_gain, gain, phase, thd, steady, mean: that output's columns; frequency,
    periods, settled, error, grid values}; or the single run at f."""
    per_output = {q: f"{q}({output})" for q in ("rel_amplitude", "thd", "steady", "mean")}
    per_output.update({q: f"{q}({output}/{res.input})" for q in ("rel_gain", "gain", "phase")})
    rs = [{**{q: r[c] for q, c in per_output.items()}, **{k: r[k] for k in ("frequency", "periods", "settled", "error")},
           **{k: r[k] for k in res.index}}
          for r in res.rows() if all(np.isclose(r[k], v) for k, v in grid.items())]
    rs.sort(key=lambda r: r["frequency"])
    if f is None:
        return rs
    (r,) = [r for r in rs if np.isclose(r["frequency"], f)]
    return r


def series(res, output, key, **grid):
    rs = pick(res, output, **grid)
    return np.array([r["frequency"] for r in rs]), np.array([r[key] for r in rs])


# ------------------------------------------------------------ 1. AC = small-signal limit --------
def test_ac_matches_nonlinear_frequency_response_at_small_amplitude(artc):
    freqs = [0.005, 0.05, 0.1, 0.5, 1.0]
    ac = ac_response(artc, "Pa", [Q1, Q2], freqs)
    rows = frequency_response(artc, freqs, [Q1, Q2], step=0.0, amplitude=0.01, scheduler="serial")
    assert not any(rows["error"])
    for o in (Q1, Q2):
        f, gain = series(rows, o, "rel_gain")
        _, phase = series(rows, o, "phase")
        np.testing.assert_allclose(f, freqs)
        assert all(rows["settled"])
        np.testing.assert_allclose(gain, ac.rel_gain[o], rtol=0.02, err_msg=o)
        # arg difference, wrapped (AC phase is unwrapped along frequency, the batch's is not)
        dphi = (phase - ac.phase[o] + 180.0) % 360.0 - 180.0
        assert np.max(np.abs(dphi)) < 2.0, (o, phase, ac.phase[o])


# ------------------------------------------------------------ 2. thesis numbers ----------------
F_NL = [0.01, 0.02, 0.04, 0.07, 0.1, 0.12, 0.2, 0.4, 1.0]


@pytest.fixture(scope="module")
def nl_pa(artc):
    """Thesis forcing (10 % step + 10 % sine), tau_Ca = 1 s, Pa = 30 and 80 mmHg: one batch."""
    rows = frequency_response(artc, F_NL, [Q1, Q2], step=0.1, amplitude=0.1,
                              grid=[("Pa.value", [30.0, 80.0])], scheduler="serial")
    assert not any(rows["error"])
    return rows


@pytest.fixture(scope="module")
def ac_cases(artc):
    f = np.logspace(-3, 0, 121)
    out = {}
    for name, sets in (("80", {}), ("tau10", {"art.tau_Ca": 10.0}), ("30", {"Pa.value": 30.0})):
        c = artc
        if sets:
            c = c.with_values(sets)
        out[name] = ac_response(c, "Pa", [Q1, Q2], f)
    return out


def test_resonance_of_q2_between_008_and_014_hz(nl_pa, ac_cases):
    f, amp = series(nl_pa, Q2, "rel_amplitude", **{"Pa.value": 80.0})
    k = int(np.argmax(amp))
    assert 0.08 <= f[k] <= 0.14, (f[k], amp)
    assert 0 < k < len(f) - 1  # an interior maximum: a resonance, not an edge
    assert amp[k] > 1.5 * amp[0]
    ac = ac_cases["80"]
    kac = int(np.argmax(ac.rel_gain[Q2]))
    assert 0.08 <= ac.freq[kac] <= 0.14  # linear: 1.53 at 0.115 Hz


def test_flow_leads_pa_by_20_to_35_deg_at_01_hz(nl_pa, ac_cases):
    # measured: q1 +25.9 deg, q2 +20.6 deg (nonlinear); AC +25.6 / +20.0.  Both inside the
    # thesis band; q2 only just (0.6 deg), q1 comfortably.
    for o in (Q1, Q2):
        ph = pick(nl_pa, o, 0.1, **{"Pa.value": 80.0})["phase"]
        assert 20.0 <= ph <= 35.0, (o, ph)


def test_maximum_lead_55_to_75_deg_in_the_low_band(nl_pa, ac_cases):
    for o in (Q1, Q2):
        f, ph = series(nl_pa, o, "phase", **{"Pa.value": 80.0})
        low = f <= 0.1
        k = int(np.argmax(ph[low]))
        assert 55.0 <= ph[low][k] <= 75.0, (o, f[low], ph[low])
        assert 0 < k < np.count_nonzero(low) - 1  # interior: the band brackets the maximum
    ac = ac_cases["80"]
    assert 55.0 <= np.max(ac.phase[Q1]) <= 75.0  # linear: 60 deg near 0.02 Hz


def test_slower_calcium_moves_the_peak_lower_and_raises_it(artc, nl_pa, ac_cases):
    # rtol 1e-7 (not the default 1e-8): 2x faster, amplitudes unchanged to 5 digits
    rows = frequency_response(artc, [0.02, 0.03, 0.045], [Q2], step=0.1, amplitude=0.1, rtol=1e-7,
                              grid=[("art.tau_Ca", [10.0])], scheduler="serial")
    assert all(rows["settled"]) and not any(rows["error"])
    f10, a10 = series(rows, Q2, "rel_amplitude")
    f1, a1 = series(nl_pa, Q2, "rel_amplitude", **{"Pa.value": 80.0})
    k = int(np.argmax(a10))
    assert k == 1, (f10, a10)  # interior maximum near 0.03 Hz
    assert f10[k] < f1[np.argmax(a1)]
    assert a10[k] > 1.5 * a1.max()
    # linear (AC, dense grid): the same shift
    g1, g10 = ac_cases["80"].rel_gain[Q2], ac_cases["tau10"].rel_gain[Q2]
    fa = ac_cases["80"].freq
    assert fa[np.argmax(g10)] < 0.6 * fa[np.argmax(g1)]
    assert g10.max() > 1.5 * g1.max()


def test_no_peak_at_30_mmhg(nl_pa, ac_cases):
    # 'no peak': q2's relative amplitude is flat over 0.01-1 Hz (within 20 %), against a factor
    # ~6 and a resonance at 80 mmHg.  (It is not strictly monotone: a 1 % rise to 0.1 Hz.)
    _, a30 = series(nl_pa, Q2, "rel_amplitude", **{"Pa.value": 30.0})
    _, a80 = series(nl_pa, Q2, "rel_amplitude", **{"Pa.value": 80.0})
    assert a30.max() / a30.min() < 1.2, a30
    assert a80.max() / a80.min() > 3.0
    g = ac_cases["30"].rel_gain[Q2]
    assert g.max() / g.min() < 1.2


def test_q1_at_1hz_about_twice_as_large_at_30_as_at_80_mmhg(nl_pa, ac_cases):
    a30 = pick(nl_pa, Q1, 1.0, **{"Pa.value": 30.0})["rel_amplitude"]
    a80 = pick(nl_pa, Q1, 1.0, **{"Pa.value": 80.0})["rel_amplitude"]
    assert 1.6 <= a30 / a80 <= 2.6, (a30, a80)
    r_ac = ac_cases["30"].rel_gain[Q1][-1] / ac_cases["80"].rel_gain[Q1][-1]
    assert 1.6 <= r_ac <= 2.6


def test_settle_detection_is_not_fooled_by_a_slow_drift(artc, nl_pa):
    """The frequency response at Pa = 30 mmHg, 1 Hz (10 % step) against the exact periodic steady
    state from forced shooting.  The settle test compares the fundamental of two consecutive
    periods; a slow mode (-0.048 /s, time constant 21 s) drifts the mean during the first
    4 periods, leaks about the same amount into both periods' fundamental, and passes the test:
    the batch stops after 4 periods with q2 at 0.13690 against 0.13583 (+0.79 %), q1 at 0.39838
    against 0.39795 (+0.11 %), well above the 1e-3 settle tolerance for q2.  (With
    settle_tol = 1e-12 and 60 periods the batch gives 0.135827, the shooting value.)"""
    c = artc.with_values({"Pa.value": 30.0})
    op = operating_point(c)
    c = c.with_values({"Pa.value": 33.0})
    c = c.with_values({"Pa.amplitude": 3.0})
    c = c.with_values({"Pa.frequency": 1.0})
    orb = shoot(c, op.x, 1.0, forced=True, rtol=1e-8, tol=1e-7)
    assert orb.converged
    n = len(orb.t) - 1
    assert abs(abs(_dft(orb.columns["P(in)"][:n], n, 1)) - 3.0) < 1e-6
    for o in (Q1, Q2):
        exact = abs(_dft(orb.columns[o][:n], n, 1)) / abs(op.values[o])
        got = pick(nl_pa, o, 1.0, **{"Pa.value": 30.0})["rel_amplitude"]
        assert abs(got / exact - 1) <= 2e-3, (o, got, exact)


# ------------------------------------------------------------ 3. executors ---------------------
def _small_batch(artc, **kw):
    return frequency_response(artc, [0.2, 0.5, 1.0], [Q1, Q2], step=0.0, amplitude=0.05, rtol=1e-6,
                              grid=[("art.tau_Ca", [1.0, 2.0])], **kw)


def _assert_same_rows(a, b):
    assert a.n_rows == b.n_rows and list(a.keys()) == list(b.keys())
    assert not any(a["error"]) and not any(b["error"])
    for k, col in a.items():
        if col.dtype.kind == "f":
            np.testing.assert_allclose(b[k], col, rtol=1e-12, atol=0, err_msg=k)
        else:
            assert list(b[k]) == list(col), k


@pytest.fixture(scope="module")
def serial_batch(artc):
    return _small_batch(artc, scheduler="serial")


def test_local_processes_give_identical_numbers(artc, serial_batch):
    _assert_same_rows(serial_batch, _small_batch(artc, scheduler="processes", workers=2))


def test_dask_local_cluster_gives_identical_numbers(artc):
    """The Dask path end to end on a local cluster of two worker processes (the chunks are
    pickled to them, as on a real cluster): numbers identical to the serial run.  Two members,
    one chunk per worker, to stay quick (worker start-up dominates).  CI installs the
    'distributed' extra, so this runs there."""
    distributed = pytest.importorskip("dask.distributed")

    def batch(**kw):
        return frequency_response(artc, [0.5], [Q1, Q2], step=0.0, amplitude=0.05, rtol=1e-6,
                                  grid=[("art.tau_Ca", [1.0, 2.0])], workers=2, **kw)

    serial = batch(scheduler="serial")
    with distributed.LocalCluster(n_workers=2, processes=True, threads_per_worker=1, dashboard_address=None) \
            as cluster, distributed.Client(cluster) as client:
        assert len(client.scheduler_info()["workers"]) == 2
        rows = batch(scheduler=client)
    _assert_same_rows(serial, rows)


def test_member_trajectory_does_not_depend_on_its_batch_companions(vaso):
    """execution.py: 'A member's numbers do not depend on which chunk or executor ran it'.  Two
    vasomotion members that both reach the Ca floor (second-order Ca), together and alone."""
    x = np.array(operating_point(vaso).x, float).reshape(-1)
    b = vaso.batch(2)
    b = b.with_values({"art.zeta": np.array([0.1, 0.2])})
    i = vaso.state_names.index("art.dCa")
    x0 = np.repeat(x[None], 2, axis=0)
    x0[0, i], x0[1, i] = -5 * vaso.state_scales[i], -8 * vaso.state_scales[i]
    grid = np.linspace(0.0, 10.0, 101)
    together = integrate(b, x0, grid, rtol=1e-6, atol=1e-6)
    assert together.ok.all()
    for k in range(2):
        alone = integrate(b.subset([k]), x0[k:k + 1], grid, rtol=1e-6, atol=1e-6)
        diff = np.max(np.abs(alone.x[0] - together.x[k]) / vaso.state_scales)
        assert diff <= 1e-12, (k, diff)  # measured: 5.9e-8 and 1.5e-4


# ------------------------------------------------------------ 4. failures ----------------------
BAD_PA = -500.0  # mmHg: the operating point fails cleanly (SolverError, Newton + fallbacks)


def _check_failure_rows(res):
    good = [r for r in res.rows() if r["Pa.value"] == 80.0]
    bad = [r for r in res.rows() if r["Pa.value"] == BAD_PA]
    assert len(good) == len(bad) == 1  # one row per run, every output in it
    for r in bad:
        assert "operating point" in r["error"] and "no operating point found" in r["error"], r
        assert np.isnan(r[f"rel_gain({Q1}/Pa.value)"])
    for r in good:
        assert r["error"] == "", r["error"]
        for o in (Q1, Q2):
            assert 1.0 < r[f"rel_gain({o}/Pa.value)"] < 2.5
    assert len(res.metadata["failed"]) == 1


def test_failing_member_recorded_others_complete_with_worker_processes(artc):
    # two chunks (one per member): the failure stays in its chunk
    rows = frequency_response(artc, [1.0], [Q1, Q2], step=0.0, amplitude=0.05, rtol=1e-6,
                              grid=[("Pa.value", [80.0, BAD_PA])], scheduler="processes", workers=2)
    _check_failure_rows(rows)


def test_failing_member_recorded_others_complete_in_one_chunk(artc):
    rows = frequency_response(artc, [1.0], [Q1, Q2], step=0.0, amplitude=0.05, rtol=1e-6,
                              grid=[("Pa.value", [80.0, BAD_PA])], scheduler="serial")
    _check_failure_rows(rows)


def test_block_outputs_equal_member_by_member_outputs(artc):
    """freq evaluates a block's outputs for all its members in one stacked call (member-major
    rows, each member's parameters repeated): every column equals the member's own
    evaluation, with members whose parameters and times differ."""
    from hemocircuit.analyses.freq import _block_outputs, _member_columns

    bc = artc.batch(3).with_values({"Pa.value": np.array([60.0, 80.0, 100.0]),
                                    "Pa.amplitude": np.array([0.0, 8.0, 10.0]),
                                    "Pa.frequency": np.array([0.1, 0.2, 0.5])})
    X0 = np.asarray(operating_point(bc).x, float)
    W = 5
    T = np.array([np.linspace(0.0, 2.0, W), np.linspace(1.0, 3.0, W), np.linspace(0.3, 0.9, W)])
    X = np.repeat(X0[:, None, :], W, axis=1) * (1.0 + 1e-3 * np.arange(W))[None, :, None]
    js = [0, 2]  # a subset, as when member 1 failed
    cols = _block_outputs(bc, js, T[js], X[js])
    for i, j in enumerate(js):
        own = _member_columns(bc, j, T[j], X[j])
        assert set(own) == set(cols)
        for name, v in own.items():
            np.testing.assert_array_equal(cols[name][i], np.broadcast_to(v, (W,)), err_msg=name)
    # the members differ (Pa 60 and 100 mmHg): a mix-up of their rows would show
    assert np.all(cols[Q1][1] > 1.2 * cols[Q1][0])


def test_freq_member_by_member_fallback_gives_the_same_rows(artc, monkeypatch):
    """When a block's stacked output evaluation raises (some member's outputs cannot be
    evaluated), each member is evaluated alone: the rows are those of the stacked path."""
    import hemocircuit.analyses.freq as freq
    from hemocircuit.errors import HemocircuitError

    kw = dict(outputs=[Q1, Q2], grid=[("Pa.value", [70.0, 90.0])], rtol=1e-6, scheduler="serial")
    stacked = frequency_response(artc, [0.05, 0.5], **kw)

    def refuse(*a, **k):
        raise HemocircuitError("not in one block")

    monkeypatch.setattr(freq, "_block_outputs", refuse)
    alone = frequency_response(artc, [0.05, 0.5], **kw)
    for key in stacked.keys():
        if key != "error":
            np.testing.assert_array_equal(np.asarray(stacked[key]), np.asarray(alone[key]), err_msg=key)


_WARMED = []


def _set_warm():
    _WARMED.append(os.getpid())


def _report_warm(chunk):
    return [(v, list(_WARMED)) for v in chunk]


def _fail_warm():
    raise RuntimeError("warm-up failed")


@pytest.mark.skipif(not hasattr(os, "fork"), reason="workers inherit the warm-up only when forked")
def test_run_chunks_warms_up_once_before_forking_the_workers():
    """``warm`` runs once, in this process, before the workers fork: they inherit its effect
    (here a list, for the compiled integrator its loaded code).  A failing warm-up is only a
    lost head start: the chunks still run."""
    _WARMED.clear()
    out = run_chunks(_report_warm, [[1], [2], [3]], scheduler="processes", workers=2, warm=_set_warm)
    assert [r for c in out for r in c] == [(1, [os.getpid()]), (2, [os.getpid()]), (3, [os.getpid()])]
    _WARMED.clear()
    assert run_chunks(_report_warm, [[1], [2]], scheduler="processes", workers=2, warm=_fail_warm) \
        == [[(1, [])], [(2, [])]]


def test_split_contiguous_or_interleaved():
    assert split(list(range(7)), 3) == [[0, 1], [2, 3, 4], [5, 6]]
    assert split(list(range(7)), 3, interleave=True) == [[0, 3, 6], [1, 4], [2, 5]]
    assert split([1, 2], 5, interleave=True) == [[1], [2]] and split([], 3, interleave=True) == []


def test_distinct_members_of_a_batch(artc):
    from hemocircuit.batch import distinct_members

    bc = artc.batch(5).with_values({"art.tau_Ca": np.array([2.0, 1.0, 2.0, 3.0, 1.0])})
    first, inverse = distinct_members(bc)
    assert first.tolist() == [0, 1, 3] and inverse.tolist() == [0, 1, 0, 2, 1]
    assert [k.tolist() for k in distinct_members(artc)] == [[0], [0]]


def test_frequencies_of_a_grid_point_share_one_operating_point(artc, monkeypatch):
    """The baseline operating point is solved once per grid point (in the calling process),
    not once per frequency: 2 x 2 runs, one solve of 2 members."""
    import hemocircuit.analyses.op as op_mod

    sizes, real = [], op_mod.operating_points
    monkeypatch.setattr(op_mod, "operating_points", lambda c, *a, **k: sizes.append(c.B) or real(c, *a, **k))
    rows = frequency_response(artc, [0.5, 1.0], [Q1], step=0.0, amplitude=0.05, rtol=1e-6,
                              grid=[("art.tau_Ca", [1.0, 2.0])], scheduler="processes", workers=2)
    assert sizes == [2] and not any(rows["error"])
    steady = operating_point(artc).values[Q1]
    np.testing.assert_allclose(rows[f"steady({Q1})"], steady, rtol=1e-12)


def test_envelope_members_keep_their_own_operating_point_in_interleaved_chunks(artc):
    """Operating points solved for the whole batch, members spread over interleaved chunks on
    worker processes: each row's steady value is its own member's operating point."""
    pas = [60.0, 70.0, 80.0, 90.0, 100.0]
    res = envelope(artc, ("Pa.value", pas), outputs=[Q1], t_end=2.0, dt=0.5, scheduler="processes", workers=2)
    assert not any(res["error"])
    for pa, q in zip(res["Pa.value"], res[f"steady({Q1})"]):
        assert q == pytest.approx(operating_point(artc.with_values({"Pa.value": pa})).values[Q1], rel=1e-9)
    assert len(set(np.round(res[f"steady({Q1})"], 9))) == len(pas)


def test_envelope_warm_up_loads_what_the_summaries_use_before_the_workers_fork(artc, monkeypatch):
    """The envelope's warm-up (run in this process before the workers fork) integrates a chunk
    for zero time and evaluates a summary's outputs on the compiled path (at least
    COMPILED_OUTPUT_ROWS rows of one member): without the outputs every forked worker loaded the
    compiled nodal outputs from numba's cache before its first summary (~0.08 s each)."""
    import hemocircuit.analyses.envelope as env_mod
    from hemocircuit.system.outputs import COMPILED_OUTPUT_ROWS, Outputs

    warms, rows = [], []
    monkeypatch.setattr(env_mod, "run_chunks", lambda fn, jobs, warm=None, **kw: warms.append(warm)
                        or [fn(j) for j in jobs])
    res = envelope(artc, ("Pa.value", [70.0, 90.0]), outputs=[Q1], t_end=2.0, dt=0.5, workers=2)
    assert not any(res["error"]) and len(warms) == 1 and warms[0] is not None
    real = Outputs.outputs
    monkeypatch.setattr(Outputs, "outputs", lambda self, t, x, *a, **k: rows.append((self.B, len(x)))
                        or real(self, t, x, *a, **k))
    warms[0]()
    assert rows == [(1, COMPILED_OUTPUT_ROWS)]


def test_no_member_with_an_operating_point_gives_failed_rows_on_worker_processes(artc):
    """Every member fails before integrating: nothing is left to run, the rows say why."""
    res = frequency_response(artc, [1.0], [Q1], step=0.0, amplitude=0.05, rtol=1e-6,
                             grid=[("Pa.value", [BAD_PA, 2 * BAD_PA])], scheduler="processes", workers=2)
    env = envelope(artc, ("Pa.value", [BAD_PA, 2 * BAD_PA]), outputs=[Q1], t_end=2.0, scheduler="processes",
                   workers=2)
    for r in (res, env):
        assert r.metadata["status"] == "partial" and len(r.metadata["failed"]) == 2
        assert all("no operating point found" in e for e in r["error"])


def test_run_chunks_propagates_an_exception_from_a_chunk():
    """The executor layer itself does not catch: per-member failure recording lives inside the
    analyses' chunk functions (freq, envelope), which return error rows instead of raising."""
    def fn(chunk):
        if 3 in chunk:
            raise ValueError("boom")
        return [2 * v for v in chunk]

    assert run_chunks(fn, [[1, 2], [4]], scheduler="serial") == [[2, 4], [8]]
    with pytest.raises(ValueError, match="boom"):
        run_chunks(fn, [[1, 2], [3], [4]], scheduler="serial")


# ------------------------------------------------------------ 5. envelope ----------------------
@pytest.fixture(scope="module")
def vaso_env(vaso):
    # the instability grows at +0.067 /s: from the 1e-3 kick the cycle is full-size after
    # ~100 s; window = last 30 % (168-240 s).  t_end 200/250/300/400 s give the same min/max
    # within 0.15 um.
    res = envelope(vaso, ("art.zeta", [0.1, 0.5]), outputs=["art.r", Q1], t_end=240.0, dt=0.1, rtol=1e-5,
                   keep_series=["art.r"], scheduler="serial")
    assert not any(res["error"])
    return {r["art.zeta"]: {**r, "series": s} for r, s in zip(res.rows(), res.series)}


def test_vasomotion_limit_cycle_envelope(vaso_env):
    r = vaso_env[0.1]
    assert r["oscillating"]
    assert 57.0 <= r["min(art.r)"] <= 64.0, r["min(art.r)"]
    assert 99.0 <= r["max(art.r)"] <= 106.0, r["max(art.r)"]
    assert 76.0 <= r["steady(art.r)"] <= 78.0, r["steady(art.r)"]
    assert 7.0 <= r["period"] <= 9.0, r["period"]
    assert r[f"mean({Q1})"] > 1.1 * r[f"steady({Q1})"]  # oscillation raises the mean flow
    # the limit cycle has been reached: both halves of the window have the same range
    y = r["series"]["art.r"]
    h = len(y) // 2
    assert abs(y[:h].min() - y[h:].min()) < 0.3 and abs(y[:h].max() - y[h:].max()) < 0.5


def test_more_damping_removes_the_oscillation(vaso_env):
    r = vaso_env[0.5]
    assert not r["oscillating"]
    assert np.isnan(r["period"])
    assert r["max(art.r)"] - r["min(art.r)"] < 1e-3
    assert r["mean(art.r)"] == pytest.approx(r["steady(art.r)"], abs=1e-3)


def test_envelope_checks_the_settling_run_too(tmp_path):
    """The statistics read the window (the last 30 %), but plausibility covers the whole run:
    a source pressure beyond 1e4 mmHg from 1.5 to 3 s of 20 (long before the window, at
    the settling part's coarser output times) is reported for the member it happens in."""
    (tmp_path / "spike.yaml").write_text(
        "name: spike\nelements:\n"
        "  - {id: Ps, type: pressure_source, nodes: [in, ground], value: {pwl: [[0 s, 80 mmHg], [1 s, 80 mmHg],"
        " [1.5 s, 2e4 mmHg], [3 s, 2e4 mmHg], [3.5 s, 80 mmHg], [20 s, 80 mmHg]]}}\n"
        "  - {id: R1, type: resistor, nodes: [in, a], R: 2 mmHg*s/mL}\n"
        "  - {id: C1, type: compliance, nodes: [a, ground], C: 0.5 mL/mmHg}\n")
    c = hc.load(str(tmp_path / "spike.yaml"))
    res = envelope(c, ("R1.R", [2.0, 4.0]), outputs=["P(a)"], t_end=20.0, dt=0.1, scheduler="serial")
    assert not any(res["error"])
    assert np.all(res["max(P(a))"] < 1e3)  # the window (14-20 s) has settled near 80 mmHg
    warned = res.metadata.get("warnings", [])
    for member in ("R1.R=2.0", "R1.R=4.0"):
        assert any(w.startswith(member) and "P(in)" in w and "beyond" in w for w in warned), warned


# ------------------------------------------------------------ 6. periodic orbits ---------------
def test_shooting_converges_on_the_vasomotion_limit_cycle(vaso, vaso_env):
    x, T = guess_from_run(vaso, "art.r", t_settle=300.0, rtol=1e-5)
    orb = shoot(vaso, x, T, rtol=1e-7, tol=1e-6)
    env = vaso_env[0.1]
    assert orb.converged
    assert orb.period == pytest.approx(env["period"], rel=0.02)
    r = orb.columns["art.r"]
    assert abs(r.min() - env["min(art.r)"]) < 1.0
    assert abs(r.max() - env["max(art.r)"]) < 1.0
    # orbital stability: the flow direction and the ICP conservation law give multipliers ~1;
    # the others lie inside the unit circle (measured: |mu| <= 0.688)
    assert len(orb.nontrivial_multipliers) == vaso.nx - 2
    assert np.all(np.abs(orb.nontrivial_multipliers) < 1.0)
    assert orb.stable
    # the time-averaged flow over the exact cycle exceeds the steady flow
    assert orb.columns[Q1][:-1].mean() > env[f"steady({Q1})"]
    # phi_T(x0) = x0 with an independent integrator (LSODA)
    res = vaso.simulate(orb.period, dt=orb.period / 50, x0=orb.x0, method="LSODA", rtol=1e-9, atol=1e-9)
    assert np.max(np.abs(res.x[-1] - orb.x0) / vaso.state_scales) < 1e-3


def test_forced_periodic_steady_state_matches_the_frequency_response(artc, nl_pa):
    """Pa = 88 + 8 sin(2 pi 0.1 t) mmHg = the thesis forcing (10 % step + 10 % sine of 80 mmHg):
    shooting from the 80 mmHg operating point gives the periodic steady state directly."""
    x_op = operating_point(artc).x
    c = artc.with_values({"Pa.value": 88.0})
    c = c.with_values({"Pa.amplitude": 8.0})
    c = c.with_values({"Pa.frequency": 0.1})
    orb = shoot(c, x_op, 10.0, forced=True, rtol=1e-8, tol=1e-7)
    assert orb.converged and orb.period == 10.0
    assert orb.stable  # a stable equilibrium forced: every multiplier inside (|mu| <= 0.62)
    res = c.simulate(10.0, dt=0.5, x0=orb.x0, method="LSODA", rtol=1e-10, atol=1e-10)
    assert np.max(np.abs(res.x[-1] - orb.x0) / c.state_scales) < 1e-5  # phi_T(x0) = x0
    n = len(orb.t) - 1
    X1 = _dft(orb.columns["P(in)"][:n], n, 1)
    for o in (Q1, Q2):
        H_orb = _dft(orb.columns[o][:n], n, 1) / X1
        row = pick(nl_pa, o, 0.1, **{"Pa.value": 80.0})
        H_fr = row["gain"] * np.exp(1j * np.radians(row["phase"]))
        assert abs(H_orb - H_fr) <= 0.01 * abs(H_fr), (o, H_orb, H_fr)


def test_numpy_output_keeps_limited_states_on_their_bound():
    """The numpy batch integrator's dense output (batch_integrator._emit): between two steps on
    a bound (x = 0 at both ends, slopes -1 and +1 over 1 s) the cubic Hermite dips to -0.25 at
    the midpoint; a state with a hard limit there is written on its bound, another state is not."""
    from hemocircuit.batch_integrator import _emit

    t_out = np.array([[0.0, 0.5, 1.0]])
    x0, f0 = np.zeros((1, 2)), np.array([[-1.0, -1.0]])
    x1, f1 = np.zeros((1, 2)), np.array([[1.0, 1.0]])

    def emit(**limits):
        out = np.full((1, 3, 2), np.nan)
        _emit(out, t_out, np.array([1]), np.array([0]), np.zeros(1), x0, f0, np.ones(1), x1, f1, **limits)
        return out[0]

    out = emit(limits=[(0, 0.0, None)])
    assert out[1].tolist() == [0.0, -0.25] and out[2].tolist() == [0.0, 0.0]
    assert emit()[1].tolist() == [-0.25, -0.25]


def test_every_engine_gives_the_requested_grid_across_a_hard_limit(tmp_path):
    """Through the second-order Ca's floor (a hard-limit event at ~35.5 s, MODEL_NOTES) the
    scipy path and the compiled engine return the same output times, the requested grid, and
    agree on the trajectory: a measure on the result (a period from interpolated crossings)
    then does not depend on the engine.  The scipy path used to add the event's time to the
    output, which moved vasomotion's measured period by 1.3e-4 relative (on one grid the two
    agree to 6e-10)."""
    from hemocircuit.analyses.transient import simulate

    proto = tmp_path / "kick.yaml"
    proto.write_text("events:\n  - {at: 0.5 s, set: {Pa.value: 88 mmHg}}\n  - {at: 1.5 s, set: {Pa.value: 80 mmHg}}\n")
    c = hc.load(ROOT / "netlists" / "vasomotion.yaml")
    runs = {integ: simulate(c, 37.0, dt=0.5, protocol=str(proto), integrator=integ, rtol=1e-8)
            for integ in ("rodas5p", "scipy-bdf")}
    comp, sci = runs["rodas5p"], runs["scipy-bdf"]
    assert comp.stats["limit_events"] >= 1                      # the floor was reached
    np.testing.assert_array_equal(sci.t, comp.t)
    np.testing.assert_array_equal(comp.t, np.arange(0.0, 37.01, 0.5))
    r_c, r_s = np.asarray(comp["art.r"]), np.asarray(sci["art.r"])
    assert np.max(np.abs(r_s - r_c) / r_c) < 1e-5
