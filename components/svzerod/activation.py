"""Elastance activation functions of svZeroDSolver's chambers (a periodic function of time).

Equations from SimVascular/svZeroDSolver src/model/ActivationFunction.cpp (commit c7b0ca09):
  half_cosine       t_c = max(0, fmod(t, T) - t_active); A = 0.5 - 0.5 cos(2 pi t_c / t_twitch)
                    while t_c <= t_twitch, else 0
  piecewise_cosine  s = fmod(t - contract_start, T): 0.5 (1 - cos(pi s / contract_duration)) for
                    0 <= s < contract_duration; else s = fmod(t - relax_start, T):
                    0.5 (1 + cos(pi s / relax_duration)) for 0 <= s < relax_duration; else 0
  two_hill          s = (fmod(t, T) - t_shift) mod T; g1 = (s/tau_1)^m1, g2 = (s/tau_2)^m2;
                    A = N g1/(1 + g1) / (1 + g2), N = 1 / max over [0, T) of the same product
  wrapping_cosine   Tsa' = T Tsa, tp = T / tpwave, tc = fmod(t, T):
                    tc <= tp: 0.5 (1 - cos(2 pi (tc - tp + Tsa')/Tsa'));
                    T - Tsa' + tp <= tc < T: 0.5 (1 - cos(2 pi (tc - tp - (T - Tsa'))/Tsa')); else 0
  fourier           tc = fmod(t, T); F = sum_i a_i cos(2 pi i tc/T) - b_i sin(2 pi i tc/T) (their
                    25-mode table FT_ELAST, J. Tran / Menon 2023); A = (F - min F)/(max F - min F)
fmod is C's (sign of the dividend), as theirs.  two_hill is normalised by its exact maximum
(bisection on d/ds log A = 0) instead of their 1e-5 s scan, fourier by the min and max of
their 10000-point scan of the cycle (constants: docs/svzerod.md).
Chamber components take these as parameters (``ACT_PARAMS``, times in s, the rest
dimensionless) and the option ``activation``; only the parameters of the chosen function are used.
"""
from __future__ import annotations

import math

import numpy as np

from hemocircuit.component import Observable, open_branches, Param, periodic_breakpoints, State, Storage

from ..common import flow_observables, jit

KINDS = ("half_cosine", "piecewise_cosine", "two_hill", "wrapping_cosine", "fourier")

#: (name, unit) in the order the kernels read them
ACT_PARAMS = (("t_active", "s"), ("t_twitch", "s"),
              ("contract_start", "s"), ("relax_start", "s"), ("contract_duration", "s"), ("relax_duration", "s"),
              ("t_shift", "s"), ("tau_1", "s"), ("tau_2", "s"), ("m1", "dimensionless"), ("m2", "dimensionless"),
              ("Tsa", "dimensionless"), ("tpwave", "dimensionless"))
#: defaults: the values of their test cases (chamber_elastance_inductor, piecewise_Chamber_and_Valve
#: ventricle, closed_loop_two_hill LV, closedLoopHeart_singleVessel atria)
_DEFAULTS = {"t_active": 0.2, "t_twitch": 0.3, "contract_start": 0.207, "relax_start": 0.29625,
             "contract_duration": 0.08925, "relax_duration": 0.26975, "t_shift": 0.207, "tau_1": 0.18551724137931036,
             "tau_2": 0.31172413793103454, "m1": 1.32, "m2": 27.4, "Tsa": 0.40742, "tpwave": 8.976868}

#: the parameters each function needs (checked > 0 where they divide)
USED = {"half_cosine": ("t_active", "t_twitch"),
        "piecewise_cosine": ("contract_start", "relax_start", "contract_duration", "relax_duration"),
        "two_hill": ("t_shift", "tau_1", "tau_2", "m1", "m2"),
        "wrapping_cosine": ("Tsa", "tpwave"),
        "fourier": ()}
POSITIVE = ("t_twitch", "contract_duration", "relax_duration", "tau_1", "tau_2", "m1", "m2", "Tsa", "tpwave")


