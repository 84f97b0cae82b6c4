"""Unit conversions (hand values) and unit checking of netlist parameters."""
import signal

import numpy as np
import pytest

import hemocircuit as hc
from hemocircuit import units
from hemocircuit.errors import HemocircuitError, NetlistError
from hemocircuit.units import UnitError, parse_quantity

MMHG = 133.322387415  # Pa
CMH2O = 98.0665  # Pa


@pytest.mark.parametrize("text, unit, expected", [
    ("1 mmHg", "Pa", MMHG),
    ("1 cmH2O", "Pa", CMH2O),
    ("133.322387415 Pa", "mmHg", 1.0),
    ("1 Pa", "mmHg", 1 / MMHG),
    ("10 cmH2O", "mmHg", 10 * CMH2O / MMHG),  # 7.35559 mmHg
    ("1 kPa", "mmHg", 1000 / MMHG),
    ("1 mL", "m^3", 1e-6),
    ("1 m^3", "mL", 1e6),
    ("2.5 m**3", "L", 2500.0),
    ("1 cm^3", "mL", 1.0),
    ("60 um", "m", 6e-5),
    ("60 um", "mm", 0.06),
    ("2 L/min", "mL/s", 2000 / 60),  # 33.333... mL/s
    ("750 mL/min", "mL/s", 12.5),
    ("1 m^3/s", "mL/s", 1e6),
    ("1.06 kg/L", "kg/m^3", 1060.0),
    ("1.06 g/cm^3", "kg/m^3", 1060.0),
    ("0.4 mmHg*s/mL", "Pa*s/m^3", 0.4 * MMHG / 1e-6),
    ("1 Pa*s/m^3", "mmHg*s/mL", 1e-6 / MMHG),
    ("1 dyn*s/cm^5", "mmHg*s/mL", 0.1 / MMHG),  # 1e5 Pa s/m^3 = 1e5 Pa s / 1e6 mL
    ("1 mmHg*s**2/mL", "Pa*s^2/m^3", MMHG * 1e6),
    ("0.558 1/mL", "1/m^3", 0.558e6),
    ("90 deg", "rad", np.pi / 2),
    ("60 1/min", "Hz", 1.0),
    ("1 min", "s", 60.0),
])
def test_conversions_by_hand(text, unit, expected):
    assert parse_quantity(text, unit) == pytest.approx(expected, rel=1e-12)


def test_module_constants_and_helpers():
    assert units.PA_PER_MMHG == pytest.approx(MMHG, rel=1e-12)
    assert units.PA_PER_CMH2O == pytest.approx(CMH2O, rel=1e-12)
    assert units.mmhg_to_pa(80.0) == pytest.approx(80 * MMHG, rel=1e-12)
    assert units.pa_to_mmhg(MMHG) == pytest.approx(1.0, rel=1e-12)
    np.testing.assert_allclose(units.ml_to_m3(np.array([1.0, 2.0])), [1e-6, 2e-6], rtol=1e-12)
    assert units.m3_to_ml(3e-6) == pytest.approx(3.0, rel=1e-12)
    assert units.conversion_factor("cmH2O", "mmHg") == pytest.approx(CMH2O / MMHG, rel=1e-12)
    assert units.conversion_factor("L/min", "mL/s") == pytest.approx(1000 / 60, rel=1e-12)
    assert units.si_factor("mmHg") == pytest.approx(MMHG, rel=1e-12)
    assert units.si_factor("mL") == pytest.approx(1e-6, rel=1e-12)
    assert units.si_factor("um") == pytest.approx(1e-6, rel=1e-12)
    with pytest.raises(UnitError):
        units.conversion_factor("mmHg", "mL")
    with pytest.raises(UnitError):
        units.check_unit("furlongs_per_fortnightx")


def test_bare_numbers_rejected_for_dimensional_quantities():
    for value in (0.4, 3, "0.4", " 12 "):
        with pytest.raises(UnitError, match="no unit"):
            parse_quantity(value, "mmHg*s/mL", "parameter 'R'")
    with pytest.raises(UnitError):
        parse_quantity(True, "mmHg")
    with pytest.raises(UnitError):
        parse_quantity(None, "mmHg")
    # dimensionless targets accept bare numbers (rad is dimensionless)
    assert parse_quantity(2, "dimensionless") == 2.0
    assert parse_quantity("0.5", "rad") == 0.5


def test_wrong_dimension_rejected():
    with pytest.raises(UnitError, match=r"parameter 'R'.*dimension.*mmHg\*s/mL"):
        parse_quantity("0.4 mmHg", "mmHg*s/mL", "parameter 'R'")
    with pytest.raises(UnitError, match="cannot parse"):
        parse_quantity("0.4 flibbles", "mmHg")
    with pytest.raises(UnitError):
        parse_quantity("2 L/min", "mL")


def test_unit_errors_are_framework_errors():
    assert issubclass(UnitError, HemocircuitError)


@pytest.mark.parametrize("text", ["10**10**10 mmHg", "2**2**2**2**2 mmHg", "mmHg**99999999999",
                                  "1 mmHg**1e308", "1e400 mmHg**2"])
