"""The closed-loop heart worked example (examples/svzerod_closed_loop.py, docs/svzerod.md):
its periodic state by shooting against cycle-by-cycle integration, and physical relations of
the orbit.  Needs their closedLoopHeart_singleVessel.json (../shared/svzerod; skipped
otherwise)."""
from __future__ import annotations

import importlib.util
import os

import numpy as np
import pytest

from paths import SHARED_SVZEROD as SHARED

HERE = os.path.dirname(os.path.abspath(__file__))
MODEL = os.path.join(SHARED, "cases", "closedLoopHeart_singleVessel.json")
pytestmark = pytest.mark.skipif(not os.path.isfile(MODEL), reason="svZeroDSolver test cases not present")


@pytest.fixture(scope="module")
def example():
    spec = importlib.util.spec_from_file_location("svzerod_closed_loop",
                                                  os.path.join(HERE, "..", "examples", "svzerod_closed_loop.py"))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def orbit(example):
    (fig, orb), = example.sweep(MODEL, (1.0,), max_iter=6)
    return fig, orb


def test_shooting_agrees_with_cycles_to_convergence(example, orbit):
    """The orbit's start is the state after 15 cycles from their initial condition (the
    multipliers' |mu| ~ 0.25: 15 cycles leave ~1e-9 of the start's distance), and the
    orbit closes: x(T) = x(0)."""
    from hemocircuit.analyses.transient import simulate
    from hemocircuit.ic import apply_ic

    fig, orb = orbit
    c, model = example.load(MODEL)
    S = c.state_scales
    x0 = apply_ic(c, np.zeros(c.nx), model.initial)
    res = simulate(c, 15 * model.period, dt=model.period / 100, x0=x0, rtol=1e-9, progress=False)
    assert np.max(np.abs((orb.x0 - np.asarray(res.x)[-1]) / S)) < 1e-4
    assert np.max(np.abs((orb.x[-1] - orb.x[0]) / S)) < 1e-4
    mu = np.abs(orb.nontrivial_multipliers)
    assert 0.1 < mu.max() < 0.5  # stable: the cycles converge (from their start: 5 cycles to 1 %)


def test_stroke_volume_and_mean_pressures(orbit):
    """SV = max - min V_LV equals the aortic valve's flow integrated over the cycle (mitral and
    aortic valves never open together); the mean flow through the vessel is SV/T (the aortic
    capacitor's volume is periodic); the mean pressure drop from the heart's outlet to its
    inlet is (R_vessel + Rp + Rd) times that flow (the vessel's inductor and the RCR's
    capacitor average out over a period)."""
    fig, orb = orbit
    assert 20.0 < fig["stroke_volume"] < 100.0
    assert fig["aortic_valve_volume"] == pytest.approx(fig["stroke_volume"], rel=1e-3)
    assert fig["mean_vessel_flow"] == pytest.approx(fig["stroke_volume"] / orb.period, rel=1e-3)
    drop = fig["mean_aortic_pressure"] - fig["mean_venous_pressure"]
    assert drop == pytest.approx(fig["R_systemic"] * fig["mean_vessel_flow"], rel=1e-3)
    assert 0 < fig["ejection_fraction"] < 1 and fig["P_LV_max"] > fig["mean_aortic_pressure"]


