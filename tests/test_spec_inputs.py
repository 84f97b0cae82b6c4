"""Fit and sensitivity specs under the one input policy (hemocircuit.spec_inputs): the folders a
spec may read, special files, YAML limits, excerpts instead of file contents in errors, bounded
run counts, clear errors instead of tracebacks or silent NaN, the outputs (mode, re-runs into a
fit's folder, a fitted fragment that loads anywhere), the progress bar's count, and a quick
version of benchmarks/fuzz_specs.py."""
import contextlib
import json
import os
import shutil
import stat
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest
import yaml

from hemocircuit.analyses.fit import fit
from hemocircuit.circuit import load
from hemocircuit.cli import main
from hemocircuit.errors import FitSpecError
from hemocircuit.fitting import load_problem
from hemocircuit.fitting.datasets import write_table
from hemocircuit.results import Result
from hemocircuit.sensitivity import parse_spec, run
from hemocircuit.sensitivity.outputs import FunctionObjective, evaluate, make_objective
from hemocircuit.sensitivity.spec import load_spec as load_sensitivity_spec

from guards import deadline
from paths import ROOT

LINEAR = ROOT / "tests" / "fitting" / "linear.yaml"
ARTERIOLE = ROOT / "netlists" / "isolated_arteriole.yaml"
TOKEN = "SECRET-TOKEN-4f1c9e2ab7d35e60"

pytestmark = pytest.mark.filterwarnings("ignore::RuntimeWarning")


@pytest.fixture
def project(tmp_path):
    """A project folder (pyproject.toml) with the linear netlist, its data and a fit spec, and
    a folder outside it holding a secret."""
    proj = tmp_path / "proj"
    proj.mkdir()
    (proj / "pyproject.toml").write_text("")
    shutil.copy(LINEAR, proj / "linear.yaml")
    q = np.linspace(0.5, 4.0, 8)
    write_table(proj / "line.csv", {"Q": q, "P": 10.0 + 2.0 * q}, {"Q": "mL/s", "P": "mmHg"})
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "secret.csv").write_text(f"{TOKEN} [mmHg],Q [mL/s]\n{TOKEN},1\n")
    (outside / "secret.yaml").write_text(f"change: {{{TOKEN}: 1}}\nevents: [{TOKEN}]\n")
    return proj, outside


def linear_spec(proj, name="spec.yaml", **extra):
    body = {"parameters": {"Ps.value": {"bounds": ["-50 mmHg", "50 mmHg"], "start": "0 mmHg"},
                           "R1.R": {"bounds": ["0.1 mmHg*s/mL", "20 mmHg*s/mL"], "log": True,
                                    "start": "0.5 mmHg*s/mL"}},
            "datasets": [{"name": "line", "file": "line.csv", "observe": "P(b)", "column": "P", "sigma": "0.5 mmHg",
                          "experiment": {"type": "op", "inputs": {"Qs.value": "Q"}}}],
            "settings": {"starts": 1, "seed": 0, "max_nfev": 50, "workers": 1}}
    for k, v in extra.items():
        if k == "dataset":
            body["datasets"][0].update(v)
        elif k == "settings":
            body["settings"].update(v)
        else:
            body[k] = v
    path = proj / name
    path.write_text(yaml.safe_dump(body, sort_keys=False))
    return path


def sens_spec(proj, output, name="sens.yaml", method=None, **extra):
    body = {"method": method or {"name": "constellation", "scheme": "additive", "n": 4},
            "parameters": [{"path": "R1.R", "lower": "1 mmHg*s/mL", "upper": "3 mmHg*s/mL"}], "output": output,
            **extra}
    path = proj / name
    path.write_text(yaml.safe_dump(body, sort_keys=False))
    return path


def assert_clean(msg):
    """Nothing of the outside files in a message."""
    assert TOKEN not in msg and "root:x:0:0" not in msg and "root:*:0:0" not in msg, msg


