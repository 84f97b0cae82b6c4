"""The ``arteriole`` element's kernel functions (hemocircuit.kernels contract): its equations
(equations.py, each written once) composed for one element, in the circuit's units at the
boundary (hemocircuit.units: mmHg, mL, s outside; Pa, m, N, s, M inside).

``p``: the element's parameters in the order of ``Arteriole.parameters`` (= PARAMETERS), raw:
``no_speed`` (sec. dynfitting) is applied here (equations.no_rates).
``x``: states [Ca, (dCa,) Cw, lambda (, M, Mp, AMp, AM)] (model.state_names).
``iopt`` (``Arteriole.kernel_options``), int64:
    [0] ca_order        1 (eq dCadt) or 2 (eq dCadt2)
    [1] kinetics        0 quasi_steady (eq 4stateSS), 1 dynamic (eq 4state)
    [2] passive         0 / 1
    [3] volume_flow     0: local unknowns [in, out, ref]; 1: [in, out, ref, mid]
    [4] pim_reference   0 'gauge', 1 'ref'
Non-finite results propagate as NaN/inf (the callers check finiteness).
"""
from __future__ import annotations

import math

from hemocircuit.kernels.jit import equation, njit
from hemocircuit.units import M3_PER_ML, PA_PER_MMHG
from hemocircuit.kernels.stamps import conductance


from .equations import (C_IN, CA_FLOOR, DP0, ETA, F1, F2, GAMMA_WB, K3, K4, K7, K_CA1, K_CA2, K_CGMP, L0, L_VES,
                        LAMBDA_OPT, LN10, MAX_EXP, MU_B, N_CA1, N_CA2, N_CGMP, N_VES, NO_L, NO_U, OMEGA_N,
                        PCA_L, PCA_U, PCGMP_L, PCGMP_U, PSI_SERIES_X, Q1, Q2, Q3, R0, R_DB, SIGMA_L, SIGMA_U, T_W,
                        TAU_CA, V_XB, W_C, ZETA, active_force, bed_volume, ca_bar, cb_inf, cb_mean, cgmp, d2Ca,
                        dCa_first, dCw, dlam_affine, dr_dlambda, flow, friction, kinetics, l2r, no_loss, no_rates,
                        overlap, passive_force, psi, qs_numerators, quasi_steady, rates, resistance,
                        sigmoid_fraction, tau_hat, transport_number, wall_area, wall_stress)

# --- iopt slots ---------------------------------------------------------------------------
OPT_CA_ORDER, OPT_DYNAMIC, OPT_PASSIVE, OPT_VOLUME_FLOW, OPT_PIM_REF = 0, 1, 2, 3, 4

_PI = math.pi
_R_FACTOR = M3_PER_ML / PA_PER_MMHG   # Pa*s/m^3 -> mmHg*s/mL

# the contract functions compile on their own (hemocircuit.elementwise runs them compiled for
# large batches); the helpers are equations, run as Python whenever Python calls them
_jit = njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
_eq = equation(cache=True, nogil=True, error_model="numpy", _nrt=False)


@_eq
def pressures(u, iopt):
    """(P_im, dP) [Pa] from local pressures [mmHg] (eqs Pab2Pim, Pab2DP): the boundary between
    the circuit's units and the arteriole's.  From Python ``u`` may be (L, ...) arrays."""
    P_im = 0.5 * (u[0] + u[1])
    if iopt[OPT_PIM_REF] != 0:
        P_im = P_im - u[2]
    return P_im * PA_PER_MMHG, (u[0] - u[1]) * PA_PER_MMHG


@_eq
def _bridges(x, p, iopt):
    """(K1, K2, M, Mp, AMp, AM): the kinetic rates (eqs NOcGMP, phos, dephos) and the bridge
    fractions, states (eq 4state) or quasi-steady (eq 4stateSS)."""
    j = 2 if iopt[OPT_CA_ORDER] == 2 else 1   # index of Cw in x
    K1, K2 = rates(x[0], cgmp(x[j], p), p, iopt[OPT_PASSIVE] != 0)
    if iopt[OPT_DYNAMIC] != 0:
        return K1, K2, x[j + 2], x[j + 3], x[j + 4], x[j + 5]
    M, Mp, AMp, AM = quasi_steady(K1, K2, p)
    return K1, K2, M, Mp, AMp, AM


