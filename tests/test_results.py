"""The shared result base (hemocircuit.results), provenance and safe writing (hemocircuit.io):
CSV/JSON round trips, provenance fields and the netlist hash over its extends chain, atomic
writes, output folders checked before computing, a failed transient's partial output, printed
summaries that say what they leave out, and re-running a result's stored command."""
import os

import numpy as np
import pytest

import hemocircuit as hc
from hemocircuit import io, provenance
from hemocircuit.analyses import transient as transient_mod
from hemocircuit.cli import main
from hemocircuit.errors import HemocircuitError
from hemocircuit.results import Result

from paths import NETLISTS

BASE_RC = NETLISTS / "base_rc.yaml"


@pytest.fixture(scope="module")
def rc():
    return hc.load(BASE_RC)


# ---------------------------------------------------------------- round trips --------------
def test_csv_round_trip_pandas_and_load(rc, tmp_path):
    res = rc.simulate(2.0, dt=0.25, ic={"C1.V": "10 mL"}, rtol=1e-8)
    path = res.save(tmp_path / "run.csv")
    pd = pytest.importorskip("pandas")
    df = pd.read_csv(path, comment="#")  # the provenance header is skipped
    assert list(df.columns) == [res.label(k) for k in res.keys()]
    assert list(df.columns)[:2] == ["time [s]", "P(in) [mmHg]"]
    np.testing.assert_array_equal(df["time [s]"], np.arange(0, 2.01, 0.25))
    # RC charging from V = 10 mL (P = 20 mmHg) towards 40 mL, tau = R C = 1 s
    np.testing.assert_allclose(df["V(C1) [mL]"], 40 - 30 * np.exp(-df["time [s]"]), rtol=1e-6)
    back = Result.load(path)
    assert back.units == res.units and back.index == ["time"] and back.analysis == "tran"
    for k in res.keys():
        np.testing.assert_array_equal(back[k], res[k])  # repr() of floats: exact
    md = back.metadata
    assert md["status"] == "complete" and md["settings"]["rtol"] == 1e-8
    assert md["settings"]["ic"] == {"C1.V": "10 mL"}
    assert md["solver"]["method"] == res.stats["method"]
    # and the pandas view of the result itself
    df2 = res.to_dataframe()
    assert list(df2.columns) == list(df.columns) and df2.attrs["units"]["V(C1)"] == "mL"
    assert "<table" in res._repr_html_() and "V(C1) [mL]" in res._repr_html_()


def test_point_result_json_round_trip(rc, tmp_path):
    op = rc.operating_point()
    assert op["P(a)"] == pytest.approx(80.0)  # a number, as before
    path = op.save(tmp_path / "op.json")
    back = Result.load(path)
    assert back.n_rows == 1 and back.units["V(C1)"] == "mL" and back["V(C1)"][0] == pytest.approx(40.0)
    assert back.metadata["analysis"] == "op" and back.metadata["provenance"]["netlist_sha256"]


def test_text_flag_and_integer_columns_keep_their_type(tmp_path):
    r = Result({"x": [1.0, 2.0], "n": np.array([3, 4]), "ok": [True, False], "error": np.array(["", "boom, 1"],
                                                                                              dtype=object)},
               {"x": "mmHg"}, index="x", metadata={"analysis": "demo", "settings": {"a.b": 1}})
    assert r.units == {"x": "mmHg", "n": "1", "ok": "", "error": ""}  # dimensionless -> '1', text none
    back = Result.load(r.save(tmp_path / "r.csv"))
    assert back["n"].dtype.kind == "i" and back["ok"].dtype == bool and list(back["error"]) == ["", "boom, 1"]
    assert back.metadata["settings"] == {"a.b": 1}  # a dotted key inside a section survives


