"""The simple element types against closed forms computed by hand (resistor, inductor, linear
and log compliance, sources, ResistanceBC, RCR, BloodVessel, valves at their limits); waveform
records and expression bytecode against their Python references (Waveform.__call__,
Expression.evaluate) over random inputs, every option combination and the branch edges."""
import math
import pickle
import zlib

import numba
import numpy as np
import pytest

from hemocircuit.build import parse_netlist
from hemocircuit.components.compliance import LinearCompliance, LogCompliance
from hemocircuit.components.inductor import Inductor
from hemocircuit.components.resistor import Resistor
from hemocircuit.components.sources import FlowSource, PressureSource
from hemocircuit.components.svzerod.blood_vessel import BloodVessel
from hemocircuit.components.svzerod.piecewise_valve import PiecewiseValve
from hemocircuit.components.svzerod.rcr_bc import RCRBC
from hemocircuit.components.svzerod.resistance_bc import ResistanceBC
from hemocircuit.components.svzerod.valve_tanh import ValveTanh
from hemocircuit.components.tracer_pools import TissuePool, TracerPool
from hemocircuit.expressions import Expression, Reference, constant_reference
from hemocircuit.kernels import Kernel
from hemocircuit.kernels import expressions as kx
from hemocircuit.kernels import waveforms as kw
from hemocircuit.netlist import load_netlist
from hemocircuit.waveforms import Constant, Sine, Sum, Table, parse_waveform

from paths import ROOT
from options import option_combinations

RTOL = 1e-13
E = 400  # elements per random draw


def close(got, ref, rtol=RTOL, atol=0.0):
    np.testing.assert_allclose(got, ref, rtol=rtol, atol=atol, equal_nan=True)


# =========================================================== components ======================

def _u(rng, L):
    return rng.uniform(-50.0, 150.0, (1, E, L))


def gen_resistor(rng):
    return {"R": rng.uniform(0.01, 10.0, (1, E))}, np.zeros((1, E, 0)), _u(rng, 2)


def gen_compliance(rng):
    p = {"C": rng.uniform(0.01, 5.0, (1, E)), "V0": rng.uniform(-5.0, 20.0, (1, E))}
    V = rng.uniform(-10.0, 50.0, (1, E, 1))
    V[0, :20, 0] = 0.0  # at the clamp limit
    u = _u(rng, 3)
    u[0, :, 2] = rng.uniform(-5.0, 5.0, E)
    return p, V, u


def gen_log_compliance(rng):
    k = np.exp(rng.uniform(np.log(0.02), np.log(3.0), (1, E)))
    Vn = rng.uniform(-5.0, 30.0, (1, E))
    p = {"k": k, "P0": rng.uniform(-10.0, 20.0, (1, E)), "Vn": Vn}
    z = rng.uniform(-30.0, 760.0, (1, E))  # k (V - Vn): below V_eps (z < ln EPS), clipped at 700
    V = (Vn + z / k)[..., None]
    V[0, :20, 0] = 0.0
    u = _u(rng, 3)
    u[0, :, 2] = rng.uniform(-5.0, 5.0, E)
    return p, V, u


def gen_inductor(rng):
    return ({"L": np.exp(rng.uniform(np.log(1e-4), 0.0, (1, E)))}, rng.uniform(-20.0, 20.0, (1, E, 1)),
            _u(rng, 2))


def _source_params(rng):
    return {"value": rng.uniform(-100.0, 100.0, (1, E)), "amplitude": rng.uniform(-10.0, 10.0, (1, E)),
            "frequency": rng.uniform(0.0, 5.0, (1, E)), "phase": rng.uniform(-4.0, 4.0, (1, E)),
            "start": np.where(rng.random((1, E)) < 0.2, 0.0, rng.uniform(0.0, 6.0, (1, E)))}


def gen_pressure_source(rng):
    return _source_params(rng), np.zeros((1, E, 0)), _u(rng, 3)


def gen_flow_source(rng):
    return _source_params(rng), np.zeros((1, E, 0)), _u(rng, 2)


def _pool_params(rng):
    V = rng.uniform(0.0, 100.0, (1, E))
    V[0, :20] = 0.0  # collapsed compliance: the volume floor
    return {"V": V, "k_d": rng.uniform(0.0, 5.0, (1, E)), "h": np.exp(rng.uniform(-25.0, -15.0, (1, E))),
            "l": rng.uniform(0.0, 5.0, (1, E)), "C_x": np.exp(rng.uniform(-40.0, -30.0, (1, E)))}


def gen_tracer_pool(rng):
    p = _pool_params(rng)
    p.update({"C_0": np.exp(rng.uniform(-40.0, -30.0, (1, E))), "C_inf": np.exp(rng.uniform(-40.0, -30.0, (1, E))),
              "k_feed": np.exp(rng.uniform(-28.0, -14.0, (1, E))), "L_feed": rng.uniform(0.0, 1e-3, (1, E)),
              "n_feed": np.exp(rng.uniform(0.0, 10.0, (1, E)))})
    u = _u(rng, 3)
    u[0, :, 2] = rng.uniform(-1.0, 5.0, E)
    u[0, :20, 2] = 0.0
    p["L_feed"][0, 10:30] = 0.0  # K = 0, also at q = 0 (x = inf there, not 0/0)
    return p, np.exp(rng.uniform(-38.0, -30.0, (1, E, 1))), u


def gen_tissue_pool(rng):
    return _pool_params(rng), np.exp(rng.uniform(-38.0, -30.0, (1, E, 1))), np.zeros((1, E, 0))


TYPES = {
    "resistor": (Resistor, gen_resistor),
    "compliance": (LinearCompliance, gen_compliance),
    "log_compliance": (LogCompliance, gen_log_compliance),
    "inductor": (Inductor, gen_inductor),
    "pressure_source": (PressureSource, gen_pressure_source),
    "flow_source": (FlowSource, gen_flow_source),
    "tracer_pool": (TracerPool, gen_tracer_pool),
    "tissue_pool": (TissuePool, gen_tissue_pool),
}

