"""Parameter estimation (hemocircuit fit, hemocircuit.fitting): spec validation, exact recovery
and linear-regression standard errors on closed-form circuits, recovery of the kuo91 passive
stage from generated data, and the fitted fragment re-loading to the reported rms."""
import json
import os

import numpy as np
import pytest
import yaml

import hemocircuit as hc
from hemocircuit.analyses.fit import fit
from hemocircuit.cli import main
from hemocircuit.errors import FitSpecError
from hemocircuit.fitting import load_problem
from hemocircuit.fitting.datasets import write_table
from hemocircuit.units import conversion_factor

from paths import ROOT

HERE = ROOT / "tests" / "fitting"
EXAMPLES = ROOT / "examples" / "fitting"
ARTERIOLE = ROOT / "netlists" / "isolated_arteriole.yaml"
KUO91_PASSIVE = {"art.q1": 26.4e-9, "art.q2": 8.38, "art.q3": 1.06, "art.l0": 77.5e-6}  # tabPassiveFit

pytestmark = pytest.mark.filterwarnings("ignore::RuntimeWarning")


def write_spec(tmp_path, body, name="spec.yaml"):
    p = tmp_path / name
    p.write_text(yaml.safe_dump(body, sort_keys=False))
    return p


# ------------------------------------------------------------- 1. linear closed form ------
def linear_data(tmp_path, noise, seed=0):
    """P(b) = P0 + R Q at 8 flows, P0 = 10 mmHg, R = 2 mmHg*s/mL (+ Gaussian noise in mmHg)."""
    Q = np.linspace(0.5, 4.0, 8)
    P = 10.0 + 2.0 * Q + np.random.default_rng(seed).normal(0.0, noise, Q.size)
    write_table(tmp_path / "line.csv", {"Q": Q, "P": P}, {"Q": "mL/s", "P": "mmHg"}, ["test data"])
    return Q, P


def linear_spec(tmp_path, **extra):
    body = {"parameters": {"Ps.value": {"bounds": ["-50 mmHg", "50 mmHg"], "start": "0 mmHg"},
                           "R1.R": {"bounds": ["0.1 mmHg*s/mL", "20 mmHg*s/mL"], "log": True,
                                    "start": "0.5 mmHg*s/mL"}},
            "datasets": [{"name": "line", "file": "line.csv", "observe": "P(b)", "column": "P", "sigma": "0.5 mmHg",
                          "experiment": {"type": "op", "inputs": {"Qs.value": "Q"}}}],
            "settings": {"starts": 1, "seed": 0, "max_nfev": 50, "workers": 1}}
    body.update(extra)
    return write_spec(tmp_path, body)


def test_linear_fit_is_exact_and_standard_errors_are_the_regression_ones(tmp_path):
    Q, P = linear_data(tmp_path, noise=0.5, seed=7)
    problem, res, paths = fit(HERE / "linear.yaml", linear_spec(tmp_path), out=tmp_path / "out", plot=False)
    X = np.column_stack([np.ones_like(Q), Q])
    beta, ssr, *_ = np.linalg.lstsq(X, P, rcond=None)         # ordinary least squares
    s2 = float(ssr[0]) / (len(Q) - 2)
    se = np.sqrt(np.diag(s2 * np.linalg.inv(X.T @ X)))
    corr = np.linalg.inv(X.T @ X)[0, 1] / np.sqrt(np.linalg.inv(X.T @ X)[0, 0] * np.linalg.inv(X.T @ X)[1, 1])
    assert res["p"] == pytest.approx(beta, rel=1e-7)
    assert res["se"] == pytest.approx(se, rel=1e-5)
    assert res["corr"][0, 1] == pytest.approx(corr, rel=1e-5)
    assert res["rms"][0] == pytest.approx(np.sqrt(float(ssr[0]) / len(Q)), rel=1e-6)
    report = json.loads(open(paths["report"]).read())
    assert [p["unit"] for p in report["parameters"]] == ["mmHg", "mmHg*s/mL"]
    assert report["provenance"]["spec"].endswith("spec.yaml") and report["provenance"]["netlist"].endswith("linear.yaml")


