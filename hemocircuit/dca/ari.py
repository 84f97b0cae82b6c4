"""The autoregulation index ARI (Tiecks et al. 1995, Stroke 26:1014): the cerebral flow velocity
after a sudden fall of arterial pressure (a thigh-cuff release) compared with the responses of
Tiecks' second-order model family, ARI 0 (no autoregulation) to 9 (the fastest).

The model, driven by the measured pressure normalised by its baseline P0 and the critical
closing pressure CCP, dP = (P - P0)/(P0 - CCP), at sampling rate f:
    x2[n] = x2[n-1] + (x1[n-1] - 2 D x2[n-1]) / (f T)
    x1[n] = x1[n-1] + (dP[n] - x2[n]) / (f T)
    V[n]  = V0 (1 + dP[n] - K x2[n])
with (T [s], D, K) from Tiecks' table.  The ARI is the model whose V fits the measured velocity
best (least squares over the fit interval after the release); between the table's integers T,
D and K are interpolated linearly, so the ARI is found to 0.1.
"""
from __future__ import annotations

import numpy as np

from ..errors import HemocircuitError

#: Tiecks et al. 1995, Table: ARI -> (T [s], D, K)
TIECKS = {0: (2.00, 0.00, 0.00), 1: (2.00, 1.60, 0.20), 2: (2.00, 1.50, 0.40), 3: (2.00, 1.15, 0.60),
          4: (2.00, 0.90, 0.80), 5: (1.90, 0.75, 0.90), 6: (1.60, 0.65, 0.94), 7: (1.20, 0.55, 0.96),
          8: (0.87, 0.52, 0.97), 9: (0.65, 0.50, 0.98)}


def parameters(ari):
    """(T, D, K) of a (fractional) ARI in [0, 9], interpolated linearly in Tiecks' table."""
    if not 0 <= ari <= 9:
        raise HemocircuitError(f"ARI {ari}: the model family runs from 0 to 9")
    lo = min(int(np.floor(ari)), 8)
    w = ari - lo
    return tuple((1 - w) * a + w * b for a, b in zip(TIECKS[lo], TIECKS[lo + 1]))


def model_velocity(dP, fs, ari, V0=1.0):
    """Tiecks' model velocity for the normalised pressure ``dP`` sampled at ``fs`` [Hz], at rest
    (x1 = x2 = 0, dP = 0) before the first sample."""
    T, D, K = parameters(ari)
    x1 = x2 = 0.0
    v = np.empty(len(dP))
    for n, p in enumerate(dP):
        x2 = x2 + (x1 - 2.0 * D * x2) / (fs * T)
        x1 = x1 + (p - x2) / (fs * T)
        v[n] = V0 * (1.0 + p - K * x2)
    return v


def fit_ari(t, P, V, release, baseline=10.0, duration=30.0, ccp=12.0, step=0.1):
    """Fit Tiecks' models to a pressure drop at ``release`` [s] (uniform ``t`` [s], pressure
    ``P`` [mmHg], velocity or flow ``V``).  Baselines P0, V0: means over ``baseline`` seconds
    before the release; the fit runs over ``duration`` seconds from it.  Returns (ari, grid,
    errors, fitted velocity over the fit interval, its times): errors are the mean squared
    differences relative to V0^2."""
    t, P, V = (np.asarray(a, dtype=float) for a in (t, P, V))
    fs = 1.0 / np.median(np.diff(t))
    before = (t >= release - baseline) & (t < release)
    after = (t >= release) & (t <= release + duration)
    dt = 1.0 / fs
    if t[0] > release - baseline + dt / 2 or t[-1] < release + duration - dt / 2 or before.sum() < 2:
        raise HemocircuitError(f"--release {release:g} s: the recording ({t[0]:g}-{t[-1]:g} s) needs {baseline:g} s "
                               f"before the release and {duration:g} s after it")
    P0, V0 = P[before].mean(), V[before].mean()
    if not P0 > ccp:
        raise HemocircuitError(f"--ccp {ccp:g}: the baseline pressure {P0:.4g} must exceed the critical closing "
                               "pressure")
    dP = (P[after] - P0) / (P0 - ccp)
    grid = np.round(np.arange(0.0, 9.0 + step / 2, step), 10)
    errors = np.array([np.mean((model_velocity(dP, fs, a, V0) - V[after]) ** 2) / V0 ** 2 for a in grid])
    best = int(np.argmin(errors))
    return float(grid[best]), grid, errors, model_velocity(dP, fs, grid[best], V0), t[after]


def release_time(t, P):
    """The time of the steepest fall of the pressure (a cuff release), from 1 s means."""
    fs = 1.0 / np.median(np.diff(t))
    k = max(1, int(round(fs)))
    smooth = np.convolve(P, np.ones(k) / k, mode="same")
    slope = np.gradient(smooth, t)
    inner = slice(k, len(t) - k)  # the running mean's edges are not a fall
    return float(t[inner][np.argmin(slope[inner])])
