"""A vectorised stiff integrator for a batch of independent runs of one circuit.

Every member has its own time, step size and error control, but all members advance
together: each step costs one batched Jacobian (all finite-difference columns of all members
in one right-hand-side evaluation), two batched right-hand sides and batched dense (nx x nx)
linear solves.  The Python overhead is paid once per step for the whole batch, which is what
makes batches (frequency responses, parameter maps) fast.

Method: ROS34PW2 (Rang & Angermann 2005, BIT 45:761), a 4-stage, order-3, L-stable and
stiffly accurate Rosenbrock-W method with an embedded order-2 solution for error control.
Being a W-method it stays consistent with an approximate Jacobian, so the (batched
finite-difference) Jacobian is reused over several steps and refreshed after rejections.
Hard state limits (e.g. the Ca floor of second-order Ca): a member whose step would cross the
limit retries with a secant-shortened step until it lands on it, then the state is set to
the limit and its rate state reset to zero (the same rule as the single-run integrator).
Output: cubic Hermite interpolation onto a common output grid.
"""
from __future__ import annotations

import numpy as np

# ROS34PW2 tableau (Hairer convention: W = I - gamma h J,
# W k_i = h f(t + c_i h, x + sum_j A_ij k_j) + h J sum_j G_ij k_j + h^2 d_i f_t)
GAMMA = 4.3586652150845900e-01
A = np.array([[0.0, 0.0, 0.0, 0.0],
              [8.7173304301691801e-01, 0.0, 0.0, 0.0],
              [8.4457060015369423e-01, -1.1299064236397981e-01, 0.0, 0.0],
              [0.0, 0.0, 1.0, 0.0]])
G = np.array([[0.0, 0.0, 0.0, 0.0],
              [-8.7173304301691801e-01, 0.0, 0.0, 0.0],
              [-9.0338057013044082e-01, 5.4180672388095326e-02, 0.0, 0.0],
              [2.4212380706095346e-01, -1.2232505839045147e+00, 5.4526025533510214e-01, 0.0]])
B_SOL = np.array([2.4212380706095346e-01, -1.2232505839045147e+00, 1.5452602553351023e+00,
                  4.3586652150845900e-01])
B_EMB = np.array([3.7810903145819369e-01, -9.6042292212423178e-02, 5.0000000000000000e-01,
                  2.1793326075422950e-01])
C_T = A.sum(axis=1)
D_T = GAMMA + G.sum(axis=1)
ORDER = 3
JAC_REUSE = 4  # accepted steps per Jacobian (W-method)


class BatchResult:
    """``t`` (T,), ``x`` (B, T, nx), ``ok`` (B,), ``message`` list, ``stats`` dict."""

    def __init__(self, t, x, ok, message, stats):
        self.t, self.x, self.ok, self.message, self.stats = t, x, ok, message, stats


