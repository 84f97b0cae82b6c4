"""Vessel geometry (SI: m, m^2, m^3, Pa*s/m^3)."""
from __future__ import annotations

import numpy as np


def l2r(lam, p):
    """Internal radius [m] from normalised cell length lambda [-] (eq l2r):
    r = (lambda l0 n_c / pi - t_w) / 2."""
    return 0.5 * (lam * p["l0"] * p["n_c"] / np.pi - p["t_w"])


def r2l(r, p):
    """Normalised cell length [-] from internal radius r [m] (inverse of eq l2r)."""
    return (2.0 * r + p["t_w"]) * np.pi / (p["l0"] * p["n_c"])


def dr_dlambda(p):
    """dr/dlambda [m] (eq l2r): l0 n_c / (2 pi)."""
    return 0.5 * p["l0"] * p["n_c"] / np.pi


def wall_area(p):
    """Wall cross-section A_w [m^2] = pi((r0 + t_w)^2 - r0^2), constant (sec. NOeqns)."""
    r0, tw = p["r0"], p["t_w"]
    return np.pi * ((r0 + tw) ** 2 - r0 ** 2)


def lumen_area(r):
    """Lumen cross-section A_b [m^2] = pi r^2 (sec. NOeqns)."""
    return np.pi * r * r


def flow(r, dP, p):
    """Poiseuille flow Q [m^3/s] of ONE vessel, Q = pi r^4 dP / (8 mu_b L) (eq Poiseuille)."""
    return np.pi * r ** 4 * dP / (8.0 * p["mu_b"] * p["L"])


def resistance(r, p):
    """Bed resistance [Pa*s/m^3] of n parallel vessels, R = 8 mu_b L / (pi r^4 n) (eq Poiseuille).

    Infinite (not NaN) at r = 0."""
    with np.errstate(divide="ignore"):
        return 8.0 * p["mu_b"] * p["L"] / (np.pi * r ** 4 * p["n"])


def bed_volume(r, p):
    """Lumen volume [m^3] of the bed of n vessels, V = pi r^2 L n."""
    return np.pi * r * r * p["L"] * p["n"]
