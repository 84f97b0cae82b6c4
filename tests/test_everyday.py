"""Everyday use: what a new user meets first (the --help examples, the terminal tables)."""
import numpy as np
import pytest

from hemocircuit.cli import main
from hemocircuit.results import Result

from paths import NETLISTS

BASE_RC = NETLISTS / "base_rc.yaml"


def test_grid_range_from_the_help_text_runs_with_its_unit(tmp_path):
    # --help: "Pa.value=60:120:20mmHg"; a range's values must reach --set with their unit
    out = tmp_path / "g.csv"
    assert main(["op", str(BASE_RC), "--grid", "Ps.value=60:120:20mmHg", "--out", str(out), "--quiet"]) == 0
    res = Result.load(out)
    np.testing.assert_allclose(res["Ps.value"], [60, 80, 100, 120])
    np.testing.assert_allclose(res["P(a)"], [60, 80, 100, 120])  # no flow at steady state: P(a) = Ps
    assert "error" not in res


@pytest.mark.parametrize("integrator, method", [("rodas5p", "RODAS5P (compiled)"), ("ros34pw2", "ROS34PW2 (compiled)"),
                                                ("bdf", "BDF (compiled)"), ("scipy-bdf", "BDF"),
                                                ("scipy-radau", "Radau"), ("lsoda", "LSODA")])
def test_tran_integrators_by_name_with_their_tolerances_recorded(tmp_path, integrator, method):
    out = tmp_path / "t.csv"
    assert main(["tran", str(BASE_RC), "--t-end", "5", "--dt", "0.5", "--ic", "C1.V=10mL", "--integrator", integrator,
                 "--rtol", "1e-8", "--atol", "1e-10", "--out", str(out), "--quiet"]) == 0
    res = Result.load(out)
    # R C = 2 mmHg*s/mL * 0.5 mL/mmHg = 1 s, from 10 mL towards C * 80 mmHg = 40 mL
    np.testing.assert_allclose(res["V(C1)"], 40 - 30 * np.exp(-res["time"]), rtol=1e-6)
    md = res.metadata
    assert md["solver"]["method"] == method
    assert (md["settings"]["integrator"], md["settings"]["rtol"], md["settings"]["atol"]) == (integrator, 1e-8, 1e-10)


def test_tran_max_step_bounds_the_steps(tmp_path):
    out = tmp_path / "t.csv"
    assert main(["tran", str(BASE_RC), "--t-end", "5", "--dt", "1", "--ic", "C1.V=10mL", "--max-step", "10ms",
                 "--integrator", "rodas5p", "--out", str(out), "--quiet"]) == 0
    md = Result.load(out).metadata
    assert md["solver"]["steps"] >= 500 and md["settings"]["max_step"] == pytest.approx(0.01)


@pytest.mark.parametrize("flag, value, message", [("--rtol", "2", "between 0 and 1"), ("--atol", "-1", "positive"),
                                                  ("--max-step", "0s", "positive time")])
def test_tran_bad_tolerances_are_clear_errors(capsys, flag, value, message):
    assert main(["tran", str(BASE_RC), "--t-end", "1", flag, value, "--quiet"]) == 2
    assert message in capsys.readouterr().err


def test_dc_table_shows_the_outputs_of_interest(capsys):
    from paths import PAYNE06
    assert main(["dc", str(PAYNE06), "--sweep", "Pa.value=20:200:90mmHg", "--quiet"]) == 0
    head = [ln for ln in capsys.readouterr().out.splitlines() if ln.lstrip().startswith("Pa.value")][0]
    # payne06_passive declares its outputs: the cerebral flow, not the source's own (negative) flow
    assert "Q(Rla)" in head and "Q(Pa)" not in head


def test_first_api_simulate_says_once_that_it_compiles(monkeypatch, capsys):
    import hemocircuit as hc
    from hemocircuit.analyses import transient
    from hemocircuit.kernels import background, prebuild

    monkeypatch.setattr(transient, "_told", [])
    monkeypatch.setattr(background, "ready", lambda system: False)  # as on a fresh install
    monkeypatch.setattr(prebuild, "start", lambda system: None)
    c = hc.load(str(BASE_RC))
    c.simulate(1.0, dt=0.5)
    c.simulate(1.0, dt=0.5)
    assert capsys.readouterr().err.count("hemocircuit: compiling the engine") == 1


def test_vasomotion_netlist_starts_its_limit_cycle(tmp_path, capsys):
    from paths import ROOT
    out = tmp_path / "v.csv"
    assert main(["tran", str(ROOT / "netlists" / "vasomotion.yaml"), "--t-end", "300", "--dt", "0.5",
                 "--measure", "period art.r from=150s", "--out", str(out), "--quiet"]) == 0
    res = Result.load(out)
    late = res["art.r"][res["time"] >= 150]
    assert np.ptp(late) > 10  # um: a limit cycle of the radius, not a flat line
    period = res.metadata["measures"]["period art.r from=150s"]["period [s]"]
    assert 7.6 < period < 7.8  # the thesis's ~7.7 s cycle (zeta = 0.1, omega_n = pi/5)
    assert "unstable equilibrium" not in capsys.readouterr().err


