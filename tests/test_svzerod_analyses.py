"""Analyses svZeroDSolver does not have, on their models unchanged (issue 13, "beyond them"):
ac (input impedance), stability (eigenvalues), --grid sweeps, local sensitivity and fitting,
each against the closed form of the RCR or coronary circuit (cgs numbers as in their JSON;
the circuit works in mmHg, mL, s)."""
import csv
import os

import numpy as np
import pytest

from hemocircuit.circuit import load
from hemocircuit.units import PA_PER_MMHG

from paths import SHARED_SVZEROD as SHARED

pytestmark = pytest.mark.skipif(not os.path.isdir(SHARED), reason="../shared/svzerod not present")
CASES = os.path.join(SHARED, "cases")
DYN = 10.0 * PA_PER_MMHG  # dyn/cm^2 per mmHg (1 Pa = 10 dyn/cm^2)
RCR = os.path.join(CASES, "steadyFlow_R_RCR.json")  # Q 5 mL/s -> R 100 -> RCR Rp 1000, C 1e-4, Rd 1000, Pd 0
COR = os.path.join(CASES, "steadyFlow_R_coronary.json")
P_IN = "P(INFLOW__branch0_seg0)"


def _coronary_values():
    import json

    with open(COR) as fh:
        cfg = json.load(fh)
    bc = next(b for b in cfg["boundary_conditions"] if b["bc_type"] == "CORONARY")["bc_values"]
    R = cfg["vessels"][0]["zero_d_element_values"]["R_poiseuille"]
    return R, {k: (v if np.ndim(v) == 0 else float(np.mean(v))) for k, v in bc.items() if k != "t"}


def test_input_impedance_of_rcr_is_the_closed_form():
    """ac from the inflow to the inlet pressure: Z = R + Rp + Rd / (1 + j w Rd C) (cgs)."""
    c = load(RCR)
    f = np.array([0.01, 0.3, 1.0 / (2 * np.pi * 1000 * 1e-4), 10.0, 100.0])
    res = c.ac_response(input="INFLOW", outputs=[P_IN], freqs=f)
    w = 2 * np.pi * f
    Z = 100.0 + 1000.0 + 1000.0 / (1 + 1j * w * 1000.0 * 1e-4)  # dyn s/cm^5
    H = res.H[P_IN]  # mmHg per mL/s
    assert np.allclose(H * DYN, Z, rtol=1e-6, atol=0)
    assert abs(res.phase[P_IN][2] - np.degrees(np.angle(Z[2]))) < 1e-4  # the corner: -12.6 deg
    assert res.stable


def test_input_impedance_of_coronary_is_the_closed_form():
    """Their open-loop coronary: Z = R + Ra1 + 1 / (j w Ca + 1 / (Ra2 + 1 / (j w Cc + 1/Rv1)))."""
    R, v = _coronary_values()
    c = load(COR)
    f = np.logspace(-2, 2, 9)
    w = 2 * np.pi * f
    Z = R + v["Ra1"] + 1.0 / (1j * w * v["Ca"] + 1.0 / (v["Ra2"] + 1.0 / (1j * w * v["Cc"] + 1.0 / v["Rv1"])))
    H = c.ac_response(input="INFLOW", outputs=[P_IN], freqs=f).H[P_IN]
    assert np.allclose(H * DYN, Z, rtol=1e-6, atol=0)


def test_eigenvalues_are_the_time_constants():
    """stability: the RCR's one mode -1/(Rd C) = -10 1/s; the coronary's two modes are those of
    its two-capacitor network (flow-driven inlet: Ra1 carries no dynamics)."""
    from hemocircuit.analyses.stability import eigenvalues

    c = load(RCR)
    lam = eigenvalues(c, c.operating_point().x)
    assert np.allclose(np.sort(lam.real), [-1.0 / (1000.0 * 1e-4)], rtol=1e-7) and np.allclose(lam.imag, 0)
    R, v = _coronary_values()
    c = load(COR)
    Ra2, Rv1, Ca, Cc = v["Ra2"], v["Rv1"], v["Ca"], v["Cc"]
    # pressures Pa, Pim: Ca dPa/dt = Q - (Pa - Pim)/Ra2; Cc dPim/dt = (Pa - Pim)/Ra2 - (Pim - Pv)/Rv1
    A = np.array([[-1 / (Ra2 * Ca), 1 / (Ra2 * Ca)], [1 / (Ra2 * Cc), -(1 / Ra2 + 1 / Rv1) / Cc]])
    expect = np.sort(np.linalg.eigvals(A).real)
    lam = eigenvalues(c, c.operating_point().x)
    assert np.allclose(np.sort(lam.real), expect, rtol=1e-7)


