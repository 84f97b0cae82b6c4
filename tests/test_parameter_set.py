"""Immutable circuits and parameter sets (hemocircuit/parameters.py, Circuit.with_values):
values in declared units, read-only arrays, new objects for every change, member slicing and
stacking, bounds errors naming element and parameter, and analyses that leave the circuit
they are given unchanged."""
import numpy as np
import pytest

import hemocircuit as hc
from hemocircuit.errors import HemocircuitError, NetlistError
from hemocircuit.parameters import ParameterSet
from hemocircuit.units import Q_

RC2 = """
elements:
  - {id: Ps, type: pressure_source, nodes: [in, ground], value: 50 mmHg}
  - {id: R1, type: resistor,   nodes: [in, a],     R: 2 mmHg*s/mL}
  - {id: C1, type: compliance, nodes: [a, ground], C: 0.5 mL/mmHg}
  - {id: R2, type: resistor,   nodes: [a, b],      R: 4 mmHg*s/mL}
  - {id: C2, type: compliance, nodes: [b, ground], C: 0.25 mL/mmHg}
"""


@pytest.fixture
def rc(write):
    return hc.load(write(RC2))


def _snapshot(c):
    return {p: np.array(v) for p, v in c.parameters.values.items()}, [
        {n: np.array(a) for n, a in g.p.items()} for g in c.groups]


def _same(c, snap):
    vals, groups = snap
    assert {p: np.array(v) for p, v in c.parameters.values.items()}.keys() == vals.keys()
    for p, v in c.parameters.values.items():
        np.testing.assert_array_equal(v, vals[p], err_msg=p)
    for g, ref in zip(c.groups, groups):
        for n, a in ref.items():
            np.testing.assert_array_equal(g.p[n], a, err_msg=n)


def test_values_in_declared_units_and_read_only(rc):
    ps = rc.parameters
    assert ps.B == 1
    assert ps.values["R1.R"].tolist() == [2.0] and ps.unit("R1.R") == "mmHg*s/mL"
    assert ps.values["C2.C"].tolist() == [0.25]
    with pytest.raises(ValueError):
        ps.values["R1.R"][0] = 3.0  # a returned array cannot be written
    with pytest.raises(ValueError):
        rc.groups[0].p[next(iter(rc.groups[0].p))][0, 0] = 1.0  # nor the evaluator's arrays
    assert "R1.R" in ps.values and "Ps.value" in ps.values and len(ps.values) == len(list(ps.values))


def test_with_values_makes_a_new_circuit_and_keeps_the_original(rc):
    snap = _snapshot(rc)
    q0 = rc.operating_point()["Q(R1)"]
    c2 = rc.with_values({"Ps.value": "100 cmH2O", "R1.R": 4, "C1.C": Q_(500, "uL/mmHg")})
    assert c2 is not rc and c2.structure is rc.structure  # the structure is shared
    assert c2.parameters.values["Ps.value"][0] == pytest.approx(100 * 98.0665 / 133.322387415, rel=1e-8)
    assert c2.parameters.values["R1.R"][0] == 4.0 and c2.parameters.values["C1.C"][0] == pytest.approx(0.5)
    _same(rc, snap)
    assert rc.operating_point()["Q(R1)"] == q0  # the original evaluates as before
    # steady flow through a capacitor branch is zero; the pressures follow the new source
    op = c2.operating_point()
    assert op["P(a)"] == pytest.approx(100 * 98.0665 / 133.322387415, rel=1e-8) and abs(op["Q(R1)"]) < 1e-9
    assert rc.with_values({}) is rc


@pytest.mark.parametrize("value", [90.0, "90 mmHg", np.float64(90.0), np.array([90.0]), Q_(90, "mmHg"),
                                   {"steps": [["0 s", "90 mmHg"]]}])
def test_a_value_replaces_a_waveform_in_every_form(rc, value):
    """A source driven by a sine, then set to 90 mmHg: the same constant 90 mmHg whether the
    value is a number in the declared unit, a quantity string, a numpy number or array, a pint
    quantity or a waveform (as a netlist's ``value: 90 mmHg`` replaces a waveform).  A bare
    number used to keep the sine and add 90 to it (80 + 5 sin -> 170 + 5 sin: no error)."""
    sine = rc.with_values({"Ps.value": {"sine": {"offset": "80 mmHg", "amplitude": "5 mmHg", "frequency": "0.1 Hz"}}})
    assert sine.parameters.waveform("Ps.value") is not None
    c = sine.with_values({"Ps.value": value})
    # a value leaves no waveform; a waveform leaves itself (a one-row table), not the sine
    wf = c.parameters.waveform("Ps.value")
    assert (wf is None) if not isinstance(value, dict) else type(wf).__name__ == "Table"
    res = c.simulate(t_end=7.5, dt=2.5, progress=False)
    np.testing.assert_allclose(res["P(in)"], 90.0, rtol=0, atol=1e-9)
    # the original keeps its sine: 80 + 5 sin(2 pi 0.1 t) at t = 2.5 s is 85 mmHg
    assert sine.simulate(t_end=2.5, dt=2.5, progress=False)["P(in)"][-1] == pytest.approx(85.0, abs=1e-6)


