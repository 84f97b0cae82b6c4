"""Parameters of the active arteriole element (thesis chapters 3-4), all in SI.

Units: Pa, m, N, s; concentrations in M = mol/L (MODEL_NOTES "Units").  Every entry of
``PARAMETERS`` is the element's declaration (hemocircuit.component.Param), written
``_P(unit, lower, upper, doc, lower_open)``: a pint-parseable unit, physical bounds (``None`` =
unbounded; ``lower_open`` makes the lower bound strict) and a one-line description naming the
thesis table the value comes from.

Presets: ``kuo91`` (Kuo column of tabPassiveFit / tabActiveFit, tab4State) and ``falcone91``
(Falcone column; where it has '--' or N/A the Kuo value).  Both use the NO coefficients of
tabNewNOValues (the tabActiveFit values x 0.005); ``no_speed`` multiplies h_w, r_dw, s_w and
k_tau together (thesis section dynfitting), so ``no_speed = 1/0.005`` restores tabActiveFit.
"""
from __future__ import annotations

import numpy as np

from hemocircuit.component import Param
from hemocircuit.units import PA_PER_MMHG


def _P(unit, lower, upper, doc, lower_open=False):
    return Param(unit, lower=lower, upper=upper, lower_open=lower_open, doc=doc)


PARAMETERS: dict[str, Param] = {
    # --- NO model (tabActiveFit, tabNewNOValues) ---------------------------------------
    "h_w": _P("m**2/s", 0.0, None, "NO wall-blood transport coefficient (tabNewNOValues)"),
    "s_w": _P("M/s", 0.0, None, "basal NO production rate in the wall (tabNewNOValues)"),
    "gamma_wb": _P("dimensionless", 0.0, None, "baseline wall:blood [NO] ratio (tabActiveFit)", True),
    "r_db": _P("1/s", 0.0, None, "NO decay rate in blood (tabActiveFit)"),
    "r_dw": _P("1/s", 0.0, None, "NO decay rate in the wall (tabNewNOValues)"),
    "k_tau": _P("m**2*mol/L/s", 0.0, None, "shear-stress NO production coefficient (tabNewNOValues)"),
    "C_in": _P("M", 0.0, None, "[NO] of blood entering the vessel (tabActiveFit)"),
    "mu_b": _P("Pa*s", 0.0, None, "blood viscosity (tabActiveFit, 'Ns/m' read as Pa*s)", True),
    "dP0": _P("Pa", 0.0, None, "normalising pressure drop, 60 mmHg (tabActiveFit)", True),
    "r0": _P("m", 0.0, None, "baseline internal radius, sets A_w and tau_hat (tabActiveFit)", True),
    # --- NO -> cGMP sigmoid (eqs NOcGMP, sigmoiddef; tabActiveFit) ----------------------
    "NO_L": _P("M", None, None, "[NO] at 5 % of the cGMP sigmoid (tabActiveFit)"),
    "NO_U": _P("M", None, None, "[NO] at 95 % of the cGMP sigmoid (tabActiveFit)"),
    "pcGMP_L": _P("dimensionless", None, None, "lower bound of log10[cGMP] (tabActiveFit)"),
    "pcGMP_U": _P("dimensionless", None, None, "upper bound of log10[cGMP] (tabActiveFit)"),
    # --- myogenic sigmoid (tabActiveFit; thesis writes sigma in 'N/m', P r/t_w is Pa) ---
    "sigma_L": _P("Pa", None, None, "wall stress at 5 % of the Ca sigmoid (tabActiveFit)"),
    "sigma_U": _P("Pa", None, None, "wall stress at 95 % of the Ca sigmoid (tabActiveFit)"),
    "pCa_L": _P("dimensionless", None, None, "lower bound of log10[Ca] (tabActiveFit)"),
    "pCa_U": _P("dimensionless", None, None, "upper bound of log10[Ca] (tabActiveFit)"),
    # --- mechanics (tabActiveFit, tabPassiveFit) ---------------------------------------
    "f1": _P("N*s/m", 0.0, None, "friction of cycling cross-bridges AMp (tabActiveFit)"),
    "f2": _P("N*s/m", 0.0, None, "friction of latch bridges AM (tabActiveFit)"),
    "lambda_opt": _P("dimensionless", 0.0, None, "cell length of maximal overlap (tabActiveFit)", True),
    "v": _P("m/s", 0.0, None, "cross-bridge cycling velocity (tabActiveFit)"),
    "eta": _P("dimensionless", 0.0, None, "variance of the sarcomere distribution (tabActiveFit)", True),
    "q1": _P("N", 0.0, None, "passive stiffness coefficient (tabPassiveFit)"),
    "q2": _P("dimensionless", None, None, "passive stiffness exponent (tabPassiveFit)"),
    "q3": _P("dimensionless", 0.0, None, "passive stiffness length exponent (tabPassiveFit)", True),
    "l0": _P("m", 0.0, None, "relaxed cell length (tabPassiveFit)", True),
    "w_c": _P("m", 0.0, None, "effective muscle-cell width (tabPassiveFit)", True),
    "n_c": _P("dimensionless", 0.0, None, "number of cells around the circumference (tabPassiveFit)", True),
    "t_w": _P("m", 0.0, None, "wall thickness (tabPassiveFit)", True),
    # --- 4-state kinetics (tab4State) --------------------------------------------------
    "K3": _P("1/s", 0.0, None, "phosphorylated attachment rate (tab4State)"),
    "K4": _P("1/s", 0.0, None, "phosphorylated detachment rate (tab4State)"),
    "K7": _P("1/s", 0.0, None, "latch detachment rate (tab4State)"),
    "k_Ca1": _P("M", 0.0, None, "phosphorylation Ca sensitivity (tab4State)", True),
    "n_Ca1": _P("dimensionless", 0.0, None, "phosphorylation Hill exponent (tab4State)", True),
    "k_Ca2": _P("M", 0.0, None, "dephosphorylation Ca sensitivity (tab4State)", True),
    "n_Ca2": _P("dimensionless", 0.0, None, "dephosphorylation Ca Hill exponent (tab4State)", True),
    "k_cGMP": _P("M", 0.0, None, "dephosphorylation cGMP sensitivity (tab4State)", True),
    "n_cGMP": _P("dimensionless", 0.0, None, "dephosphorylation cGMP Hill exponent (tab4State)", True),
    # --- Ca dynamics (eq dCadt, tabTauCaVals; eq dCadt2, tabOmegaZeta) -----------------
    "tau_Ca": _P("s", 0.0, None, "first-order Ca time constant (tabTauCaVals, fast value 1 s)", True),
    "omega_n": _P("rad/s", 0.0, None, "second-order Ca natural frequency (tabOmegaZeta)", True),
    "zeta": _P("dimensionless", 0.0, None, "second-order Ca damping factor (tabOmegaZeta)"),
    # --- scaling and geometry of the element --------------------------------------------
    "no_speed": _P("dimensionless", 0.0, None, "common factor on h_w, r_dw, s_w, k_tau (sec. dynfitting)", True),
    "L": _P("m", 0.0, None, "vessel length (tabActiveFit)", True),
    "n": _P("dimensionless", 0.0, None, "number of identical vessels in parallel", True),
    # --- beyond the thesis ------------------------------------------------------------------
    "pCa_shift": _P("dimensionless", None, None, "added to eq ssCa's log10[Ca]: non-myogenic tone (CO2, neural, "
                                                 "metabolic); not in the thesis (0); may be a waveform"),
}

