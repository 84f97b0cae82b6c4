"""Compiled (numba nopython) equations of the ``arteriole`` element (hemocircuit.kernels contract).

One element per call, scalar math, no allocation.  The reference is the vectorised numpy code
(element.py and the physics modules model, geometry, no_transport, cgmp, myogenic, kinetics,
mechanics); every expression below follows its operation order so both paths agree to rounding.

``p``: the element's parameters in the order of ``Arteriole.parameters`` (= parameters.PARAMETERS),
raw: ``no_speed`` (sec. dynfitting) is applied here, as ``parameters.effective`` does.
``x``: states [Ca, (dCa,) Cw, lambda (, M, Mp, AMp, AM)] (model.state_names).
``iopt`` (``Arteriole.kernel_options``), int64:
    [0] ca_order        1 (eq dCadt) or 2 (eq dCadt2)
    [1] kinetics        0 quasi_steady (eq 4stateSS), 1 dynamic (eq 4state)
    [2] passive         0 / 1
    [3] volume_flow     0: local unknowns [in, out, ref]; 1: [in, out, ref, mid]
    [4] pim_reference   0 'gauge', 1 'ref'
Units: circuit side mmHg, mL, s; physics SI (Pa, m, N, s, M) via hemocircuit.units.
Non-finite results propagate as NaN/inf (the numpy path raises ArterioleError; the caller of
the kernel checks finiteness).
"""
from __future__ import annotations

import math

import numba
import numpy as np

from hemocircuit.units import M3_PER_ML, PA_PER_MMHG

from .cgmp import LN10, LN_95
from .mechanics import _MAX_EXP, FRICTION_FLOOR, PASSIVE_FRICTION
from .myogenic import CA_FLOOR
from .no_transport import _PSI_SERIES_X
from .parameters import PARAMETERS

# --- parameter indices (order of PARAMETERS = Arteriole.parameters) ---------------------
_IDX = {name: i for i, name in enumerate(PARAMETERS)}
H_W, S_W, GAMMA_WB, R_DB, R_DW, K_TAU = (_IDX[k] for k in ("h_w", "s_w", "gamma_wb", "r_db", "r_dw", "k_tau"))
C_IN, MU_B, DP0, R0 = (_IDX[k] for k in ("C_in", "mu_b", "dP0", "r0"))
NO_L, NO_U, PCGMP_L, PCGMP_U = (_IDX[k] for k in ("NO_L", "NO_U", "pcGMP_L", "pcGMP_U"))
SIGMA_L, SIGMA_U, PCA_L, PCA_U = (_IDX[k] for k in ("sigma_L", "sigma_U", "pCa_L", "pCa_U"))
F1, F2, LAMBDA_OPT, V_XB, ETA = (_IDX[k] for k in ("f1", "f2", "lambda_opt", "v", "eta"))
Q1, Q2, Q3, L0, W_C, N_C, T_W = (_IDX[k] for k in ("q1", "q2", "q3", "l0", "w_c", "n_c", "t_w"))
K3, K4, K7 = (_IDX[k] for k in ("K3", "K4", "K7"))
K_CA1, N_CA1, K_CA2, N_CA2, K_CGMP, N_CGMP = (_IDX[k] for k in ("k_Ca1", "n_Ca1", "k_Ca2", "n_Ca2",
                                                                "k_cGMP", "n_cGMP"))
TAU_CA, OMEGA_N, ZETA = (_IDX[k] for k in ("tau_Ca", "omega_n", "zeta"))
NO_SPEED, L_VES, N_VES = (_IDX[k] for k in ("no_speed", "L", "n"))
N_PARAMS = len(PARAMETERS)

# --- iopt slots ---------------------------------------------------------------------------
OPT_CA_ORDER, OPT_DYNAMIC, OPT_PASSIVE, OPT_VOLUME_FLOW, OPT_PIM_REF = 0, 1, 2, 3, 4
N_OPTS = 5

_PI = math.pi
_R_FACTOR = M3_PER_ML / PA_PER_MMHG   # Pa*s/m^3 -> mmHg*s/mL (element._OBS["R"])
_TWO_PI = 2 * np.pi
_INF = math.inf

_jit = numba.njit(cache=True, nogil=True, error_model="numpy", _nrt=False)


