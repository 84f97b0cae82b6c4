"""The derivatives service (hemocircuit/derivatives.py) against closed forms.

Two-stage RC ladder: Ps -> R1 -> a (C1 to ground) -> R2 -> b (C2 to ground), linear
compliances with V0 = 0, so P_a = V1/C1, P_b = V2/C2 and

    dV1/dt = (Ps - P_a)/R1 - (P_a - P_b)/R2,    dV2/dt = (P_a - P_b)/R2.
"""
import numpy as np
import pytest

import hemocircuit as hc
from hemocircuit import derivatives
from hemocircuit.errors import HemocircuitError, NetlistError

RC2 = """
elements:
  - {id: Ps, type: pressure_source, nodes: [in, ground], value: 50 mmHg}
  - {id: R1, type: resistor,   nodes: [in, a],     R: 2 mmHg*s/mL}
  - {id: C1, type: compliance, nodes: [a, ground], C: 0.5 mL/mmHg}
  - {id: R2, type: resistor,   nodes: [a, b],      R: 4 mmHg*s/mL}
  - {id: C2, type: compliance, nodes: [b, ground], C: 0.25 mL/mmHg}
"""
X = np.array([12.0, 4.0])  # V1, V2 [mL]: P_a = 24, P_b = 16 mmHg


@pytest.fixture
def rc(write):
    return hc.load(write(RC2))


def closed_jacobian(R1, R2, C1, C2):
    return np.array([[-1 / (R1 * C1) - 1 / (R2 * C1), 1 / (R2 * C2)],
                     [1 / (R2 * C1), -1 / (R2 * C2)]])


def test_state_jacobian_matches_the_closed_form(rc):
    """Central differences of the right-hand side (the elements' kernel functions) give the
    closed-form Jacobian of the linear ladder to their round-off, and the circuit's forward
    differences to theirs."""
    J_ref = closed_jacobian(2.0, 4.0, 0.5, 0.25)
    np.testing.assert_allclose(derivatives.state_jacobian(rc, X), J_ref, rtol=1e-8)
    np.testing.assert_allclose(rc.jacobian(0.0, X), J_ref, rtol=1e-6)


def test_state_jacobian_for_a_batch_and_with_the_clamp(rc):
    b = rc.batch(2).with_values({"R1.R": np.array([1.0, 3.0]), "C2.C": np.array([0.25, 2.0])})
    Xb = np.array([[12.0, 4.0], [3.0, 7.0]])
    J = derivatives.state_jacobian(b, Xb)
    for k, (R1, C2) in enumerate([(1.0, 0.25), (3.0, 2.0)]):
        np.testing.assert_allclose(J[k], closed_jacobian(R1, 4.0, 0.5, C2), rtol=1e-8)
    # a clamped store emptied with flow into it: the clamp is off, the Jacobian the ladder's
    cl = rc.with_options({"C1.clamp_at_zero": True})
    Xc = np.array([-1.0, 40.0])  # P_a = -2, P_b = 160: flow into a
    np.testing.assert_allclose(derivatives.state_jacobian(cl, Xc), closed_jacobian(2.0, 4.0, 0.5, 0.25), rtol=1e-8)
    # with net outflow the clamp holds V1 (dV1/dt = 0 whatever the states: a zero row)
    cl2 = rc.with_options({"C1.clamp_at_zero": True}).with_values({"Ps.value": "-100 mmHg"})
    Xd = np.array([-1.0, -10.0])  # P_a = -2 > P_b = -40 and > Ps: net outflow, clamp holds V1
    J = derivatives.state_jacobian(cl2, Xd)
    assert np.all(J[0] == 0.0)
    np.testing.assert_allclose(J[1], closed_jacobian(2.0, 4.0, 0.5, 0.25)[1], rtol=1e-8)


