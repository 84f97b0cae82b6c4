"""Sensitivity analysis (hemocircuit/sensitivity, docs/sensitivity.md): every method on
functions with known effects, spec validation, failed samples, and small real-model cases."""
from __future__ import annotations

import os
import re
import shlex

import numpy as np
import pytest

from hemocircuit.circuit import load
from hemocircuit.errors import HemocircuitError, NetlistError
from hemocircuit.sensitivity import constellation, parse_spec, run
from hemocircuit.sensitivity.outputs import FunctionObjective, make_objective, operating_points, _with_values

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
NETLIST = os.path.join(ROOT, "netlists", "isolated_arteriole.yaml")


def spec(method, params, output=None, **kw):
    return parse_spec({"method": method, "parameters": params, "output": output or {"function": None}, **kw})


BOX = [{"path": "x1", "lower": 0, "upper": 1}, {"path": "x2", "lower": 0, "upper": 2},
       {"path": "x3", "lower": -1, "upper": 1}]


def quad(v):  # f = 3 x1 + 2 x2^2 + 0 x3
    return 3 * v["x1"] + 2 * v["x2"] ** 2 + 0 * v["x3"]


# ---------------------------------------------------------------- constellation ----------
def test_constellation_additive_linear_gives_the_coefficients_with_zero_sigma():
    r = run(spec({"name": "constellation", "scheme": "additive", "n": 30}, BOX),
            FunctionObjective(lambda v: 3 * v["x1"] - 2 * v["x2"] + 0 * v["x3"]), scheduler="serial")
    mu, sigma = r.values("mu"), r.values("sigma")
    assert mu["x1"] == pytest.approx(3.0, rel=1e-8) and mu["x2"] == pytest.approx(-2.0, rel=1e-8)
    assert mu["x3"] == 0.0 and sigma["x3"] == 0.0
    assert sigma["x1"] < 1e-7 and sigma["x2"] < 1e-7
    assert r.n_runs == 30 * 4 and r.values("n_used")["x1"] == 30


def test_constellation_additive_quadratic_effects_are_the_difference_quotients():
    r = run(spec({"name": "constellation", "scheme": "additive", "n": 40, "step": 1e-3}, BOX),
            FunctionObjective(quad), scheduler="serial")
    pts = r.extra["points"][:, 0, :]  # base points (n, k)
    h = 1e-3 * 2.0 * np.where(pts[:, 1] / 2 + 1e-3 <= 1, 1, -1)
    ee_x2 = 2 * (2 * pts[:, 1] + h)  # ((x + h)^2 - x^2)/h times 2
    assert r.values("mu")["x2"] == pytest.approx(ee_x2.mean(), rel=1e-9)
    assert r.values("sigma")["x2"] == pytest.approx(ee_x2.std(ddof=1), rel=1e-7)
    assert r.ranking() == ["x2", "x1", "x3"]  # 2 x 2 x E[x2] = 4 > 3 > 0


def test_constellation_multiplicative_power_law_gives_the_exponent():
    p = 2.5
    r = run(spec({"name": "constellation", "scheme": "multiplicative", "range": 10, "n": 25},
                 [{"path": "x1", "centre": 6.0}, {"path": "x2", "centre": -3.0}]),
            FunctionObjective(lambda v: v["x1"] ** p * 7.0 + 0 * v["x2"]), scheduler="serial")
    s = 10 / 1e4  # thesis: a 0.1 % step for the +/-10 % scheme
    exact = ((1 + s) ** p - 1) / s  # the %/% effect of a power law, the same at every point
    assert r.values("mu")["x1"] == pytest.approx(exact, rel=1e-9)
    assert abs(exact - p) < p * (p - 1) * s  # = p to first order in the step
    assert r.values("sigma")["x1"] < 1e-8
    # the space: +/-10 % around the centres (sorted for a negative centre)
    assert list(r.space.lower) == pytest.approx([5.4, -3.3]) and list(r.space.upper) == pytest.approx([6.6, -2.7])


def test_design_is_a_latin_hypercube_and_the_best_of_several():
    rng = np.random.default_rng(3)
    U = constellation.design(4, 50, 8, rng)
    for j in range(4):  # one point per stratum in every dimension
        assert sorted(np.floor(U[:, j] * 50).astype(int)) == list(range(50))
    from scipy.spatial.distance import pdist
    from scipy.stats import qmc
    rng2 = np.random.default_rng(3)
    seps = [pdist(qmc.LatinHypercube(d=4, seed=rng2).random(50)).mean() for _ in range(8)]
    assert pdist(U).mean() == pytest.approx(max(seps))


