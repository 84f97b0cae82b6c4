"""Every validation error is triggered by a bad netlist in tests/netlists/bad/ and names the
file, the element and (where it applies) the node; the CLI reports it without a traceback."""
import subprocess
import sys

import pytest

import hemocircuit as hc
from hemocircuit.cli import main
from hemocircuit.errors import HemocircuitError, NetlistError, TopologyError

from paths import BAD, PAYNE06

# file, exception type, element named, node named, fragments the message must contain
CASES = [
    ("unknown_type.yaml", NetlistError, "Rx", None, ["unknown component type 'resistorr'", "resistor"]),
    ("wrong_node_count.yaml", NetlistError, "R3", None, ["2 terminals", "3 node(s)"]),
    ("missing_param.yaml", NetlistError, "Rm", None, ["missing parameter 'R'", "mmHg*s/mL"]),
    ("unknown_param.yaml", NetlistError, "Ru", None, ["unknown parameter", "Rx"]),
    ("nonphysical_R.yaml", NetlistError, "Rz", None, ["'R'", "not physical", "0 <"]),
    ("nonphysical_k.yaml", NetlistError, "Ck", None, ["'k'", "not physical", "-0.186"]),
    ("wrong_dimension.yaml", NetlistError, "Rd", None, ["'R'", "dimension", "mmHg*s/mL"]),
    ("bare_number.yaml", NetlistError, "Rb", None, ["'R'", "no unit"]),
    ("duplicate_id.yaml", NetlistError, "R1", None, ["duplicate element id 'R1'"]),
    ("dangling_node.yaml", TopologyError, "R2", "loose", ["only one element terminal"]),
    ("shorted_element.yaml", TopologyError, "Rs", "in", ["both terminals", "'in'"]),
    ("no_ground_path.yaml", TopologyError, "Rf1", "x", ["no path to 'ground'", "'y'"]),
    ("no_ground_at_all.yaml", TopologyError, "Ps", "in", ["no element connects to 'ground'"]),
    ("pressure_loop.yaml", TopologyError, "Cp", "in", ["loop made only of pressure-defining", "Ps", "Cp"]),
    ("inductor_across_source.yaml", TopologyError, "Lx", None, ["inductor", "Ps", "Lx", "no operating point"]),
    ("pressure_loop_sources.yaml", TopologyError, "Cb", None, ["loop made only of pressure-defining", "Ps1", "Ps2"]),
    ("flow_only_node.yaml", TopologyError, "L1", "m", ["only through flow-defining"]),
    ("store_only_node.yaml", TopologyError, "Ca", "ic", ["constraints:", "{node: ic, volume:",
                                                         "V(Ca) - V(Cic)", "calibration"]),
    ("malformed.yaml", NetlistError, None, None, ["not valid YAML", "line 4"]),
    ("duplicate_key.yaml", NetlistError, None, None, ["duplicate key 'R'", "line 4"]),
    ("extends_cycle_a.yaml", NetlistError, None, None, ["'extends' cycle", "extends_cycle_b.yaml"]),
    ("remove_missing.yaml", NetlistError, "Rnope", None, ["cannot remove 'Rnope'", "base_rc.yaml"]),
    ("change_missing.yaml", NetlistError, "Cnope", None, ["cannot change 'Cnope'"]),
    ("unknown_param_ref.yaml", NetlistError, "Ps", None, ["${Pinn}", "Pin"]),
]


def test_every_bad_netlist_has_a_case():
    assert {c[0] for c in CASES} | {"extends_cycle_b.yaml"} == {p.name for p in BAD.glob("*.yaml")}


@pytest.mark.parametrize("name, exc_type, element, node, fragments", CASES, ids=[c[0] for c in CASES])
def test_bad_netlist(name, exc_type, element, node, fragments):
    path = BAD / name
    with pytest.raises(HemocircuitError) as ei:
        hc.load(str(path))
    e = ei.value
    assert type(e) is exc_type, f"{type(e).__name__}: {e}"
    msg = str(e)
    assert e.file == str(path) and str(path) in msg
    assert e.element == element
    if element:
        assert f"element '{element}'" in msg
    if node is not None:
        assert e.node == node and f"node '{node}'" in msg
    for frag in fragments:
        assert frag in msg, (frag, msg)


def test_pressure_loop_names_a_node_of_the_loop():
    with pytest.raises(TopologyError) as ei:
        hc.load(str(BAD / "pressure_loop_sources.yaml"))
    assert ei.value.node in {"a", "b", "ground"}
    assert f"node '{ei.value.node}'" in str(ei.value)


