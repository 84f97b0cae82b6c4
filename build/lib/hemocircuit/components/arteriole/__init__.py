"""Active arteriole element: pure, vectorised physics (thesis chapters 3, 4 and 6).

Sub-models: parameters (presets, units, no_speed), geometry, no_transport (NO model),
cgmp (NO -> cGMP and the 5 %/95 % sigmoid), myogenic (stress -> Ca, Ca dynamics),
kinetics (4-state cross-bridges), mechanics (forces, dlambda/dt), model (states, derivatives,
observables), steady_state (equilibria), lee97 (phosphorylation curves).  SI throughout.
"""
from . import cgmp, geometry, kinetics, lee97, mechanics, model, myogenic, no_transport, parameters, steady_state
from .model import (DEFAULT_OPTIONS, OBSERVABLE_UNITS, STATE_SCALES, STATE_UNITS, ArterioleError,
                    at_ca_floor, clip_states, derivatives, dlambda_dt_affine, dr_dt_affine,
                    observables, pack, resolve_options, state_names, state_scales, unpack)
from .myogenic import CA_FLOOR
from .parameters import PARAMETERS, PRESETS, effective, make_params, check_params
from .steady_state import SteadyStateWarning, solve_steady

__all__ = [
    "cgmp", "geometry", "kinetics", "lee97", "mechanics", "model", "myogenic", "no_transport",
    "parameters", "steady_state", "DEFAULT_OPTIONS", "OBSERVABLE_UNITS", "STATE_SCALES",
    "STATE_UNITS", "ArterioleError", "at_ca_floor", "clip_states", "derivatives",
    "dlambda_dt_affine", "dr_dt_affine", "observables", "pack", "resolve_options", "state_names",
    "state_scales", "unpack", "CA_FLOOR", "PARAMETERS", "PRESETS", "effective", "make_params",
    "check_params", "SteadyStateWarning", "solve_steady",
]
from .element import Arteriole  # noqa: E402,F401  (the circuit element)
