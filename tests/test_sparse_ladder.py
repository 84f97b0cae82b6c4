"""The sparse path for large circuits (hemocircuit.sparse): a ladder of resistor +
log-compliance segments against its closed-form operating point, sparse against dense
transients, mass balance, and the sparse path forced onto the small shipped netlists.

Ladder (benchmarks/ladder.py): Pa -> R_1 -> n1 -> R_2 -> ... -> nN -> R_out -> Pv, with a log
compliance C_i from every n_i to ground.  With a constant source no store fills in the steady
state, so every node pressure follows from the series resistor chain and every volume from
the log law V = Vn + ln(dP - P0)/k.
"""
import importlib.util
import inspect

import numpy as np
import pytest
from scipy.integrate import cumulative_simpson

import hemocircuit as hc
from hemocircuit import sparse as sparse_la
from hemocircuit.analyses.transient import simulate
from hemocircuit.derivatives import fd_steps

from paths import ROOT

_spec = importlib.util.spec_from_file_location("ladder", ROOT / "benchmarks" / "ladder.py")
ladder_mod = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(ladder_mod)

# the compiled engine (small circuits) is not what these tests compare
SCIPY = {"engine": "scipy"} if "engine" in inspect.signature(simulate).parameters else {}


def ladder(write, N, **kw):
    return hc.load(write(ladder_mod.ladder_yaml(N, **kw), f"ladder{N}.yaml"))


def test_ladder_operating_point_closed_form(write):
    N = 200
    c = ladder(write, N, amplitude=0.0)
    assert c.sparse and c.n == 2 * N + 4 and c.nx == N
    op = c.operating_point()
    L = ladder_mod
    r = L.R_TOTAL / N
    Q = (L.PA - L.PV) / (L.R_TOTAL + L.R_OUT)  # series chain
    P = L.PA - Q * r * np.arange(N + 1)  # P(n_i), i = 0..N
    k, vn = L.K_TOTAL * N, L.VN_TOTAL / N
    V = vn + np.log(P[1:] - L.P0) / k
    got_P = np.array([op[f"P(n{i})"] for i in range(N + 1)])
    got_V = np.array([op[f"V(C_{i})"] for i in range(1, N + 1)])
    np.testing.assert_allclose(got_P, P, rtol=1e-11)
    np.testing.assert_allclose(got_V, V, rtol=1e-9)
    np.testing.assert_allclose([op[f"Q(R_{i})"] for i in range(1, N + 1)], Q, rtol=1e-9)
    assert op["Q(R_out)"] == pytest.approx(Q, rel=1e-9)
    assert op["P(nv)"] == pytest.approx(L.PV, rel=1e-12)
    assert max(abs(op[f"Q(C_{i})"]) for i in range(1, N + 1)) < 1e-9 * Q
    assert op.method == "newton"


def test_sparse_path_holds_no_dense_system(write):
    c = ladder(write, 200)
    assert c.sparse
    assert c.system.A_const.shape[1] < 20 * c.n  # values on the pattern, not (n+1)^2
    assert c.system.Ainv is None and c.system.lu.lus is not None
    x = np.atleast_2d(c.operating_point().x)[0]
    J = c.jacobian(0.0, x)
    assert J.shape == (c.nx, c.nx) and J.nnz <= 3 * c.nx  # tridiagonal
    plan = next(iter(c.system.jac_plans.values()))
    assert plan.how == "structural" and plan.ncolours == 3


