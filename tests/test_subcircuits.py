"""Subcircuits (netlist ``instances:``, hemocircuit.subcircuits): a netlist used as a block with
its ports wired to nodes; names, parameters, nesting, and clear errors."""
import shutil
import textwrap

import numpy as np
import pytest

import hemocircuit as hc
from hemocircuit.cli import main
from hemocircuit.errors import NetlistError

from paths import ROOT

TWO = """
name: two_hemispheres
elements:
  - {id: Pa, type: pressure_source, nodes: [carotid, ground], value: 80 mmHg}
  - {id: Pv, type: pressure_source, nodes: [jugular, ground], value: 6 mmHg}
instances:
  - {id: left, netlist: payne06.yaml, ports: {in: carotid, out: jugular}, remove: [Pa, Pv]}
  - {id: right, netlist: payne06.yaml, ports: {in: carotid, out: jugular}, remove: [Pa, Pv],
     change: {Rla: {R: 0.8 mmHg*s/mL}}}
"""


@pytest.fixture
def folder(tmp_path):
    for src in (ROOT / "netlists").glob("*.yaml"):  # the chains icp -> arterial_compliance -> payne06 ...
        shutil.copy(src, tmp_path / src.name)

    def write(text, name):
        (tmp_path / name).write_text(textwrap.dedent(text))
        return str(tmp_path / name)
    write.path = tmp_path
    return write


def test_two_instances_are_two_beds_in_parallel(folder):
    alone = hc.load(str(folder.path / "payne06.yaml")).operating_point()
    both = hc.load(folder(TWO, "two.yaml"))
    assert "left.art" in both.elements and "right.Rla" in both.elements
    op = both.operating_point()
    q_alone = alone["Q(Rla)"]
    assert op["Q(left.Rla)"] == pytest.approx(q_alone, rel=1e-9)  # the same bed at the same pressures
    assert op["P(left.alpha)"] == pytest.approx(alone["P(alpha)"], rel=1e-9)
    # the right bed has a doubled upstream resistance: its arteriole dilates, so its flow falls far
    # less than the 1/(1 + 0.4/R_total) a passive bed would lose
    q_right = op["Q(right.Rla)"]
    assert 0.99 * q_alone < q_right < q_alone
    assert op["right.art.r"] > op["left.art.r"]
    # conservation: the source delivers both beds' flow
    assert -op["Q(Pa)"] == pytest.approx(q_alone + q_right, rel=1e-9)


def test_instance_parameters_take_set_and_grid(folder, capsys):
    path = folder(TWO, "two.yaml")
    c = hc.load(path).with_values({"left.Rla.R": "0.8 mmHg*s/mL"})
    op = c.operating_point()
    assert op["Q(left.Rla)"] == pytest.approx(op["Q(right.Rla)"], rel=1e-9)
    assert main(["op", path, "--grid", "left.art.tau_Ca=1,10s", "--quiet"]) == 0
    assert "left.art.tau_Ca" in capsys.readouterr().out


def test_instances_nest_and_keep_their_own_parameters(folder):
    folder("""
        name: pair
        ports: [feed, drain]
        elements:
          - {id: Rin, type: resistor, nodes: [feed, mid], R: "${R_in}"}
        parameters: {R_in: 1 mmHg*s/mL}
        instances:
          - {id: bed, netlist: payne06_passive.yaml, ports: {in: mid, out: drain}, remove: [Pa, Pv]}
        """, "pair.yaml")
    top = folder("""
        name: top
        elements:
          - {id: Pa, type: pressure_source, nodes: [a, ground], value: 100 mmHg}
          - {id: Pv, type: pressure_source, nodes: [v, ground], value: 0 mmHg}
        instances:
          - {id: one, netlist: pair.yaml, ports: {feed: a, drain: v}, parameters: {R_in: 2 mmHg*s/mL}}
        """, "top.yaml")
    c = hc.load(top)
    assert "one.bed.Rla" in c.elements and "one.Rin" in c.elements
    assert c.parameters.values["one.Rin.R"][0] == pytest.approx(2.0)
    op = c.operating_point()
    # passive bed: series resistances 2 + 0.4 + 20 + 1.32 + 0.56 (Cv and Pic carry no steady flow)
    assert op["Q(one.Rin)"] == pytest.approx(100.0 / (2 + 0.4 + 20 + 1.32 + 0.56), rel=1e-9)


