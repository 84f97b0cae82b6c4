"""One front for every command (netlist -> --set -> --protocol, loading.load_circuit), structural
options that keep the numbers already set (Circuit.with_options), initial conditions
(tran --ic, simulate(ic=...)) and a repository that stays clean when commands run."""
import csv
import shutil
import subprocess

import numpy as np
import pytest

import hemocircuit as hc
from hemocircuit.analyses import freq as freq_mod
from hemocircuit.analyses import periodic as periodic_mod
from hemocircuit.batch import build_batches
from hemocircuit.cli import main
from hemocircuit.errors import NetlistError
from hemocircuit.loading import load_circuit

from paths import NETLISTS, ROOT

NETS = ROOT / "netlists"
PAYNE06_ACTIVE = NETS / "payne06.yaml"
BASE_RC = NETLISTS / "base_rc.yaml"

pytestmark = pytest.mark.filterwarnings("ignore::RuntimeWarning")


@pytest.fixture(scope="module")
def active():
    return hc.load(PAYNE06_ACTIVE)


def read_csv(path):
    """(header, rows) of a result CSV, its '# key: value' provenance lines skipped."""
    with open(path) as fh:
        rows = list(csv.reader(ln for ln in fh if not ln.startswith("#")))
    return rows[0], rows[1:]


# ------------------------------------------------ 1. structural options keep the numbers ----
def test_with_options_keeps_values_set_on_the_changed_element(active):
    c = active.with_values({"art.tau_Ca": "5 s"})
    c = c.with_values({"Rla.R": 2 * float(c.parameters.values["Rla.R"][0])})
    new = c.with_options({"art.volume_flow": False})
    assert new.elements["art"].opts["volume_flow"] is False
    assert new.parameters.values["art.tau_Ca"][0] == 5.0        # was reset to the preset's 1 s
    assert new.parameters.values["Rla.R"][0] == c.parameters.values["Rla.R"][0]
    assert new.parameters.values["art.L"][0] == pytest.approx(50e-3)  # the netlist's value
    # and a second change keeps them again
    again = new.with_options({"art.ca_order": 2})
    assert again.parameters.values["art.tau_Ca"][0] == 5.0
    assert "art.dCa" in again.state_names


def test_with_options_keeps_per_member_values_of_a_batch(active):
    b = active.batch(3)
    b = b.with_values({"art.tau_Ca": np.array([1.0, 2.0, 3.0])})
    new = b.with_options({"art.ca_order": 2})
    assert new.B == 3
    np.testing.assert_array_equal(new.parameters.values["art.tau_Ca"], [1.0, 2.0, 3.0])


def test_with_options_keeps_a_waveform_set_on_the_circuit(active):
    c = active.with_values({"Pa.value": {"pwl": [["0 s", "80 mmHg"], ["7 s", "90 mmHg"]]}})
    new = c.with_options({"art.volume_flow": False})
    assert 7.0 in new.breakpoints(0.0, 20.0)
    # ...and a constant set over a netlist waveform stays constant
    c2 = new.with_values({"Pa.value": "85 mmHg"})
    assert c2.with_options({"art.ca_order": 2}).breakpoints(0.0, 20.0) == []


def test_preset_change_replaces_preset_values_but_keeps_explicit_ones(active):
    from hemocircuit.components.arteriole.parameters import PRESETS
    c = active.with_values({"art.eta": 0.3})        # explicit (--set)
    c = c.with_values({"art.tau_Ca": "5 s"})  # explicit
    new = c.with_options({"art.preset": "falcone91"})
    assert new.parameters.values["art.eta"][0] == 0.3
    assert new.parameters.values["art.tau_Ca"][0] == 5.0
    assert new.parameters.values["art.v"][0] == PRESETS["falcone91"]["v"] != PRESETS["kuo91"]["v"]
    assert new.parameters.values["art.L"][0] == pytest.approx(50e-3)  # written in the netlist
    assert new.parameters.values["art.n"][0] == 16000