#: expected iopt for given options (the documented encodings)
OPTION_ENCODINGS = [
    (Resistor, {}, []),
    (Inductor, {}, []),
    (PressureSource, {}, []),
    (FlowSource, {}, []),
    (LinearCompliance, {"clamp_at_zero": False}, [0, 0]),
    (LinearCompliance, {"clamp_at_zero": True}, [1, 0]),
    (LogCompliance, {"clamp_at_zero": False, "extended": False}, [0, 0]),
    (LogCompliance, {"clamp_at_zero": True, "extended": False}, [1, 0]),
    (LogCompliance, {"clamp_at_zero": False, "extended": True}, [0, 1]),
    (LogCompliance, {"clamp_at_zero": True, "extended": True}, [1, 1]),
    (TracerPool, {"units_reading": "consistent", "scale": 1e-20}, [0]),
    (TracerPool, {"units_reading": "thesis"}, [1]),
    (TissuePool, {"units_reading": "consistent"}, [0]),
    (TissuePool, {"units_reading": "thesis", "scale": 1e-17}, [1]),
]


CASES = [(tn, opts) for tn, (cls, _) in TYPES.items() for opts in option_combinations(cls)]


def _run_kernel(comp, p, x, u, t, src=None):
    """Kernel outputs for every element: (A, b, dx, obs) stacked over elements."""
    k = comp.kernel()
    iopt = comp.kernel_options()
    pmat = np.ascontiguousarray(np.stack([p[n][0] for n in comp.parameters], axis=1))
    if src is not None:
        pmat[:, 0] += src[0]  # the circuit kernel adds the waveform value to the value slot
    L = len(comp.local_nodes) + len(comp.branches())
    S = len(comp.states())
    As, bs, dxs, obs = (np.full((E, L, L), np.nan), np.full((E, L), np.nan), np.full((E, S), np.nan),
                        np.full((E, len(k.observables)), np.nan))
    for e in range(E):
        A, b = np.zeros((L, L)), np.zeros(L)
        xe, ue = np.ascontiguousarray(x[0, e]), np.ascontiguousarray(u[0, e])
        k.stamp(pmat[e], xe, ue, t, iopt, A, b)
        dx = np.full(S, np.nan)
        k.derivs(pmat[e], xe, ue, t, iopt, dx)
        out = np.full(len(k.observables), np.nan)
        k.observe(pmat[e], xe, iopt, out)
        As[e], bs[e], dxs[e], obs[e] = A, b, dx, out
    return As, bs, dxs, obs


@pytest.mark.parametrize("type_name,opts", CASES, ids=[f"{t}-{o}" for t, o in CASES])
def test_component_kernels_are_numba_functions(type_name, opts):
    cls, _ = TYPES[type_name]
    comp = cls(opts)
    k = comp.kernel()
    assert isinstance(k, Kernel)
    assert k.observables == tuple(o.name for o in comp.observables() if o.state_only)
    for f in (k.stamp, k.derivs, k.observe):
        f = getattr(f, "dispatcher", f)  # hemocircuit.kernels.jit.njit: made on first use
        assert isinstance(f, numba.core.registry.CPUDispatcher) and f.targetoptions.get("nogil")
    iopt = comp.kernel_options()
    assert iopt.dtype == np.int64 and iopt.ndim == 1


# ---------------------------------------------------- closed forms, computed by hand ---------
def evaluate(comp, p, x, u, t=0.0, src=None):
    """(flows A u - b of the stamp [node rows then branch residuals], dx/dt, {observable: value})
    of ONE element through the component's hooks (its kernel functions)."""
    p = {k: np.full((1, 1), float(v)) for k, v in p.items()}
    x = np.array(x, dtype=float).reshape(1, 1, -1)
    u = np.array(u, dtype=float).reshape(1, 1, -1)
    s = None if src is None else np.full((1, 1), float(src))
    L = u.shape[-1]
    A, b = comp.stamp(p, x, None if comp.linear_in_pressure else u, t, s)
    A = np.broadcast_to(A, (1, 1, L, L))[0, 0]
    b = np.broadcast_to(b, (1, 1, L))[0, 0]
    dx = np.broadcast_to(comp.derivatives(p, x, u, t, s), x.shape)[0, 0]
    obs = {k: float(np.broadcast_to(v, (1, 1))[0, 0]) for k, v in comp.observe(p, x, u, t, s).items()}
    return A @ u[0, 0] - b, dx, obs


def test_resistor_closed_form():
    # q = (P_a - P_b)/R = (10 - 4)/2 = 3 mL/s leaves a, enters b
    flows, dx, _ = evaluate(Resistor(), {"R": 2.0}, [], [10.0, 4.0])
    close(flows, [3.0, -3.0])
    assert dx.shape == (0,)


def test_inductor_closed_form():
    # the state q = 2 mL/s flows a -> b; dq/dt = (P_a - P_b)/L = (10 - 4)/0.5 = 12 mL/s^2
    flows, dx, obs = evaluate(Inductor(), {"L": 0.5}, [2.0], [10.0, 4.0])
    close(flows, [2.0, -2.0])
    close(dx, [12.0])
    assert obs["q"] == 2.0