# ------------------------------------------------------------------ 1. folder policy --------
@pytest.mark.parametrize("name", ["/etc/passwd", "OUTSIDE/secret.csv", "../outside/secret.csv",
                                  "../../../../../../../../../etc/passwd"])
def test_a_data_file_outside_the_allowed_folders_is_refused_before_reading(project, name):
    proj, outside = project
    spec = linear_spec(proj, dataset={"file": name.replace("OUTSIDE", str(outside))})
    with pytest.raises(FitSpecError) as exc:
        load_problem(proj / "linear.yaml", spec)
    msg = str(exc.value)
    assert str(spec) in msg and "datasets[0].file" in msg and "outside the allowed folders" in msg, msg
    assert "--allow-path" in msg
    assert_clean(msg)


def test_start_from_and_a_tran_protocol_outside_are_refused(project):
    proj, outside = project
    spec = linear_spec(proj, start_from=str(outside / "secret.yaml"))
    with pytest.raises(FitSpecError, match=r"start_from: the fitted fragment .* outside the allowed folders") as exc:
        load_problem(proj / "linear.yaml", spec)
    assert_clean(str(exc.value))
    shutil.copy(ROOT / "tests" / "fitting" / "rc.yaml", proj / "rc.yaml")
    write_table(proj / "rc.csv", {"t": np.array([0.0, 1.0, 2.0]), "P": np.array([0.0, 1.0, 2.0])},
                {"t": "s", "P": "mmHg"})
    spec = proj / "rc_spec.yaml"
    spec.write_text(yaml.safe_dump({
        "parameters": {"C1.C": {"bounds": ["0.1 mL/mmHg", "2 mL/mmHg"]}},
        "datasets": [{"file": "rc.csv", "observe": "P(a)", "column": "P",
                      "experiment": {"type": "tran", "protocol": str(outside / "secret.yaml"), "time": "t"}}]}))
    with pytest.raises(FitSpecError, match=r"datasets\[0\]\.experiment\.protocol: the protocol file .* outside") as exc:
        load_problem(proj / "rc.yaml", spec)
    assert_clean(str(exc.value))


def test_sensitivity_protocol_and_fit_error_outside_are_refused(project):
    proj, outside = project
    c = load(str(proj / "linear.yaml"))
    for output, key in (({"tran": {"column": "P(b)", "protocol": str(outside / "secret.yaml"), "times": "0:2:1 s"}},
                         "output.tran.protocol"),
                        ({"fit_error": "../outside/secret.yaml"}, "output.fit_error")):
        spec = sens_spec(proj, output)
        with pytest.raises(FitSpecError) as exc:
            s = load_sensitivity_spec(str(spec))
            make_objective(s, c, str(proj / "linear.yaml"))
        msg = str(exc.value)
        assert str(spec) in msg and key in msg and "outside the allowed folders" in msg, msg
        assert_clean(msg)


def test_allow_paths_admits_a_folder_and_errors_quote_only_a_short_excerpt(project):
    """A data file in an allowed folder whose cell or header holds a long line: the error names
    the line and column and quotes a short excerpt, never the whole line."""
    proj, outside = project
    long_cell = "x" * 200 + TOKEN
    (outside / "cells.csv").write_text(f"Q [mL/s],P [mmHg]\n1,12\n2,{long_cell}\n")
    spec = linear_spec(proj, dataset={"file": str(outside / "cells.csv")})
    with pytest.raises(FitSpecError) as exc:
        load_problem(proj / "linear.yaml", spec, allow_paths=[outside])
    msg = str(exc.value)
    assert "datasets[0].file" in msg and "data line 3" in msg and "'P'" in msg and "is not a number" in msg, msg
    assert_clean(msg)
    assert len(msg) < 600
    (outside / "header.csv").write_text(f"{'h' * 100}{TOKEN}\n1\n2\n")
    spec = linear_spec(proj, dataset={"file": str(outside / "header.csv")})
    with pytest.raises(FitSpecError, match=r"datasets\[0\]\.experiment\.inputs\.Qs\.value: .* has no column 'Q'") as exc:
        load_problem(proj / "linear.yaml", spec, allow_paths=[outside])
    assert_clean(str(exc.value))


