"""Netlist features: extends chains, relative paths, ${name} parameters, expressions, the
ID.PARAM namespace (with_values, sweeps, protocols), constraints, CLI outputs."""
import csv
import json
import math

import numpy as np
import pytest

import hemocircuit as hc
from hemocircuit.cli import main
from hemocircuit.errors import NetlistError, TopologyError
from hemocircuit.protocol import Protocol

from paths import NETLISTS, PAYNE06, ROOT

MMHG, CMH2O = 133.322387415, 98.0665


# ----------------------------------------------------------------------- extends ----------
@pytest.fixture
def chain(write):
    """A (lib/A.yaml) <- B (lib/variants/B.yaml) <- C (C.yaml), in a project folder (B reads
    ../A.yaml: files are read inside the project, see hemocircuit.access)."""
    write("[project]\nname = 'chain'\n", "pyproject.toml")
    write("""
        time [s],value [mL/s]
        0,0
        10,20
        """, "lib/tables/ramp.csv")
    a = write("""
        name: A
        parameters:
          Pin: 80 mmHg
          Rbase: 2 mmHg*s/mL
          Rhalf: ${Rbase} / 2
        elements:
          - {id: Ps, type: pressure_source, nodes: [in, ground], value: "${Pin}"}
          - {id: R1, type: resistor,        nodes: [in, a],      R: "${Rbase}"}
          - {id: R2, type: resistor,        nodes: [a, ground],  R: "${Rhalf}"}
          - {id: C1, type: compliance,      nodes: [a, ground],  C: 1 mL/mmHg}
          - {id: Qx, type: flow_source,     nodes: [ground, a],  value: 0 mL/s}
        """, "lib/A.yaml")
    b = write("""
        name: B
        extends: ../A.yaml
        parameters: {Rbase: 4 mmHg*s/mL}
        change:
          R2: {R: 6 mmHg*s/mL}
        add:
          - {id: R3, type: resistor, nodes: [a, b],      R: 1 mmHg*s/mL}
          - {id: R4, type: resistor, nodes: [b, ground], R: 3 mmHg*s/mL}
        """, "lib/variants/B.yaml")
    c = write("""
        extends: lib/variants/B.yaml
        parameters: {Pin: 100 mmHg}
        remove: [R4]
        change:
          R1: {R: 1 mmHg*s/mL}
          Qx: {amplitude: 0 mL/s}
        add:
          - {id: Cb, type: compliance, nodes: [b, ground], C: 0.5 mL/mmHg}
        """, "C.yaml")
    return a, b, c


def test_extends_chain(chain):
    a, b, c = (hc.load(str(p)) for p in chain)
    # A: Rbase = 2 -> R1 = 2, Rhalf = 1 -> R2 = 1: P(a) = 80 * 1/3
    assert a.parameters.values["R2.R"][0] == 1.0
    assert a.operating_point()["P(a)"] == pytest.approx(80 / 3, rel=1e-12)
    # B: Rbase = 4 (overridden) -> R1 = 4, R2 = 6 (changed) parallel to R3 + R4 = 4 -> 2.4
    assert b.parameters.values["R1.R"][0] == 4.0
    assert b.operating_point()["P(a)"] == pytest.approx(80 * 2.4 / 6.4, rel=1e-12)
    assert b.netlist.name == "B"
    # C: Pin = 100 (overridden), R1 = 1 (changed), R4 removed, Cb added: P(a) = 100 * 6/7
    assert sorted(c.elements) == ["C1", "Cb", "Ps", "Qx", "R1", "R2", "R3"]
    op = c.operating_point()
    assert op["P(a)"] == pytest.approx(600 / 7, rel=1e-12)
    assert op["P(b)"] == pytest.approx(600 / 7, rel=1e-12)
    assert op["V(Cb)"] == pytest.approx(0.5 * 600 / 7, rel=1e-12)
    assert c.netlist.name == "B"  # inherited when not given
    # each element remembers the file that last defined it
    assert c.elements["Ps"].file == str(chain[0])
    assert c.elements["R3"].file == str(chain[1])
    assert c.elements["R1"].file == str(chain[2]) and c.elements["Cb"].file == str(chain[2])
    # the base files are unchanged by loading the variants
    assert hc.load(str(chain[0])).parameters.values["R1.R"][0] == 2.0


