"""Every example the README lists runs, and what it writes holds sane physics.

Each script runs as a user runs it (``python examples/NAME.py``, a subprocess) in its smoke
mode, ``HEMOCIRCUIT_EXAMPLES_QUICK=1`` (the same code, coarser grids and shorter runs), with
``HEMOCIRCUIT_EXAMPLES_OUT`` pointing at a scratch folder, so the files a user's full run left in
examples/out/ stay as they are.  The fitting/ and sensitivity/ READMEs' commands run as written
(plus smoke flags) in a copy of those folders, since they write next to their specs.  The
quick-start notebook runs with nbclient when it is installed, else cell by cell in one
namespace.  Each test then reads the files back and checks numbers against the physiology
(ranges, monotone curves, autoregulation, who leads whom), not only that nothing raised.
"""
from __future__ import annotations

import csv
import json
import os
import re
import shlex
import shutil
import subprocess
import sys

import numpy as np
import pytest

from paths import ROOT, SHARED_SVZEROD

EXAMPLES = ROOT / "examples"
SVZEROD_MODEL = os.path.join(SHARED_SVZEROD, "cases",
                             "closedLoopHeart_singleVessel.json")


def quick_env(out):
    return {**os.environ, "HEMOCIRCUIT_EXAMPLES_QUICK": "1", "HEMOCIRCUIT_EXAMPLES_OUT": str(out),
            "MPLBACKEND": "Agg"}


def run(argv, out, cwd=ROOT, timeout=600):
    """Run a command in smoke mode; its stdout.  A failure shows the end of its stderr."""
    r = subprocess.run(argv, cwd=cwd, env=quick_env(out), capture_output=True, text=True, timeout=timeout)
    assert r.returncode == 0, (f"{' '.join(map(str, argv))} exited {r.returncode}:\n{r.stdout[-1500:]}\n"
                               f"{r.stderr[-3000:]}")
    return r.stdout


def run_example(name, out, *args):
    return run([sys.executable, str(EXAMPLES / name), *args], out)


def read_csv(path):
    """{header: array} of a plain CSV (numbers where a column is numeric)."""
    with open(path, newline="") as fh:
        rows = list(csv.reader(line for line in fh if not line.startswith("#")))
    cols = {}
    for j, name in enumerate(rows[0]):
        vals = [r[j] for r in rows[1:]]
        try:
            cols[name] = np.array([float(v) for v in vals])
        except ValueError:
            cols[name] = np.array(vals, dtype=object)
    return cols


def assert_pngs(folder, names):
    for n in names:
        assert os.path.getsize(os.path.join(folder, n)) > 10_000, n  # a drawn figure, not an empty canvas


# ------------------------------------------------------------------ the README's list -----
def readme_examples():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    section = text.split("**Examples**", 1)[1].split("\n---", 1)[0]
    return re.findall(r"^\| `([^`]+)` \|", section, flags=re.M)


TESTED = {"steady_state_curves.py", "lee97_phosphorylation.py", "kuo91_dynamics.py", "compare_variants.py",
          "body_autoregulation.py",
          "payne06_phase_vs_tau.py", "svzerod_closed_loop.py", "fitting/", "sensitivity/", "quickstart.ipynb"}


def test_every_readme_example_is_run_here_and_writes_under_examples_out():
    listed = readme_examples()
    assert set(listed) == TESTED, "a README example without a test here (or a test of an unlisted one)"
    for name in listed:
        assert (EXAMPLES / name).exists(), name
        if name.endswith(".py"):
            src = (EXAMPLES / name).read_text(encoding="utf-8")
            assert "HEMOCIRCUIT_EXAMPLES_QUICK" in src and "HEMOCIRCUIT_EXAMPLES_OUT" in src, name
            assert '"out"' in src and '"output"' not in src, name  # one output folder: examples/out/
    ignored = (ROOT / ".gitignore").read_text().splitlines()
    assert "examples/out/" in ignored