# ------------------------------------------------------------------- SALib ------------------
def test_morris_linear_and_quadratic():
    r = run(spec({"name": "morris", "trajectories": 12, "levels": 4}, BOX), FunctionObjective(quad),
            scheduler="serial")
    ms = r.values("mu_star")
    # SALib's effects are per normalised range: a linear term gives coefficient x range
    assert ms["x1"] == pytest.approx(3.0, rel=1e-9) and r.values("sigma")["x1"] < 1e-9
    assert ms["x3"] == 0.0
    assert r.ranking() == ["x2", "x1", "x3"]


def test_sobol_ishigami_indices_within_their_sampling_error():
    a, b = 7.0, 0.1
    pi = np.pi
    fn = FunctionObjective(lambda v: np.sin(v["x1"]) + a * np.sin(v["x2"]) ** 2
                           + b * v["x3"] ** 4 * np.sin(v["x1"]))
    params = [{"path": f"x{i}", "lower": -pi, "upper": pi} for i in (1, 2, 3)]
    r = run(spec({"name": "sobol", "n": 1024, "resamples": 100}, params), fn, scheduler="serial")
    # analytic indices of the Ishigami function
    V = a ** 2 / 8 + b * pi ** 4 / 5 + b ** 2 * pi ** 8 / 18 + 0.5
    V1 = 0.5 * (1 + b * pi ** 4 / 5) ** 2
    V2 = a ** 2 / 8
    VT3 = 8 * b ** 2 * pi ** 8 / 225
    S1 = {"x1": V1 / V, "x2": V2 / V, "x3": 0.0}
    ST = {"x1": (V1 + VT3) / V, "x2": V2 / V, "x3": VT3 / V}
    for name in S1:
        row = next(x for x in r.table if x["parameter"] == name)
        # 95 % bootstrap intervals: allow 2 of them (the estimator's sampling error at n = 1024)
        assert abs(row["S1"] - S1[name]) < 2 * row["S1_conf"] + 1e-3, (name, row)
        assert abs(row["ST"] - ST[name]) < 2 * row["ST_conf"] + 1e-3, (name, row)
    assert r.ranking(key="ST") == ["x1", "x2", "x3"]


def test_local_normalised_derivatives_of_a_power_law():
    r = run(spec({"name": "local"}, [{"path": "x1", "centre": 2.0}, {"path": "x2", "centre": 5.0}]),
            FunctionObjective(lambda v: v["x1"] ** 2 / v["x2"]), scheduler="serial")
    S = r.values("normalised")
    assert S["x1"] == pytest.approx(2.0, rel=1e-5) and S["x2"] == pytest.approx(-1.0, rel=1e-5)
    assert r.values("derivative")["x1"] == pytest.approx(2 * 2.0 / 5.0, rel=1e-5)


# ---------------------------------------------------------------- failed samples ----------
def test_failing_samples_are_excluded_and_reported():
    def f(v):
        y = 3 * v["x1"] - 2 * v["x2"] + 0 * v["x3"]
        return np.where(v["x1"] > 0.8, np.nan, y)  # the model 'fails' there

    r = run(spec({"name": "constellation", "scheme": "additive", "n": 40}, BOX), FunctionObjective(f),
            scheduler="serial")
    base = r.extra["points"][:, 0, 0]
    n_ok = int(np.sum(base <= 0.8))
    assert 0 < n_ok < 40
    assert r.values("n_used")["x2"] == n_ok  # a failed base point loses all its effects
    assert r.values("mu")["x2"] == pytest.approx(-2.0, rel=1e-8)  # the rest is unaffected
    assert len(r.failures) >= 40 - n_ok and all(reason == "non-finite output" for _, reason in r.failures)
    assert r.failures[0][0].startswith("point ")