def test_an_unperturbed_start_on_an_unstable_equilibrium_is_flagged(capsys):
    from paths import ROOT
    # vasomotion's parameters without its netlist's starting kick
    args = ["tran", str(ROOT / "netlists" / "second_order_ca.yaml"), "--set", "art.omega_n=0.6283185307179586rad/s",
            "--set", "art.zeta=0.1", "--t-end", "100", "--dt", "0.5", "--quiet"]
    assert main(args) == 0
    err = capsys.readouterr().err
    assert "started on an unstable equilibrium" in err and "--ic" in err
    # a period of its round-off is refused, and the warning says why
    assert main(args + ["--measure", "period art.r"]) == 2
    err = capsys.readouterr().err
    assert "round-off: no oscillation" in err and "unstable equilibrium" in err


def test_ac_with_an_input_of_zero_reports_the_absolute_gain(tmp_path, capsys):
    # an imported svZeroDSolver inflow has mean 0: there is no relative change to compare
    net = tmp_path / "q.yaml"
    net.write_text("name: q\nelements:\n"
                   "  - {id: Q, type: flow_source, nodes: [ground, a], value: 0 mL/s}\n"
                   "  - {id: R, type: resistor, nodes: [a, ground], R: 2 mmHg*s/mL}\n"
                   "  - {id: C, type: compliance, nodes: [a, ground], C: 0.5 mL/mmHg}\n")
    out = tmp_path / "ac.csv"
    assert main(["ac", str(net), "--input", "Q", "--output", "P(a)", "--freq", "0.1,1Hz", "--out", str(out),
                 "--plot", str(tmp_path / "ac.png")]) == 0
    assert "no relative gain: the input is 0 at the operating point" in capsys.readouterr().out
    res = Result.load(out)
    w = 2 * np.pi * np.array([0.1, 1.0])
    # the input impedance of R || C: R / (1 + j w R C), R C = 1 s
    np.testing.assert_allclose(res["gain(P(a)/Q.value)"], 2 / np.sqrt(1 + w ** 2), rtol=1e-5)
    assert np.isnan(res["rel_gain(P(a)/Q.value)"]).all()


def test_envelope_phase_plot_of_many_members_colours_by_the_sweep(monkeypatch):
    from types import SimpleNamespace

    from hemocircuit.analyses import envelope

    t = np.linspace(0, 2 * np.pi, 50)
    rows = [{"Pa.value": 60.0 + k, "art.zeta": z} for z in (0.0, 0.1) for k in range(55)]
    series = [{"x": np.cos(t) * (1 + r["Pa.value"] / 100), "y": np.sin(t)} for r in rows]
    res = SimpleNamespace(rows=lambda: rows, series=series, index=["Pa.value", "art.zeta"],
                          units={"Pa.value": "mmHg", "art.zeta": "1"})
    saved = {}
    monkeypatch.setattr(envelope, "save_figure", lambda fig, path: saved.update(fig=fig))
    envelope.plot_phase_plane("p.png", res, "x", "y")
    fig = saved["fig"]
    main_ax, bar = fig.axes  # the curves and a colour bar for the sweep
    assert len(main_ax.lines) == 110 + 2  # 110 curves, 2 line-style keys
    assert [t.get_text() for t in main_ax.get_legend().get_texts()] == ["art.zeta=0", "art.zeta=0.1"]
    assert "Pa.value [mmHg]" in bar.get_ylabel()


def _mixed_result():
    from hemocircuit.results import Result
    cols = {"time": np.array([0.0, 0.1, 1e-7, 1e22]), "x": np.array([np.nan, -0.0, np.inf, 1 / 3]),
            "n": np.array([1, -2, 3, 2 ** 40]), "flag": np.array([True, False, True, True]),
            "note": np.array(["a,b", 'say "hi"', "", None], dtype=object)}
    return Result(cols, {"time": "s", "x": "mmHg", "n": "1"}, index=["time"], metadata={"analysis": "tran"})


def test_csv_writer_writes_what_the_csv_module_writes():
    """The pyarrow-backed writer's cells read back as the csv module's per-cell writer's did:
    the same text after csv quoting, and the same numbers (floats in their shortest round-trip
    notation, which differs from repr only in form: 1e+22 either way, 1e-07 as 1e-7)."""
    import csv
    import io

    from hemocircuit.arrow_tables import rows_text
    from hemocircuit.results import _cell
    res = _mixed_result()
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerows(zip(*[[_cell(v) for v in res[n].tolist()] for n in res.keys()]))
    ours = rows_text([res[n] for n in res.keys()], _cell)
    theirs = list(csv.reader(io.StringIO(buf.getvalue())))
    mine = list(csv.reader(io.StringIO(ours)))
    assert len(mine) == len(theirs) == 4
    for a, b in zip(mine, theirs):
        assert [float(v) for v in a[:2]] == [float(v) for v in b[:2]] or "nan" in a[1]
        assert a[2:] == b[2:]  # integers, flags and text exactly
    assert ours.splitlines()[0] == '0,nan,1,"True","a,b"'  # text quoted throughout: the table has "a,b"
    assert ours.splitlines()[2] == '1e-7,inf,3,"True",""'
    assert ours.splitlines()[3] == '1e+22,0.3333333333333333,1099511627776,"True",""'