# ------------------------------------------------------------------ scripts ---------------
def test_steady_state_curves(tmp_path):
    run_example("steady_state_curves.py", tmp_path)
    d = read_csv(tmp_path / "steady_state_curves.csv")
    P, r = d["P [cmH2O]"], d["r [um]"]
    assert np.all((r > 20) & (r < 150))
    for preset in ("kuo91", "falcone91"):
        curve = {case: r[(d["preset"] == preset) & (d["case"] == case)] for case in
                 ("passive", "active_no_flow", "active_flow")}
        p = P[(d["preset"] == preset) & (d["case"] == "passive")]
        assert len(p) >= 10
        assert np.all(np.diff(curve["passive"]) > 0)                        # a passive vessel distends
        assert np.all(curve["active_no_flow"] < curve["passive"])          # tone constricts it
        mid = (p >= 60) & (p <= 120)
        assert np.all(np.diff(curve["active_no_flow"][mid]) < 0)           # myogenic: higher P, smaller r
        assert np.all(curve["active_flow"] > curve["active_no_flow"])      # flow dilates (NO)
    kuo = (d["preset"] == "kuo91") & (d["case"] == "active_no_flow")
    assert np.interp(60.0, d["P [mmHg]"][kuo], r[kuo]) == pytest.approx(60.0, abs=3.0)  # the thesis's set point
    assert_pngs(tmp_path, ["steady_kuo91.png", "steady_falcone91.png", "steady_passive_both.png"])


def test_body_autoregulation(tmp_path):
    """Smoke mode: 50 s records, 20 s windows, a cuff release at 20 s.  What the clinic sees:
    the intact model within healthy adults' ranges (docs/body.md: LF phase 30-60 deg, ARI 4-7;
    with the thesis's arteriole dynamics it is 19 deg and 3.6), impaired (passive) arterioles
    without the phase lead (LF phase near 0), with more flow per pressure and an ARI of about 0,
    and a slower Ca (larger tau_Ca) lessening the LF phase lead."""
    run_example("body_autoregulation.py", tmp_path)
    out = tmp_path / "body_autoregulation"
    t = read_csv(out / "tfa.csv")
    lf = {case: t["phase_deg"][(t["case"] == case) & (t["band"] == "LF")][0] for case in ("intact", "impaired")}
    gain = {case: t["gain"][(t["case"] == case) & (t["band"] == "LF")][0] for case in ("intact", "impaired")}
    assert 30.0 <= lf["intact"] <= 60.0 and abs(lf["impaired"]) < 15.0
    assert gain["impaired"] > 1.3 * gain["intact"]
    a = read_csv(out / "ari.csv")
    ari = dict(zip(a["case"], a["ari"]))
    assert 4.0 <= ari["intact"] <= 7.0 and ari["impaired"] <= 1
    tau = read_csv(out / "tau_phase.csv")
    assert tau["lf_phase_deg"][0] > tau["lf_phase_deg"][-1]  # tau_Ca 2 s leads more than 20 s
    assert_pngs(out, ["tfa.png", "cuff.png", "tau_phase.png"])


def test_lee97_phosphorylation(tmp_path):
    run_example("lee97_phosphorylation.py", tmp_path)
    d = read_csv(tmp_path / "lee97_phosphorylation.csv")
    phos, ca, cg = d["Mp+AMp [-]"], d["Ca [M]"], d["cGMP [M]"]
    assert np.all((phos > 0) & (phos < 1))
    dec = d["curve"] == "decade"
    levels = sorted(set(cg[dec]))
    assert len(levels) == 6
    curves = [phos[dec & (cg == c)] for c in levels]
    for y in curves:
        assert np.all(np.diff(y) > 0)                                      # more Ca, more phosphorylation
        assert y[0] < 0.05 and y[-1] > 0.5
    at_1uM = [np.interp(-6.0, np.log10(ca[dec & (cg == c)]), y) for c, y in zip(levels, curves)]
    assert np.all(np.diff(at_1uM) < 0)                                     # cGMP relaxes (less phosphorylation)
    assert_pngs(tmp_path, ["lee97_phosphorylation.png"])


