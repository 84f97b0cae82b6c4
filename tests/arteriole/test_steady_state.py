"""Steady state (thesis sec. ssmodel) against the thesis's own numbers and the dynamics."""
import warnings

import numpy as np
import pytest

from element_calls import rates

MMHG = 133.322387415   # Pa per mmHg
CMH2O = 98.0665        # Pa per cmH2O

OPTIONS = [{}, {"ca_order": 2}, {"kinetics": "dynamic"}, {"ca_order": 2, "kinetics": "dynamic"},
           {"passive": True}, {"passive": True, "kinetics": "dynamic", "ca_order": 2}]


@pytest.mark.parametrize("options", OPTIONS)
@pytest.mark.parametrize("preset", ["kuo91", "falcone91"])
def test_steady_state_is_fixed_point(art, options, preset):
    p = art.make_params(preset)
    P = np.array([30.0, 60.0, 100.0, 140.0])[:, None] * MMHG
    dP = np.array([0.0, 4.0 * CMH2O, 20.0 * CMH2O])
    s = art.solve_steady(P, dP, p, options)
    assert s["found"].all() and s["converged"].all()
    d = rates(art, s, P, dP, p, options)
    scales = {n: art.STATE_SCALES[n] for n in art.state_names(options)}
    assert set(d) == set(art.state_names(options))
    for name, rate in d.items():
        # |dx/dt| / scale in 1/s; the slowest rates of the model are ~1e-3 /s
        assert np.max(np.abs(rate)) / scales[name] < 1e-9, name
    # and the packed state vector round-trips
    x = art.pack(s, options)
    assert x.shape == (4, 3, len(scales))
    np.testing.assert_array_equal(art.unpack(x, options)["lambda"], s["lambda"])


def test_thesis_radii_kuo91(art, kuo):
    """Kuo91 fit (figPassiveFitBoth): r = 60 um at P = 60 mmHg, active, no flow; the passive
    vessel is much wider; flow (dP = 4 cmH2O) dilates the active vessel."""
    P = 60 * MMHG
    active = art.solve_steady(P, 0.0, kuo)
    passive = art.solve_steady(P, 0.0, kuo, {"passive": True})
    flow = art.solve_steady(P, 4 * CMH2O, kuo)
    assert active["r"] == pytest.approx(60e-6, abs=1e-6)
    assert 85e-6 < passive["r"] < 115e-6
    assert flow["r"] > active["r"] + 5e-6          # measured: 71.0 vs 60.4 um
    assert flow["Cw"] > 10 * active["Cw"]          # shear-stress NO
    assert passive["Ca"] == 0 and passive["AMp"] == 0 and passive["M"] == 1
    # stated values (tabActiveFit fit): 60.4, 103.0, 71.0 um
    np.testing.assert_allclose([active["r"], passive["r"], flow["r"]],
                               [60.44e-6, 102.98e-6, 70.96e-6], rtol=2e-3)


def test_passive_radius_grows_with_pressure_and_exceeds_active(art, kuo):
    P = np.linspace(20, 140, 13) * MMHG
    rp = art.solve_steady(P, 0.0, kuo, {"passive": True})["r"]
    ra = art.solve_steady(P, 0.0, kuo)["r"]
    assert np.all(np.diff(rp) > 0)
    assert np.all(rp > ra)


@pytest.mark.parametrize("dP", [0.0, 4 * CMH2O, 15 * CMH2O])
def test_no_speed_barely_changes_steady_state(art, kuo, dP):
    """NO speed 1 (tabNewNOValues) vs 1/0.005 (tabActiveFit): same steady state (thesis
    sec. dynfitting), though dCw/dt is ~200x faster."""
    P = np.linspace(20, 140, 7) * MMHG
    slow = art.solve_steady(P, dP, kuo)
    fast = art.solve_steady(P, dP, dict(kuo, no_speed=1 / 0.005))
    np.testing.assert_allclose(fast["Cw"], slow["Cw"], rtol=1e-2)
    np.testing.assert_allclose(fast["r"], slow["r"], rtol=1e-3)
    # away from the steady state, the wall-NO rate scales with no_speed
    st = dict(Ca=slow["Ca"], Cw=2 * slow["Cw"], **{"lambda": slow["lambda"]})
    d1 = rates(art, st, P, dP, kuo)["Cw"]
    d200 = rates(art, st, P, dP, dict(kuo, no_speed=200.0))["Cw"]
    np.testing.assert_allclose(d200 / d1, 200.0, rtol=2e-2)


def test_vectorised_equals_elementwise(art, kuo):
    f1 = np.array([5e-6, 9.34e-6, 2e-5])[:, None]
    P = np.array([40.0, 80.0, 120.0, 160.0]) * MMHG
    p = dict(kuo, f1=f1)
    s = art.solve_steady(P, 2 * CMH2O, p)
    assert s["r"].shape == (3, 4) and s["alpha"].shape == (3, 4, 4)
    for i in range(3):
        for j in range(4):
            one = art.solve_steady(P[j], 2 * CMH2O, dict(kuo, f1=f1[i, 0]))
            assert one["r"] == pytest.approx(s["r"][i, j], rel=1e-12)
            assert one["Cw"] == pytest.approx(s["Cw"][i, j], rel=1e-12)


def test_multiple_equilibria_are_flagged_and_stable_one_returned(art, kuo):
    """A narrow, strong active-force peak (eta = 0.01, f1 = 5e-5, lambda_opt = 1.2) gives three
    equilibria at 100 mmHg: two stable, one unstable between them."""
    p = dict(kuo, eta=0.01, f1=5e-5, lambda_opt=1.2)
    P = 100 * MMHG
    with pytest.warns(art.SteadyStateWarning, match="several equilibria"):
        hi = art.solve_steady(P, 0.0, p, branch="high")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", art.SteadyStateWarning)
        lo = art.solve_steady(P, 0.0, p, branch="low")
        near = art.solve_steady(P, 0.0, p, r_guess=lo["r"] * 1.01)
    assert hi["n_roots"] == 3 and hi["n_stable"] == 2
    assert hi["r"] > lo["r"] + 5e-6
    assert near["r"] == lo["r"]
    pe = art.equations.vector(p)
    for s in (hi, lo):
        assert np.max(np.abs(rates(art, s, P, 0.0, p)["lambda"])) < 1e-9
        h = 1e-6
        g = [art.steady_state.slaved(s["lambda"] + e, P, 0.0, pe)["g"] for e in (-h, h)]
        assert (g[1] - g[0]) / (2 * h) < 0                  # stable: d(dlambda/dt)/dlambda < 0


def test_no_equilibrium_in_range_is_nan_and_warned(art, kuo):
    with pytest.warns(art.SteadyStateWarning, match="no stable equilibrium"):
        s = art.solve_steady(np.array([60.0, 600.0]) * MMHG, 0.0, kuo, {"passive": True},
                             r_max=120e-6)
    assert s["found"].tolist() == [True, False]
    assert np.isnan(s["r"][1]) and np.isfinite(s["r"][0])