def test_csv_writer_keeps_whole_float_columns_floats_and_quotes_only_when_needed():
    from hemocircuit.arrow_tables import rows_text
    from hemocircuit.results import _cell, _typed
    text = rows_text([np.array([0.0, 1.0, 2.0]), np.array([0.5, 80.0, -0.0]), np.array(["a", "b", "c"])], _cell)
    assert text == "0.0,0.5,a\n1.0,80,b\n2.0,-0,c\n"  # no cell needs quotes, so none has them
    col = _typed([ln.split(",")[0] for ln in text.splitlines()])
    assert col.dtype == float and list(col) == [0.0, 1.0, 2.0]


def test_csv_writer_formats_blocks_in_parallel_and_keeps_row_order(tmp_path):
    """A long table is formatted in blocks on several threads: the rows come back in order,
    every number exact, and text quoted by the whole table's rule (one cell with a comma in the
    last block quotes the first block's text too)."""
    from hemocircuit import arrow_tables
    n = 4 * arrow_tables._BLOCK_ROWS + 7
    rng = np.random.default_rng(3)
    x = rng.standard_normal(n) * 10.0 ** rng.integers(-12, 12, n)
    words = np.array([f"w{i}" for i in range(n)], dtype=object)
    words[-1] = "a,b"
    res = Result({"time": np.arange(n) * 0.1, "x": x, "word": words}, {"time": "s", "x": "mmHg"},
                 index=["time"], metadata={"analysis": "tran"})
    res.save(tmp_path / "r.csv")
    back = Result.load(tmp_path / "r.csv")
    assert np.array_equal(back["time"], np.arange(n) * 0.1) and np.array_equal(back["x"], x)
    assert list(back["word"]) == list(words)
    body = (tmp_path / "r.csv").read_text().splitlines()
    assert body[-n].endswith(',"w0"') and body[-1].endswith(',"a,b"')


@pytest.mark.parametrize("ext", [".csv", ".json", ".npz", ".parquet"])
def test_result_formats_round_trip_exactly(tmp_path, ext):
    if ext == ".parquet":
        pytest.importorskip("pyarrow")
    res = _mixed_result()
    path = tmp_path / f"r{ext}"
    res.save(path)
    back = Result.load(path)
    assert list(back.keys()) == list(res.keys()) and back.index == ["time"]
    for k in ("time", "x", "n"):
        np.testing.assert_array_equal(back[k], res[k])  # bit for bit, nan and -0.0 included
    assert np.signbit(back["x"][1])
    assert list(back["flag"]) == [True, False, True, True]
    assert [("" if v is None else v) for v in back["note"]] == ["a,b", 'say "hi"', "", ""]
    assert back.units["x"] == "mmHg" and back.metadata["analysis"] == "tran"


def test_unknown_result_format_is_refused_before_computing(tmp_path, capsys):
    assert main(["tran", str(BASE_RC), "--t-end", "1", "--out", str(tmp_path / "r.xlsx"), "--quiet"]) == 2
    assert "unknown result format '.xlsx'" in capsys.readouterr().err
    assert not (tmp_path / "r.xlsx").exists()


def test_simulate_takes_a_protocol_path_and_per_state_atol(tmp_path):
    import hemocircuit as hc
    proto = tmp_path / "p.yaml"
    proto.write_text("events:\n  - {at: 1 s, set: {Ps.value: 100 mmHg}}\n")
    c = hc.load(str(BASE_RC))
    res = c.simulate(3.0, dt=0.5, protocol=str(proto), atol=np.full(c.nx, 1e-10), rtol=1e-8)
    # from 40 mL at 80 mmHg towards 50 mL after the step at 1 s, R C = 1 s
    np.testing.assert_allclose(res["V(C1)"][-1], 50 - 10 * np.exp(-2.0), rtol=1e-6)


def test_writing_csv_and_parquet_does_not_import_pandas(tmp_path):
    """pyarrow's pa.array/pa.table import pandas (0.5-0.8 s of a run's time) to check their
    argument; the writers build their arrays from buffers instead."""
    import subprocess
    import sys
    code = ("import sys, numpy as np\nfrom hemocircuit.results import Result\n"
            "r = Result({'t': np.arange(4) * 0.5, 'b': np.array([True, False, True, True]), "
            "'s': np.array(['a', None, 'c,d', ''], dtype=object)}, {'t': 's'}, index=['t'])\n"
            f"r.save({str(tmp_path / 'r.csv')!r}); r.save({str(tmp_path / 'r.parquet')!r})\n"
            "print('pandas' in sys.modules)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "False"
    back = Result.load(tmp_path / "r.parquet")
    assert list(back["b"]) == [True, False, True, True] and list(back["s"]) == ["a", None, "c,d", ""]