def test_kuo91_dynamics(tmp_path):
    run_example("kuo91_dynamics.py", tmp_path)
    names = [f"{e}{s}" for e in "ABCD" for s in ("", "_2nd")] + ["A_tau230"]
    for n in names:
        d = read_csv(tmp_path / f"kuo91_{n}.csv")
        assert np.all((d["r [um]"] > 30) & (d["r [um]"] < 120)), n
        assert d["t [s]"][-1] >= 300, n
    a = read_csv(tmp_path / "kuo91_A.csv")
    t, r = a["t [s]"], a["r [um]"]
    at = lambda s: float(np.interp(s, t, r))  # noqa: E731
    peak = r[(t > 51) & (t < 100)].max()
    assert peak > at(50) + 5                   # the pressure step 60 -> 80 cmH2O distends it first
    assert at(238) < peak - 10                 # then the myogenic response constricts it
    assert at(299) > at(238) + 5               # flow (dP = 4 cmH2O) dilates it
    assert at(440) < at(299) - 5               # and it constricts again after the flow stops
    feats = read_csv(tmp_path / "kuo91_features.csv")
    assert set(feats["run"]) == set(names)
    assert_pngs(tmp_path, [f"kuo91_{e}.png" for e in "ABCD"] + ["kuo91_fig2_overview.png", "kuo91_A_states.png"])


def test_compare_variants(tmp_path):
    import hemocircuit as hc

    run_example("compare_variants.py", tmp_path)
    out = tmp_path / "compare"
    st = hc.Result.load(out / "steady.csv")
    nets = list(dict.fromkeys(st["netlist"]))
    assert nets == ["payne06", "arterial-compliance", "icp", "inertia", "two-generations"]
    for n in nets:
        sel = st["netlist"] == n
        pa, q = st["Pa.value"][sel], st["flow"][sel]
        assert np.all(np.diff(q) > 0), n                                   # more pressure, more flow
        assert 5 < np.interp(80, pa, q) < 12, n                            # mL/s, a human brain
        # autoregulation: Pa 60 -> 140 mmHg (x 2.3) moves the flow by far less
        assert np.interp(140, pa, q) / np.interp(60, pa, q) < 1.4, n
    step = hc.Result.load(out / "step_80_72.csv")
    for n in ("arterial-compliance", "two-generations"):
        sel = step["netlist"] == n
        t, q = step["time"][sel], step["Q(Rla)"][sel]
        before, after = q[t < 10][-1], q[t > 10]
        assert after.min() < 0.95 * before                                 # the step lowers the flow ...
        assert after.min() < after[-1] < before                            # ... which recovers, partly
    sine = hc.Result.load(out / "sine_0p1Hz.csv")
    sel = (sine["netlist"] == "arterial-compliance") & (sine["time"] > 20)
    swing = np.ptp(sine["Q(Rla)"][sel])
    assert 0.05 < swing < 5                                                # a 4 mmHg sine moves the flow
    assert_pngs(out, ["steady.png", "step_80_72.png", "sine_0p1Hz.png"])


def test_payne06_phase_vs_tau(tmp_path):
    import hemocircuit as hc

    text = run_example("payne06_phase_vs_tau.py", tmp_path)
    res = hc.Result.load(tmp_path / "payne06_phase_vs_tau.csv")
    assert res.n_rows >= 8 and all(res["settled"]) and not any(res["error"])
    tau = res["art.tau_Ca"]
    for o in ("Q(Rla)", "Q(Rsv)"):
        ph = res[f"phase({o}/Pa.value)"]
        for vf in (True, False):
            sel = np.array([str(v).lower() == str(vf).lower() for v in res["art.volume_flow"]])
            assert ph[sel][np.argmin(tau[sel])] > 0 > ph[sel][np.argmax(tau[sel])], (o, vf)  # lead -> lag
    # the thesis: with the volume flow neglected the phase reverses near tau_Ca = 2.5 s
    m = re.search(r"volume flow neglected, q1 = Q\(Rla\): lead -> lag at tau_Ca = ([0-9.]+) s", text)
    assert m and 1.5 < float(m.group(1)) < 4.0, text[-1500:]
    assert_pngs(tmp_path, ["payne06_phase_vs_tau.png"])


