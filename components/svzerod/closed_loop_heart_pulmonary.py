"""svZeroDSolver ``ClosedLoopHeartAndPulmonary``: four chambers with valves and inductive
outflows, a pulmonary RC and the aortic capacitor (Sankaran 2012 / Menon 2023 heart model).

Equations (SimVascular/svZeroDSolver src/model/ClosedLoopHeartPulmonary.cpp, ``update_constant``,
``update_time``, ``update_solution``, ``get_activation_and_elastance_functions``,
``get_psi_ra_la``, ``get_valve_positions``, ``post_solve``); pressures relative to ``ref``:
    P_in = P_RA = AA Emax_ra (V_RA - Vaso_ra) + psi_ra (1 - AA),
           psi_ra = Kxp_ra (exp((V_RA - Vaso_ra) Kxv_ra) - 1)            (P_LA likewise, _la)
    P_RV = Erv (V_RV - Vrv_u),  P_LV = Elv (V_LV - Vlv_u),  Erv|Elv = F(t) Erv_s|Elv_s
    dV_RA = Q_in - v_RA Q_RA          Lra_v dQ_RA = P_RA - P_RV - Rra_v v_RA Q_RA
    dV_RV = v_RA Q_RA - v_RV Q_RV     Lrv_a dQ_RV = P_RV - P_pul - Rrv_a v_RV Q_RV
    Cp dP_pul = v_RV Q_RV - (P_pul - P_LA)/Rpd
    dV_LA = v_RV Q_RV - v_LA Q_LA     Lla_v dQ_LA = P_LA - P_LV - Rla_v v_LA Q_LA
    dV_LV = v_LA Q_LA - v_LV Q_LV     Llv_a dQ_LV = P_LV - P_out - Rlv_ao v_LV Q_LV
    Cpa dP_out = v_LV Q_LV - Q_out
AA: their atrial activation (the ``wrapping_cosine`` of activation.py with Tsa, tpwave); F(t):
their 25-mode Fourier series of ventricular elastance, NOT normalised (as in this block).
Valves: v = 0 (closed) while P_upstream <= P_downstream and Q <= 0, else 1; their post_solve
sets a closed valve's Q to 0.  Here Q >= 0 is a hard limit (the integration stops where Q
reaches 0 and holds it there) and v = 0 only on it (Q = 0 exactly, dP <= 0): the same on the
solution.  Below the bound (only the integrator's stages go there) the open valve is continued
smoothly, so f does not jump there (docs/svzerod.md, "Speed").
Note (theirs, kept): the left atrium fills with the right ventricle's outflow v_RV Q_RV; the
pulmonary RC only sets the back-pressure P_pul.  So the blood volume is
V_RA + V_RV + V_LA + V_LV + Cpa P_out (not Cp P_pul), which is what the stores declare.
Units: PARAMS (iml, imr, Elv_s/Erv_s, Vlv_u/Vrv_u and the state-only V_LV/V_RV are read by
the closed_loop_coronary blocks through netlist expressions).
States: V_RA, Q_RA, V_RV, Q_RV, V_pul = Cp P_pul, V_LA, Q_LA, V_LV, Q_LV, V_ao = Cpa P_out.
Local unknowns [P_in, P_out, P_ref, q_in, q_out]: branch (in, ref) P_in - P_ref = P_RA carrying
Q_in; branch (out, ref) P_out - P_ref = V_ao/Cpa carrying -Q_out.
"""
from __future__ import annotations

import numpy as np

from hemocircuit.component import Component, Observable, Param, State, Storage, batch_shape, kernel_method
from hemocircuit.derivatives import FD_REL
from hemocircuit.kernels.stamps import branch

from ..common import C_UNIT, E_UNIT, flow_observables, jit, L_UNIT, R_UNIT
from .activation import activation_breakpoints, fourier_raw, wrapping_cosine
from .chamber_elastance_inductor_exponential import atrium_pressure, atrium_slope