# ---------------------------------------------------------------- provenance ---------------
def test_cli_output_carries_provenance(tmp_path, capsys):
    out = tmp_path / "run.csv"
    assert main(["tran", str(BASE_RC), "--t-end", "1", "--dt", "0.5", "--set", "R1.R=4mmHg*s/mL",
                 "--out", str(out)]) == 0
    p = Result.load(out).metadata["provenance"]
    assert p["hemocircuit"] == hc.__version__
    for key in ("python", "numpy", "scipy", "date", "wall_time_s", "cwd"):
        assert p[key] not in (None, ""), key
    assert p["date"].endswith("+00:00")  # ISO 8601, UTC
    assert p["netlist"] == str(BASE_RC) and p["sets"] == {"R1.R": "4 mmHg*s/mL"}
    assert p["command"].startswith("hemocircuit tran ") and p["argv"][-4:-2] == ["--set", "R1.R=4mmHg*s/mL"]
    assert p["netlist_sha256"] == provenance.netlist_sources(BASE_RC).sha256()
    assert p["netlist_files"] == [str(BASE_RC)]
    assert out.read_text().startswith("# index: ")


def test_netlist_hash_covers_the_extends_chain_and_tables(write):
    write("name: parent\nelements:\n"
          "  - {id: Ps, type: pressure_source, nodes: [in, ground], value: {pwl: {file: drive.csv}}}\n"
          "  - {id: R1, type: resistor, nodes: [in, ground], R: 2 mmHg*s/mL}\n", "base/parent.yaml")
    table = write("time [s],value [mmHg]\n0,80\n10,90\n", "base/drive.csv")
    child = write("extends: base/parent.yaml\nchange: {R1: {R: 3 mmHg*s/mL}}\n", "child.yaml")
    files = provenance.netlist_sources(child).paths
    assert [os.path.basename(f) for f in files] == ["child.yaml", "parent.yaml", "drive.csv"]
    h0 = provenance.netlist_sources(child).sha256()
    c = hc.load(child)
    assert c.parameters.values["R1.R"][0] == 3.0  # the chain the hash covers is the one the loader reads
    parent = child.parent / "base" / "parent.yaml"
    parent.write_text(parent.read_text().replace("2 mmHg", "5 mmHg"))
    h1 = provenance.netlist_sources(child).sha256()
    assert h1 != h0
    table.write_text("time [s],value [mmHg]\n0,80\n10,91\n")
    assert provenance.netlist_sources(child).sha256() not in (h0, h1)


# ---------------------------------------------------------------- atomic writes ------------
def test_interrupted_write_leaves_the_previous_file(rc, tmp_path, monkeypatch):
    path = tmp_path / "run.csv"
    rc.simulate(1.0, dt=0.5).save(path)
    before = path.read_bytes()
    with pytest.raises(RuntimeError):
        with io.atomic_file(path, "w") as fh:
            fh.write("half a tab")
            raise RuntimeError("interrupted")
    assert path.read_bytes() == before

    def failing_fsync(fd):
        raise KeyboardInterrupt  # Ctrl-C while the new file is being flushed

    monkeypatch.setattr(os, "fsync", failing_fsync)
    with pytest.raises(KeyboardInterrupt):
        rc.simulate(2.0, dt=0.1).save(path)
    assert path.read_bytes() == before
    assert os.listdir(tmp_path) == ["run.csv"]  # no temporary file left behind


# ---------------------------------------------------------------- output folders -----------
def test_output_folder_checked_before_computing(tmp_path, monkeypatch, capsys):
    calls = []
    monkeypatch.setattr(transient_mod, "simulate", lambda *a, **k: calls.append(1))
    missing = tmp_path / "no" / "such" / "run.csv"
    assert main(["tran", str(BASE_RC), "--t-end", "1", "--out", str(missing)]) == 2
    err = capsys.readouterr().err
    assert "--out" in err and "does not exist" in err and "Traceback" not in err
    assert calls == []  # nothing was computed
    assert main(["dc", str(BASE_RC), "--sweep", "Ps.value=1,2mmHg", "--plot", str(missing.with_suffix(".png"))]) == 2
    assert "--plot" in capsys.readouterr().err
    with pytest.raises(HemocircuitError, match="is a folder"):
        io.prepare_output(tmp_path)
    # a missing folder whose parent exists is created
    new = tmp_path / "new" / "sweep.csv"
    assert main(["dc", str(BASE_RC), "--sweep", "Ps.value=10,20mmHg", "--out", str(new)]) == 0
    np.testing.assert_allclose(Result.load(new)["P(a)"], [10.0, 20.0])