@pytest.mark.parametrize("name", [c[0] for c in CASES])
def test_cli_check_reports_without_traceback(name, capsys):
    path = str(BAD / name)
    assert main(["check", path]) == 2
    out, err = capsys.readouterr()
    assert err.startswith("error: ") and path in err
    assert "Traceback" not in err and "Traceback" not in out
    assert "ok:" not in out


def test_cli_process_exit_status_and_stderr():
    path = str(BAD / "dangling_node.yaml")
    r = subprocess.run([sys.executable, "-m", "hemocircuit.cli", "check", path], capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 2
    assert "Traceback" not in r.stderr
    assert "element 'R2'" in r.stderr and "node 'loose'" in r.stderr and path in r.stderr


def test_cli_check_good_netlist(capsys):
    assert main(["check", str(PAYNE06)]) == 0
    out, err = capsys.readouterr()
    assert "ok: the netlist is valid" in out and "8 elements, 6 nodes, 1 states" in out and err == ""


@pytest.mark.parametrize("args, fragments", [
    (["--set", "Pa.value=90"], ["element 'Pa'", "no unit"]),
    (["--set", "Rla.R=-1mmHg*s/mL"], ["element 'Rla'", "not physical"]),
    (["--set", "Rla.R=1 mmHg"], ["element 'Rla'", "dimension"]),
    (["--set", "Rla.Q=1 mmHg"], ["element 'Rla'", "no parameter 'Q'"]),
    (["--set", "Nope.R=1 mmHg"], ["no element 'Nope'"]),
    (["--set", "Rla=1"], ["ID.PARAM"]),
    (["--set", "Rla.R"], ["ID.PARAM=VALUE"]),
])
def test_cli_bad_set_values(args, fragments, capsys):
    assert main(["check", str(PAYNE06)] + args) == 2
    _, err = capsys.readouterr()
    assert "Traceback" not in err
    for frag in fragments:
        assert frag in err, (frag, err)


def test_cli_missing_files(tmp_path, capsys):
    assert main(["check", str(tmp_path / "nope.yaml")]) == 2
    assert "not found" in capsys.readouterr().err
    assert main(["check", str(PAYNE06), "--protocol", str(tmp_path / "nope.yaml")]) == 2
    assert "protocol file not found" in capsys.readouterr().err


def test_bad_protocol_files(write, capsys):
    p = write("events:\n  - {at: 1 s, set: {Pa.value: 50}}\n", "p1.yaml")
    assert main(["check", str(PAYNE06), "--protocol", str(p)]) == 2
    err = capsys.readouterr().err
    assert "no unit" in err and "event at 1 s" in err and str(p) in err
    p = write("events:\n  - {at: 1, set: {Pa.value: 50 mmHg}}\n", "p2.yaml")
    assert main(["check", str(PAYNE06), "--protocol", str(p)]) == 2
    assert "event 0 time" in capsys.readouterr().err
    p = write("events:\n  - {at: 1 s, set: {Pa.nope: 50 mmHg}}\n", "p3.yaml")
    assert main(["check", str(PAYNE06), "--protocol", str(p)]) == 2
    assert "no parameter 'nope'" in capsys.readouterr().err
    p = write("evnts: []\n", "p4.yaml")
    assert main(["check", str(PAYNE06), "--protocol", str(p)]) == 2
    assert "unknown protocol key" in capsys.readouterr().err


def test_constraint_errors(write):
    base = (BAD / "store_only_node.yaml").read_text()
    p = write(base + "constraints:\n  - {node: ic}\n", "c1.yaml")
    with pytest.raises(NetlistError, match="needs 'volume'") as ei:
        hc.load(str(p))
    assert ei.value.node == "ic" and ei.value.file == str(p)
    p = write(base + "constraints:\n  - {node: ic, volume: 3}\n", "c2.yaml")
    with pytest.raises(NetlistError, match="no unit"):
        hc.load(str(p))
    p = write(base + "constraints:\n  - {node: a, volume: 3 mL}\n", "c3.yaml")
    with pytest.raises(TopologyError, match="add 'constraints"):
        hc.load(str(p))  # 'a' is not the store-only node
    p = write(base + "constraints:\n  - {node: ic, volume: 3 mL}\n  - {node: a, volume: 3 mL}\n", "c4.yaml")
    with pytest.raises(NetlistError, match="does not match a conservation law") as ei:
        hc.load(str(p))
    assert ei.value.node == "a"
    p = write(base + "constraints:\n  - {node: ic, pressure: 10 mmHg, when: {Px.value: 80 mmHg}}\n", "c5.yaml")
    with pytest.raises(NetlistError, match="no element 'Px'"):
        hc.load(str(p))


