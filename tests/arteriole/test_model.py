"""Element interface: state layout, derivatives, observables, affine dr/dt, robustness.

The rates and observables are the element's kernel functions (element_calls)."""
import numpy as np
import pytest

from element_calls import observed, rates

MMHG = 133.322387415   # Pa per mmHg
CMH2O = 98.0665        # Pa per cmH2O


def test_state_names(art):
    assert art.state_names() == ["Ca", "Cw", "lambda"]
    assert art.state_names({"ca_order": 2}) == ["Ca", "dCa", "Cw", "lambda"]
    assert art.state_names({"kinetics": "dynamic"}) == ["Ca", "Cw", "lambda", "M", "Mp", "AMp", "AM"]
    with pytest.raises(ValueError):
        art.state_names({"ca_order": 3})
    with pytest.raises(ValueError):
        art.state_names({"kinetcs": "dynamic"})


def _states(art, kuo, options, shape=(5,)):
    rng = np.random.default_rng(0)
    s = art.solve_steady(60 * MMHG, 0.0, kuo, options)
    x = art.pack(s, options) * rng.uniform(0.8, 1.2, shape + (len(art.state_names(options)),))
    return x


@pytest.mark.parametrize("options", [{}, {"ca_order": 2}, {"kinetics": "dynamic"}])
def test_dr_dt_is_affine_in_P_and_balances_the_forces(art, kuo, options):
    x = _states(art, kuo, options)
    lam_dot = {P: rates(art, x, P, 3 * CMH2O, kuo, options)["lambda"] for P in (0.0, 40 * MMHG, 130 * MMHG)}
    b = (lam_dot[130 * MMHG] - lam_dot[0.0]) / (130 * MMHG)
    np.testing.assert_allclose(lam_dot[40 * MMHG], lam_dot[0.0] + b * 40 * MMHG, rtol=1e-9, atol=1e-18)
    assert np.all(b > 0)   # more pressure, faster dilation
    for P in lam_dot:
        obs = observed(art, x, P, 3 * CMH2O, kuo, options)
        # force balance (eqs FT, FMFP): F_a + F_p = w_c P r at every state (forces ~1e-6 N;
        # the numerical friction floor adds l0 FRICTION_FLOOR lambda_dot ~ 1e-14 N)
        np.testing.assert_allclose(obs["F_a"] + obs["F_p"], kuo["w_c"] * P * obs["r"] * 1e-6,
                                   rtol=1e-9, atol=1e-13)


def test_batch_shapes_and_elementwise_agreement(art, kuo):
    x = _states(art, kuo, {}, shape=(3, 4))
    P = np.linspace(40, 100, 4) * MMHG
    p = dict(kuo, tau_Ca=np.array([1.0, 5.0, 230.0])[:, None])
    d = rates(art, x, P, 100.0, p)
    assert all(v.shape == (3, 4) for v in d.values())
    one = rates(art, x[2, 1], P[1], 100.0, dict(kuo, tau_Ca=230.0))
    for k in d:
        assert d[k][2, 1] == pytest.approx(float(one[k]), rel=1e-13)


def test_observables_units_and_values(art, kuo):
    opts = {"ca_order": 2}
    s = art.solve_steady(60 * MMHG, 4 * CMH2O, dict(kuo, n=320.0), opts)
    obs = observed(art, s, 60 * MMHG, 4 * CMH2O, dict(kuo, n=320.0), opts)
    assert "dCa" in obs
    r = obs["r"] * 1e-6   # um -> m
    Q1 = np.pi * r ** 4 * 4 * CMH2O / (8 * kuo["mu_b"] * kuo["L"])   # one vessel [m^3/s]
    assert obs["Q"] == pytest.approx(320 * Q1 * 1e6, rel=1e-12)       # the bed [mL/s]
    assert obs["R"] == pytest.approx(4 * CMH2O / Q1 / 320 * 1e-6 / MMHG, rel=1e-12)  # the bed [mmHg*s/mL]
    assert obs["V"] == pytest.approx(np.pi * r ** 2 * kuo["L"] * 320 * 1e6, rel=1e-12)
    assert obs["sigma"] == pytest.approx(60 * MMHG * r / kuo["t_w"], rel=1e-12)
    assert obs["q_out"] == pytest.approx(obs["Q"], rel=1e-12)   # no volume flow: what enters leaves


def test_units_parse_with_pint(art):
    pint = pytest.importorskip("pint")
    ureg = pint.UnitRegistry()
    for u in art.STATE_UNITS.values():
        ureg.Quantity(1, u)
    obs = {o.name: o.unit for o in art.Arteriole({"ca_order": 2}).observables()}
    for u in obs.values():
        ureg.Quantity(1, u)
    assert ureg.Quantity(1, obs["R"]).check("[pressure]*[time]/[volume]")


def test_nonpositive_ca_and_odd_lambda_give_finite_derivatives(art, kuo):
    s = {"Ca": np.array([-1e-7, 0.0, 1e-15, 1e-7]), "dCa": 0.0, "Cw": -1e-9,
         "lambda": np.array([0.05, 0.5, 3.0, 8.0])}
    for opts in ({"ca_order": 2}, {"ca_order": 2, "passive": True}):
        d = rates(art, s, 60 * MMHG, 100.0, kuo, opts)
        assert all(np.all(np.isfinite(v)) for v in d.values())
    dyn = {"Ca": 1e-7, "Cw": 1e-8, "lambda": 1.0, "M": 1.0, "Mp": 0.0, "AMp": 0.0, "AM": 0.0}
    d = rates(art, dyn, 60 * MMHG, 0.0, kuo, {"kinetics": "dynamic"})
    assert np.isfinite(d["lambda"]) and d["lambda"] > 0    # no bridges: the wall gives way


def test_nan_state_raises(art, kuo):
    """A NaN state is an error naming the arteriole (the kernel itself propagates NaN)."""
    from hemocircuit.components.arteriole.element import ArterioleError
    with pytest.raises(ArterioleError, match="arteriole derivatives: non-finite"):
        rates(art, {"Ca": np.nan, "Cw": 1e-8, "lambda": 1.0}, 8000.0, 0.0, kuo)