def test_extends_keeps_table_paths_relative_to_their_own_file(chain, write):
    base = chain[0]
    base.write_text(base.read_text().replace("value: 0 mL/s}", "value: {pwl: {file: tables/ramp.csv}}}"))
    # B and C live in other folders; the table stays relative to A's folder
    for p in chain:
        c = hc.load(str(p))
        res = c.simulate(5.0, dt=1.0)
        np.testing.assert_allclose(res["Q(Qx)"], 2.0 * res.t, rtol=1e-12, atol=1e-12)
    # even when a variant changes another parameter of that element
    v = write("extends: C.yaml\nchange: {Qx: {amplitude: 1 mL/s, frequency: 0 Hz}}\n", "D.yaml")
    assert hc.load(str(v)).parameters.values["Qx.amplitude"][0] == 1.0


def test_extends_errors_name_the_variant_file(chain, write):
    v = write("extends: C.yaml\nadd:\n  - {id: R9, type: resistor, nodes: [a, ground], R: -1 mmHg*s/mL}\n",
              "bad/V.yaml")
    v.write_text(v.read_text().replace("C.yaml", "../C.yaml"))
    with pytest.raises(NetlistError) as ei:
        hc.load(str(v))
    assert ei.value.file == str(v) and ei.value.element == "R9"
    v = write("extends: C.yaml\nelements: []\n", "V2.yaml")
    with pytest.raises(NetlistError, match="add/remove/change"):
        hc.load(str(v))
    v = write("elements: []\nremove: [R1]\n", "V3.yaml")
    with pytest.raises(NetlistError, match="needs 'extends'"):
        hc.load(str(v))
    v = write("extends: C.yaml\nchange: {R1: {id: Rz}}\n", "V4.yaml")
    with pytest.raises(NetlistError, match="cannot change an element's id"):
        hc.load(str(v))
    v = write("extends: nowhere/X.yaml\n", "V5.yaml")
    with pytest.raises(NetlistError, match="not found"):
        hc.load(str(v))


def test_extends_with_base_rc(write):
    """A variant of the shared test base, changing the element type and nodes."""
    v = write(f"""
        extends: {NETLISTS / 'base_rc.yaml'}
        change:
          C1: {{type: log_compliance, k: 0.2 1/mL, P0: 0 mmHg, Vn: 10 mL, C: null}}
        """)
    with pytest.raises(NetlistError, match=r"unknown parameter\(s\) \['C'\]"):
        hc.load(str(v), allow_paths=[NETLISTS])
    v = write(f"""
        extends: {NETLISTS / 'base_rc.yaml'}
        parameters: {{Pin: 30 mmHg}}
        remove: [C1]
        add:
          - {{id: C1, type: log_compliance, nodes: [a, ground], k: 0.2 1/mL, P0: 0 mmHg, Vn: 10 mL}}
        """)
    op = hc.load(str(v), allow_paths=[NETLISTS]).operating_point()
    assert op["V(C1)"] == pytest.approx(10 + math.log(30) / 0.2, rel=1e-10)


# -------------------------------------------------------------------- parameters ----------
def test_the_documented_netlist_shape_loads_verbatim(write):
    """The example of the issue / docs/netlist.md, with ``${Pic}`` unquoted inside ``{...}``."""
    c = hc.load(write("""
        name: windkessel-demo
        description: free text
        parameters:                 # optional named quantities, referenced as ${name} in values
          Pic: 10 mmHg
        elements:
          - {id: Pa,  type: pressure_source, nodes: [in, ground], value: 80 mmHg}
          - {id: Rla, type: resistor,        nodes: [in, a],      R: 0.4 mmHg*s/mL}
          - {id: Ca,  type: log_compliance,  nodes: [a, ic],      k: 0.558 1/mL, P0: -2.25 mmHg, Vn: 3 mL}
          - {id: Pic, type: pressure_source, nodes: [ic, ground], value: ${Pic}}
        """))
    assert c.netlist.name == "windkessel-demo" and c.netlist.description == "free text"
    op = c.operating_point()
    # no flow at DC: P(a) = 80, V(Ca) = 3 + ln(80 - 10 + 2.25)/0.558 = 3 + 4.28012.../0.558
    assert op["P(a)"] == pytest.approx(80.0, rel=1e-12)
    assert op["V(Ca)"] == pytest.approx(10.6704880412053, rel=1e-10)
    assert op["Ca.C"] == pytest.approx(1 / (0.558 * 72.25), rel=1e-10)