def test_special_files_are_refused_without_blocking(project):
    proj, _ = project
    os.mkfifo(proj / "fifo.csv")
    os.mkfifo(proj / "fifo.yaml")
    with deadline(20):
        for extra in ({"dataset": {"file": "fifo.csv"}}, {"start_from": "fifo.yaml"}):
            with pytest.raises(FitSpecError, match="not a regular file"):
                load_problem(proj / "linear.yaml", linear_spec(proj, **extra))
        with pytest.raises(FitSpecError, match="not a regular file"):
            load_problem(proj / "linear.yaml", proj / "fifo.yaml")          # the spec itself
        with pytest.raises(FitSpecError, match="not a regular file"):
            load_sensitivity_spec(str(proj / "fifo.yaml"))
        with pytest.raises(FitSpecError, match="outside the allowed folders"):
            load_problem(proj / "linear.yaml", linear_spec(proj, dataset={"file": "/dev/zero"}))
        with pytest.raises(FitSpecError, match=r"output.fit_error: .*not a regular file"):
            make_objective(load_sensitivity_spec(str(sens_spec(proj, {"fit_error": "fifo.yaml"}))),
                           load(str(proj / "linear.yaml")), str(proj / "linear.yaml"))


_BOMB = ("description:\n" + "".join(
    f"  - &a{i} [" + ", ".join([f"*a{i - 1}" if i else '"lol"'] * 9) + "]\n" for i in range(9)) + "  - *a8\n")


@pytest.mark.parametrize("kind", ["fit", "sensitivity"])
def test_an_alias_bomb_in_a_spec_is_refused_quickly(project, kind):
    """The YAML limits of netlists apply to specs: a billion laughs in ``description:`` is
    refused (in a child process with a time and memory limit: unguarded, it expands to GiBs)."""
    proj, _ = project
    base = linear_spec(proj) if kind == "fit" else sens_spec(proj, {"op": {"column": "P(b)"}})
    spec = proj / "bomb.yaml"
    spec.write_text(base.read_text() + _BOMB)
    code = textwrap.dedent(f"""
        import resource, sys
        resource.setrlimit(resource.RLIMIT_AS, (3 * 2 ** 30, 3 * 2 ** 30))
        from hemocircuit.errors import HemocircuitError
        try:
            if {kind!r} == "fit":
                from hemocircuit.fitting import load_problem
                load_problem({str(proj / 'linear.yaml')!r}, {str(spec)!r})
            else:
                from hemocircuit.sensitivity.spec import load_spec
                load_spec({str(spec)!r})
        except HemocircuitError as exc:
            print(exc)
            sys.exit(2)
        """)
    t0 = time.perf_counter()
    try:
        r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    except subprocess.TimeoutExpired:
        pytest.fail("the spec with an alias bomb was still being read after 60 s")
    assert r.returncode == 2, r.stderr[-2000:]
    assert "HEMOCIRCUIT_MAX_YAML_NODES" in r.stdout and str(spec) in r.stdout, r.stdout
    assert time.perf_counter() - t0 < 30


# ------------------------------------------------------------------ 2. outputs ---------------
@contextlib.contextmanager
def umask(mask):
    old = os.umask(mask)
    try:
        yield
    finally:
        os.umask(old)


def _modes(folder):
    return {f: stat.S_IMODE(os.stat(os.path.join(folder, f)).st_mode) for f in os.listdir(folder)}


def test_fit_outputs_get_the_usual_mode_and_leave_no_temporary_files(project):
    proj, _ = project
    with umask(0o022):
        _, _, paths = fit(proj / "linear.yaml", linear_spec(proj), out=proj / "out")
    modes = _modes(proj / "out")
    assert {"report.json", "fitted.yaml", "fit.csv", "fit.png"} <= set(modes)
    assert set(modes.values()) == {0o644}, modes