def test_parameter_sensitivity_matches_closed_forms(rc):
    """d rhs/dR1 = -(Ps - P_a)/R1^2 (first state only), d rhs/dPs = 1/R1, d rhs/dC2 = -/+ P_b/(R2 C2),
    and the flow through R1 d Q(R1)/dR1 = -(Ps - P_a)/R1^2, all from one batched evaluation."""
    Ps, R1, R2, C1, C2 = 50.0, 2.0, 4.0, 0.5, 0.25
    Pa, Pb = X[0] / C1, X[1] / C2
    s = derivatives.parameter_sensitivity(rc, ["R1.R", "Ps.value", "C2.C", "R2.R"], X, outputs=["Q(R1)", "P(b)"])
    assert s.rhs.shape == (1, 2, 4) and s.outputs.shape == (1, 2, 4)
    ref = np.array([[-(Ps - Pa) / R1 ** 2, 1 / R1, -Pb / (R2 * C2), (Pa - Pb) / R2 ** 2],
                    [0.0, 0.0, Pb / (R2 * C2), -(Pa - Pb) / R2 ** 2]])
    np.testing.assert_allclose(s.rhs[0], ref, rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(s.outputs[0, 0], [-(Ps - Pa) / R1 ** 2, 1 / R1, 0.0, 0.0], rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(s.outputs[0, 1], [0.0, 0.0, -X[1] / C2 ** 2, 0.0], rtol=1e-8, atol=1e-12)
    np.testing.assert_array_equal(s.p0[0], [R1, Ps, C2, R2])
    assert np.all(s.steps > 0)


def test_parameter_sensitivity_of_a_batch_is_per_member(rc):
    b = rc.batch(3).with_values({"R1.R": np.array([1.0, 2.0, 5.0])})
    Xb = np.array([[12.0, 4.0], [10.0, 4.0], [20.0, 1.0]])
    s = derivatives.parameter_sensitivity(b, ["R1.R"], Xb)
    for k, R1 in enumerate([1.0, 2.0, 5.0]):
        Pa = Xb[k, 0] / 0.5
        assert s.rhs[k, 0, 0] == pytest.approx(-(50.0 - Pa) / R1 ** 2, rel=1e-8)
        single = derivatives.parameter_sensitivity(rc.with_values({"R1.R": R1}), ["R1.R"], Xb[k])
        np.testing.assert_allclose(single.rhs[0], s.rhs[k], rtol=1e-12)
    with pytest.raises(HemocircuitError, match="state rows"):
        derivatives.parameter_sensitivity(b, ["R1.R"], X)


def test_parameter_sensitivity_errors_name_the_parameter(rc):
    with pytest.raises(NetlistError, match="no parameter 'Z'"):
        derivatives.parameter_sensitivity(rc, ["R1.Z"], X)


def test_linearize_input_matrix_is_the_sensitivity(rc):
    from hemocircuit.analyses.linearize import linearize

    lin = linearize(rc, X, input="Ps", outputs=["Q(R1)"])
    # central differences of a linear map: no truncation, round-off ~ 1e-16 / CENTRAL_REL
    np.testing.assert_allclose(lin.A, closed_jacobian(2.0, 4.0, 0.5, 0.25), rtol=1e-9)
    np.testing.assert_allclose(lin.B, [0.5, 0.0], rtol=1e-8, atol=1e-12)  # 1/R1 into V1
    np.testing.assert_allclose(lin.C, [[-1 / (2.0 * 0.5), 0.0]], rtol=1e-8, atol=1e-12)  # -dP_a/dV1 / R1
    np.testing.assert_allclose(lin.D, [0.5], rtol=1e-8)


def test_central_and_forward_rules():
    """Exact on quadratics (central) and to the step on the forward rule."""
    f = lambda rows: np.stack([rows[:, 0] ** 2 + 3 * rows[:, 1], rows[:, 0] * rows[:, 1]], axis=1)  # noqa: E731
    x = np.array([[2.0, -1.5]])
    ref = np.array([[4.0, 3.0], [-1.5, 2.0]])
    J, F0 = derivatives.central_jacobian(f, x, np.ones(2), with_value=True)
    np.testing.assert_allclose(J[0], ref, rtol=1e-9)
    np.testing.assert_allclose(F0[0], f(x)[0])
    Jf, _ = derivatives.dense_jacobian(f, x, np.ones(2))
    np.testing.assert_allclose(Jf[0], ref, rtol=1e-6)
    h = derivatives.fd_steps(x, np.ones(2))
    assert np.all(h == (x + 1e-7 * np.maximum(np.abs(x), 1.0)) - x)
