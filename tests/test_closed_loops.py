"""Hearts and valves that never stop the solver: closed loops of separate chamber and valve
blocks run for many beats, conserve the blood volume and reach a periodic state.

netlists/svzerod/closedLoopHeart_singleVessel_decomposed.json is svZeroDSolver's case of that
name (their tests/cases at commit c7b0ca09, BSD licence in that folder): four chambers with
outflow inductors, four ValveTanh valves (steepness 1e4/mmHg), pulmonary and systemic vessels,
numbers in mmHg, mL, s.  It stopped with "step size too small" at t = 0.32-1.58 s (rtol 1e-4 to
1e-6): one nodal solve that did not converge (a rejected stage's far-away state) left its
iterate as the warm start of every later solve, which then failed too.
"""
from __future__ import annotations

import os

import numpy as np
import pytest

from paths import ROOT, SHARED_SVZEROD as SHARED

from hemocircuit.kernels.system import CompiledSystem
from hemocircuit.svzerod import load_svzerod

DECOMPOSED = ROOT / "netlists" / "svzerod" / "closedLoopHeart_singleVessel_decomposed.json"
PERIOD = 1.0169  # s, their cardiac_period


@pytest.fixture(scope="module")
def heart():
    return load_svzerod(str(DECOMPOSED), "mmHg")