WINDKESSEL = """
elements:
  - {id: Ps, type: pressure_source, nodes: [in, ground], value: 80 mmHg}
  - {id: W, type: closed_loop_rcr, nodes: [in, out, ground], Rp: 0.1 mmHg*s/mL, C: 1 mL/mmHg,
     Rd: {sine: {offset: 1 mmHg*s/mL, amplitude: 0.9 mmHg*s/mL, frequency: 1 Hz}}}
  - {id: Pv, type: pressure_source, nodes: [out, ground], value: 5 mmHg}
"""


def test_a_value_set_is_checked_with_the_waveform_it_leaves_in_effect(write):
    """W.Rd (> 0) carries a sine from 0.1 to 1.9 in the netlist.  A constant that replaces it is
    checked alone (-0.05 was accepted: checked as -0.05 + the old sine's 0.1..1.9), and a new
    waveform by its own range (a sine from -1 to 1 was accepted: checked as the old one's)."""
    c = hc.load(write(WINDKESSEL))
    with pytest.raises(NetlistError, match=r"element 'W': parameter 'Rd' = -0.05 .* not physical"):
        c.with_values({"W.Rd": "-0.05 mmHg*s/mL"})
    with pytest.raises(NetlistError, match=r"parameter 'Rd': its waveform's lowest value -1 .* not physical"):
        c.with_values({"W.Rd": {"sine": {"offset": "0 mmHg*s/mL", "amplitude": "1 mmHg*s/mL", "frequency": "1 Hz"}}})
    assert c.with_values({"W.Rd": 3.0}).parameters.values["W.Rd"].tolist() == [3.0]
    # a waveform within the bounds, set where the netlist had none, is checked by its range too
    c2 = c.with_values({"W.Rd": "2 mmHg*s/mL"}).with_values(
        {"W.Rd": {"sine": {"offset": "2 mmHg*s/mL", "amplitude": "1 mmHg*s/mL", "frequency": "1 Hz"}}})
    assert c2.parameters.waveform("W.Rd") is not None


VALVE = """
elements:
  - {id: Ps, type: pressure_source, nodes: [in, ground], value: 80 mmHg}
  - {id: V, type: valve_tanh, nodes: [in, out], Rmin: 100 mmHg*s/mL, Rmax: 1e5 mmHg*s/mL, steepness: 10 1/mmHg}
  - {id: R, type: resistor, nodes: [out, ground], R: 1 mmHg*s/mL}
"""


def test_relations_between_values_are_checked_on_the_values_in_effect(write):
    """A valve needs Rmin <= Rmax.  Both lowered in one mapping (Rmax 50 before Rmin 10), or Rmax
    lowered after Rmin was: accepted (both were refused, Rmax checked against the netlist's
    Rmin 100); Rmin above the Rmax in effect: refused, naming the element."""
    c = hc.load(write(VALVE))
    both = c.with_values({"V.Rmax": 50.0, "V.Rmin": 10.0})
    assert (both.parameters.values["V.Rmin"].tolist(), both.parameters.values["V.Rmax"].tolist()) == ([10.0], [50.0])
    assert c.with_values({"V.Rmin": 10.0}).with_values({"V.Rmax": 50.0}).parameters.values["V.Rmax"].tolist() == [50.0]
    with pytest.raises(NetlistError, match=r"element 'V': needs Rmin <= Rmax"):
        both.with_values({"V.Rmin": 60.0})
    # per member: one member's bad pair is refused
    with pytest.raises(NetlistError, match="needs Rmin <= Rmax"):
        c.batch(2).with_values({"V.Rmin": np.array([10.0, 10.0]), "V.Rmax": np.array([50.0, 5.0])})