def test_linear_fit_recovers_noiseless_parameters_and_flags_a_bound(tmp_path):
    linear_data(tmp_path, noise=0.0)
    _, res, _ = fit(HERE / "linear.yaml", linear_spec(tmp_path), out=tmp_path / "out", plot=False)
    assert res["p"] == pytest.approx([10.0, 2.0], rel=1e-9)
    assert res["bounds_hit"] == ["", ""]
    # the true R = 2 lies above the upper bound 1.5: the optimum rests on it and is flagged
    spec = linear_spec(tmp_path)
    body = yaml.safe_load(spec.read_text())
    body["parameters"]["R1.R"]["bounds"] = ["0.1 mmHg*s/mL", "1.5 mmHg*s/mL"]
    _, res, _ = fit(HERE / "linear.yaml", write_spec(tmp_path, body), out=tmp_path / "out2", plot=False)
    assert res["bounds_hit"] == ["", "upper"]
    assert res["p"][1] == pytest.approx(1.5, rel=1e-6)


# ------------------------------------------------------------- 2. transient, epochs -------
def test_transient_fit_recovers_a_time_constant_and_an_epoch_value(tmp_path):
    """R-C step (closed form): C from the first epoch's tau = R1 C, the epoch value R1.R@5s
    from the second's tau = R1' C."""
    t = np.arange(0.0, 12.0 + 1e-9, 0.25)
    C, R1, R2 = 0.5, 2.0, 4.0
    P5 = 100.0 * (1 - np.exp(-4.0 / (R1 * C)))
    P = np.where(t < 1, 0.0, np.where(t < 5, 100.0 * (1 - np.exp(-(t - 1) / (R1 * C))),
                                      100.0 - (100.0 - P5) * np.exp(-(t - 5) / (R2 * C))))
    write_table(tmp_path / "rc.csv", {"t": t, "P": P}, {"t": "s", "P": "mmHg"})
    spec = write_spec(tmp_path, {
        "parameters": {"C1.C": {"bounds": ["0.1 mL/mmHg", "2 mL/mmHg"], "log": True, "start": "1 mL/mmHg"},
                       "R1.R@5s": {"bounds": ["0.5 mmHg*s/mL", "20 mmHg*s/mL"], "log": True,
                                   "start": "1 mmHg*s/mL"}},
        "datasets": [{"name": "step", "file": "rc.csv", "observe": "P(a)", "column": "P",
                      "experiment": {"type": "tran", "protocol": str(HERE / "rc_protocol.yaml"), "time": "t"}}],
        "settings": {"starts": 1, "max_nfev": 40, "workers": 1}})
    problem, res, paths = fit(HERE / "rc.yaml", spec, out=tmp_path / "out", plot=False)
    assert res["p"] == pytest.approx([C, R2], rel=1e-4)
    assert res["rms"][0] < 1e-3  # mmHg
    proto = yaml.safe_load(open(paths["protocol step"]).read())
    assert proto["events"][1]["set"]["R1.R"].startswith("4.0000") or \
        float(proto["events"][1]["set"]["R1.R"].split()[0]) == pytest.approx(R2, rel=1e-4)


# ------------------------------------------------------------- 3. kuo91 passive stage -----
def test_kuo91_passive_recovered_and_fragment_reproduces_the_rms(tmp_path):
    problem, res, paths = fit(ARTERIOLE, EXAMPLES / "kuo91_1_passive.yaml", out=tmp_path / "s1", plot=False,
                              settings={"starts": 0, "workers": 1})
    assert res["starts"][0]["z0"] is not None
    start = dict(zip(problem.parameters, problem.start))
    assert all(abs(start[k] / v - 1) > 0.05 for k, v in KUO91_PASSIVE.items())  # a real start
    for k, v in KUO91_PASSIVE.items():
        assert res["p"][problem.parameters.index(k)] == pytest.approx(v, rel=5e-3), k   # within 0.5 %
    # the fragment is a variant netlist: load it and recompute the rms independently of the fit code
    c = hc.load(paths["fragment"]).with_options({"art.passive": True})
    data = problem.datasets[0].table
    mmhg = conversion_factor("cmH2O", "mmHg")
    c = c.batch(data.n).with_values({"Pup.value": data.columns["Pup"] * mmhg,
                                     "Pdown.value": data.columns["Pdown"] * mmhg})
    r = np.asarray(c.operating_point()["art.r"])
    rms = np.sqrt(np.mean((r - data.columns["r"]) ** 2))
    assert rms == pytest.approx(res["rms"][0], rel=1e-3, abs=1e-6)
    assert rms < 0.05  # um
    # a later stage starts from it
    stage2 = yaml.safe_load((EXAMPLES / "kuo91_2_active.yaml").read_text())
    stage2["start_from"] = str(paths["fragment"])
    for d in stage2["datasets"]:
        d["file"] = str(EXAMPLES / d["file"])
    (tmp_path / "stage2.yaml").write_text(yaml.safe_dump(stage2))
    p2 = load_problem(ARTERIOLE, tmp_path / "stage2.yaml")
    assert set(KUO91_PASSIVE) <= set(p2.start_from)  # stage 2 starts from stage 1's values
    assert not set(KUO91_PASSIVE) & set(p2.parameters)  # ... and keeps them fixed


