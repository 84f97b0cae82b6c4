"""NO model: wall and blood compartments (thesis sec. NOeqns, eqs NO1, cbbar, dNOdt, psi, NOSS).

Units: concentrations in M (mol/L), Q in m^3/s, areas in m^2, h_w in m^2/s (h_w/A_w in 1/s),
k_tau in m^2*M/s (k_tau tau_hat / A_w in M/s), rates in 1/s.
"""
from __future__ import annotations

import numpy as np

from .geometry import lumen_area, wall_area

#: below this x the series of psi is used (truncation error < 1e-13 relative)
_PSI_SERIES_X = 1e-2


def tau_hat(dP, r, p):
    """Normalised wall shear stress [-], tau_hat = (|dP| / dP0)(r / r0) (sec. NOeqns).

    |dP|: shear stress produces NO whichever way the blood flows (identical for dP >= 0)."""
    return (np.abs(dP) / p["dP0"]) * (r / p["r0"])


def transport_number(Q, r, p):
    """x = (h_w + r_db A_b) L / |Q| [-] (exponent in eqs cbbar, cinv); +inf at Q = 0."""
    k = p["h_w"] + p["r_db"] * lumen_area(r)  # m^2/s
    aq = np.abs(Q)
    with np.errstate(divide="ignore", invalid="ignore"):
        x = k * p["L"] / aq
    return np.where(aq > 0, x, np.inf)


def psi_of_x(x):
    """psi = 1 - (1 - exp(-x)) / x (eq psi), safe for all x >= 0: series for small x, 1 at x = inf."""
    x = np.asarray(x, dtype=float)
    small = x < _PSI_SERIES_X
    xs = np.where(small, x, 0.0)
    series = xs * (1 / 2 - xs * (1 / 6 - xs * (1 / 24 - xs * (1 / 120 - xs / 720))))
    xl = np.where(small, 1.0, x)
    direct = 1.0 - (-np.expm1(-xl)) / xl  # x = inf -> 1 exactly
    return np.where(small, series, direct)


def psi(Q, r, p):
    """psi [-] (eq psi) for flow Q [m^3/s] through a vessel of radius r [m]; psi(Q = 0) = 1."""
    return psi_of_x(transport_number(Q, r, p))


def _cb_inf(Cw, r, p):
    """Far-downstream blood [NO] [M], h_w C_we / (h_w + r_db A_b), C_we = C_w / gamma_wb."""
    return p["h_w"] * (Cw / p["gamma_wb"]) / (p["h_w"] + p["r_db"] * lumen_area(r))


def cb_mean(Cw, Q, r, p):
    """Length-averaged blood [NO] [M] (eqs cbbar, cbbarpsi):
    Cb_mean = (h_w C_we / (h_w + r_db A_b) - C_in) psi + C_in."""
    return (_cb_inf(Cw, r, p) - p["C_in"]) * psi(Q, r, p) + p["C_in"]


def cb_outlet(Cw, Q, r, p):
    """Blood [NO] at x = L [M] (eq cinv): (h_w C_we/(h_w + r_db A_b) - C_in)(1 - e^-x) + C_in."""
    x = transport_number(Q, r, p)
    return (_cb_inf(Cw, r, p) - p["C_in"]) * (-np.expm1(-x)) + p["C_in"]


def dCw_dt(Cw, Q, r, tau, p):
    """Wall [NO] rate [M/s] (eq dNOdt):
    dC_w/dt = -(h_w/A_w)(C_w/gamma_wb - Cb_mean) - r_dw C_w + s_w + k_tau tau_hat / A_w."""
    Aw = wall_area(p)
    return (-(p["h_w"] / Aw) * (Cw / p["gamma_wb"] - cb_mean(Cw, Q, r, p))
            - p["r_dw"] * Cw + p["s_w"] + p["k_tau"] * tau / Aw)


def cw_steady(Q, r, tau, p):
    """Steady wall [NO] [M] (eq NOSS):
    C_w = ((h_w/A_w) C_in (1 - psi) + s_w + k_tau tau_hat/A_w)
          / (h_w/(A_w gamma_wb) + r_dw - h_w^2 psi / (A_w (h_w + A_b r_db) gamma_wb))."""
    Aw = wall_area(p)
    h, g = p["h_w"], p["gamma_wb"]
    ps = psi(Q, r, p)
    num = (h / Aw) * p["C_in"] * (1.0 - ps) + p["s_w"] + p["k_tau"] * tau / Aw
    den = h / (Aw * g) + p["r_dw"] - h * h * ps / (Aw * (h + lumen_area(r) * p["r_db"]) * g)
    return num / den
