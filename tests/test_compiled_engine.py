"""The compiled engine (hemocircuit.kernels) against the numpy path and closed forms."""
from __future__ import annotations

import glob
import os

import numpy as np
import pytest

import hemocircuit as hc
from hemocircuit.analyses.op import operating_point
from hemocircuit.kernels.layout import EngineLayout
from hemocircuit.kernels.system import CompiledSystem

from paths import NETLISTS as TEST_NETLISTS, ROOT, SHARED_SVZEROD

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


SHARED_CASES = os.path.join(SHARED_SVZEROD, "cases")
#: bundled netlists, plus their valve models (elements nonlinear in the pressures: Newton in the
#: nodal solve) when the shared svZeroDSolver cases are here
OUTPUT_MODELS = BUNDLED + [os.path.join(SHARED_CASES, f"{n}.json") for n in ("valve_tanh", "chamber_elastance_inductor")]


@pytest.mark.parametrize("path", OUTPUT_MODELS, ids=os.path.basename)
def test_compiled_outputs_match_numpy_path(path):
    """Circuit.outputs with the nodal solution and flows from the compiled engine
    (CompiledSystem.nodal_outputs) gives the numpy evaluation's columns, in its order, to
    rounding: over a simulated run, and for a batch of members with their rows member-major
    (as freq evaluates a block)."""
    from hemocircuit.system import COMPILED_OUTPUT_ROWS

    if not os.path.exists(path):
        pytest.skip(f"{path} is not here")
    c = hc.load(path)
    system = CompiledSystem.of(c)
    if system is None:
        pytest.skip("a component type without a kernel")
    res = c.simulate(2.0, dt=2.0 / (COMPILED_OUTPUT_ROWS + 10), engine="compiled", rtol=1e-6)
    x, t = np.asarray(res.x), np.asarray(res.t)
    # the compiled nodal solve gives a result here (else outputs() would fall back to numpy and
    # this would compare the numpy path with itself), and is then ready for outputs()
    assert system.nodal_outputs(t, x, system.params(c)) is not None
    assert system.nodal_outputs_ready()
    fast, ref = c.outputs(t, x), c.outputs(t, x, engine="numpy")
    assert list(fast) == list(ref)
    _assert_columns_close(c, fast, ref)
    # three members with other values of a parameter (the first positive one), W rows each,
    # member-major
    path_, base = next((f"{g.ids[0]}.{name}", float(np.ravel(v)[0])) for g, p in zip(c.groups, c.group_params())
                       for name, v in p.items() if np.all(np.isfinite(v)) and np.ravel(v)[0] > 0)
    b = c.batch(3).with_values({path_: base * np.array([0.9, 1.0, 1.1])})
    W = x.shape[0]
    T, X = np.tile(t, 3), np.tile(x, (3, 1))
    assert system.nodal_outputs(T, X, system.params(b)) is not None
    fast, ref = b.outputs(T, X), b.outputs(T, X, engine="numpy")
    _assert_columns_close(c, fast, ref)
    assert W >= COMPILED_OUTPUT_ROWS


def _assert_columns_close(c, fast, ref):
    """Equal to rounding: relative 1e-9, absolute 1e-10 of the largest column of the same unit
    (a flow that is zero to rounding, 1e-13 mL/s, is compared with the circuit's flows)."""
    units = c.column_units()
    big = {}
    for k, v in ref.items():
        big[units[k]] = max(big.get(units[k], 0.0), float(np.max(np.abs(v))))
    for k in ref:
        assert np.allclose(fast[k], ref[k], rtol=1e-9, atol=1e-10 * big[units[k]] + 1e-300), k


def test_rc_step_closed_form(tmp_path):
    """R-C charged from a pressure step: V(t) = C P (1 - exp(-t/RC)) (compiled integrator)."""
    c = hc.load(os.path.join(TEST_NETLISTS, "base_rc.yaml"))  # R = 2 mmHg s/mL, C = 0.5 mL/mmHg
    res = c.simulate(5.0, dt=0.05, x0=np.zeros(c.nx), engine="compiled", rtol=1e-8)
    assert "compiled" in res.stats["method"]
    t = res.t
    expect = 0.5 * 80.0 * (1 - np.exp(-t / 1.0))
    assert np.max(np.abs(res["V(C1)"] - expect)) < 2e-7 * 40.0  # rtol 1e-8, plus dense output


def test_integrator_called_through_its_entry_gets_a_float64_atol_vector():
    """After its first call the Rosenbrock integrator's compiled entry is called directly
    (numba's dispatch skipped: kernels.system._entry_point), and that entry reads an array as
    the type it was compiled for, unchecked.  A second call through the entry gives the first
    call's run to the bit, R-C charging V = C P (1 - exp(-t/RC)); an atol of shape (1, nx) is
    refused (integrate_batch makes atol a float64 vector of nx), not read as a vector of one
    element (without that the call runs on, reading past its end)."""
    c = hc.load(os.path.join(TEST_NETLISTS, "base_rc.yaml"))  # R = 2 mmHg s/mL, C = 0.5 mL/mmHg
    system = CompiledSystem.of(c)
    t, x0, P = np.linspace(0.0, 5.0, 51), np.zeros((1, c.nx)), system.params(c)
    ref, _ = system.integrate_batch(t, x0, P, rtol=1e-8, atol=np.full(c.nx, 2.0 ** -20))
    assert system._addresses and all(entry is not None for _, _, entry in system._addresses.values())
    X, st = system.integrate_batch(t, x0, P, rtol=1e-8, atol=2.0 ** -20)
    assert st[0, 0] == 0
    np.testing.assert_array_equal(X, ref)
    V = X[0, :, c.state_names.index("C1.V")]
    assert np.max(np.abs(V - 0.5 * 80.0 * (1 - np.exp(-t)))) < 2e-7 * 40.0
    with pytest.raises(ValueError):
        system.integrate_batch(t, x0, P, rtol=1e-8, atol=np.full((1, c.nx), 2.0 ** -20))


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


