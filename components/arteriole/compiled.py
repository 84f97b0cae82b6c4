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