def test_anderson_shooting_finds_the_orbit_in_few_periods(example, orbit):
    """Anderson-accelerated shooting from their initial condition: x(T) = x(0) to 1e-6 of the
    state scales within 10 periods (plain cycling needs 12 for that at rtol 1e-8: |mu| ~ 0.25), at the
    Newton orbit's start within the integrators' difference, the blood volume kept exactly;
    with multipliers, the same dominant |mu| as Newton's, without them no stability claimed; an autonomous orbit and an unknown
    method are refused."""
    from hemocircuit.analyses.periodic import shoot
    from hemocircuit.errors import HemocircuitError
    from hemocircuit.ic import apply_ic

    fig, newton = orbit
    c, model = example.load(MODEL)
    S = c.state_scales
    x0 = apply_ic(c, np.zeros(c.nx), model.initial)
    orb = shoot(c, x0, model.period, forced=True, rtol=1e-9, tol=1e-6, max_iter=10, method="anderson",
                progress=False)
    assert orb.converged and orb.residual < 1e-6 and orb.iterations <= 10
    assert np.max(np.abs((orb.x[-1] - orb.x[0]) / S)) < 1e-5
    assert np.max(np.abs((orb.x0 - newton.x0) / S)) < 1e-4
    total = lambda x: sum(v[0] for v in c.law_volumes(np.asarray(x)[None]))  # noqa: E731
    assert total(orb.x0) == pytest.approx(total(x0), rel=1e-9)
    mu_a, mu_n = np.abs(orb.nontrivial_multipliers).max(), np.abs(newton.nontrivial_multipliers).max()
    assert mu_a == pytest.approx(mu_n, abs=0.05)
    bare = shoot(c, x0, model.period, forced=True, rtol=1e-6, tol=1e-5, method="anderson", multipliers=False,
                 progress=False)
    assert bare.converged and bare.multipliers.size == 0 and bare.stable is None  # not claimed stable
    with pytest.raises(HemocircuitError, match="anderson"):
        shoot(c, x0, model.period, forced=False, method="anderson", progress=False)
    with pytest.raises(HemocircuitError, match="choose 'newton' or 'anderson'"):
        shoot(c, x0, model.period, forced=True, method="broyden", progress=False)


@pytest.mark.parametrize("method", [None, "bdf"])
def test_a_start_on_the_valves_bounds_is_held_not_crossed(method):
    """From the operating point the heart's four valve flows sit on their hard limit 0 to
    rounding (3.4e-16 mL/s).  Such a state counts as on its bound (kernels.runs.
    LIMIT_ON_BOUND x atol): held, not "crossed" at s ~ 0 by every step.  Before, every step was
    a limit event advancing t by ~1e-21 s, and `tran MODEL.json` hit the 10-million-step limit
    at t = 3.8e-11 s after 3 minutes.  Now 0.1 s takes a few dozen steps, and no valve flow
    goes below its bound."""
    import hemocircuit as hc
    from hemocircuit.kernels.system import CompiledSystem

    c = hc.load(MODEL, svzerod_units="mmHg")
    x = np.atleast_2d(c.operating_point().x)[0]
    limits = c.hard_limits()
    assert len(limits) == 4 and all(0.0 < x[i] - b < 1e-12 for i, b, _ in limits)
    system = CompiledSystem.of(c)
    X, st = system.integrate_batch(np.linspace(0.0, 0.1, 11), x[None], system.params(c), rtol=1e-6,
                                   max_steps=20_000, method=method)
    assert st[0, 0] == 0 and st[0, 1] == pytest.approx(0.1) and st[0, 2] < 500, st[0]
    assert all(np.all(X[0, :, i] >= b) for i, b, _ in limits)


def test_heart_partials_give_the_jacobian_of_element_differences(example, orbit):
    """The heart's analytic partials (closed_loop_heart_pulmonary.heart_derivs_jac) give the
    integrator the Jacobian it had from element-local differences, at every 10th row of the
    orbit (valves open and closed: a closed valve's flow sits exactly on its bound 0, where f
    jumps and the partial in that flow is the forward quotient at the engine's step, ~1e11 /s,
    while the balances' v Q terms keep the partial 1) and 1 % (+ 1e-3) off it (every valve
    open), entry by entry to 1e-5 of (|entry| + 1 /s): the differences' error is ~1.6e-6."""
    from hemocircuit.kernels.system import CompiledSystem

    _, orb = orbit
    c, _ = example.load(MODEL)
    system = CompiledSystem.of(c)
    P = system.params(c)[0]
    q = [c.state_names.index(f"CLH.Q_{v}") for v in ("RA", "RV", "LA", "LV")]
    closed = 0
    rows = [(orb.t[i], orb.x[i]) for i in range(0, len(orb.t), 10)]
    rows += [(t, x * 1.01 + 1e-3) for t, x in rows[::4]]
    for t, x in rows:
        closed += int(np.sum(x[q] == 0.0))
        J_an = system.jacobian(t, x, P, local=1)
        J_fd = system.jacobian(t, x, P, local=2)
        assert np.all(np.abs(J_an - J_fd) <= 1e-5 * (np.abs(J_fd) + 1.0)), (t, x, J_an - J_fd)
    assert closed >= 20  # the closed branch is exercised