def test_linear_compliance_closed_form():
    # P_node - P_ref = (V - V0)/C = (5 - 1)/2 = 2 mmHg: at P = 3, 1 the branch row is satisfied;
    # the branch flow 0.7 mL/s leaves node, returns at ref and fills the store: dV/dt = 0.7
    p = {"C": 2.0, "V0": 1.0}
    flows, dx, obs = evaluate(LinearCompliance(), p, [5.0], [3.0, 1.0, 0.7])
    close(flows, [0.7, -0.7, 0.0], atol=1e-15)
    close(dx, [0.7])
    assert obs == {"V": 5.0, "C": 2.0}
    flows, _, _ = evaluate(LinearCompliance(), p, [5.0], [4.0, 1.0, 0.0])
    close(flows[2], 1.0)  # residual: 3 mmHg across, 2 mmHg from the volume
    clamped = LinearCompliance({"clamp_at_zero": True})
    close(evaluate(clamped, p, [0.0], [0.0, 0.0, -0.7])[1], [0.0])  # empty: no more draining
    close(evaluate(clamped, p, [0.0], [0.0, 0.0, 0.7])[1], [0.7])  # filling goes on
    assert evaluate(clamped, p, [-1.0], [0.0, 0.0, 0.0])[2]["V"] == 0.0


def test_log_compliance_closed_form():
    # dP = P0 + exp(k (V - Vn)) = 2 + exp(0.5 * (5 - 3)) = 2 + e;  C = exp(-k (V - Vn))/k = 2/e
    p = {"k": 0.5, "P0": 2.0, "Vn": 3.0}
    flows, dx, obs = evaluate(LogCompliance({"clamp_at_zero": False}), p, [5.0], [2.0 + math.e, 0.0, 1.5])
    close(flows, [1.5, -1.5, 0.0], atol=1e-15)
    close(dx, [1.5])
    close([obs["V"], obs["C"]], [5.0, 2.0 / math.e])
    # below V_eps = Vn + ln(EPS)/k = 3 + ln(1e-3)/0.5: the plain law, and the extension
    # dP = P0 + EPS (1 + k (V - V_eps)), C = 1/(k EPS) = 2000 mL/mmHg
    V, V_eps = -12.0, 3.0 + 2.0 * math.log(1e-3)
    plain = evaluate(LogCompliance({"clamp_at_zero": False}), p, [V], [0.0, 0.0, 0.0])
    close(-plain[0][2], 2.0 + math.exp(0.5 * (V - 3.0)))
    ext = evaluate(LogCompliance({"clamp_at_zero": False, "extended": True}), p, [V], [0.0, 0.0, 0.0])
    close(-ext[0][2], 2.0 + 1e-3 * (1.0 + 0.5 * (V - V_eps)))
    close(ext[2]["C"], 2000.0)


SINE = {"amplitude": 10.0, "frequency": 0.25, "phase": 0.0, "start": 1.0}


def test_pressure_source_closed_form():
    # value(t) = 80 + 10 sin(2 pi 0.25 (t - 1)) for t >= 1: 90 mmHg at t = 2; 80 before the start,
    # plus a waveform's value (5 mmHg) added to the value
    comp = PressureSource()
    for t, src, value in ((2.0, None, 90.0), (0.5, None, 80.0), (0.5, 5.0, 85.0)):
        flows, _, _ = evaluate(comp, {"value": 80.0, **SINE}, [], [0.0, 0.0, 4.0], t, src)
        close(flows, [4.0, -4.0, -value])  # the branch flow 4 mL/s; P_node - P_ref - value = -value
    flows, _, _ = evaluate(comp, {"value": 80.0, **SINE}, [], [100.0, 10.0, 0.0], 2.0)
    close(flows[2], 0.0)


def test_flow_source_closed_form():
    # q = 3 + 1 sin(2 pi 0.5 (1 - 0) + pi/2) = 3 + sin(3 pi/2) = 2 mL/s from a to b at t = 1
    p = {"value": 3.0, "amplitude": 1.0, "frequency": 0.5, "phase": math.pi / 2, "start": 0.0}
    flows, _, _ = evaluate(FlowSource(), p, [], [50.0, 7.0], 1.0)
    close(flows, [2.0, -2.0])


def test_resistance_bc_closed_form():
    # Q = (P - Pd)/R = (10 - 2)/4 = 2 mL/s into the block
    flows, _, obs = evaluate(ResistanceBC(), {"R": 4.0, "Pd": 2.0}, [], [10.0, 0.0])
    close(flows, [2.0, -2.0])
    close(obs["Q_in"], 2.0)


def test_rcr_closed_form():
    # V = 8 mL, C = 2: P_c = 4 mmHg; P = 7 = P_c + Rp Q with Rp = 1, Q = 3;
    # C dP_c/dt = Q - (P_c - Pd)/Rd = 3 - (4 - 1)/3 = 2, so dV/dt = 2 mL/s
    p = {"Rp": 1.0, "C": 2.0, "Rd": 3.0, "Pd": 1.0}
    flows, dx, obs = evaluate(RCRBC(), p, [8.0], [7.0, 0.0, 3.0])
    close(flows, [3.0, -3.0, 0.0], atol=1e-15)
    close(dx, [2.0])
    close([obs["P_c"], obs["Q_in"]], [4.0, 3.0])


