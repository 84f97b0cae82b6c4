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

from .derivatives import fd_steps, time_step

# the ROS34PW2 tableau (one definition, with the compiled engine's: kernels/tableaus.py)
from .kernels.tableaus import ROS34PW2_A as A, ROS34PW2_B_EMB as B_EMB, ROS34PW2_B_SOL as B_SOL, ROS34PW2_G as G, \
    ROS34PW2_GAMMA as GAMMA

C_T = A.sum(axis=1)
D_T = GAMMA + G.sum(axis=1)
ORDER = 3
JAC_REUSE = 4  # accepted steps per Jacobian (W-method)


class BatchResult:
    """``t`` (T,), ``x`` (B, T, nx), ``ok`` (B,), ``message`` list, ``stats`` dict."""

    def __init__(self, t, x, ok, message, stats):
        self.t, self.x, self.ok, self.message, self.stats = t, x, ok, message, stats


def integrate(circuit, x0, t_out, rtol=1e-5, atol=None, h0=1e-3, max_steps=500000, h_max=np.inf, engine="auto",
              method=None, controller=None):
    """Integrate every member of a batch circuit (B parameter sets) from x0 (B, nx) at the
    first output time and return the states on the output grid: t_out (T,) common to all, or
    (B, T), one grid per member (e.g. whole periods of each member's forcing frequency).
    Members that fail are marked (ok False) with a reason; the others are unaffected, and every
    member's trajectory is independent of which other members share the batch.

    engine: 'auto' runs the compiled kernel (hemocircuit.kernels, one member after another
    inside numba) when the circuit has one, 'numpy' this vectorised code (ROS34PW2).
    method: the compiled engine's method ('bdf' or a Rosenbrock tableau name; None:
    hemocircuit.kernels.tableaus.DEFAULT); ``controller``: its step-size rule for a Rosenbrock
    method (tableaus.CONTROLLERS; None: the method's own; the numpy engine has one rule)."""
    if engine not in ("auto", "numpy"):
        raise ValueError(f"engine {engine!r}: choose 'auto' or 'numpy'")
    if engine == "auto":
        system = circuit.system.compiled()  # the System chooses the engine
        if system is not None:
            return _integrate_compiled(system, circuit, x0, t_out, rtol, atol, h0, max_steps, h_max, method,
                                       controller)
    B, nx = np.shape(x0)
    assert circuit.B == B or circuit.B == 1
    t_out = np.asarray(t_out, dtype=float)
    if t_out.ndim == 1:
        t_out = np.broadcast_to(t_out, (B, len(t_out)))
    T = t_out.shape[1]
    scales = circuit.state_scales
    atol_v = (rtol * 1e-3 if atol is None else atol) * scales
    limits = circuit.hard_limits()
    x = np.array(x0, dtype=float)
    t = t_out[:, 0].copy()
    t_end = t_out[:, -1]
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
        ti, xi, hi, fi = t[idx], x[idx], np.minimum(h[idx], t_end[idx] - t[idx]), f_cur[idx]
        hi = np.minimum(hi, h_max if np.ndim(h_max) == 0 else np.asarray(h_max)[idx])
        c = circuit.subset(idx)
        try:
            # one batched evaluation on the whole active set (so the subset view is reused) once
            # any member is due; only the due members take the new Jacobian, so a member's
            # trajectory does not depend on which other members share its batch
            due = age[idx] >= JAC_REUSE
            if due.any():
                Jn, Fn = jac_and_ft(c, ti, xi, fi)
                d = idx[due]
                Jac[d], Ft[d], age[d] = Jn[due], Fn[due], 0
            x_new, err_vec = _step(c, ti, xi, fi, hi, Jac[idx], Ft[idx], eye)
        except Exception as exc:  # a member left the physical domain: find which
            _fail_members(circuit, idx, ti, xi, hi, ok, active, message, exc)
            continue
        scale = atol_v + rtol * np.maximum(np.abs(xi), np.abs(x_new))
        err = np.sqrt(np.mean((err_vec / scale) ** 2, axis=1))
        finite = np.all(np.isfinite(x_new), axis=1) & np.isfinite(err)
        err = np.where(finite, err, np.inf)
        accept = err <= 1.0
        # step-size control (embedded order 2 -> exponent 1/3)
        fac = np.clip(0.9 * np.where(err > 0, err, 1e-10) ** (-1.0 / ORDER), 0.2, 5.0)
        h[idx] = hi * np.where(accept, fac, np.where(np.isfinite(err), np.minimum(fac, 0.5), 0.25))
        age[idx] = age[idx] + 1
        nrej += int(np.sum(~accept))
        if accept.any():
            a = idx[accept]
            xa = x_new[accept]
            ha = hi[accept]
            ta = ti[accept] + ha
            fa = _rhs(circuit, ta, xa, members=a)
            # hard limits: locate the crossing on the step's cubic Hermite interpolant, end
            # the step there, put the state on the bound and reset its rate state
            hit_any = np.zeros(len(a), bool)
            for li, bound, reset in limits:
                hit = xa[:, li] < bound
                if not hit.any():
                    continue
                j = np.nonzero(hit)[0]
                s_cross = _hermite_root(x[a[j], li] - bound, f_cur[a[j], li] * ha[j], xa[j, li] - bound,
                                        fa[j, li] * ha[j])
                xs = _hermite(x[a[j]], f_cur[a[j]], xa[j], fa[j], ha[j], s_cross)
                xs[:, li] = bound
                if reset is not None:
                    xs[:, reset] = np.maximum(xs[:, reset], 0.0)
                xa[j], ta[j] = xs, ti[accept][j] + s_cross * ha[j]
                hit_any[j] = True
            if hit_any.any():
                fa[hit_any] = _rhs(circuit, ta[hit_any], xa[hit_any], members=a[hit_any])
                age[a[hit_any]] = JAC_REUSE
            # dense output on the grid: cubic Hermite between (t, x, f) and (ta, xa, fa)
            _emit(out, t_out, next_out, a, t[a], x[a], f_cur[a], ta, xa, fa, limits)
            t[a], x[a], f_cur[a] = ta, xa, fa
            done = t[a] >= t_end[a] - 1e-12 * np.maximum(1.0, np.abs(t_end[a]))
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