@pytest.mark.parametrize("method", ["rodas5p", "bdf"])
def test_batch_members_step_on_their_own_breakpoints_only(method):
    """Members whose sine terms start at different times (breakpoints 5 s and 7.3 s): through
    batch_integrator.integrate each gets exactly the trajectory it gets alone, so no member's
    steps end on another member's breakpoint (with the union of them, they did)."""
    from hemocircuit.batch_integrator import integrate

    c = hc.load(os.path.join(NETLISTS, "arterial_compliance.yaml"))
    b = c.batch(2).with_values({"Pa.amplitude": "8 mmHg", "Pa.frequency": "0.1 Hz",
                                "Pa.start": np.array([5.0, 7.3])})
    assert b.breakpoints(0.0, 30.0, members=True) == [[5.0], [7.3]]
    x0 = np.repeat(operating_point(c).x[None], 2, axis=0)
    t = np.linspace(0.0, 30.0, 301)
    both = integrate(b, x0, t, rtol=1e-6, method=method)
    for m in range(2):
        alone = integrate(b.subset([m]), x0[m:m + 1], t, rtol=1e-6, method=method)
        assert np.array_equal(both.x[m], alone.x[0]), m
    assert not np.allclose(both.x[0], both.x[1])


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


# --- Rosenbrock tableaus (hemocircuit.kernels.tableaus) ---------------------------------------
NOMINAL_ORDER = {"ros34pw2": 3, "ros34pw3": 4, "rodas4": 4, "rodas5p": 5}


def _rosenbrock_fixed(name, n, embedded=False):
    """Fixed-step run of a tableau with the exact Jacobian (numpy, the classical form)
    on a nonlinear, non-autonomous problem over [0, 1]; returns y(1)."""
    from hemocircuit.kernels.tableaus import classical

    def f(t, y):
        return np.array([-y[1] + 0.1 * t * y[0], y[0] - 0.5 * y[1] ** 2 + np.sin(t)])

    gamma, A, G, b, e, _ = classical(name)
    c, d = A.sum(axis=1), gamma + G.sum(axis=1)
    y, t, h = np.array([1.0, 0.5]), 0.0, 1.0 / n
    for _ in range(n):
        J = np.array([[0.1 * t, -1.0], [1.0, -y[1]]])
        ft = np.array([0.1 * y[0], np.cos(t)])
        W = np.eye(2) - gamma * h * J
        K = np.zeros((len(b), 2))
        for s in range(len(b)):
            K[s] = np.linalg.solve(W, h * f(t + c[s] * h, y + A[s, :s] @ K[:s]) + h * J @ (G[s, :s] @ K[:s])
                                   + h * h * d[s] * ft)
        y = y + ((b - e) if embedded else b) @ K
        t += h
    return y


@pytest.mark.parametrize("name", sorted(NOMINAL_ORDER))
def test_tableau_observed_order(name):
    """Each method converges with its nominal order (errors at h = 1/16 .. 1/64 against a
    DOP853 reference at 1e-13), its embedded solution with the order its step-size exponent
    assumes (q - 1), and the stage points are consistent (c = row sums of A)."""
    from scipy.integrate import solve_ivp

    from hemocircuit.kernels.tableaus import classical

    ref = solve_ivp(lambda t, y: [-y[1] + 0.1 * t * y[0], y[0] - 0.5 * y[1] ** 2 + np.sin(t)], (0, 1), [1.0, 0.5],
                    method="DOP853", rtol=1e-13, atol=1e-14).y[:, -1]
    q = classical(name)[-1]
    ns = (8, 16) if name == "rodas5p" else (16, 32)  # rodas5p reaches the reference's accuracy sooner
    err = [np.max(np.abs(_rosenbrock_fixed(name, n) - ref)) for n in ns]
    assert np.log2(err[0] / err[1]) > NOMINAL_ORDER[name] - 0.35, err
    err = [np.max(np.abs(_rosenbrock_fixed(name, n, embedded=True) - ref)) for n in ns]
    assert np.log2(err[0] / err[1]) > q - 1 - 0.2, err