# --- the contract -------------------------------------------------------------------------
@_jit
def stamp(p, x, u, t, iopt, A, b):
    """Local MNA stamp; A, b arrive zeroed."""
    j = 2 if iopt[OPT_CA_ORDER] == 2 else 1
    r = l2r(x[j + 1], p)
    g = 1.0 / (resistance(r, p) * _R_FACTOR)   # eq Rsa: conductance of the bed [mL/s per mmHg]
    if iopt[OPT_VOLUME_FLOW] == 0:
        conductance(A, 0, 1, g)  # section artComp: a variable resistor in -> out; ref carries no flow
        return
    # section autoregFirst: halves R/2 in -> mid -> out; local nodes in 0, out 1, ref 2, mid 3
    conductance(A, 0, 3, 2.0 * g)
    conductance(A, 3, 1, 2.0 * g)
    # eqs Vsa, dVsadt: q_v = 2 pi r L n dr/dt leaves mid into ref, dr/dt = (a + b P_im) dr/dlambda
    _, _, _, _, AMp, AM = _bridges(x, p, iopt)
    da, db = dlam_affine(x[j + 1], r, AMp, AM, p, iopt[OPT_PASSIVE] != 0)   # eq FaNew solved for lambda_dot
    k_r = dr_dlambda(p)
    k = 2 * _PI * r * p[L_VES] * p[N_VES] / M3_PER_ML   # mL per m of radius
    c0 = k * (da * k_r)                       # mL/s
    c1 = k * (db * k_r) * PA_PER_MMHG         # mL/s per mmHg of P_im (eq Pab2Pim)
    w = c1 * 0.5
    A[3, 0] += w
    A[2, 0] -= w
    A[3, 1] += w
    A[2, 1] -= w
    if iopt[OPT_PIM_REF] != 0:
        A[3, 2] += -c1
        A[2, 2] -= -c1
    b[3] = -c0
    b[2] = c0


@_jit
def derivs(p, x, u, t, iopt, dx):
    """dx/dt in the states' units per second."""
    j = 2 if iopt[OPT_CA_ORDER] == 2 else 1
    Ca, Cw, lam = x[0], x[j], x[j + 1]
    P, dP = pressures(u, iopt)
    h_w, r_dw, s_w, k_tau = no_rates(p)
    r = l2r(lam, p)                                             # eq l2r [m]
    Q = flow(r, dP, p)                                          # eq Poiseuille, one vessel
    K1, K2, M, Mp, AMp, AM = _bridges(x, p, iopt)
    Cab = 0.0 if iopt[OPT_PASSIVE] != 0 else ca_bar(wall_stress(P, r, p), p)   # eq ssCa; 0 when passive
    a, bb = dlam_affine(lam, r, AMp, AM, p, iopt[OPT_PASSIVE] != 0)
    cbm = cb_mean(Cw, r, transport_number(Q, r, h_w, p), h_w, p)   # eqs cbbar, cbbarpsi, psi
    if iopt[OPT_CA_ORDER] == 2:
        dx[0] = x[1]
        dx[1] = d2Ca(Ca, x[1], Cab, p)                          # eq dCadt2
    else:
        dx[0] = dCa_first(Ca, Cab, p)                           # eq dCadt
    dx[j] = dCw(Cw, cbm, tau_hat(dP, r, p), h_w, r_dw, s_w, k_tau, p)   # eq dNOdt
    dx[j + 1] = a + bb * P                                      # eq FaNew solved for lambda_dot
    if iopt[OPT_DYNAMIC] != 0:
        dx[j + 2], dx[j + 3], dx[j + 4], dx[j + 5] = kinetics(K1, K2, M, Mp, AMp, AM, p)   # eq 4state


