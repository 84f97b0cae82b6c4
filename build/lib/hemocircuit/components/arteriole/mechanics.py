"""Cell mechanics (thesis sec. Mechanical Model, eqs Fa/FaNew, Fp/passiveNew, FT, l2r, FMFP).

Units: forces in N, P in Pa, lengths in m, f1/f2 in N*s/m, v in m/s, lambda [-], time in s.
Force balance F_a + F_p = w_c P r (eqs FT, FMFP) with
    F_a = l0 (f1 AMp (v_hat + lambda_dot) + f2 AM lambda_dot) G,   v_hat = v / l0   (eq FaNew)
    G   = exp(-(lambda - lambda_opt)^2 / (2 eta))
solved for lambda_dot (MODEL_NOTES):
    dlambda/dt = (w_c P r - F_p - f1 v AMp G) / (l0 G (f1 AMp + f2 AM)).
"""
from __future__ import annotations

import numpy as np

from .geometry import l2r

#: numerical guard [N*s/m] added to G (f1 AMp + f2 AM): keeps dlambda/dt finite when no bridge
#: is attached or G underflows (lambda far from lambda_opt).  ~1e-8 of the typical value
#: (G f2 AM ~ 0.1 N*s/m); it does not change steady states.
FRICTION_FLOOR = 1e-9
#: friction [N*s/m] used in passive mode instead, where no bridge is attached (Ca = 0) and the
#: wall is purely elastic: the radius then relaxes to its passive equilibrium with a time
#: constant l0 PASSIVE_FRICTION / (dF_p/dlambda - w_c P dr/dlambda), about 10-30 ms.
#: Not in the thesis (which treats the passive case only at steady state); steady states are
#: unaffected.
PASSIVE_FRICTION = 1e-4
#: cap on the exponent of F_p (keeps F_p finite for absurd lambda; exp(700) ~ 1e304)
_MAX_EXP = 700.0


def overlap(lam, p):
    """Actin-myosin overlap G = exp(-(lambda - lambda_opt)^2 / (2 eta)) [-] (eq FaNew)."""
    d = lam - p["lambda_opt"]
    return np.exp(-d * d / (2.0 * p["eta"]))


def passive_force(lam, p):
    """F_p = q1 (exp(q2 (lambda^q3 - 1)) - 1) [N] (eq passiveNew).

    lambda <= 0 is unphysical: it is clipped at 0 (never NaN for non-integer q3)."""
    lq = np.maximum(lam, 0.0) ** p["q3"]
    return p["q1"] * np.expm1(np.minimum(p["q2"] * (lq - 1.0), _MAX_EXP))


def active_force_isometric(lam, AMp, p):
    """F_a at lambda_dot = 0 [N] = l0 f1 AMp v_hat G = f1 v AMp G (eqs FaNew, FTSS)."""
    return p["f1"] * p["v"] * AMp * overlap(lam, p)


def active_force(lam, lam_dot, AMp, AM, p):
    """F_a [N] (eq FaNew) = l0 (f1 AMp (v/l0 + lambda_dot) + f2 AM lambda_dot) G."""
    G = overlap(lam, p)
    return (p["f1"] * AMp * (p["v"] + p["l0"] * lam_dot) + p["f2"] * AM * p["l0"] * lam_dot) * G


def pressure_force(P, r, p):
    """F_Cell = w_c P r [N] (eq FMFP), P intramural pressure [Pa], r internal radius [m]."""
    return p["w_c"] * P * r


def friction(lam, AMp, AM, p, passive=False):
    """Denominator of dlambda/dt [N*s]: l0 (G (f1 AMp + f2 AM) + floor), the floor being
    PASSIVE_FRICTION in passive mode and FRICTION_FLOOR otherwise."""
    floor = PASSIVE_FRICTION if passive else FRICTION_FLOOR
    return p["l0"] * (overlap(lam, p) * (p["f1"] * AMp + p["f2"] * AM) + floor)


def dlambda_dt_affine(lam, AMp, AM, p, passive=False, r=None):
    """(a [1/s], b [1/(s*Pa)]) with dlambda/dt = a + b P (the rate is affine in P at given
    states: r, F_p, F_a and the friction depend on lambda and the bridge fractions only).
    ``r``: l2r(lam) if already computed."""
    D = friction(lam, AMp, AM, p, passive)
    a = -(passive_force(lam, p) + active_force_isometric(lam, AMp, p)) / D
    b = p["w_c"] * (l2r(lam, p) if r is None else r) / D
    return a, b


def dlambda_dt(lam, P, AMp, AM, p, passive=False):
    """dlambda/dt [1/s] = (w_c P r - F_p - f1 v AMp G) / (l0 G (f1 AMp + f2 AM)) (eq FaNew
    solved for lambda_dot with eqs FT, FMFP, l2r)."""
    a, b = dlambda_dt_affine(lam, AMp, AM, p, passive)
    return a + b * P


def force_residual(lam, P, AMp, p):
    """g = w_c P r - F_p - F_a|lambda_dot=0 [N] (eq mechSS with passiveNew and FaNew);
    g = 0 is the mechanical steady state and dlambda/dt = g / friction."""
    return (pressure_force(P, l2r(lam, p), p) - passive_force(lam, p)
            - active_force_isometric(lam, AMp, p))