def test_blood_vessel_closed_forms():
    p = {"R_poiseuille": 2.0, "C": 0.5, "L": 0.5, "stenosis_coefficient": 0.0}
    # R alone: P_in - P_out = R q: 10 - 4 = 2 * 3
    flows, _, obs = evaluate(BloodVessel(), p, [], [10.0, 4.0, 0.0, 3.0])
    close(flows, [3.0, -3.0, 0.0, 0.0], atol=1e-15)
    assert obs["Q_in"] == obs["Q_out"] == 3.0
    # a zero stenosis coefficient changes nothing; S = 0.5 adds S|q|q: 10 - 4 = (2 + 0.5 * 2) 2
    st = BloodVessel({"stenotic": True})
    close(evaluate(st, p, [], [10.0, 4.0, 0.0, 3.0])[0], [3.0, -3.0, 0.0, 0.0], atol=1e-15)
    close(evaluate(st, {**p, "stenosis_coefficient": 0.5}, [], [10.0, 4.0, 0.0, 2.0])[0], [2.0, -2.0, 0.0, 0.0],
          atol=1e-15)
    # RC: V = 3, C = 0.5: P_c = 6 = P_out; P_in = P_c + R Q_in = 6 + 2 * 1; Q_out = 0.4:
    # dV/dt = Q_in - Q_out = 0.6
    flows, dx, obs = evaluate(BloodVessel({"capacitive": True}), p, [3.0], [8.0, 6.0, 0.0, 1.0, -0.4])
    close(flows, [1.0, -0.4, -0.6, 0.0, 0.0], atol=1e-15)
    close(dx, [0.6])
    close([obs["V"], obs["Q_in"], obs["Q_out"]], [3.0, 1.0, 0.4])
    # RL: L dQ/dt = P_in - P_out - R Q = 10 - 4 - 2 * 1 = 4, dQ/dt = 8
    flows, dx, _ = evaluate(BloodVessel({"inductive": True}), p, [1.0], [10.0, 4.0, 0.0])
    close(flows, [1.0, -1.0, 0.0])
    close(dx, [8.0])


def test_valve_limits():
    # ValveTanh open (P_in > P_out by 5 mmHg, k = 10: the Rmax weight 1/(1 + e^100) ~ 4e-44): R = Rmin,
    # Q = 5/0.1 = 50 satisfies the branch row; closed (5 mmHg the other way): R = Rmax, Q = -5/1000
    p = {"Rmin": 0.1, "Rmax": 1000.0, "steepness": 10.0}
    flows, _, obs = evaluate(ValveTanh(), p, [], [10.0, 5.0, 50.0])
    close(flows, [50.0, -50.0, 0.0], atol=1e-12)
    close(obs["status"], 0.0, atol=1e-40)
    flows, _, obs = evaluate(ValveTanh(), p, [], [5.0, 10.0, -0.005])
    close(flows, [-0.005, 0.005, 0.0], atol=1e-12)
    close(obs["status"], 1.0)
    # halfway (equal pressures): R = (Rmin + Rmax)/2, status 1/2
    close(evaluate(ValveTanh(), p, [], [5.0, 5.0, 0.0])[2]["status"], 0.5)
    # PiecewiseValve: Q = dP/Rmin forward, dP/Rmax backward
    pv = {"Rmin": 0.5, "Rmax": 100.0}
    close(evaluate(PiecewiseValve(), pv, [], [10.0, 5.0])[0], [10.0, -10.0])
    close(evaluate(PiecewiseValve(), pv, [], [5.0, 10.0])[0], [-0.05, 0.05])
    close(evaluate(PiecewiseValve(), pv, [], [5.0, 10.0])[2]["Q"], -0.05)


def test_option_encodings():
    for cls, opts, expected in OPTION_ENCODINGS:
        got = cls(opts).kernel_options()
        assert got.dtype == np.int64
        assert got.tolist() == expected, (cls.__name__, opts, got)


def _branches_hit(type_name, opts):
    """(component, p, x, u): one random draw of the type's inputs (for the coverage checks)."""
    rng = np.random.default_rng(1)
    cls, gen = TYPES[type_name]
    p, x, u = gen(rng)
    return cls(opts), p, x, u


def test_inputs_reach_every_branch():
    """The random inputs cross every branch the kernels implement (so the comparisons above
    would see a wrong branch): clamping, the EPS continuation, the exp clip, sines not yet
    started, reversed and zero metered flows, the volume floor."""
    comp, p, x, u = _branches_hit("log_compliance", {"clamp_at_zero": True, "extended": True})
    k, Vn, V = p["k"], p["Vn"], x[..., 0]
    V_eps = Vn + np.log(1e-3) / k
    assert np.any(V < V_eps) and np.any(V >= V_eps) and np.any(k * (V - Vn) > 700)
    assert np.any((V <= 0) & (u[..., 2] < 0)) and np.any((V <= 0) & (u[..., 2] > 0))
    # the options change the numbers for these inputs
    on = comp.derivatives(p, x, u, 0.0)
    off = LogCompliance({"clamp_at_zero": False}).derivatives(p, x, u, 0.0)
    assert not np.array_equal(on, off)
    ext = comp.stamp(p, x, None, 0.0)[1]
    plain = LogCompliance({"extended": False}).stamp(p, x, None, 0.0)[1]
    assert not np.array_equal(ext, plain)
    comp, p, x, u = _branches_hit("tracer_pool", {})
    q = u[..., 2]
    assert np.any(q < 0) and np.any(q == 0) and np.any(q > 0) and np.any(p["V"] == 0)
    assert not np.array_equal(TracerPool({"units_reading": "thesis"}).derivatives(p, x, u, 0.0),
                              comp.derivatives(p, x, u, 0.0))


def test_kernels_propagate_nan():
    """The kernels' clamps (max(V, 0), max(q, 0), the volume floor) keep a NaN input NaN, as
    np.maximum does: a NaN state, flow or volume gives NaN, never a clamped finite number."""
    for type_name, opts in [("log_compliance", {"clamp_at_zero": True, "extended": True}),
                            ("log_compliance", {"clamp_at_zero": True, "extended": False}),
                            ("compliance", {"clamp_at_zero": True}), ("tracer_pool", {})]:
        comp, p, x, u = _branches_hit(type_name, opts)
        x = x.copy()
        x[0, 5:10, 0] = np.nan
        if type_name == "tracer_pool":
            u = u.copy()
            u[0, 10:15, 2] = np.nan
            p = dict(p)
            p["V"] = p["V"].copy()
            p["V"][0, 15:20] = np.nan
        A_k, b_k, dx_k, obs_k = _run_kernel(comp, p, x, u, 0.0)
        assert np.all(np.isnan(obs_k[5:10, 0])), type_name  # V (compliances) or C (pools)
        assert np.all(np.isfinite(obs_k[20:, 0])), type_name
        if type_name == "tracer_pool":
            assert np.all(np.isnan(dx_k[5:20, 0])) and np.all(np.isfinite(dx_k[20:, 0]))
        else:
            assert np.all(np.isnan(b_k[5:10, 2])) and np.all(np.isfinite(b_k[20:, 2]))


