"""Myogenic response: wall stress -> equilibrium [Ca] and the Ca dynamics.

Thesis sec. "Myogenic Response Model" (eqs for sigma and pCa_bar, eq dCadt) and sec.
"Making Ca Dynamics 2nd Order" (eq dCadt2).  Units: P in Pa, r and t_w in m, sigma in Pa
(the thesis labels it N/m), concentrations in M, time in s.
"""
from __future__ import annotations

import numpy as np

from .cgmp import LN10, sigmoid_5_95

#: lower floor of [Ca] [M] for the second-order dynamics (MODEL_NOTES): the integrator stops
#: at it, resets dCa/dt to 0 and continues (model.at_ca_floor, model.clip_states); K1/K2 clip
#: Ca at it.
CA_FLOOR = 1e-12


def wall_stress(P, r, p):
    """sigma = P r / t_w [Pa] (sec. Myogenic Response Model), P intramural pressure [Pa]."""
    return P * r / p["t_w"]


def ca_bar(sigma, p):
    """Equilibrium [Ca] [M] = 10**pCa_bar with pCa_bar the 5 %/95 % sigmoid of sigma
    (eq for pCa_bar, same form as eq NOcGMP / sigmoiddef)."""
    return np.exp(LN10 * sigmoid_5_95(sigma, p["sigma_L"], p["sigma_U"], p["pCa_L"], p["pCa_U"]))


def dCa_dt_first(Ca, Ca_bar, p):
    """First-order Ca [M/s] (eq dCadt): dCa/dt = (Ca_bar - Ca) / tau_Ca."""
    return (Ca_bar - Ca) / p["tau_Ca"]


def d2Ca_dt2(Ca, dCa, Ca_bar, p):
    """Second-order Ca [M/s^2] (eq dCadt2 with G_dc = 1):
    d2Ca/dt2 = omega_n^2 (Ca_bar - Ca) - 2 zeta omega_n dCa/dt."""
    w = p["omega_n"]
    return w * w * (Ca_bar - Ca) - 2.0 * p["zeta"] * w * dCa