def test_freq_grid_over_a_structural_option_keeps_set_values(active):
    """The API path of ``freq --set art.tau_Ca=5s --grid art.volume_flow=true,false``."""
    c, _ = load_circuit(PAYNE06_ACTIVE, {"art.tau_Ca": "5 s"})
    batches = build_batches(c, [{"art.volume_flow": v} for v in (True, False)])
    assert len(batches) == 2
    for bc, _ in batches:
        np.testing.assert_array_equal(bc.parameters.values["art.tau_Ca"], 5.0)


# ------------------------------------------------ 2. one CLI front, structural --set ---------
def test_op_structural_set(tmp_path, capsys):
    out = tmp_path / "op.json"
    assert main(["op", str(PAYNE06_ACTIVE), "--set", "art.ca_order=2", "--set", "art.tau_Ca=5s",
                 "--out", str(out)]) == 0
    assert "art.dCa" in out.read_text()


def test_freq_structural_set_and_grid_over_an_option(monkeypatch, tmp_path, capsys):
    seen = []
    real = freq_mod._run_chunk

    def spy(job):
        c = job[0]
        seen.append((c.elements["art"].opts["volume_flow"], c.elements["art"].opts["ca_order"],
                     c.parameters.values["art.tau_Ca"].tolist()))
        return real(job)

    monkeypatch.setattr(freq_mod, "_run_chunk", spy)
    out = tmp_path / "freq.csv"
    assert main(["freq", str(PAYNE06_ACTIVE), "--set", "art.tau_Ca=5s", "--set", "art.ca_order=2",
                 "--grid", "art.volume_flow=true,false", "--freq", "1Hz", "--step", "0", "--amplitude", "1",
                 "--rtol", "1e-5", "--workers", "1", "--out", str(out)]) == 0
    assert sorted(seen) == [(False, 2, [5.0]), (True, 2, [5.0])]
    head, rows = read_csv(out)
    assert len(rows) == 2 and all(r[head.index("error")] == "" for r in rows)  # one row per run


def test_envelope_structural_set(tmp_path, capsys):
    out = tmp_path / "env.csv"
    assert main(["envelope", str(PAYNE06_ACTIVE), "--set", "art.ca_order=2", "--sweep", "Pa.value=80mmHg",
                 "--output", "art.dCa", "--t-end", "2", "--dt", "0.1", "--workers", "1", "--out", str(out)]) == 0
    head, rows = read_csv(out)
    assert "max(art.dCa) [M/s]" in head and "Pa.value [mmHg]" in head and len(rows) == 1


def test_periodic_structural_set(monkeypatch, tmp_path, capsys):
    seen = []
    real = periodic_mod.shoot

    def spy(circuit, *a, **kw):
        seen.append(circuit.elements["C1"].opts["clamp_at_zero"])
        return real(circuit, *a, **kw)

    monkeypatch.setattr(periodic_mod, "shoot", spy)
    out = tmp_path / "orb.csv"
    assert main(["periodic", str(BASE_RC), "--forced", "Ps", "--set", "Ps.amplitude=5mmHg",
                 "--set", "Ps.frequency=0.5Hz", "--set", "C1.clamp_at_zero=true", "--output", "Q(R1)",
                 "--out", str(out)]) == 0
    assert seen == [True]
    assert "converged" in capsys.readouterr().out


def test_every_command_takes_set_and_protocol():
    from hemocircuit.cli import build_parser
    p = build_parser()
    sub = next(a for a in p._actions if a.dest == "command")
    # conformance and import-svzerod read svZeroDSolver JSON models; reproduce runs the bundled netlists;
    # tfa, ari and mx read two series from a result file or a recording
    not_on_a_netlist = {"conformance", "import-svzerod", "reproduce", "tfa", "ari", "mx"}
    for name, sp in sub.choices.items():
        if name in not_on_a_netlist:
            continue
        opts = {o for a in sp._actions for o in a.option_strings}
        assert {"--set", "--protocol"} <= opts, name


