"""svZeroDSolver models and result files as inputs: every read under the input policy
(hemocircuit.inputs), clear errors naming the block and key instead of tracebacks or silent
acceptance, bounds on the run's size, an importer linear in the model's size, the output
written atomically, and a quick sample of benchmarks/fuzz_svzerod.py.  Their shared cases are
read from ../shared/svzerod when present (skipped otherwise), never copied."""
from __future__ import annotations

import builtins
import copy
import io
import json
import os
import shutil
import sys
import time

import pytest

from paths import SHARED_SVZEROD as SHARED

from hemocircuit import inputs
from hemocircuit.cli import main
from hemocircuit.errors import HemocircuitError, NetlistError
from hemocircuit.svzerod import import_svzerod, write_netlist

have_cases = pytest.mark.skipif(not os.path.isdir(os.path.join(SHARED, "cases")),
                                reason="svZeroDSolver test cases not present")
SIM = {"number_of_cardiac_cycles": 2, "number_of_time_pts_per_cardiac_cycle": 5}


def _model(**changes):
    """A small valid model: FLOW -> vessel -> RCR (a pulsatile inflow)."""
    cfg = {"simulation_parameters": dict(SIM),
           "vessels": [{"vessel_name": "v", "vessel_id": 0, "zero_d_element_type": "BloodVessel",
                        "zero_d_element_values": {"R_poiseuille": 100.0},
                        "boundary_conditions": {"inlet": "IN", "outlet": "OUT"}}],
           "boundary_conditions": [
               {"bc_name": "IN", "bc_type": "FLOW", "bc_values": {"Q": [1.0, 3.0, 1.0], "t": [0.0, 0.4, 1.0]}},
               {"bc_name": "OUT", "bc_type": "RCR", "bc_values": {"Rp": 100.0, "C": 1e-3, "Rd": 900.0, "Pd": 0.0}}]}
    cfg.update(changes)
    return cfg


def _write(path, cfg):
    path.write_text(json.dumps(cfg))
    return str(path)


@pytest.fixture
def no_bare_reads(monkeypatch):
    """Reading any file of the folder ``watch`` with builtins.open / io.open fails the test: those
    reads must go through hemocircuit.inputs (which opens with os.open and records the file)."""
    watched = []
    real_open = builtins.open

    def guarded(file, mode="r", *args, **kwargs):
        if isinstance(file, (str, os.PathLike)) and not any(c in mode for c in "wax+"):
            real = os.path.realpath(os.fspath(file))
            if any(real.startswith(w) for w in watched):
                raise AssertionError(f"bare open() of {file}: read it through hemocircuit.inputs")
        return real_open(file, mode, *args, **kwargs)

    monkeypatch.setattr(builtins, "open", guarded)
    monkeypatch.setattr(io, "open", guarded)
    return watched


# ------------------------------------------------------------------ 1. every read under the policy ----------
def _case_folder(tmp_path, result=None, readme="| case | points | time |\n|---|---|---|\n| m | 5 x 2 | 1 ms |\n"):
    folder = tmp_path / "suite"
    (folder / "cases").mkdir(parents=True)
    (folder / "converged").mkdir()
    _write(folder / "cases" / "m.json", _model())
    if result is not None:
        (folder / "converged" / "result_m.json").write_text(result)
    (folder / "README.md").write_text(readme)
    return folder