@_eq
def _state_part(p, x, iopt, out):
    """r [um], lambda, Ca [M], (dCa [M/s],) Cw [M] into out; returns (r [m], the next index)."""
    j = 2 if iopt[OPT_CA_ORDER] == 2 else 1
    r = l2r(x[j + 1], p)
    out[0] = r * 1e6
    out[1] = x[j + 1]
    out[2] = x[0]
    if j == 2:
        out[3] = x[1]
    out[j + 2] = x[j]
    return r, j + 3


@_jit
def observe(p, x, iopt, out):
    """State-only observables in the order of ``observables(ca_order)``, circuit units (element._OBS)."""
    r, i = _state_part(p, x, iopt, out)
    Cw = out[i - 1]
    out[i] = resistance(r, p) * _R_FACTOR                      # eq Rsa
    out[i + 1] = bed_volume(r, p) / M3_PER_ML                  # eq Vsa
    h_w = no_rates(p)[0]
    out[i + 2] = cb_inf(Cw, r, h_w, p)                          # eqs cbbar, cinv
    out[i + 3] = no_loss(r, h_w, p)                             # exponent of eq cinv [m^2/s]


@_jit
def report(p, x, u, t, iopt, out):
    """Every observable in the order of ``Arteriole.observables()``, circuit units (element._OBS)."""
    r, i = _state_part(p, x, iopt, out)
    Cw, lam = out[i - 1], out[1]
    P, dP = pressures(u, iopt)
    h_w = no_rates(p)[0]
    Q = flow(r, dP, p)
    _, _, M, Mp, AMp, AM = _bridges(x, p, iopt)
    a, bb = dlam_affine(lam, r, AMp, AM, p, iopt[OPT_PASSIVE] != 0)
    R = resistance(r, p) * _R_FACTOR
    out[i] = cb_mean(Cw, r, transport_number(Q, r, h_w, p), h_w, p)
    out[i + 1] = cgmp(Cw, p)
    out[i + 2] = M
    out[i + 3] = Mp
    out[i + 4] = AMp
    out[i + 5] = AM
    out[i + 6] = wall_stress(P, r, p)
    out[i + 7] = tau_hat(dP, r, p)
    out[i + 8] = Q * p[N_VES] / M3_PER_ML
    out[i + 9] = R
    out[i + 10] = bed_volume(r, p) / M3_PER_ML
    out[i + 11] = active_force(a + bb * P, AMp, AM, overlap(lam, p), p)
    out[i + 12] = passive_force(lam, p)
    if iopt[OPT_VOLUME_FLOW] != 0:   # the outlet half R/2 from mid
        out[i + 13] = 2.0 * (u[3] - u[1]) / R
    else:
        out[i + 13] = (u[0] - u[1]) / R
    out[i + 14] = cb_inf(Cw, r, h_w, p)
    out[i + 15] = no_loss(r, h_w, p)


def observables(ca_order: int) -> tuple:
    """Names written by ``observe`` for this ca_order (the state-only observables of the element)."""
    return ("r", "lambda", "Ca") + (("dCa",) if ca_order == 2 else ()) + ("Cw", "R", "V", "Cb_inf", "k_NO")


# --- analytic partial derivatives (the engine's element-local Jacobian) -------------------
# The values come from the equations above; these functions add only their derivatives.
@_eq
def _sigmoid_slope(x, x_L, x_U, y_L, y_U):
    """d/dx of equations.sigmoid_5_95: (y_U - y_L) s (1 - s) / k_z."""
    s, k_z = sigmoid_fraction(x, x_L, x_U)
    return (y_U - y_L) * s * (1.0 - s) / k_z