def test_dollar_parameters(write):
    c = hc.load(write("""
        parameters:
          P1: 90 mmHg
          P2: ${P1}
          Rtot: 10 mmHg*s/mL
        elements:
          - {id: Ps, type: pressure_source, nodes: [in, ground], value: "${P2} - 10 mmHg"}
          - {id: R1, type: resistor,   nodes: [in, a],     R: "${Rtot} * 0.3"}
          - {id: R2, type: resistor,   nodes: [a, ground], R: "0.7 * ${Rtot}"}
          - {id: C1, type: compliance, nodes: [a, ground], C: 1 mL/mmHg}
        """))
    assert c.parameters.values["Ps.value"][0] == pytest.approx(80.0, rel=1e-12)
    assert c.parameters.values["R1.R"][0] == pytest.approx(3.0, rel=1e-12)
    assert c.operating_point()["P(a)"] == pytest.approx(56.0, rel=1e-12)
    assert c.netlist.parameters["P2"] == "90 mmHg"


@pytest.fixture
def expr_circuit(write):
    return hc.load(write("""
        parameters:
          rho_b: 1.06 kg/L
          Lb: 1 cm
          r0: 60 um
          n: 1000
          Rk: 0.5 mmHg*s/mL**2
          R0: 1 mmHg*s/mL
        elements:
          - {id: Ps, type: pressure_source, nodes: [in, ground], value: 7 mmHg}
          - {id: L1, type: inductor,   nodes: [in, c],     L: "= rho_b * Lb / (pi * r0**2 * n)"}
          - {id: R1, type: resistor,   nodes: [c, d],      R: 3 mmHg*s/mL}
          - {id: R2, type: resistor,   nodes: [d, ground], R: "= 2 * R1.R"}
          - {id: C1, type: compliance, nodes: [d, ground], C: 1 mL/mmHg, V0: 4 mL}
          - {id: R3, type: resistor,   nodes: [in, ground], R: "= Rk * C1.V + R0"}
        """))


def test_expression_following_another_parameter(expr_circuit):
    c = expr_circuit
    op = c.operating_point()
    # R2 = 2 R1 = 6: q = 7/9, P(d) = 6 q
    assert op["Q(R2)"] == pytest.approx(7 / 9, rel=1e-12)
    assert op["P(d)"] == pytest.approx(42 / 9, rel=1e-12)
    # the expression follows R1 when it is changed (same ID.PARAM path as --set)
    c = c.with_values({"R1.R": "5 mmHg*s/mL"})
    op = c.operating_point()
    assert op["Q(R2)"] == pytest.approx(7 / 15, rel=1e-12)
    assert op["P(d)"] == pytest.approx(70 / 15, rel=1e-12)
    # a parameter that follows an expression cannot be set
    with pytest.raises(NetlistError, match="follows an expression"):
        c.with_values({"R2.R": "1 mmHg*s/mL"})
    # sweeping the parameter an expression follows
    sw = c.dc_sweep("R1.R", [1.0, 2.0])
    np.testing.assert_allclose(sw["Q(R2)"], [7 / 3, 7 / 6], rtol=1e-12)


