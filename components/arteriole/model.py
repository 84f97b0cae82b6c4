"""The active arteriole's states and options (thesis chapters 3 and 6); its equations are in
equations.py, composed per element in compiled.py.

States (``state_names``): [Ca] (M), optionally dCa/dt (M/s, second-order Ca, eq dCadt2), wall
[NO] C_w (M), normalised cell length lambda (-), optionally the bridge fractions M, Mp, AMp, AM
(kinetics 'dynamic').  States are given either as a dict name -> array or as one array whose
LAST axis holds the states in ``state_names`` order.

Options (``OPTIONS``, which the element declares too): ``ca_order`` 1 (eq dCadt) or 2 (eq dCadt2); ``kinetics``
'quasi_steady' (default, eq 4stateSS, as the thesis) or 'dynamic' (eq 4state); ``passive``
(Ca = 0 exactly in the kinetics, no myogenic drive: Ca_bar = 0; alpha -> [1,0,0,0], F_a = 0).
"""
from __future__ import annotations

import numpy as np

from hemocircuit.component import Option

from .equations import BRIDGE_STATES

OPTIONS = {"ca_order": Option(1, choices=(1, 2), kind=int, doc="first- (eq. dCadt) or second-order (eq. dCadt2) Ca"),
           "kinetics": Option("quasi_steady", choices=("quasi_steady", "dynamic"), doc="4-state kinetics"),
           "passive": Option(False, choices=(False, True), kind=bool,
                             doc="Ca = 0, no myogenic response (passive curves)")}

STATE_UNITS = {"Ca": "M", "dCa": "M/s", "Cw": "M", "lambda": "dimensionless",
               "M": "dimensionless", "Mp": "dimensionless", "AMp": "dimensionless",
               "AM": "dimensionless"}
#: natural scales (for solver tolerances).  Measured with kuo91 at 60 mmHg: Ca 4e-8..6e-8 M,
#: Cw 7e-9 M (no flow) .. 2.4e-7 M (dP = 4 cmH2O), lambda ~ 0.9, dCa ~ omega_n Ca.
STATE_SCALES = {"Ca": 1e-7, "dCa": 1e-7, "Cw": 1e-7, "lambda": 1.0,
                "M": 1.0, "Mp": 1.0, "AMp": 1.0, "AM": 1.0}


def resolve_options(options=None) -> dict:
    """The ``OPTIONS`` defaults updated with ``options``; raises ValueError on unknown keys/values."""
    o = {k: opt.default for k, opt in OPTIONS.items()}
    unknown = set(options or ()) - set(o)
    if unknown:
        raise ValueError(f"unknown arteriole option(s) {sorted(unknown)}")
    o.update(options or {})
    for k, opt in OPTIONS.items():
        if o[k] not in opt.choices:
            raise ValueError(f"arteriole option {k}={o[k]!r}: choose one of {opt.choices}")
    o["passive"] = bool(o["passive"])
    return o


def state_names(options=None) -> list[str]:
    """Ordered state names: ['Ca', ('dCa',) 'Cw', 'lambda' (, 'M', 'Mp', 'AMp', 'AM')]."""
    o = resolve_options(options)
    return ["Ca", "dCa"][:o["ca_order"]] + ["Cw", "lambda"] + (list(BRIDGE_STATES) if o["kinetics"] == "dynamic" else [])


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
