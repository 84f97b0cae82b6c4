"""The active arteriole element: states, derivatives, observables (thesis chapters 3 and 6).

States (``state_names``): [Ca] (M), optionally dCa/dt (M/s, second-order Ca, eq dCadt2), wall
[NO] C_w (M), normalised cell length lambda (-), optionally the bridge fractions M, Mp, AMp, AM
(kinetics 'dynamic').  Inputs: P intramural pressure [Pa] (gauge), dP pressure drop along the
vessel [Pa].  ``params``: dict name -> float or array (see parameters.PARAMETERS), raw (this
module applies ``no_speed`` itself).  All functions are vectorised over any broadcastable
shapes (batch x elements); states are given either as a dict name -> array or as one array
whose LAST axis holds the states in ``state_names`` order.

Options (``DEFAULT_OPTIONS``): ``ca_order`` 1 (eq dCadt) or 2 (eq dCadt2); ``kinetics``
'quasi_steady' (default, eq 4stateSS, as the thesis) or 'dynamic' (eq 4state); ``passive``
(Ca = 0 exactly in the kinetics, no myogenic drive: Ca_bar = 0; alpha -> [1,0,0,0], F_a = 0).
"""
from __future__ import annotations

import numpy as np

from . import kinetics as kin
from .cgmp import cgmp
from .geometry import bed_volume, dr_dlambda, flow, l2r, resistance
from .mechanics import (active_force, dlambda_dt_affine as _dlam_affine, passive_force)
from .myogenic import CA_FLOOR, ca_bar, d2Ca_dt2, dCa_dt_first, wall_stress
from .no_transport import cb_mean, dCw_dt, tau_hat
from .parameters import effective

DEFAULT_OPTIONS = {"ca_order": 1, "kinetics": "quasi_steady", "passive": False}
OPTION_CHOICES = {"ca_order": (1, 2), "kinetics": ("quasi_steady", "dynamic"), "passive": (False, True)}

STATE_UNITS = {"Ca": "mol/L", "dCa": "mol/L/s", "Cw": "mol/L", "lambda": "dimensionless",
               "M": "dimensionless", "Mp": "dimensionless", "AMp": "dimensionless",
               "AM": "dimensionless"}
#: natural scales (for solver tolerances).  Measured with kuo91 at 60 mmHg: Ca 4e-8..6e-8 M,
#: Cw 7e-9 M (no flow) .. 2.4e-7 M (dP = 4 cmH2O), lambda ~ 0.9, dCa ~ omega_n Ca.
STATE_SCALES = {"Ca": 1e-7, "dCa": 1e-7, "Cw": 1e-7, "lambda": 1.0,
                "M": 1.0, "Mp": 1.0, "AMp": 1.0, "AM": 1.0}
OBSERVABLE_UNITS = {
    "r": "m", "lambda": "dimensionless", "Ca": "mol/L", "dCa": "mol/L/s", "Cw": "mol/L",
    "Cb_mean": "mol/L", "cGMP": "mol/L", "M": "dimensionless", "Mp": "dimensionless",
    "AMp": "dimensionless", "AM": "dimensionless", "sigma": "Pa", "tau_hat": "dimensionless",
    "Q": "m**3/s", "R": "Pa*s/m**3", "V": "m**3", "F_a": "N", "F_p": "N", "dr_dt": "m/s",
}


from hemocircuit.errors import HemocircuitError


class ArterioleError(HemocircuitError, ValueError):
    """Non-finite derivatives or observables (invalid states, inputs or parameters)."""


class ResolvedOptions(dict):
    """Options already checked by resolve_options (passed through without re-checking)."""


def resolve_options(options=None) -> dict:
    """``DEFAULT_OPTIONS`` updated with ``options``; raises ValueError on unknown keys/values."""
    if isinstance(options, ResolvedOptions):
        return options
    if options:
        options = {k: v for k, v in options.items() if k != "_names"}
    o = ResolvedOptions(DEFAULT_OPTIONS)
    if options:
        unknown = set(options) - set(o)
        if unknown:
            raise ValueError(f"unknown arteriole option(s) {sorted(unknown)}")
        o.update(options)
    for k, choices in OPTION_CHOICES.items():
        if o[k] not in choices:
            raise ValueError(f"arteriole option {k}={o[k]!r}: choose one of {choices}")
    o["passive"] = bool(o["passive"])
    return o


