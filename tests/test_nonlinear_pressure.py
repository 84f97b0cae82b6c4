"""Elements nonlinear in the pressures: the assembly runs Newton on the nodal equations."""
import numpy as np
import pytest
from scipy.optimize import brentq

import hemocircuit as hc
from hemocircuit.component import Component, Param
from hemocircuit.registry import component_types


class QuadraticResistor(Component):
    """Turbulent-type resistance: dP = K q |q|, i.e. q = sign(dP) sqrt(|dP| / K)."""

    type_name = "test_quadratic_resistor"
    terminals = ("a", "b")
    parameters = {"K": Param("mmHg*s**2/mL**2", lower=0.0, lower_open=True)}
    linear_in_pressure = False

    def stamp(self, p, x, u, t, src=None):
        dP = np.zeros(x.shape[:2]) + 1.0 if u is None else u[..., 0] - u[..., 1]
        a = np.maximum(np.abs(dP), 1e-9)
        q = np.sign(dP) * np.sqrt(a / p["K"])
        g = 0.5 / np.sqrt(a * p["K"])  # dq/d(dP)
        # a legacy numpy hook: q = g (P_a - P_b) + j from a to b
        j = q - g * dP
        A = np.empty(g.shape + (2, 2))
        A[..., 0, 0], A[..., 0, 1], A[..., 1, 0], A[..., 1, 1] = g, -g, -g, g
        return A, np.stack([-j, j], axis=-1)


@pytest.fixture
def registered():
    types = component_types()
    types[QuadraticResistor.type_name] = QuadraticResistor
    yield
    types.pop(QuadraticResistor.type_name)


def test_series_quadratic_and_linear_resistor(registered, tmp_path):
    net = tmp_path / "nl.yaml"
    net.write_text("""
elements:
  - {id: Ps, type: pressure_source, nodes: [in, ground], value: 50 mmHg}
  - {id: Rq, type: test_quadratic_resistor, nodes: [in, a], K: 2 mmHg*s**2/mL**2}
  - {id: R, type: resistor, nodes: [a, ground], R: 3 mmHg*s/mL}
""")
    c = hc.load(str(net))
    op = c.operating_point()
    # by hand: 2 q^2 + 3 q = 50
    q = brentq(lambda q: 2 * q * q + 3 * q - 50, 0, 10)
    assert op["Q(R)"] == pytest.approx(q, rel=1e-10)
    assert op["Q(Rq)"] == pytest.approx(q, rel=1e-10)
    assert op["P(a)"] == pytest.approx(3 * q, rel=1e-10)


class _ImposedFlow(component_types()["flow_source"]):
    """A flow source declaring what is true of it: its A_loc is 0 (matrix_params = ()), so an
    expression on its value leaves the nodal matrix constant -- but not its right-hand side."""

    type_name = "test_imposed_flow"
    matrix_params = ()


def test_an_expression_on_a_right_hand_side_parameter_is_stamped_at_every_evaluation(tmp_path):
    """Q = q0 - k V(C1) into C1 (C = 0.5 mL/mmHg): dV/dt = q0 - k V, so at V = 10 and 20 mL
    the right-hand side is 5 - 0.1 V.  On the numpy path the element was static (stamped once,
    at the expression's first value) because its matrix is constant; the compiled path
    re-stamped it.  Both now follow the expression."""
    types = component_types()
    types[_ImposedFlow.type_name] = _ImposedFlow
    try:
        net = tmp_path / "flow_expr.yaml"
        net.write_text("""
parameters:
  q0: 5 mL/s
  k: 0.1 1/s
elements:
  - {id: Qs, type: test_imposed_flow, nodes: [ground, a], value: "= q0 - k * C1.V"}
  - {id: C1, type: compliance, nodes: [a, ground], C: 0.5 mL/mmHg}
  - {id: R, type: resistor, nodes: [a, ground], R: 1e12 mmHg*s/mL}
""")
        c = hc.load(str(net))
        from hemocircuit.kernels.system import CompiledSystem
        system = CompiledSystem.of(c)
        for V in (10.0, 20.0):
            expect = 5.0 - 0.1 * V - (V / 0.5) / 1e12
            assert c.rhs(0.0, np.array([V]))[0] == pytest.approx(expect, rel=1e-12), V
            assert system.rhs(0.0, np.array([V]), system.params(c))[0] == pytest.approx(expect, rel=1e-12), V
    finally:
        types.pop(_ImposedFlow.type_name)