def test_rodas5p_dense_output_order():
    """RODAS5P's own dense output (tableaus.dense: Steinebach's coefficients, given over the
    transformed stages, converted to the classical ones here) is order 4 inside a step:
    halving h divides its local error at theta = 0.3, 0.5, 0.8 by ~2^5, against a DOP853
    reference; it ends on the step's solution (theta = 1) and starts on x0 (theta = 0)."""
    from scipy.integrate import solve_ivp

    from hemocircuit.kernels.tableaus import classical, dense

    def f(t, y):
        return np.array([-2 * y[0] + y[1] ** 2 + np.sin(t), -y[1] + np.cos(t) * y[0]])

    gamma, A, G, b, e, _ = classical("rodas5p")
    H = dense("rodas5p")
    assert H.shape == (3, 8)
    c, d = A.sum(axis=1), gamma + G.sum(axis=1)
    t0, y0 = 0.3, np.array([1.0, 0.5])
    errs = []
    for h in (0.1, 0.05):
        J = np.array([[-2.0, 2 * y0[1]], [np.cos(t0), -1.0]])
        ft = np.array([np.cos(t0), -np.sin(t0) * y0[0]])
        W = np.eye(2) - gamma * h * J
        K = np.zeros((8, 2))
        for s in range(8):
            K[s] = np.linalg.solve(W, h * f(t0 + c[s] * h, y0 + A[s, :s] @ K[:s]) + h * J @ (G[s, :s] @ K[:s])
                                   + h * h * d[s] * ft)
        y1, D = y0 + b @ K, H @ K
        ref = solve_ivp(f, (t0, t0 + h), y0, method="DOP853", rtol=1e-13, atol=1e-14, dense_output=True)

        def at(th):
            return (1 - th) * y0 + th * (y1 + (1 - th) * (D[0] + th * (D[1] + th * D[2])))
        assert np.array_equal(at(1.0), y1) and np.allclose(at(0.0), y0, rtol=0, atol=1e-15)
        errs.append(max(np.max(np.abs(at(th) - ref.sol(t0 + th * h))) for th in (0.3, 0.5, 0.8)))
    assert np.log2(errs[0] / errs[1]) > 4.4, errs


def test_step_size_controllers():
    """Every controller reaches the RC closed form at rtol 1e-8 (the predictive one, RODAS5P's
    default, in fewer steps than PI here); an unknown one is an error naming the choices."""
    from hemocircuit.kernels import tableaus

    c = hc.load(os.path.join(TEST_NETLISTS, "base_rc.yaml"))
    system = CompiledSystem.of(c)
    t = np.linspace(0.0, 5.0, 101)
    steps = {}
    for ctrl in ("pi", "predictive", "predictive-halving"):
        X, st = system.integrate_batch(t, np.zeros((1, c.nx)), system.params(c), rtol=1e-8, controller=ctrl)
        assert st[0, 0] == 0
        expect = 0.5 * 80.0 * (1 - np.exp(-t))
        assert np.max(np.abs(X[0, :, c.state_names.index("C1.V")] - expect)) < 2e-7 * 40.0, ctrl
        steps[ctrl] = st[0, 2]
    assert steps["predictive"] < steps["pi"], steps
    with pytest.raises(ValueError, match="predictive"):
        tableaus.packed("rodas5p", controller="fast")


def test_rejection_rule_of_the_predictive_controller():
    """After a rejection the predictive controller takes Hairer & Wanner's 0.9 err^(-1/q) of the
    step (at most 0.9 of it), predictive-halving at most half: on 300 s of vasomotion at rtol
    1e-5 (a rejection mostly has err just above 1) the first rejects about half as often and
    takes fewer steps, and both give the same oscillation to the tolerance's order."""
    c = hc.load(os.path.join(NETLISTS, "vasomotion.yaml"))
    system = CompiledSystem.of(c)
    x0 = np.asarray(operating_point(c).x, float)
    x0 = x0 + 1e-3 * c.state_scales * (c.state_names.index("art.Ca") == np.arange(c.nx))
    t = np.linspace(0.0, 300.0, 3001)
    out = {}
    for ctrl in ("predictive", "predictive-halving"):
        X, st = system.integrate_batch(t, x0[None], system.params(c), rtol=1e-5, atol=1e-5, controller=ctrl)
        assert st[0, 0] == 0, ctrl
        out[ctrl] = (X[0], st[0, 2], st[0, 3])
    (Xp, steps_p, rej_p), (Xh, steps_h, rej_h) = out["predictive"], out["predictive-halving"]
    assert rej_p < 0.7 * rej_h and steps_p < steps_h, (steps_p, rej_p, steps_h, rej_h)
    lam = c.state_names.index("art.lambda")
    assert np.ptp(Xp[2000:, lam]) > 0.05  # it oscillates (lambda swings by 0.56 here)
    assert abs(np.ptp(Xp[2000:, lam]) - np.ptp(Xh[2000:, lam])) < 1e-2 * np.ptp(Xh[2000:, lam])


@pytest.mark.parametrize("name", sorted(NOMINAL_ORDER))
def test_tableau_stiff_limit(name):
    """R(z) at z = h lambda -> -inf: 0 for the L-stable methods, ~0.63 for ROS34PW3 (A-stable
    only, as Rang & Angermann 2005 give it)."""
    from hemocircuit.kernels.tableaus import classical

    gamma, A, G, b, e, _ = classical(name)
    z = -1e9
    ns = len(b)
    K = np.zeros(ns)
    for s in range(ns):  # y' = lambda y, y0 = 1, h = 1: W k_s = z (1 + A k) + z G k
        K[s] = (z * (1 + A[s, :s] @ K[:s]) + z * (G[s, :s] @ K[:s])) / (1 - gamma * z)
    r_inf = 1 + b @ K
    expect = 0.63 if name == "ros34pw3" else 0.0
    assert abs(abs(r_inf) - expect) < 0.01, r_inf


