"""The compiled engine's layout in files (hemocircuit.kernels.codegen): the template files in
their order, the functions shared with importable modules (one LU in hemocircuit.linalg, the
dense output in kernels.dense, the end of a run in kernels.runs), named scratch buffers and
method fields instead of numbered slots, and module sizes."""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

import hemocircuit
from hemocircuit import batch_integrator, linalg
from hemocircuit.kernels import codegen, dense, freshness, tableaus
from hemocircuit.registry import component_types

PKG = Path(hemocircuit.__file__).parent
KERNELS = PKG / "kernels"


def _resistor_kernels():
    return [component_types()["resistor"]().kernel()]


def test_the_generated_module_is_the_header_then_the_template_files_in_order():
    src = codegen.source(_resistor_kernels())
    starts = [src.index(f"# {'-' * 64} {name}\n") for name in codegen.TEMPLATES]
    assert starts == sorted(starts) and starts[0] > src.index("def elem_stamp(")
    for name in codegen.TEMPLATES:  # each file whole, as it is on disk
        assert (KERNELS / name).read_text().rstrip("\n") in src
    compile(src, "engine", "exec")  # one valid module


def test_the_freshness_key_covers_every_engine_source():
    names = {f.name for f in freshness.sources()}
    assert set(codegen.TEMPLATES) <= names
    for module, _ in codegen.SHARED:  # the shared compiled functions' files
        assert Path(__import__(module, fromlist=["_"]).__file__).name in names


def test_no_numbered_work_slots():
    """The scratch buffers (Work, JacWork), the layout (EngineLayout) and the method
    (RosenbrockMethod) are read by name in the engine."""
    pattern = re.compile(r"\b(work|jw|lay|tab|meta)\[\s*\d")
    for f in sorted(KERNELS.glob("*.py")):
        hits = [i + 1 for i, line in enumerate(f.read_text().splitlines()) if pattern.search(line)]
        assert not hits, (f.name, hits)


def test_no_engine_module_over_800_lines():
    """The kernels package (the template files among them) and the linear algebra."""
    for f in [*sorted(KERNELS.glob("*.py")), PKG / "linalg.py"]:
        assert len(f.read_text().splitlines()) <= 800, f


def test_the_scratch_buffers_are_named_tuples_of_arrays():
    from hemocircuit.kernels.layout import EngineLayout

    pytest.importorskip("numba")
    from hemocircuit.kernels.system import CompiledSystem

    c = hemocircuit.load(str(PKG.parent / "netlists" / "payne06.yaml"))
    system = CompiledSystem.of(c)
    fields = system.layout.fields
    assert isinstance(fields, EngineLayout) and fields.n == c.n
    assert all(a is b for a, b in zip(fields, system.lay))
    work = system.mod.make_work.py_func(system.lay)
    jw = system.mod.make_jac_work.py_func(system.lay)
    for buffers in (work, jw):
        assert hasattr(buffers, "_fields") and all(isinstance(getattr(buffers, f), np.ndarray)
                                                   for f in buffers._fields)
    assert work.A.shape == (c.n + 1, c.n + 1) and work.condensed.shape == (1,)
    # the engine binds the shared functions' numba dispatchers: one definition
    assert system.mod.lu_factor is linalg.lu_factor.dispatcher
    assert system.mod.hermite is dense.hermite.dispatcher


def test_one_lu_batched_solve():
    """solve_batched's compiled path (linalg._solve_nb: lu_factor and lu_apply, the engine's LU)
    against numpy; singular rows NaN."""
    pytest.importorskip("numba")
    rng = np.random.default_rng(3)
    A = rng.normal(size=(80, 7, 7)) + 4 * np.eye(7)
    b = rng.normal(size=(80, 7))
    A[3] = 0.0
    A[5, :, 2] = 0.0
    u = linalg.solve_batched(A, b)
    assert np.isnan(u[3]).all() and np.isnan(u[5]).all()
    ok = np.ones(80, bool)
    ok[[3, 5]] = False
    ref = np.linalg.solve(A[ok], b[ok][..., None])[..., 0]
    np.testing.assert_allclose(u[ok], ref, rtol=1e-10, atol=1e-12)