# --- shared pieces (inlined by LLVM) ------------------------------------------------------
@_jit
def _l2r(lam, p):
    # eq l2r: r = (lambda l0 n_c / pi - t_w) / 2  [m]
    return 0.5 * (lam * p[L0] * p[N_C] / _PI - p[T_W])


@_jit
def _resistance(r, p):
    # eq Poiseuille / Rsa: R = 8 mu_b L / (pi r^4 n) of the bed [Pa*s/m^3]; inf at r = 0
    return 8.0 * p[MU_B] * p[L_VES] / (_PI * r ** 4.0 * p[N_VES])


@_jit
def _sigmoid_5_95(x, x_L, x_U, y_L, y_U):
    # eq sigmoiddef: y_L + (y_U - y_L) expit((x - z_half)/k_z), k_z = (x_L - x_U)/(2 ln(1/0.95 - 1))
    z_half = 0.5 * (x_L + x_U)
    k_z = (x_L - x_U) / (2.0 * LN_95)
    return y_L + (y_U - y_L) * (1.0 / (1.0 + math.exp(-((x - z_half) / k_z))))


@_jit
def _cb_inf(Cw, r, h_w, p):
    # eqs cbbar, cinv: far-downstream blood [NO] h_w (C_w / gamma_wb) / (h_w + r_db A_b) [M]
    return h_w * (Cw / p[GAMMA_WB]) / (h_w + p[R_DB] * (_PI * r * r))


@_jit
def _bridges_affine(x, p, iopt):
    """(lambda, r, a, b): eq FaNew solved for lambda_dot = a + b P (P intramural, Pa)."""
    ca_order = iopt[OPT_CA_ORDER]
    passive = iopt[OPT_PASSIVE] != 0
    j = 2 if ca_order == 2 else 1          # index of Cw in x
    Ca = x[0]
    Cw = x[j]
    lam = x[j + 1]
    r = _l2r(lam, p)
    if iopt[OPT_DYNAMIC] != 0:
        AMp = x[j + 4]
        AM = x[j + 5]
    else:
        K1, K2 = _rates(Ca, Cw, p, passive)
        _, _, AMp, AM = _quasi_steady(K1, K2, p)
    a, b = _dlam_affine(lam, r, AMp, AM, p, passive)
    return lam, r, a, b


@_jit
def _rates(Ca, Cw, p, passive):
    """(K1 = K6, K2 = K5) [1/s] from [Ca] and wall [NO] (eqs NOcGMP, phos, dephos)."""
    # eq NOcGMP: [cGMP] = 10**(5 %/95 % sigmoid of C_w)
    cG = math.exp(LN10 * _sigmoid_5_95(Cw, p[NO_L], p[NO_U], p[PCGMP_L], p[PCGMP_U]))
    # eq phos: K1 = K6 = 1/(1 + (k_Ca1/Ca)^n_Ca1), Ca clipped at CA_FLOOR; passive: Ca = 0
    Cac = CA_FLOOR if Ca < CA_FLOOR else Ca   # NaN propagates
    if passive:
        K1 = 0.0
        ca_inhib = 1.0
    else:
        K1 = 1.0 / (1.0 + (p[K_CA1] / Cac) ** p[N_CA1])
        ca_inhib = 1.0 / (1.0 + (Cac / p[K_CA2]) ** p[N_CA2])
    # eq dephos: K2 = K5 = 0.55 + 2 cGMP-activation * Ca-inhibition
    cg = 0.0 if cG < 0.0 else cG
    cg_act = 1.0 / (1.0 + (p[K_CGMP] / cg) ** p[N_CGMP])   # cGMP = 0 -> 0 (numpy error model)
    K2 = 0.55 + 2.0 * cg_act * ca_inhib
    return K1, K2


@_jit
def _quasi_steady(a, b, p):
    # eq 4stateSS with eq 4stateCons (closed form, kinetics.quasi_steady), a = K1 = K6, b = K2 = K5
    k3 = p[K3]
    k4 = p[K4]
    k7 = p[K7]
    M = b * (a * k4 + k3 * k7 + b * k7 + k4 * k7)
    Mp = a * (a * k4 + b * k7 + k4 * k7)
    AMp = a * k3 * (a + k7)
    AM = a * b * k3
    s = M + Mp + AMp + AM
    return M / s, Mp / s, AMp / s, AM / s