@pytest.mark.parametrize("name", sorted(NOMINAL_ORDER))
def test_methods_rc_step_closed_form(name):
    """Every method in the compiled engine: R-C charged from a pressure step, V(t) = C P
    (1 - exp(-t/RC))."""
    c = hc.load(os.path.join(TEST_NETLISTS, "base_rc.yaml"))  # R = 2 mmHg s/mL, C = 0.5 mL/mmHg
    system = CompiledSystem.of(c)
    t = np.linspace(0.0, 5.0, 101)
    X, st = system.integrate(t, np.zeros(c.nx), system.params(c)[0], rtol=1e-8, method=name)
    assert st["status"] == 0
    assert np.max(np.abs(X[:, 0] - 0.5 * 80.0 * (1 - np.exp(-t / 1.0)))) < 2e-7 * 40.0


def test_pwl_kinks_keep_the_jacobian(tmp_path):
    """A pwl source with 200 slope-only kinks: stepping onto each kink without a restart
    (soft_kinks) gives the same course as restarting at every one, with fewer evaluations;
    a value jump (steps table) still restarts."""
    c = _pwl_rc(tmp_path)
    system = CompiledSystem.of(c)
    t = np.linspace(0.0, 10.0, 201)
    x0 = np.array([40.0])
    P = system.params(c)[0]
    brk = c.breakpoints(0.0, 10.0)
    assert len(brk) >= 190
    # a W-method reusing its Jacobian over steps (RODAS-type methods take a new one each step);
    # Jacobians from whole right-hand sides, so that nfev counts them
    soft, st_soft = system.integrate(t, x0, P, rtol=1e-6, breaks=brk, method="ros34pw2", local_jacobian=0)
    hard, st_hard = system.integrate(t, x0, P, rtol=1e-6, breaks=brk, method="ros34pw2", soft_kinks=0,
                                     local_jacobian=0)
    assert st_soft["steps"] == st_hard["steps"]  # both step onto every kink
    assert np.max(np.abs(soft - hard)) < 1e-9 * 40
    assert st_soft["nfev"] < 0.85 * st_hard["nfev"], (st_soft, st_hard)  # measured 1213 against 1533


# their cases that load here (valves and the closed-loop heart are nonlinear in the pressures)
SVZEROD_CASES = ["chamber_elastance_inductor", "closedLoopHeart_singleVessel", "closed_loop_two_hill",
                 "piecewise_Chamber_and_Valve", "pulsatileFlow_R_RCR", "pulsatileFlow_R_coronary",
                 "steadyFlow_RLC_R", "steadyFlow_blood_vessel_junction", "steadyFlow_stenosis_R", "valve_tanh"]
JAC_CASES = BUNDLED + [os.path.join(SHARED_CASES, c + ".json") for c in SVZEROD_CASES
                       if os.path.exists(os.path.join(SHARED_CASES, c + ".json"))]


def _load_any(path):
    if path.endswith(".json"):
        import json

        from hemocircuit.ic import apply_ic
        from hemocircuit.svzerod import import_svzerod, load_svzerod
        from hemocircuit.svzerod.importer import guess_units

        with open(path) as fh:
            units = guess_units(json.load(fh))
        m = import_svzerod(path, units=units)
        c = load_svzerod(path, units=units)
        return c, apply_ic(c, np.zeros(c.nx), m.initial)
    c = hc.load(path)
    return c, np.asarray(operating_point(c).x, float)


def _pwl_rc(tmp_path, n=200):
    """R-C charged through a pwl pressure source of n points (80 + 10 sin(0.4 pi t) mmHg)."""
    tt = np.linspace(0.0, 10.0, n)
    rows = ", ".join(f"[{a:.6f} s, {80 + 10 * np.sin(2 * np.pi * 0.2 * a):.6f} mmHg]" for a in tt)
    (tmp_path / "pwl.yaml").write_text(
        "name: pwl-rc\nelements:\n"
        f"  - {{id: Ps, type: pressure_source, nodes: [in, ground], value: {{pwl: [{rows}]}}}}\n"
        "  - {id: R1, type: resistor, nodes: [in, a], R: 2 mmHg*s/mL}\n"
        "  - {id: C1, type: compliance, nodes: [a, ground], C: 0.5 mL/mmHg}\n")
    return hc.load(str(tmp_path / "pwl.yaml"))


def test_pwl_kinks_end_steps_without_an_evaluation(tmp_path):
    """A pwl table's times are slope-only kinks (its value is continuous): given as kinks the
    integrator still ends a step on each but takes f(t-) for f(t+), one evaluation less per
    kink, with the same steps and the same course (RODAS5P, a new Jacobian every step)."""
    c = _pwl_rc(tmp_path)
    system = CompiledSystem.of(c)
    t = np.linspace(0.0, 10.0, 201)
    x0, P = np.array([40.0]), system.params(c)[0]
    brk = c.breakpoints(0.0, 10.0)
    assert c.breakpoints(0.0, 10.0, kinks=False) == [] and len(brk) == 198  # interior table times
    as_breaks, st_b = system.integrate(t, x0, P, rtol=1e-6, breaks=brk)
    as_kinks, st_k = system.integrate(t, x0, P, rtol=1e-6, kinks=brk)
    assert st_k["steps"] == st_b["steps"] and st_k["rejected"] == st_b["rejected"]
    assert st_b["nfev"] - st_k["nfev"] == len(brk)  # the right-limit evaluation at each kink
    assert np.max(np.abs(as_kinks - as_breaks)) < 1e-9 * 40
    # and the course is the R-C's: dV/dt = (Ps(t) - V/C)/R, against a fine scipy run
    ref = c.simulate(10.0, dt=0.05, x0=x0, engine="scipy", method="Radau", rtol=1e-10, progress=False)
    rt = np.asarray(ref.t)
    rows = np.searchsorted(rt, t - 1e-12)  # its rows also hold the table's times
    assert np.max(np.abs(rt[rows] - t)) < 1e-12
    assert np.max(np.abs(as_kinks[:, 0] - np.asarray(ref.x)[rows, 0])) < 1e-5 * 40