@pytest.mark.skipif(not os.path.isfile(SVZEROD_MODEL), reason="svZeroDSolver test cases not present")
def test_svzerod_closed_loop(tmp_path):
    run_example("svzerod_closed_loop.py", tmp_path, "--model", SVZEROD_MODEL)
    row = {k: float(v[0]) for k, v in read_csv(tmp_path / "svzerod_closed_loop.csv").items()
           if isinstance(v[0], float)}
    assert 20 < row["stroke_volume"] < 100                                 # mL per beat
    assert row["aortic_valve_volume"] == pytest.approx(row["stroke_volume"], rel=1e-2)
    assert 0.3 < row["ejection_fraction"] < 0.8
    assert 40 < row["mean_aortic_pressure"] < 120 and row["P_LV_max"] > row["mean_aortic_pressure"]
    assert row["max_abs_multiplier"] < 1                                   # a stable orbit
    assert_pngs(tmp_path, ["svzerod_closed_loop.png"])


# ------------------------------------------------------------------ README commands -------
def sh_commands(readme):
    """The commands of a README's sh blocks (continuation lines joined; the for loop kept)."""
    text = readme.read_text(encoding="utf-8")
    return [b.replace("\\\n", " ") for b in re.findall(r"```sh\n(.*?)```", text, flags=re.S)]


@pytest.fixture
def project(tmp_path):
    """A scratch project laid out like the repository: its netlists, a copy of examples/'s
    fitting, sensitivity and protocols folders (the commands write next to their specs)."""
    (tmp_path / "pyproject.toml").write_text("")  # the project's root for the input policy
    (tmp_path / "netlists").symlink_to(ROOT / "netlists")
    for d in ("fitting", "sensitivity", "protocols"):
        shutil.copytree(EXAMPLES / d, tmp_path / "examples" / d, ignore=shutil.ignore_patterns("output", "results"))
    return tmp_path


def hemocircuit_cli():
    exe = os.path.join(os.path.dirname(sys.executable), "hemocircuit")
    return exe if os.path.exists(exe) else "hemocircuit"


def test_fitting_readme_commands(project):
    """generate_data.py and the staged fit chain, as the README writes them (each fit with
    --starts 1 --max-nfev 3): the regenerated data equal the committed data, stage 1 recovers
    the passive parameters, every later stage reads its predecessor and lowers its error."""
    gen, chain = sh_commands(EXAMPLES / "fitting" / "README.md")[0].strip().split("\n", 1)
    assert gen.strip() == "python examples/fitting/generate_data.py"
    run([sys.executable] + shlex.split(gen)[1:], project, cwd=project)
    data = project / "examples" / "fitting" / "data"
    for f in sorted(os.listdir(EXAMPLES / "fitting" / "data")):
        new, old = read_csv(data / f), read_csv(EXAMPLES / "fitting" / "data" / f)
        assert new.keys() == old.keys(), f
        tol = 1e-4 if "_A_" in f else 1e-8  # a transient: the integrator's tolerance
        for k in old:
            np.testing.assert_allclose(new[k], old[k], rtol=tol, err_msg=f"{f}: {k}")

    stages = re.search(r"for s in (.*?); do", chain).group(1).split()
    assert stages == ["kuo91_1_passive", "kuo91_2_active", "kuo91_3_flow", "kuo91_4_dynamic", "falcone91_1_passive"]
    body = re.search(r"do\n\s*(.*?)\ndone", chain, flags=re.S).group(1).strip()
    for s in stages:
        argv = shlex.split(body.replace("$s", s))
        assert argv[:2] == ["hemocircuit", "fit"]
        run([hemocircuit_cli()] + argv[1:] + ["--starts", "1", "--max-nfev", "3", "--workers", "1", "--no-plot",
                                              "--quiet"], project, cwd=project)
    out = project / "examples" / "fitting" / "output"
    reports = {s: json.loads((out / s / "report.json").read_text()) for s in stages}
    for s, rep in reports.items():
        assert (out / s / "fitted.yaml").exists(), s
        best = rep["starts"][rep["best_start"]]
        assert np.isfinite(best["cost"]) and rep["rms_error"] < 50, s      # um: a fit, not a failure
        for p in rep["parameters"]:
            assert p["lower"] <= p["value"] <= p["upper"], (s, p["path"])
    # stage 1 at 3 evaluations already recovers the generating values (tabPassiveFit)
    for s, truth in (("kuo91_1_passive", {"art.q2": 8.38, "art.q3": 1.06, "art.l0": 77.5e-6}),
                     ("falcone91_1_passive", {"art.q2": 8.27, "art.q3": 0.619, "art.l0": 64.3e-6})):
        got = {p["path"]: p["value"] for p in reports[s]["parameters"]}
        for k, v in truth.items():
            assert got[k] == pytest.approx(v, rel=0.02), (s, k)
        assert reports[s]["rms_error"] < 0.5
    # stage 2 starts from stage 1's fragment
    frag2 = (out / "kuo91_2_active" / "fitted.yaml").read_text()
    assert "art.l0" in frag2 or "l0" in frag2