#: their FT_ELAST table (ActivationFunction.cpp): (a_i, b_i) of cos and -sin of mode i
FT_ELAST = np.array([[0.283748803, 0.000000000], [0.031830626, -0.374299825], [-0.209472400, -0.018127770],
                     [0.020520047, 0.073971113], [0.008316883, -0.047249597], [-0.041677660, 0.003212163],
                     [0.000867323, 0.019441411], [-0.001675379, -0.005565534], [-0.011252277, 0.003401432],
                     [-0.000414677, 0.008376795], [0.000253749, -0.000071880], [-0.002584966, 0.001566861],
                     [0.000584752, 0.003143555], [0.000028502, -0.000024787], [0.000022961, -0.000007476],
                     [0.000018735, -0.000001281], [0.000015573, 0.000001781], [0.000013133, 0.000003494],
                     [0.000011199, 0.000004507], [0.000009634, 0.000005117], [0.000008343, 0.000005481],
                     [0.000007265, 0.000005687], [0.000006354, 0.000005789], [0.000005575, 0.000005821],
                     [0.000004903, 0.000005805]])
_FT_A = np.ascontiguousarray(FT_ELAST[:, 0])
_FT_B = np.ascontiguousarray(FT_ELAST[:, 1])


def _fourier_scan(n=10000):
    """(min, max - min) of the series over their n-point scan of one cycle (phase k/n):
    sum_j A_j cos(2 pi j k/n) - B_j sin(2 pi j k/n) = Re(n ifft(A + iB)) (an FFT, not the
    n x 25 cosines: 3 ms instead of 20 at import)."""
    c = np.zeros(n, complex)
    c[:_FT_A.size] = _FT_A + 1j * _FT_B
    f = (np.fft.ifft(c) * n).real
    return float(f.min()), float(f.max() - f.min())


FOURIER_MIN, FOURIER_RANGE = _fourier_scan()


@jit
def fourier_raw(tc, T):
    """Their un-normalised 25-mode series at time tc in the cycle (the heart block's F(t)).
    cos and sin of mode i by the angle-addition recurrence from mode 1: two trigonometric
    calls instead of 50 (the heart evaluates this in every derivs call); it agrees with the
    direct sum to ~1e-15 (tests/test_svzerod_blocks.py)."""
    w = 2.0 * math.pi * tc / T
    c1, s1 = math.cos(w), math.sin(w)
    c, s = 1.0, 0.0
    F = 0.0
    for i in range(25):
        F += _FT_A[i] * c - _FT_B[i] * s
        c, s = c * c1 - s * s1, s * c1 + c * s1
    return F


def act_parameters():
    """Component parameter declarations of the activation functions."""
    out = {"period": Param("s", default="1 s", lower=0.0, lower_open=True, doc="cardiac period T")}
    for name, unit in ACT_PARAMS:
        d = _DEFAULTS[name]
        out[name] = Param(unit, default=f"{d} {unit}" if unit != "dimensionless" else str(d),
                          doc=f"activation parameter (used by {', '.join(k for k in KINDS if name in USED[k])})")
    return out


class Activated:
    """Mixin of the chambers driven by an activation function (their option ``activation``):
    terminals in, out, ref; their volume Vc stored from in to ref by branch 3 (q = dVc/dt)."""

    time_dependent = True
    terminals = ("in", "out", "ref")
    STATES = (State("Vc", "mL", 10.0, "chamber volume"),)
    STORAGES = (Storage("in", "ref", "Vc", state="Vc"),)
    OBSERVABLES = (Observable("Vc", "mL", "chamber volume", state_only=True),
                   *flow_observables("the chamber", "the chamber"))

    def check(self, p):
        """The chosen function's dividing parameters are > 0."""
        kind, out = self.opts["activation"], []
        for name in USED[kind]:
            if name in POSITIVE:
                bad = np.any(np.asarray(p[name]) <= 0, axis=tuple(range(np.ndim(p[name]) - 1)))
                out += [(int(i), f"activation {kind} needs {name} > 0") for i in np.nonzero(np.atleast_1d(bad))[0]]
        return out

    def breakpoints(self, p, t0, t1):
        """The activation's kinks (kink_phases): steps end there."""
        return activation_breakpoints(self.opts["activation"], p, t0, t1)

    def kernel_options(self):
        """[activation kind (index in KINDS)]."""
        return np.array([KINDS.index(self.opts["activation"])], dtype=np.int64)

    def dc_stamp(self, p, A_loc, b_loc, keep):
        """Steady state: the store open (q = 0) unless it anchors a conservation law."""
        return open_branches(A_loc, b_loc, (3,), keep)