def test_grid_sweep_of_their_model(tmp_path, capsys):
    """op --grid over the distal resistance: P_in = Q (R + Rp + Rd) + Pd at every member."""
    from hemocircuit.cli import main

    out = tmp_path / "grid.csv"
    rd = [500.0, 1000.0, 4000.0]
    assert main(["op", RCR, "--grid", "OUT.Rd=" + ",".join(f"{r:g} dyn*s/cm**5" for r in rd), "--quiet",
                 "--out", str(out)]) == 0
    with open(out) as fh:
        rows = list(csv.DictReader(line for line in fh if not line.startswith("#")))
    p = np.array([float(r[f"{P_IN} [mmHg]"]) for r in rows])
    assert np.allclose(p * DYN, 5.0 * (100.0 + 1000.0 + np.array(rd)), rtol=1e-9)


def test_local_sensitivity_of_their_model(tmp_path):
    """sensitivity (local) of the inlet pressure: dP/dRd = dP/dRp = dP/dR = Q = 5 mL/s, and
    the normalised values R_i Q / P."""
    from hemocircuit.analyses.sensitivity import sensitivity

    spec = tmp_path / "sens.yaml"
    spec.write_text("method: {name: local}\n"
                    "parameters: [OUT.Rd, OUT.Rp, branch0_seg0.R_poiseuille]\n"
                    f"output:\n  op: {{column: '{P_IN}', at: [{{INFLOW.value: 5 mL/s}}]}}\n")
    res = sensitivity(load(RCR), str(spec), workers=1, scheduler="serial")
    rows = {r["parameter"]: r for r in res.table}  # one row per (output, parameter)
    for name, r_cgs in (("OUT.Rd", 1000.0), ("OUT.Rp", 1000.0), ("branch0_seg0.R_poiseuille", 100.0)):
        assert abs(float(rows[name]["derivative"]) - 5.0) < 5.0 * 1e-6, name
        assert abs(float(rows[name]["normalised"]) - r_cgs / 2100.0) < 1e-6, name


def test_fit_recovers_their_distal_resistance(tmp_path):
    """fit: pressure-flow data made with Rd = 1500 dyn s/cm^5 give back Rd."""
    from hemocircuit.analyses.fit import fit

    q = np.array([1.0, 2.0, 3.0, 4.0, 5.0])
    p = q * (100.0 + 1000.0 + 1500.0) / DYN
    (tmp_path / "pq.csv").write_text("Q [mL/s],P [mmHg]\n" + "".join(f"{a},{float(b)!r}\n" for a, b in zip(q, p)))
    spec = tmp_path / "fit.yaml"
    spec.write_text("parameters:\n  OUT.Rd: {bounds: [100 dyn*s/cm**5, 5000 dyn*s/cm**5], start: 3000 dyn*s/cm**5}\n"
                    "datasets:\n  - name: pq\n    file: pq.csv\n"
                    "    experiment: {type: op, inputs: {INFLOW.value: Q}}\n"
                    f"    observe: '{P_IN}'\n    column: P\n    sigma: 0.01 mmHg\n"
                    "settings: {starts: 1, max_nfev: 60, workers: 1}\n")
    _, result, _ = fit(RCR, str(spec), out=str(tmp_path / "out"), plot=False)
    rd = float(result["p"][0])  # the one estimated parameter, in its declared unit mmHg*s/mL
    assert abs(rd * DYN - 1500.0) < 1500.0 * 1e-6
