"""5 %/95 % sigmoids (eqs NOcGMP, sigmoiddef and the myogenic pCa_bar)."""
import numpy as np
import pytest


@pytest.mark.parametrize("preset", ["kuo91", "falcone91"])
def test_no_to_cgmp_passes_5_and_95_percent(art, preset):
    p = art.make_params(preset)
    eq = art.equations
    pc = np.log10(eq.cgmp(np.array([p["NO_L"], p["NO_U"]]), eq.vector(p)))
    span = p["pcGMP_U"] - p["pcGMP_L"]
    np.testing.assert_allclose(pc, [p["pcGMP_L"] + 0.05 * span, p["pcGMP_L"] + 0.95 * span],
                               rtol=0, atol=1e-12)


@pytest.mark.parametrize("preset", ["kuo91", "falcone91"])
def test_stress_to_ca_passes_5_and_95_percent(art, preset):
    p = art.make_params(preset)
    ca = art.equations.ca_bar(np.array([p["sigma_L"], p["sigma_U"]]), art.equations.vector(p))
    span = p["pCa_U"] - p["pCa_L"]
    np.testing.assert_allclose(np.log10(ca), [p["pCa_L"] + 0.05 * span, p["pCa_L"] + 0.95 * span],
                               rtol=0, atol=1e-12)


def test_sigmoid_limits_and_reversed_bounds(art):
    f = art.equations.sigmoid_5_95
    with np.errstate(over="ignore"):   # exp overflows to inf: the sigmoid is then exactly 0
        y = f(np.array([-1e300, 1e300]), 1.0, 2.0, -3.0, 5.0)
    np.testing.assert_array_equal(y, [-3.0, 5.0])
    # x_L > x_U gives a falling sigmoid through the same two points
    np.testing.assert_allclose(f(np.array([2.0, 1.0]), 2.0, 1.0, 0.0, 1.0), [0.05, 0.95])