def test_failing_operating_point_is_reported_per_member_and_only_it_runs_the_fallbacks(monkeypatch):
    from hemocircuit.analyses import op as op_module
    from hemocircuit.errors import SolverError

    seen = []
    for name in ("_ptc", "_source_stepping"):
        stage = getattr(op_module, name)
        monkeypatch.setattr(op_module, name, lambda c, *a, _s=stage, _n=name: seen.append((_n, c.B)) or _s(c, *a))
    c = load(NETLIST)
    f1 = np.full(7, 9.34e-6)
    f1[4] = 1e-2  # the upper bound of tabBounds: the DC network of this member is singular
    X, vals, errors = operating_points(_with_values(c, {"art.f1": f1}))
    assert [e is None for e in errors] == [True] * 4 + [False] + [True] * 2
    assert "DC guess" in errors[4] and np.isnan(vals["art.r"][4]) and np.all(np.isnan(X[4]))
    single = c.operating_point()["art.r"]
    assert np.allclose(np.delete(vals["art.r"], 4), single, rtol=1e-10)
    assert seen == []  # Newton solved the six others; nothing else ran
    # at 20 cmH2O, pCa_L 10 % less negative: Newton, then both fallbacks fail (the wall
    # collapses); the fallbacks run on that member alone, the batch keeps the others
    low = c.with_values({"Pup.value": "20 cmH2O", "Pdown.value": "20 cmH2O"})
    batch = _with_values(low, {"art.pCa_L": -8.5 * np.array([1.0, 1.1, 0.9, 1.05])})
    X, vals, errors = operating_points(batch)
    assert [e is None for e in errors] == [True, True, False, True]
    assert "worst-balanced state" in errors[2]
    assert seen == [("_ptc", 1), ("_source_stepping", 1)]
    for k in (0, 1, 3):
        assert vals["art.r"][k] == pytest.approx(batch.member(k).operating_point()["art.r"], rel=1e-10)
    # operating_point (all or nothing) names the failed member
    with pytest.raises(SolverError, match=r"batch member 2 \(1 of 4 members failed: 2\)"):
        op_module.operating_point(batch)


# ---------------------------------------------------------------- spec errors ----------
@pytest.mark.parametrize("data, message", [
    ({"method": "constellation", "parameters": ["x"], "output": {"function": None}, "bogus": 1}, "unknown key"),
    ({"method": {"name": "constellation", "scheme": "additive"}, "parameters": ["x"],
      "output": {"function": None}}, "needs 'lower' and 'upper'"),
    ({"method": "annealing", "parameters": ["x"], "output": {"function": None}}, "unknown method"),
    ({"method": {"name": "sobol", "n": 100}, "parameters": [{"path": "x", "lower": 0, "upper": 1}],
      "output": {"function": None}}, "power of 2"),
    ({"method": {"name": "constellation", "range": 150}, "parameters": ["x"], "output": {"function": None}},
     "between 0 and 100"),
    ({"method": "constellation", "parameters": ["x", "x"], "output": {"function": None}}, "appear twice"),
    ({"method": "constellation", "parameters": ["x"], "ties": [{"path": "y", "scale_with": "z"}],
      "output": {"function": None}}, "not one of the varied parameters"),
    ({"method": "constellation", "parameters": ["x"], "output": {"op": {}, "tran": {}}}, "exactly one"),
    ({"method": "dynamic", "parameters": ["x"], "output": {"op": {"column": "art.r"}}}, "must be 'tran'"),
    ({"method": {"name": "morris", "levels": 3}, "parameters": ["x"], "output": {"function": None}}, "even"),
])
def test_spec_errors(data, message):
    with pytest.raises(NetlistError, match=message):
        parse_spec(data, "s.yaml")


def test_spec_errors_against_the_circuit():
    c = load(NETLIST)
    bad_col = spec("constellation", ["art.f2"], {"op": {"column": "art.radius"}})
    with pytest.raises(NetlistError, match="unknown output column 'art.radius'.*art.r"):
        make_objective(bad_col, c)
    with pytest.raises(NetlistError, match="no parameter 'tau'"):
        run(spec("constellation", ["art.tau"], {"op": {"column": "art.r"}}),
            make_objective(spec("constellation", ["art.tau"], {"op": {"column": "art.r"}}), c))
    zero = spec({"name": "constellation", "n": 2}, ["art.C_in"], {"op": {"column": "art.r"}})
    with pytest.raises(NetlistError, match="non-zero centre"):
        run(zero, make_objective(zero, c), scheduler="serial")
    wide = spec({"name": "constellation", "scheme": "additive", "n": 2},
                [{"path": "art.f2", "lower": "-1 N*s/m", "upper": "1 N*s/m"}], {"op": {"column": "art.r"}})
    with pytest.raises(NetlistError, match="physical bounds"):
        run(wide, make_objective(wide, c), scheduler="serial")
    ev = spec("constellation", [{"path": "art.tau_Ca", "event": "239 s"}], {"op": {"column": "art.r"}})
    with pytest.raises(NetlistError, match="tran output only"):
        make_objective(ev, c)