def test_sensitivity_outputs_get_the_usual_mode(tmp_path):
    from hemocircuit.analyses.sensitivity import write_outputs

    s = parse_spec({"method": {"name": "constellation", "scheme": "additive", "n": 6},
                    "parameters": [{"path": "x", "lower": 0, "upper": 1}], "output": {"function": None}})
    res = run(s, FunctionObjective(lambda v: np.where(v["x"] > 0.9, np.nan, v["x"] ** 2)), scheduler="serial")
    assert res.failures
    with umask(0o022):
        written = write_outputs(res, str(tmp_path / "t.csv"), str(tmp_path / "t.png"), None, str(tmp_path / "f.csv"))
    assert len(written) == 3
    assert set(_modes(tmp_path).values()) == {0o644}, _modes(tmp_path)


def test_a_fit_runs_again_into_its_own_folder_but_not_over_other_files(project, capsys):
    proj, _ = project
    spec, out = linear_spec(proj), proj / "out"
    argv = ["fit", str(proj / "linear.yaml"), str(spec), "--out", str(out), "--no-plot", "--quiet"]
    assert main(argv) == 0
    first = json.loads((out / "report.json").read_text())
    assert main(argv) == 0                                        # the same folder again: replaced
    second = json.loads((out / "report.json").read_text())
    assert first["parameters"][0]["value"] == second["parameters"][0]["value"]
    assert not [f for f in os.listdir(out) if f.startswith(".")]
    (out / "notes.txt").write_text("mine")
    capsys.readouterr()
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "notes.txt" in err and "--out" in err and "Traceback" not in err
    assert (out / "notes.txt").read_text() == "mine"
    assert main(argv[:3] + ["--out", str(spec), "--no-plot"]) == 2   # a file, not a folder
    assert "not a folder" in capsys.readouterr().err


def test_a_fitted_fragment_written_outside_the_project_loads(project, tmp_path, capsys):
    """The netlist (tests/fitting/linear.yaml, in this repository's project) cannot be read from
    /tmp by a netlist there: fitted.yaml extends a copy written beside it, and loads."""
    proj, _ = project
    out = tmp_path / "elsewhere" / "fit"
    os.makedirs(out.parent)
    _, res, paths = fit(LINEAR, linear_spec(proj), out=out, plot=False)
    assert res["p"] == pytest.approx([10.0, 2.0], rel=1e-6)
    capsys.readouterr()
    assert main(["op", str(out / "fitted.yaml"), "--out", str(tmp_path / "op.json")]) == 0, capsys.readouterr().err
    op = Result.load(str(tmp_path / "op.json"))
    assert float(np.ravel(op["P(b)"])[0]) == pytest.approx(10.0 + 2.0 * 1.0, rel=1e-6)   # P0 + R Q at Q = 1 mL/s
    # a later stage may start from it (its folder allowed)
    stage2 = linear_spec(proj, "stage2.yaml", start_from=str(out / "fitted.yaml"))
    problem = load_problem(LINEAR, stage2, allow_paths=[out])
    assert problem.start_from["R1.R"].startswith("2") and problem.start_from["Ps.value"].startswith("10")
    # inside the netlist's project the fragment extends the netlist itself
    _, _, paths = fit(proj / "linear.yaml", linear_spec(proj), out=proj / "fit", plot=False)
    assert yaml.safe_load((proj / "fit" / "fitted.yaml").read_text())["extends"] == "../linear.yaml"
    assert "netlist" not in paths