def test_output_from_keeps_the_later_rows(tmp_path, monkeypatch):
    """simulate(output_from=...) integrates from t0 but keeps the rows from that time on: the
    same rows, bit for bit, as the full run's (on both engines); a run longer than a piece of
    the compiled integrator continues through the early rows it keeps as restart points; a
    time outside the run is refused."""
    from hemocircuit.analyses import compiled_run
    from hemocircuit.errors import SolverError

    c = _pwl_rc(tmp_path, n=50)
    lates = {}
    for engine in ("compiled", "scipy"):
        full = c.simulate(10.0, dt=0.01, x0=np.array([40.0]), engine=engine, rtol=1e-7, progress=False)
        late = c.simulate(10.0, dt=0.01, x0=np.array([40.0]), engine=engine, rtol=1e-7, progress=False,
                           output_from=7.0)
        sel = np.asarray(full.t) >= 7.0 - 1e-9
        assert np.asarray(late.t).tolist() == np.asarray(full.t)[sel].tolist() and late.t[0] == pytest.approx(7.0)
        for col in ("P(a)", "Q(R1)"):
            assert np.asarray(late[col]).tolist() == np.asarray(full[col])[sel].tolist(), (engine, col)
        assert late.metadata["settings"]["output_from"] == 7.0
        lates[engine] = late
    late = lates["compiled"]
    monkeypatch.setattr(compiled_run, "PIECE_STEPS", 40)  # the run takes 102 steps: 3 pieces
    pieces = c.simulate(10.0, dt=0.01, x0=np.array([40.0]), engine="compiled", rtol=1e-7, progress=False,
                        output_from=7.0)
    assert np.asarray(pieces.t).tolist() == np.asarray(late.t).tolist()
    assert np.max(np.abs(np.asarray(pieces["P(a)"]) - np.asarray(late["P(a)"]))) < 1e-5 * 40
    for bad in (-1.0, 10.5, float("nan"), "7 s"):
        with pytest.raises(SolverError, match="output_from"):
            c.simulate(10.0, dt=0.1, x0=np.array([40.0]), progress=False, output_from=bad)


@pytest.mark.parametrize("path", JAC_CASES, ids=os.path.basename)
def test_local_jacobian_matches_whole_rhs_differences(path):
    """The integrator's element-local Jacobian (element differences composed through the nodal
    solve, with the expression parameters' dependence on other elements' states, e.g. the
    inertia's L(art.r)) equals the one from whole right-hand sides differenced, to the
    accuracy of forward differences (both use the FD_REL step), at perturbed states and
    t = 0.3 s (waveforms).  Circuits with elements nonlinear in the pressures (the valves of
    the svZeroDSolver cases) through Newton's matrix dR/du at the nodal solution, the valves'
    columns central differences of their residuals (engine_jacobian.U_STEP_REL): on
    chamber_elastance_inductor (a valve switching within 7.5e-6 mmHg) forward differences in u
    were 1.2e-2 off."""
    c, x = _load_any(path)
    system = CompiledSystem.of(c)
    if system is None or c.nx == 0:
        pytest.skip("runs on the numpy path or has no states")
    P = system.params(c)[0]
    rng = np.random.default_rng(3)
    for _ in range(2):
        xp = x + 0.01 * rng.standard_normal(c.nx) * c.state_scales
        J_loc = system.jacobian(0.3, xp, P, local=True)
        J_fd = system.jacobian(0.3, xp, P, local=False)
        assert np.all(np.isfinite(J_loc))
        col = np.maximum(np.max(np.abs(J_fd), axis=0), 1e-300)  # a column's scale
        err = np.max(np.abs(J_loc - J_fd) / col)
        assert err < 2e-5, (err, J_loc, J_fd)
        if not system.layout.autonomous:  # df/dt: the Jacobian's time column against f(t + dt) - f(t)
            ft_loc = system.time_derivative(0.3, xp, P, local=True)
            ft_fd = system.time_derivative(0.3, xp, P, local=False)
            scale = max(np.max(np.abs(ft_fd)), 1e-300)
            assert np.max(np.abs(ft_loc - ft_fd)) < 2e-5 * scale, (ft_loc, ft_fd)