_KUO91 = {
    # NO model: tabNewNOValues for h_w, s_w, r_dw, k_tau; the rest tabActiveFit (Kuo)
    "h_w": 38.0e-12, "s_w": 346e-12, "gamma_wb": 7.27, "r_db": 89.5, "r_dw": 47.6e-3,
    "k_tau": 1.24e-15, "C_in": 0.0, "mu_b": 4.37e-3, "dP0": 60.0 * PA_PER_MMHG, "r0": 60e-6,
    "NO_L": 780e-12, "NO_U": 36.5e-9, "pcGMP_L": -9.57, "pcGMP_U": -8.29,
    "sigma_L": -8.16e3, "sigma_U": 52.4e3, "pCa_L": -8.50, "pCa_U": -6.94,
    "f1": 9.34e-6, "f2": 500e-3, "lambda_opt": 1.49, "v": 9.71, "eta": 264e-3,
    # tabPassiveFit (Kuo)
    "q1": 26.4e-9, "q2": 8.38, "q3": 1.06, "l0": 77.5e-6, "w_c": 2.67e-6, "n_c": 6.0, "t_w": 15e-6,
    # tab4State
    "K3": 0.4, "K4": 0.1, "K7": 0.01, "k_Ca1": 3e-6, "n_Ca1": 0.85, "k_Ca2": 8e-7, "n_Ca2": 1.5,
    "k_cGMP": 3e-8, "n_cGMP": 1.0,
    # Ca dynamics defaults: tau_Ca 1 s (tabTauCaVals), omega_n 1.5 rad/s, zeta 0.5 (tabOmegaZeta)
    "tau_Ca": 1.0, "omega_n": 1.5, "zeta": 0.5,
    "no_speed": 1.0, "L": 1e-3, "n": 1.0,
    "pCa_shift": 0.0,  # not in the thesis: no tone input
}
_FALCONE91 = dict(_KUO91)
_FALCONE91.update({
    # tabPassiveFit (Falcone)
    "q1": 61.4e-9, "q2": 8.27, "q3": 0.619, "l0": 64.3e-6,
    # tabActiveFit (Falcone); NO model, f2 ('N/A') and the cGMP sigmoid stay Kuo
    "sigma_L": 11.3e3, "sigma_U": 47.3e3, "pCa_L": -8.84, "pCa_U": -7.57,
    "f1": 98.7e-6, "lambda_opt": 1.79, "v": 8.99, "eta": 217e-3,
})