def test_expression_with_netlist_parameters_and_units(expr_circuit):
    # L = rho_b Lb / (pi r0^2 n) = 1060 * 0.01 / (pi * 3.6e-9 * 1000) Pa s^2/m^3
    L_si = 1060 * 0.01 / (math.pi * (60e-6) ** 2 * 1000)
    L = L_si / MMHG * 1e-6  # mmHg s^2/mL: 0.00702992...
    assert L == pytest.approx(0.0070299204369, rel=1e-10)
    c = expr_circuit
    idx = c.state_names.index("L1.q")
    x = np.zeros(c.nx)
    x[c.state_names.index("C1.V")] = 4.0  # P(d) = 0
    # with no flow P(c) = P(d) = 0, so dq/dt = 7 mmHg / L
    assert c.rhs(0.0, x)[idx] == pytest.approx(7 / L, rel=1e-10)


def test_expression_following_a_state(expr_circuit):
    c = expr_circuit
    iV = c.state_names.index("C1.V")
    X = np.zeros((3, c.nx))
    X[:, iV] = [5.0, 10.0, 20.0]
    out = c.outputs(0.0, X)
    # R3 = 0.5 V + 1: Q(R3) = 7 / (0.5 V + 1)
    np.testing.assert_allclose(out["Q(R3)"], 7 / (0.5 * X[:, iV] + 1), rtol=1e-12)
    # at the operating point V = V0 + C P(d) = 4 + 42/9 and the source feeds R3 as well
    op = c.operating_point()
    V = 4 + 42 / 9
    assert op["V(C1)"] == pytest.approx(V, rel=1e-12)
    assert op["Q(Ps)"] == pytest.approx(-(7 / 9 + 7 / (0.5 * V + 1)), rel=1e-12)


def test_value_of_an_expression_is_a_clear_error(expr_circuit):
    """A parameter that follows an expression has no fixed value: say so (never a silent NaN)."""
    with pytest.raises(hc.NetlistError, match="expression"):
        expr_circuit.parameters.values["R2.R"]


def test_expression_errors(write):
    net = """
        parameters: {r: 1 mmHg*s/mL, p: 1 mmHg}
        elements:
          - {{id: Ps, type: pressure_source, nodes: [in, ground], value: 1 mmHg}}
          - {{id: R1, type: resistor, nodes: [in, a], R: 2 mmHg*s/mL}}
          - {{id: R2, type: resistor, nodes: [a, ground], R: "{expr}"}}
        """.replace("{r: 1 mmHg*s/mL, p: 1 mmHg}", "{{r: 1 mmHg*s/mL, p: 1 mmHg}}")
    cases = {
        "= p * 2": "does not give a quantity in mmHg*s/mL",
        "= r - 2 * R1.R": "not physical",
        "= nope * 2": "unknown name 'nope'",
        "= Rx.R * 2": "no element 'Rx'",
        "= R2.R * 2": "refers to its own element",
        "= R1.Q * 2": "no parameter or state-only observable 'Q'",
        "= __import__('os')": "only exp, log, sqrt may be called",
        "= r if r else r": "not allowed",
        "= 10**10**10 * r": "does not give a quantity",
        "= (r": "cannot parse expression",
    }
    for i, (expr, frag) in enumerate(cases.items()):
        p = write(net.format(expr=expr), f"e{i}.yaml")
        with pytest.raises(NetlistError) as ei:
            hc.load(str(p))
        assert ei.value.element == "R2" and ei.value.file == str(p), expr
        assert frag in str(ei.value), (expr, str(ei.value))


# --------------------------------------------------------------- ID.PARAM / set ----------
def test_with_values_units_and_bounds():
    c = hc.load(str(PAYNE06))
    c = c.with_values({"Pa.value": "100 cmH2O"})
    assert c.parameters.values["Pa.value"][0] == pytest.approx(100 * CMH2O / MMHG, rel=1e-12)
    q = (100 * CMH2O / MMHG - 6) / 22.28
    assert c.operating_point()["Q(Rla)"] == pytest.approx(q, rel=1e-10)
    c = c.with_values({"Cv.k": "186 1/L"})
    assert c.parameters.values["Cv.k"][0] == pytest.approx(0.186, rel=1e-12)
    for path, value, frag in [("Rla.R", "0 mmHg*s/mL", "not physical"),
                              ("Rla.R", "-3 mmHg*s/mL", "not physical"),
                              ("Cv.k", "-1 1/mL", "not physical"),
                              ("Rla.R", "1 mmHg", "dimension"),
                              ("Rla.R", "1", "no unit"),
                              ("Rla.L", "1 mmHg", "no parameter 'L'"),
                              ("Zz.R", "1 mmHg", "no element 'Zz'"),
                              ("Rla", "1 mmHg", "ID.PARAM")]:
        with pytest.raises(NetlistError, match=frag) as ei:
            c.with_values({path: value})
        if "." in path and path.split(".")[0] in c.elements:
            assert ei.value.element == path.split(".")[0]
    # the circuit given is unchanged by the failed with_values (circuits are immutable)
    assert c.parameters.values["Rla.R"][0] == 0.4 and c.parameters.values["Cv.k"][0] == pytest.approx(0.186)