@_jit
def _dlam_affine(lam, r, AMp, AM, p, passive):
    """(a [1/s], b [1/(s Pa)]), dlambda/dt = a + b P (mechanics.dlambda_dt_affine)."""
    # eq FaNew: overlap G = exp(-(lambda - lambda_opt)^2 / (2 eta))
    d = lam - p[LAMBDA_OPT]
    G = math.exp(-d * d / (2.0 * p[ETA]))
    # eq passiveNew: F_p = q1 (exp(q2 (lambda^q3 - 1)) - 1), lambda >= 0, exponent capped
    lm = 0.0 if lam < 0.0 else lam
    z = p[Q2] * (lm ** p[Q3] - 1.0)
    z = _MAX_EXP if z > _MAX_EXP else z
    Fp = p[Q1] * math.expm1(z)
    # eqs FaNew, FTSS: isometric active force f1 v AMp G
    Fa = p[F1] * p[V_XB] * AMp * G
    # friction l0 (G (f1 AMp + f2 AM) + floor)
    floor = PASSIVE_FRICTION if passive else FRICTION_FLOOR
    D = p[L0] * (G * (p[F1] * AMp + p[F2] * AM) + floor)
    # eqs FT, FMFP: w_c P r - F_p - F_a = friction * lambda_dot
    return -(Fp + Fa) / D, p[W_C] * r / D


@_jit
def _pressures(u, iopt):
    """(P_im, dP) [Pa] from local pressures [mmHg] (eqs Pab2Pim, Pab2DP)."""
    P_im = 0.5 * (u[0] + u[1])
    if iopt[OPT_PIM_REF] != 0:
        P_im = P_im - u[2]
    return P_im * PA_PER_MMHG, (u[0] - u[1]) * PA_PER_MMHG


