"""The arteriole's equations, each written once (thesis chapters 3, 4 and 6; SI units).

Every function here is compiled into the engine by the element's kernel functions
(compiled.py) and, called from Python, runs on numpy arrays (the steady-state solver, the
thesis's curves): ``hemocircuit.kernels.jit.equation``.  So they use only what works on
scalars in numba and on arrays in numpy (arithmetic, np.exp, np.maximum, ..., ``select``).

``p`` is the parameter vector in the order of ``parameters.PARAMETERS`` with the parameter on
its FIRST axis: (N_PARAMS,) in a kernel, (N_PARAMS, ...) from Python (:func:`vector`), so
``p[T_W]`` is a number or an array alike.  ``no_speed`` (sec. dynfitting) is applied by
:func:`no_rates`.  Units: P, dP, sigma in Pa; r, t_w, l0 in m; Q in m^3/s; forces in N;
concentrations in M; rates in 1/s.
"""
from __future__ import annotations

import math

import numpy as np

from hemocircuit.kernels.jit import equation, select

from .parameters import PARAMETERS

_eq = equation(cache=True, nogil=True, error_model="numpy", _nrt=False)

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
NO_SPEED, L_VES, N_VES, PCA_SHIFT = (_IDX[k] for k in ("no_speed", "L", "n", "pCa_shift"))
N_PARAMS = len(PARAMETERS)

# --- constants ------------------------------------------------------------------------------
#: ln(1/0.95 - 1) = -ln 19, from the 5 %/95 % definition (eq sigmoiddef); ln 10
LN_95 = math.log(1.0 / 0.95 - 1.0)
LN10 = math.log(10.0)
#: the bridge fractions of eq 4state, in the order the kinetics functions take and return them
BRIDGE_STATES = ("M", "Mp", "AMp", "AM")
#: lower floor of [Ca] [M] (MODEL_NOTES): K1/K2 clip Ca at it; second-order Ca stops at it
CA_FLOOR = 1e-12
#: numerical guard [N*s/m] added to G (f1 AMp + f2 AM): keeps dlambda/dt finite when no bridge
#: is attached or G underflows; ~1e-8 of the typical value, steady states unchanged
FRICTION_FLOOR = 1e-9
#: friction [N*s/m] in passive mode (no bridge attached): the radius relaxes to its passive
#: equilibrium in l0 PASSIVE_FRICTION / (dF_p/dlambda - w_c P dr/dlambda), about 10-30 ms
#: (not in the thesis, which treats the passive case only at steady state)
PASSIVE_FRICTION = 1e-4
#: cap on the exponent of F_p (keeps it finite for absurd lambda; exp(700) ~ 1e304)
MAX_EXP = 700.0
#: below this transport number the series of psi is used (truncation < 1e-13 relative)
PSI_SERIES_X = 1e-2


def vector(params: dict, names=PARAMETERS) -> np.ndarray:
    """The parameter vector (N_PARAMS, ...) of a dict of numbers or arrays (broadcast together)."""
    return np.stack(np.broadcast_arrays(*(np.asarray(params[k], dtype=float) for k in names)))


# --- geometry (eqs l2r, Poiseuille, Rsa, Vsa) -------------------------------------------------
@_eq
def l2r(lam, p):
    """Internal radius [m] (eq l2r): r = (lambda l0 n_c / pi - t_w) / 2."""
    return 0.5 * (lam * p[L0] * p[N_C] / math.pi - p[T_W])


@_eq
def r2l(r, p):
    """Normalised cell length [-] from the radius r [m] (eq l2r inverted)."""
    return (2.0 * r + p[T_W]) * math.pi / (p[L0] * p[N_C])


@_eq
def dr_dlambda(p):
    """dr/dlambda [m] (eq l2r): l0 n_c / (2 pi)."""
    return 0.5 * p[L0] * p[N_C] / math.pi


@_eq
def resistance(r, p):
    """Bed resistance [Pa*s/m^3] of n vessels, 8 mu_b L / (pi r^4 n) (eqs Poiseuille, Rsa); inf at r = 0."""
    return 8.0 * p[MU_B] * p[L_VES] / (math.pi * r ** 4.0 * p[N_VES])