def _integrate_compiled(system, circuit, x0, t_out, rtol, atol, h0, max_steps, h_max, method=None, controller=None):
    from .kernels.system import STATUS

    B = np.shape(x0)[0]
    t_out = np.asarray(t_out, dtype=float)
    grid = np.broadcast_to(t_out, (B, t_out.shape[-1]))
    P = np.broadcast_to(system.params(circuit), (B, system.layout.n_params))
    # each member's own breakpoints (a member never steps on another's); one parameter set:
    # the same for every row of x0
    breaks, kinks = circuit.jumps_and_kinks(float(grid[:, 0].min()), float(grid[:, -1].max()),
                                            members=circuit.B > 1)
    out, st = system.integrate_batch(grid, x0, P, rtol=rtol, atol=atol, breaks=breaks, kinks=kinks, h0=h0,
                                     hmax=h_max, max_steps=max_steps, method=method,
                                     **({} if controller is None else {"controller": controller}))
    ok = st[:, 0] == 0
    message = ["" if k else f"{STATUS[int(s)]} at t = {t:.6g} s" for k, s, t in zip(ok, st[:, 0], st[:, 1])]
    return BatchResult(t_out, out, ok, message, {"steps": int(st[:, 2].sum()), "rejected": int(st[:, 3].sum())})


def _rhs(circuit, t, x, members=None, B=None):
    """f for a subset of members (their parameters) at per-member times t."""
    c = circuit if members is None else circuit.subset(members)
    return c.evaluate(np.asarray(t, dtype=float).reshape(-1, 1), x)


def jac_and_ft(circuit, t, x, f0):
    """Batched finite-difference Jacobian (n, nx, nx) and df/dt (n, nx), one evaluation."""
    n, nx = x.shape
    hx = fd_steps(x, circuit.state_scales)
    ht = time_step(t)
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


def _hermite(x0, f0, x1, f1, h, s):
    """Cubic Hermite interpolant at fractions s (n,) of steps h (n,)."""
    s = s[:, None]
    hh = h[:, None]
    return ((1 + 2 * s) * (1 - s) ** 2 * x0 + s * (1 - s) ** 2 * hh * f0
            + s * s * (3 - 2 * s) * x1 + s * s * (s - 1) * hh * f1)


def _hermite_root(y0, d0, y1, d1):
    """Fraction s in [0, 1] where the cubic with values y0, y1 and scaled slopes d0, d1 (= h f)
    first crosses zero from above (bisection on the sign; y0 > 0 >= y1)."""
    lo = np.zeros_like(y0)
    hi = np.ones_like(y0)
    for _ in range(40):
        m = 0.5 * (lo + hi)
        v = (1 + 2 * m) * (1 - m) ** 2 * y0 + m * (1 - m) ** 2 * d0 + m * m * (3 - 2 * m) * y1 + m * m * (m - 1) * d1
        above = v > 0
        lo = np.where(above, m, lo)
        hi = np.where(above, hi, m)
    return hi


def _emit(out, t_out, next_out, members, t0, x0, f0, t1, x1, f1, limits=()):
    """Fill each member's output grid points t0 < t_out <= t1 by cubic Hermite interpolation,
    a hard-limited state on or above its bound (as the compiled engine's output: the
    interpolant between two steps that respect it may dip below by its error)."""
    T = t_out.shape[1]
    k = next_out[members].copy()
    while True:
        kc = np.minimum(k, T - 1)
        pending = (k < T) & (t_out[members, kc] <= t1 + 1e-12 * np.maximum(1.0, np.abs(t1)))
        if not pending.any():
            break
        j = np.nonzero(pending)[0]
        m = members[j]
        dt = t1[j] - t0[j]
        s = np.clip((t_out[m, k[j]] - t0[j]) / dt, 0.0, 1.0)
        out[m, k[j]] = _hermite(x0[j], f0[j], x1[j], f1[j], dt, s)
        for li, bound, _ in limits:
            out[m, k[j], li] = np.maximum(out[m, k[j], li], bound)
        k[j] += 1
    next_out[members] = k


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