# --- the contract -------------------------------------------------------------------------
@_jit
def stamp(p, x, u, t, iopt, A, b):
    """Local MNA stamp (element.Arteriole.stamp); A, b arrive zeroed."""
    j = 2 if iopt[OPT_CA_ORDER] == 2 else 1
    r = _l2r(x[j + 1], p)
    # eq Rsa: conductance of the bed [mL/s per mmHg]
    g = 1.0 / (_resistance(r, p) * _R_FACTOR)
    if iopt[OPT_VOLUME_FLOW] == 0:
        # section artComp: a variable resistor in -> out; ref carries no flow
        A[0, 0] = g
        A[0, 1] = -g
        A[1, 0] = -g
        A[1, 1] = g
        return
    # section autoregFirst: halves R/2 in -> mid -> out; local nodes in 0, out 1, ref 2, mid 3
    g2 = 2.0 * g
    A[0, 0] = g2
    A[0, 3] = -g2
    A[3, 0] = -g2
    A[3, 3] = g2 + g2
    A[3, 1] = -g2
    A[1, 3] = -g2
    A[1, 1] = g2
    # eqs Vsa, dVsadt: q_v = 2 pi r L n dr/dt leaves mid into ref, dr/dt = (a + b P_im) dr/dlambda
    _, r, da, db = _bridges_affine(x, p, iopt)
    k_r = 0.5 * p[L0] * p[N_C] / _PI          # dr/dlambda [m] (eq l2r)
    k = _TWO_PI * r * p[L_VES] * p[N_VES] / M3_PER_ML   # mL per m of radius
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
    """dx/dt in the states' units per second (element.Arteriole.derivatives)."""
    ca_order = iopt[OPT_CA_ORDER]
    dynamic = iopt[OPT_DYNAMIC] != 0
    passive = iopt[OPT_PASSIVE] != 0
    j = 2 if ca_order == 2 else 1
    Ca = x[0]
    Cw = x[j]
    lam = x[j + 1]
    P, dP = _pressures(u, iopt)
    # sec. dynfitting: no_speed scales h_w, r_dw, s_w, k_tau (parameters.effective)
    ns = p[NO_SPEED]
    h_w = p[H_W] * ns
    r_dw = p[R_DW] * ns
    s_w = p[S_W] * ns
    k_tau = p[K_TAU] * ns

    r = _l2r(lam, p)                                            # eq l2r [m]
    Q = _PI * r ** 4.0 * dP / (8.0 * p[MU_B] * p[L_VES])        # eq Poiseuille, one vessel [m^3/s]
    tau = (abs(dP) / p[DP0]) * (r / p[R0])                      # normalised shear stress (sec. NOeqns)

    # kinetics: eqs NOcGMP, phos, dephos; eq 4stateSS (quasi-steady) or the states (eq 4state)
    K1, K2 = _rates(Ca, Cw, p, passive)
    if dynamic:
        M = x[j + 2]
        Mp = x[j + 3]
        AMp = x[j + 4]
        AM = x[j + 5]
    else:
        M, Mp, AMp, AM = _quasi_steady(K1, K2, p)

    # sec. Myogenic Response Model: sigma = P r / t_w, Ca_bar = 10**sigmoid(sigma)
    sigma = P * r / p[T_W]
    if passive:
        Cab = 0.0
    else:
        Cab = math.exp(LN10 * _sigmoid_5_95(sigma, p[SIGMA_L], p[SIGMA_U], p[PCA_L], p[PCA_U]))

    # eq FaNew solved for lambda_dot (eqs FT, FMFP, passiveNew)
    a, bb = _dlam_affine(lam, r, AMp, AM, p, passive)
    lam_dot = a + bb * P

    # eq dNOdt with eqs cbbar, cbbarpsi, psi
    Aw = _PI * ((p[R0] + p[T_W]) ** 2.0 - p[R0] ** 2.0)         # wall area A_w [m^2]
    aq = abs(Q)
    if aq > 0.0:
        xt = (h_w + p[R_DB] * (_PI * r * r)) * p[L_VES] / aq   # transport number (eq cinv)
    else:
        xt = _INF
    if xt < _PSI_SERIES_X:
        psi = xt * (1 / 2 - xt * (1 / 6 - xt * (1 / 24 - xt * (1 / 120 - xt / 720))))
    else:
        psi = 1.0 - (-math.expm1(-xt)) / xt
    cbm = (_cb_inf(Cw, r, h_w, p) - p[C_IN]) * psi + p[C_IN]
    dCw = (-(h_w / Aw) * (Cw / p[GAMMA_WB] - cbm) - r_dw * Cw + s_w + k_tau * tau / Aw)

    if ca_order == 2:
        # eq dCadt2 (G_dc = 1): d2Ca/dt2 = omega_n^2 (Ca_bar - Ca) - 2 zeta omega_n dCa/dt
        dCa = x[1]
        w = p[OMEGA_N]
        dx[0] = dCa
        dx[1] = w * w * (Cab - Ca) - 2.0 * p[ZETA] * w * dCa
    else:
        # eq dCadt: dCa/dt = (Ca_bar - Ca) / tau_Ca
        dx[0] = (Cab - Ca) / p[TAU_CA]
    dx[j] = dCw
    dx[j + 1] = lam_dot
    if dynamic:
        # eq 4state, K5 = K2, K6 = K1
        k3 = p[K3]
        k4 = p[K4]
        k7 = p[K7]
        dx[j + 2] = -K1 * M + K2 * Mp + k7 * AM
        dx[j + 3] = K1 * M - (K2 + k3) * Mp + k4 * AMp
        dx[j + 4] = k3 * Mp - (k4 + K2) * AMp + K1 * AM
        dx[j + 5] = K2 * AMp - (K1 + k7) * AM


@_jit
def observe(p, x, iopt, out):
    """State-only observables, circuit units, order OBSERVABLES(ca_order):
    r [um], lambda, Ca [M], (dCa [M/s],) Cw [M], R [mmHg*s/mL], V [mL], Cb_inf [M], k_NO [m^2/s]."""
    ca_order = iopt[OPT_CA_ORDER]
    j = 2 if ca_order == 2 else 1
    lam = x[j + 1]
    r = _l2r(lam, p)                                           # eq l2r
    out[0] = r * 1e6
    out[1] = lam
    out[2] = x[0]
    i = 3
    if ca_order == 2:
        out[3] = x[1]
        i = 4
    out[i] = x[j]
    out[i + 1] = _resistance(r, p) * _R_FACTOR                 # eq Rsa
    out[i + 2] = _PI * r * r * p[L_VES] * p[N_VES] / M3_PER_ML  # eq Vsa
    h_w = p[H_W] * p[NO_SPEED]                                  # sec. dynfitting
    out[i + 3] = _cb_inf(x[j], r, h_w, p)                       # eqs cbbar, cinv
    out[i + 4] = h_w + p[R_DB] * (_PI * r * r)                  # exponent of eq cinv [m^2/s]