# ------------------------------------------------------------- 4. spec errors -------------
@pytest.mark.parametrize("edit, key, words", [
    (lambda b: b.update(colour="red"), None, "unknown key(s) ['colour']"),
    (lambda b: b["parameters"]["R1.R"].pop("bounds"), "parameters.R1.R", "'bounds' must be [lower, upper]"),
    (lambda b: b["parameters"]["R1.R"].update(bounds=[0.1, 20]), "parameters.R1.R.bounds", "has no unit"),
    (lambda b: b["parameters"]["R1.R"].update(bounds=["20 mmHg*s/mL", "1 mmHg*s/mL"]), "parameters.R1.R.bounds",
     "is not below the upper bound"),
    (lambda b: b["parameters"].update({"R9.R": {"bounds": ["1 mmHg*s/mL", "2 mmHg*s/mL"]}}), "parameters.R9.R",
     "no element 'R9'"),
    (lambda b: b["datasets"][0].update(column="pressure"), "datasets[0].column", "has no column 'pressure'"),
    (lambda b: b["datasets"][0]["experiment"].update(type="ac"), "datasets[0].experiment", "needs a type"),
    (lambda b: b["datasets"][0].update(observe="Q(nowhere)"), "datasets[0].observe", "neither an output column"),
    (lambda b: b["datasets"][0].update(sigma="0.5 mL"), "datasets[0].sigma", "dimension"),
    (lambda b: b["datasets"][0].update(normalise={"dataset": "other"}), "datasets[0].normalise", "does not exist"),
    (lambda b: b["settings"].update(starts=0), "settings.starts", "positive integer"),
    (lambda b: b["parameters"].update({"Ps.value@3s": {"bounds": ["1 mmHg", "2 mmHg"]}}), "parameters.Ps.value@3s",
     "no tran dataset's protocol sets Ps.value"),
])
def test_spec_errors_name_the_file_and_key(tmp_path, edit, key, words):
    linear_data(tmp_path, noise=0.0)
    body = yaml.safe_load(linear_spec(tmp_path).read_text())
    edit(body)
    spec = write_spec(tmp_path, body, "bad.yaml")
    with pytest.raises(FitSpecError) as exc:
        load_problem(HERE / "linear.yaml", spec)
    msg = str(exc.value)
    assert str(spec) in msg and words in msg, msg
    if key:
        assert key in msg, msg


def test_estimated_parameter_set_by_a_protocol_event_is_rejected(tmp_path):
    write_table(tmp_path / "rc.csv", {"t": np.array([0.0, 1.0]), "P": np.array([0.0, 0.0])}, {"t": "s", "P": "mmHg"})
    spec = write_spec(tmp_path, {
        "parameters": {"R1.R": {"bounds": ["0.5 mmHg*s/mL", "20 mmHg*s/mL"]}},
        "datasets": [{"file": "rc.csv", "observe": "P(a)", "column": "P",
                      "experiment": {"type": "tran", "protocol": str(HERE / "rc_protocol.yaml"), "time": "t"}}]})
    with pytest.raises(FitSpecError, match=r"R1.R@5s"):
        load_problem(HERE / "rc.yaml", spec)


@pytest.mark.parametrize("start", [None, "1 mmHg"])
def test_a_parameter_with_a_waveform_is_not_fitted(tmp_path, start):
    """Ps.value driven by a sine: a fit would replace the sine by a number (with_values), so it
    is an error naming the parameter and the fix, with or without a start."""
    net = tmp_path / "rc_sine.yaml"
    net.write_text((HERE / "rc.yaml").read_text().replace(
        "value: 0 mmHg}", "value: {sine: {offset: 5 mmHg, amplitude: 1 mmHg, frequency: 0.5 Hz}}}"))
    write_table(tmp_path / "rc.csv", {"t": np.array([0.0, 1.0]), "P": np.array([0.0, 0.0])}, {"t": "s", "P": "mmHg"})
    par = {"bounds": ["-10 mmHg", "10 mmHg"], **({"start": start} if start else {})}
    (tmp_path / "run.yaml").write_text("t_end: 2 s\n")
    spec = write_spec(tmp_path, {
        "parameters": {"Ps.value": par},
        "datasets": [{"file": "rc.csv", "observe": "P(a)", "column": "P",
                      "experiment": {"type": "tran", "protocol": "run.yaml", "time": "t"}}]})
    with pytest.raises(hc.NetlistError, match=r"fit: Ps.value carries a waveform .*--set Ps.value=VALUE"):
        load_problem(net, spec)


