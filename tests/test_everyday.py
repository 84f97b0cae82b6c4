"""Everyday use: what a new user meets first (the --help examples, the terminal tables)."""
import numpy as np

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