def integrate(circuit, x0, t_out, rtol=1e-5, atol=None, h0=1e-3, max_steps=200000, h_max=np.inf):
    """Integrate every member of a batch circuit (B parameter sets) from x0 (B, nx) at t_out[0]
    and return the states on the grid t_out (T,).  Members that fail are marked (ok False)
    with a reason; the others are unaffected."""
    B, nx = np.shape(x0)
    assert circuit.B == B or circuit.B == 1
    t_out = np.asarray(t_out, dtype=float)
    T = len(t_out)
    scales = circuit.state_scales
    atol_v = (rtol * 1e-3 if atol is None else atol) * scales
    limits = circuit.hard_limits()
    x = np.array(x0, dtype=float)
    t = np.full(B, t_out[0])
    t_end = t_out[-1]
    h = np.full(B, h0)
    active = np.ones(B, bool)
    ok = np.ones(B, bool)
    message = [""] * B
    out = np.full((B, T, nx), np.nan)
    out[:, 0] = x
    next_out = np.ones(B, dtype=int)
    f_cur = _rhs(circuit, t, x)
    nsteps = nrej = 0
    eye = np.eye(nx)
    Jac = np.zeros((B, nx, nx))
    Ft = np.zeros((B, nx))
    age = np.full(B, JAC_REUSE)  # steps since the member's Jacobian was computed
    while active.any() and nsteps < max_steps:
        idx = np.nonzero(active)[0]
        ti, xi, hi, fi = t[idx], x[idx], np.minimum(h[idx], t_end - t[idx]), f_cur[idx]
        hi = np.minimum(hi, h_max)
        c = circuit.subset(idx)
        try:
            stale = age[idx] >= JAC_REUSE
            if stale.any():
                cs = circuit.subset(idx[stale])
                Jn, Fn = jac_and_ft(cs, ti[stale], xi[stale], fi[stale])
                Jac[idx[stale]], Ft[idx[stale]], age[idx[stale]] = Jn, Fn, 0
            x_new, err_vec = _step(c, ti, xi, fi, hi, Jac[idx], Ft[idx], eye)
        except Exception as exc:  # a member left the physical domain: find which
            _fail_members(circuit, idx, ti, xi, hi, ok, active, message, exc)
            continue
        scale = atol_v + rtol * np.maximum(np.abs(xi), np.abs(x_new))
        err = np.sqrt(np.mean((err_vec / scale) ** 2, axis=1))
        finite = np.all(np.isfinite(x_new), axis=1) & np.isfinite(err)
        err = np.where(finite, err, np.inf)
        accept = err <= 1.0
        # hard limits: a step that crosses a bound is shortened to land on it
        landed = np.zeros(len(idx), bool)
        for li, bound, reset in limits:
            cross = accept & (x_new[:, li] < bound)
            if cross.any():
                frac = (xi[:, li] - bound) / np.maximum(xi[:, li] - x_new[:, li], 1e-300)
                near = cross & (np.abs(x_new[:, li] - bound) <= 1e-3 * np.abs(xi[:, li] - bound) + atol_v[li])
                landed |= near
                retry = cross & ~near
                accept &= ~retry
                hi_new = np.where(retry, hi * np.clip(frac, 0.05, 0.999), hi)
                h[idx] = np.where(retry, hi_new, h[idx])
        # step-size control (embedded order 2 -> exponent 1/3)
        fac = np.clip(0.9 * np.where(err > 0, err, 1e-10) ** (-1.0 / ORDER), 0.2, 5.0)
        age[idx] = np.where(accept, age[idx] + 1, JAC_REUSE)  # refresh J after a rejection
        rej = ~accept & ~landed
        grow = np.where(accept, fac, np.where(np.isfinite(err), np.minimum(fac, 0.5), 0.25))
        h_next = np.where(accept | rej, hi * grow, h[idx])
        # members that hit a limit keep the shortened h chosen above
        crossed_retry = ~accept & ~rej
        h[idx] = np.where(crossed_retry, h[idx], h_next)
        nrej += int(np.sum(~accept))
        if accept.any():
            a = idx[accept]
            xa = x_new[accept]
            ta = ti[accept] + hi[accept]
            for li, bound, reset in limits:
                hit = xa[:, li] <= bound * (1 + 1e-12) + 1e-300
                if hit.any():
                    xa[hit, li] = bound
                    if reset is not None:
                        xa[hit, reset] = np.maximum(xa[hit, reset], 0.0)
            fa = _rhs(circuit, ta, xa, members=a, B=B)
            # dense output on the grid: cubic Hermite between (t, x, f) and (ta, xa, fa)
            _emit(out, t_out, next_out, a, t[a], x[a], f_cur[a], ta, xa, fa)
            t[a], x[a], f_cur[a] = ta, xa, fa
            done = t[a] >= t_end - 1e-12 * max(1.0, abs(t_end))
            active[a[done]] = False
        tiny = (h[idx] < 1e-12 * np.maximum(1.0, np.abs(t[idx]))) & active[idx]
        if tiny.any():
            for m in idx[tiny]:
                ok[m], active[m] = False, False
                message[m] = f"step size too small at t = {t[m]:.6g} s"
        nsteps += 1
    for m in np.nonzero(active)[0]:
        ok[m] = False
        message[m] = f"step limit ({max_steps}) reached at t = {t[m]:.6g} s"
    return BatchResult(t_out, out, ok, message, {"steps": nsteps, "rejected": nrej})


