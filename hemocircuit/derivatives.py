"""The derivatives service: every derivative the analyses take, with one step rule.

Step rule.  State j is perturbed by ``rel * max(|x_j|, scale_j)`` (the state's natural scale
from its component), rounded so that x + h is representable; time by ``FD_REL * max(|t|, 1 s)``;
a parameter by ``rel * |p|`` (``rel`` when p = 0, in the declared unit).  ``rel`` is
``FD_REL`` = 1e-7 for forward differences (Newton and integrator Jacobians: error ~ rel) and
``CENTRAL_REL`` = 1e-6 for central differences (linearisation, sensitivities, law gradients:
truncation ~ rel^2, round-off ~ 1e-16 / rel).  The compiled engine uses the same forward rule
(``FD_REL`` in kernels/engine_template.py).  Maps computed by integration (the periodic
shooting's flow map, noisy at the integrator's tolerance) are differenced with
``FLOW_REL * scale_j`` (:func:`flow_steps`).

Services:
  :func:`dense_jacobian`, :func:`central_jacobian`  d fun / d x of any row-wise map, every
      column from ONE batched evaluation
  :func:`state_jacobian`   d(dx/dt)/dx of a circuit by central differences
  :func:`parameter_sensitivity`   d(dx/dt)/dp and d(outputs)/dp for a list of ID.PARAM, all
      parameters and members from ONE batched evaluation (fitting, sensitivity analysis,
      the linearisation's input matrices)
  :func:`law_gradients`    gradients of the conserved volumes
The circuit's own forward Jacobians (``Circuit.jacobian``, ``sparse_jacobian``) and the
operating point's residual Jacobian use :func:`dense_jacobian` / the coloured variant in
hemocircuit.sparse with :func:`fd_steps`.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

FD_REL = 1e-7
CENTRAL_REL = 1e-6
FLOW_REL = 1e-6


def fd_steps(X, scales, rel=FD_REL):
    """Forward-difference steps (same shape as X) for states X (..., nx).  ``rel`` replaces
    FD_REL where the function differentiated is itself only accurate to a tolerance (a fit
    through an integrator with rtol: rel ~ sqrt(rtol), hemocircuit.fitting)."""
    X = np.asarray(X, dtype=float)
    h = rel * np.maximum(np.abs(X), scales)
    return (X + h) - X


def time_step(t):
    """Forward-difference step in time [s] (scalar or array): FD_REL seconds, as represented at
    t.  Absolute, not relative to t: time has an arbitrary origin, and a step growing with t
    (FD_REL |t| was 54 us at t = 544 s) straddles a heart valve's switching, whose df/dt then
    stalls a Rosenbrock integrator (netlists/body/body.yaml at rtol 1e-6)."""
    t = np.asarray(t, dtype=float)
    return (t + FD_REL) - t


def param_steps(p0, rel=CENTRAL_REL):
    """Steps for parameter values p0 (any shape, declared units): rel * |p| (rel at p = 0)."""
    p0 = np.asarray(p0, dtype=float)
    h = rel * np.where(p0 != 0, np.abs(p0), 1.0)
    return (p0 + h) - p0


def flow_steps(scales, rel=FLOW_REL):
    """Steps for differencing a map computed by integration: rel * scale (not relative to
    |x|: the step must stay well above the integrator's error at every state)."""
    return rel * np.asarray(scales, dtype=float)


def dense_jacobian(fun, X, scales, steps=None):
    """Forward differences: d fun / d x at every member of X (B, nx), all columns from ONE
    evaluation of the stacked rows (B * (nx + 1), nx).  ``fun`` maps rows (m, nx) ->
    (m, nx_out).  ``steps`` (nx,) or (B, nx): default :func:`fd_steps`.
    Returns (J (B, nx_out, nx), fun(X) (B, nx_out))."""
    X = np.atleast_2d(np.asarray(X, dtype=float))
    B, nx = X.shape
    h = fd_steps(X, scales) if steps is None else np.broadcast_to(np.asarray(steps, dtype=float), (B, nx))
    stack = np.repeat(X[:, None, :], nx + 1, axis=1)
    idx = np.arange(nx)
    stack[:, idx + 1, idx] += h
    F = np.asarray(fun(stack.reshape(B * (nx + 1), nx)))
    F = F.reshape(B, nx + 1, -1)
    J = (F[:, 1:, :] - F[:, :1, :]) / h[:, :, None]  # (B, column, row)
    return np.swapaxes(J, 1, 2), F[:, 0, :]


def central_jacobian(fun, X, scales, rel=CENTRAL_REL, with_value=False):
    """Central differences: d fun / d x at every member of X (B, nx) from ONE evaluation of
    the stacked rows (2 nx per member; 2 nx + 1 with the unperturbed row when ``with_value``).
    Returns J (B, nx_out, nx), or (J, fun(X) (B, nx_out)) with ``with_value``."""
    X = np.atleast_2d(np.asarray(X, dtype=float))
    B, nx = X.shape
    h = fd_steps(X, scales, rel)
    o = 1 if with_value else 0
    stack = np.repeat(X[:, None, :], 2 * nx + o, axis=1)
    idx = np.arange(nx)
    stack[:, o + idx, idx] += h
    stack[:, o + nx + idx, idx] -= h
    F = np.asarray(fun(stack.reshape(-1, nx))).reshape(B, 2 * nx + o, -1)
    J = np.swapaxes((F[:, o:o + nx, :] - F[:, o + nx:, :]) / (2 * h[:, :, None]), 1, 2)  # (B, row, col)
    return (J, F[:, 0, :]) if with_value else J


# ------------------------------------------------------------------ circuits -------------
def state_jacobian(circuit, x, t=0.0, rel=CENTRAL_REL):
    """d(dx/dt)/dx of ``circuit`` at x: (nx,) -> (nx, nx); (B, nx) -> (B, nx, nx), by central
    differences (one batched evaluation of the elements' kernel functions).  The
    linearisation passes the steady variant."""
    single = np.ndim(x) == 1
    X = np.atleast_2d(np.asarray(x, dtype=float))
    J = central_jacobian(lambda rows: circuit.evaluate(t, rows), X, circuit.state_scales, rel)
    return J[0] if single else J


def output_values(circuit, t, X, names):
    """Output columns ``names`` (circuit columns or the netlist's derived quantities) for
    states X (rows a multiple of the circuit's batch) -> (rows, ny)."""
    from .derived import evaluate_derived
    from .errors import HemocircuitError

    cols = circuit.outputs(t, X)
    missing = [n for n in names if n not in cols]
    derived = circuit.netlist.derived or {}
    if missing:
        want = {n: derived[n] for n in missing if n in derived}
        unknown = [n for n in missing if n not in derived]
        if unknown:
            raise HemocircuitError(f"unknown output(s) {unknown}; available: {sorted(cols)} "
                                   + (f"and derived {sorted(derived)}" if derived else ""))
        cols = {**cols, **evaluate_derived(want, cols, circuit.file)}
    return np.stack([np.broadcast_to(np.asarray(cols[n], dtype=float), (X.shape[0],)) for n in names], axis=1)


@dataclass
class Sensitivity:
    """Central-difference sensitivities at states x of a circuit with B members, for the
    parameters ``paths`` (P of them, declared units).

    rhs (B, nx, P): d(dx/dt)/dp; outputs (B, ny, P): d(output)/dp (None without outputs);
    p0 (B, P) the parameter values, steps (B, P) the steps taken."""

    paths: list
    p0: np.ndarray
    steps: np.ndarray
    rhs: np.ndarray
    outputs: np.ndarray | None
    output_names: list


def parameter_sensitivity(circuit, paths, x, t=0.0, outputs=(), rel=CENTRAL_REL) -> Sensitivity:
    """d(dx/dt)/dp and d(outputs)/dp at states x ((nx,) for a single circuit, (B, nx) for a
    batch of B) for every ID.PARAM in ``paths``, by central differences.

    One batched circuit holds, per member m and parameter j, the two members with p_j = p0
    +- h (the other parameters at p0): a single evaluation of 2 P B rows serves every
    parameter and member.  A parameter that follows an expression cannot be perturbed (error
    naming it); a step across a parameter's bound is rejected like any value."""
    from .errors import HemocircuitError

    paths = list(paths)
    X = np.atleast_2d(np.asarray(x, dtype=float))
    Bm, nx = X.shape
    if Bm != circuit.B:
        raise HemocircuitError(f"parameter_sensitivity: {Bm} state rows for a batch of {circuit.B} parameter sets")
    P, K = len(paths), 2 * len(paths)
    ps = circuit.parameters
    p0 = np.stack([np.asarray(ps.values[p], dtype=float) for p in paths], axis=1)  # (B, P)
    h = param_steps(p0, rel)
    values = {}
    for j, path in enumerate(paths):
        col = np.repeat(p0[:, j][:, None], K, axis=1)  # (B, K): member-major rows
        col[:, 2 * j] = p0[:, j] + h[:, j]
        col[:, 2 * j + 1] = p0[:, j] - h[:, j]
        values[path] = col.reshape(-1)
    cb = circuit.with_parameters(ps[np.repeat(np.arange(Bm), K)].with_values(values))
    Xp = np.repeat(X, K, axis=0)
    F = cb.evaluate(t, Xp).reshape(Bm, P, 2, nx)
    drhs = np.swapaxes((F[:, :, 0] - F[:, :, 1]) / (2 * h[:, :, None]), 1, 2)  # (B, nx, P)
    dout = None
    outputs = list(outputs or [])
    if outputs:
        Y = output_values(cb, t, Xp, outputs).reshape(Bm, P, 2, len(outputs))
        dout = np.swapaxes((Y[:, :, 0] - Y[:, :, 1]) / (2 * h[:, :, None]), 1, 2)  # (B, ny, P)
    return Sensitivity(paths, p0, h, drhs, dout, outputs)


def law_gradients(circuit, x, t=0.0, rel=CENTRAL_REL):
    """Gradients c (m, nx) (or (B, m, nx)) of the conserved combinations sum(sign * V).

    Stores whose volume is a state contribute exactly +-1; a store whose volume is a function
    of other states (an arteriolar bed's pi r^2 L n) contributes its central-difference gradient
    (the raw volume, not the reported max(V, 0) of a collapsed store).
    """
    single = np.ndim(x) == 1
    X = np.atleast_2d(np.asarray(x, dtype=float))
    Bm, nx = X.shape
    specs = circuit.law_specs
    c = np.zeros((Bm, len(specs), nx))
    if not specs:
        return c[0] if single else c
    plist = circuit.group_params(Bm)
    for k, spec in enumerate(specs):
        for g, i, vol, sign in spec["terms"]:
            st = next((s for s in g.comp.storages() if s.volume == vol), None)
            names = [s.name for s in g.states]
            if st is not None and st.state is not None:
                c[:, k, g.sidx[i, names.index(st.state)]] += sign
                continue
            p = plist[circuit.groups.index(g)]
            xl = X[:, g.sidx]  # (B, E, S)
            for j in range(g.S):
                h = rel * np.maximum(np.abs(xl[:, i, j]), g.states[j].scale)
                xp, xm = xl.copy(), xl.copy()
                xp[:, i, j] += h
                xm[:, i, j] -= h
                dv = (g.comp.observe(p, xp, None, t)[vol][:, i] - g.comp.observe(p, xm, None, t)[vol][:, i]) / (2 * h)
                c[:, k, g.sidx[i, j]] += sign * dv
    return c[0] if single else c