def test_one_engine_per_set_of_component_types(monkeypatch):
    """The engine covers exactly the circuit's types, in an order that does not depend on the
    netlist (same set: same module); another set of types gets another module.  With
    HEMOCIRCUIT_ENGINE_TYPES=all every registered type is in, so every netlist shares one."""
    from hemocircuit.kernels import codegen
    from hemocircuit.kernels.layout import build_layout, engine_kernels, kernels_of

    monkeypatch.setenv("HEMOCIRCUIT_ENGINE_TYPES", "used")
    vaso = hc.load(os.path.join(NETLISTS, "vasomotion.yaml"))
    passive = hc.load(os.path.join(NETLISTS, "payne06_passive.yaml"))
    pairs = kernels_of(vaso)
    distinct = {(k.stamp, k.derivs, k.observe) for _, k in pairs}
    kernels = build_layout(vaso).kernels
    assert {(k.stamp, k.derivs, k.observe) for k in kernels} == distinct and len(kernels) == len(distinct)
    assert engine_kernels(pairs[::-1]) == kernels
    key = codegen._fingerprint(kernels)
    assert codegen._fingerprint(engine_kernels(pairs[::-1])) == key
    other = codegen._fingerprint(build_layout(passive).kernels)
    assert other[0] != key[0] and other[1] != key[1]
    monkeypatch.setenv("HEMOCIRCUIT_ENGINE_TYPES", "all")
    fns = lambda ks: [(k.stamp, k.derivs, k.observe) for k in ks]  # noqa: E731
    everything = fns(build_layout(vaso).kernels)
    assert len(everything) > len(kernels) and fns(build_layout(passive).kernels) == everything
    monkeypatch.setenv("HEMOCIRCUIT_ENGINE_TYPES", "some")
    with pytest.raises(hc.HemocircuitError, match="HEMOCIRCUIT_ENGINE_TYPES='some'"):
        build_layout(vaso)


def test_stale_engine_versions_are_pruned(tmp_path):
    """Other source versions of the same type set unused for STALE_DAYS go, with their numba
    files; recently used ones, the current one and other type sets stay."""
    from hemocircuit.kernels import codegen

    (tmp_path / "__pycache__").mkdir()
    old = os.path.getmtime(tmp_path) - (codegen.STALE_DAYS + 1) * 86400
    names = {tag: f"hemocircuit_engine_{s}_{v * 12}" for tag, s, v in (
        ("cur", "a" * 12, "1"), ("stale", "a" * 12, "2"), ("used", "a" * 12, "3"), ("other", "b" * 12, "4"))}
    for tag, name in names.items():
        for f in (tmp_path / f"{name}.py", tmp_path / "__pycache__" / f"{name}.rhs-1.py311.nbi"):
            f.write_text("")
            os.utime(f, (old, old))
    (tmp_path / f"{names['used']}.used").write_text("")  # loaded just now
    codegen._prune(tmp_path, "aaaaaaaaaaaa", names["cur"])
    left = {p.name for p in tmp_path.rglob("*")}
    assert f"{names['stale']}.py" not in left and f"{names['stale']}.rhs-1.py311.nbi" not in left
    for tag in ("cur", "used", "other"):
        assert f"{names[tag]}.py" in left and f"{names[tag]}.rhs-1.py311.nbi" in left, tag


def test_op_does_not_import_numba():
    """Commands that run no compiled code do not pay numba's import (~0.25 s): the component
    kernels are lazy (hemocircuit.kernels.jit)."""
    import subprocess
    import sys

    code = ("import sys; from hemocircuit.cli import main; main(['op', sys.argv[1]]); "
            "print('numba' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code, os.path.join(NETLISTS, "payne06.yaml")],
                         capture_output=True, text=True, check=True).stdout
    assert out.strip().splitlines()[-1] == "False", out


def test_compiled_system_is_kept_per_structure_and_type_setting(monkeypatch):
    """Every batch integrate call asks for the compiled system: it is built once per structure
    (new values, subsets and batches share it; only the parameter matrix differs) and follows
    HEMOCIRCUIT_ENGINE_TYPES."""
    from hemocircuit.kernels.system import CompiledSystem

    monkeypatch.setenv("HEMOCIRCUIT_ENGINE_TYPES", "used")
    c = hc.load(os.path.join(NETLISTS, "payne06.yaml"))
    s = CompiledSystem.of(c)
    bc = c.batch(3).with_values({"Pa.value": np.array([60.0, 80.0, 100.0])})
    assert CompiledSystem.of(bc) is s and CompiledSystem.of(bc.subset([0, 2])) is s
    np.testing.assert_array_equal(s.params(bc)[:, s.layout.slots[("Pa", "value")]], [60.0, 80.0, 100.0])
    monkeypatch.setenv("HEMOCIRCUIT_ENGINE_TYPES", "all")
    s_all = CompiledSystem.of(c)
    assert s_all is not s and len(s_all.layout.kernels) > len(s.layout.kernels)


def test_output_grid_ends_once_at_t_end():
    """The output times from t0 every dt, and t_end once: t0 + k dt that rounds just below
    t_end (0.7 + 10 x 0.1 = 1.7000000000000002, 2.1 + 20 x 0.05 ...) used to be followed by
    t_end itself, a second row at the same time (99 of 284 (t0, dt) pairs below)."""
    from hemocircuit.analyses.compiled_run import output_grid as _output_grid

    for t0 in np.arange(0.0, 50.0, 0.7):
        for dt in (0.1, 0.05, 0.01, 0.3):
            t_end = t0 + 1.0
            g = _output_grid(t0, t_end, dt)
            assert g[0] == t0 and g[-1] == t_end, (t0, dt)
            gaps = np.diff(g)
            assert np.all(gaps[:-1] > 0.999 * dt) and 1e-6 * dt < gaps[-1] < 1.001 * dt, (t0, dt, g[-3:])
    np.testing.assert_allclose(_output_grid(0.0, 1.0, 0.3), [0.0, 0.3, 0.6, 0.9, 1.0], rtol=0, atol=1e-15)