def state_names(options=None) -> list[str]:
    """Ordered state names: ['Ca', ('dCa',) 'Cw', 'lambda' (, 'M', 'Mp', 'AMp', 'AM')]."""
    o = resolve_options(options)
    if "_names" in o:
        return o["_names"]
    names = ["Ca", "dCa"] if o["ca_order"] == 2 else ["Ca"]
    names += ["Cw", "lambda"]
    if o["kinetics"] == "dynamic":
        names += list(kin.STATES)
    if isinstance(o, ResolvedOptions):
        o["_names"] = names
    return names


def state_scales(options=None) -> dict:
    """Natural scale of each state (same units as the state)."""
    return {n: STATE_SCALES[n] for n in state_names(options)}


def pack(states: dict, options=None) -> np.ndarray:
    """Dict name -> array  ->  one array with the states on the last axis (state_names order)."""
    names = state_names(options)
    arrs = np.broadcast_arrays(*[np.asarray(states[n], dtype=float) for n in names])
    return np.stack(arrs, axis=-1)


def unpack(x, options=None) -> dict:
    """Array with the states on the last axis -> dict name -> array (views)."""
    names = state_names(options)
    x = np.asarray(x, dtype=float)
    if x.shape[-1] != len(names):
        raise ValueError(f"state array has {x.shape[-1]} states on its last axis, "
                         f"expected {len(names)} ({names})")
    return {n: x[..., i] for i, n in enumerate(names)}


def _as_dict(states, options) -> dict:
    return states if isinstance(states, dict) else unpack(states, options)


def _check_finite(out: dict, what: str) -> dict:
    bad = [k for k, v in out.items() if not np.all(np.isfinite(v))]
    if bad:
        raise ArterioleError(f"arteriole {what}: non-finite {bad} (invalid states, inputs or "
                             f"parameters)")
    return out


def _bridges(s, cG, p, o):
    """(K, (M, Mp, AMp, AM)): kinetic rates and the bridge fractions (state or quasi-steady)."""
    K = kin.rate_constants(s["Ca"], cG, p, o["passive"])
    if o["kinetics"] == "dynamic":
        return K, tuple(s[n] for n in kin.STATES)
    return K, kin.quasi_steady(K)


def _evaluate(states, P, dP, params, options):
    o = resolve_options(options)
    p = effective(params)
    s = _as_dict(states, o)
    lam, Ca, Cw = s["lambda"], s["Ca"], s["Cw"]
    r = l2r(lam, p)                                   # eq l2r [m]
    Q = flow(r, dP, p)                                # eq Poiseuille, one vessel [m^3/s]
    tau = tau_hat(dP, r, p)                           # normalised shear stress [-]
    cG = cgmp(Cw, p)                                  # eq NOcGMP [M]
    K, alpha = _bridges(s, cG, p, o)
    sigma = wall_stress(P, r, p)                      # [Pa]
    Cab = np.zeros_like(sigma) if o["passive"] else ca_bar(sigma, p)   # [M]
    a, b = _dlam_affine(lam, alpha[2], alpha[3], p, o["passive"], r)
    lam_dot = a + b * P                               # eq FaNew solved for lambda_dot [1/s]
    d = {"Cw": dCw_dt(Cw, Q, r, tau, p), "lambda": lam_dot}
    if o["ca_order"] == 2:
        d["Ca"] = s["dCa"]
        d["dCa"] = d2Ca_dt2(Ca, s["dCa"], Cab, p)     # eq dCadt2 [M/s^2]
    else:
        d["Ca"] = dCa_dt_first(Ca, Cab, p)            # eq dCadt [M/s]
    if o["kinetics"] == "dynamic":
        d.update(zip(kin.STATES, kin.derivative(alpha, K)))   # eq 4state [1/s]
    ctx = dict(o=o, p=p, s=s, r=r, Q=Q, tau=tau, cG=cG, alpha=alpha, sigma=sigma, lam_dot=lam_dot)
    return {n: d[n] for n in state_names(o)}, ctx