def test_a_failed_nodal_solve_leaves_no_poisoned_start(heart):
    """Rows evaluated one after another share the nodal solve's warm start (as the integrator's
    stages do).  A row whose solve fails (an atrial volume of 1e6 mL: its exponential
    pressure-volume law overflows) must not make the next, ordinary rows fail: each gives what
    it gives evaluated alone."""
    cs = CompiledSystem.of(heart)
    P = cs.params(heart)
    x = np.full(heart.nx, 10.0)
    x[heart.state_names.index("LA.Q_out")] = -0.01
    alone = cs.rhs(0.3, x, P[0])
    assert np.all(np.isfinite(alone))
    X = np.repeat(x[None], 3, 0)
    X[0, heart.state_names.index("LA.Vc")] = 1e6
    F = cs.rhs(0.3, X, np.repeat(P, 3, 0))
    assert not np.all(np.isfinite(F[0]))
    np.testing.assert_allclose(F[1], alone, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(F[2], alone, rtol=1e-9, atol=1e-9)


@pytest.fixture(scope="module")
def thirty_beats(tmp_path_factory):
    """The command of netlists/svzerod/README.md, as written (its CSV read back)."""
    from hemocircuit.cli import main
    from hemocircuit.results import Result

    out = tmp_path_factory.mktemp("heart") / "heart.csv"
    readme = (DECOMPOSED.parent / "README.md").read_text()
    line, = [ln.strip() for ln in readme.splitlines() if ln.strip().startswith("hemocircuit tran")]
    args = line.split()[1:]
    args[args.index("heart.csv")] = str(out)
    args[args.index("netlists/svzerod/closedLoopHeart_singleVessel_decomposed.json")] = str(DECOMPOSED)
    assert main(args + ["--quiet"]) == 0
    return Result.load(out)


def _col(r, name):
    return np.asarray(r[name], dtype=float)


def test_decomposed_heart_runs_thirty_beats_conserving_blood_volume(heart, thirty_beats):
    """30 beats without a solver failure; the blood volume (the loop's conservation law: its
    chambers and capacitors, each a V(NAME) column) is the same at every output time to 1e-9
    of itself."""
    r = thirty_beats
    t = _col(r, "time")
    assert t[-1] == pytest.approx(30 * PERIOD)
    law, = heart.laws
    V = sum(w * _col(r, f"V({elem})") for elem, _, w in law.terms)
    assert V[0] > 100.0
    assert np.max(np.abs(V - V[0])) <= 1e-9 * V[0]


def test_decomposed_heart_reaches_a_periodic_state_with_equal_stroke_volumes(thirty_beats):
    """After 30 beats the last two beats agree (the left ventricle's volume to 1e-3 of its
    range), and in the last beat the two ventricles eject the same volume (a periodic closed
    loop has no net transfer between its halves), to 1e-3 of the stroke volume."""
    r = thirty_beats
    t = _col(r, "time")
    assert t.size == 30 * 1000 + 1  # 1000 rows a beat
    last = np.arange(t.size) >= 29 * 1000
    vlv = _col(r, "V(LV)")
    a, b = vlv[29 * 1000:], vlv[28 * 1000:29 * 1000 + 1]
    rng = np.ptp(a)
    assert rng > 10.0  # a beating ventricle, mL
    assert np.max(np.abs(a - b)) <= 1e-3 * rng
    tl = t[last]
    q_av = np.trapezoid(_col(r, "Q(AV)")[last], tl)
    q_pv = np.trapezoid(_col(r, "Q(PV)")[last], tl)
    assert q_av > 10.0
    assert abs(q_av - q_pv) <= 1e-3 * q_av




@pytest.mark.parametrize("case", ["piecewise_Chamber_and_Valve", "closed_loop_two_hill"])
def test_piecewise_valve_loops_run_thirty_beats_from_their_start(case):
    """Their closed loops of LinearElastanceChamber and PiecewiseValve blocks (the first with a
    merging junction: two pulmonary veins into the left atrium) run 30 beats from their
    initial_condition (the imported netlist's ic names every state, so no operating point is
    computed: the time-averaged loop has no pump, all its valves sit on their kink at zero flow
    and Newton cycled there: "no operating point found"), conserving the blood volume to 1e-9."""
    from hemocircuit.analyses.transient import simulate
    from hemocircuit.svzerod import import_svzerod

    path = os.path.join(SHARED, "cases", case + ".json")
    if not os.path.isfile(path):
        pytest.skip("svZeroDSolver test cases not present")
    T = import_svzerod(path).period
    c = load_svzerod(path)
    r = simulate(c, 30 * T, dt=T / 100, progress=False)
    assert r.t[-1] == pytest.approx(30 * T)
    law, = c.laws
    V = sum(w * np.asarray(r[f"V({elem})"]) for elem, _, w in law.terms)
    assert np.max(np.abs(V - V[0])) <= 1e-9 * V[0]
    assert np.ptp(np.asarray(r["V(" + law.terms[-1][0] + ")"])[-100:]) > 1.0  # still beating, mL


def test_periodic_start_begins_on_the_beat(tmp_path, capsys):
    """tran --periodic-start: the run starts on the periodic steady state (shooting from their
    initial condition), so its second beat repeats its first: every volume at the end of beat 1
    equals its value at the start to 1e-5 of its range.  From their initial condition (no
    periodic start) the first beat does not close (the left ventricle drifts by more than 1 %)."""
    from hemocircuit.cli import main
    from hemocircuit.results import Result

    def run(*extra):
        out = tmp_path / f"run{len(extra)}.csv"
        assert main(["tran", str(DECOMPOSED), "--svzerod-units", "mmHg", "--t-end", str(2 * PERIOD), "--dt",
                     str(PERIOD / 1000), "--out", str(out), "--quiet", *extra]) == 0
        return Result.load(out)

    r = run("--periodic-start")
    assert "periodic start: the orbit of period 1.0169 s" in capsys.readouterr().err
    volumes = [k for k in r.data if k.startswith("V(")]
    assert len(volumes) >= 6
    for k in volumes:
        v = np.asarray(r[k], dtype=float)
        assert abs(v[1000] - v[0]) <= 1e-5 * np.ptp(v), k
    plain = np.asarray(run()["V(LV)"], dtype=float)
    assert abs(plain[1000] - plain[0]) > 1e-2 * np.ptp(plain)


def test_chamber_sphere_loop_with_piecewise_valves_runs_thirty_beats(tmp_path):
    """A ChamberSphere ventricle (their chamber_sphere case's values, SI) in a closed loop with two
    PiecewiseValves (tests/netlists/chamber_sphere_loop.json, illustrative loop values; their
    issue #246 reports such loops not converging): 30 beats run, the ventricle ejects (its
    pressure swings by more than 100 mmHg in the last beat, the outlet valve carries forward
    flow), and the blood volume is kept to 1e-9 of itself."""
    from hemocircuit.cli import main
    from hemocircuit.results import Result

    model = ROOT / "tests" / "netlists" / "chamber_sphere_loop.json"
    out = tmp_path / "sphere.csv"
    assert main(["tran", str(model), "--svzerod-units", "SI", "--t-end", "30", "--dt", "0.01", "--out", str(out),
                 "--quiet"]) == 0
    r = Result.load(out)
    t = _col(r, "time")
    assert t[-1] == pytest.approx(30.0)
    c = load_svzerod(str(model), "SI")
    law, = c.laws
    V = sum(w * _col(r, f"V({elem})") for elem, _, w in law.terms)
    assert np.max(np.abs(V - V[0])) <= 1e-9 * V[0]
    last = t >= 29.0
    assert np.ptp(_col(r, "P(ventricle__outlet_valve)")[last]) > 100.0
    assert _col(r, "Q(outlet_valve)")[last].max() > 100.0


@pytest.mark.parametrize("factor", [1.0, 1e4])
def test_stenosis_at_ten_thousand_times_runs_on_its_closed_form(tmp_path, factor):
    """Their pulsatileFlow_CStenosis_steadyPressure with the stenosis coefficient S at 1x and 1e4x
    (their issue #237: Newton diverging at large coefficients) runs three periods through tran.
    The vessel's capacitor sits under the PRESSURE outlet, so the circuit has no state (the
    compiled integrator stopped with 'step size too small' at t = 0 on a stateless circuit);
    every row is then the closed form P_in - P_out = S |Q| Q with Q the inflow."""
    import json

    from hemocircuit.cli import main
    from hemocircuit.results import Result
    from hemocircuit.units import parse_quantity

    path = os.path.join(SHARED, "cases", "pulsatileFlow_CStenosis_steadyPressure.json")
    if not os.path.isfile(path):
        pytest.skip("svZeroDSolver test cases not present")
    with open(path) as fh:
        m = json.load(fh)
    vals = m["vessels"][0]["zero_d_element_values"]
    vals["stenosis_coefficient"] *= factor
    model = tmp_path / "stenosis.json"
    model.write_text(json.dumps(m))
    out = tmp_path / "stenosis.csv"
    T = 6.283185307  # their inflow table's period, s
    assert main(["tran", str(model), "--t-end", str(3 * T), "--dt", "0.01", "--out", str(out), "--quiet"]) == 0
    r = Result.load(out)
    assert _col(r, "time")[-1] == pytest.approx(3 * T)
    S = parse_quantity(f"{vals['stenosis_coefficient']} dyn*s**2/cm**8", "mmHg*s**2/mL**2")
    q = _col(r, "Q(INFLOW)")
    dp = _col(r, "P(INFLOW__branch0_seg0)") - _col(r, "P(branch0_seg0__OUT)")
    assert np.ptp(q) > 0.5
    np.testing.assert_allclose(dp, S * np.abs(q) * q, rtol=1e-9, atol=1e-12 * factor)


def test_a_failure_names_the_fastest_state_and_its_element(heart):
    """Failures say which element: the compiled run's error names the state changing fastest
    against its size where the step size collapsed, with its element and type.  On the
    decomposed heart with the left ventricle's outflow set to -50 mL/s against a closed aortic
    valve (Rmax 1000 mmHg s/mL, L 1.1e-4 mmHg s^2/mL: d/dt ~ 4.5e8 mL/s^2), that is LV.Q_out."""
    from hemocircuit.analyses.compiled_run import fastest_state

    cs = CompiledSystem.of(heart)
    P = cs.params(heart)[0]
    x = cs.integrate(np.array([0.0, 0.1]), np.array([float(v) for v in _their_start(heart)]), P)[0][-1]
    x[heart.state_names.index("LV.Q_out")] = -50.0
    text = fastest_state(cs, heart, P, 0.1, x)
    assert "LV.Q_out (LV, type chamber_elastance_inductor)" in text
    assert "d/dt = 4." in text and "e+08 mL/s^2" in text


def _their_start(c):
    from hemocircuit.analyses.transient import start_state
    return start_state(c)


def test_a_beat_costs_the_same_late_in_a_run_as_early():
    """Time has an arbitrary origin: the same beats of the whole-body model, from the same state,
    started 0 s and 600 beats into a run, take the same steps and give the same states.  The
    df/dt difference step used to grow with t (1e-7 |t|: 54 us at t = 544 s), straddled the valve
    switchings and made every beat dearer, until netlists/body/body.yaml stopped at t = 544 s
    at the default tolerance (more than 10 million steps in one 0.01 s output interval)."""
    import hemocircuit as hc

    c = hc.load(os.path.join(ROOT, "netlists", "body", "body.yaml"))
    period = float(str(c.netlist.element("heart").values["period"]).split()[0])  # "0.857 s": shifts are whole beats
    x0 = np.asarray(c.operating_point().x, float)
    runs = []
    for t0 in (0.0, 600 * period):
        r = c.simulate(t0 + 3 * period, t0=t0, x0=x0, dt=period / 50)
        runs.append(r)
    early, late = runs
    assert late.stats["steps"] <= 1.2 * early.stats["steps"], (early.stats, late.stats)
    # the states at each beat's end, in their ranges (mid-beat, a valve opening a few us
    # earlier or later moves its fast flow by more than the run's tolerance)
    scale = np.maximum(np.ptp(early.x, axis=0), c.state_scales)
    ends = slice(50, None, 50)
    assert np.max(np.abs(late.x[ends] - early.x[ends]) / scale) < 1e-4


def _heart_only(tmp_path):
    """body.yaml's heart, aorta and systemic bed alone (no brain), 500 mL of blood."""
    import yaml

    import hemocircuit as hc

    net = yaml.safe_load((ROOT / "netlists" / "body" / "body.yaml").read_text())
    net = {"name": "heart_only", "elements": net["elements"], "constraints": [{"node": "vc", "volume": "500 mL"}]}
    path = tmp_path / "heart_only.yaml"
    path.write_text(yaml.safe_dump(net, sort_keys=False))
    return hc.load(str(path))


def test_a_valve_opening_is_stepped_onto_not_crept_up_to(tmp_path):
    """A closed valve (its flow held on the hard limit Q >= 0) opens where its pressure
    difference turns positive: a kink of the flow, which the error estimate of a step across
    it rejects.  The step-size controller alone crept up to each opening with steps down to
    1e-7 s and ~25 extra steps (half of the whole-body model's steps).  The integrator now
    locates the release in the rejected step and ends the retried step just past it: three
    beats of the heart take a third fewer steps and under half the rejections, and stay as
    close to a rtol 1e-10 run as before."""
    c = _heart_only(tmp_path)
    period = 0.857
    x0 = c.simulate(10 * period, dt=period / 50).x[-1].copy()
    cs = CompiledSystem.of(c)
    P = cs.params(c)[0]
    t = 10 * period + np.linspace(0, 3 * period, 151)
    breaks, kinks = c.jumps_and_kinks(t[0], t[-1])
    ref, _ = cs.integrate(t, x0, P, rtol=1e-10, breaks=breaks, kinks=kinks)
    scale = np.maximum(np.ptp(ref, axis=0), cs.scales)
    runs = {}
    for land in (1, 0):
        X, st = cs.integrate(t, x0, P, rtol=1e-6, breaks=breaks, kinks=kinks, land_releases=land)
        assert st["status"] == 0 and st["limit_events"] >= 3 * 4, st  # every valve closes each beat
        assert np.max(np.abs(X - ref) / scale) < 1e-5
        runs[land] = st
    assert runs[1]["steps"] <= 0.75 * runs[0]["steps"], runs
    assert runs[1]["rejected"] <= 0.5 * runs[0]["rejected"], runs


def test_a_closed_valve_on_the_scipy_path_stops_with_an_error_not_a_hang(tmp_path):
    """solve_ivp cannot hold a state on its hard limit while the rate points outward: from the
    operating point of body.yaml's heart (every valve closed, flows exactly 0) the tricuspid's
    limit fired again at once after each restart, and a 50 ms run went on for hours.  It must
    stop, name the limit and say how to run it, and keep the rows it has."""
    import hemocircuit as hc
    from hemocircuit.analyses import transient

    c = _heart_only(tmp_path)
    with pytest.raises(hc.SolverError, match=r"stalled at t = .*hard limit heart\.Q_\w+ >= 0.*compiled engine") as err:
        c.simulate(0.05, engine="scipy", rtol=1e-6, dt=0.001)
    assert err.value.time < transient.STALL_ADVANCE * transient.STALL_RESTARTS
    assert err.value.partial is not None and err.value.partial.n_rows >= 1
