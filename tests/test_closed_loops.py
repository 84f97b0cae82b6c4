"""Hearts and valves that never stop the solver: closed loops of separate chamber and valve
blocks run for many beats, conserve the blood volume and reach a periodic state.

netlists/svzerod/closedLoopHeart_singleVessel_decomposed.json is svZeroDSolver's case of that
name (their tests/cases at commit c7b0ca09, BSD licence in that folder): four chambers with
outflow inductors, four ValveTanh valves (steepness 1e4/mmHg), pulmonary and systemic vessels,
numbers in mmHg, mL, s.  It stopped with "step size too small" at t = 0.32-1.58 s (rtol 1e-4 to
1e-6): one nodal solve that did not converge (a rejected stage's far-away state) left its
iterate as the warm start of every later solve, which then failed too.
"""
from __future__ import annotations

import numpy as np
import pytest

from paths import ROOT

from hemocircuit.kernels.system import CompiledSystem
from hemocircuit.svzerod import load_svzerod

DECOMPOSED = ROOT / "netlists" / "svzerod" / "closedLoopHeart_singleVessel_decomposed.json"
PERIOD = 1.0169  # s, their cardiac_period


@pytest.fixture(scope="module")
def heart():
    return load_svzerod(str(DECOMPOSED), "mmHg")


def _blood_volume(c, X):
    """The loop's conserved blood volume [mL] of state rows X: the sum its conservation law
    names (chambers' and vessels' volume stores; a BloodVesselRC's charge is not one)."""
    law, = c.laws
    total = 0.0
    for elem, k, w in law.terms:
        own = [i for i, n in enumerate(c.state_names) if n.startswith(elem + ".")]
        total = total + w * X[:, own[k]]
    return total


def test_a_failed_nodal_solve_leaves_no_poisoned_start(heart):
    """Rows evaluated one after another share the nodal solve's warm start (as the integrator's
    stages do).  A row whose solve fails (an atrial volume of 1e6 mL: its exponential
    pressure-volume law overflows) must not make the next, ordinary rows fail: each gives what
    it gives evaluated alone."""
    cs = CompiledSystem.of(heart)
    P = cs.params(heart)
    x = np.full(heart.nx, 10.0)
    x[heart.state_names.index("LA.Q_out")] = -0.01
    alone = cs.rhs(0.3, x, P[0])
    assert np.all(np.isfinite(alone))
    X = np.repeat(x[None], 3, 0)
    X[0, heart.state_names.index("LA.Vc")] = 1e6
    F = cs.rhs(0.3, X, np.repeat(P, 3, 0))
    assert not np.all(np.isfinite(F[0]))
    np.testing.assert_allclose(F[1], alone, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(F[2], alone, rtol=1e-9, atol=1e-9)


@pytest.fixture(scope="module")
def thirty_beats(heart):
    from hemocircuit.analyses.transient import simulate
    return simulate(heart, 30 * PERIOD, dt=PERIOD / 500, rtol=1e-6, engine="compiled", progress=False)


def test_decomposed_heart_runs_thirty_beats_conserving_blood_volume(heart, thirty_beats):
    """30 beats without a solver failure; the blood volume (the loop's conservation law: its
    chambers and capacitors) is the same at every output time to 1e-9 of itself."""
    r = thirty_beats
    assert r.t[-1] == pytest.approx(30 * PERIOD)
    V = _blood_volume(heart, r.x)
    assert V[0] > 100.0
    assert np.max(np.abs(V - V[0])) <= 1e-9 * V[0]


def test_decomposed_heart_reaches_a_periodic_state_with_equal_stroke_volumes(heart, thirty_beats):
    """After 30 beats the last two beats agree (the left ventricle's volume to 1e-3 of its
    range), and in the last beat the two ventricles eject the same volume (a periodic closed
    loop has no net transfer between its halves), to 1e-3 of the stroke volume."""
    r = thirty_beats
    t = r.t
    last = t >= 29 * PERIOD - 1e-9
    before = (t >= 28 * PERIOD - 1e-9) & (t <= 29 * PERIOD + 1e-9)
    vlv = r["V(LV)"]
    a, b = np.asarray(vlv)[last], np.asarray(vlv)[before]
    n = min(a.size, b.size)
    rng = np.ptp(a)
    assert rng > 10.0  # a beating ventricle, mL
    assert np.max(np.abs(a[:n] - b[:n])) <= 1e-3 * rng
    tl = t[last]
    q_av = np.trapezoid(np.asarray(r["Q(AV)"])[last], tl)
    q_pv = np.trapezoid(np.asarray(r["Q(PV)"])[last], tl)
    assert q_av > 10.0
    assert abs(q_av - q_pv) <= 1e-3 * q_av