def test_sensitivity_readme_commands(project):
    """The README's hemocircuit sensitivity commands (with --n 3) and run_fit_error.py in its
    smoke mode: the Ca bounds lead, k_tau does nothing without flow, the fit error at the
    preset is the noise's rms."""
    import pandas as pd

    blocks = sh_commands(EXAMPLES / "sensitivity" / "README.md")
    cmds = [c.strip() for c in blocks[0].splitlines() if c.strip()]
    assert cmds[0] == "mkdir -p examples/out/sensitivity"
    (project / "examples" / "out" / "sensitivity").mkdir(parents=True)
    for c in cmds[1:]:
        argv = shlex.split(c)
        assert argv[:2] == ["hemocircuit", "sensitivity"]
        extra = [] if "local" in argv else ["--n", "3"]
        run([hemocircuit_cli()] + argv[1:] + extra + ["--workers", "1", "--quiet"], project, cwd=project)
    sens = project / "examples" / "out" / "sensitivity"
    op = pd.read_csv(sens / "op.csv", comment="#")
    for _, g in op.groupby("output"):
        top = g.sort_values("mu_star [%/%]", ascending=False)["parameter"].tolist()
        assert top[0] in ("art.pCa_L", "art.pCa_U")
        assert float(g.loc[g["parameter"] == "art.k_tau", "mu_star [%/%]"].iloc[0]) == 0.0
    loc = pd.read_csv(sens / "op_local.csv", comment="#")
    assert np.all((loc["value"] > 40) & (loc["value"] < 120))               # r [um] at the centre
    assert np.all(loc.loc[loc["parameter"] == "art.k_tau", "normalised [%/%]"] == 0.0)
    series = pd.read_csv(sens / "dyn_series.csv", comment="#")
    assert series.shape[0] > 100
    assert_pngs(sens, ["op.png", "dyn.png", "fit_error.png"])

    script = [ln for ln in blocks[1].splitlines() if ln.strip()]
    assert script == ["python examples/sensitivity/run_fit_error.py"]
    text = run([sys.executable, "examples/sensitivity/run_fit_error.py", "--only", "mult10", "local", "--workers", "1"],
               project, cwd=project)
    assert "| mult10 |" in text and "| local |" in text
    quick = project / "sensitivity"  # HEMOCIRCUIT_EXAMPLES_OUT/sensitivity; results/ untouched
    assert not (project / "examples" / "sensitivity" / "results").exists()
    local = pd.read_csv(quick / "fit_error_local.csv", comment="#")
    assert local["value"].iloc[0] == pytest.approx(1.74, abs=0.02)          # um: the 1 um noise's rms
    mult = pd.read_csv(quick / "fit_error_mult10.csv", comment="#")
    top2 = mult.sort_values("mu_star [%/%]", ascending=False)["parameter"].tolist()[:2]
    assert set(top2) == {"art.pCa_U", "art.pCa_L"}                          # the thesis's finding
    assert_pngs(quick, ["fit_error_mult10.png"])


# ------------------------------------------------------------------ the notebook ----------
def _has_nbclient():
    import importlib.util
    return all(importlib.util.find_spec(m) is not None for m in ("nbclient", "nbformat", "ipykernel"))