def test_fit_error_output_is_the_rms_of_the_fit_spec(tmp_path):
    """fit_error on a closed form: P(b) = P0 + R Q fitted to noiseless data (P0 = 10 mmHg,
    R = 2 mmHg*s/mL).  A P0 off by d gives rms = |d|; an R off by d gives rms = |d| rms(Q)."""
    import yaml
    from hemocircuit.fitting.datasets import write_table

    Q = np.linspace(0.5, 4.0, 8)
    write_table(tmp_path / "line.csv", {"Q": Q, "P": 10.0 + 2.0 * Q}, {"Q": "mL/s", "P": "mmHg"}, ["test data"])
    fit_spec = tmp_path / "fit.yaml"
    fit_spec.write_text(yaml.safe_dump({
        "parameters": {"Ps.value": {"bounds": ["-50 mmHg", "50 mmHg"]},
                       "R1.R": {"bounds": ["0.1 mmHg*s/mL", "20 mmHg*s/mL"]}},
        "datasets": [{"name": "line", "file": "line.csv", "observe": "P(b)", "column": "P",
                      "experiment": {"type": "op", "inputs": {"Qs.value": "Q"}}}]}))
    netlist = os.path.join(os.path.dirname(__file__), "fitting", "linear.yaml")
    obj = make_objective(spec("constellation", None, {"fit_error": str(fit_spec)}), load(netlist), netlist)
    assert [p.path for p in obj.default_parameters()] == ["Ps.value", "R1.R"]
    y, errors = obj.evaluate_batch({"Ps.value": np.array([10.0, 12.5, 10.0]), "R1.R": np.array([2.0, 2.0, 2.5])})
    assert errors == [None] * 3
    assert y[:, 0] == pytest.approx([0.0, 2.5, 0.5 * np.sqrt(np.mean(Q ** 2))], abs=1e-9)


# ---------------------------------------------------------------- the real model ----------
PARAMS = ["art.pCa_L", "art.pCa_U", "art.q2", "art.f2", "art.k_tau"]
AT = [{"Pup.value": f"{p} cmH2O", "Pdown.value": f"{p} cmH2O"} for p in (60, 100)]


def test_arteriole_op_constellation_ranks_like_local_derivatives():
    """~50 runs: the radius at 60 and 100 cmH2O without flow.  The Ca bounds dominate, the
    passive exponent matters a little, f2 (friction: dynamics only) and k_tau (shear NO: no
    flow) not at all - and the local derivatives at the centre say the same."""
    c = load(NETLIST)
    out = {"op": {"column": "art.r", "at": AT}}
    s = spec({"name": "constellation", "scheme": "multiplicative", "range": 10, "n": 8}, PARAMS, out)
    r = run(s, make_objective(s, c), scheduler="serial")
    assert r.n_runs == 48 and not r.failures
    sl = spec({"name": "local"}, PARAMS, out)
    loc = run(sl, make_objective(sl, c), scheduler="serial")
    for j in range(2):
        mu, S = r.values("mu", j), loc.values("normalised", j)
        assert set(r.ranking(j)[:2]) == {"art.pCa_L", "art.pCa_U"} == set(loc.ranking(j)[:2])
        # no effect beyond the solver's rounding (the Ca bounds' effects are ~1 %/%)
        assert max(abs(mu["art.f2"]), abs(mu["art.k_tau"]), abs(S["art.f2"]), abs(S["art.k_tau"])) < 1e-8
        for p in ("art.pCa_L", "art.pCa_U"):  # same sign, same size within the +/-10 % nonlinearity
            assert np.sign(mu[p]) == np.sign(S[p]) and 0.5 < mu[p] / S[p] < 2.0
    # the elementary effect of a Ca bound is the finite-difference version of the derivative:
    # check one by hand at the centre (raising pCa_U raises the target Ca, so the vessel constricts)
    cc = _with_values(c, {**AT[1], "art.pCa_U": -6.94 * (1 + 1e-3)})
    r0 = _with_values(c, AT[1]).operating_point()["art.r"]
    ee = ((cc.operating_point()["art.r"] - r0) / r0) / 1e-3
    assert ee == pytest.approx(loc.values("normalised", 1)["art.pCa_U"], rel=1e-2)