def test_sparse_and_dense_transients_agree(write):
    N = 60  # 124 unknowns: the sparse path by default, the dense one forced
    cs = ladder(write, N)
    cd = ladder(write, N).with_sparse_threshold(10**9)
    assert cs.sparse and not cd.sparse
    kw = dict(dt=0.01, rtol=1e-8, **SCIPY)
    rs, rd = simulate(cs, 0.5, **kw), simulate(cd, 0.5, **kw)
    assert rs.stats["method"] == "BDF" and rs.stats["njev"] >= 1
    np.testing.assert_allclose(rs.x[0], rd.x[0], rtol=1e-12)  # the same operating point
    scale = np.max(np.abs(rd.x), axis=0)
    assert np.max(np.abs(rs.x - rd.x) / scale) < 1e-6
    # every output column, same names in the same order (the sparse path fills them vectorised)
    assert list(rs.columns) == list(rd.columns)
    for kind in ("P(", "V(", "C_"):
        cols = [k for k in rd.columns if k.startswith(kind)]
        big = max(np.max(np.abs(rd[k])) for k in cols)
        assert max(np.max(np.abs(rs[k] - rd[k])) for k in cols) <= 1e-6 * big, kind
    # flows on the same states: a compliance's flow is the difference of its neighbours' (~17
    # mL/s each), so between two runs it carries the runs' state difference (~3e-9) amplified
    # ~1e3 (1.2e-6 of the largest flow with scipy 1.17), which says nothing of how each path
    # fills the columns; on equal states the two paths agree to rounding
    qs, qd = cs.outputs(rs.t, rs.x), cd.outputs(rs.t, rs.x)
    cols = [k for k in rd.columns if k.startswith("Q(")]
    big = max(np.max(np.abs(rd[k])) for k in cols)
    assert max(np.max(np.abs(qs[k] - qd[k])) for k in cols) <= 1e-12 * big
    assert all(np.array_equal(rs[k], qs[k]) for k in cols)  # the result's columns are these outputs
    # the Jacobians themselves: coloured sparse = dense column by column.  A structural zero of
    # the dense forward difference (f(x + h_j e_j) - f(x)) / h_j is rounding: a few ulp of the
    # terms that cancel in f_i (size sum_k |J_ik x_k|) over h_j (hemocircuit.derivatives.fd_steps);
    # the coloured one has exactly 0 there.
    x = rd.x[-1]
    Js, Jd = cs.jacobian(0.3, x).toarray(), cd.jacobian(0.3, x)
    h = fd_steps(x[None], cd.state_scales)[0]
    rounding = 4 * np.finfo(float).eps * (np.abs(Jd) @ np.abs(x))[:, None] / h[None, :]
    assert np.all(np.abs(Js - Jd) <= 1e-5 * np.abs(Jd) + 1e-6 + rounding)
    assert np.count_nonzero(Js) >= 3 * cs.nx - 2  # the tridiagonal is there (not all zero)


def test_ladder_mass_balance(write):
    """Sum of the stored volumes changes by the integrated net inflow Q(R_1) - Q(R_out)."""
    N = 200
    c = ladder(write, N)
    res = simulate(c, 1.0, dt=1e-3, rtol=1e-9, **SCIPY)
    # past the first microseconds (fast segment modes, steeper than the output grid)
    sel = res.t >= 0.1
    t = res.t[sel]
    V = sum(res[f"V(C_{i})"][sel] for i in range(1, N + 1))
    net = res["Q(R_1)"][sel] - res["Q(R_out)"][sel]
    inflow = cumulative_simpson(net, x=t, initial=0.0)
    swing = np.ptp(V)
    assert swing > 1e-2  # the sine really moves volume in and out
    assert np.max(np.abs((V - V[0]) - inflow)) < 1e-5 * swing  # seen: 5e-7 (integrator tolerance)
    # and node by node (KCL): each store fills with the difference of its resistor flows
    Q = np.array([res[f"Q(R_{i})"] for i in range(1, N + 1)] + [res["Q(R_out)"]])
    Qc = np.array([res[f"Q(C_{i})"] for i in range(1, N + 1)])
    assert np.max(np.abs(Qc - (Q[:-1] - Q[1:]))) < 1e-9 * np.max(np.abs(Q))