def test_load_with_values():
    c = hc.load(str(PAYNE06), {"Pa.value": "60 mmHg", "Rsa.R": "10 mmHg*s/mL"})
    q = (60 - 6) / (0.4 + 10 + 1.32 + 0.56)
    assert c.operating_point()["Q(Rsa)"] == pytest.approx(q, rel=1e-10)


# --------------------------------------------------------------------- protocols ----------
RC = """
elements:
  - {id: Ps, type: pressure_source, nodes: [in, ground], value: 50 mmHg}
  - {id: R1, type: resistor,   nodes: [in, a],     R: 2 mmHg*s/mL}
  - {id: C1, type: compliance, nodes: [a, ground], C: 0.5 mL/mmHg}
"""


def test_protocol_events_change_sources_at_their_time(write):
    c = hc.load(write(RC))
    proto = Protocol.from_dict({
        "t_end": "6 s",
        "initial": {"Ps.value": "20 mmHg"},
        "events": [{"at": "4 s", "set": {"R1.R": "1 mmHg*s/mL"}},   # listed out of order on purpose
                   {"at": "2 s", "set": {"Ps.value": "60 cmH2O"}}],
    }, circuit=c)
    assert [e.at for e in proto.events] == [2.0, 4.0]
    res = c.simulate(None, dt=0.1, protocol=proto, rtol=1e-9)
    t, Pa = res.t, res["P(a)"]
    P2 = 60 * CMH2O / MMHG
    # initial setting: the run starts from the operating point at 20 mmHg
    assert Pa[0] == pytest.approx(20.0, rel=1e-12)
    assert np.all(np.abs(Pa[t < 2] - 20) < 1e-9)
    # after 2 s: exponential towards P2 with tau = 1 s; after 4 s with tau = 0.5 s
    P_at4 = P2 + (20 - P2) * math.exp(-2 / 1.0)
    ref = np.where(t < 2, 20, np.where(t < 4, P2 + (20 - P2) * np.exp(-(t - 2) / 1.0),
                                        P2 + (P_at4 - P2) * np.exp(-(t - 4) / 0.5)))
    assert np.max(np.abs(Pa - ref)) / P2 <= 1e-6
    # the source and the resistor flow jump at the event times
    i2 = np.flatnonzero(np.isclose(t, 2.0))
    assert res["P(in)"][i2[-1]] == pytest.approx(P2) and res["P(in)"][i2[-1] - 1] == pytest.approx(20.0)
    i4 = np.flatnonzero(np.isclose(t, 4.0))[-1]
    assert res["Q(R1)"][i4] == pytest.approx((P2 - P_at4) / 1.0, rel=1e-6)
    assert res["Q(R1)"][i4 - 1] == pytest.approx((P2 - Pa[i4 - 1]) / 2.0, rel=1e-6)
    # the circuit itself is untouched by the protocol
    assert c.parameters.values["Ps.value"][0] == 50.0 and c.parameters.values["R1.R"][0] == 2.0


def test_protocol_sets_a_waveform(write):
    c = hc.load(write(RC))
    p = write("""
        t_end: 3 s
        events:
          - {at: 1 s, set: {Ps.value: {pwl: [[1 s, 50 mmHg], [2 s, 70 mmHg]]}}}
        """, "p.yaml")
    res = c.simulate(None, dt=0.25, protocol=str(p))
    np.testing.assert_allclose(res["P(in)"], np.interp(res.t, [1, 2], [50, 70]), rtol=1e-12)


