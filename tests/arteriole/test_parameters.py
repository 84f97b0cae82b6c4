"""Parameter table, presets, units, no_speed."""
import numpy as np
import pytest


def test_presets_complete_and_within_bounds(art):
    """Every preset gives every parameter, each within the bounds the element declares (which
    the framework checks), and no combination check_params rejects."""
    from hemocircuit.components.arteriole.element import Arteriole

    for name, p in art.PRESETS.items():
        assert set(p) == set(art.PARAMETERS), name
        assert not [k for k, v in p.items() if Arteriole.parameters[k].violates(np.atleast_1d(v)).any()], name
        assert art.check_params(p) == [], name


def test_a_value_outside_its_bounds_is_an_error_naming_the_element(art, write):
    """The bounds of PARAMETERS reach the framework's check: a negative tau_Ca is refused."""
    import hemocircuit as hc

    c = hc.load(write("elements:\n  - {id: Pa, type: pressure_source, nodes: [in, ground], value: 60 mmHg}\n"
                      "  - {id: art, type: arteriole, nodes: [in, ground, ground]}\n"))
    with pytest.raises(hc.NetlistError, match=r"element 'art'.*tau_Ca.*not physical"):
        c.with_values({"art.tau_Ca": "-1 s"})


def test_units_parse_with_pint_and_have_si_dimensions(art):
    pint = pytest.importorskip("pint")
    ureg = pint.UnitRegistry()
    # MODEL_NOTES units: k_tau m^2 M/s and h_w m^2/s (so h_w/A_w is 1/s), mu_b Pa*s, ...
    dims = {"h_w": "[length]**2/[time]", "k_tau": "[length]**2*[substance]/[length]**3/[time]",
            "mu_b": "[pressure]*[time]", "f1": "[force]*[time]/[length]", "q1": "[force]",
            "s_w": "[substance]/[length]**3/[time]", "sigma_L": "[pressure]", "omega_n": "1/[time]",
            "dP0": "[pressure]", "v": "[length]/[time]", "NO_L": "[substance]/[length]**3"}
    for name, spec in art.PARAMETERS.items():
        q = ureg.Quantity(1, spec.unit)
        if name in dims:
            assert q.check(dims[name]), name
        assert spec.doc and ("tab" in spec.doc or "sec." in spec.doc or name in ("n", "pCa_shift")), name


def test_known_values(art):
    k, f = art.PRESETS["kuo91"], art.PRESETS["falcone91"]
    assert k["dP0"] == pytest.approx(60 * 133.322, rel=1e-5)
    assert (k["h_w"], k["r_dw"], k["s_w"], k["k_tau"]) == (38.0e-12, 47.6e-3, 346e-12, 1.24e-15)
    assert f["f2"] == k["f2"] and f["h_w"] == k["h_w"] and f["k_tau"] == k["k_tau"]
    assert (f["q3"], f["l0"], f["f1"], f["lambda_opt"]) == (0.619, 64.3e-6, 98.7e-6, 1.79)


def test_no_speed_scales_the_four_no_coefficients(art, kuo):
    """equations.no_rates (sec. dynfitting): (h_w, r_dw, s_w, k_tau) times no_speed; 1/0.005
    restores tabActiveFit's values, and an array of no_speed scales element by element."""
    rates = art.equations.no_rates(art.equations.vector(dict(kuo, no_speed=1 / 0.005)))
    # tabActiveFit values: h_w 7.61e-9, r_dw 9.51, s_w 69.2e-9, k_tau 248e-15
    np.testing.assert_allclose(rates, [7.61e-9, 9.51, 69.2e-9, 248e-15], rtol=2e-3)
    h_w = art.equations.no_rates(art.equations.vector(dict(kuo, no_speed=np.array([1.0, 2.0]))))[0]
    np.testing.assert_array_equal(h_w, [38e-12, 76e-12])
    assert kuo["no_speed"] == 1.0


def test_make_params_rejects_unknown(art):
    with pytest.raises(KeyError):
        art.make_params("kuo91", hw=1.0)
    with pytest.raises(KeyError):
        art.make_params("nope")
    assert art.check_params(dict(art.make_params(), NO_U=780e-12)) != []


def test_tone_shift_multiplies_the_equilibrium_calcium(art):
    """pCa_shift (not in the thesis, 0 in both presets) adds to eq ssCa's log10[Ca]: the
    equilibrium Ca at every wall stress is 10**shift times the thesis's, and the presets keep
    the thesis's curve."""
    from hemocircuit.components.arteriole import equations as eq

    p = art.make_params("kuo91")
    assert p["pCa_shift"] == 0.0 and art.PRESETS["falcone91"]["pCa_shift"] == 0.0
    sigma = np.linspace(-2e4, 8e4, 11)
    base = eq.ca_bar(sigma, eq.vector(p))
    hand = 10.0 ** eq.sigmoid_5_95(sigma, p["sigma_L"], p["sigma_U"], p["pCa_L"], p["pCa_U"])
    np.testing.assert_allclose(base, hand, rtol=1e-13)
    for shift in (-0.1, 0.05, 0.3):
        np.testing.assert_allclose(eq.ca_bar(sigma, eq.vector({**p, "pCa_shift": shift})), 10.0 ** shift * base,
                                   rtol=1e-13)