def test_huge_powers_fail_fast_with_unit_error(text):
    """Integer powers in pint's parser used to run without bound (10**10**10)."""
    def timeout(*_):
        raise TimeoutError(f"parsing {text!r} did not finish")

    old = signal.signal(signal.SIGALRM, timeout)
    signal.alarm(5)
    try:
        with pytest.raises(UnitError):
            parse_quantity(text, "mmHg")
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


NET = """
elements:
  - {{id: Ps, type: pressure_source, nodes: [in, ground], value: {P}}}
  - {{id: R1, type: resistor,        nodes: [in, a],      R: {R}}}
  - {{id: Qs, type: flow_source,     nodes: [ground, a],  value: {Q}}}
  - {{id: R2, type: resistor,        nodes: [a, ground],  R: 1 mmHg*s/mL}}
  - {{id: C1, type: compliance,      nodes: [a, ground],  C: {C}}}
"""


def test_netlist_values_in_other_units_give_the_same_circuit(write):
    a = hc.load(write(NET.format(P="10 cmH2O", R="0.5 mmHg*s/mL", Q="2 L/min", C="1 mL/mmHg"), "a.yaml"))
    b = hc.load(write(NET.format(P=f"{10 * CMH2O} Pa", R=f"{0.5 * MMHG * 1e6} Pa*s/m^3",
                                 Q="3.3333333333333333e-5 m^3/s", C=f"{1e-6 / MMHG} m^3/Pa"), "b.yaml"))
    assert a.parameters.values["Ps.value"][0] == pytest.approx(10 * CMH2O / MMHG, rel=1e-12)
    assert a.parameters.values["Qs.value"][0] == pytest.approx(100 / 3, rel=1e-12)
    for p in ("Ps.value", "R1.R", "Qs.value", "C1.C"):
        assert a.parameters.values[p][0] == pytest.approx(b.parameters.values[p][0], rel=1e-12), p
    # hand-solved operating point: node a from Kirchhoff, (P - Pa)/0.5 + Q = Pa/1
    P, Q = 10 * CMH2O / MMHG, 100 / 3
    Pa = (P / 0.5 + Q) / (1 / 0.5 + 1)
    op = a.operating_point()
    assert op["P(a)"] == pytest.approx(Pa, rel=1e-12)
    assert op["V(C1)"] == pytest.approx(Pa, rel=1e-12)
    assert op.units["P(a)"] == "mmHg" and op.units["Q(R1)"] == "mL/s" and op.units["V(C1)"] == "mL"


def test_bare_number_in_netlist_names_element_and_parameter(write):
    path = write(NET.format(P="80 mmHg", R="0.4", Q="1 mL/s", C="1 mL/mmHg"))
    with pytest.raises(NetlistError) as ei:
        hc.load(str(path))
    e = ei.value
    assert e.element == "R1" and e.file == str(path)
    msg = str(e)
    assert str(path) in msg and "R1" in msg and "'R'" in msg and "no unit" in msg and "mmHg*s/mL" in msg


def test_wrong_dimension_in_netlist_names_element(write):
    path = write(NET.format(P="80 mmHg", R="1 mmHg*s/mL", Q="1 mL", C="1 mL/mmHg"))
    with pytest.raises(NetlistError) as ei:
        hc.load(str(path))
    assert ei.value.element == "Qs"
    msg = str(ei.value)
    assert str(path) in msg and "Qs" in msg and "dimension" in msg and "mL/s" in msg


def test_with_values_converts_units(write):
    c = hc.load(write(NET.format(P="80 mmHg", R="1 mmHg*s/mL", Q="1 mL/s", C="1 mL/mmHg")))
    c = c.with_values({"Ps.value": "100 cmH2O"})
    assert c.parameters.values["Ps.value"][0] == pytest.approx(100 * CMH2O / MMHG, rel=1e-12)
    c = c.with_values({"Qs.value": "1.2 L/min"})
    assert c.parameters.values["Qs.value"][0] == pytest.approx(20.0, rel=1e-12)
    c = c.with_values({"R1.R": 2.5})  # plain numbers are in the declared unit
    assert c.parameters.values["R1.R"][0] == 2.5
    with pytest.raises(NetlistError, match="no unit"):
        c.with_values({"R1.R": "2.5"})
    with pytest.raises(NetlistError, match="dimension"):
        c.with_values({"R1.R": "2.5 mmHg"})
    assert c.parameters.values["R1.R"][0] == 2.5


def test_boundary_constants_are_pints():
    """The mmHg/cmH2O factors are written out (no pint at import); they must be pint's."""
    import pint

    from hemocircuit.units import PA_PER_CMH2O, PA_PER_MMHG

    ureg = pint.UnitRegistry()
    assert PA_PER_MMHG == float(ureg.Quantity(1, "mmHg").to("Pa").magnitude)
    # 98.0665 exactly by definition; pint's float arithmetic lands one ulp below it
    assert abs(PA_PER_CMH2O / float(ureg.Quantity(1, "cmH2O").to("Pa").magnitude) - 1) < 1e-15