# =========================================================== waveforms =======================

def _waves():
    unit = "mmHg"
    return [
        Constant(80.0),
        Constant(-0.0),
        Table(np.array([2.0]), np.array([7.5]), linear=True),
        Table(np.array([2.0]), np.array([7.5]), linear=False),
        parse_waveform({"pwl": [["0 s", "80 mmHg"], ["5 s", "90 mmHg"], ["5 s", "60 mmHg"], ["12 s", "61 mmHg"],
                                ["20 s", "61 mmHg"], ["20 s", "70 mmHg"], ["20 s", "75 mmHg"]]}, unit),
        parse_waveform({"pwl": [["1 s", "1 mmHg"], ["1.5 s", "-3 mmHg"], ["2 s", "4 mmHg"], ["3 s", "4 mmHg"],
                                ["4.25 s", "0.1 mmHg"], ["6 s", "1e5 mmHg"], ["7 s", "2 mmHg"]]}, unit),
        # slopes overflow to -inf: np.interp returns the table value at a time of the table
        Table(np.array([0.0, 1.0, 2.0, 3.0]), np.array([1e308, -1e308, 0.0, 1e308]), linear=True),
        parse_waveform({"steps": [["0 s", "80 mmHg"], ["10 s", "72 mmHg"], ["10 s", "71 mmHg"], ["15 s", "75 mmHg"]]},
                       unit),
        parse_waveform({"pwc": [["3 s", "1 mmHg"], ["4 s", "2 mmHg"], ["5 s", "3 mmHg"], ["6 s", "4 mmHg"],
                                ["7 s", "5 mmHg"], ["8 s", "6 mmHg"]]}, unit),
        parse_waveform({"sine": {"offset": "80 mmHg", "amplitude": "8 mmHg", "frequency": "0.1 Hz",
                                 "phase": "30 deg", "start": "2.5 s"}}, unit),
        Sine(offset=1.0, amplitude=-2.0, frequency=3.3, phase=0.0, start=0.0),
        parse_waveform({"sum": [{"sine": {"offset": "1 mmHg", "amplitude": "3 mmHg", "frequency": "0.7 Hz",
                                          "start": "1 s"}},
                                {"pwl": [["0 s", "0 mmHg"], ["4 s", "10 mmHg"]]},
                                "5 mmHg",
                                {"sum": [{"steps": [["2 s", "1 mmHg"], ["6 s", "2 mmHg"]]}, "0.25 mmHg",
                                         {"sum": ["1e-17 mmHg", "3 mmHg"]}]}]}, unit),
        # summation order matters here: 1e16 + (1 + 1) != (1e16 + 1) + 1
        Sum([Constant(1e16), Sum([Constant(1.0), Constant(1.0)])]),
        Sum([Sum([Constant(1.0), Sum([Constant(1e16), Constant(1.0)])]), Constant(1.0), Constant(-1e16)]),
        Sum([]),
    ]


def _times(wf):
    bps = sorted(set(_breakpoints(wf)))
    ts = [-100.0, -1.0, 0.0, 1e-300, 1e3, math.inf, -math.inf, math.nan]
    for b in bps:
        ts += [b, np.nextafter(b, -np.inf), np.nextafter(b, np.inf), b - 1e-9, b + 1e-9, b - 0.5, b + 0.5]
    ts += list(np.random.default_rng(0).uniform(-5.0, 25.0, 300))
    return np.array(ts, dtype=float)


def _breakpoints(wf):
    return wf.breakpoints() if not isinstance(wf, Sum) else [b for p in wf.parts for b in _breakpoints(p)]


def test_waveform_sum_order_matters():
    """The reference really distinguishes nested from flat summation (so the test can fail)."""
    wf = _waves()[-3]
    assert wf(0.0) == 1e16 + 2.0 and (1e16 + 1.0) + 1.0 != wf(0.0)


@pytest.mark.parametrize("i", range(len(_waves())))
def test_waveform_record_matches_call(i):
    wf = _waves()[i]
    rec = kw.encode(wf)
    assert rec.dtype == np.float64 and rec[1] == rec.size  # header [kind, length]
    # placed in the middle of a concatenated array: start offsets work
    data, starts = kw.concat([kw.encode(Constant(3.0)), rec, kw.encode(_waves()[5])])
    assert starts.tolist() == [0, 3, 3 + rec.size]
    has_sine = "Sine" in repr(wf)
    for t in _times(wf):
        with np.errstate(invalid="ignore"):
            ref = wf(float(t))
        got = kw.wave_value(data, starts[1], float(t))
        if has_sine and np.isfinite(t):
            close(got, ref, rtol=1e-15, atol=1e-15 * 100)
        else:  # tables and constants: bit for bit
            assert (got == ref) or (np.isnan(got) and np.isnan(ref)), (t, got, ref)


def _periodic_waves():
    rows = [["0.5 s", "1 mmHg"], ["0.8 s", "4 mmHg"], ["0.8 s", "-2 mmHg"], ["1.5 s", "1 mmHg"]]
    return [parse_waveform({"periodic": {"period": "1 s", "pwl": rows}}, "mmHg"),
            parse_waveform({"periodic": {"period": "2.5 s", "steps": rows}}, "mmHg"),
            Sum([parse_waveform({"periodic": {"period": "0.7 s", "pwl": [["0 s", "3 mmHg"], ["0.7 s", "5 mmHg"]]}},
                                "mmHg"), Sine(offset=1.0, amplitude=-2.0, frequency=3.3, phase=0.0, start=0.0)])]


