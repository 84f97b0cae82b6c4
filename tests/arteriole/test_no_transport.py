"""NO model: eqs NO1, cbbar, cinv, psi, dNOdt, NOSS."""
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp


@pytest.mark.parametrize("Q", [1e-8, 1e-10, 1e-12, 1e-14, 1e-16])
def test_cbbar_equals_integrated_NO1(art, kuo, Q):
    """Integrate eq NO1 over x in [0, L] (plus the running integral) and average."""
    p = dict(kuo, C_in=2e-9, h_w=7.61e-9, no_speed=1.0)   # C_in > 0 exercises every term
    r, Cw = 50e-6, 3e-8
    Ab = np.pi * r ** 2
    k, Cwe = p["h_w"] + p["r_db"] * Ab, Cw / p["gamma_wb"]

    def rhs(x, y):
        dCb = (p["h_w"] * (Cwe - y[0]) - p["r_db"] * Ab * y[0]) / Q
        return [dCb, y[0]]

    jac = [[-k / Q, 0.0], [1.0, 0.0]]
    sol = solve_ivp(rhs, (0, p["L"]), [p["C_in"], 0.0], method="Radau", jac=jac,
                    rtol=1e-11, atol=[1e-22, 1e-26])
    mean_num = sol.y[1, -1] / p["L"]
    end_num = sol.y[0, -1]
    eq, pv = art.equations, art.equations.vector(p)
    x = eq.transport_number(Q, r, p["h_w"], pv)
    np.testing.assert_allclose(eq.cb_mean(Cw, r, x, p["h_w"], pv), mean_num, rtol=1e-7)
    outlet = eq.outlet_concentration(eq.cb_inf(Cw, r, p["h_w"], pv), p["C_in"], x)
    np.testing.assert_allclose(outlet, end_num, rtol=1e-7)


def test_psi_limits_without_nan(art, kuo):
    r = 60e-6
    eq, p = art.equations, art.equations.vector(kuo)
    h_w = eq.no_rates(p)[0]
    Q = np.array([0.0, 1e-300, 1e-20, 1e-12, 1e-3, 1.0, 1e10, -1e-12])
    with np.errstate(all="ignore"):   # both branches are evaluated; the chosen one is finite
        ps = eq.psi(eq.transport_number(Q, r, h_w, p))
    assert np.all(np.isfinite(ps))
    assert ps[0] == 1.0 and ps[1] == 1.0            # no flow: psi = 1 exactly
    assert 0 < ps[3] < 1
    assert ps[-1] == ps[3]                            # reverse flow: same psi
    x = eq.transport_number(Q[4:7], r, h_w, p)
    np.testing.assert_allclose(ps[4:7], x / 2, rtol=1e-3)  # psi ~ x/2 for x -> 0
    # continuity across the series switch and agreement with the direct formula
    xs = np.array([1e-2 * (1 - 1e-12), 1e-2 * (1 + 1e-12)])
    a, b = eq.psi(xs)
    assert abs(a - b) < 1e-14
    # reference without cancellation: alternating series for x <= 2, direct formula above
    x = np.logspace(-6, 2, 50)
    series = sum((-1) ** (k + 1) * x ** k / math.factorial(k + 1) for k in range(1, 40))
    exact = np.where(x <= 2, series, 1 - (1 - np.exp(-x)) / x)
    with np.errstate(all="ignore"):
        np.testing.assert_allclose(eq.psi(x), exact, rtol=1e-12)


@pytest.mark.parametrize("no_speed", [1.0, 200.0])
def test_noss_solves_dCw_dt_zero(art, kuo, no_speed):
    eq = art.equations
    p = eq.vector(dict(kuo, C_in=1e-9, no_speed=no_speed))
    h_w, r_dw, s_w, k_tau = eq.no_rates(p)
    r = np.array([20e-6, 60e-6, 120e-6])[:, None]
    dP = np.array([0.0, 50.0, 400.0, 2000.0])
    Q = eq.flow(r, dP, p)
    tau = eq.tau_hat(dP, r, p)
    with np.errstate(all="ignore"):
        x = eq.transport_number(Q, r, h_w, p)
        Cw = eq.cw_steady(r, x, tau, h_w, r_dw, s_w, k_tau, p)

    def f(c):
        with np.errstate(all="ignore"):
            return eq.dCw(c, eq.cb_mean(c, r, x, h_w, p), tau, h_w, r_dw, s_w, k_tau, p)
    # dCw/dt is affine in Cw: its zero, from two evaluations, must be eq NOSS
    f0, f1 = f(0.0), f(1e-6)
    root = -f0 * 1e-6 / (f1 - f0)
    np.testing.assert_allclose(Cw, root, rtol=1e-10)
    assert np.max(np.abs(f(Cw)) / np.abs(f0)) < 1e-12
    assert np.all(np.diff(Cw, axis=1) > 0)   # more flow, more NO


def test_tau_hat_normalisation(art, kuo):
    """tau_hat = (dP/dP0)(r/r0), dP0 = 60 mmHg, r0 = 60 um; Poiseuille wall shear r dP/(2L)."""
    p = art.equations.vector(kuo)

    def th(dP, r, _):
        return art.equations.tau_hat(dP, r, p)
    mmhg = 133.322387415
    assert th(60 * mmhg, 60e-6, kuo) == pytest.approx(1.0, rel=1e-12)
    assert th(30 * mmhg, 120e-6, kuo) == pytest.approx(1.0, rel=1e-12)
    assert th(15 * mmhg, 60e-6, kuo) == pytest.approx(0.25, rel=1e-12)
    assert th(-15 * mmhg, 60e-6, kuo) == th(15 * mmhg, 60e-6, kuo)   # either flow direction