# ------------------------------------------------------------------ 3. bounded counts -------
@pytest.mark.parametrize("method, key, limit", [
    ({"name": "constellation", "n": 2 ** 40}, "method.n", "SENS_RUNS"),
    ({"name": "constellation", "n": 100, "designs": 2 ** 40}, "method.designs", "SENS_DESIGNS"),
    ({"name": "constellation", "n": 100_000, "designs": 1000}, "method.designs", "SENS_DESIGN_POINTS"),
    ({"name": "dynamic", "n": 2 ** 40}, "method.n", "SENS_RUNS"),
    ({"name": "morris", "trajectories": 2 ** 40}, "method.trajectories", "SENS_RUNS"),
    ({"name": "sobol", "n": 2 ** 40}, "method.n", "SENS_RUNS"),
    ({"name": "sobol", "n": 1024, "resamples": 2 ** 40}, "method.resamples", "SENS_RESAMPLES"),
])
def test_sensitivity_counts_are_bounded_by_named_limits(method, key, limit):
    output = {"tran": {"column": "x"}} if method["name"] == "dynamic" else {"function": None}
    with deadline(20), pytest.raises(FitSpecError) as exc:
        parse_spec({"method": method, "parameters": [{"path": "x", "lower": 0, "upper": 1}], "output": output},
                   "s.yaml")
    msg = str(exc.value)
    assert key in msg and f"HEMOCIRCUIT_MAX_{limit}" in msg and "s.yaml" in msg, msg


def test_run_count_with_the_parameters_known_is_bounded_and_the_limit_can_be_raised(monkeypatch):
    from hemocircuit.sensitivity import prepare

    params = [{"path": f"x{i}", "lower": 0, "upper": 1} for i in range(9)]
    data = {"method": {"name": "constellation", "scheme": "additive", "n": 200_000, "designs": 1}, "parameters": params,
            "output": {"function": None}}                          # 2e5 x (9 + 1) runs
    match = r"method.n: .*2,000,000 model evaluations for k = 9.*HEMOCIRCUIT_MAX_SENS_RUNS"
    with pytest.raises(FitSpecError, match=match):
        parse_spec(data, "s.yaml")
    monkeypatch.setenv("HEMOCIRCUIT_MAX_SENS_RUNS", "3000000")
    s = parse_spec(data, "s.yaml")
    obj = FunctionObjective(lambda v: v["x0"])
    space, runs = prepare(s, obj)
    assert runs == 2_000_000 and space.k == 9
    monkeypatch.setenv("HEMOCIRCUIT_MAX_SENS_RUNS", "1000000")
    with pytest.raises(FitSpecError, match=match):                 # checked again before the runs
        prepare(s, obj)


def test_fit_starts_are_bounded_and_the_limit_can_be_raised(project, monkeypatch):
    proj, _ = project
    spec = linear_spec(proj, settings={"starts": 2 ** 40})
    with deadline(20), pytest.raises(FitSpecError, match=r"settings.starts: .*HEMOCIRCUIT_MAX_FIT_STARTS"):
        load_problem(proj / "linear.yaml", spec)
    monkeypatch.setenv("HEMOCIRCUIT_MAX_FIT_STARTS", str(2 ** 41))
    assert load_problem(proj / "linear.yaml", spec).spec.settings["starts"] == 2 ** 40


def test_fit_data_rows_are_bounded(project, monkeypatch):
    proj, _ = project
    monkeypatch.setenv("HEMOCIRCUIT_MAX_FIT_ROWS", "5")
    with pytest.raises(FitSpecError, match=r"datasets: data rows in all datasets: 8.*HEMOCIRCUIT_MAX_FIT_ROWS"):
        load_problem(proj / "linear.yaml", linear_spec(proj))