@pytest.mark.parametrize("i", range(len(_waves()) + len(_periodic_waves())))
def test_waveform_sample_matches_call(i):
    """sample(t) over an array (the outputs of a run) is the scalar call at every time, bit for
    bit, NaN and infinite times included."""
    wf = (_waves() + _periodic_waves())[i]
    ts = _times(wf) if i < len(_waves()) else np.concatenate(
        [np.linspace(-3.0, 7.0, 2001), [0.5, 1.5, 0.8, np.nextafter(1.5, 0), math.nan, 1e6 + 0.3]])
    with np.errstate(invalid="ignore"):
        ref = np.array([wf(float(t)) for t in ts], dtype=float)
        got = wf.sample(ts)
    assert got.shape == ts.shape and got.dtype == np.float64
    same = (got == ref) | (np.isnan(got) & np.isnan(ref))
    assert same.all(), (ts[~same][:5], got[~same][:5], ref[~same][:5])


def test_waveform_kinks_are_continuous():
    """The breakpoints jumps() leaves out are slope-only kinks: the value's left and right
    limits agree there (so the integrator may skip the re-evaluation); the jumps() of a pwl
    table with a repeated time do jump."""
    t0, t1 = -3.0, 25.0
    kinks = jumps = 0
    for wf in _waves() + _periodic_waves():
        periodic = "Periodic" in repr(wf)
        brk = set(wf.breakpoints(t0, t1)) if periodic else set(_breakpoints(wf))
        jmp = set(wf.jumps(t0, t1))
        assert jmp <= brk, wf
        for b in sorted(brk - jmp):
            if t0 < b < t1:
                # the change across b shrinks with the distance (a jump would stay)
                with np.errstate(invalid="ignore", over="ignore"):
                    d1, d2 = (abs(wf(b + e) - wf(b - e)) for e in (1e-7, 1e-10))
                    scale = 1e-12 * max(1.0, abs(wf(b)))
                if np.isfinite(d1) and np.isfinite(d2):
                    assert d2 <= 0.01 * d1 + scale, (wf, b, d1, d2)
                    kinks += 1
        if isinstance(wf, Table) and wf.linear:
            for b in jmp:
                assert abs(wf(b + 1e-9) - wf(b - 1e-9)) > 1e-3, (wf, b)
                jumps += 1
    assert kinks > 20 and jumps >= 2  # the examples have both


def test_waveform_jumps_of_tables():
    """A pwl table jumps only at a repeated time with another value, a steps table at every
    time; a periodic pwl cycle that ends on its first value is continuous at the boundary."""
    pwl = parse_waveform({"pwl": [["0 s", "1 mmHg"], ["1 s", "2 mmHg"], ["1 s", "5 mmHg"], ["2 s", "5 mmHg"],
                                  ["2 s", "5 mmHg"], ["3 s", "0 mmHg"]]}, "mmHg")
    assert pwl.jumps() == [1.0] and pwl.breakpoints() == [0.0, 1.0, 1.0, 2.0, 2.0, 3.0]
    steps = parse_waveform({"steps": [["0 s", "1 mmHg"], ["1 s", "2 mmHg"]]}, "mmHg")
    assert steps.jumps() == [0.0, 1.0]
    closed = parse_waveform({"periodic": {"period": "1 s", "pwl": [["0 s", "2 mmHg"], ["0.4 s", "7 mmHg"],
                                                                  ["1 s", "2 mmHg"]]}}, "mmHg")
    assert closed.jumps(0.0, 3.0) == [] and closed.breakpoints(0.0, 3.0) == [0.0, 0.4, 1.0, 1.4, 2.0, 2.4, 3.0]
    open_ = parse_waveform({"periodic": {"period": "1 s", "pwl": [["0 s", "2 mmHg"], ["0.4 s", "7 mmHg"],
                                                                 ["1 s", "3 mmHg"]]}}, "mmHg")
    assert open_.jumps(0.0, 3.0) == [0.0, 1.0, 2.0, 3.0]
    short = parse_waveform({"periodic": {"period": "1 s", "pwl": [["0 s", "2 mmHg"], ["0.5 s", "3 mmHg"]]}}, "mmHg")
    assert short.jumps(0.0, 2.0) == [0.0, 0.5, 1.0, 1.5, 2.0]  # held at 3 mmHg, back to 2 at each cycle


def test_waveform_record_format():
    rec = kw.encode(parse_waveform({"steps": [["0 s", "80 mmHg"], ["10 s", "72 mmHg"]]}, "mmHg"))
    assert rec.tolist() == [kw.STEPS, 7, 2, 0.0, 10.0, 80.0, 72.0]
    rec = kw.encode(Sum([Constant(2.0), Sine(1.0, 2.0, 3.0, 4.0, 5.0)]))
    assert rec.tolist() == [kw.SUM, 13, 2, kw.CONSTANT, 3, 2.0, kw.SINE, 7, 1.0, 2.0, 3.0, 4.0, 5.0]
    with pytest.raises(TypeError):
        kw.encode(object())
    deep = Constant(1.0)
    for _ in range(kw.MAX_SUM_DEPTH + 1):
        deep = Sum([deep, Constant(1.0)])
    with pytest.raises(ValueError, match="nested"):
        kw.encode(deep)
    ok = Constant(1.0)
    for _ in range(kw.MAX_SUM_DEPTH):
        ok = Sum([Constant(0.5), ok])
    assert kw.wave_value(kw.encode(ok), 0, 0.0) == ok(0.0)


# =========================================================== expressions =====================

def _netlist_expressions():
    out = []
    for name in ("inertia.yaml", "payne06_no_transport.yaml", "payne06_no_transport_thesis.yaml"):
        els = parse_netlist(load_netlist(str(ROOT / "netlists" / name)))
        by_id = {e.id: e for e in els}
        for e in els:
            for pname, ex in e.expressions.items():
                out.append((f"{name}:{e.id}.{pname}", ex, by_id))
    return out


