"""svZeroDSolver ``CORONARY_VAR_RES`` boundary condition: the open-loop coronary (``CORONARY``)
with a time-varying microvascular resistance Ram(t) (Yong et al. 2025).

Equations (SimVascular/svZeroDSolver src/model/OpenLoopCoronaryVarResBC.cpp ``get_Ram``, used
by OpenLoopCoronaryBC.cpp ``update_time`` in place of the constant Ra2): with
t_c = fmod(t, T) and the cardiac period T,
    e(t) = (1 - cos(pi t_c / T_vc)) / 2                 0 <= t_c <= T_vc      (contraction)
         = (1 + cos(pi (t_c - T_vc) / T_vr)) / 2        T_vc < t_c <= T_vc + T_vr (relaxation)
         = 0                                            later
    Ram(t) = (sqrt(Ra2_min) + (sqrt(Ra2_max) - sqrt(Ra2_min)) e(t))^2
and otherwise the circuit of ``coronary_bc`` (their equations are algebraic in Ram, so the
instantaneous Ram(t) simply replaces Ra2):
    Ca dP_a/dt = Q_in - (P_a - P_im)/Ram(t),  Cc d(P_im - Pim)/dt = (P_a - P_im)/Ram(t) - (P_im - P_v)/Rv1
Their steady-initial equations use Ram(0) = Ra2_min (e(0) = 0), as does ``dc_stamp`` here.
Units: Ra1, Ra2_min, Ra2_max, Rv1 [mmHg*s/mL], Ca, Cc [mL/mmHg], Pim, P_v [mmHg], T_vc, T_vr,
period [s].  States V_a = Ca P_a, V_im = Cc (P_im - Pim) [mL] (physical volumes, as coronary_bc).
"""
from __future__ import annotations

import math

import numpy as np

from hemocircuit.component import Observable, Param, kernel_method, periodic_breakpoints

from ..common import jit, R_UNIT
from .coronary_bc import CoronaryBC, coronary_balance, coronary_stamp


@jit
def var_resistance(t, T, Rmin, Rmax, T_vc, T_vr):
    """Ram(t) [mmHg*s/mL] of their get_Ram."""
    tc = np.fmod(t, T)
    if tc <= T_vc:
        e = 0.5 * (1.0 - math.cos(math.pi * tc / T_vc))
    elif tc <= T_vc + T_vr:
        e = 0.5 * (1.0 + math.cos(math.pi * (tc - T_vc) / T_vr))
    else:
        e = 0.0
    r = math.sqrt(Rmin) + (math.sqrt(Rmax) - math.sqrt(Rmin)) * e
    return r * r


# --- the equations: p = [Ra1, Ra2_min, Rv1, Ca, Cc, Pim, P_v, Ra2_max, T_vc, T_vr, period];
# states [V_a, V_im]; the stamp is coronary_bc's
@jit
def _ram(p, t):
    return var_resistance(t, p[10], p[1], p[7], p[8], p[9])


@jit
def coronary_var_res_derivs(p, x, u, t, iopt, dx):
    coronary_balance(p, x, u, _ram(p, t), dx)


@jit
def coronary_var_res_report(p, x, u, t, iopt, out):
    out[0] = u[2]  # Q_in
    out[1] = _ram(p, t) + 0.0 * u[2]


class CoronaryVarResBC(CoronaryBC):
    type_name = "coronary_var_res_bc"
    svzerod_blocks = ("CORONARY_VAR_RES",)
    # the first seven in coronary_bc's order (its compiled stamp reads p[0] = Ra1, p[3] = Ca)
    parameters = {"Ra1": Param(R_UNIT, lower=0.0, doc="arterial resistance"),
                  "Ra2_min": Param(R_UNIT, lower=0.0, lower_open=True, doc="minimum microvascular resistance"),
                  **{k: CoronaryBC.parameters[k] for k in ("Rv1", "Ca", "Cc", "Pim", "P_v")},
                  "Ra2_max": Param(R_UNIT, lower=0.0, lower_open=True, doc="maximum microvascular resistance"),
                  "T_vc": Param("s", lower=0.0, lower_open=True, doc="contraction time"),
                  "T_vr": Param("s", lower=0.0, lower_open=True, doc="relaxation time"),
                  "period": Param("s", default="1 s", lower=0.0, lower_open=True, doc="cardiac period T")}
    time_dependent = True
    kernel = kernel_method(coronary_stamp, coronary_var_res_derivs, report=coronary_var_res_report)

    def observables(self):
        return super().observables() + (Observable("Ram", "mmHg*s/mL", "microvascular resistance Ram(t)"),)

    def breakpoints(self, p, t0, t1):
        """Where Ram(t)'s pieces meet (its second derivative jumps): each period's start, T_vc
        and T_vc + T_vr; steps end there."""
        return periodic_breakpoints(lambda T, a: [0.0, a["T_vc"], a["T_vc"] + a["T_vr"]], p, ("T_vc", "T_vr"), t0, t1)

    def dc_stamp(self, p, A_loc, b_loc, keep):
        return super().dc_stamp({**p, "Ra2": p["Ra2_min"]}, A_loc, b_loc, keep)

    def initial_states(self, p, u, flows=None, x=None):
        return super().initial_states({**p, "Ra2": p["Ra2_min"]}, u, flows, x)
