"""The compiled engine (hemocircuit.kernels) against the numpy path and closed forms."""
from __future__ import annotations

import glob
import os

import numpy as np
import pytest

import hemocircuit as hc
from hemocircuit.analyses.op import operating_point
from hemocircuit.kernels.system import CompiledSystem

from paths import NETLISTS as TEST_NETLISTS, ROOT

NETLISTS = str(ROOT / "netlists")
BUNDLED = sorted(glob.glob(os.path.join(NETLISTS, "*.yaml")))


@pytest.mark.parametrize("path", BUNDLED, ids=os.path.basename)
def test_rhs_matches_numpy_path(path):
    """Every bundled netlist: the compiled right-hand side equals the numpy one at perturbed
    operating points (the kernels are exact ports, so to rounding)."""
    c = hc.load(path)
    system = CompiledSystem.of(c)
    if system is None:
        pytest.skip("a component type without a kernel")
    x = operating_point(c).x
    rng = np.random.default_rng(1)
    P = system.params(c)
    for t in (0.0, 3.7):
        xp = x + 0.02 * rng.standard_normal(c.nx) * c.state_scales
        f_np = c.rhs(t, xp)
        f_c = system.rhs(t, xp, P)
        assert np.allclose(f_c, f_np, rtol=1e-9, atol=1e-12 * np.max(np.abs(f_np))), (f_c, f_np)
    # the whole batch entry point, one call for many rows
    X = x + 0.01 * rng.standard_normal((5, c.nx)) * c.state_scales
    assert np.allclose(system.rhs(1.0, X, P), c.rhs(1.0, X), rtol=1e-9, atol=1e-12)


def test_rc_step_closed_form(tmp_path):
    """R-C charged from a pressure step: V(t) = C P (1 - exp(-t/RC)) (compiled integrator)."""
    c = hc.load(os.path.join(TEST_NETLISTS, "base_rc.yaml"))  # R = 2 mmHg s/mL, C = 0.5 mL/mmHg
    res = c.simulate(5.0, dt=0.05, x0=np.zeros(c.nx), engine="compiled", rtol=1e-8)
    assert "compiled" in res.stats["method"]
    t = res.t
    expect = 0.5 * 80.0 * (1 - np.exp(-t / 1.0))
    assert np.max(np.abs(res["V(C1)"] - expect)) < 2e-7 * 40.0  # rtol 1e-8, plus dense output


def test_compiled_matches_scipy_with_protocol_and_waveform():
    """A step protocol on the inertia variant (inductor following the arteriole's radius
    through an expression): both engines agree within their tolerances."""
    c = hc.load(os.path.join(NETLISTS, "inertia.yaml"))
    c = c.with_values({"Pa.amplitude": "8 mmHg"})
    c = c.with_values({"Pa.frequency": "0.1 Hz"})
    a = c.simulate(30.0, dt=0.5, engine="compiled", rtol=1e-8)
    b = c.simulate(30.0, dt=0.5, engine="scipy", rtol=1e-8)
    for col in ("art.r", "Q(Rla)", "Q(Lb)", "V(Cic)"):
        scale = np.max(np.abs(b[col])) + 1e-30
        assert np.max(np.abs(a[col] - b[col])) / scale < 2e-5, col


def test_hard_limit_events_match_scipy():
    """Vasomotion (second-order Ca with its floor): the compiled engine locates the floor
    events like scipy's event handling, and both give the same radius course."""
    c = hc.load(os.path.join(NETLISTS, "vasomotion.yaml"))
    x0 = operating_point(c).x.copy()
    x0[c.state_names.index("art.lambda")] *= 1.05
    a = c.simulate(60.0, dt=0.1, x0=x0, engine="compiled", rtol=1e-8)
    b = c.simulate(60.0, dt=0.1, x0=x0, engine="scipy", rtol=1e-8)
    assert a.stats["limit_events"] >= 3  # the floor is reached in each cycle
    ca_floor = c.hard_limits()[0][1]
    assert np.min(a["art.Ca"]) >= ca_floor - 1e-15
    on_grid = np.isin(b.t, a.t)  # scipy's output also holds the event times
    assert np.max(np.abs(a["art.r"] - b["art.r"][on_grid])) < 0.05  # um, on ~40 um swings


def test_protocol_events_change_waveforms_and_coincide(tmp_path):
    """Protocol events on the compiled engine: an event that turns a constant source into a
    waveform (and back), and two events at the same time, give what scipy gives."""
    proto = tmp_path / "p.yaml"
    proto.write_text(
        "t_end: 6 s\n"
        "events:\n"
        "  - {at: 1 s, set: {Ps.value: {pwl: [[0 s, 80 mmHg], [2 s, 40 mmHg], [10 s, 40 mmHg]]}}}\n"
        "  - {at: 3 s, set: {Ps.value: 60 mmHg}}\n"
        "  - {at: 3 s, set: {R1.R: 1 mmHg*s/mL}}\n")
    c = hc.load(os.path.join(TEST_NETLISTS, "base_rc.yaml"))
    a = c.simulate(None, dt=0.1, x0=np.zeros(c.nx), protocol=str(proto), engine="compiled", rtol=1e-9)
    b = c.simulate(None, dt=0.1, x0=np.zeros(c.nx), protocol=str(proto), engine="scipy", rtol=1e-9)
    assert np.all(np.isfinite(a["V(C1)"]))
    va = np.interp([0.9, 1.5, 2.5, 2.9, 3.5, 6.0], a.t, a["V(C1)"])
    vb = np.interp([0.9, 1.5, 2.5, 2.9, 3.5, 6.0], b.t, b["V(C1)"])
    assert np.allclose(va, vb, rtol=1e-6), (va, vb)
    # closed form after the last events: V -> C * 60 mmHg with time constant R C = 0.5 s
    v3 = np.interp(3.0, b.t, b["V(C1)"])
    assert abs(va[-1] - (30.0 + (v3 - 30.0) * np.exp(-3.0 / 0.5))) < 1e-5


def test_batch_members_independent():
    """integrate_batch gives each member the trajectory it gets alone."""
    c = hc.load(os.path.join(NETLISTS, "arterial_compliance.yaml"))
    system = CompiledSystem.of(c)
    x0 = operating_point(c).x
    cb = c.batch(3)
    cb = cb.with_values({"Pa.value": np.array([70.0, 80.0, 90.0])})
    P = system.params(cb)
    t = np.linspace(0, 20, 21)
    X, st = system.integrate_batch(t, np.repeat(x0[None], 3, axis=0), P, rtol=1e-7)
    assert np.all(st[:, 0] == 0)
    alone, _ = system.integrate(t, x0, P[2], rtol=1e-7)
    assert np.array_equal(X[2], alone)
    assert not np.allclose(X[0], X[2])


def test_one_finite_difference_rule():
    """The derivatives service's dense Jacobian of a known function: d(x^2, x0*x1)/dx."""
    from hemocircuit.derivatives import dense_jacobian

    def fun(rows):
        return np.stack([rows[:, 0] ** 2, rows[:, 0] * rows[:, 1]], axis=1)

    X = np.array([[3.0, -2.0], [0.5, 4.0]])
    J, F = dense_jacobian(fun, X, np.ones(2))
    expect = np.array([[[6.0, 0.0], [-2.0, 3.0]], [[1.0, 0.0], [4.0, 0.5]]])
    assert np.allclose(F, fun(X))
    assert np.allclose(J, expect, rtol=1e-6, atol=1e-6)