@jit
def _two_hill(s, tau1, tau2, m1, m2):
    """(g1/(1 + g1)/(1 + g2), its slope d log/d log s) with g1 = (s/tau1)^m1, g2 = (s/tau2)^m2."""
    g1 = (s / tau1) ** m1
    g2 = (s / tau2) ** m2
    return g1 / (1.0 + g1) / (1.0 + g2), m1 / (1.0 + g1) - m2 * g2 / (1.0 + g2)


@jit
def _two_hill_max(T, tau1, tau2, m1, m2):
    lo, hi = math.log(T) - 40.0, math.log(T)
    s = T
    if _two_hill(s, tau1, tau2, m1, m2)[1] < 0.0:  # the maximum lies inside (0, T)
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            if _two_hill(math.exp(mid), tau1, tau2, m1, m2)[1] > 0.0:
                lo = mid
            else:
                hi = mid
        s = math.exp(0.5 * (lo + hi))
    return _two_hill(s, tau1, tau2, m1, m2)[0]


@jit
def activation(kind, t, T, a):
    """Activation in [0, 1] at time t for period T; ``a`` the 13 ACT_PARAMS in order."""
    if kind == 0:  # half_cosine
        tc = np.fmod(t, T)
        t_contract = tc - a[0] if tc >= a[0] else 0.0
        if t_contract <= a[1]:
            return -0.5 * math.cos(2.0 * math.pi * t_contract / a[1]) + 0.5
        return 0.0
    if kind == 1:  # piecewise_cosine
        s = np.fmod(t - a[2], T)
        if 0.0 <= s and s < a[4]:
            return 0.5 * (1.0 - math.cos(math.pi * s / a[4]))
        s = np.fmod(t - a[3], T)
        if 0.0 <= s and s < a[5]:
            return 0.5 * (1.0 + math.cos(math.pi * s / a[5]))
        return 0.0
    if kind == 2:  # two_hill
        tc = np.fmod(t, T)
        s = np.fmod(tc - a[6], T)
        if s < 0.0:
            s += T
        return _two_hill(s, a[7], a[8], a[9], a[10])[0] / _two_hill_max(T, a[7], a[8], a[9], a[10])
    if kind == 4:  # fourier
        return (fourier_raw(np.fmod(t, T), T) - FOURIER_MIN) / FOURIER_RANGE
    return wrapping_cosine(t, T, a[11], a[12])


@jit
def wrapping_cosine(t, T, Tsa, tpwave):
    """The wrapping_cosine activation (also the closed-loop heart's atrial activation AA)."""
    Tsa = T * Tsa
    tp = T / tpwave
    tc = np.fmod(t, T)
    if tc <= tp:
        return 0.5 * (1.0 - math.cos(2.0 * math.pi * (tc - tp + Tsa) / Tsa))
    if tc >= (T - Tsa) + tp and tc < T:
        return 0.5 * (1.0 - math.cos(2.0 * math.pi * (tc - tp - (T - Tsa)) / Tsa))
    return 0.0


def kink_phases(kind, T, a):
    """Times within the first period where A(t) (or its slope) is not smooth, from which the
    function repeats every T (for t >= 0, where their models run): the ends of the cosine
    pieces above and, where a piece can reach past the period (half_cosine, piecewise_cosine),
    the period's start, where fmod wraps; two_hill: its onset at t_shift, where s^m1 starts;
    fourier: none.  ``a``: {ACT_PARAMS name: value}."""
    if kind == "half_cosine":
        return [0.0, a["t_active"], a["t_active"] + a["t_twitch"]]
    if kind == "piecewise_cosine":
        return [0.0, a["contract_start"], a["contract_start"] + a["contract_duration"], a["relax_start"],
                a["relax_start"] + a["relax_duration"]]
    if kind == "two_hill":
        return [a["t_shift"]]
    if kind == "wrapping_cosine":
        return [T / a["tpwave"], T - T * a["Tsa"] + T / a["tpwave"]]
    return []


def activation_breakpoints(kind, p, t0, t1):
    """The kinks of activation ``kind`` in (t0, t1) for every parameter set and element of
    ``p`` (Component.breakpoints of the chambers)."""
    return periodic_breakpoints(lambda T, a: kink_phases(kind, T, a), p, USED[kind], t0, t1)
