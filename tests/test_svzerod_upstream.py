"""Optional: their test cases that are not in ../shared/svzerod, from a checkout of
SimVascular/svZeroDSolver named by HEMOCIRCUIT_SVZEROD_UPSTREAM (the repository root or its
tests/cases folder; skipped when unset).  Their case files are copied into pytest's temporary
folder for each case, never into this repository.

Compared with their stored results (tests/cases/results), which are not converged for the
valve, chamber and closed-loop cases: the allowance of each case is the issue's tolerance plus
the measured distance of their stored result from their own converged one (their solver at a
tenth of the time step, same rows), listed in GAP.  Excluded: the external-coupling cases
(coupledBlock_*), the two their suite expects to fail (*mismatchPeriod: inconsistent periods,
which the importer rejects, checked here), steadyFlow_calibration (a calibration input, no
simulation) and chamber_sphere (its first output rows carry their integrator's start from an
inconsistent all-zero state, which does not converge with their step: see docs/svzerod.md).
The two use_cycle_to_cycle_error cases run their cycles (the runner's extra cycles and their
eq. 21 count).
"""
from __future__ import annotations

import os
import shutil

import pytest

from paths import SHARED_SVZEROD

from hemocircuit.errors import NetlistError

UPSTREAM = os.environ.get("HEMOCIRCUIT_SVZEROD_UPSTREAM")
pytestmark = pytest.mark.skipif(not UPSTREAM, reason="HEMOCIRCUIT_SVZEROD_UPSTREAM not set")

#: max distance (pressure, flow) of their stored result from their dt/10 solution over the
#: compared rows, relative to the stored result's range (the scale run_case uses), measured
#: with their solver (svzerod 3.2, which reproduces these stored results to 1e-11), rounded
#: up; cases not listed are converged within 1e-3 of the issue's tolerance
GAP = {"closedLoopHeart_singleVessel_decomposed": (0.45, 0.065),
       "closedLoopHeart_withCoronaries": (0.24, 0.25),
       "pulsatileFlow_CStenosis_steadyPressure_definedPeriod": (2.5e-4, 1.2e-2),
       # steady_initial false: their first steps from the all-zero start; stored vs dt/10 0.1395 / 0.2204
       "pulsatileFlow_R_coronary_cycle_error": (0.14, 0.23),
       # 5 points per cycle: stored vs dt/10 0.0799 / 0.2428, and their dt/10 is itself 2.24e-3 /
       # 1.51e-3 from their dt/1000 solution (ours is 2.5e-5 / 5.4e-6 from that one)
       "pulsatileFlow_bifurcationR_RCR_cycle_error": (0.0825, 0.245)}
SKIP = ("steadyFlow_calibration", "chamber_sphere")


def _cases_dir():
    for d in (os.path.join(UPSTREAM, "tests", "cases"), UPSTREAM):
        if os.path.isdir(os.path.join(d, "results")):
            return d
    pytest.skip(f"no tests/cases/results under {UPSTREAM}")


def _not_shared():
    shared = SHARED_SVZEROD
    have = set(os.listdir(os.path.join(shared, "cases"))) if os.path.isdir(os.path.join(shared, "cases")) else set()
    if not UPSTREAM:
        return []
    d = _cases_dir()
    return sorted(f[:-5] for f in os.listdir(d) if f.endswith(".json") and f not in have
                  and not f.startswith("coupledBlock_") and "mismatchPeriod" not in f
                  and "mistmatchPeriod" not in f and f[:-5] not in SKIP)


def _folder(tmp_path, name):
    """A conformance folder (cases/, results/) with copies of their two files in pytest's
    temporary folder: links would lead outside the folder, which the input policy refuses
    (hemocircuit.access: a model's files are read inside its own folder only)."""
    d = _cases_dir()
    (tmp_path / "cases").mkdir()
    (tmp_path / "results").mkdir()
    shutil.copyfile(os.path.join(d, name + ".json"), tmp_path / "cases" / (name + ".json"))
    shutil.copyfile(os.path.join(d, "results", f"result_{name}.json"), tmp_path / "results" / f"result_{name}.json")
    return tmp_path / "cases" / (name + ".json")


@pytest.mark.parametrize("name", _not_shared() or ["none"])
def test_their_other_cases(name, tmp_path):
    from hemocircuit.svzerod.conformance import run_case

    if name == "none":
        pytest.skip("no upstream cases found")
    r = run_case(str(_folder(tmp_path, name)), "results")
    assert not r.note, r.note
    gp, gq = GAP.get(name, (0.0, 0.0))
    assert r.err_p <= r.tol_p + gp and r.err_q <= r.tol_q + gq, (r.err_p, r.err_q, r.worst)


@pytest.mark.parametrize("name", ["pulsatileFlow_R_RCR_mismatchPeriod", "closedLoopHeart_singleVessel_mistmatchPeriod"])
def test_their_expected_failures_are_clear_errors(name):
    from hemocircuit.svzerod import import_svzerod

    path = os.path.join(_cases_dir(), name + ".json")
    if not os.path.isfile(path):
        pytest.skip(f"{name} not in {UPSTREAM}")
    with pytest.raises(NetlistError, match="period"):
        import_svzerod(path)
