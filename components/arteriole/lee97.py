"""Relative phosphorylation vs [Ca] for several [cGMP] (thesis figure figrPhospCa, fit to Lee97):
the 4-state cross-bridge kinetics (eqs phos, dephos, 4stateSS) at steady state.  Fractions [-],
concentrations [M]."""
from __future__ import annotations

import numpy as np

from . import equations as eq
from .parameters import make_params


def relative_phosphorylation(Ca, cGMP, params):
    """Mp + AMp [-] at kinetic steady state (figure figrPhospCa), for [Ca], [cGMP] in M."""
    p = eq.vector(params)
    with np.errstate(divide="ignore"):
        _, Mp, AMp, _ = eq.quasi_steady(*eq.rates(np.asarray(Ca, dtype=float), np.asarray(cGMP, dtype=float),
                                                  p, False), p)
    return Mp + AMp


def phosphorylation_curves(params=None, Ca=None, cGMP=None):
    """(Ca [M], cGMP [M], phos [-] of shape (len(cGMP), len(Ca))) with phos = Mp + AMp at
    kinetic steady state.  Defaults: Ca 1e-8..1e-4 M (81 points), cGMP 1e-10..1e-5 M (6 decades),
    the kuo91 kinetic parameters (tab4State)."""
    p = make_params("kuo91") if params is None else params
    Ca = np.logspace(-8, -4, 81) if Ca is None else np.asarray(Ca, dtype=float)
    cGMP = np.logspace(-10, -5, 6) if cGMP is None else np.asarray(cGMP, dtype=float)
    return Ca, cGMP, relative_phosphorylation(Ca[None, :], cGMP[:, None], p)