# ---------------------------------------------------------------- partial transients -------
def test_failed_tran_writes_the_computed_part_marked_partial(tmp_path, monkeypatch, capsys):
    from hemocircuit.kernels.system import CompiledSystem

    real = CompiledSystem.integrate
    calls = []

    def fail_in_second_segment(self, t_out, x0, P, **kw):
        X, st = real(self, t_out, x0, P, **kw)
        calls.append(1)
        if len(calls) == 2:  # the integrator gives up half-way through the segment after the event
            k = len(t_out) // 2
            X = X.copy()
            X[k:] = np.nan
            st = {**st, "status": -3, "message": "step size too small (test)", "t": float(t_out[k])}
        return X, st

    monkeypatch.setattr(CompiledSystem, "integrate", fail_in_second_segment)
    proto = tmp_path / "p.yaml"
    proto.write_text("events:\n  - {at: 1 s, set: {Ps.value: 40 mmHg}}\n")
    out = tmp_path / "run.csv"
    assert main(["tran", str(BASE_RC), "--protocol", str(proto), "--t-end", "3", "--dt", "0.25",
                 "--out", str(out)]) == 2
    err = capsys.readouterr().err
    part = tmp_path / "run.partial.csv"
    assert "step size too small" in err and str(part) in err and "partial" in err
    assert not out.exists()
    res = Result.load(part)
    assert res.status == "partial" and "step size too small" in res.metadata["error"]
    t = res["time"]
    assert t[0] == 0.0 and 1.0 < t[-1] < 3.0 and np.all(np.isfinite(res["V(C1)"]))
    # the part before the event is the exact RC response (constant 80 mmHg: V = 40 mL)
    np.testing.assert_allclose(res["V(C1)"][t <= 1.0], 40.0, rtol=1e-6)


# ---------------------------------------------------------------- summaries ----------------
def test_summary_says_what_it_leaves_out():
    cols = {"x": np.arange(30.0), **{f"c{k}": np.arange(30.0) * k for k in range(36)}}
    r = Result(cols, {"x": "mmHg"}, index="x")
    text = r.summary(max_cols=5, max_rows=10, where="dc.csv")
    assert "showing 5 of 37 columns" in text and "showing 10 of 30 rows" in text and "all in dc.csv" in text
    assert text.splitlines()[0].split()[:2] == ["x", "[mmHg]"]
    full = Result({"x": [1.0, 2.0], "y": [3.0, 4.0]}, {}, index="x").summary()
    assert "showing" not in full  # nothing left out, nothing said
    with pytest.raises(HemocircuitError, match="did you mean c12"):
        r.summary(show=["c12x"])


def test_cli_dc_prints_what_it_omits(capsys, tmp_path):
    out = tmp_path / "dc.csv"
    assert main(["dc", str(BASE_RC), "--sweep", "Ps.value=10,20mmHg", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    n = len(Result.load(out))
    assert f"of {n} columns; all in {out}" in text


# ---------------------------------------------------------------- show and re-run ----------
def test_show_reloads_replots_and_reruns_to_the_same_numbers(tmp_path, capsys):
    first = tmp_path / "a.csv"
    assert main(["tran", str(BASE_RC), "--t-end", "2", "--dt", "0.25", "--ic", "C1.V=10mL",
                 "--set", "R1.R=3mmHg*s/mL", "--out", str(first)]) == 0
    png, second = tmp_path / "a.png", tmp_path / "b.csv"
    capsys.readouterr()
    # the netlist lies outside the result's folder (tmp_path): allowed explicitly
    assert main(["show", str(first), "--plot", str(png), "--rerun", str(second), "--allow-path", str(NETLISTS)]) == 0
    printed = capsys.readouterr().out
    assert "netlist_sha256" in printed and "R1.R" in printed and png.stat().st_size > 5000
    a, b = Result.load(first), Result.load(second)
    assert list(a.keys()) == list(b.keys()) and a.units == b.units
    for k in a.keys():
        np.testing.assert_array_equal(a[k], b[k])
    assert b.metadata["provenance"]["sets"] == {"R1.R": "3 mmHg*s/mL"}
    # tau = R C = 1.5 s from 10 mL towards 40 mL
    np.testing.assert_allclose(a["V(C1)"], 40 - 30 * np.exp(-a["time"] / 1.5), rtol=1e-5)
