"""Steady state of the arteriole for given P (intramural) and dP (drop along the vessel), in Pa.

Thesis sec. ssmodel.  At a given cell length lambda everything else is explicit:
    r      eq l2r,     Q = pi r^4 dP / (8 mu_b L)   (eq Poiseuille, one vessel)
    C_w    eq NOSS,    cGMP eq NOcGMP,   sigma = P r / t_w,   Ca = Ca_bar(sigma)  (eq ssCa)
    alpha  quasi-steady kinetics (eq 4stateSS; passive: Ca = 0, alpha = [1, 0, 0, 0])
so the force balance  g(lambda) = w_c P r - F_p - F_a|lambda_dot=0 = 0  (eq mechSS) is 1-D.
Its roots are bracketed on a lambda grid from r = r_min to r = r_max, and refined by a
vectorised Illinois (regula falsi) iteration.  dlambda/dt = g / friction with a positive
friction, so a root where g falls through zero (+ to -) is stable for the 1-D reduced dynamics
(Ca, C_w and alpha slaved) and a root where it rises is unstable.
"""
from __future__ import annotations

import warnings

import numpy as np

from . import equations as eq
from .model import resolve_options


class SteadyStateWarning(RuntimeWarning):
    """Several equilibria, or none in the searched radius range."""


def slaved(lam, P, dP, p, passive=False) -> dict:
    """Everything that is explicit at a given lambda (``p`` the parameter vector,
    equations.vector), and the force residual g [N] of eq mechSS."""
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        r = eq.l2r(lam, p)
        Q = eq.flow(r, dP, p)
        tau = eq.tau_hat(dP, r, p)
        h_w, r_dw, s_w, k_tau = eq.no_rates(p)
        x = eq.transport_number(Q, r, h_w, p)
        Cw = eq.cw_steady(r, x, tau, h_w, r_dw, s_w, k_tau, p)
        cG = eq.cgmp(Cw, p)
        sigma = eq.wall_stress(P, r, p)
        Ca = np.zeros(np.shape(sigma)) if passive else eq.ca_bar(sigma, p)
        alpha = eq.quasi_steady(*eq.rates(Ca, cG, p, passive), p)
        g = eq.force_excess(lam, r, P, alpha[2], p)
        Cb_mean = eq.cb_mean(Cw, r, x, h_w, p)
    return dict(lambda_=lam, r=r, Q=Q, tau_hat=tau, Cw=Cw, cGMP=cG, sigma=sigma, Ca=Ca,
                alpha=alpha, g=g, Cb_mean=Cb_mean)


def _illinois(f, a, b, fa, fb, xtol, maxiter):
    """Vectorised Illinois iteration on brackets [a, b] with fa, fb of opposite sign (not scipy's
    optimize.elementwise.find_root: importing scipy.optimize costs ~0.4 s of every ``op``)."""
    done = (fa == 0) | (fb == 0)
    x = np.where(fa == 0, a, b)
    for _ in range(maxiter):
        if np.all(done):
            break
        with np.errstate(invalid="ignore", divide="ignore"):
            c = b - fb * (b - a) / (fb - fa)
        c = np.where(np.isfinite(c) & (c > np.minimum(a, b)) & (c < np.maximum(a, b)),
                     c, 0.5 * (a + b))
        fc = f(c)
        flip = np.sign(fc) != np.sign(fb)          # root between b and c: a <- b
        a_new = np.where(flip, b, a)
        fa_new = np.where(flip, fb, 0.5 * fa)      # Illinois: halve the stale end
        a, fa = np.where(done, a, a_new), np.where(done, fa, fa_new)
        b, fb = np.where(done, b, c), np.where(done, fb, fc)
        x = np.where(done, x, c)
        done = done | (fc == 0) | (np.abs(b - a) <= xtol * np.maximum(1.0, np.abs(b)))
    return x, done


