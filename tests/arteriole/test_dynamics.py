"""Ca dynamics: second order (eq dCadt2) vs first order (eq dCadt), and the full element."""
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from element_calls import rates

MMHG = 133.322387415   # Pa per mmHg


def _ca_step(art, p, t):
    """Linear step response of the Ca subsystem alone: Ca_bar 1e-8 -> 1e-7 M at t = 0."""
    def rhs(_, y):
        return [y[1], art.equations.d2Ca(y[0], y[1], 1e-7, art.equations.vector(p))]
    sol = solve_ivp(rhs, (0, t[-1]), [1e-8, 0.0], t_eval=t, method="LSODA",
                    rtol=1e-10, atol=[1e-18, 1e-18])
    return sol.y[0]


def test_heavily_damped_second_order_is_first_order(art, kuo):
    zeta, omega = 20.0, 1.0
    tau = 2 * zeta / omega                                 # slow pole ~ omega / (2 zeta)
    t = np.linspace(0, 5 * tau, 400)
    ca2 = _ca_step(art, dict(kuo, zeta=zeta, omega_n=omega), t)
    ca1 = 1e-7 + (1e-8 - 1e-7) * np.exp(-t / tau)          # eq dCadt, exact
    assert np.max(np.abs(ca2 - ca1)) < 0.005 * 9e-8
    # the comparison can fail: moderate damping is far from first order
    ca_mid = _ca_step(art, dict(kuo, zeta=1.0, omega_n=1 / tau * 2), t)
    assert np.max(np.abs(ca_mid - ca1)) > 0.05 * 9e-8


def test_light_damping_rings_with_theoretical_overshoot(art, kuo):
    zeta, omega = 0.1, 1.0
    t = np.linspace(0, 20, 4001)
    ca = _ca_step(art, dict(kuo, zeta=zeta, omega_n=omega), t)
    overshoot = (ca.max() - 1e-7) / 9e-8
    assert overshoot == pytest.approx(np.exp(-np.pi * zeta / np.sqrt(1 - zeta ** 2)), rel=1e-3)
    assert np.sum(np.diff(np.sign(ca - 1e-7)) != 0) >= 5  # rings around the target
    over = _ca_step(art, dict(kuo, zeta=2.0, omega_n=omega), t)
    assert over.max() <= 1e-7                              # overdamped: no overshoot


def _run_element(art, p, options, P0, P1, dP, t):
    s0 = art.solve_steady(P0, dP, p, options)
    x0 = art.pack(s0, options)

    def rhs(_, x):
        d = rates(art, x, P1, dP, p, options)
        return np.array([float(d[n]) for n in art.state_names(options)])

    sol = solve_ivp(rhs, (0, t[-1]), x0, t_eval=t, method="LSODA", rtol=1e-8,
                    atol=[art.STATE_SCALES[n] * 1e-8 for n in art.state_names(options)])
    assert sol.success
    return art.equations.l2r(sol.y[art.state_names(options).index("lambda")], art.equations.vector(p)), \
        art.solve_steady(P1, dP, p, options)["r"]


def test_full_element_second_order_large_zeta_matches_first_order(art, kuo):
    """Pressure step 60 -> 80 mmHg at fixed dP: radius trajectories with 2nd-order Ca
    (zeta = 10, omega_n = 2 rad/s) and 1st-order Ca with tau_Ca = 2 zeta / omega_n = 10 s."""
    t = np.linspace(0, 200, 201)   # Ca (10 s) and wall NO (1/r_dw ~ 21 s) settle
    zeta, omega = 10.0, 2.0
    r1, r1_end = _run_element(art, dict(kuo, tau_Ca=2 * zeta / omega), {}, 60 * MMHG, 80 * MMHG, 50.0, t)
    r2, r2_end = _run_element(art, dict(kuo, zeta=zeta, omega_n=omega), {"ca_order": 2},
                              60 * MMHG, 80 * MMHG, 50.0, t)
    assert r1_end == pytest.approx(r2_end, rel=1e-12)
    excursion = np.max(np.abs(r1 - r1[0]))
    assert excursion > 1e-6                                 # the step does move the vessel
    assert np.max(np.abs(r2 - r1)) < 0.02 * excursion
    assert r1[-1] == pytest.approx(r1_end, rel=1e-3)        # and it settles at the steady state
