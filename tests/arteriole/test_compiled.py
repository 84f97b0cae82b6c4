"""The arteriole's kernel functions (components/arteriole/compiled.py) compiled by numba against
the same functions run as Python (what the operating point and small batches run).

Every option combination (ca_order x kinetics x passive x volume_flow x pim_reference) and both
presets: random physiological parameters (presets perturbed, no_speed 0.5..200, some C_in > 0,
some short vessels so that the series branch of psi is taken), pressures (including dP = 0 and
reversed flow) and states (steady states at those pressures, perturbed); stamp, derivs, observe
and report must agree to rtol 1e-12.  ``test_detects_wrong_parameter`` shows that the
comparison would catch a wrong parameter.  The physics itself is checked against closed forms
and the thesis in the other files of this folder.

Run this file as a script for a micro-benchmark of one ``derivs`` call from an njit loop.
"""
import itertools

import numpy as np
import pytest

from hemocircuit.units import PA_PER_MMHG

numba = pytest.importorskip("numba")

RTOL = 1e-12
PRESET_NAMES = ("kuo91", "falcone91")
COMBOS = list(itertools.product(PRESET_NAMES, (1, 2), ("quasi_steady", "dynamic"), (False, True),
                                (False, True), ("gauge", "ref")))
N = 12  # samples per combination


@pytest.fixture(scope="module")
def compiled(art):
    import importlib
    return importlib.import_module(art.__name__ + ".compiled")


def _element(art, preset, ca_order, kinetics, passive, volume_flow, pim_reference):
    return art.Arteriole({"preset": preset, "ca_order": ca_order, "kinetics": kinetics, "passive": passive,
                          "volume_flow": volume_flow, "pim_reference": pim_reference})


def _params(art, preset, rng, n):
    """Parameter dict of (1, n) arrays: the preset, each value x (1 + 2 % noise), no_speed
    log-uniform 0.5..200 (1 for the first sample), C_in > 0 in some, short vessels in some,
    pCa_shift uniform in +-0.1."""
    base = art.PRESETS[preset]
    p = {k: np.full((1, n), float(v)) * (1.0 + 0.02 * rng.standard_normal((1, n))) for k, v in base.items()
         if k != "pCa_shift"}
    p["no_speed"] = np.exp(rng.uniform(np.log(0.5), np.log(200.0), (1, n)))
    p["no_speed"][0, 0] = 1.0
    p["C_in"] = np.where(rng.random((1, n)) < 0.5, rng.uniform(0.0, 3e-8, (1, n)), 0.0)
    p["L"][0, :3] = rng.uniform(1e-4, 2e-4, 3)   # high flow per unit length: psi series branch
    p["pCa_shift"] = rng.uniform(-0.1, 0.1, (1, n))  # drawn last: the other samples as before it existed
    return p


def _pressures(el, rng, n):
    """Local unknowns (1, n, L) [mmHg]: in, out, ref (, mid); sample 1 has dP = 0, sample 2
    reversed flow."""
    P_in = rng.uniform(40.0, 120.0, n)
    dP = rng.uniform(2.0, 40.0, n)
    dP[1] = 0.0
    dP[2] = -dP[2]
    P_out = P_in - dP
    P_ref = rng.uniform(-5.0, 15.0, n)
    cols = [P_in, P_out, P_ref]
    if el.opts["volume_flow"]:
        cols.append(P_out + rng.uniform(0.3, 0.7, n) * dP + rng.normal(0.0, 0.5, n))
    return np.stack(cols, axis=-1)[None]


def _states(art, el, p, u, rng):
    """Steady states at the pressures ``u`` (default states where none is found), perturbed."""
    x0 = el.default_states(p)
    x = el.initial_states(p, u)
    x = np.where(np.isfinite(x), x, x0)
    names = [s.name for s in el.states()]
    n = x.shape[1]
    s = {k: x[..., i].copy() for i, k in enumerate(names)}
    s["Ca"] *= np.exp(0.3 * rng.standard_normal((1, n)))
    s["Cw"] *= np.exp(0.3 * rng.standard_normal((1, n)))
    s["lambda"] *= 1.0 + 0.03 * rng.standard_normal((1, n))
    if "dCa" in s:
        s["dCa"] = 0.3 * p["omega_n"] * s["Ca"] * rng.standard_normal((1, n))
    if "M" in s:
        tot = 0.0
        for k in ("M", "Mp", "AMp", "AM"):
            s[k] = (s[k] + 0.05) * np.exp(0.3 * rng.standard_normal((1, n)))
            tot = tot + s[k]
        for k in ("M", "Mp", "AMp", "AM"):
            s[k] /= tot
    return np.stack([s[k] for k in names], axis=-1)