def solve_steady(P, dP, params, options=None, *, r_min=1e-6, r_max=300e-6, n_grid=400,
                 branch="high", r_guess=None, xtol=1e-14, maxiter=100, warn=True) -> dict:
    """Steady states for arrays of P, dP [Pa] and parameter arrays (all broadcast together).

    Returns a dict of arrays: the states under their state names (Ca, dCa (= 0), Cw, lambda,
    M, Mp, AMp, AM), so ``model.pack(result, options)`` gives the state vector, plus r [m],
    alpha (..., 4), Cb_mean, cGMP, sigma, Q, tau_hat, ``n_roots`` (all equilibria found in
    [r_min, r_max]), ``n_stable`` and ``found`` (False: no stable root in range, values NaN).
    With several stable roots: ``r_guess`` [m] picks the one nearest to it, else ``branch``
    'high' (largest radius) or 'low'.  Warns (SteadyStateWarning) on multiplicity or absence.
    Roots closer together than the grid step (r range / n_grid) can be missed."""
    o = resolve_options(options)
    p = eq.vector(params)
    passive = o["passive"]
    P = np.asarray(P, dtype=float)
    dP = np.asarray(dP, dtype=float)
    shape = np.broadcast_shapes(P.shape, dP.shape, p.shape[1:])
    lam_lo, lam_hi = eq.r2l(r_min, p), eq.r2l(r_max, p)
    s = np.linspace(0.0, 1.0, n_grid).reshape((-1,) + (1,) * len(shape))
    grid = np.broadcast_to(lam_lo + (lam_hi - lam_lo) * s, (n_grid,) + shape)
    g = slaved(grid, P, dP, p, passive)["g"]
    pos = g > 0
    down = pos[:-1] & ~pos[1:]          # stable crossings
    up = ~pos[:-1] & pos[1:]            # unstable crossings
    n_stable = down.sum(axis=0)
    n_roots = n_stable + up.sum(axis=0)
    found = n_stable > 0
    if r_guess is not None:
        mid = 0.5 * (grid[:-1] + grid[1:])
        dist = np.where(down, np.abs(mid - eq.r2l(np.asarray(r_guess, dtype=float), p)), np.inf)
        k = np.argmin(dist, axis=0)
    elif branch == "high":
        k = (n_grid - 2) - np.argmax(down[::-1], axis=0)
    elif branch == "low":
        k = np.argmax(down, axis=0)
    else:
        raise ValueError(f"branch={branch!r}: choose 'high' or 'low'")
    k = np.where(found, k, 0)[None]
    a = np.take_along_axis(grid, k, 0)[0]
    b = np.take_along_axis(grid, k + 1, 0)[0]
    fa = np.where(found, np.take_along_axis(g, k, 0)[0], 1.0)
    fb = np.where(found, np.take_along_axis(g, k + 1, 0)[0], -1.0)
    lam, conv = _illinois(lambda x: slaved(x, P, dP, p, passive)["g"], a, b, fa, fb,
                          xtol, maxiter)
    lam = np.where(found, lam, np.nan)
    if warn and np.any(n_roots > 1):
        warnings.warn(f"arteriole steady state: several equilibria for {np.sum(n_roots > 1)} of "
                      f"{int(np.prod(shape))} cases (returned the '{branch}' stable one unless "
                      f"r_guess was given; see n_roots)", SteadyStateWarning, stacklevel=2)
    if warn and not np.all(found):
        warnings.warn(f"arteriole steady state: no stable equilibrium with {r_min:g} m <= r <= "
                      f"{r_max:g} m for {np.sum(~found)} cases (NaN returned)",
                      SteadyStateWarning, stacklevel=2)
    with np.errstate(invalid="ignore"):
        sl = slaved(lam, P, dP, p, passive)
    al = [np.broadcast_to(x, shape) for x in sl["alpha"]]
    out = {"Ca": np.broadcast_to(sl["Ca"], shape), "Cw": np.broadcast_to(sl["Cw"], shape),
           "lambda": lam, "r": sl["r"], "cGMP": sl["cGMP"], "sigma": sl["sigma"],
           "Q": np.broadcast_to(sl["Q"], shape), "tau_hat": sl["tau_hat"],
           "Cb_mean": np.broadcast_to(sl["Cb_mean"], shape),
           "alpha": np.stack(al, axis=-1), "n_roots": n_roots, "n_stable": n_stable,
           "found": found, "converged": conv | ~found}
    out.update(zip(eq.BRIDGE_STATES, al))
    out["dCa"] = np.zeros(shape)
    return out