@pytest.mark.parametrize("content, what", [
    ("{not json", "not valid JSON"),
    ('{"name": {"0": "v"}, "time": {"0": 0.0}}', "'flow_in' is missing"),
    ('{"name": {"0": "v"}, "time": {"0": 0.0}, "y": {"0": NaN}}', "NaN"),
    ('{"name": {"x": "v"}, "time": {"x": 0.0}, "y": {"x": 1.0}}', "numbered"),
    ('{"name": {"0": "v"}, "time": {"0": 0.0}, "y": {"0": "abc"}}', "'y' of row 0"),
    ('[1, 2]', "a JSON object is expected"),
])
def test_a_malformed_result_file_is_the_cases_error_naming_the_file(tmp_path, content, what):
    """conformance read result files with json.load: a malformed one was a traceback (or, with
    NaN, a silent comparison).  Now read_result says what is wrong, naming the file, and the
    runner reports it as the case's note."""
    from hemocircuit.svzerod.conformance import read_result, run_case

    folder = _case_folder(tmp_path, content)
    path = str(folder / "converged" / "result_m.json")
    with pytest.raises(NetlistError, match=what) as exc:
        read_result(path)
    assert path in str(exc.value) and "Traceback" not in str(exc.value)
    r = run_case(str(folder / "cases" / "m.json"), "converged")
    assert not r.ok and path in r.note and what.split("'")[0] in r.note


def test_conformance_reads_case_result_and_readme_under_the_policy(tmp_path, no_bare_reads):
    """Every file the runner reads (the case, its result, the README) goes through
    hemocircuit.inputs: recorded, no bare open(); a case linked from outside the folder is refused."""
    from hemocircuit.svzerod.conformance import run_case

    folder = _case_folder(tmp_path, '{"name": {"0": "v"}, "time": {"0": 0.0}, "y": {"0": 1.0}}')
    no_bare_reads.append(os.path.realpath(folder))
    with inputs.recording() as src:
        r = run_case(str(folder / "cases" / "m.json"), "converged")
    assert r.theirs == "1 ms"
    assert {os.path.realpath(folder / p) for p in ("cases/m.json", "converged/result_m.json", "README.md")} <= \
        set(src.paths), src.paths
    outside = tmp_path / "elsewhere.json"
    _write(outside, _model())
    os.symlink(outside, folder / "cases" / "linked.json")
    r = run_case(str(folder / "cases" / "linked.json"), "converged")
    assert "outside the allowed folders" in r.note