def test_protocol_via_cli_tran(write, tmp_path, capsys):
    net = write(RC)
    p = write("t_end: 4 s\nevents:\n  - {at: 1 s, set: {Ps.value: 10 mmHg}}\n", "p.yaml")
    out = tmp_path / "run.csv"
    assert main(["tran", str(net), "--protocol", str(p), "--dt", "0.5 s", "--out", str(out),
                 "--set", "R1.R=4mmHg*s/mL"]) == 0
    with open(out) as fh:
        rows = list(csv.reader(ln for ln in fh if not ln.startswith("#")))  # provenance lines skipped
    assert rows[0] == ["time [s]", "P(in) [mmHg]", "P(a) [mmHg]", "Q(Ps) [mL/s]", "Q(R1) [mL/s]",
                       "Q(C1) [mL/s]", "V(C1) [mL]", "C1.C [mL/mmHg]"]
    data = np.array(rows[1:], dtype=float)
    t = data[:, 0]
    np.testing.assert_allclose(t, np.arange(0, 4.01, 0.5))
    ref = np.where(t < 1, 50, 10 + 40 * np.exp(-(t - 1) / 2.0))  # tau = 4 * 0.5
    np.testing.assert_allclose(data[:, 2], ref, rtol=1e-4)
    np.testing.assert_allclose(data[:, 6], 0.5 * data[:, 2], rtol=1e-12)


# ------------------------------------------------------------------- constraints ----------
ICP = """
name: icp
elements:
  - {id: Pa, type: pressure_source, nodes: [in, ground], value: 100 mmHg}
  - {id: R1, type: resistor,   nodes: [in, a],   R: 1 mmHg*s/mL}
  - {id: R2, type: resistor,   nodes: [a, v],    R: 6 mmHg*s/mL}
  - {id: R3, type: resistor,   nodes: [v, out],  R: 1 mmHg*s/mL}
  - {id: Pv, type: pressure_source, nodes: [out, ground], value: 5 mmHg}
  - {id: Ca, type: compliance, nodes: [a, ic],   C: 0.2 mL/mmHg, V0: 10 mL}
  - {id: Cv, type: compliance, nodes: [v, ic],   C: 1.5 mL/mmHg, V0: 30 mL}
"""


def _pic(Pa, W):
    """Hand solution: q = (Pa - 5)/8, P(a) = Pa - q, P(v) = 5 + q;
    W = V(Ca) + V(Cv) = 40 + 0.2 (P(a) - Pic) + 1.5 (P(v) - Pic)."""
    q = (Pa - 5) / 8
    return (40 + 0.2 * (Pa - q) + 1.5 * (5 + q) - W) / 1.7


def test_store_only_node_without_constraint_says_what_to_add(write):
    with pytest.raises(TopologyError) as ei:
        hc.load(str(write(ICP)))
    e = ei.value
    assert e.node == "ic" and e.element in ("Ca", "Cv")
    assert "add 'constraints:" in str(e) and "V(Ca) + V(Cv)" in str(e)


def test_store_only_node_volume_constraint(write):
    # W = 58.6875 mL gives P(ic) = 10 mmHg at Pa = 80 mmHg (hand: 40 + 0.2*60.625 + 1.5*4.375)
    c = hc.load(write(ICP + "constraints:\n  - {node: ic, volume: 58.6875 mL}\n"))
    op = c.operating_point()
    assert op["P(ic)"] == pytest.approx(_pic(100, 58.6875), rel=1e-10)
    assert op["P(ic)"] == pytest.approx(14.2647058823529, rel=1e-10)
    assert op["V(Ca)"] + op["V(Cv)"] == pytest.approx(58.6875, rel=1e-12)
    c = c.with_values({"Pa.value": "80 mmHg"})
    op = c.operating_point()
    assert op["P(ic)"] == pytest.approx(10.0, rel=1e-10)
    assert op["P(a)"] == pytest.approx(70.625, rel=1e-12)
    # the stored volume is conserved through a transient with a pressure step
    proto = Protocol.from_dict({"events": [{"at": "1 s", "set": {"Pa.value": "120 mmHg"}}]}, circuit=c)
    res = c.simulate(20.0, dt=0.5, protocol=proto, rtol=1e-9)
    total = res["V(Ca)"] + res["V(Cv)"]
    assert np.max(np.abs(total - 58.6875)) <= 1e-9 * 58.6875
    assert res["P(ic)"][-1] == pytest.approx(_pic(120, 58.6875), rel=1e-6)
    assert res["P(ic)"][0] == pytest.approx(10.0, rel=1e-10)