class Slots:
    """A caller's slot map: param references into P, observables into O."""

    def __init__(self):
        self.index = {}

    def __call__(self, ref):
        kind = "param" if ref.kind == "param" else "obs"
        key = (kind, ref.element, ref.name)
        if key not in self.index:
            self.index[key] = sum(1 for k in self.index if k[0] == kind)
        return kind, self.index[key]


def _random_values(ex, slots, rng, by_id=None, n=0):
    """(values for evaluate, P, O) with P/O holding the same numbers at the slot indices."""
    P = np.full(64, np.nan)
    O = np.full(64, np.nan)
    vals = {}
    for key, ref in ex.refs.items():
        if ref.kind == "constant":
            continue
        base = 1.0
        if by_id is not None and ref.kind == "param":
            base = float(by_id[ref.element].values[ref.name])
        v = base * np.exp(rng.uniform(-2.0, 2.0)) if n % 3 else rng.uniform(-3.0, 3.0) * base
        if n % 7 == 6 and rng.random() < 0.5:
            v = 0.0  # divisions by zero, log(0): inf and NaN as numpy gives them
        kind, i = slots(ref)
        (P if kind == "param" else O)[i] = v
        vals[key] = np.array([v])
    return vals, P, O


def _check(ex, rng, by_id=None, draws=40):
    slots = Slots()
    code, consts = kx.encode(ex, slots)
    assert code.dtype == np.int64 and consts.dtype == np.float64 and code[-1] == kx.OP_END
    for n in range(draws):
        vals, P, O = _random_values(ex, slots, rng, by_id, n)
        with np.errstate(all="ignore"):
            ref = float(np.asarray(ex.evaluate(vals)).reshape(-1)[0])
        got = kx.eval_expr(code, 0, consts, 0, P, O)
        close(got, ref, rtol=1e-14)
    return code, consts


@pytest.mark.parametrize("label,ex,by_id", _netlist_expressions(), ids=lambda v: v if isinstance(v, str) else "")
def test_netlist_expressions(label, ex, by_id):
    code, consts = _check(ex, np.random.default_rng(7), by_id)
    if all(r.kind == "constant" for r in ex.refs.values()):
        assert code.tolist() == [kx.OP_CONST, 0, kx.OP_END]  # folded to one number
        assert consts[0] == ex.evaluate({})


def test_inertia_expression_value():
    """L = rho_b l / (pi r^2 n) by hand, in mmHg*s^2/mL (the unit factors are applied)."""
    (label, ex, _), = [c for c in _netlist_expressions() if c[0].startswith("inertia")]
    slots = Slots()
    code, consts = kx.encode(ex, slots)
    P, O = np.zeros(4), np.zeros(4)
    P[slots.index[("param", "art", "L")]] = 1e-3  # m
    P[slots.index[("param", "art", "n")]] = 200.0
    O[slots.index[("obs", "art", "r")]] = 25.0  # um
    L_si = 1060.0 * 1e-3 / (np.pi * (25e-6) ** 2 * 200.0)  # kg/m^4 = Pa s^2/m^3
    close(kx.eval_expr(code, 0, consts, 0, P, O), L_si * 1e-6 / 133.322387415, rtol=1e-9)


WHERE = {"file": None, "element": "t"}
UNITS = {"a.x": ("mmHg", "param"), "b.y": ("mmHg", "observable"), "a.k": ("1/s", "param"),
         "b.t": ("s", "observable"), "a.n": ("dimensionless", "param"), "b.m": ("dimensionless", "observable"),
         "a.p": ("kPa", "param"), "a.r": ("um", "param"), "a.L": ("mm", "param"), "b.V": ("mL", "observable")}
CONSTS = {"c0": "2 mmHg", "c1": "60 mL", "rho": "1.06 kg/L", "zero": "0"}


def _resolve(elem, attr):
    if elem is None:
        return constant_reference(attr, CONSTS[attr], WHERE)
    unit, kind = UNITS[f"{elem}.{attr}"]
    return Reference(elem, attr, unit, kind)


DIRECT = [
    ("= -a.x + +b.y * 2", "mmHg"),
    ("= a.p * 1000 / b.m", "mmHg"),
    ("= a.p", "Pa"),
    ("= -(-(a.x))", "kPa"),
    ("= exp(-a.k * b.t) * sqrt(a.x**2 + b.y**2) - log(a.n / 3) * c0", "mmHg"),
    ("= a.n ** 0.5 ** 2 + 2 ** -a.n - b.m ** 3", "dimensionless"),
    ("= (a.x - b.y) / (a.x + b.y) * c0", "mmHg"),
    ("= 97/3 * 4/3 * c1", "mL"),
    ("= 3**(1/3) * c1 + b.V", "L"),
    ("= pi * a.r**2 * a.L", "mL"),
    ("= rho * a.L / (pi * a.r**2 * a.n)", "mmHg*s**2/mL"),
    ("= (a.n - 2) ** 1.5 + sqrt(b.m - 1) + log(b.m)", "dimensionless"),
    ("= a.n / b.m - log(b.m) + b.m ** -1.0", "dimensionless"),
    ("= exp(a.n * 300) * b.m", "dimensionless"),
    ("= 2 * a.x + 1e-3 * a.p * (1 / c0) * c0 - exp(0) * b.y", "mmHg"),
    ("= ((((a.n + b.m) * a.n - b.m) / a.n + 1) ** 2 - (b.m - (a.n - (b.m - (a.n - 1)))))", "dimensionless"),
    ("= zero * a.n + 4", "dimensionless"),
    ("= a.n * 1 / 0.5 + +a.n - -b.m", "dimensionless"),
]