PARAMS = {"period": ("s", "cardiac period (their cardiac_cycle_period)"),
      "Tsa": ("dimensionless", "atrial systole fraction of the period"),
      "tpwave": ("dimensionless", "P-wave divisor of the period"),
      "Erv_s": (E_UNIT, "right ventricular elastance scale"), "Elv_s": (E_UNIT, "left ventricular elastance scale"),
      "iml": ("dimensionless", "left intramyocardial pressure scale (read by closed_loop_coronary)"),
      "imr": ("dimensionless", "right intramyocardial pressure scale (read by closed_loop_coronary)"),
      "Lra_v": (L_UNIT, "RA outflow inductance"), "Rra_v": (R_UNIT, "RA outflow resistance"),
      "Lrv_a": (L_UNIT, "RV outflow inductance"), "Rrv_a": (R_UNIT, "RV outflow resistance"),
      "Lla_v": (L_UNIT, "LA outflow inductance"), "Rla_v": (R_UNIT, "LA outflow resistance"),
      "Llv_a": (L_UNIT, "LV outflow inductance"), "Rlv_ao": (R_UNIT, "LV outflow resistance"),
      "Vrv_u": ("mL", "RV unstressed volume"), "Vlv_u": ("mL", "LV unstressed volume"),
      "Rpd": (R_UNIT, "pulmonary resistance"), "Cp": (C_UNIT, "pulmonary capacitance"),
      "Cpa": (C_UNIT, "aortic capacitance"),
      "Kxp_ra": ("mmHg", "RA passive pressure scale"), "Kxv_ra": ("1/mL", "RA passive volume exponent"),
      "Kxp_la": ("mmHg", "LA passive pressure scale"), "Kxv_la": ("1/mL", "LA passive volume exponent"),
      "Emax_ra": (E_UNIT, "RA active elastance"), "Emax_la": (E_UNIT, "LA active elastance"),
      "Vaso_ra": ("mL", "RA rest volume"), "Vaso_la": ("mL", "LA rest volume")}
_POSITIVE = {"period", "tpwave", "Tsa", "Lra_v", "Lrv_a", "Lla_v", "Llv_a", "Rpd", "Cp", "Cpa"}
_NONNEG = {"Rra_v", "Rrv_a", "Rla_v", "Rlv_ao"}

#: every state's scale [mL or mL/s]; for the valve flows it also sets the engine's difference
#: step, which heart_derivs_jac reproduces at a closed valve
Q_SCALE = 10.0
_STATES = ("V_RA", "Q_RA", "V_RV", "Q_RV", "V_pul", "V_LA", "Q_LA", "V_LV", "Q_LV", "V_ao")
(PERIOD, TSA, TPWAVE, ERV_S, ELV_S, IML, IMR, LRA_V, RRA_V, LRV_A, RRV_A, LLA_V, RLA_V, LLV_A, RLV_AO, VRV_U,
 VLV_U, RPD, CP, CPA, KXP_RA, KXV_RA, KXP_LA, KXV_LA, EMAX_RA, EMAX_LA, VASO_RA, VASO_LA) = range(len(PARAMS))


@jit
def ventricle_pressure(F, E_s, V, V_u):
    """P = F(t) E_s (V - V_u): a ventricle's pressure at the raw Fourier elastance F (also the
    intramyocardial pressure of closed_loop_coronary)."""
    return F * E_s * (V - V_u)


@jit
def _pressures(p, x, t):
    """(P_RA, P_RV, P_pul, P_LA, P_LV, P_ao) from the states at time t, and the activations
    (AA, F): their atrial activation and the raw ventricular Fourier elastance."""
    AA, F = wrapping_cosine(t, p[PERIOD], p[TSA], p[TPWAVE]), fourier_raw(np.fmod(t, p[PERIOD]), p[PERIOD])
    P_ra = atrium_pressure(AA, p[EMAX_RA], p[KXP_RA], p[KXV_RA], p[VASO_RA], x[0])
    P_la = atrium_pressure(AA, p[EMAX_LA], p[KXP_LA], p[KXV_LA], p[VASO_LA], x[5])
    P_rv = ventricle_pressure(F, p[ERV_S], x[2], p[VRV_U])
    P_lv = ventricle_pressure(F, p[ELV_S], x[7], p[VLV_U])
    return P_ra, P_rv, x[4] / p[CP], P_la, P_lv, x[9] / p[CPA], AA, F


@jit
def _valve(dp, q):
    """1 open, 0 closed: closed on the hard limit Q = 0 while the pressure difference is <= 0
    (their dp <= 0 and Q <= 0 on a solution with Q >= 0); open below the bound (see above)."""
    return 0.0 if (dp <= 0.0 and q == 0.0) else 1.0


@jit
def heart_stamp(p, x, u, t, iopt, A, b):
    # the two pressures it defines; the ventricles' Fourier elastance is not needed here
    AA = wrapping_cosine(t, p[PERIOD], p[TSA], p[TPWAVE])
    branch(A, b, 0, 2, 3, atrium_pressure(AA, p[EMAX_RA], p[KXP_RA], p[KXV_RA], p[VASO_RA], x[0]))  # P_RA
    branch(A, b, 1, 2, 4, x[9] / p[CPA])  # P_ao