@_eq
def flow(r, dP, p):
    """Poiseuille flow [m^3/s] of ONE vessel, pi r^4 dP / (8 mu_b L) (eq Poiseuille)."""
    return math.pi * r ** 4.0 * dP / (8.0 * p[MU_B] * p[L_VES])


@_eq
def bed_volume(r, p):
    """Lumen volume [m^3] of the bed, pi r^2 L n (eq Vsa)."""
    return math.pi * r * r * p[L_VES] * p[N_VES]


@_eq
def wall_area(p):
    """Wall cross-section A_w [m^2] = pi((r0 + t_w)^2 - r0^2) (sec. NOeqns)."""
    return math.pi * ((p[R0] + p[T_W]) ** 2.0 - p[R0] ** 2.0)


# --- sigmoids (eqs sigmoiddef, NOcGMP, ssCa) ------------------------------------------------
@_eq
def sigmoid_fraction(x, x_L, x_U):
    """(s, k_z) of eq sigmoiddef: the step's fraction s = 1 / (1 + exp(-(x - z_half)/k_z)),
    z_half = (x_L + x_U)/2, k_z = (x_L - x_U)/(2 ln(1/0.95 - 1)): s = 0.05 at x_L, 0.95 at x_U."""
    z_half = 0.5 * (x_L + x_U)
    k_z = (x_L - x_U) / (2.0 * LN_95)
    return 1.0 / (1.0 + np.exp(-((x - z_half) / k_z))), k_z


@_eq
def sigmoid_5_95(x, x_L, x_U, y_L, y_U):
    """y_L + (y_U - y_L) s(x) (eq sigmoiddef, s of :func:`sigmoid_fraction`)."""
    s, _ = sigmoid_fraction(x, x_L, x_U)
    return y_L + (y_U - y_L) * s


@_eq
def cgmp(Cw, p):
    """[cGMP] [M] = 10**sigmoid(C_w) (eq NOcGMP), instantaneous."""
    return np.exp(LN10 * sigmoid_5_95(Cw, p[NO_L], p[NO_U], p[PCGMP_L], p[PCGMP_U]))


@_eq
def wall_stress(P, r, p):
    """sigma = P r / t_w [Pa] (sec. Myogenic Response Model), P intramural [Pa]."""
    return P * r / p[T_W]


@_eq
def ca_bar(sigma, p):
    """Equilibrium [Ca] [M] = 10**(sigmoid(sigma) + pCa_shift) (eq ssCa; pCa_shift, 0 in the
    thesis, is a tone input that moves log10[Ca] independently of the wall stress)."""
    return np.exp(LN10 * (sigmoid_5_95(sigma, p[SIGMA_L], p[SIGMA_U], p[PCA_L], p[PCA_U]) + p[PCA_SHIFT]))


# --- Ca dynamics (eqs dCadt, dCadt2) ----------------------------------------------------------
@_eq
def dCa_first(Ca, Cab, p):
    """First-order Ca [M/s] (eq dCadt): (Ca_bar - Ca) / tau_Ca."""
    return (Cab - Ca) / p[TAU_CA]


@_eq
def d2Ca(Ca, dCa, Cab, p):
    """Second-order Ca [M/s^2] (eq dCadt2, G_dc = 1): omega_n^2 (Ca_bar - Ca) - 2 zeta omega_n dCa/dt."""
    w = p[OMEGA_N]
    return w * w * (Cab - Ca) - 2.0 * p[ZETA] * w * dCa


# --- cross-bridge kinetics (eqs phos, dephos, 4state, 4stateSS, 4stateCons) -------------------
@_eq
def rates(Ca, cG, p, passive):
    """(K1 = K6, K2 = K5) [1/s] from [Ca] and [cGMP] [M] (eqs phos, dephos), Hill terms as
    1/(1 + (k/x)^n); Ca clipped at CA_FLOOR; passive: Ca = 0 exactly (K1 = 0, no inhibition)."""
    Cac = np.maximum(Ca, CA_FLOOR)
    if passive:
        K1 = 0.0
        ca_inhib = 1.0
    else:
        K1 = 1.0 / (1.0 + (p[K_CA1] / Cac) ** p[N_CA1])
        ca_inhib = 1.0 / (1.0 + (Cac / p[K_CA2]) ** p[N_CA2])
    cg = np.maximum(cG, 0.0)
    cg_act = 1.0 / (1.0 + (p[K_CGMP] / cg) ** p[N_CGMP])   # cGMP = 0 -> 0
    return K1, 0.55 + 2.0 * cg_act * ca_inhib