def test_tran_svzerod_output_and_periodic_read_the_model_under_the_policy(tmp_path, monkeypatch, no_bare_reads,
                                                                          capsys):
    """tran --svzerod-output and periodic re-read the model JSON with open/json.load: a model over
    the size limit ran anyway, NaN was accepted.  Now the read is the policy's (size, NaN, record)."""
    folder = tmp_path / "m"
    folder.mkdir()
    no_bare_reads.append(os.path.realpath(folder))
    path = _write(folder / "m.json", _model())
    assert main(["tran", path, "--svzerod-output", str(tmp_path / "r.json"), "--quiet"]) == 0
    assert main(["periodic", path, "--forced", "--quiet"]) == 0
    capsys.readouterr()
    big = _model(_comment="x" * (3 * 2 ** 20 // 2))  # 1.5 MiB
    path = _write(folder / "big.json", big)
    monkeypatch.setenv("HEMOCIRCUIT_MAX_FILE_MB", "1")
    assert main(["tran", path, "--svzerod-output", str(tmp_path / "r2.json"), "--quiet"]) == 2
    assert "HEMOCIRCUIT_MAX_FILE_MB" in capsys.readouterr().err
    assert not os.path.exists(tmp_path / "r2.json")


def test_a_nan_in_the_models_json_is_refused_by_every_command(tmp_path, capsys):
    text = json.dumps(_model()).replace("3.0", "NaN")
    path = tmp_path / "m.json"
    path.write_text(text)
    for argv in (["tran", str(path), "--svzerod-output", str(tmp_path / "r.json")], ["check", str(path)],
                 ["import-svzerod", str(path), "-o", str(tmp_path / "m.yaml")]):
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert "NaN is not a JSON number" in err and str(path) in err, (argv, err)


# ------------------------------------------------------------------ 2. import-svzerod -o ----------
def test_write_netlist_never_writes_through_a_link_leading_elsewhere(tmp_path):
    """write_netlist opened its path for writing: a symbolic link to a file in another folder was
    written through (the target replaced).  Now the io policy's: refused, the target intact."""
    other = tmp_path / "other"
    other.mkdir()
    target = other / "precious.txt"
    target.write_text("keep me")
    out = tmp_path / "out"
    out.mkdir()
    os.symlink(target, out / "m.yaml")
    nl = import_svzerod(_model()).netlist
    with pytest.raises(HemocircuitError, match="symbolic link"):
        write_netlist(nl, str(out / "m.yaml"))
    assert target.read_text() == "keep me"
    assert main(["import-svzerod", _write(tmp_path / "m.json", _model()), "-o", str(out / "m.yaml")]) == 2
    assert target.read_text() == "keep me"


def test_write_netlist_is_atomic_and_0644(tmp_path):
    """An interrupted write (here: a value YAML cannot represent) leaves the previous file whole,
    not a truncated one; the file gets the usual permissions."""
    path = tmp_path / "m.yaml"
    path.write_text("previous: netlist\n")
    with pytest.raises(Exception):
        write_netlist({"name": "x", "elements": [{"id": "a", "bad": object()}]}, str(path))
    assert path.read_text() == "previous: netlist\n"
    assert sorted(os.listdir(tmp_path)) == ["m.yaml"]  # no temporary left behind
    old = os.umask(0o022)
    try:
        write_netlist(import_svzerod(_model()).netlist, str(path))
    finally:
        os.umask(old)
    assert oct(os.stat(path).st_mode & 0o777) == "0o644"
    from hemocircuit.circuit import load
    assert load(str(path)).nx > 0


# ------------------------------------------------------------------ 3./4. clear errors ----------
def _bc(cfg, name):
    return next(b for b in cfg["boundary_conditions"] if b["bc_name"] == name)


def _mutated(change):
    cfg = copy.deepcopy(_model())
    change(cfg)
    return cfg


BAD_MODELS = [  # (what, change, words the message must hold)
    ("cycles None", lambda c: c["simulation_parameters"].update(number_of_cardiac_cycles=None),
     ["number_of_cardiac_cycles", "whole number", "None"]),
    ("cycles 2.5", lambda c: c["simulation_parameters"].update(number_of_cardiac_cycles=2.5),
     ["number_of_cardiac_cycles", "not a whole number", "2.5"]),
    ("cycles -3", lambda c: c["simulation_parameters"].update(number_of_cardiac_cycles=-3),
     ["number_of_cardiac_cycles", ">= 1"]),
    ("cycles inf", lambda c: c["simulation_parameters"].update(number_of_cardiac_cycles=float("inf")),
     ["number_of_cardiac_cycles", "inf"]),
    ("cycles 10**400", lambda c: c["simulation_parameters"].update(number_of_cardiac_cycles=10 ** 400),
     ["number_of_cardiac_cycles", "SVZEROD_POINTS"]),
    ("points 0", lambda c: c["simulation_parameters"].update(number_of_time_pts_per_cardiac_cycle=0),
     ["number_of_time_pts_per_cardiac_cycle", ">= 2"]),
    ("points -5", lambda c: c["simulation_parameters"].update(number_of_time_pts_per_cardiac_cycle=-5),
     ["number_of_time_pts_per_cardiac_cycle", ">= 2"]),
    ("points 1e-30", lambda c: c["simulation_parameters"].update(number_of_time_pts_per_cardiac_cycle=1e-30),
     ["number_of_time_pts_per_cardiac_cycle", "1e-30"]),
    ("sim not a mapping", lambda c: c.update(simulation_parameters=5.0), ["simulation_parameters", "mapping"]),
    ("bc_values a float", lambda c: _bc(c, "OUT").update(bc_values=1.0), ["'OUT'", "bc_values", "mapping"]),
    ("vessel values a float", lambda c: c["vessels"][0].update(zero_d_element_values=2.0),
     ["'v'", "zero_d_element_values", "mapping"]),
    ("a block a float", lambda c: c["boundary_conditions"].append(3.0), ["boundary_conditions[2]", "mapping"]),
    ("section a float", lambda c: c.update(junctions=1.5), ["junctions", "list"]),
    ("unhashable name", lambda c: _bc(c, "OUT").update(bc_name=["OUT"]), ["bc_name", "non-empty string"]),
    ("unhashable inlet", lambda c: c["vessels"][0]["boundary_conditions"].update(inlet=["IN"]),
     ["'v'", "boundary_conditions.inlet"]),
    ("value 10**400", lambda c: _bc(c, "OUT")["bc_values"].update(Rd=10 ** 400),
     ["'OUT'", "'Rd'", "finite number", "digits"]),
    ("value inf", lambda c: c["vessels"][0]["zero_d_element_values"].update(C=float("inf")),
     ["'v'", "'C'", "finite number"]),
    ("value a string", lambda c: c["vessels"][0]["zero_d_element_values"].update(R_poiseuille="100"),
     ["'v'", "'R_poiseuille'", "finite number"]),
    ("NaN in a time series", lambda c: _bc(c, "IN")["bc_values"]["Q"].__setitem__(1, float("nan")),
     ["'IN'", "'Q[1]'", "finite number", "nan"]),
    ("a string in the times", lambda c: _bc(c, "IN")["bc_values"]["t"].__setitem__(1, "0.4"),
     ["'IN'", "'t[1]'", "finite number"]),
    ("period 1e300 (times)", lambda c: _bc(c, "IN")["bc_values"].update(t=[0.0, 0.4, 1e300]),
     ["'IN'", "period", "SVZEROD_PERIOD_S"]),
    ("period 1e300 (settings)", lambda c: c["simulation_parameters"].update(cardiac_period=1e300),
     ["cardiac_period", "SVZEROD_PERIOD_S"]),
    ("duplicate boundary condition", lambda c: c["boundary_conditions"].append(copy.deepcopy(_bc(c, "OUT"))),
     ["'OUT'", "used twice", "boundary_conditions[1]"]),
    ("a vessel named as a BC", lambda c: c["vessels"][0].update(vessel_name="IN"), ["'IN'", "used twice"]),
    ("ic a list", lambda c: c.update(initial_condition={"pressure_all": [1.0]}), ["initial_condition", "pressure_all"]),
    ("flag a string", lambda c: c["simulation_parameters"].update(output_all_cycles="yes"),
     ["output_all_cycles", "true or false"]),
    ("cycle error 0 %", lambda c: c["simulation_parameters"].update(sim_cycle_to_cycle_percent_error=0),
     ["sim_cycle_to_cycle_percent_error", "between 0 and 100"]),
    ("not a model", lambda c: c.clear() or c.update(x=1), ["simulation_parameters"]),
]


@pytest.mark.parametrize("what, change, words", BAD_MODELS, ids=[m[0] for m in BAD_MODELS])
def test_malformed_models_are_clear_errors_naming_the_key(what, change, words):
    """Each of these was a traceback (int(None), float of a dict, an unhashable list, infinity or
    10**400 to int) or accepted silently (NaN in a series, 2.5 cycles taken as 2, negative cycles,
    a period of 1e300, a duplicate boundary condition dropped)."""
    with pytest.raises(NetlistError) as exc:
        import_svzerod(_mutated(change))
    msg = str(exc.value)
    for w in words:
        assert w in msg, (what, msg)
    assert len(msg) < 600 and "Traceback" not in msg


def test_the_file_is_named_and_tran_points_per_cycle_are_checked(tmp_path, capsys):
    """Through the command line (tran's svZeroDSolver settings): points per cycle 0, -5 and 1e-30
    are clear errors naming the file and the key, no traceback, nothing written."""
    for n in (0, -5, 1e-30):
        path = _write(tmp_path / "m.json", _mutated(
            lambda c: c["simulation_parameters"].update(number_of_time_pts_per_cardiac_cycle=n)))
        assert main(["tran", path, "--svzerod-output", str(tmp_path / "r.json")]) == 2
        err = capsys.readouterr().err
        assert path in err and "number_of_time_pts_per_cardiac_cycle" in err and "Traceback" not in err
        assert not os.path.exists(tmp_path / "r.json")


def test_conformance_case_typo_is_an_error_listing_the_cases(tmp_path, capsys):
    folder = _case_folder(tmp_path, '{"name": {"0": "v"}, "time": {"0": 0.0}, "y": {"0": 1.0}}')
    (folder / "cases" / "steadyFlow_R_R.json").write_text(json.dumps(_model()))
    assert main(["conformance", str(folder), "--case", "steadyFlow_R_r"]) == 2
    err = capsys.readouterr().err
    assert "no such case" in err and "did you mean 'steadyFlow_R_R'" in err and "m, steadyFlow_R_R" in err
    empty = tmp_path / "empty"
    (empty / "cases").mkdir(parents=True)
    assert main(["conformance", str(empty)]) == 2
    assert "no svZeroDSolver cases" in capsys.readouterr().err


# ------------------------------------------------------------------ 5. bounds ----------
@pytest.mark.parametrize("key", ["number_of_cardiac_cycles", "number_of_time_pts_per_cardiac_cycle"])
def test_a_run_of_too_many_points_is_refused_naming_the_limit(key, monkeypatch, tmp_path, capsys):
    """1e12 cycles or points per cycle hung or exhausted memory; now an error naming the limit
    (10 million time points) and how to raise it, before anything is built."""
    cfg = _mutated(lambda c: c["simulation_parameters"].update({key: 1e12}))
    with pytest.raises(NetlistError, match="SVZEROD_POINTS") as exc:
        import_svzerod(cfg)
    assert "HEMOCIRCUIT_MAX_SVZEROD_POINTS" in str(exc.value) and "10,000,000" in str(exc.value)
    t0 = time.perf_counter()
    assert main(["tran", _write(tmp_path / "m.json", cfg), "--svzerod-output", str(tmp_path / "r.json")]) == 2
    assert "SVZEROD_POINTS" in capsys.readouterr().err and time.perf_counter() - t0 < 10
    ok = _mutated(lambda c: c["simulation_parameters"].update({key: 1000}))
    import_svzerod(ok)
    monkeypatch.setenv("HEMOCIRCUIT_MAX_SVZEROD_POINTS", "100")
    with pytest.raises(NetlistError, match="limit 100;"):
        import_svzerod(ok)


def test_their_cycle_count_rule_is_bounded():
    """use_cycle_to_cycle_error with an RCR: ceil(-tau/T ln tol) of an enormous tau was
    int(inf) (OverflowError); now a clear error naming the RCR's tau."""
    from hemocircuit.svzerod.cycles import pfaller_cycles

    assert pfaller_cycles([0.9], 1.0, 0.01) == 5
    with pytest.raises(HemocircuitError, match="tau"):
        pfaller_cycles([1e308 * 10], 1.0, 0.01)


# ------------------------------------------------------------------ 6. linear import ----------
def chain(n):
    """An svZeroDSolver model of n vessels in series (FLOW -> v0 -> J0 -> v1 -> ... -> RESISTANCE)."""
    vessels = [{"vessel_id": i, "vessel_name": f"branch{i}_seg0", "zero_d_element_type": "BloodVessel",
                "zero_d_element_values": {"R_poiseuille": 100.0, "C": 1e-4}} for i in range(n)]
    vessels[0]["boundary_conditions"] = {"inlet": "INFLOW"}
    vessels[-1].setdefault("boundary_conditions", {})["outlet"] = "OUT"
    return {"simulation_parameters": dict(SIM), "vessels": vessels,
            "junctions": [{"junction_name": f"J{i}", "junction_type": "NORMAL_JUNCTION", "inlet_vessels": [i],
                           "outlet_vessels": [i + 1]} for i in range(n - 1)],
            "boundary_conditions": [{"bc_name": "INFLOW", "bc_type": "FLOW",
                                     "bc_values": {"Q": [5.0, 6.0, 5.0], "t": [0.0, 0.5, 1.0]}},
                                    {"bc_name": "OUT", "bc_type": "RESISTANCE", "bc_values": {"R": 100.0, "Pd": 0.0}}]}


def test_the_importer_is_linear_in_the_models_size():
    """8 000 vessels took 4.7 s (20 000 over 20 s): a scan of every block per block (the element
    ids' values, the block of an element id).  4x the vessels (2 000 -> 8 000) must take well
    under the quadratic 16x: best of 3 each, interleaved, so that a loaded machine slows both
    alike (linear: 4.0-4.9 here; the quadratic importer 13.6).  The absolute times are the
    benchmark's (python benchmarks/fuzz_svzerod.py --import-times)."""
    import gc

    small, big = chain(2000), chain(8000)
    import_svzerod(small)
    best = {2000: 1e9, 8000: 1e9}
    for _ in range(3):
        for n, cfg in ((2000, small), (8000, big)):
            gc.collect()
            t0 = time.perf_counter()
            m = import_svzerod(cfg)
            best[n] = min(best[n], time.perf_counter() - t0)
    assert len(m.netlist["elements"]) == 8002
    assert best[8000] / best[2000] < 8.0, best


def test_the_mean_netlist_is_the_steady_import():
    """The time-averaged netlist (their steady_initial's model) is built from the import's own
    elements; it equals a second import with every series at its mean (what it used to be)."""
    from hemocircuit.svzerod.importer import Importer, guess_units

    cases = [os.path.join(SHARED, "cases", f) for f in sorted(os.listdir(os.path.join(SHARED, "cases")))] \
        if os.path.isdir(os.path.join(SHARED, "cases")) else []
    for case in cases + [chain(5), _model()]:
        cfg = inputs.read_json(case) if isinstance(case, str) else case
        m = import_svzerod(cfg)
        steady = Importer(cfg, None, guess_units(cfg))
        steady.run(steady=True)
        assert m.mean_netlist["elements"] == steady.elements, case
        assert m.mean_netlist.get("derived") == (steady.derived or None), case


# ------------------------------------------------------------------ 7. fuzz (quick) ----------
@have_cases
def test_mutated_svzerod_models_quick_fuzz(tmp_path_factory):
    """A seeded sample of benchmarks/fuzz_svzerod.py (100 mutated shared cases: values replaced by
    None, strings, lists, mappings, NaN, infinities, huge integers, negative numbers; keys
    deleted, blocks duplicated, names repeated, settings and time series broken), each imported,
    checked and some run with tran in a forked child (20 s, 2 GiB): only clean errors or
    acceptance; no traceback, run over the limits, silent NaN or read outside the folders.
    The full run (1 000 models) is the benchmark script itself."""
    from paths import ROOT

    sys.path.insert(0, str(ROOT / "benchmarks"))
    try:
        import fuzz_svzerod
    finally:
        sys.path.pop(0)
    fuzz_svzerod.SHARED = SHARED
    folder = tmp_path_factory.mktemp("fuzz-svz")
    report = fuzz_svzerod.run(100, seed=11, folder=str(folder), jobs=2, timeout=20, mem_gib=2, quiet=True,
                              tran_share=0.5, tran_bases=("steadyFlow_R_RCR", "pulsatileFlow_R_RCR", "steadyFlow_RC_R"),
                              budget_s=45)
    counts = report["counts"]
    assert report["cases"] >= 30, report
    assert counts["accepted"] + counts["clean_error"] == report["cases"], report["examples"]
    assert all(counts[k] == 0 for k in fuzz_svzerod.BAD), report
    assert counts["clean_error"] > 0 and counts["accepted"] > 0  # the corpus exercises both
    shutil.rmtree(folder, ignore_errors=True)