@pytest.mark.parametrize("instance, message", [
    ("{id: b, netlist: payne06.yaml, ports: {inn: x}}", "has no node 'inn' (did you mean 'in'"),
    ("{id: b, netlist: nowhere.yaml, ports: {in: x}}", "nowhere.yaml"),
    ("{id: b, netlist: payne06.yaml, port: {in: x}}", "unknown key(s) ['port'] (did you mean 'ports'"),
    ("{id: b, netlist: payne06.yaml, ports: {ground: x}}", "ground is shared by every circuit"),
    ("{id: b, netlist: payne06.yaml, parameters: {Pic2: 1 mmHg}}", "has no parameter 'Pic2'"),
    ("{id: b.c, netlist: payne06.yaml}", "needs an 'id' (letters, digits, _"),
    ("{id: b, netlist: icp.yaml, ports: {in: x}, remove: [Pa]}",
     "is calibrated at Pa.value, but the instance has no element 'Pa'; give the instance its own 'constraints:'"),
])
def test_instance_errors_name_the_instance_and_the_fix(folder, instance, message):
    path = folder(f"""
        name: bad
        elements:
          - {{id: Px, type: pressure_source, nodes: [x, ground], value: 80 mmHg}}
        instances:
          - {instance}
        """, "bad.yaml")
    with pytest.raises(NetlistError) as exc:
        hc.load(path)
    assert message in str(exc.value)
    assert "bad.yaml" in str(exc.value)


def test_a_calibrated_child_runs_with_its_own_constraints(folder):
    path = folder("""
        name: icp_bed
        elements:
          - {id: P0, type: pressure_source, nodes: [x, ground], value: 80 mmHg}
          - {id: P1, type: pressure_source, nodes: [y, ground], value: 6 mmHg}
        instances:
          - {id: b, netlist: icp.yaml, ports: {in: x, out: y}, remove: [Pa, Pv],
             constraints: [{node: ic, pressure: 10 mmHg, when: {P0.value: 80 mmHg}}]}
        """, "icp_bed.yaml")
    op = hc.load(path).operating_point()
    alone = hc.load(str(folder.path / "icp.yaml")).operating_point()
    assert op["P(b.ic)"] == pytest.approx(10.0, rel=1e-9)
    assert op["Q(b.Rla)"] == pytest.approx(alone["Q(Rla)"], rel=1e-9)


def test_declared_ports_must_all_be_connected_and_cycles_are_named(folder):
    folder("""
        name: part
        ports: [feed, drain]
        elements:
          - {id: R, type: resistor, nodes: [feed, drain], R: 1 mmHg*s/mL}
        """, "part.yaml")
    path = folder("""
        name: user
        elements:
          - {id: Px, type: pressure_source, nodes: [x, ground], value: 80 mmHg}
        instances:
          - {id: p, netlist: part.yaml, ports: {feed: x}}
        """, "user.yaml")
    with pytest.raises(NetlistError, match=r"port\(s\) \['drain'\] of .*part.yaml are not connected"):
        hc.load(path)
    folder("""
        name: a
        elements: [{id: Px, type: pressure_source, nodes: [x, ground], value: 80 mmHg}]
        instances: [{id: b, netlist: b.yaml, ports: {}}]
        """, "a.yaml")
    folder("""
        name: b
        elements: [{id: Py, type: pressure_source, nodes: [y, ground], value: 80 mmHg}]
        instances: [{id: a, netlist: a.yaml, ports: {}}]
        """, "b.yaml")
    with pytest.raises(NetlistError, match=r"instances form a cycle: .*a.yaml -> .*b.yaml -> .*a.yaml"):
        hc.load(str(folder.path / "a.yaml"))