PRESETS: dict[str, dict[str, float]] = {"kuo91": _KUO91, "falcone91": _FALCONE91}
assert all(set(p) == set(PARAMETERS) for p in PRESETS.values())


def make_params(preset: str = "kuo91", **overrides) -> dict:
    """A complete parameter dict (copy of ``PRESETS[preset]``) with ``overrides`` applied.

    Values may be floats or arrays (any broadcastable shapes: batch x elements).
    """
    if preset not in PRESETS:
        raise KeyError(f"unknown arteriole preset {preset!r}; choose one of {sorted(PRESETS)}")
    unknown = set(overrides) - set(PARAMETERS)
    if unknown:
        raise KeyError(f"unknown arteriole parameter(s) {sorted(unknown)}")
    out = dict(PRESETS[preset])
    out.update(overrides)
    return out


def check_params(params: dict, complete: bool = True) -> list[str]:
    """Messages for missing parameters (``complete``: a netlist's expression-valued ones are
    absent until evaluated) and for combinations the equations cannot take.  Each value's own
    bounds (``PARAMETERS``) are the framework's: the element declares them (``Param``), and
    assembly and every ``with_values`` check them (build.check_values)."""
    msgs = []
    missing = set(PARAMETERS) - set(params)
    if missing and complete:
        msgs.append(f"missing parameter(s) {sorted(missing)}")
    p = params
    for lo, hi in (("NO_L", "NO_U"), ("sigma_L", "sigma_U")):
        if lo in p and hi in p and np.any(np.equal(p[lo], p[hi])):
            msgs.append(f"{lo} == {hi}: the 5 %/95 % sigmoid is undefined")
    # eq l2r: the ring of n_c relaxed cells must enclose a lumen (r(lambda = 1) > 0)
    if {"l0", "n_c", "t_w"} <= set(p) and np.any(np.asarray(p["l0"]) * p["n_c"] / np.pi <= p["t_w"]):
        msgs.append("l0 n_c / pi <= t_w: radius at lambda = 1 is not positive")
    return msgs