@pytest.mark.parametrize("text,unit", DIRECT)
def test_direct_expressions(text, unit):
    ex = Expression(text, unit, _resolve, WHERE)
    _check(ex, np.random.default_rng(len(text)), draws=200)


def test_expression_after_pickling_and_concatenation():
    exprs = [Expression(t, u, _resolve, WHERE) for t, u in DIRECT]
    exprs = [pickle.loads(pickle.dumps(ex)) for ex in exprs]  # as sent to worker processes
    slots = Slots()
    programs = [kx.encode(ex, slots) for ex in exprs]
    code, consts, c0, k0 = kx.concat(programs)
    rng = np.random.default_rng(3)
    for _ in range(20):
        P, O = rng.uniform(0.1, 4.0, 64), rng.uniform(0.1, 4.0, 64)
        for j, ex in enumerate(exprs):
            vals = {}
            for key, ref in ex.refs.items():
                if ref.kind != "constant":
                    kind, i = slots(ref)
                    vals[key] = np.array([(P if kind == "param" else O)[i]])
            with np.errstate(all="ignore"):
                ref = float(np.asarray(ex.evaluate(vals)).reshape(-1)[0])
            close(kx.eval_expr(code, c0[j], consts, k0[j], P, O), ref, rtol=1e-14)
            # and alone, the same program
            assert (kx.eval_expr(programs[j][0], 0, programs[j][1], 0, P, O)
                    == kx.eval_expr(code, c0[j], consts, k0[j], P, O)) or np.isnan(ref)


def test_circuits_with_expression_constants_pickle_without_pint():
    """A circuit sent to a worker process carries no pint object: the first pint quantity a
    process unpickles builds pint's application registry (measured 1.56 s per worker for the
    vasomotion circuit, whose inertia expression reads the constant rho_b).  The unpickled
    circuit evaluates as the original, and the load-time dimension check still has the
    constant as a quantity."""
    import hemocircuit as hc

    c = hc.load(ROOT / "netlists" / "vasomotion.yaml")
    ref = constant_reference("rho_b", "1060 kg/m^3", WHERE)
    assert ref.pint.to("g/cm^3").magnitude == pytest.approx(1.06, rel=1e-12)
    blob = pickle.dumps(c.batch(2))
    assert b"pint" not in blob
    c2 = pickle.loads(blob)
    from hemocircuit.analyses.op import operating_point
    x = np.tile(np.asarray(operating_point(c).x, float) * 1.01, (2, 1))  # off the equilibrium
    f = c.batch(2).rhs(0.0, x)
    assert np.all(np.isfinite(f)) and np.any(f != 0)
    np.testing.assert_array_equal(c2.rhs(0.0, x), f)


def test_expression_stack_limit():
    deep = "= " + "(a.n + " * kx.MAX_STACK + "a.n" + ")" * kx.MAX_STACK
    with pytest.raises(kx.ExpressionTooDeep, match="stack"):
        kx.encode(Expression(deep, "dimensionless", _resolve, WHERE), Slots())
    fits = "= " + "(a.n + " * (kx.MAX_STACK - 1) + "a.n" + ")" * (kx.MAX_STACK - 1)
    _check(Expression(fits, "dimensionless", _resolve, WHERE), np.random.default_rng(0), draws=5)
    long_left = "= " + " + ".join(["a.n * b.m"] * 200)  # long but shallow
    _check(Expression(long_left, "dimensionless", _resolve, WHERE), np.random.default_rng(0), draws=5)


def test_expression_slot_errors():
    ex = Expression("= a.x * 2", "mmHg", _resolve, WHERE)
    with pytest.raises(ValueError, match="kind"):
        kx.encode(ex, lambda ref: ("state", 0))
    seen = []
    kx.encode(Expression("= a.x * a.x / b.y + c0 + b.y", "mmHg", _resolve, WHERE),
              lambda ref: seen.append(ref.element + "." + ref.name) or ("param", len(seen)))
    assert seen == ["a.x", "b.y"]  # once per reference, constants never asked for


def test_lazy_kernels_pickle_by_name():
    """A lazy kernel (hemocircuit.kernels.jit) survives pickling as the same object, so
    circuits and kernels can be sent to worker processes."""
    from hemocircuit.components.resistor import kernel_stamp

    assert pickle.loads(pickle.dumps(kernel_stamp)) is kernel_stamp


def test_pwl_tables_kink_only_where_the_slope_changes():
    """An interior time between two intervals of the same slope (a run of equal values, a
    straight ramp) is no breakpoint; the ends, repeated times and slope changes are, also in
    every cycle of a periodic table (svZeroDSolver's inlet pressure: zero after 0.18 s)."""
    pwl = parse_waveform({"pwl": [["0 s", "0 mmHg"], ["1 s", "1 mmHg"], ["2 s", "2 mmHg"], ["3 s", "0 mmHg"],
                                  ["4 s", "0 mmHg"], ["5 s", "0 mmHg"], ["5 s", "3 mmHg"], ["6 s", "3 mmHg"]]},
                         "mmHg")
    assert pwl.breakpoints() == [0.0, 2.0, 3.0, 5.0, 5.0, 6.0]
    t = np.linspace(-1.0, 7.0, 801)
    assert np.array_equal(pwl.sample(t), np.interp(t, pwl.times, pwl.values))  # values unchanged
    per = parse_waveform({"periodic": {"period": "1 s", "pwl": [["0 s", "0 mmHg"], ["0.1 s", "4 mmHg"],
                                                                ["0.2 s", "0 mmHg"], ["0.5 s", "0 mmHg"],
                                                                ["1 s", "0 mmHg"]]}}, "mmHg")
    assert per.breakpoints(0.0, 2.0) == pytest.approx([0.0, 0.1, 0.2, 1.0, 1.1, 1.2, 2.0])