def _flat_side(p, rla):
    return f"""
  - {{id: {p}Rla, type: resistor, nodes: [carotid, {p}alpha], R: {rla} mmHg*s/mL}}
  - {{id: {p}Rsv, type: resistor, nodes: [{p}beta, {p}v], R: 1.32 mmHg*s/mL}}
  - {{id: {p}Cv, type: log_compliance, nodes: [{p}v, {p}ic], k: 0.186 1/mL, P0: -2.25 mmHg, Vn: 28 mL}}
  - {{id: {p}Pic, type: pressure_source, nodes: [{p}ic, ground], value: 10 mmHg}}
  - {{id: {p}Rlv, type: resistor, nodes: [{p}v, jugular], R: 0.56 mmHg*s/mL}}
  - {{id: {p}art, type: arteriole, nodes: [{p}alpha, {p}beta, {p}ic], preset: kuo91, volume_flow: true,
     L: 50 mm, n: 16000}}"""


def test_two_instances_equal_the_hand_written_flat_netlist(folder):
    """The same circuit written out by hand (L_*, R_* for left.*, right.*): operating point and a
    pressure-step transient equal to 1e-12; --set reaches into an instance's arteriole."""
    from hemocircuit.protocol import Protocol
    flat = folder("""
        name: flat
        elements:
          - {id: Pa, type: pressure_source, nodes: [carotid, ground], value: 80 mmHg}
          - {id: Pv, type: pressure_source, nodes: [jugular, ground], value: 6 mmHg}""" +
                  textwrap.indent(_flat_side("L_", 0.4) + _flat_side("R_", 0.8), "        ") + "\n", "flat.yaml")
    runs = {}
    for name, path in (("inst", folder(TWO, "two.yaml")), ("flat", flat)):
        c = hc.load(path)
        proto = Protocol.from_dict({"events": [{"at": "1 s", "set": {"Pa.value": "90 mmHg"}}]}, circuit=c)
        runs[name] = (c.operating_point(), c.simulate(20.0, dt=0.5, protocol=proto, rtol=1e-8))
    pairs = {"Q(left.Rla)": "Q(L_Rla)", "Q(right.Rla)": "Q(R_Rla)", "P(right.alpha)": "P(R_alpha)",
             "left.art.r": "L_art.r", "right.art.Ca": "R_art.Ca", "V(left.Cv)": "V(L_Cv)"}
    (op_i, tr_i), (op_f, tr_f) = runs["inst"], runs["flat"]
    for a, b in pairs.items():
        assert op_i[a] == pytest.approx(op_f[b], rel=1e-12, abs=0)
        np.testing.assert_allclose(tr_i[a], tr_f[b], rtol=1e-12, atol=0)
    c = hc.load(folder(TWO, "two.yaml")).with_values({"left.art.tau_Ca": "5 s"})
    assert c.parameters.values["left.art.tau_Ca"][0] == pytest.approx(5.0)
    assert c.parameters.values["right.art.tau_Ca"][0] != pytest.approx(5.0)


INERTIA_TWICE = """
name: two_inertia_beds
parameters:
  rho_b: 2.0 kg/L                 # this netlist's own; the children's expressions keep theirs (1.06 kg/L)
elements:
  - {id: Pa, type: pressure_source, nodes: [carotid, ground], value: 80 mmHg}
  - {id: Pv, type: pressure_source, nodes: [jugular, ground], value: 6 mmHg}
  - {id: art, type: resistor, nodes: [carotid, jugular], R: 1000 mmHg*s/mL}   # an 'art' of this netlist
instances:
  - {id: left, netlist: inertia.yaml, ports: {in: carotid, out: jugular}, remove: [Pa, Pv],
     constraints: [{node: ic, pressure: 10 mmHg}]}
  - {id: right, netlist: inertia.yaml, ports: {in: carotid, out: jugular}, remove: [Pa, Pv],
     change: {art: {n: 8000}}, constraints: [{node: ic, pressure: 10 mmHg}]}
"""