def test_quickstart_notebook(tmp_path, monkeypatch):
    """examples/quickstart.ipynb runs top to bottom (its own asserts check the physics), from
    examples/ as Jupyter starts it; it writes only under HEMOCIRCUIT_EXAMPLES_OUT/quickstart."""
    path = EXAMPLES / "quickstart.ipynb"
    nb = json.loads(path.read_text(encoding="utf-8"))
    assert nb["nbformat"] == 4 and nb["metadata"]["kernelspec"]["name"] == "python3"
    cells = [c for c in nb["cells"] if c["cell_type"] == "code"]
    assert all(not c["outputs"] for c in cells)  # committed without outputs
    code = "\n".join("".join(c["source"]) for c in cells)
    for call in ("hc.load", "operating_point()", ".simulate(", "frequency_response(", "fit(", "to_dataframe()"):
        assert call in code, call

    for k, v in quick_env(tmp_path).items():
        monkeypatch.setenv(k, v)
    if _has_nbclient():
        import nbclient
        import nbformat

        book = nbformat.read(str(path), as_version=4)
        nbclient.NotebookClient(book, timeout=300, kernel_name="python3",
                                resources={"metadata": {"path": str(EXAMPLES)}}).execute()
        ns = None
    else:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        monkeypatch.chdir(EXAMPLES)
        ns = {"__name__": "__main__"}
        try:
            for k, c in enumerate(cells):
                exec(compile("".join(c["source"]), f"quickstart.ipynb code cell {k + 1}", "exec"), ns)
        finally:
            plt.close("all")

    out = tmp_path / "quickstart"
    assert sorted(os.listdir(tmp_path)) == ["quickstart"]
    import hemocircuit as hc
    tr = hc.Result.load(out / "step_80_72.csv")
    q = tr["Q(Rla)"]
    assert 5 < q[-1] < 12 and q.min() < q[-1]                             # the flow recovers after the step
    rep = json.loads((out / "fit_passive" / "report.json").read_text())
    l0 = {p["path"]: p["value"] for p in rep["parameters"]}["art.l0"]
    assert l0 == pytest.approx(77.5e-6, rel=0.01)
    if ns is not None:
        assert ns["fr"].n_rows == 6 and ns["table"].shape == (3, 4)


# ------------------------------------------------------------------ docs/body.md ----------
def test_body_doc_commands(project):
    """docs/body.md's commands, as written, in a scratch project (every output written): the
    two long ones shortened (the 600 s run to 20 s; the 20-member tau_Ca grid to two members of
    5 s).  What they print holds the page's physics: the intact beds lead the pressure at LF
    (30-60 deg) and the cuff release gives an ARI of 4-7."""
    text = (ROOT / "docs" / "body.md").read_text(encoding="utf-8")
    commands = re.findall(r"^    (hemocircuit .*)$", text, flags=re.M)
    assert len(commands) >= 9, commands
    short = {"--t-end 600 --dt 0.01": "--t-end 20 --dt 0.01",
             "--t-end 600 --dt 0.1 --grid left.art.tau_Ca=0.1:2.0:0.1s": "--t-end 5 --dt 0.1 --grid left.art.tau_Ca=0.1,2s"}
    printed = {}
    for line in commands:
        for long, brief in short.items():
            line = line.replace(long, brief)
        argv = shlex.split(line)
        printed[argv[1]] = run([hemocircuit_cli()] + argv[1:], project, cwd=project)
    for out in ("body.csv", "body.png", "body.npz", "grid.npz", "low.csv", "fl.npz", "tfa.png", "cuff.npz"):
        assert (project / out).stat().st_size > 0, out
    lf = re.search(r"^\s*LF\s+(\S+)\s+(\S+)\s+(\S+)\s+(\S+)\s+(\S+)", printed["tfa"], flags=re.M)
    assert 30.0 <= float(lf.group(5)) <= 60.0, printed["tfa"]
    ari = float(re.search(r"ARI (\S+)", printed["ari"]).group(1))
    assert 4.0 <= ari <= 7.0, printed["ari"]