@_eq
def _rates_d(Ca, Cw, p):
    """(K1, K2, dK1/dCa, dK2/dCa, dK2/dCw) of equations.rates (not passive)."""
    cG = cgmp(Cw, p)
    dcG = cG * LN10 * _sigmoid_slope(Cw, p[NO_L], p[NO_U], p[PCGMP_L], p[PCGMP_U])
    K1, K2 = rates(Ca, cG, p, False)
    floor = Ca < CA_FLOOR
    Cac = CA_FLOOR if floor else Ca
    z1 = (p[K_CA1] / Cac) ** p[N_CA1]
    z2 = (Cac / p[K_CA2]) ** p[N_CA2]
    ci = 1.0 / (1.0 + z2)
    dK1 = 0.0 if floor else K1 * K1 * p[N_CA1] * z1 / Cac
    dci = 0.0 if floor else -ci * ci * p[N_CA2] * z2 / Cac
    cg = 0.0 if cG < 0.0 else cG
    z3 = (p[K_CGMP] / cg) ** p[N_CGMP]
    act = 1.0 / (1.0 + z3)
    dact = act * act * p[N_CGMP] * z3 / cg if cg > 0.0 else 0.0
    return K1, K2, dK1, 2.0 * act * dci, 2.0 * ci * dact * dcG


@_eq
def _quasi_steady_d(a, b, p):
    """(AMp, AM, dAMp/da, dAMp/db, dAM/da, dAM/db) of equations.quasi_steady (fractions N_i / s)."""
    k3, k4, k7 = p[K3], p[K4], p[K7]
    M, Mp, AMp, AM = qs_numerators(a, b, p)
    s = M + Mp + AMp + AM
    dM_a, dM_b = b * k4, a * k4 + k3 * k7 + 2.0 * b * k7 + k4 * k7
    dMp_a, dMp_b = 2.0 * a * k4 + b * k7 + k4 * k7, a * k7
    dAMp_a, dAMp_b = k3 * (2.0 * a + k7), 0.0
    dAM_a, dAM_b = b * k3, a * k3
    ds_a = dM_a + dMp_a + dAMp_a + dAM_a
    ds_b = dM_b + dMp_b + dAMp_b + dAM_b
    fAMp, fAM = AMp / s, AM / s
    return (fAMp, fAM, (dAMp_a - fAMp * ds_a) / s, (dAMp_b - fAMp * ds_b) / s,
            (dAM_a - fAM * ds_a) / s, (dAM_b - fAM * ds_b) / s)