@jit
def _heart(p, x, u, t, dx):
    """dx/dt into dx; returns what the partials need: the valve positions (v_ra, v_rv, v_la,
    v_lv), their pressure differences and the activations (AA, F)."""
    P_ra, P_rv, P_pul, P_la, P_lv, P_ao, AA, F = _pressures(p, x, t)
    q_ra, q_rv, q_la, q_lv = x[1], x[3], x[6], x[8]
    v_ra = _valve(P_ra - P_rv, q_ra)
    v_rv = _valve(P_rv - P_pul, q_rv)
    v_la = _valve(P_la - P_lv, q_la)
    v_lv = _valve(P_lv - P_ao, q_lv)
    dx[0] = u[3] - v_ra * q_ra
    dx[1] = v_ra * (P_ra - P_rv - p[RRA_V] * q_ra) / p[LRA_V]
    dx[2] = v_ra * q_ra - v_rv * q_rv
    dx[3] = v_rv * (P_rv - P_pul - p[RRV_A] * q_rv) / p[LRV_A]
    dx[4] = v_rv * q_rv - (P_pul - P_la) / p[RPD]
    dx[5] = v_rv * q_rv - v_la * q_la
    dx[6] = v_la * (P_la - P_lv - p[RLA_V] * q_la) / p[LLA_V]
    dx[7] = v_la * q_la - v_lv * q_lv
    dx[8] = v_lv * (P_lv - P_ao - p[RLV_AO] * q_lv) / p[LLV_A]
    dx[9] = v_lv * q_lv + u[4]
    return v_ra, v_rv, v_la, v_lv, P_ra - P_rv, P_rv - P_pul, P_la - P_lv, P_lv - P_ao, AA, F


@jit
def heart_derivs(p, x, u, t, iopt, dx):
    _heart(p, x, u, t, dx)


@jit
def _valve_row(Jx, i, q, v, dp, R, L, up, a_up, down, a_down):
    """Row i (dQ/dt = v (P_up - P_down - R Q) / L) of a valve's flow Q = x[q]; a_up, a_down: the
    pressures' slopes in the states up, down.  d/dQ: -R/L while open; for a closed valve (v = 0
    on its bound Q = 0) the engine's forward quotient (dp - R h) / (L h), h = FD_REL Q_SCALE (f
    jumps at Q = h; this entry keeps the Rosenbrock stages of a closed valve on its bound:
    docs/performance.md)."""
    Jx[i, up] = v * a_up / L
    Jx[i, down] = -v * a_down / L
    if v != 0.0:
        Jx[i, q] = -R / L
    else:
        h = FD_REL * Q_SCALE
        Jx[i, q] = (dp - R * h) / (L * h)


@jit
def heart_derivs_jac(p, x, u, t, iopt, dx, Jx, Ju):
    """heart_derivs and its partials Jx (10, 10), Ju (10, 5) (the equations above).  A valve's
    flow enters every balance through v Q, and v = 1 wherever Q > 0, so d(v Q)/dQ = 1 on the
    feasible side Q >= 0, open or closed."""
    v_ra, v_rv, v_la, v_lv, dp_ra, dp_rv, dp_la, dp_lv, AA, F = _heart(p, x, u, t, dx)
    for i in range(10):
        for k in range(10):
            Jx[i, k] = 0.0
        for k in range(5):
            Ju[i, k] = 0.0
    a_ra = atrium_slope(AA, p[EMAX_RA], p[KXP_RA], p[KXV_RA], p[VASO_RA], x[0])
    a_la = atrium_slope(AA, p[EMAX_LA], p[KXP_LA], p[KXV_LA], p[VASO_LA], x[5])
    a_rv, a_lv = F * p[ERV_S], F * p[ELV_S]
    a_pul, a_ao = 1.0 / p[CP], 1.0 / p[CPA]
    Ju[0, 3] = 1.0  # dV_RA = Q_in - v_RA Q_RA
    Jx[0, 1] = -1.0
    _valve_row(Jx, 1, 1, v_ra, dp_ra, p[RRA_V], p[LRA_V], 0, a_ra, 2, a_rv)
    Jx[2, 1], Jx[2, 3] = 1.0, -1.0  # dV_RV = v_RA Q_RA - v_RV Q_RV
    _valve_row(Jx, 3, 3, v_rv, dp_rv, p[RRV_A], p[LRV_A], 2, a_rv, 4, a_pul)
    Jx[4, 3] = 1.0  # dV_pul = v_RV Q_RV - (P_pul - P_LA) / Rpd
    Jx[4, 4] = -a_pul / p[RPD]
    Jx[4, 5] = a_la / p[RPD]
    Jx[5, 3], Jx[5, 6] = 1.0, -1.0  # dV_LA = v_RV Q_RV - v_LA Q_LA
    _valve_row(Jx, 6, 6, v_la, dp_la, p[RLA_V], p[LLA_V], 5, a_la, 7, a_lv)
    Jx[7, 6], Jx[7, 8] = 1.0, -1.0  # dV_LV = v_LA Q_LA - v_LV Q_LV
    _valve_row(Jx, 8, 8, v_lv, dp_lv, p[RLV_AO], p[LLV_A], 7, a_lv, 9, a_ao)
    Jx[9, 8] = 1.0  # dV_ao = v_LV Q_LV - Q_out
    Ju[9, 4] = 1.0
    return 1