def derivatives(states, P, dP, params, options=None) -> dict:
    """State derivatives, dict name -> array (keys = state_names(options), units = state unit/s).

    Raises ArterioleError if any is non-finite."""
    d, _ = _evaluate(states, P, dP, params, options)
    return _check_finite(d, "derivatives")


def observables(states, P, dP, params, options=None) -> dict:
    """Observables, dict name -> array, units in OBSERVABLE_UNITS.  Q is the flow of ONE vessel,
    R and V those of the bed of n vessels; F_a includes the friction term (eq FaNew)."""
    _, c = _evaluate(states, P, dP, params, options)
    p, s, r, alpha = c["p"], c["s"], c["r"], c["alpha"]
    lam = s["lambda"]
    out = {"r": r, "lambda": lam, "Ca": s["Ca"], "Cw": s["Cw"],
           "Cb_mean": cb_mean(s["Cw"], c["Q"], r, p), "cGMP": c["cG"],
           "M": alpha[0], "Mp": alpha[1], "AMp": alpha[2], "AM": alpha[3],
           "sigma": c["sigma"], "tau_hat": c["tau"], "Q": c["Q"],
           "R": resistance(r, p), "V": bed_volume(r, p),
           "F_a": active_force(lam, c["lam_dot"], alpha[2], alpha[3], p),
           "F_p": passive_force(lam, p), "dr_dt": dr_dlambda(p) * c["lam_dot"]}
    if c["o"]["ca_order"] == 2:
        out["dCa"] = s["dCa"]
    finite = {k: v for k, v in out.items() if k != "R"}   # R = inf at r = 0 is legitimate
    _check_finite(finite, "observables")
    return out


def dlambda_dt_affine(states, params, options=None):
    """(a [1/s], b [1/(s*Pa)]) with dlambda/dt = a + b P at the given states."""
    o = resolve_options(options)
    p = effective(params)
    s = _as_dict(states, o)
    _, alpha = _bridges(s, cgmp(s["Cw"], p), p, o)
    return _dlam_affine(s["lambda"], alpha[2], alpha[3], p, o["passive"])


def dr_dt_affine(states, params, options=None):
    """(a [m/s], b [m/(s*Pa)]) with dr/dt = a + b P at the given states (P intramural, Pa).

    The circuit solves the node pressures and this rate together (the bed volume flow is
    2 pi r L n dr/dt)."""
    a, b = dlambda_dt_affine(states, params, options)
    k = dr_dlambda(params)
    out = _check_finite({"a": a * k, "b": b * k}, "dr_dt_affine")
    return out["a"], out["b"]


def at_ca_floor(states, options=None):
    """True where [Ca] <= CA_FLOOR (the integrator then resets dCa/dt to 0 and continues)."""
    return np.asarray(_as_dict(states, options)["Ca"]) <= CA_FLOOR


def clip_states(states, options=None):
    """Project onto the physical domain: Ca >= CA_FLOOR and, where Ca is at the floor and
    falling, dCa/dt = 0 (second order).  Returns a copy of the same type (dict or array)."""
    o = resolve_options(options)
    if isinstance(states, dict):
        base, s = None, dict(states)
    else:
        base = np.array(states, dtype=float)
        s = unpack(base, o)  # views into the copy
    Ca = np.asarray(s["Ca"], dtype=float)
    new = {"Ca": np.maximum(Ca, CA_FLOOR)}
    if o["ca_order"] == 2:
        new["dCa"] = np.where((Ca <= CA_FLOOR) & (np.asarray(s["dCa"]) < 0), 0.0, s["dCa"])
    if base is None:
        s.update(new)
        return s
    for k, v in new.items():
        s[k][...] = v
    return base