def observables(ca_order: int) -> tuple:
    """Names written by ``observe`` for this ca_order (the state-only observables of the element)."""
    names = ("r", "lambda", "Ca") + (("dCa",) if ca_order == 2 else ()) + ("Cw", "R", "V", "Cb_inf", "k_NO")
    return names


# --- analytic partial derivatives (the engine's element-local Jacobian) -------------------
@_jit
def _sigmoid_5_95_d(x, x_L, x_U, y_L, y_U):
    """(y, dy/dx) of _sigmoid_5_95 (same operations for y)."""
    z_half = 0.5 * (x_L + x_U)
    k_z = (x_L - x_U) / (2.0 * LN_95)
    s = 1.0 / (1.0 + math.exp(-((x - z_half) / k_z)))
    return y_L + (y_U - y_L) * s, (y_U - y_L) * s * (1.0 - s) / k_z


@_jit
def _rates_d(Ca, Cw, p):
    """(K1, K2, dK1/dCa, dK2/dCa, dK2/dCw) of _rates (not passive)."""
    y, dy = _sigmoid_5_95_d(Cw, p[NO_L], p[NO_U], p[PCGMP_L], p[PCGMP_U])
    cG = math.exp(LN10 * y)
    dcG = cG * LN10 * dy
    floor = Ca < CA_FLOOR
    Cac = CA_FLOOR if floor else Ca
    z1 = (p[K_CA1] / Cac) ** p[N_CA1]
    K1 = 1.0 / (1.0 + z1)
    z2 = (Cac / p[K_CA2]) ** p[N_CA2]
    ci = 1.0 / (1.0 + z2)
    dK1 = 0.0 if floor else K1 * K1 * p[N_CA1] * z1 / Cac
    dci = 0.0 if floor else -ci * ci * p[N_CA2] * z2 / Cac
    cg = 0.0 if cG < 0.0 else cG
    z3 = (p[K_CGMP] / cg) ** p[N_CGMP]
    act = 1.0 / (1.0 + z3)
    dact = act * act * p[N_CGMP] * z3 / cg if cg > 0.0 else 0.0
    return K1, 0.55 + 2.0 * act * ci, dK1, 2.0 * act * dci, 2.0 * ci * dact * dcG


