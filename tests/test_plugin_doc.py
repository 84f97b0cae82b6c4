"""The plug-in of docs/components.md (a Starling resistor), taken from the document, installed
through the entry point and run by the CLI through op, tran (on the compiled engine), ac and
stability, against hand-computed values; and a plug-in written against the old numpy hooks,
which still runs (numpy path, said once).

Circuit: Ps (100 mmHg) -> Ra (1 mmHg*s/mL) -> node a (compliance C = 1 mL/mmHg) -> Starling
resistor S (R = 4, P_ext = 10 mmHg) -> b held by Pv.  Collapsed (Pv = 5 < P_ext): the flow
through S is (P_a - 10)/4, so 100 - P_a = (P_a - 10)/4: P_a = 82 mmHg, q = 18 mL/s, and P_a
does not depend on Pv.  Open (Pv = 20 > P_ext): P_a = 84, q = 16, dP_a/dPv = 0.2.  Either way
dV/dt = (Ps - P_a)/Ra - (P_a - P_down)/R with P_a = V/C: one eigenvalue -(1/Ra + 1/R)/C = -1.25/s.
"""
import os
import re
import subprocess
import sys

import pytest

from paths import ROOT

NETLIST = """name: starling
elements:
  - {id: Ps, type: pressure_source, nodes: [in, ground], value: 100 mmHg}
  - {id: Ra, type: resistor, nodes: [in, a], R: 1 mmHg*s/mL}
  - {id: Ca, type: compliance, nodes: [a, ground], C: 1 mL/mmHg}
  - {id: S, type: %s, nodes: [a, b], R: 4 mmHg*s/mL, P_ext: 10 mmHg}
  - {id: Pv, type: pressure_source, nodes: [b, ground], value: 5 mmHg}
"""

LEGACY = '''"""A Starling resistor written against the old vectorised numpy hooks (no kernel)."""
import numpy as np

from hemocircuit.component import Component, Param


class OldStarling(Component):
    type_name = "old_starling"
    terminals = ("a", "b")
    parameters = {"R": Param("mmHg*s/mL", lower=0.0, lower_open=True), "P_ext": Param("mmHg")}
    linear_in_pressure = False
    constant_matrix = False

    def stamp(self, p, x, u, t, src=None):
        g = 1.0 / p["R"] * np.ones(x.shape[:2])
        P_b = np.zeros(g.shape) if u is None else u[..., 1]
        open_ = P_b >= p["P_ext"]
        A = np.zeros(g.shape + (2, 2))
        b = np.zeros(g.shape + (2,))
        A[..., 0, 0], A[..., 1, 0] = g, -g
        A[..., 0, 1], A[..., 1, 1] = np.where(open_, -g, 0.0), np.where(open_, g, 0.0)
        b[..., 0], b[..., 1] = np.where(open_, 0.0, g * p["P_ext"]), np.where(open_, 0.0, -g * p["P_ext"])
        return A, b
'''


def _install(tmp_path, module, source, entry):
    """``module``.py and a dist-info whose entry point registers ``entry`` in tmp_path."""
    (tmp_path / f"{module}.py").write_text(source)
    info = tmp_path / f"{module}-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {module}\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(f"[hemocircuit.components]\n{module} = {module}:{entry}\n")


def _cli(tmp_path, *args):
    env = dict(os.environ, PYTHONPATH=str(tmp_path) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.run([sys.executable, "-m", "hemocircuit.cli", *args], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=900)


def _value(out, column):
    m = re.search(re.escape(column) + r"[^\n]*?(-?[0-9.]+(?:e[-+]?[0-9]+)?)\s*$", out, re.M)
    assert m, (column, out)
    return float(m.group(1))


@pytest.fixture(scope="module")
def plugin(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("starling")
    doc = (ROOT / "docs" / "components.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", doc, re.S)
    assert len(blocks) == 1, "docs/components.md should hold exactly one python block: the plug-in"
    _install(tmp, "starling", blocks[0], "StarlingResistor")
    (tmp / "net.yaml").write_text(NETLIST % "starling_resistor")
    return tmp


def test_op_is_the_waterfall(plugin):
    out = _cli(plugin, "op", "net.yaml")
    assert out.returncode == 0, out.stderr
    assert _value(out.stdout, "P(a) [mmHg]") == pytest.approx(82.0, rel=1e-9)
    assert _value(out.stdout, "Q(S) [mL/s]") == pytest.approx(18.0, rel=1e-9)
    opened = _cli(plugin, "op", "net.yaml", "--set", "Pv.value=20mmHg")
    assert _value(opened.stdout, "P(a) [mmHg]") == pytest.approx(84.0, rel=1e-9)
    assert _value(opened.stdout, "Q(S) [mL/s]") == pytest.approx(16.0, rel=1e-9)


def test_tran_runs_compiled_and_settles(plugin):
    out = _cli(plugin, "tran", "net.yaml", "--t-end", "20", "--dt", "1", "--compile", "wait",
               "--set", "Ps.value=110mmHg")
    assert out.returncode == 0, out.stderr
    assert "(compiled)" in out.stdout and "scipy" not in out.stdout.split("solver")[1].split("\n")[0]
    # from P_a = 110 (the start at the new value's operating point) it stays: (110 - P)/1 = (P - 10)/4
    assert _value(out.stdout, "P(a) [mmHg] at end:") == pytest.approx(90.0, rel=1e-6)


def test_ac_sees_the_collapse(plugin):
    """Collapsed, the downstream pressure does not reach a (gain 0); open it does (R_a/(R_a + R))."""
    shut = _cli(plugin, "ac", "net.yaml", "--input", "Pv", "--output", "P(a)", "--freq", "0.0001:0.001")
    opened = _cli(plugin, "ac", "net.yaml", "--input", "Pv", "--output", "P(a)", "--freq", "0.0001:0.001",
                  "--set", "Pv.value=20mmHg")
    for r in (shut, opened):
        assert r.returncode == 0, r.stderr
    gain = lambda o: float(re.search(r"gain at 0\.0001 Hz (-?[0-9.e+-]+)", o).group(1))  # noqa: E731
    assert gain(shut.stdout) == pytest.approx(0.0, abs=1e-12)
    assert gain(opened.stdout) == pytest.approx(0.2, rel=1e-4)


def test_stability_eigenvalue(plugin):
    out = _cli(plugin, "stability", "net.yaml", "--sweep", "Ps.value=50:150:50mmHg")
    assert out.returncode == 0, out.stderr
    rows = re.findall(r"^\s+(50|100|150)\s+stable node\s+(-?[0-9.e+-]+)", out.stdout, re.M)
    assert len(rows) == 3, out.stdout
    for _, lam in rows:
        assert float(lam) == pytest.approx(-1.25, rel=1e-5)


def test_a_legacy_numpy_plugin_still_runs_and_says_so_once(tmp_path):
    _install(tmp_path, "old_starling", LEGACY, "OldStarling")
    (tmp_path / "net.yaml").write_text(NETLIST % "old_starling")
    out = _cli(tmp_path, "tran", "net.yaml", "--t-end", "2", "--dt", "1", "--set", "Ps.value=110mmHg")
    assert out.returncode == 0, out.stderr
    assert (out.stdout + out.stderr).count("has no kernel functions") == 1
    assert "numpy path" in out.stderr + out.stdout and "docs/components.md" in out.stderr + out.stdout
    assert "(compiled)" not in out.stdout
    assert _value(out.stdout, "P(a) [mmHg] at end:") == pytest.approx(90.0, rel=1e-6)