@_eq
def qs_numerators(a, b, p):
    """Unnormalised (M, Mp, AMp, AM) of eq 4stateSS with a = K1 = K6, b = K2 = K5 (spanning
    trees of the M-Mp-AMp-AM cycle, the matrix-tree theorem)."""
    k3, k4, k7 = p[K3], p[K4], p[K7]
    return (b * (a * k4 + k3 * k7 + b * k7 + k4 * k7), a * (a * k4 + b * k7 + k4 * k7), a * k3 * (a + k7),
            a * b * k3)


@_eq
def quasi_steady(a, b, p):
    """(M, Mp, AMp, AM) [-], the null vector of eq 4stateSS summing to 1 (eq 4stateCons);
    passive (a = 0): [1, 0, 0, 0]."""
    M, Mp, AMp, AM = qs_numerators(a, b, p)
    s = M + Mp + AMp + AM
    return M / s, Mp / s, AMp / s, AM / s


@_eq
def kinetics(K1, K2, M, Mp, AMp, AM, p):
    """d(M, Mp, AMp, AM)/dt [1/s] (eq 4state, K5 = K2, K6 = K1)."""
    k3, k4, k7 = p[K3], p[K4], p[K7]
    return (-K1 * M + K2 * Mp + k7 * AM, K1 * M - (K2 + k3) * Mp + k4 * AMp,
            k3 * Mp - (k4 + K2) * AMp + K1 * AM, K2 * AMp - (K1 + k7) * AM)


# --- mechanics (eqs FaNew, passiveNew, FT, FMFP) ----------------------------------------------
@_eq
def overlap(lam, p):
    """Actin-myosin overlap G = exp(-(lambda - lambda_opt)^2 / (2 eta)) [-] (eq FaNew)."""
    d = lam - p[LAMBDA_OPT]
    return np.exp(-d * d / (2.0 * p[ETA]))


@_eq
def passive_force(lam, p):
    """F_p = q1 (exp(q2 (lambda^q3 - 1)) - 1) [N] (eq passiveNew); lambda clipped at 0, the
    exponent at MAX_EXP."""
    z = p[Q2] * (np.maximum(lam, 0.0) ** p[Q3] - 1.0)
    return p[Q1] * np.expm1(np.minimum(z, MAX_EXP))


@_eq
def active_force(lam_dot, AMp, AM, G, p):
    """F_a [N] = l0 (f1 AMp (v/l0 + lambda_dot) + f2 AM lambda_dot) G (eq FaNew); at
    lambda_dot = 0 the isometric force f1 v AMp G (eq FTSS)."""
    return (p[F1] * AMp * (p[V_XB] + p[L0] * lam_dot) + p[F2] * AM * p[L0] * lam_dot) * G


@_eq
def isometric_load(lam, AMp, p):
    """F_p + F_a at lambda_dot = 0 [N] (eqs passiveNew, FaNew/FTSS: f1 v AMp G): what the
    pressure force w_c P r (eqs FT, FMFP) balances at steady length."""
    return passive_force(lam, p) + p[F1] * p[V_XB] * AMp * overlap(lam, p)


@_eq
def force_excess(lam, r, P, AMp, p):
    """g = w_c P r - F_p - F_a|lambda_dot=0 [N] (eq mechSS): g = 0 is the mechanical steady
    state, and dlambda/dt = g / friction."""
    return p[W_C] * P * r - isometric_load(lam, AMp, p)


@_eq
def friction(lam, AMp, AM, p, passive):
    """The force per lambda_dot in F_a [N*s] (eq FaNew), l0 (G (f1 AMp + f2 AM) + floor), the floor
    PASSIVE_FRICTION in passive mode and FRICTION_FLOOR otherwise."""
    floor = PASSIVE_FRICTION if passive else FRICTION_FLOOR
    return p[L0] * (overlap(lam, p) * (p[F1] * AMp + p[F2] * AM) + floor)


