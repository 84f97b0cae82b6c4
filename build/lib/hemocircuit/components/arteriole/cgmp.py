"""[NO] -> [cGMP] relationship (thesis sec. NOcGMP) and the shared 5 %/95 % sigmoid."""
from __future__ import annotations

import numpy as np
from scipy.special import expit

#: ln(1/0.95 - 1) = -ln 19, from the 5 %/95 % definition (eq sigmoiddef)
LN_95 = np.log(1.0 / 0.95 - 1.0)
LN10 = np.log(10.0)


def sigmoid_5_95(x, x_L, x_U, y_L, y_U):
    """y = y_L + (y_U - y_L) / (1 + exp(-(x - z_half)/k_z)) (eqs NOcGMP, sigmoiddef), with
    z_half = (x_L + x_U)/2 and k_z = (x_L - x_U) / (2 ln(1/0.95 - 1)).

    y passes y_L + 5 % (y_U - y_L) at x = x_L and y_L + 95 % at x = x_U.  Overflow-free
    (scipy.special.expit).  Units: y as y_L, y_U; x as x_L, x_U."""
    z_half = 0.5 * (x_L + x_U)
    k_z = (x_L - x_U) / (2.0 * LN_95)
    return y_L + (y_U - y_L) * expit((x - z_half) / k_z)


def p_cgmp(Cw, p):
    """log10([cGMP]/M) [-] from wall [NO] C_w [M] (eq NOcGMP; the sigmoid takes the wall
    NO of the NO model, sec. NOcGMP and figSSoverallflow)."""
    return sigmoid_5_95(Cw, p["NO_L"], p["NO_U"], p["pcGMP_L"], p["pcGMP_U"])


def cgmp(Cw, p):
    """[cGMP] [M] = 10**pcGMP (eq NOcGMP), instantaneous (no dynamics)."""
    return np.exp(LN10 * p_cgmp(Cw, p))