def test_a_childs_expressions_read_the_instances_own_elements_and_parameters(folder):
    """inertia.yaml's Lb has L = rho_b art.L / (pi art.r^2 art.n): in each instance it reads that
    instance's arteriole and the child's rho_b (1.06 kg/L), not the including netlist's element
    'art' or its own rho_b.  Checked against the closed form at the operating point, the left bed
    against inertia.yaml alone."""
    c = hc.load(folder(INERTIA_TWICE, "two_inertia.yaml"))
    alone = hc.load(str(folder.path / "inertia.yaml"))
    op, op1 = c.operating_point(), alone.operating_point()
    assert op["Q(left.Rla)"] == pytest.approx(op1["Q(Rla)"], rel=1e-9)
    L = {}
    for side in ("left", "right"):
        g = next(g for g in c.groups if f"{side}.Lb" in g.ids)
        p = c.system.bound_params(np.atleast_2d(op.x), c.system._params_for(1), 0.0)[c.groups.index(g)]
        L[side] = float(np.ravel(p["L"])[g.ids.index(f"{side}.Lb")])
    # closed form, mmHg*s^2/mL: rho [kg/m^3] * L_bed [m] / (pi r^2 [m^2] n) in Pa*s^2/m^3 -> / 133.322 * 1e-6
    values = c.parameters.values
    assert values["left.art.n"][0] == 320 and values["right.art.n"][0] == 8000  # inertia.yaml's, changed
    for side in ("left", "right"):
        r, n, bed = op[f"{side}.art.r"] * 1e-6, values[f"{side}.art.n"][0], values[f"{side}.art.L"][0]  # m, 1, m
        expected = 1060.0 * bed / (np.pi * r ** 2 * n) / 133.322387415 * 1e-6
        assert L[side] == pytest.approx(expected, rel=1e-6), (side, L[side], expected)


CHILD_READS_PA = """
name: child
parameters:
  Qref: 10 mL/s
elements:
  - {id: Pa, type: pressure_source, nodes: [in, ground], value: 80 mmHg}
  - {id: R1, type: resistor, nodes: [in, out], R: "= Pa.value / Qref * pi / pi"}
  - {id: R2, type: resistor, nodes: [out, ground], R: 1 mmHg*s/mL}
"""


@pytest.mark.parametrize("instance, parameters, message", [
    ("{id: left, netlist: child.yaml, ports: {in: top}, remove: [Pa]}", "",
     "child.yaml's R1.R is the expression .* reads 'Pa', an element the instance removes; keep 'Pa', or give the "
     "instance change: {R1: {R: VALUE}}"),
    ("{id: left, netlist: child.yaml, ports: {in: top}}", "parameters: {left__Qref: 1 mL/s}",
     "parameter 'left__Qref' is also the name under which an instance carries"),
])
def test_a_childs_expression_that_loses_its_element_or_parameter_name_is_an_error(folder, instance, parameters,
                                                                                   message):
    folder(CHILD_READS_PA, "child.yaml")
    parent = f"""
name: parent
{parameters}
elements:
  - {{id: P0, type: pressure_source, nodes: [top, ground], value: 50 mmHg}}
instances:
  - {instance}
"""
    with pytest.raises(NetlistError, match=message):
        hc.load(folder(parent, "parent.yaml"))


def test_a_childs_expression_keeps_pi_and_reads_its_own_parameter(folder):
    """In the child's R1 = Pa.value / Qref * pi / pi, ``pi`` stays pi and Qref is the child's
    (80 mmHg / 10 mL/s = 8 mmHg*s/mL); a 'change' replacing the expression lets the instance
    remove Pa."""
    folder(CHILD_READS_PA, "child.yaml")
    parent = """
name: parent
elements:
  - {id: P0, type: pressure_source, nodes: [top, ground], value: 50 mmHg}
instances:
  - {id: left, netlist: child.yaml, ports: {in: top}, remove: [Pa], change: {R1: {R: 2 mmHg*s/mL}}}
  - {id: right, netlist: child.yaml, ports: {in: top2}}
"""
    c = hc.load(folder(parent, "parent.yaml"))
    op = c.operating_point()
    assert op["Q(left.R1)"] == pytest.approx(50.0 / 3.0, rel=1e-12)  # 50 mmHg over 2 + 1 mmHg*s/mL
    assert op["Q(right.R1)"] == pytest.approx(80.0 / 9.0, rel=1e-12)  # its own Pa, over 8 + 1
