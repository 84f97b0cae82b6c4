"""--grid on every command (hemocircuit.grid): Cartesian members, grid columns first, values
with units, options, failed members kept apart, one result."""
import numpy as np
import pytest

from hemocircuit.cli import main
from hemocircuit.results import Result

DIVIDER = """
name: divider
elements:
  - {id: Ps, type: pressure_source, nodes: [in, ground], value: 60 mmHg}
  - {id: R1, type: resistor,        nodes: [in, a],      R: 2 mmHg*s/mL}
  - {id: R2, type: resistor,        nodes: [a, ground],  R: 1 mmHg*s/mL}
  - {id: C1, type: compliance,      nodes: [a, ground],  C: 0.5 mL/mmHg, V0: 1 mL}
"""


def test_op_grid_is_cartesian_with_units_and_grid_columns_first(write, tmp_path):
    out = tmp_path / "op.csv"
    assert main(["op", str(write(DIVIDER)), "--grid", "Ps.value=30,60mmHg", "--grid", "R1.R=1,3 mmHg*s/mL",
                 "--grid", "R2.R=7.5,10 Pa*s/mL", "--workers", "2", "--quiet", "--out", str(out)]) == 0
    res = Result.load(out)
    assert list(res.data)[:3] == ["Ps.value", "R1.R", "R2.R"] and res.index == ["Ps.value", "R1.R", "R2.R"]
    assert res.units["R2.R"] == "mmHg*s/mL" and res.n_rows == 8
    np.testing.assert_allclose(res["Ps.value"], [30] * 4 + [60] * 4)  # the first grid varies slowest
    np.testing.assert_allclose(res["R1.R"], [1, 1, 3, 3] * 2)
    r2 = res["R2.R"]
    np.testing.assert_allclose(r2, np.tile([7.5, 10.0], 4) / 133.322387415, rtol=1e-9)
    # steady divider: Q = P / (R1 + R2) through both resistors, P(a) = Q R2
    q = res["Ps.value"] / (res["R1.R"] + r2)
    np.testing.assert_allclose(res["Q(R1)"], q, rtol=1e-9)
    np.testing.assert_allclose(res["P(a)"], q * r2, rtol=1e-9)
    assert res.metadata["grid"] == ["Ps.value", "R1.R", "R2.R"]


def test_dc_grid_stacks_sweeps_and_a_structural_option(write, tmp_path):
    out = tmp_path / "dc.csv"
    assert main(["dc", str(write(DIVIDER)), "--sweep", "Ps.value=10:30:10mmHg", "--grid", "R2.R=1,2mmHg*s/mL",
                 "--grid", "C1.clamp_at_zero=false,true", "--quiet", "--out", str(out)]) == 0
    res = Result.load(out)
    assert res.index == ["R2.R", "C1.clamp_at_zero", "Ps.value"] and res.n_rows == 12
    assert list(res["C1.clamp_at_zero"][:6]) == [False, False, False, True, True, True]
    np.testing.assert_allclose(res["Q(R1)"], res["Ps.value"] / (2 + res["R2.R"]), rtol=1e-9)


def test_tran_and_ac_grids(write, tmp_path):
    tr = tmp_path / "tr.csv"
    assert main(["tran", str(write(DIVIDER)), "--t-end", "2", "--dt", "0.5", "--grid", "R1.R=1,2mmHg*s/mL",
                 "--quiet", "--out", str(tr)]) == 0
    res = Result.load(tr)
    assert res.index == ["R1.R", "time"] and res.n_rows == 10
    np.testing.assert_allclose(res["time"], np.tile(np.arange(0, 2.01, 0.5), 2))
    # at the operating point throughout: Q = 60 / (R1 + 1)
    np.testing.assert_allclose(res["Q(R1)"], 60 / (res["R1.R"] + 1), rtol=1e-6)
    ac = tmp_path / "ac.csv"
    assert main(["ac", str(write(DIVIDER)), "--input", "Ps", "--output", "P(a)", "--freq", "0.001,1Hz",
                 "--grid", "R2.R=1,3mmHg*s/mL", "--quiet", "--out", str(ac)]) == 0
    res = Result.load(ac)
    assert res.index == ["R2.R", "frequency"]
    low = res["frequency"] == 0.001  # DC limit of the divider: R2 / (R1 + R2)
    np.testing.assert_allclose(res["gain(P(a)/Ps.value)"][low], [1 / 3, 3 / 5], rtol=1e-3)


def test_failed_member_is_kept_apart(write, tmp_path, capsys):
    out = tmp_path / "op.csv"
    # a negative compliance is refused for one member; the other still runs
    assert main(["op", str(write(DIVIDER)), "--grid", "C1.C=0.5,-1mL/mmHg", "--quiet", "--out", str(out)]) == 0
    assert "failed: {'C1.C': '-1 mL/mmHg'}" in capsys.readouterr().err
    res = Result.load(out)
    assert res["error"][0] == "" and "not physical" in res["error"][1]
    assert res["Q(R1)"][0] == pytest.approx(20.0) and np.isnan(res["Q(R1)"][1])
    assert res.status == "partial" and len(res.metadata["failed"]) == 1


def test_grid_errors_name_the_problem(write, capsys):
    net = str(write(DIVIDER))
    assert main(["op", net, "--grid", "R3.R=1,2mmHg*s/mL", "--quiet"]) == 2
    assert "no element 'R3'; elements: ['Ps', 'R1', 'R2', 'C1']" in capsys.readouterr().err
    assert main(["op", net, "--grid", "R1.Rx=1,2mmHg*s/mL", "--quiet"]) == 2
    assert "no parameter 'Rx'" in capsys.readouterr().err
    assert main(["op", net, "--grid", "R1.R=1,2", "--quiet"]) == 2
    assert "has no unit" in capsys.readouterr().err
    assert main(["op", net, "--grid", "R1.R=1mmHg*s/mL", "--grid", "R1.R=2mmHg*s/mL", "--quiet"]) == 2
    assert "more than once" in capsys.readouterr().err


def test_progress_counts_runs_not_chunks(write, capsys):
    net = str(write(DIVIDER))
    # 3 frequencies x 2 grid members = 6 runs in 2 chunks of 3 (two workers)
    assert main(["freq", net, "--input", "Ps", "--output", "P(a)", "--freq", "0.1,0.2,0.5Hz",
                 "--grid", "C1.C=0.5,2mL/mmHg", "--workers", "2"]) == 0
    err = capsys.readouterr().err
    assert "frequency response" in err and "6/6" in err and "/2 " not in err
    assert main(["op", net, "--grid", "R1.R=1,2,3mmHg*s/mL", "--workers", "1"]) == 0
    assert "3/3" in capsys.readouterr().err
    assert main(["freq", net, "--input", "Ps", "--output", "P(a)", "--freq", "0.1Hz", "--quiet"]) == 0
    assert "run" not in capsys.readouterr().err  # --quiet: no bar