def test_constant_value_for_a_study_refuses_a_waveform(rc):
    """ParameterSet.constant: a parameter's number for a fit or a sensitivity study, and an
    error naming the study, the parameter and the fix when a waveform drives it."""
    assert rc.parameters.constant("Ps.value", "sensitivity") == 50.0
    sine = rc.with_values({"Ps.value": {"sine": {"offset": "80 mmHg", "amplitude": "5 mmHg", "frequency": "0.1 Hz"}}})
    with pytest.raises(NetlistError, match=r"sensitivity: Ps.value carries a waveform.*--set Ps.value=VALUE") as exc:
        sine.parameters.constant("Ps.value", "sensitivity")
    assert exc.value.element == "Ps"


def test_bounds_and_path_errors_name_element_and_parameter(rc):
    snap = _snapshot(rc)
    cases = [({"R1.R": -1.0}, "R1", "'R'"), ({"R1.R": "0 mmHg*s/mL"}, "R1", "not physical"),
             ({"C2.C": "1 mmHg"}, "C2", "dimension"), ({"R1.Q": 1.0}, "R1", "no parameter 'Q'"),
             ({"Zz.R": 1.0}, "Zz", "no element 'Zz'")]
    for mapping, element, frag in cases:
        with pytest.raises(NetlistError, match=frag) as ei:
            rc.with_values(mapping)
        assert ei.value.element == element
    b = rc.batch(3)
    with pytest.raises(NetlistError, match="not physical") as ei:  # one bad member is enough
        b.with_values({"R2.R": np.array([1.0, -2.0, 3.0])})
    assert ei.value.element == "R2"
    with pytest.raises(NetlistError, match="one value per member") as ei:
        b.with_values({"R2.R": np.array([1.0, 2.0])})
    assert ei.value.element == "R2"
    # a rejected mapping changes nothing, also its valid entries
    with pytest.raises(NetlistError):
        rc.with_values({"R1.R": 7.0, "R2.R": -1.0})
    _same(rc, snap)


def test_members_slicing_and_stack_round_trip(rc):
    b = rc.batch(3).with_values({"R1.R": np.array([1.0, 2.0, 3.0]), "Ps.value": "60 mmHg"})
    ps = b.parameters
    assert ps.B == 3 and ps.values["R1.R"].tolist() == [1.0, 2.0, 3.0]
    assert ps.values["Ps.value"].tolist() == [60.0] * 3
    one = ps[1]
    assert one.B == 1 and one.values["R1.R"].tolist() == [2.0]
    assert ps[[2, 0]].values["R1.R"].tolist() == [3.0, 1.0]
    assert ps[1:].values["R1.R"].tolist() == [2.0, 3.0]
    assert ps[np.array([0, 0, 2])].values["R1.R"].tolist() == [1.0, 1.0, 3.0]  # repeats allowed
    members = list(ps.members())
    assert [m.values["R1.R"][0] for m in members] == [1.0, 2.0, 3.0]
    assert ParameterSet.stack(members) == ps
    assert ParameterSet.stack([ps[2], ps[:2]]).values["R1.R"].tolist() == [3.0, 1.0, 2.0]
    with pytest.raises(IndexError):
        ps[3]
    # circuits: member k and subset evaluate like a single circuit with those values
    for k, R in enumerate([1.0, 2.0, 3.0]):
        single = rc.with_values({"R1.R": R, "Ps.value": "60 mmHg"})
        x = np.array([10.0, 5.0])
        np.testing.assert_allclose(b.member(k).rhs(0.0, x), single.rhs(0.0, x), rtol=1e-14)
        np.testing.assert_allclose(b.subset([k]).rhs(0.0, x[None])[0], single.rhs(0.0, x), rtol=1e-14)
    assert b.subset([0, 2]) is b.subset([0, 2])  # cached view
    assert b.subset([0, 2]).parameters.values["R1.R"].tolist() == [1.0, 3.0]
    with pytest.raises(HemocircuitError):
        b.batch(2)


def test_stack_rejects_other_structures_and_other_waveforms(rc, write):
    other = hc.load(write(RC2))
    with pytest.raises(NetlistError, match="different circuit structures"):
        ParameterSet.stack([rc.parameters, other.parameters])
    wave = rc.with_values({"Ps.value": {"sine": {"offset": "50 mmHg", "amplitude": "5 mmHg",
                                                  "frequency": "1 Hz"}}})
    assert wave.parameters.waveform("Ps.value") is not None and rc.parameters.waveform("Ps.value") is None
    with pytest.raises(NetlistError, match="waveforms"):
        ParameterSet.stack([rc.parameters, wave.parameters])
    # a quantity replaces the waveform again
    assert wave.with_values({"Ps.value": "50 mmHg"}).parameters.waveform("Ps.value") is None


