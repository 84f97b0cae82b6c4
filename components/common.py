"""Shared pieces of the bundled component types: kernel declarations, units, the stenosis
branch of the svZeroDSolver vessels (components/svzerod/).  The stamps every type builds on
are hemocircuit.kernels.stamps; the declarative structure, ``kernel_method`` and the DC-guess
stamps are hemocircuit.component's.

Their vessels carry a flow-dependent stenosis resistance: pressure drop (R + S|q|) q
(svZeroDSolver src/model/BloodVessel.cpp, "stenosis_resistance = stenosis_coeff * fabs(q_in)").
In the nodal equations this is a branch row  P_a - P_b - f(q) = rhs, linearised at the
current iterate q0 (f'(q0) = R + 2 S |q0|).
"""
from __future__ import annotations

import numpy as np

from hemocircuit.component import Observable
from hemocircuit.kernels.jit import njit

jit = njit(cache=True, nogil=True, error_model="numpy", _nrt=False)  # numba imported on first use

#: units of the blocks' parameters (the circuit's units: mmHg, mL, s)
R_UNIT = "mmHg*s/mL"
C_UNIT = "mL/mmHg"
L_UNIT = "mmHg*s**2/mL"
S_UNIT = "mmHg*s**2/mL**2"
E_UNIT = "mmHg/mL"


def flow_observables(into="the inlet", out="the outlet"):
    """The observables Q_in (flow into ``into``) and Q_out (flow out of ``out``) [mL/s]."""
    return (Observable("Q_in", "mL/s", f"flow into {into}"), Observable("Q_out", "mL/s", f"flow out of {out}"))


@jit
def observe_first_state(p, x, iopt, out):
    """``observe`` of the types whose one state-only observable is their first state."""
    out[0] = x[0]


def check_rmin_rmax(comp, p):
    """The valves' ``check`` method: Rmin <= Rmax."""
    bad = np.any(p["Rmax"] < p["Rmin"], axis=tuple(range(np.ndim(p["Rmin"]) - 1)))
    return [(int(i), "needs Rmin <= Rmax") for i in np.nonzero(np.atleast_1d(bad))[0]]


@jit
def stenosis_drop(R, S, q):
    """f(q) = (R + S|q|) q: the pressure drop of a resistance R with stenosis coefficient S."""
    return (R + S * abs(q)) * q


@jit
def stenosis_linearised(R, S, q0):
    """(slope, offset) of f(q) = (R + S|q|) q linearised at q0: f ~ slope q + offset."""
    a = abs(q0)
    return R + 2.0 * S * a, -S * a * q0
