"""The arteriole kernel's analytic partials (compiled.derivs_jac, the engine's element-local
Jacobian) against central differences of its own ``derivs``, on every option combination and
the random samples of test_compiled.py (pressures with dP = 0 and reversed flow, the series
branch of psi, perturbed steady states).  ``dx`` must be ``derivs``' bit for bit; the partials
within what a central difference can tell (relative 1e-6 of the row's scale).  A passive
arteriole returns 0 (the engine differences ``derivs`` then).
"""
import numpy as np
import pytest

from test_compiled import COMBOS, _param_vectors, _setup

numba = pytest.importorskip("numba")


def _central(fn, v, k, h):
    vp, vm = v.copy(), v.copy()
    vp[k] += h
    vm[k] -= h
    return (fn(vp) - fn(vm)) / (vp[k] - vm[k])


@pytest.mark.parametrize("combo", COMBOS, ids=["-".join(map(str, c)) for c in COMBOS])
def test_partials_match_central_differences(art, combo):
    el, p, x, u = _setup(art, combo, 11)
    k, io = el.kernel(), el.kernel_options()
    pv = _param_vectors(el, p)
    S, L = x.shape[2], u.shape[2]
    passive = combo[3]
    checked = 0
    for i in range(x.shape[1]):
        xi, ui = np.ascontiguousarray(x[0, i]), np.ascontiguousarray(u[0, i])
        dx, Jx, Ju = np.zeros(S), np.full((S, S), np.nan), np.full((S, L), np.nan)
        got = k.derivs_jac(pv[i], xi, ui, 0.0, io, dx, Jx, Ju)
        if passive:
            assert got == 0
            continue
        assert got == 1
        ref = np.zeros(S)
        k.derivs(pv[i], xi, ui, 0.0, io, ref)
        np.testing.assert_array_equal(dx, ref)

        def f_x(v):
            out = np.zeros(S)
            k.derivs(pv[i], v, ui, 0.0, io, out)
            return out

        def f_u(v):
            out = np.zeros(S)
            k.derivs(pv[i], xi, v, 0.0, io, out)
            return out

        FDx = np.stack([_central(f_x, xi, c, 1e-6 * max(abs(xi[c]), 1e-9)) for c in range(S)], axis=1)
        FDu = np.stack([_central(f_u, ui, c, 1e-6 * max(abs(ui[c]), 1.0)) for c in range(L)], axis=1)
        # each row's scale: its largest |partial x typical state size| (the columns of states as
        # small as Ca ~1e-7 M and as large as lambda ~1 differ by 1e7)
        xs = np.maximum(np.abs(xi), 1e-12)
        scale_x = np.max(np.abs(FDx) * xs[None, :], axis=1, keepdims=True) + 1e-300
        scale_u = np.max(np.abs(FDu), axis=1, keepdims=True) + np.max(np.abs(FDx) * xs[None, :], axis=1,
                                                                     keepdims=True) * 1e-3 + 1e-300
        assert np.all(np.abs(Jx - FDx) * xs[None, :] <= 1e-6 * scale_x), (combo, i, Jx, FDx)
        assert np.all(np.abs(Ju - FDu) <= 1e-6 * scale_u), (combo, i, Ju, FDu)
        checked += 1
    assert passive or checked == x.shape[1]