@_eq
def dlam_affine(lam, r, AMp, AM, p, passive):
    """(a [1/s], b [1/(s Pa)]) with dlambda/dt = a + b P: the force balance w_c P r = F_p + F_a
    (eqs FT, FMFP, FaNew, passiveNew) solved for lambda_dot, D = friction."""
    D = friction(lam, AMp, AM, p, passive)
    return -isometric_load(lam, AMp, p) / D, p[W_C] * r / D


# --- NO transport (sec. NOeqns: eqs cbbar, cbbarpsi, psi, cinv, dNOdt, NOSS) -------------------
@_eq
def no_rates(p):
    """(h_w, r_dw, s_w, k_tau) scaled by no_speed (sec. dynfitting)."""
    ns = p[NO_SPEED]
    return p[H_W] * ns, p[R_DW] * ns, p[S_W] * ns, p[K_TAU] * ns


@_eq
def tau_hat(dP, r, p):
    """Normalised wall shear stress (|dP| / dP0)(r / r0) [-] (sec. NOeqns): NO is produced
    whichever way the blood flows."""
    return (np.abs(dP) / p[DP0]) * (r / p[R0])


@_eq
def no_loss(r, h_w, p):
    """Blood NO loss per unit length h_w + r_db A_b [m^2/s] (the exponent of eq cinv)."""
    return h_w + p[R_DB] * (math.pi * r * r)


@_eq
def transport_number(Q, r, h_w, p):
    """x = (h_w + r_db A_b) L / |Q| [-] (eqs cbbar, cinv); inf at Q = 0."""
    aq = np.abs(Q)
    return select(aq > 0.0, no_loss(r, h_w, p) * p[L_VES] / aq, math.inf)


@_eq
def psi(x):
    """psi = 1 - (1 - exp(-x))/x (eq psi): its series below PSI_SERIES_X, 1 at x = inf."""
    series = x * (1 / 2 - x * (1 / 6 - x * (1 / 24 - x * (1 / 120 - x / 720))))
    return select(x < PSI_SERIES_X, series, 1.0 - (-np.expm1(-x)) / x)


@_eq
def cb_inf(Cw, r, h_w, p):
    """Far-downstream blood [NO] [M], h_w (C_w / gamma_wb) / (h_w + r_db A_b) (eqs cbbar, cinv)."""
    return h_w * (Cw / p[GAMMA_WB]) / no_loss(r, h_w, p)


@_eq
def cb_mean(Cw, r, x, h_w, p):
    """Length-averaged blood [NO] [M] (eqs cbbar, cbbarpsi): (Cb_inf - C_in) psi(x) + C_in."""
    return (cb_inf(Cw, r, h_w, p) - p[C_IN]) * psi(x) + p[C_IN]


@_eq
def outlet_concentration(c_far, c_in, x):
    """Concentration at the outlet of a perfused length with transport number x (eq cinv):
    (c_far - c_in)(1 - e^-x) + c_in; the blood's [NO] with c_far = Cb_inf (the tracer pools'
    feed too).  x = inf (no flow) gives c_far."""
    return (c_far - c_in) * (-np.expm1(-x)) + c_in


@_eq
def dCw(Cw, cbm, tau, h_w, r_dw, s_w, k_tau, p):
    """Wall [NO] rate [M/s] (eq dNOdt):
    -(h_w/A_w)(C_w/gamma_wb - Cb_mean) - r_dw C_w + s_w + k_tau tau_hat / A_w."""
    Aw = wall_area(p)
    return -(h_w / Aw) * (Cw / p[GAMMA_WB] - cbm) - r_dw * Cw + s_w + k_tau * tau / Aw


@_eq
def cw_steady(r, x, tau, h_w, r_dw, s_w, k_tau, p):
    """Steady wall [NO] [M] (eq NOSS, dCw = 0 solved for C_w):
    ((h_w/A_w) C_in (1 - psi) + s_w + k_tau tau_hat/A_w)
    / (h_w/(A_w gamma_wb) + r_dw - h_w^2 psi / (A_w (h_w + A_b r_db) gamma_wb))."""
    Aw = wall_area(p)
    g = p[GAMMA_WB]
    ps = psi(x)
    num = (h_w / Aw) * p[C_IN] * (1.0 - ps) + s_w + k_tau * tau / Aw
    return num / (h_w / (Aw * g) + r_dw - h_w * h_w * ps / (Aw * no_loss(r, h_w, p) * g))