def test_dynamic_kuo91_A_phases():
    """Thesis, dynamic results: f2 dominates during the passive dilation after the pressure
    step (51 s), tau_Ca1 during the slow contraction, NO speed after flow stops (300 s); before
    the step nothing has an effect and the tie f1 ~ 1/v keeps v without effect at steady state."""
    c = load(NETLIST)
    s = parse_spec({"method": {"name": "dynamic", "n": 3, "range": 50}, "seed": 2,
                    "parameters": ["art.v", "art.f2", {"name": "tau_Ca1", "path": "art.tau_Ca"},
                                   {"name": "tau_Ca2", "path": "art.tau_Ca", "event": "239 s"},
                                   {"name": "NO speed", "path": "art.no_speed"}],
                    "ties": [{"path": "art.f1", "scale_with": "art.v", "power": -1}],
                    "output": {"tran": {"column": "art.r", "times": ["30 s", "54 s", "120 s", "330 s", "450 s"],
                                        "protocol": os.path.join(ROOT, "examples/protocols/kuo91_A.yaml")}}})
    obj = make_objective(s, c)
    assert obj.parameter_info("art.tau_Ca", 239.0)["centre"] == 1.0  # tau_Ca2: the event's value
    assert obj.parameter_info("art.tau_Ca")["centre"] == 230.0  # tau_Ca1: the protocol's initial
    r = run(s, obj, scheduler="serial")
    assert not r.failures
    mag = np.abs(r.extra["mean"][:, :, 0])  # (k, T)
    names = r.space.names
    assert np.all(mag[:, 0] < 1e-6)  # t = 30 s: steady state, untouched by every parameter
    assert names[int(np.argmax(mag[:, 1]))] == "art.f2"  # passive dilation
    assert names[int(np.argmax(mag[:, 2]))] == "tau_Ca1"  # slow myogenic contraction
    assert names[int(np.argmax(mag[:, 3]))] == "NO speed"  # after flow stops
    assert np.all(mag[0] < 1e-3)  # v, with f1 tied inversely: no effect on the steady states
    base = r.extra["baseline"][:, :, 0]
    # nearly the same steady state at every base point: the NO speed factor scales h_w, r_dw,
    # s_w, k_tau but not the blood decay r_db, so steady NO (eq NOSS) moves very slightly
    assert np.allclose(base[:, 0], base[0, 0], rtol=1e-7)


# ---------------------------------------------------------------- docs ---------------------
def test_docs_worked_example_commands_run(tmp_path, monkeypatch, capsys):
    """The commands of docs/sensitivity.md's worked example, as written (small budgets)."""
    from hemocircuit.cli import main

    text = open(os.path.join(ROOT, "docs", "sensitivity.md")).read()
    block = re.search(r"## Worked example.*?```sh\n(.*?)```", text, re.S).group(1)
    cmds = [shlex.split(line) for line in block.splitlines() if line.startswith("hemocircuit sensitivity")]
    assert len(cmds) == 3
    monkeypatch.chdir(tmp_path)
    for argv in cmds:
        argv = [a if not a.startswith(("netlists/", "examples/")) else os.path.join(ROOT, a) for a in argv[1:]]
        assert main(argv + ["--scheduler", "serial"]) == 0
    out = capsys.readouterr().out
    first = out.split("ranking by mu_star for ")[1]
    assert first.splitlines()[1].split()[1] in ("art.pCa_L", "art.pCa_U")
    assert re.search(r"art\.k_tau\s+0\n", out)
    for f in ("sens_op.csv", "sens_op.png", "sens_local.csv", "sens_dyn.csv", "sens_dyn_series.csv", "sens_dyn.png"):
        assert (tmp_path / f).stat().st_size > 0
    header = (tmp_path / "sens_op.csv").read_text().splitlines()[0]
    assert "mu_star [%/%]" in header and "lower" in header
    assert not [p for p in os.listdir(tmp_path) if p.startswith(".")]  # no temporary files left