@_jit
def _quasi_steady_d(a, b, p):
    """(AMp, AM, dAMp/da, dAMp/db, dAM/da, dAM/db) of _quasi_steady (fractions N_i / s)."""
    k3 = p[K3]
    k4 = p[K4]
    k7 = p[K7]
    M = b * (a * k4 + k3 * k7 + b * k7 + k4 * k7)
    Mp = a * (a * k4 + b * k7 + k4 * k7)
    AMp = a * k3 * (a + k7)
    AM = a * b * k3
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
    """dx/dt as ``derivs`` and its partial derivatives, Jx[i, k] = d dx_i / d x_k (S, S) and
    Ju[i, k] = d dx_i / d u_k (S, L, u in mmHg), by the chain rule through the same equations
    (eqs l2r, Poiseuille, NOcGMP, phos, dephos, 4stateSS / 4state, ssCa, FaNew, passiveNew,
    dNOdt, dCadt / dCadt2).  Returns 1, or 0 for a passive arteriole (the engine then
    differences ``derivs``).  At the clips (Ca at CA_FLOOR, the passive-force exponent cap,
    Q = 0) it gives the one-sided derivative of the branch taken."""
    ca_order = iopt[OPT_CA_ORDER]
    dynamic = iopt[OPT_DYNAMIC] != 0
    if iopt[OPT_PASSIVE] != 0:
        return 0
    S = 8 if dynamic else 4
    if ca_order != 2:
        S -= 1
    j = 2 if ca_order == 2 else 1
    Lu = 4 if iopt[OPT_VOLUME_FLOW] != 0 else 3
    for i in range(S):
        for k in range(S):
            Jx[i, k] = 0.0
        for k in range(Lu):
            Ju[i, k] = 0.0
    Ca = x[0]
    Cw = x[j]
    lam = x[j + 1]
    P, dP = _pressures(u, iopt)
    ns = p[NO_SPEED]
    h_w = p[H_W] * ns
    r_dw = p[R_DW] * ns
    s_w = p[S_W] * ns
    k_tau = p[K_TAU] * ns
    kr = 0.5 * p[L0] * p[N_C] / _PI                             # dr/dlambda (eq l2r)
    r = _l2r(lam, p)
    c_q = _PI / (8.0 * p[MU_B] * p[L_VES])
    Q = _PI * r ** 4.0 * dP / (8.0 * p[MU_B] * p[L_VES])
    dQ_r = 4.0 * c_q * r ** 3.0 * dP
    dQ_dP = c_q * r ** 4.0
    tau = (abs(dP) / p[DP0]) * (r / p[R0])
    dtau_r = (abs(dP) / p[DP0]) / p[R0]
    sgn_dP = 1.0 if dP > 0.0 else (-1.0 if dP < 0.0 else 0.0)
    dtau_dP = sgn_dP / p[DP0] * (r / p[R0])

    K1, K2, dK1_Ca, dK2_Ca, dK2_Cw = _rates_d(Ca, Cw, p)
    if dynamic:
        M = x[j + 2]
        Mp = x[j + 3]
        AMp = x[j + 4]
        AM = x[j + 5]
        # d(AMp, AM)/d(Ca, Cw) = 0: they are states
        dAMp_Ca = dAMp_Cw = dAM_Ca = dAM_Cw = 0.0
    else:
        AMp, AM, dAMp_a, dAMp_b, dAM_a, dAM_b = _quasi_steady_d(K1, K2, p)
        dAMp_Ca = dAMp_a * dK1_Ca + dAMp_b * dK2_Ca
        dAMp_Cw = dAMp_b * dK2_Cw
        dAM_Ca = dAM_a * dK1_Ca + dAM_b * dK2_Ca
        dAM_Cw = dAM_b * dK2_Cw

    # Ca_bar(sigma), sigma = P r / t_w
    sigma = P * r / p[T_W]
    ys, dys = _sigmoid_5_95_d(sigma, p[SIGMA_L], p[SIGMA_U], p[PCA_L], p[PCA_U])
    Cab = math.exp(LN10 * ys)
    dCab_sigma = Cab * LN10 * dys
    dCab_lam = dCab_sigma * P / p[T_W] * kr
    dCab_P = dCab_sigma * r / p[T_W]

    # lambda_dot = N / D (eq FaNew with eqs FT, FMFP, passiveNew); a + b P as _dlam_affine
    d = lam - p[LAMBDA_OPT]
    G = math.exp(-d * d / (2.0 * p[ETA]))
    dG = -G * d / p[ETA]
    lm = 0.0 if lam < 0.0 else lam
    z = p[Q2] * (lm ** p[Q3] - 1.0)
    capped = z > _MAX_EXP
    z = _MAX_EXP if capped else z
    Fp = p[Q1] * math.expm1(z)
    dFp = 0.0 if (capped or lam <= 0.0) else p[Q1] * math.exp(z) * p[Q2] * p[Q3] * lm ** (p[Q3] - 1.0)
    f1v = p[F1] * p[V_XB]
    Fa = f1v * AMp * G
    D = p[L0] * (G * (p[F1] * AMp + p[F2] * AM) + FRICTION_FLOOR)
    a_l = -(Fp + Fa) / D
    b_l = p[W_C] * r / D
    lam_dot = a_l + b_l * P
    dN_lam = -(dFp + f1v * AMp * dG) + p[W_C] * kr * P
    dD_lam = p[L0] * dG * (p[F1] * AMp + p[F2] * AM)
    dN_AMp = -f1v * G
    dD_AMp = p[L0] * G * p[F1]
    dD_AM = p[L0] * G * p[F2]
    dld_lam = (dN_lam - lam_dot * dD_lam) / D
    dld_AMp = (dN_AMp - lam_dot * dD_AMp) / D
    dld_AM = -lam_dot * dD_AM / D
    dld_P = b_l

    # eq dNOdt with eqs cbbar, cbbarpsi, psi
    Aw = _PI * ((p[R0] + p[T_W]) ** 2.0 - p[R0] ** 2.0)
    kk = h_w + p[R_DB] * (_PI * r * r)
    dkk_r = p[R_DB] * 2.0 * _PI * r
    aq = abs(Q)
    sgn_Q = 1.0 if Q > 0.0 else (-1.0 if Q < 0.0 else 0.0)
    if aq > 0.0:
        xt = kk * p[L_VES] / aq
        dxt_r = dkk_r * p[L_VES] / aq
        dxt_aq = -xt / aq
    else:
        xt = _INF
        dxt_r = 0.0
        dxt_aq = 0.0
    if xt < _PSI_SERIES_X:
        psi = xt * (1 / 2 - xt * (1 / 6 - xt * (1 / 24 - xt * (1 / 120 - xt / 720))))
        dpsi = 1 / 2 - xt * (1 / 3 - xt * (1 / 8 - xt * (1 / 30 - xt / 144)))
    elif xt < _INF:
        em = -math.expm1(-xt)
        psi = 1.0 - em / xt
        dpsi = em / (xt * xt) - math.exp(-xt) / xt
    else:
        psi = 1.0
        dpsi = 0.0
    cbi = _cb_inf(Cw, r, h_w, p)
    dcbi_Cw = h_w / p[GAMMA_WB] / kk
    dcbi_r = -cbi / kk * dkk_r
    cbm = (cbi - p[C_IN]) * psi + p[C_IN]
    dcbm_Cw = dcbi_Cw * psi
    dcbm_r = dcbi_r * psi + (cbi - p[C_IN]) * dpsi * (dxt_r + dxt_aq * sgn_Q * dQ_r)
    dcbm_dP = (cbi - p[C_IN]) * dpsi * dxt_aq * sgn_Q * dQ_dP
    dCw = (-(h_w / Aw) * (Cw / p[GAMMA_WB] - cbm) - r_dw * Cw + s_w + k_tau * tau / Aw)
    dCwd_Cw = -(h_w / Aw) * (1.0 / p[GAMMA_WB] - dcbm_Cw) - r_dw
    dCwd_lam = ((h_w / Aw) * dcbm_r + k_tau * dtau_r / Aw) * kr
    dCwd_dP = (h_w / Aw) * dcbm_dP + k_tau * dtau_dP / Aw

    cl = j + 1  # column of lambda
    if ca_order == 2:
        dCa = x[1]
        w = p[OMEGA_N]
        dx[0] = dCa
        dx[1] = w * w * (Cab - Ca) - 2.0 * p[ZETA] * w * dCa
        Jx[0, 1] = 1.0
        Jx[1, 0] = -w * w
        Jx[1, 1] = -2.0 * p[ZETA] * w
        Jx[1, cl] = w * w * dCab_lam
        ca_P = w * w * dCab_P
        ca_row = 1
    else:
        dx[0] = (Cab - Ca) / p[TAU_CA]
        Jx[0, 0] = -1.0 / p[TAU_CA]
        Jx[0, cl] = dCab_lam / p[TAU_CA]
        ca_P = dCab_P / p[TAU_CA]
        ca_row = 0
    dx[j] = dCw
    Jx[j, j] = dCwd_Cw
    Jx[j, cl] = dCwd_lam
    dx[cl] = lam_dot
    Jx[cl, cl] = dld_lam
    if dynamic:
        Jx[cl, j + 4] = dld_AMp
        Jx[cl, j + 5] = dld_AM
        k3 = p[K3]
        k4 = p[K4]
        k7 = p[K7]
        dx[j + 2] = -K1 * M + K2 * Mp + k7 * AM
        dx[j + 3] = K1 * M - (K2 + k3) * Mp + k4 * AMp
        dx[j + 4] = k3 * Mp - (k4 + K2) * AMp + K1 * AM
        dx[j + 5] = K2 * AMp - (K1 + k7) * AM
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