def test_with_parameters_checks_the_structure(rc, write):
    other = hc.load(write(RC2))
    with pytest.raises(HemocircuitError, match="another circuit structure"):
        rc.with_parameters(other.parameters)
    assert rc.with_parameters(rc.parameters) is rc
    ps = rc.parameters.with_values({"R2.R": 8.0})
    assert rc.with_parameters(ps).parameters is ps


def test_analyses_do_not_change_the_circuit_they_are_given(rc):
    from hemocircuit.analyses.linearize import linearize
    from hemocircuit.protocol import Protocol

    snap = _snapshot(rc)
    rc.operating_point()
    rc.dc_sweep("Ps.value", [40.0, 50.0, 60.0])
    linearize(rc, input="Ps", outputs=["Q(R1)"])
    rc.ac_response("Ps", ["Q(R1)"], [0.01, 0.1])
    rc.stability_sweep("R1.R", [1.0, 2.0], locate=False)
    rc.frequency_response([0.5], outputs=["P(b)"], input="Ps", scheduler="serial", max_periods=8)
    proto = Protocol.from_dict({"t_end": "2 s", "initial": {"R2.R": "3 mmHg*s/mL"},
                                "events": [{"at": "1 s", "set": {"Ps.value": "70 mmHg"}}]}, None, rc)
    rc.simulate(2.0, protocol=proto, dt=0.5)
    _same(rc, snap)
    b = rc.batch(2).with_values({"R1.R": np.array([1.0, 3.0])})
    bsnap = _snapshot(b)
    b.operating_point()
    linearize(b)
    b.subset([1])
    _same(b, bsnap)


def test_steady_variant_shares_values_and_is_cached(rc):
    sv = rc.steady_variant()
    assert sv is rc.steady_variant()
    assert sv.parameters is rc.parameters


def test_pickled_circuit_drops_private_caches(rc):
    import pickle

    b = rc.batch(3).with_values({"R1.R": np.array([1.0, 2.0, 3.0])})
    sub = b.subset([0, 2])
    b.cached("probe", lambda: 1)
    back = pickle.loads(pickle.dumps(b))
    assert back.parameters.schema is back.structure.schema  # one structure after unpickling
    assert {k: v.tolist() for k, v in back.parameters.values.items()} == \
        {k: v.tolist() for k, v in b.parameters.values.items()}
    assert back.cached("probe", lambda: 2) == 2  # memo not carried
    x = np.array([[10.0, 5.0]] * 2)
    np.testing.assert_array_equal(pickle.loads(pickle.dumps(sub)).rhs(0.0, x), sub.rhs(0.0, x))


def test_fingerprint_tells_long_tables_apart(rc):
    """Two 2 000-point pressure tables that differ in one middle value only, and two whose
    values differ by 1e-12 relative, have different fingerprints (numpy's repr, which the
    digest once hashed, elides a long array's middle and rounds to 8 digits); equal tables
    have equal ones, and a set's fingerprint is the same when asked again."""
    t = np.arange(2000) * 0.01
    v = 80.0 + np.sin(t)

    def table(values):
        rows = [[f"{a} s", f"{float(b)!r} mmHg"] for a, b in zip(t.tolist(), values)]
        return rc.with_values({"Ps.value": {"pwl": rows}})

    base = table(v)
    middle, tiny = v.copy(), v.copy()
    middle[1000] += 1.0
    tiny[5] *= 1 + 1e-12
    fp = base.parameters.fingerprint()
    assert fp == base.parameters.fingerprint() == table(v).parameters.fingerprint()
    assert table(middle).parameters.fingerprint() != fp
    assert table(tiny).parameters.fingerprint() != fp


def test_unpickled_values_stay_read_only(rc):
    """A pickled and unpickled parameter set (a worker's copy) keeps its values read-only and
    its fingerprint: the set is immutable there too."""
    import pickle

    ps = rc.with_values({"R1.R": "3 mmHg*s/mL"}).parameters
    fp = ps.fingerprint()
    back = pickle.loads(pickle.dumps(ps))
    assert back.fingerprint() == fp
    with pytest.raises(ValueError):
        back.values["R1.R"][0] = 1.0
    arrays = [a for gi in range(len(rc.groups)) for a in back.group_arrays(gi).values()]
    assert arrays and not any(a.flags.writeable for a in arrays)
