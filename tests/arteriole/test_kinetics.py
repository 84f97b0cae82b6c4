"""4-state kinetics (eqs 4state, 4stateCons, phos, dephos, 4stateSS) and figure figrPhospCa."""
import numpy as np

from element_calls import observed


def _linear_solve(K1, K2, p, eq):
    """Eq 4stateSS solved as in the thesis: the rate matrix of eq 4state (its columns from
    equations.kinetics at unit fractions) with the last row replaced by eq 4stateCons, batched
    np.linalg.solve -> (..., 4) fractions (M, Mp, AMp, AM); the reference of the closed form."""
    K1, K2 = np.broadcast_arrays(np.asarray(K1, dtype=float), np.asarray(K2, dtype=float))
    cols = [eq.kinetics(K1, K2, *(np.full(K1.shape, float(i == k)) for i in range(4)), p) for k in range(4)]
    A = np.stack([np.stack(np.broadcast_arrays(*c), axis=-1) for c in cols], axis=-1)
    A[..., 3, :] = 1.0
    rhs = np.zeros(A.shape[:-1])
    rhs[..., 3] = 1.0
    return np.linalg.solve(A, rhs[..., None])[..., 0]


def _grid():
    Ca = np.logspace(-12, -3, 37)[:, None]
    cG = np.concatenate([[0.0], np.logspace(-11, -4, 15)])[None, :]
    return Ca, cG


def test_quasi_steady_sums_to_one_and_is_null_vector(art, kuo):
    Ca, cG = _grid()
    eq, p = art.equations, art.equations.vector(kuo)
    K = eq.rates(Ca, cG, p, False)
    alpha = np.stack(np.broadcast_arrays(*eq.quasi_steady(*K, p)), axis=-1)
    assert alpha.shape == (37, 16, 4)
    assert np.all(alpha >= 0)
    np.testing.assert_allclose(alpha.sum(-1), 1.0, rtol=0, atol=1e-14)
    # the rates of eq 4state vanish there (the kinetics' right-hand side, as the element runs it)
    d = np.stack(np.broadcast_arrays(*eq.kinetics(*K, *np.moveaxis(alpha, -1, 0), p)), -1)
    assert np.max(np.abs(d)) < 1e-12
    # conservation (eq 4stateCons): the rates sum to zero at any fractions
    rng = np.random.default_rng(3)
    a = rng.random((37, 16, 4))
    np.testing.assert_allclose(sum(eq.kinetics(*K, *np.moveaxis(a, -1, 0), p)), 0.0, atol=1e-14)


def test_closed_form_equals_linear_solve(art, kuo):
    Ca, cG = _grid()
    p = art.equations.vector(kuo)
    K = art.equations.rates(Ca, cG, p, False)
    closed = np.stack(np.broadcast_arrays(*art.equations.quasi_steady(*K, p)), axis=-1)
    solved = _linear_solve(*K, p, art.equations)
    np.testing.assert_allclose(closed, solved, rtol=1e-10, atol=1e-14)


def test_closed_form_with_other_rate_values(art, kuo):
    """Random K3, K4, K7 (not the tab4State values): the closed form is general."""
    rng = np.random.default_rng(1)
    p = dict(kuo, K3=rng.uniform(0.01, 2, 50), K4=rng.uniform(0.01, 2, 50),
             K7=rng.uniform(0.001, 1, 50))
    p = art.equations.vector(p)
    K = art.equations.rates(rng.uniform(1e-9, 1e-5, 50), rng.uniform(0, 1e-6, 50), p, False)
    closed = np.stack(art.equations.quasi_steady(*K, p), axis=-1)
    np.testing.assert_allclose(closed, _linear_solve(*K, p, art.equations), rtol=1e-10, atol=1e-14)


def test_rates_at_nonpositive_ca_are_finite(art, kuo):
    K = art.equations.rates(np.array([-1e-6, 0.0, art.CA_FLOOR]), 1e-9, art.equations.vector(kuo), False)
    assert all(np.all(np.isfinite(k)) for k in K)
    np.testing.assert_allclose(K[0][:2], K[0][2])  # clipped at the floor


def test_passive_alpha_and_zero_active_force(art, kuo):
    eq, p = art.equations, art.equations.vector(kuo)
    K = eq.rates(np.array([1e-7, 1e-5]), np.array([1e-9, 1e-7]), p, True)
    alpha = np.stack(np.broadcast_arrays(*eq.quasi_steady(*K, p)), -1)
    np.testing.assert_array_equal(alpha, [[1, 0, 0, 0], [1, 0, 0, 0]])
    lam = np.array([0.9, 1.4])
    assert np.all(eq.active_force(0.0, alpha[:, 2], alpha[:, 3], eq.overlap(lam, p), p) == 0)
    # through the element: passive states give alpha = [1,0,0,0] and F_a = 0 whatever Ca is
    s = {"Ca": np.array([1e-7, 1e-6]), "Cw": 1e-8, "lambda": 1.2}
    obs = observed(art, s, 8000.0, 0.0, kuo, {"passive": True})
    np.testing.assert_array_equal(np.broadcast_to(obs["M"], (2,)), 1.0)
    np.testing.assert_array_equal(obs["F_a"], 0.0)


def test_lee97_phosphorylation_curves(art, kuo):
    from hemocircuit.reproduce.ch4_lee97 import phosphorylation_curves

    Ca, cG, phos = phosphorylation_curves(kuo)
    assert phos.shape == (6, 81)
    assert np.all(np.diff(phos, axis=1) > 0)          # rises with Ca
    assert np.all(np.diff(phos, axis=0) <= 1e-15)     # cGMP lowers it
    i = np.argmin(np.abs(np.log10(Ca) + 6))           # at Ca = 1 uM cGMP matters
    assert phos[0, i] - phos[-1, i] > 0.05
    assert phos[0, -1] - phos[-1, -1] < 0.5 * (phos[0, i] - phos[-1, i])  # curves converge