# ------------------------------------------------------------------ 4. errors, not tracebacks --
@pytest.mark.parametrize("output, method, key, words", [
    ({"op": {"column": "P(b)", "at": []}}, None, "output.op.at", "non-empty list"),
    ({"op": {"column": "P(b)"}}, {"name": "sobol", "n": 4, "conf_level": "abc"}, "method.conf_level",
     "confidence level"),
    ({"op": {"column": ["P(b)", [1]]}}, None, "output.op.column", "output column"),
    ({"tran": {"column": "P(b)", "protocol": "p.yaml", "times": "0:2:1 s", "rtol": "tight"}}, None,
     "output.tran.rtol", "relative tolerance"),
    ({"freq": {"column": "P(b)", "step": "big"}}, None, "output.freq.step", "percentage"),
])
def test_sensitivity_spec_mistakes_are_errors_naming_the_key(project, output, method, key, words):
    proj, _ = project
    (proj / "p.yaml").write_text("t_end: 2 s\n")
    spec = sens_spec(proj, output, method=method)
    with pytest.raises(FitSpecError) as exc:
        s = load_sensitivity_spec(str(spec))
        run(s, make_objective(s, load(str(proj / "linear.yaml")), str(proj / "linear.yaml")), scheduler="serial")
    msg = str(exc.value)
    assert str(spec) in msg and key in msg and words in msg, msg