def test_run_from_a_later_start_has_no_repeated_time():
    c = hc.load(os.path.join(NETLISTS, "payne06_passive.yaml"))
    res = c.simulate(1.7, t0=0.7, dt=0.1, engine="compiled")
    t = np.asarray(res.t)
    assert t[0] == 0.7 and t[-1] == 1.7 and len(t) == 11 and np.all(np.diff(t) > 0.09)


@pytest.mark.parametrize("method", [None, "bdf"])
def test_a_failed_member_has_nan_rows_and_the_others_run_as_alone(method):
    """A member started from a non-finite state fails (its status says why) and every output row
    after its start is NaN (kernels.runs.finish_member, the end of every member's run, failed
    or not); the other member of the batch runs as alone (R-C charging, V = C P (1 - exp(-t/RC)))."""
    from hemocircuit.kernels.system import STATUS

    c = hc.load(os.path.join(TEST_NETLISTS, "base_rc.yaml"))
    system = CompiledSystem.of(c)
    t = np.linspace(0.0, 2.0, 21)
    X, st = system.integrate_batch(t, np.array([[np.nan] * c.nx, [0.0] * c.nx]), system.params(c), rtol=1e-8,
                                   method=method)
    assert st[0, 0] < 0 and STATUS[int(st[0, 0])] and np.all(np.isnan(X[0, 1:])), st[0]
    alone, _ = system.integrate_batch(t, np.zeros((1, c.nx)), system.params(c), rtol=1e-8, method=method)
    assert st[1, 0] == 0 and np.array_equal(X[1], alone[0])
    V = X[1, :, c.state_names.index("C1.V")]
    assert np.max(np.abs(V - 0.5 * 80.0 * (1 - np.exp(-t)))) < 1e-6 * 40.0


def test_nodal_newton_with_condensation_matches_numpy_path(tmp_path):
    """A ValveTanh (nonlinear in the pressures: stamped at every Newton iterate) between chains
    of capacitive vessels, a pressure table at the inlet (time-dependent, stamped once per
    nodal solve) and a resistance outlet: few enough unknowns touched by the varying stamps
    (the valve's 3) that the nodal system is condensed (2 nv <= n), so the condensed Newton
    runs with the iterate-independent stamps kept from the first iterate.  Its right-hand
    side equals the numpy path's (a Python Newton on the whole system) at states where the
    valve is open, closed and in its switching band."""
    import json

    from hemocircuit.svzerod import load_svzerod

    chain = [{"vessel_name": f"v{i}", "vessel_id": i, "zero_d_element_type": "BloodVessel",
              "zero_d_element_values": {"R_poiseuille": 100.0 + 10 * i, "C": 1e-4 * (1 + i)},
              "boundary_conditions": ({"inlet": "IN"} if i == 0 else {}) | ({"outlet": "OUT"} if i == 5 else {})}
             for i in range(6)]
    cfg = {"simulation_parameters": {"number_of_cardiac_cycles": 1, "number_of_time_pts_per_cardiac_cycle": 11,
                                     "steady_initial": False},
           "vessels": chain,
           "junctions": [{"junction_name": f"J{i}", "junction_type": "NORMAL_JUNCTION", "inlet_vessels": [i],
                          "outlet_vessels": [i + 1]} for i in (0, 1, 3, 4)],
           "valves": [{"type": "ValveTanh", "name": "valve",
                       "params": {"Rmin": 100.0, "Rmax": 1e5, "Steepness": 100.0, "upstream_block": "v2",
                                  "downstream_block": "v3"}}],
           "boundary_conditions": [
               {"bc_name": "IN", "bc_type": "PRESSURE", "bc_values": {"t": [0.0, 0.5, 1.0], "P": [0.0, 10.0, 0.0]}},
               {"bc_name": "OUT", "bc_type": "RESISTANCE", "bc_values": {"R": 1000.0, "Pd": 2.0}}]}
    p = tmp_path / "chain.json"
    p.write_text(json.dumps(cfg))
    c = load_svzerod(str(p), units="mmHg")
    system = CompiledSystem.of(c)
    n, cm, eu, ui, st = system.lay[0], system.lay[22], system.lay[7], system.lay[8], system.lay[23]
    varying = {int(ui[k]) for e in range(len(cm)) if cm[e] == 0 for k in range(eu[e], eu[e + 1]) if ui[k] < n}
    assert 2 * len(varying) <= n, (len(varying), n)  # the condensed path
    assert 2 in st and 0 in st  # stamps of both kinds
    P = system.params(c)
    C = 1e-4 * (1 + np.arange(c.nx))  # the vessels' volumes at pressures p: V = C p
    seen = set()
    for t in (0.2, 0.5, 0.8):
        for p_down in np.linspace(0.0, 12.0, 25):  # the chain's pressures past the valve
            x = C * np.where(np.arange(c.nx) < 3, 5.0, p_down)
            status = float(np.asarray(c.outputs(np.array([t]), x[None])["valve.status"])[0])
            seen.add("open" if status < 0.01 else "closed" if status > 0.99 else "band")
            f_np, f_c = c.rhs(t, x), system.rhs(t, x, P)
            assert np.allclose(f_c, f_np, rtol=1e-8, atol=1e-10 * np.max(np.abs(f_np))), (t, p_down, f_c, f_np)
    assert seen == {"open", "closed", "band"}