def _param_vectors(el, p):
    return np.ascontiguousarray(np.stack([p[k][0] for k in el.parameters], axis=-1))  # (n, P)


def _run_all(el, pv, x, u, t, compiled):
    """stamp, derivs, observe and report of every sample, compiled or as Python."""
    k = el.kernel()
    io = el.kernel_options()
    n, S = x.shape[1], x.shape[2]
    L = len(el.local_nodes) + len(el.branches())
    out = {"A": np.zeros((n, L, L)), "b": np.zeros((n, L)), "dx": np.zeros((n, S)),
           "obs": np.zeros((n, len(k.observables))), "report": np.zeros((n, len(el.observables())))}
    run = {f: (getattr(k, f).dispatcher if compiled else getattr(k, f).py_func)
           for f in ("stamp", "derivs", "observe", "report")}
    with np.errstate(all="ignore"):
        for i in range(n):
            xi, ui = np.ascontiguousarray(x[0, i]), np.ascontiguousarray(u[0, i])
            run["stamp"](pv[i], xi, ui, t, io, out["A"][i], out["b"][i])
            run["derivs"](pv[i], xi, ui, t, io, out["dx"][i])
            run["observe"](pv[i], xi, io, out["obs"][i])
            run["report"](pv[i], xi, ui, t, io, out["report"][i])
    return out


def _python_all(el, p, x, u, t):
    return _run_all(el, _param_vectors(el, p), x, u, t, compiled=False)


def _kernel_all(el, pv, x, u, t):
    return _run_all(el, pv, x, u, t, compiled=True)


def _mismatch(got, ref):
    """Largest |got - ref| / (RTOL |ref|) over all outputs (> 1: disagreement; exact zeros must
    be exact)."""
    worst = 0.0
    for key in ref:
        g, r = got[key], ref[key]
        assert g.shape == r.shape, key
        assert np.all(np.isfinite(r)), key
        err = np.abs(g - r)
        with np.errstate(divide="ignore", invalid="ignore"):
            rel = np.where(err == 0.0, 0.0, err / (RTOL * np.abs(r)))
        worst = max(worst, float(np.max(rel)))
    return worst


def _setup(art, combo, seed):
    rng = np.random.default_rng(seed)
    el = _element(art, *combo)
    p = _params(art, combo[0], rng, N)
    u = _pressures(el, rng, N)
    x = _states(art, el, p, u, rng)
    return el, p, x, u


def test_kernel_options_and_observables(art, compiled):
    el = _element(art, "kuo91", 2, "dynamic", True, True, "ref")
    assert el.kernel_options().dtype == np.int64
    assert el.kernel_options().tolist() == [2, 1, 1, 1, 1]
    assert _element(art, "falcone91", 1, "quasi_steady", False, False, "gauge").kernel_options().tolist() \
        == [1, 0, 0, 0, 0]
    for ca_order in (1, 2):
        el = art.Arteriole({"ca_order": ca_order})
        names = el.kernel().observables
        assert names == tuple(o.name for o in el.observables() if o.state_only)
        assert names == compiled.observables(ca_order)
        assert ("dCa" in names) == (ca_order == 2)
    assert tuple(art.Arteriole.parameters) == tuple(art.PARAMETERS)
    assert art.equations.N_PARAMS == len(art.Arteriole.parameters)


@pytest.mark.parametrize("combo", COMBOS, ids=["-".join(map(str, c)) for c in COMBOS])
def test_compiled_matches_python(art, combo):
    el, p, x, u = _setup(art, combo, seed=COMBOS.index(combo))
    t = 0.37
    ref = _python_all(el, p, x, u, t)
    got = _kernel_all(el, _param_vectors(el, p), x, u, t)
    assert _mismatch(got, ref) <= 1.0
    if el.opts["volume_flow"]:
        # the volume-flow terms are really there (not just the resistor)
        assert np.all(ref["b"][:, 3] != 0.0) and np.all(ref["A"][:, 2, 0] != 0.0)
        assert np.all((ref["A"][:, 2, 2] != 0.0) == (el.opts["pim_reference"] == "ref"))