def test_sensitivity_seed_minus_one_is_a_clear_cli_error(project, capsys):
    proj, _ = project
    spec = sens_spec(proj, {"op": {"column": "P(b)"}})
    assert main(["sensitivity", str(proj / "linear.yaml"), str(spec), "--seed", "-1", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and "seed" in err and "--seed" in err and "non-negative" in err, err


def test_sensitivity_bad_scheduler_and_workers_are_clear_cli_errors(project, capsys):
    proj, _ = project
    spec = sens_spec(proj, {"op": {"column": "P(b)"}})
    for extra, words in ((["--scheduler", "bogus"], "--scheduler 'bogus'"), (["--workers", "-1"], "--workers")):
        assert main(["sensitivity", str(proj / "linear.yaml"), str(spec), "--quiet"] + extra) == 2
        err = capsys.readouterr().err
        assert "Traceback" not in err and words in err, err


@pytest.mark.parametrize("extra, key, words", [
    ({"settings": {"workers": "many"}}, "settings.workers", "expected an integer"),
    ({"settings": {"ftol": "tight"}}, "settings.ftol", "tolerance"),
    ({"settings": {"seed": -1}}, "settings.seed", "non-negative"),
    ({"dataset": {"file": "latin1.csv"}}, "datasets[0].file", "not UTF-8"),
    ({"dataset": {"observe": ["P(b)"]}}, "datasets[0].observe", "output column"),
    ({"dataset": {"weight": float("inf")}}, "datasets[0].weight", "finite"),
    ({"dataset": {"file": None}}, "datasets[0].file", "name of a data file"),
])
def test_fit_spec_mistakes_are_errors_naming_the_key(project, extra, key, words):
    proj, _ = project
    (proj / "latin1.csv").write_bytes("Q [mL/s],P [mmHg]\n# caf\xe9\n1,12\n2,14\n".encode("latin-1"))
    spec = linear_spec(proj, **extra)
    with pytest.raises(FitSpecError) as exc:
        load_problem(proj / "linear.yaml", spec)
    msg = str(exc.value)
    assert str(spec) in msg and key in msg and words in msg, msg


def test_fit_cli_overrides_are_checked(project, capsys):
    proj, _ = project
    spec = linear_spec(proj)
    base = ["fit", str(proj / "linear.yaml"), str(spec), "--out", str(proj / "o"), "--no-plot", "--quiet"]
    for extra, words in ((["--seed", "-1"], "--seed"), (["--max-nfev", "0"], "--max-nfev"),
                         (["--workers", "-2"], "--workers"), (["--starts", str(2 ** 40)], "FIT_STARTS")):
        assert main(base + extra) == 2
        err = capsys.readouterr().err
        assert words in err and "Traceback" not in err, err


# ------------------------------------------------------------------ 5. nothing silent --------
@pytest.mark.parametrize("extra, key, words", [
    ({"tied": {"Qs.value": "2 * Qs.value"}}, "tied.Qs.value", "tied to itself"),
    ({"parameters": {"R1.R": {"bounds": ["0.1 mmHg*s/mL", "20 mmHg*s/mL"], "start": "50 mmHg*s/mL"}}},
     "parameters.R1.R.start", "outside the bounds"),
    ({"parameters": {"R1.R": {"bounds": ["0.1 mmHg*s/mL", "inf mmHg*s/mL"]}}}, "parameters.R1.R.bounds", "finite"),
    ({"parameters": {"R1.R": {"bounds": ["-1 mmHg*s/mL", "20 mmHg*s/mL"]}}}, "parameters.R1.R.bounds",
     "not a value R1.R may take"),
    ({"dataset": {"file": "one.csv"}}, "datasets", "fewer than the 2 estimated parameters"),
    ({"dataset": {"normalise": {"row": 0}, "file": "zero.csv"}}, "datasets[0].normalise", "whose value is 0"),
])
def test_what_was_accepted_silently_is_a_clear_error(project, extra, key, words):
    proj, _ = project
    (proj / "one.csv").write_text("Q [mL/s],P [mmHg]\n1,12\n")
    (proj / "zero.csv").write_text("Q [mL/s],P [mmHg]\n1,0\n2,14\n3,16\n")
    spec = linear_spec(proj, **extra)
    with pytest.raises(FitSpecError) as exc:
        load_problem(proj / "linear.yaml", spec)
    msg = str(exc.value)
    assert str(spec) in msg and key in msg and words in msg, msg


def test_tied_to_a_tied_parameter_is_an_error(project):
    proj, _ = project
    spec = linear_spec(proj, tied={"Qs.value": "1 mL/s", "Ps.value": "Qs.value * 1 mmHg*s/mL"})
    spec_body = yaml.safe_load(spec.read_text())
    spec_body["parameters"].pop("Ps.value")
    spec.write_text(yaml.safe_dump(spec_body))
    with pytest.raises(FitSpecError, match=r"tied.Ps.value: .*refers to Qs.value, which is tied too"):
        load_problem(proj / "linear.yaml", spec)


def test_as_many_rows_as_parameters_gives_valid_json_with_null_standard_errors(project):
    proj, _ = project
    (proj / "two.csv").write_text("Q [mL/s],P [mmHg]\n1,12\n2,14\n")
    _, res, paths = fit(proj / "linear.yaml", linear_spec(proj, dataset={"file": "two.csv"}), out=proj / "o",
                        plot=False)
    assert res["dof"] == 0
    text = open(paths["report"]).read()
    report = json.loads(text, parse_constant=lambda c: pytest.fail(f"{c} in report.json"))
    assert [p["se"] for p in report["parameters"]] == [None, None]
    assert report["residual_variance"] is None
    assert [p["value"] for p in report["parameters"]] == pytest.approx([10.0, 2.0], rel=1e-6)


# ------------------------------------------------------------------ 6. progress --------------
def test_the_progress_bar_counts_model_evaluations_not_chunks(capsys):
    obj = FunctionObjective(lambda v: v["x"])
    B = 1200
    Y, errors = evaluate(obj, {"x": np.arange(B, dtype=float)}, scheduler="serial", progress=True, max_chunk=500)
    assert Y[:, 0] == pytest.approx(np.arange(B)) and errors == [None] * B
    err = capsys.readouterr().err
    assert "model evaluations" in err and f"{B}/{B}" in err, err


# ------------------------------------------------------------------ 7. fuzz, quick -----------
def test_fuzzed_specs_give_clean_errors_only(tmp_path):
    """benchmarks/fuzz_specs.py, quick: 60 mutated specs, parsed and validated against their
    netlists in child processes with time and memory limits."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    try:
        import fuzz_specs
    finally:
        sys.path.remove(str(ROOT / "benchmarks"))
    t0 = time.perf_counter()
    report = fuzz_specs.run(60, seed=11, folder=str(tmp_path / "fuzz"), jobs=1, mode="load", quiet=True)
    assert report["cases"] == 60
    bad = {k: report["counts"][k] for k in fuzz_specs.BAD}
    assert not any(bad.values()), (bad, report["examples"])
    assert report["counts"]["accepted"] >= 5                    # the mild variants are valid specs
    assert time.perf_counter() - t0 < 60
