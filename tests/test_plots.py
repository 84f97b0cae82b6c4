"""Every default plot has data and labelled axes (quantity and unit); Bode plots have one line
per grid member; the circuit drawing is legible.  The figures are caught before they are
written and inspected."""
import numpy as np
import pytest

import hemocircuit.io as hio
from hemocircuit.cli import main
from hemocircuit.results import Result

from paths import ROOT

NETS = ROOT / "netlists"

RC_SINE = """
name: rc-sine
elements:
  - {id: Ps, type: pressure_source, nodes: [in, ground], value: 60 mmHg}
  - {id: R1, type: resistor,        nodes: [in, a],      R: 2 mmHg*s/mL}
  - {id: R2, type: resistor,        nodes: [a, ground],  R: 1 mmHg*s/mL}
  - {id: C1, type: compliance,      nodes: [a, ground],  C: 0.5 mL/mmHg, V0: 1 mL}
outputs: [P(a), Q(R2)]
derived:
  conductance: {expr: "Q(R1) / (P(in) - P(a))", unit: mL/s/mmHg}
"""


@pytest.fixture
def figures(monkeypatch):
    """The figures the plots would have written: [(path, figure)]."""
    import importlib
    caught = []

    def catch(fig, path, dpi=110):
        fig.canvas.draw()
        caught.append((str(path), fig))

    monkeypatch.setattr(hio, "save_figure", catch)
    for mod in ("ac", "freq", "envelope", "stability"):
        m = importlib.import_module(f"hemocircuit.analyses.{mod}")
        monkeypatch.setattr(m, "save_figure", catch)
    yield caught
    import matplotlib.pyplot as plt
    plt.close("all")


def lines_with_data(ax):
    out = []
    for ln in ax.get_lines():
        y = np.asarray(ln.get_ydata(), dtype=float)
        if y.size > 1 and np.isfinite(y).sum() > 1 and ln.get_label() and not ln.get_label().startswith("_"):
            out.append(ln)
    return out


def assert_labelled(ax, quantity=None):
    """y label reads 'quantity [unit]' (x label too, on the bottom panel)."""
    yl = ax.get_ylabel()
    assert "[" in yl and yl.endswith("]") and yl.split("[")[0].strip(), yl
    if quantity:
        assert yl.startswith(quantity), yl


def data_axes(fig):
    return [ax for ax in fig.axes if ax.get_label() != "<colorbar>"]


def test_dc_default_plot_shows_outputs_of_interest_by_unit(write, figures, tmp_path):
    assert main(["dc", str(write(RC_SINE)), "--sweep", "Ps.value=10:100:10mmHg", "--plot",
                 str(tmp_path / "dc.png"), "--quiet"]) == 0
    (_, fig), = figures
    axes = data_axes(fig)
    assert len(axes) == 3  # mmHg, mL/s, mL/s/mmHg: one panel per unit, not per column
    for ax in axes:
        assert lines_with_data(ax)
        assert_labelled(ax)
    assert axes[-1].get_xlabel() == "Ps.value [mmHg]"
    labels = {ln.get_label() for ax in axes for ln in lines_with_data(ax)}
    assert labels == {"P(a)", "Q(R2)", "conductance"}  # the netlist's outputs: and derived:
    cond = next(ln for ax in axes for ln in lines_with_data(ax) if ln.get_label() == "conductance")
    np.testing.assert_allclose(cond.get_ydata(), 0.5)  # 1/R1, computed from the columns


def test_tran_plot_marks_identical_columns_and_log_axis_over_decades(figures, tmp_path):
    t = np.linspace(0, 10, 101)
    res = Result({"time": t, "Q(A)": 1 + t, "Q(B)": 1 + t, "x": np.exp(-t)},
                 {"time": "s", "Q(A)": "mL/s", "Q(B)": "mL/s", "x": "M"}, index=["time"],
                 metadata={"analysis": "tran", "interest": {"outputs": ["Q(A)", "Q(B)", "x"], "derived": {}}})
    res.plot(tmp_path / "t.png")
    (_, fig), = figures
    q_ax, x_ax = data_axes(fig)
    assert [ln.get_label() for ln in lines_with_data(q_ax)] == ["Q(A) = Q(B)"]  # not hidden under each other
    assert x_ax.get_yscale() == "log" and q_ax.get_yscale() == "linear"
    assert_labelled(x_ax, "x")
    assert x_ax.get_xlabel() == "time [s]"