@_jit
def derivs_jac(p, x, u, t, iopt, dx, Jx, Ju):
    """dx/dt (``derivs``) and its partial derivatives, Jx[i, k] = d dx_i / d x_k (S, S) and
    Ju[i, k] = d dx_i / d u_k (S, L, u in mmHg), by the chain rule through the same equations
    (eqs l2r, Poiseuille, NOcGMP, phos, dephos, 4stateSS / 4state, ssCa, FaNew, passiveNew,
    dNOdt, dCadt / dCadt2).  Returns 1, or 0 for a passive arteriole (the engine then
    differences ``derivs``).  At the clips (Ca at CA_FLOOR, the passive-force exponent cap,
    Q = 0) it gives the one-sided derivative of the branch taken."""
    ca_order = iopt[OPT_CA_ORDER]
    dynamic = iopt[OPT_DYNAMIC] != 0
    if iopt[OPT_PASSIVE] != 0:
        return 0
    derivs(p, x, u, t, iopt, dx)
    j = 2 if ca_order == 2 else 1
    S = j + (6 if dynamic else 2)  # states Ca, (dCa,) Cw, lambda (, M, Mp, AMp, AM)
    Lu = 4 if iopt[OPT_VOLUME_FLOW] != 0 else 3
    for i in range(S):
        for k in range(S):
            Jx[i, k] = 0.0
        for k in range(Lu):
            Ju[i, k] = 0.0
    Ca, Cw, lam = x[0], x[j], x[j + 1]
    P, dP = pressures(u, iopt)
    h_w, r_dw, s_w, k_tau = no_rates(p)
    kr = dr_dlambda(p)
    r = l2r(lam, p)
    c_q = _PI / (8.0 * p[MU_B] * p[L_VES])
    Q = flow(r, dP, p)
    dQ_r = 4.0 * c_q * r ** 3.0 * dP
    dQ_dP = c_q * r ** 4.0
    dtau_r = (abs(dP) / p[DP0]) / p[R0]
    sgn_dP = 1.0 if dP > 0.0 else (-1.0 if dP < 0.0 else 0.0)
    dtau_dP = sgn_dP / p[DP0] * (r / p[R0])

    K1, K2, dK1_Ca, dK2_Ca, dK2_Cw = _rates_d(Ca, Cw, p)
    if dynamic:
        M, Mp, AMp, AM = x[j + 2], x[j + 3], x[j + 4], x[j + 5]
        # d(AMp, AM)/d(Ca, Cw) = 0: they are states
        dAMp_Ca = dAMp_Cw = dAM_Ca = dAM_Cw = 0.0
    else:
        AMp, AM, dAMp_a, dAMp_b, dAM_a, dAM_b = _quasi_steady_d(K1, K2, p)
        dAMp_Ca = dAMp_a * dK1_Ca + dAMp_b * dK2_Ca
        dAMp_Cw = dAMp_b * dK2_Cw
        dAM_Ca = dAM_a * dK1_Ca + dAM_b * dK2_Ca
        dAM_Cw = dAM_b * dK2_Cw

    # Ca_bar(sigma), sigma = P r / t_w (eq ssCa)
    sigma = wall_stress(P, r, p)
    dCab_sigma = ca_bar(sigma, p) * LN10 * _sigmoid_slope(sigma, p[SIGMA_L], p[SIGMA_U], p[PCA_L], p[PCA_U])
    dCab_lam = dCab_sigma * P / p[T_W] * kr
    dCab_P = dCab_sigma * r / p[T_W]

    # lambda_dot = N / D (eq FaNew with eqs FT, FMFP, passiveNew): equations.dlam_affine
    G = overlap(lam, p)
    dG = -G * (lam - p[LAMBDA_OPT]) / p[ETA]
    lm = 0.0 if lam < 0.0 else lam
    z = p[Q2] * (lm ** p[Q3] - 1.0)
    dFp = 0.0 if (z > MAX_EXP or lam <= 0.0) else p[Q1] * math.exp(z) * p[Q2] * p[Q3] * lm ** (p[Q3] - 1.0)
    f1v = p[F1] * p[V_XB]
    D = friction(lam, AMp, AM, p, False)
    a_l, b_l = dlam_affine(lam, r, AMp, AM, p, False)
    lam_dot = a_l + b_l * P
    dN_lam = -(dFp + f1v * AMp * dG) + p[W_C] * kr * P
    dD_lam = p[L0] * dG * (p[F1] * AMp + p[F2] * AM)
    dld_lam = (dN_lam - lam_dot * dD_lam) / D
    dld_AMp = (-f1v * G - lam_dot * (p[L0] * G * p[F1])) / D
    dld_AM = -lam_dot * (p[L0] * G * p[F2]) / D
    dld_P = b_l

    # eq dNOdt with eqs cbbar, cbbarpsi, psi
    Aw = wall_area(p)
    kk = no_loss(r, h_w, p)
    dkk_r = p[R_DB] * 2.0 * _PI * r
    aq = abs(Q)
    sgn_Q = 1.0 if Q > 0.0 else (-1.0 if Q < 0.0 else 0.0)
    xt = transport_number(Q, r, h_w, p)
    dxt_r = dkk_r * p[L_VES] / aq if aq > 0.0 else 0.0
    dxt_aq = -xt / aq if aq > 0.0 else 0.0
    if xt < PSI_SERIES_X:
        dpsi = 1 / 2 - xt * (1 / 3 - xt * (1 / 8 - xt * (1 / 30 - xt / 144)))
    elif xt < math.inf:
        dpsi = -math.expm1(-xt) / (xt * xt) - math.exp(-xt) / xt
    else:
        dpsi = 0.0
    ps = psi(xt)
    cbi = cb_inf(Cw, r, h_w, p)
    dcbi_r = -cbi / kk * dkk_r
    dcbm_Cw = h_w / p[GAMMA_WB] / kk * ps
    dcbm_r = dcbi_r * ps + (cbi - p[C_IN]) * dpsi * (dxt_r + dxt_aq * sgn_Q * dQ_r)
    dcbm_dP = (cbi - p[C_IN]) * dpsi * dxt_aq * sgn_Q * dQ_dP
    dCwd_Cw = -(h_w / Aw) * (1.0 / p[GAMMA_WB] - dcbm_Cw) - r_dw
    dCwd_lam = ((h_w / Aw) * dcbm_r + k_tau * dtau_r / Aw) * kr
    dCwd_dP = (h_w / Aw) * dcbm_dP + k_tau * dtau_dP / Aw

    cl = j + 1  # column of lambda
    if ca_order == 2:
        w = p[OMEGA_N]
        Jx[0, 1] = 1.0
        Jx[1, 0] = -w * w
        Jx[1, 1] = -2.0 * p[ZETA] * w
        Jx[1, cl] = w * w * dCab_lam
        ca_P = w * w * dCab_P
        ca_row = 1
    else:
        Jx[0, 0] = -1.0 / p[TAU_CA]
        Jx[0, cl] = dCab_lam / p[TAU_CA]
        ca_P = dCab_P / p[TAU_CA]
        ca_row = 0
    Jx[j, j] = dCwd_Cw
    Jx[j, cl] = dCwd_lam
    Jx[cl, cl] = dld_lam
    if dynamic:
        Jx[cl, j + 4] = dld_AMp
        Jx[cl, j + 5] = dld_AM
        k3, k4, k7 = p[K3], p[K4], p[K7]
        # linear in the kinetic states (eq 4state) ...
        Jx[j + 2, j + 2], Jx[j + 2, j + 3], Jx[j + 2, j + 5] = -K1, K2, k7
        Jx[j + 3, j + 2], Jx[j + 3, j + 3], Jx[j + 3, j + 4] = K1, -(K2 + k3), k4
        Jx[j + 4, j + 3], Jx[j + 4, j + 4], Jx[j + 4, j + 5] = k3, -(k4 + K2), K1
        Jx[j + 5, j + 4], Jx[j + 5, j + 5] = K2, -(K1 + k7)
        # ... with rate constants K1(Ca), K2(Ca, Cw)
        Jx[j + 2, 0] = -M * dK1_Ca + Mp * dK2_Ca
        Jx[j + 3, 0] = M * dK1_Ca - Mp * dK2_Ca
        Jx[j + 4, 0] = -AMp * dK2_Ca + AM * dK1_Ca
        Jx[j + 5, 0] = AMp * dK2_Ca - AM * dK1_Ca
        Jx[j + 2, j] = Mp * dK2_Cw
        Jx[j + 3, j] = -Mp * dK2_Cw
        Jx[j + 4, j] = -AMp * dK2_Cw
        Jx[j + 5, j] = AMp * dK2_Cw
    else:
        Jx[cl, 0] = dld_AMp * dAMp_Ca + dld_AM * dAM_Ca
        Jx[cl, j] = dld_AMp * dAMp_Cw + dld_AM * dAM_Cw
    # local unknowns (mmHg): P = (u0 + u1)/2 [- u2], dP = u0 - u1, both in Pa (eqs Pab2Pim, Pab2DP)
    pim_ref = iopt[OPT_PIM_REF] != 0
    for row in range(3):
        if row == 0:
            i, gP, gD = ca_row, ca_P, 0.0
        elif row == 1:
            i, gP, gD = j, 0.0, dCwd_dP
        else:
            i, gP, gD = cl, dld_P, 0.0
        Ju[i, 0] = PA_PER_MMHG * (0.5 * gP + gD)
        Ju[i, 1] = PA_PER_MMHG * (0.5 * gP - gD)
        if pim_ref:
            Ju[i, 2] = -PA_PER_MMHG * gP
    return 1