def test_store_only_node_calibration_constraint(write):
    path = write(ICP + "constraints:\n  - {node: ic, pressure: 10 mmHg, when: {Pa.value: 80 mmHg}}\n")
    c = hc.load(str(path))
    # at the calibration point P(ic) is the given 10 mmHg
    c80 = hc.load(str(path), {"Pa.value": "80 mmHg"})
    op80 = c80.operating_point()
    assert op80["P(ic)"] == pytest.approx(10.0, rel=1e-10)
    W = op80["V(Ca)"] + op80["V(Cv)"]
    assert W == pytest.approx(58.6875, rel=1e-10)
    # at Pa = 100 mmHg the total found at the calibration point is kept, P(ic) moves
    op = c.operating_point()
    assert op["V(Ca)"] + op["V(Cv)"] == pytest.approx(58.6875, rel=1e-10)
    assert op["P(ic)"] == pytest.approx(_pic(100, 58.6875), rel=1e-9)
    assert op["P(ic)"] == pytest.approx(14.2647058823529, rel=1e-9)
    # and it stays calibrated when the same circuit is moved to yet another pressure
    c = c.with_values({"Pa.value": "60 mmHg"})
    assert c.operating_point()["P(ic)"] == pytest.approx(_pic(60, 58.6875), rel=1e-9)


def test_two_calibrated_store_only_nodes_at_the_same_or_different_conditions(write):
    """Two calibrations (two subcircuit instances of a calibrated netlist have them): solved
    together at one 'when', in turns at two.  Group ic as in _pic; group ic2 is Cb [a, ic2] and
    Cw [ic2, ground], conserving K = V(Cw) - V(Cb) = 20 + 1.4 P(ic2) - 0.4 P(a)."""
    two = ICP + ("  - {id: Cb, type: compliance, nodes: [a, ic2], C: 0.4 mL/mmHg, V0: 10 mL}\n"
                 "  - {id: Cw, type: compliance, nodes: [ic2, ground], C: 1.0 mL/mmHg, V0: 30 mL}\n")

    def p_a(Pa):
        return Pa - (Pa - 5) / 8

    same = hc.load(write(two + "constraints:\n  - {node: ic, pressure: 10 mmHg}\n  - {node: ic2, pressure: 12 mmHg}\n",
                         "same.yaml")).operating_point()
    assert same["P(ic)"] == pytest.approx(10.0, rel=1e-10) and same["P(ic2)"] == pytest.approx(12.0, rel=1e-10)
    c = hc.load(write(two + "constraints:\n  - {node: ic, pressure: 10 mmHg, when: {Pa.value: 80 mmHg}}\n"
                            "  - {node: ic2, pressure: 12 mmHg, when: {Pa.value: 60 mmHg}}\n", "apart.yaml"))
    q80 = 75 / 8
    W1 = 40 + 0.2 * (80 - q80 - 10) + 1.5 * (5 + q80 - 10)
    op = c.operating_point()  # at Pa = 100 mmHg
    assert op["P(ic)"] == pytest.approx(_pic(100, W1), rel=1e-9)
    assert op["P(ic2)"] == pytest.approx(12 + 0.4 * (p_a(100) - p_a(60)) / 1.4, rel=1e-9)
    assert op["V(Cw)"] - op["V(Cb)"] == pytest.approx(20 + 1.4 * 12 - 0.4 * p_a(60), rel=1e-10)