def test_protocol_initial_applies_to_batch_commands(write, tmp_path, capsys):
    proto = write("initial: {art.ca_order: 2}\n", "p.yaml")
    c, pr = load_circuit(PAYNE06_ACTIVE, {"art.tau_Ca": "5s"}, proto)
    assert pr is not None and "art.dCa" in c.state_names and c.parameters.values["art.tau_Ca"][0] == 5.0
    out = tmp_path / "env.csv"
    assert main(["envelope", str(PAYNE06_ACTIVE), "--protocol", str(proto), "--sweep", "Pa.value=80mmHg",
                 "--output", "art.dCa", "--t-end", "1", "--dt", "0.1", "--workers", "1", "--out", str(out)]) == 0


# ------------------------------------------------ 3. initial conditions ---------------------
def test_tran_ic_cli(tmp_path, capsys):
    out = tmp_path / "run.csv"
    assert main(["tran", str(BASE_RC), "--t-end", "1", "--dt", "0.5", "--ic", "C1.V=20mL", "--out", str(out)]) == 0
    head, rows = read_csv(out)
    data = np.array(rows, dtype=float)
    assert data[0, head.index("V(C1) [mL]")] == 20.0
    assert data[0, head.index("P(a) [mmHg]")] == pytest.approx(40.0)  # V / C
    # the operating point would start at V = C * 80 mmHg = 40 mL and stay there
    assert np.all(data[:, head.index("V(C1) [mL]")] < 40.0)


def test_simulate_ic_api(active):
    op = active.operating_point()
    res = active.simulate(0.5, dt=0.25, ic={"Cv.V": "20 mL", "art.Ca": "1e-7M"})
    names = active.state_names
    x0 = res.x[0]
    assert x0[names.index("Cv.V")] == 20.0
    assert x0[names.index("art.Ca")] == 1e-7
    assert res["V(Cv)"][0] == 20.0
    for k, n in enumerate(names):
        if n not in ("Cv.V", "art.Ca"):
            assert x0[k] == op.x[k], n
    # plain numbers are in the state's unit
    res2 = active.simulate(0.25, dt=0.25, ic={"Cv.V": 25.0})
    assert res2.x[0, names.index("Cv.V")] == 25.0


def test_ic_unknown_state_lists_close_matches(active, capsys):
    with pytest.raises(NetlistError, match=r"no state 'Cv\.VV'.*Cv\.V"):
        active.simulate(1.0, ic={"Cv.VV": "20 mL"})
    with pytest.raises(NetlistError, match="has no unit"):
        active.simulate(1.0, ic={"Cv.V": "20"})
    assert main(["tran", str(PAYNE06_ACTIVE), "--t-end", "1", "--ic", "art.ca=1e-7M"]) == 2
    err = capsys.readouterr().err
    assert "no state 'art.ca'" in err and "art.Ca" in err


# ------------------------------------------------ 4. the repository stays clean -------------
def _git(*args):
    return subprocess.run(["git", "-C", str(ROOT), *args], capture_output=True, text=True)


@pytest.mark.skipif(shutil.which("git") is None or not (ROOT / ".git").exists(), reason="not a git checkout")
def test_caches_are_untracked_and_ignored():
    assert _git("ls-files", "--", "*__pycache__*", "*.nbi", "*.nbc", "*.pyc").stdout == ""
    for path in ("hemocircuit/__pycache__/linalg._solve_nb-15.py311.nbi",
                 "hemocircuit/__pycache__/linalg._solve_nb-15.py311.1.nbc",
                 "components/__pycache__/x.cpython-311.pyc", "some/where/else.nbi", ".hypothesis/x",
                 ".pytest_cache/x"):
        assert _git("check-ignore", "-q", "--no-index", path).returncode == 0, path