@jit
def heart_observe(p, x, iopt, out):
    out[0] = x[0] + x[2] + x[5] + x[7]
    out[1] = x[9]
    out[2] = x[2]
    out[3] = x[7]


@jit
def heart_report(p, x, u, t, iopt, out):
    heart_observe(p, x, iopt, out)  # V_heart, V_ao, V_RV, V_LV
    P_ra, out[4], out[5], out[6], out[7], P_ao, AA, F = _pressures(p, x, t)  # P_RV, P_pul, P_LA, P_LV
    out[8] = u[3]  # Q_in
    out[9] = -u[4]  # Q_out


class ClosedLoopHeartAndPulmonary(Component):
    type_name = "closed_loop_heart_pulmonary"
    svzerod_blocks = ("ClosedLoopHeartAndPulmonary",)
    terminals = ("in", "out", "ref")
    parameters = {k: Param(u, lower=0.0 if (k in _POSITIVE or k in _NONNEG) else None,
                           lower_open=k in _POSITIVE, doc=d) for k, (u, d) in PARAMS.items()}
    time_dependent = True
    kernel = kernel_method(heart_stamp, heart_derivs, heart_observe, ("V_heart", "V_ao", "V_RV", "V_LV"), derivs_jac=heart_derivs_jac, report=heart_report)
    BRANCHES = (("in", "ref"), ("out", "ref"))
    EDGES = (("in", "ref", "pressure"), ("out", "ref", "pressure"))
    STATES = tuple(State(s, "mL" if s[0] == "V" else "mL/s", Q_SCALE, d) for s, d in zip(_STATES, (
          "right atrial volume", "right atrial outflow (tricuspid)", "right ventricular volume",
          "right ventricular outflow (pulmonary valve)", "pulmonary capacitor charge Cp P_pul",
          "left atrial volume", "left atrial outflow (mitral)", "left ventricular volume",
          "left ventricular outflow (aortic valve)", "aortic capacitor volume Cpa P_out")))
    STORAGES = (Storage("in", "ref", "V_heart"), Storage("out", "ref", "V_ao", state="V_ao"))
    OBSERVABLES = (Observable("V_heart", "mL", "volume of the four chambers", state_only=True),
                   Observable("V_ao", "mL", "aortic capacitor volume", state_only=True),
                   Observable("V_RV", "mL", "right ventricular volume (read by closed_loop_coronary)", state_only=True),
                   Observable("V_LV", "mL", "left ventricular volume (read by closed_loop_coronary)", state_only=True),
                   Observable("P_RV", "mmHg", "right ventricular pressure"),
                   Observable("P_pul", "mmHg", "pulmonary pressure"),
                   Observable("P_LA", "mmHg", "left atrial pressure"),
                   Observable("P_LV", "mmHg", "left ventricular pressure"),
                   *flow_observables("the right atrium", "the aortic capacitor"))

    def breakpoints(self, p, t0, t1):
        """The atrial activation's kinks (wrapping_cosine; the ventricles' Fourier series is
        smooth): steps end there."""
        return activation_breakpoints("wrapping_cosine", p, t0, t1)

    def hard_limits(self):
        """A valve's flow never falls below 0 (their post_solve zeroes a closed valve's flow):
        the integration stops there and holds it on 0 while the valve stays closed."""
        return tuple((q, 0.0, None) for q in ("Q_RA", "Q_RV", "Q_LA", "Q_LV"))

    def volume_observables(self):
        """Two stores: the chambers' volume is V(CLH), the aortic capacitor's CLH.V_ao (one
        V(ID) column cannot hold both)."""
        return ("V_heart",)

    def initial_states(self, p, u, flows=None, x=None):
        out = np.zeros(batch_shape(p, u.shape[:-1]) + (10,))
        for name, k in (("Vaso_ra", 0), ("Vrv_u", 2), ("Vaso_la", 5), ("Vlv_u", 7)):
            out[..., k] = p[name]
        out[..., 9] = p["Cpa"] * (u[..., 1] - u[..., 2])
        return out