def test_cli_error_exits_2_without_traceback(tmp_path, capsys):
    linear_data(tmp_path, noise=0.0)
    body = yaml.safe_load(linear_spec(tmp_path).read_text())
    body["datasets"][0]["file"] = "missing.csv"
    spec = write_spec(tmp_path, body)
    assert main(["fit", str(HERE / "linear.yaml"), str(spec), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "data file not found" in err and "datasets[0].file" in err and "Traceback" not in err


# ------------------------------------------------------------- 5. interface ----------------
def test_batched_rms_error_equals_single_evaluations(tmp_path):
    linear_data(tmp_path, noise=0.3, seed=1)
    problem = load_problem(HERE / "linear.yaml", linear_spec(tmp_path))
    vals = {"Ps.value": np.array([9.0, 10.0, 11.0]), "R1.R": np.array([2.0, 2.5, 1.5])}
    batch = problem.rms_error(vals)
    single = [problem.rms_error({k: v[i] for k, v in vals.items()})[0] for i in range(3)]
    assert batch == pytest.approx(single, rel=1e-12)
    R = problem.residuals(vals)
    assert R.shape == (3, problem.n_residuals)
    Q, P = problem.datasets[0].table.columns["Q"], problem.datasets[0].table.columns["P"]
    assert R[0] == pytest.approx((9.0 + 2.0 * Q - P) / 0.5, rel=1e-10)   # (model - data) / sigma
    lo, hi = problem.bounds
    assert list(lo) == [-50.0, 0.1] and list(hi) == [50.0, 20.0]


# ------------------------------------------------------------- 6. docs/fitting.md example ---
def test_docs_worked_example_runs(tmp_path, capsys):
    out = tmp_path / "stage1"
    assert main(["fit", str(ARTERIOLE), str(EXAMPLES / "kuo91_1_passive.yaml"), "--starts", "1", "--max-nfev", "30",
                 "--workers", "1", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "art.q1" in text and "rms passive" in text
    assert os.path.exists(out / "fit.png") and os.path.exists(out / "fitted.yaml")
    assert main(["op", str(out / "fitted.yaml"), "--set", "art.passive=true"]) == 0


def test_a_parameter_set_without_operating_point_gives_nan_not_an_error(tmp_path):
    """A failed member is NaN in rms_error (the sensitivity analysis excludes it), the others
    are unaffected."""
    problem = load_problem(ARTERIOLE, EXAMPLES / "kuo91_1_passive.yaml")
    vals = {k: np.array([v, v]) for k, v in KUO91_PASSIVE.items()}
    vals["art.q1"] = np.array([KUO91_PASSIVE["art.q1"], 1e-30])   # no stiffness: no equilibrium in range
    rms = problem.rms_error(vals)
    assert rms[0] < 1e-6 and np.isnan(rms[1])


def test_nearby_sets_of_a_batch_are_warm_started_and_equal_cold_solves(monkeypatch):
    """A constellation star (a point and 0.1 % steps of it) in one batch: the steps start from
    the point's solution (one cold solve for the star), the results equal separate cold solves."""
    from hemocircuit.fitting import experiments

    keys = np.array([[1.0, 2.0], [1.001, 2.0], [1.0, 2.002], [1.5, 2.0], [1.5, 2.001], [1.0, 2.0005]])
    assert list(experiments.nearby_anchors(keys)) == [0, 0, 0, 3, 3, 0]
    problem = load_problem(ARTERIOLE, EXAMPLES / "kuo91_1_passive.yaml")
    base = {k: np.array([v, v * 1.001, v, v]) for k, v in KUO91_PASSIVE.items()}
    base["art.q2"][2] *= 1.001
    base["art.q1"][3] *= 1.5                                    # a far set: its own cold solve
    calls = []
    solve = experiments.solve_steady
    monkeypatch.setattr(experiments, "solve_steady", lambda c, X0=None: calls.append((c.B, X0 is None)) or solve(c, X0))
    batch = problem.rms_error(base)
    n = problem.datasets[0].experiment.n
    assert calls == [(2 * n, True), (2 * n, False)]             # anchors cold, the two steps warm
    monkeypatch.setattr(experiments, "nearby_anchors", lambda keys, rel=0.02: np.arange(len(keys)))
    cold = problem.rms_error(base)                              # every set cold
    assert np.all(np.isfinite(batch)) and batch == pytest.approx(cold, rel=1e-9, abs=1e-9)