def test_a_source_without_its_sine_is_static():
    """A pressure source whose sine amplitude is 0 in every member is stamped once per parameter
    set and leaves the circuit autonomous (CompiledSystem.lay_for); with a sine it is stamped
    at every evaluation.  R-C driven by Pin = 80 + A sin(w t) from Pa(0) = 80 (tau = RC = 1 s):
    Pa = 80 + A / (1 + (w tau)^2) (sin w t - w tau cos w t + w tau exp(-t / tau)), in one batch with a
    member without the sine (Pa = 80), each member as it runs alone."""
    from hemocircuit.batch_integrator import integrate

    c = hc.load(os.path.join(TEST_NETLISTS, "base_rc.yaml"))  # R = 2 mmHg s/mL, C = 0.5 mL/mmHg
    system = CompiledSystem.of(c)
    ep = system.layout.fields.ep  # the source's element index: the one holding its columns of P
    src = int(np.searchsorted(ep, system.layout.slots[("Ps", "value")], side="right") - 1)
    lay, autonomous = system.lay_for(system.params(c))
    st = EngineLayout(*lay).st
    assert autonomous and st[src] == 1 and system.layout.fields.st[src] == 0
    b = c.batch(2).with_values({"Ps.amplitude": np.array([0.0, 5.0]), "Ps.frequency": "0.5 Hz"})
    lay, autonomous = system.lay_for(system.params(b))
    assert not autonomous and EngineLayout(*lay).st[src] == 0
    t = np.linspace(0.0, 6.0, 61)
    x0 = np.full((2, c.nx), 0.5 * 80.0)  # V = C Pa
    both = integrate(b, x0, t, rtol=1e-9)
    w, A = 2 * np.pi * 0.5, 5.0
    expect = 80.0 + A / (1 + w ** 2) * (np.sin(w * t) - w * np.cos(w * t) + w * np.exp(-t))
    assert np.max(np.abs(both.x[1, :, 0] / 0.5 - expect)) < 1e-6
    assert np.max(np.abs(both.x[0, :, 0] / 0.5 - 80.0)) < 1e-9
    for m in range(2):
        alone = integrate(b.subset([m]), x0[m:m + 1], t, rtol=1e-9)
        assert np.array_equal(both.x[m], alone.x[0]), m


def test_integrate_batch_edge_cases_of_the_switch_split():
    """An empty batch gives empty results (not an IndexError from the switch grouping), and an
    explicit ``autonomous`` option still reaches the tableau (tab_options override lay_for)."""
    c = hc.load(os.path.join(TEST_NETLISTS, "base_rc.yaml"))
    system = CompiledSystem.of(c)
    t = np.linspace(0.0, 1.0, 11)
    P = system.params(c)
    X, st = system.integrate_batch(t, np.zeros((0, c.nx)), P[:0], rtol=1e-8)
    assert X.shape == (0, 11, c.nx) and st.shape[0] == 0
    X1, _ = system.integrate_batch(t, np.zeros((1, c.nx)), P, rtol=1e-8, autonomous=0)
    X2, _ = system.integrate_batch(t, np.zeros((1, c.nx)), P, rtol=1e-8)
    assert np.max(np.abs(X1 - X2)) < 1e-9 * 40.0  # df/dt = 0 here either way: the same run


def test_one_integrator_specialisation_for_every_batch_shape(monkeypatch):
    """numba compiles a function once per argument types, read-only flags included: a single
    run, a batch from one grid and a batch of per-member grids reach the compiled integrator
    with the same flags (t_out, P and hmax read-only, X0 a writable copy), so a process that
    runs `tran` and then `freq` compiles (or loads) one integrator, not two."""
    c = hc.load(os.path.join(TEST_NETLISTS, "base_rc.yaml"))
    system = CompiledSystem.of(c)
    seen = []
    real = system.mod.integrate_batch

    def spy(t_out, X0, P, lay, scales, lim_i, lim_b, lim_r, brk, jump, rtol, atol, h0, hmax, *rest):
        seen.append(tuple(a.flags.writeable for a in (t_out, X0, P, hmax, brk, jump)))
        return real(t_out, X0, P, lay, scales, lim_i, lim_b, lim_r, brk, jump, rtol, atol, h0, hmax, *rest)

    monkeypatch.setattr(system.mod, "integrate_batch", spy)
    t = np.linspace(0.0, 1.0, 11)
    P = system.params(c)
    system.integrate_batch(t, np.zeros((1, c.nx)), P, rtol=1e-6)
    system.integrate_batch(t, np.zeros((3, c.nx)), np.repeat(P, 3, axis=0), rtol=1e-6)
    system.integrate_batch(np.repeat(t[None], 2, axis=0), np.zeros((2, c.nx)), np.repeat(P, 2, axis=0), rtol=1e-6,
                           hmax=np.full(2, 0.5))
    assert seen == [(False, True, False, False, True, True)] * 3, seen