def _rhs(circuit, t, x, members=None, B=None):
    """f for a subset of members (their parameters) at per-member times t."""
    c = circuit if members is None else circuit.subset(members)
    return c.evaluate(np.asarray(t, dtype=float).reshape(-1, 1), x)


def jac_and_ft(circuit, t, x, f0):
    """Batched finite-difference Jacobian (n, nx, nx) and df/dt (n, nx), one evaluation."""
    n, nx = x.shape
    hx = 1e-7 * np.maximum(np.abs(x), circuit.state_scales)
    ht = 1e-7 * np.maximum(np.abs(t), 1.0)
    stack = np.repeat(x[:, None, :], nx + 1, axis=1)
    stack[:, np.arange(nx), np.arange(nx)] += hx
    tt = np.repeat(t[:, None], nx + 1, axis=1)
    tt[:, nx] += ht
    F = circuit.evaluate(tt.reshape(-1, 1), stack.reshape(n * (nx + 1), nx)).reshape(n, nx + 1, nx)
    J = np.swapaxes((F[:, :nx, :] - f0[:, None, :]) / hx[:, :, None], 1, 2)
    return J, (F[:, nx, :] - f0) / ht[:, None]


def _step(c, t, x, f0, h, J, f_t, eye):
    """One ROS34PW2 step for all members of the (sub)circuit c.  Returns (x_new, error vector)."""
    n, nx = x.shape
    W = eye[None] - (GAMMA * h)[:, None, None] * J
    lu = np.linalg.inv(W)  # (n, nx, nx): small dense blocks; 4 stage solves reuse it
    hh = h[:, None]
    k = []
    for i in range(4):
        xs = x.copy()
        gsum = np.zeros_like(x)
        for j in range(i):
            if A[i, j]:
                xs += A[i, j] * k[j]
            if G[i, j]:
                gsum += G[i, j] * k[j]
        fi = f0 if i == 0 else c.evaluate((t + C_T[i] * h).reshape(-1, 1), xs)
        rhs = hh * fi + hh * np.einsum("nij,nj->ni", J, gsum) + hh * hh * D_T[i] * f_t
        k.append(np.einsum("nij,nj->ni", lu, rhs))
    x_new = x + sum(B_SOL[i] * k[i] for i in range(4))
    err = sum((B_SOL[i] - B_EMB[i]) * k[i] for i in range(4))
    return x_new, err


def _emit(out, t_out, next_out, members, t0, x0, f0, t1, x1, f1):
    """Fill output grid points t0 < t_out <= t1 by cubic Hermite interpolation."""
    for j, m in enumerate(members):
        k = next_out[m]
        stop = np.searchsorted(t_out, t1[j], side="right")
        if stop <= k:
            continue
        ts = t_out[k:stop]
        dt = t1[j] - t0[j]
        s = ((ts - t0[j]) / dt)[:, None]
        h00 = (1 + 2 * s) * (1 - s) ** 2
        h10 = s * (1 - s) ** 2
        h01 = s * s * (3 - 2 * s)
        h11 = s * s * (s - 1)
        out[m, k:stop] = h00 * x0[j] + h10 * dt * f0[j] + h01 * x1[j] + h11 * dt * f1[j]
        next_out[m] = stop


def _fail_members(circuit, idx, t, x, h, ok, active, message, exc):
    """Evaluate members one by one to find which made the batched step fail."""
    for j, m in enumerate(idx):
        try:
            c = circuit.subset([m])
            f0 = _rhs(c, t[j:j + 1], x[j:j + 1])
            J, ft = jac_and_ft(c, t[j:j + 1], x[j:j + 1], f0)
            _step(c, t[j:j + 1], x[j:j + 1], f0, h[j:j + 1], J, ft, np.eye(x.shape[1]))
        except Exception as e:  # noqa: BLE001 - recorded as the member's failure reason
            ok[m], active[m] = False, False
            message[m] = f"failed at t = {t[j]:.6g} s: {e}"
