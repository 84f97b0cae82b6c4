"""Active arteriole element (thesis chapters 3, 4 and 6), SI throughout.

equations (each equation of the vessel, once: geometry, NO transport, cGMP, myogenic Ca,
cross-bridge kinetics, mechanics), compiled (the element's kernel functions composed from
them), parameters (presets, units, no_speed), model (states and options), steady_state
(equilibria), element (the circuit element).
"""
from . import compiled, equations, model, parameters, steady_state
from .equations import CA_FLOOR
from .model import OPTIONS, STATE_SCALES, STATE_UNITS, pack, resolve_options, state_names, unpack
from .parameters import PARAMETERS, PRESETS, make_params, check_params
from .steady_state import SteadyStateWarning, solve_steady

__all__ = ["compiled", "equations", "model", "parameters", "steady_state", "OPTIONS", "STATE_SCALES", "STATE_UNITS",
           "pack", "resolve_options", "state_names", "unpack", "CA_FLOOR", "PARAMETERS", "PRESETS", "make_params",
           "check_params", "SteadyStateWarning", "solve_steady"]
from .element import Arteriole  # noqa: E402,F401  (the circuit element)