@pytest.mark.parametrize("name", ["payne06.yaml", "vasomotion.yaml", "two_generations.yaml", "icp.yaml"])
def test_forced_sparse_path_matches_dense(name):
    """The shipped (small) circuits through the sparse path: same operating point, same
    Jacobian, and a structural pattern that holds every numerically nonzero entry."""
    path = ROOT / "netlists" / name
    cd = hc.load(str(path))
    cs = hc.load(str(path)).with_sparse_threshold(0)
    assert cs.sparse and not cd.sparse
    opd, ops = cd.operating_point(), cs.operating_point()
    np.testing.assert_allclose(ops.x, opd.x, rtol=1e-9, atol=1e-12)
    x = np.atleast_2d(opd.x)[0]
    Jd, Js = cd.jacobian(0.0, x), cs.jacobian(0.0, x).toarray()
    np.testing.assert_allclose(Js, Jd, rtol=1e-5, atol=1e-7 * np.max(np.abs(Jd)))
    struct = next(p for k, p in cs.system.jac_plans.items() if k[0] == "rhs")
    numer = cs.jacobian_plan("rhs", lambda r: cs.evaluate(0.0, r), x, how="numerical")
    S = struct.pattern.matrix(np.ones(struct.nnz)).toarray() > 0
    Nm = numer.pattern.matrix(np.ones(numer.nnz)).toarray() > 0
    assert not np.any(Nm & ~S)
    assert np.all(Js[~S] == 0)


def test_colouring_groups_share_no_row():
    rng = np.random.default_rng(1)
    import scipy.sparse as sp
    P = sp.random(80, 80, density=0.05, random_state=rng, format="csc") + sp.identity(80)
    groups, k = sparse_la.greedy_colouring(P)
    D = (P.toarray() != 0)
    for g in range(k):
        assert np.all(D[:, groups == g].sum(axis=1) <= 1)


NONLINEAR = """
elements:
  - {id: Ps, type: pressure_source, nodes: [in, ground], value: 50 mmHg, amplitude: 5 mmHg, frequency: 1 Hz}
  - {id: Rq, type: test_quadratic_resistor, nodes: [in, a], K: 2 mmHg*s**2/mL**2}
  - {id: C1, type: compliance, nodes: [a, ground], C: 0.1 mL/mmHg}
  - {id: R, type: resistor, nodes: [a, b], R: 3 mmHg*s/mL}
  - {id: C2, type: log_compliance, nodes: [b, ground], k: 0.5 1/mL, P0: -2 mmHg, Vn: 3 mL}
  - {id: R2, type: resistor, nodes: [b, ground], R: 1 mmHg*s/mL}
"""


def test_sparse_path_with_state_dependent_matrix(write):
    """An element nonlinear in the pressures (Newton on the nodal equations, the matrix
    assembled and factorised per evaluation): forced sparse = dense."""
    from hemocircuit.registry import component_types
    from test_nonlinear_pressure import QuadraticResistor

    types = component_types()
    types[QuadraticResistor.type_name] = QuadraticResistor
    try:
        path = write(NONLINEAR)
        cd, cs = hc.load(str(path)), hc.load(str(path)).with_sparse_threshold(0)
        np.testing.assert_allclose(cs.operating_point().x, cd.operating_point().x, rtol=1e-12)
        kw = dict(dt=0.01, rtol=1e-9, **SCIPY)
        rs, rd = simulate(cs, 1.0, **kw), simulate(cd, 1.0, **kw)
        assert np.max(np.abs(rs.x - rd.x)) < 1e-8 * np.max(np.abs(rd.x))
    finally:
        types.pop(QuadraticResistor.type_name)


def test_sparse_batch_members_match_single_runs(write):
    path = write(ladder_mod.ladder_yaml(80, amplitude=0.0))
    cb = hc.load(str(path)).batch(3)
    cb = cb.with_values({"Pa.value": np.array([70.0, 80.0, 90.0])})
    cb = cb.with_values({"R_5.R": np.array([0.04, 0.05, 0.06])})
    assert cb.sparse
    op = cb.operating_point()
    for k, (pa, r) in enumerate([(70.0, 0.04), (80.0, 0.05), (90.0, 0.06)]):
        ci = hc.load(str(path))
        ci = ci.with_values({"Pa.value": pa, "R_5.R": r})
        np.testing.assert_allclose(op.x[k], ci.operating_point().x, rtol=1e-12)
    Js = cb.jacobian(0.0, op.x)
    assert len(Js) == 3 and Js[0].shape == (80, 80)