def test_psi_branches_covered(art):
    """The samples reach both branches of psi (series, direct) and Q = 0 (psi = 1)."""
    el, p, x, u = _setup(art, COMBOS[0], seed=0)
    eq = art.equations
    pv = eq.vector(p)
    lam = x[..., 2]
    r = eq.l2r(lam, pv)
    dP = (u[..., 0] - u[..., 1]) * PA_PER_MMHG
    with np.errstate(divide="ignore"):
        xt = eq.transport_number(eq.flow(r, dP, pv), r, eq.no_rates(pv)[0], pv)
    small = eq.PSI_SERIES_X
    assert np.any(xt < small) and np.any(np.isinf(xt)) and np.any(np.isfinite(xt) & (xt >= small))


def test_detects_wrong_parameter(art):
    """A parameter changed on one side only is caught by the comparison; changed on both sides
    it agrees again.  Every parameter influences some output in some option combination."""
    influential = set()
    for combo in [("kuo91", 1, "quasi_steady", False, True, "ref"), ("falcone91", 2, "dynamic", False, True, "gauge"),
                  ("kuo91", 1, "dynamic", True, False, "gauge")]:
        el, p, x, u = _setup(art, combo, seed=99)
        t = 0.0
        base_pv = _param_vectors(el, p)
        base_kernel = _kernel_all(el, base_pv, x, u, t)
        assert _mismatch(base_kernel, _python_all(el, p, x, u, t)) <= 1.0
        for i, name in enumerate(el.parameters):
            q = dict(p)
            q[name] = p[name] * 1.1 if np.all(p[name] != 0.0) else p[name] + 1e-8
            ref = _python_all(el, q, x, u, t)
            if _mismatch(base_kernel, ref) <= 1.0:
                continue  # no influence in this option combination (e.g. omega_n at ca_order 1)
            influential.add(name)
            assert _mismatch(_kernel_all(el, _param_vectors(el, q), x, u, t), ref) <= 1.0, name
        # a permuted parameter vector (two neighbours swapped) is caught
        pv = base_pv.copy()
        pv[:, [0, 1]] = pv[:, [1, 0]]
        assert _mismatch(_kernel_all(el, pv, x, u, t), _python_all(el, p, x, u, t)) > 1.0
    assert influential == set(el.parameters)


def test_non_finite_propagates(art):
    """Invalid states give NaN/inf (no exception): the caller checks finiteness."""
    el = _element(art, "kuo91", 1, "quasi_steady", False, True, "gauge")
    k, io = el.kernel(), el.kernel_options()
    p = {kk: np.full((1, 1), v) for kk, v in art.make_params("kuo91").items()}
    pv = _param_vectors(el, p)[0]
    x = el.default_states(p)[0, 0].copy()
    x[2] = np.nan
    dx = np.zeros(3)
    k.derivs(pv, x, np.array([80.0, 40.0, 0.0, 60.0]), 0.0, io, dx)
    assert not np.all(np.isfinite(dx))
    A, b = np.zeros((4, 4)), np.zeros(4)
    k.stamp(pv, x, np.zeros(4), 0.0, io, A, b)
    assert not np.all(np.isfinite(A))


def _benchmark():
    """Time one ``derivs`` call from inside an njit loop (kuo91, ca_order 2, dynamic, volume flow)."""
    import time

    from hemocircuit.components import arteriole as art
    from hemocircuit.components.arteriole import compiled as c

    results = {}
    for opts in ({}, {"ca_order": 2, "kinetics": "dynamic", "volume_flow": True, "pim_reference": "ref"},
                 {"passive": True}):
        el = art.Arteriole(opts)
        p = {k: np.full((1, 1), v) for k, v in art.make_params("kuo91", no_speed=2.0).items()}
        pv = _param_vectors(el, p)[0]
        x = el.default_states(p)[0, 0] * 1.01
        u = np.array([80.0, 40.0, 5.0, 60.0])
        io = el.kernel_options()
        dx = np.zeros(x.size)

        @numba.njit
        def loop(n, pv, x, u, io, dx):
            acc = 0.0
            for i in range(n):
                x[0] += 1e-30 * i          # defeat hoisting
                c.derivs(pv, x, u, 0.0, io, dx)
                acc += dx[0]
            return acc

        loop(10, pv, x, u, io, dx)
        n = 2_000_000
        best = np.inf
        for _ in range(5):
            t0 = time.perf_counter()
            loop(n, pv, x, u, io, dx)
            best = min(best, (time.perf_counter() - t0) / n)
        results[str(opts or "default")] = best
    for k, v in results.items():
        print(f"derivs {k}: {v * 1e9:.0f} ns per call")


if __name__ == "__main__":
    _benchmark()