def test_compare_plot_one_line_per_netlist(write, figures, tmp_path):
    a = NETS / "payne06_passive.yaml"
    b = write(f"name: stiffer\nextends: {a}\nchange:\n  Rla: {{R: 0.8 mmHg*s/mL}}\n", "b.yaml")
    assert main(["compare", str(a), str(b), "--sweep", "Pa.value=40:120:20mmHg", "--plot",
                 str(tmp_path / "cmp.png"), "--quiet"]) == 0
    (path, fig), = figures
    assert path.endswith("cmp.png")
    axes = data_axes(fig)
    assert 1 <= len(axes) <= 6
    for ax in axes:
        assert_labelled(ax)
        assert len(lines_with_data(ax)) % 2 == 0  # every quantity once per netlist
    legend = " ".join(t.get_text() for ax in axes for t in ax.get_legend().get_texts())
    assert "netlist=payne06-passive" in legend and "netlist=stiffer" in legend


def test_ac_bode_one_line_per_grid_member(write, figures, tmp_path):
    assert main(["ac", str(write(RC_SINE)), "--input", "Ps", "--output", "P(a)", "--freq", "0.01:10Hz",
                 "--grid", "C1.C=0.1,0.5,2mL/mmHg", "--plot", str(tmp_path / "ac.png"), "--quiet"]) == 0
    (_, fig), = figures
    gain_ax, phase_ax = data_axes(fig)
    assert len(lines_with_data(gain_ax)) == 3 and len(lines_with_data(phase_ax)) == 3
    assert gain_ax.get_xscale() == "log" and gain_ax.get_yscale() == "log"
    assert "C1.C=2 mL/mmHg" in " ".join(ln.get_label() for ln in lines_with_data(gain_ax))
    assert_labelled(gain_ax)
    assert phase_ax.get_ylabel().startswith("phase [deg]") and phase_ax.get_xlabel() == "frequency [Hz]"


def test_freq_bode_one_line_per_grid_member(write, figures, tmp_path):
    assert main(["freq", str(write(RC_SINE)), "--input", "Ps", "--output", "P(a)", "--freq", "0.1,0.5Hz",
                 "--grid", "C1.C=0.5,2mL/mmHg", "--workers", "1", "--plot", str(tmp_path / "f.png"), "--quiet"]) == 0
    (_, fig), = figures
    gain_ax, phase_ax = data_axes(fig)
    assert len(lines_with_data(gain_ax)) == 2 and len(lines_with_data(phase_ax)) == 2
    for ln in lines_with_data(gain_ax):
        assert len(ln.get_xdata()) == 2  # a line over the frequencies, not one point per series
    assert "relative gain" in gain_ax.get_ylabel() and "[1]" in gain_ax.get_ylabel()


def test_stability_and_envelope_plots(write, figures, tmp_path):
    net = str(write(RC_SINE))
    assert main(["stability", net, "--sweep", "Ps.value=10:50:10mmHg", "--plot", str(tmp_path / "s.png"),
                 "--quiet"]) == 0
    assert main(["envelope", net, "--sweep", "Ps.value=20,40mmHg", "--grid", "R1.R=1,2mmHg*s/mL", "--t-end", "5",
                 "--dt", "0.5", "--workers", "1", "--plot", str(tmp_path / "e.png"), "--quiet"]) == 0
    (_, sfig), (_, efig) = figures
    re_ax = data_axes(sfig)[0]
    assert re_ax.get_ylabel().startswith("Re(lambda) [1/s]") and re_ax.get_xlabel() == "Ps.value [mmHg]"
    assert any(np.isfinite(np.asarray(ln.get_ydata(), float)).any() for ln in re_ax.get_lines())
    ax, = data_axes(efig)
    assert len(lines_with_data(ax)) == 2  # the steady state of each grid member
    assert ax.get_ylabel() == "P(a) [mmHg]" and ax.get_xlabel() == "Ps.value [mmHg]"
    assert "P(a)" in ax.get_title() and "net.yaml" in ax.get_title()


def test_graph_ground_is_readable(write, figures, tmp_path):
    assert main(["graph", str(write(RC_SINE)), "--out", str(tmp_path / "g.png")]) == 0
    (_, fig), = figures
    ax = fig.axes[0]
    ground = [t for t in ax.texts if t.get_text() == "ground"]
    assert ground and ground[0].get_color() == "white"  # white on the black ground node
    assert {t.get_text() for t in ax.texts} >= {"in", "a"}