# ------------------------------------------------------------------------- CLI ------------
def test_cli_op_json(tmp_path, capsys):
    out = tmp_path / "op.json"
    assert main(["op", str(PAYNE06), "--set", "Pa.value=90mmHg", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    doc = json.loads(out.read_text())
    assert doc["metadata"]["analysis"] == "op" and doc["metadata"]["provenance"]["sets"] == {"Pa.value": "90 mmHg"}
    data = doc["values"]
    q = (90 - 6) / 22.28
    assert data["P(alpha) [mmHg]"] == pytest.approx(90 - 0.4 * q, rel=1e-10)
    assert data["Q(Rla) [mL/s]"] == pytest.approx(q, rel=1e-10)
    assert data["Q(Pa) [mL/s]"] == pytest.approx(-q, rel=1e-10)
    assert data["V(Cv) [mL]"] == pytest.approx(28 + math.log(6 + 0.56 * q - 7.75) / 0.186, rel=1e-9)
    assert "Cv.C [mL/mmHg]" in data and all(isinstance(v, float) for v in data.values())
    assert "P(alpha) [mmHg]" in printed


def test_cli_dc_sweep_pressure_flow_line(tmp_path, capsys):
    out = tmp_path / "sweep.csv"
    assert main(["dc", str(PAYNE06), "--sweep", "Pa.value=20:200:5mmHg", "--out", str(out)]) == 0
    with open(out) as fh:
        rows = list(csv.reader(ln for ln in fh if not ln.startswith("#")))  # provenance lines skipped
    head = rows[0]
    assert head[0] == "Pa.value [mmHg]" and "Q(Rla) [mL/s]" in head and "P(alpha) [mmHg]" in head
    data = np.array(rows[1:], dtype=float)
    Pa = data[:, 0]
    np.testing.assert_allclose(Pa, np.arange(20, 201, 5))
    np.testing.assert_allclose(data[:, head.index("Q(Rla) [mL/s]")], (Pa - 6) / 22.28, rtol=1e-10)


def test_cli_graph_png(tmp_path, capsys):
    out = tmp_path / "g.png"
    assert main(["graph", str(PAYNE06), "--out", str(out)]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_circuit_with_expressions_pickles(tmp_path):
    """Batches send circuits to worker processes: an expression-bound parameter must survive."""
    import pickle
    c = hc.load(str(ROOT / "netlists" / "inertia.yaml"))
    x = c.operating_point().x
    c2 = pickle.loads(pickle.dumps(c))
    assert np.array_equal(c2.rhs(0.0, x), c.rhs(0.0, x))


def test_an_expression_reads_a_parameter_with_its_waveform_on_both_paths(tmp_path):
    """Pb.value = Pa.value where Pa's value is a sine: the waveform adds to the parameter
    before the expression reads it, on the scipy path as in the compiled engine, so P(b)
    follows P(a) on both (the scipy path read the bare slot, 0, while the engine read the sine)."""
    net = tmp_path / "follow.yaml"
    net.write_text("name: follow\nelements:\n"
                   "  - {id: Pa, type: pressure_source, nodes: [a, ground], value: {sine: {offset: 80 mmHg, "
                   "amplitude: 10 mmHg, frequency: 0.5 Hz}}}\n"
                   "  - {id: R1, type: resistor, nodes: [a, m], R: 1 mmHg*s/mL}\n"
                   "  - {id: C1, type: compliance, nodes: [m, ground], C: 0.5 mL/mmHg}\n"
                   "  - {id: Pb, type: pressure_source, nodes: [b, ground], value: \"= Pa.value\"}\n"
                   "  - {id: R2, type: resistor, nodes: [b, ground], R: 1 mmHg*s/mL}\n")
    c = hc.load(str(net))
    t = np.arange(0.0, 3.0001, 0.1)
    sine = 80.0 + 10.0 * np.sin(2 * np.pi * 0.5 * t)
    for engine in ("scipy", "compiled"):
        r = c.simulate(3.0, dt=0.1, engine=engine)
        np.testing.assert_allclose(r["P(b)"], sine, rtol=0, atol=1e-9)
        np.testing.assert_allclose(r["Q(R2)"], sine, rtol=0, atol=1e-9)