def test_the_hermite_equations_are_the_batch_integrators_bit_for_bit():
    """kernels.dense's Hermite basis and crossing, run on numpy arrays, give the numpy batch
    integrator's own _hermite and _hermite_root bit for bit (40 halvings there, 50 in the
    engine): they can replace that copy."""
    rng = np.random.default_rng(5)
    n, nx = 9, 4
    x0, f0, x1, f1 = (rng.normal(size=(n, nx)) for _ in range(4))
    h, s = rng.uniform(0.01, 2.0, n), rng.uniform(0.0, 1.0, n)
    a, b, c, d = dense.hermite_basis(s[:, None], h[:, None])
    assert np.array_equal(a * x0 + b * f0 + c * x1 + d * f1, batch_integrator._hermite(x0, f0, x1, f1, h, s))
    y0, y1 = rng.uniform(0.1, 1.0, n), -rng.uniform(0.0, 1.0, n)
    d0, d1 = rng.normal(size=n), rng.normal(size=n)
    ours = dense.hermite_crossing(y0, d0, y1, d1, np.zeros_like(y0), np.ones_like(y0), 40)
    assert np.array_equal(ours, batch_integrator._hermite_root(y0, d0, y1, d1))


def test_one_compiled_integrator_serves_every_method():
    """Every method and option packs to a RosenbrockMethod of the same numba type (so choosing
    one never recompiles), with read-only arrays (a cached packing is shared)."""
    numba = pytest.importorskip("numba")
    types = set()
    for name in tableaus.METHODS:
        for opts in ({}, {"autonomous": 1, "local_jacobian": 2, "controller": "pi", "jac_reuse": 3}):
            m = tableaus.packed(name, **opts)
            assert m.a.shape == (m.stages, m.stages) and m.H.shape[1] == m.stages
            assert not any(getattr(m, f).flags.writeable for f in ("a", "C", "m", "m_err", "c", "d", "reuse", "H"))
            types.add(numba.typeof(m))
    assert len(types) == 1, types


def test_transformed_coefficients_recover_the_sources_and_the_classical_step():
    """The engine's transformed coefficients (u = Gamma k) are RODAS5P's published ones (Steinebach
    2023: a_21 = 3, C_21 = -14.155..., C_87 = -9.4886...), and for every method one step of the
    transformed form on y' = lam y + cos(t) equals the classical form's step."""
    gamma, a, C, m, m_err, H = tableaus.transformed("rodas5p")
    assert a[1, 0] == pytest.approx(3.0, rel=1e-13)
    assert C[1, 0] == pytest.approx(-14.155112264123755, rel=1e-13)
    assert C[7, 6] == pytest.approx(-9.48861652309627, rel=1e-12)
    assert np.allclose(m[-2:], 1.0) and H.shape == (3, 8)
    lam, y0, t0, h = -3.0, 1.0, 0.2, 0.1
    f = lambda t, y: lam * y + np.cos(t)  # noqa: E731
    ft = lambda t: -np.sin(t)  # noqa: E731
    for name in tableaus.METHODS:
        g, A, G, b, e, _ = tableaus.classical(name)
        _, a, C, m, me, _ = tableaus.transformed(name)
        ns = len(b)
        c, d = A.sum(axis=1), g + G.sum(axis=1)
        W = 1.0 - g * h * lam
        k, u = np.zeros(ns), np.zeros(ns)
        for s in range(ns):
            k[s] = (h * f(t0 + c[s] * h, y0 + A[s, :s] @ k[:s]) + h * lam * (G[s, :s] @ k[:s])
                    + h * h * d[s] * ft(t0)) / W
            u[s] = g * (h * f(t0 + c[s] * h, y0 + a[s, :s] @ u[:s]) + C[s, :s] @ u[:s]
                        + h * h * d[s] * ft(t0)) / W
        assert y0 + m @ u == pytest.approx(y0 + b @ k, rel=1e-13), name
        assert me @ u == pytest.approx(e @ k, rel=1e-9, abs=1e-15), name
