"""Linearisation at an operating point (shared by the AC and stability analyses).

For dx/dt = f(x, p) and outputs y = g(x, p), with p one parameter (the input: a source's
drive parameter, or any ``ID.PARAM``), this computes through the derivatives service
(hemocircuit.derivatives: central differences, or analytic partials where components give them)

    A = df/dx (nx, nx)   B = df/dp (nx,)   C = dg/dx (ny, nx)   D = dg/dp (ny,)

State steps are ``eps * max(|x_i|, state_scale_i)``, so states of very different size
(volumes in mL, concentrations in M) are perturbed by comparable relative amounts.

Everything is evaluated on the circuit's *steady variant* (``Circuit.steady_variant``): log
compliances continued smoothly below their domain and the clamps off.  A state that sits at a
hard limit (a collapsed compartment held at V = 0, second-order Ca at its floor) then gives the
derivative of the smooth law, not the jump of a one-sided difference across the clamp -- the
false, huge eigenvalue the thesis saw (chapter 6, stability analysis).  Such states are flagged
(:func:`limit_flags`) so the verdict can be read with that in mind.

Conservation laws (e.g. the ICP variant's V_a + V_v - V_ic = V_b0) make c^T f = 0 for the
gradient c of the conserved quantity, hence c^T A = 0: one structural zero eigenvalue per law.
:func:`reduce_laws` projects onto the subspace orthogonal to the c's (T = null_space(c^T),
A_red = T^T A T, B_red = T^T B, C_red = C T), which removes exactly those zeros and leaves the
other eigenvalues and every transfer function unchanged (the input does not change the
conserved totals, so c^T B = 0).

Works for a single circuit (x of shape (nx,)) and for a batch circuit (x of shape (B, nx)):
every array then gains a leading batch axis.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .. import derivatives
from ..errors import HemocircuitError

EPS = derivatives.CENTRAL_REL  # relative central-difference step (the derivatives service's rule)


@dataclass
class Linearization:
    """State-space model (A, B, C, D) about ``x`` (leading batch axis for batch circuits).

    ``A_red``, ``B_red``, ``C_red`` and ``T`` are the law-reduced matrices (equal to A, B, C and
    the identity when the circuit has no conservation law).
    """

    x: np.ndarray
    A: np.ndarray
    B: np.ndarray | None
    C: np.ndarray | None
    D: np.ndarray | None
    y0: np.ndarray | None  # outputs at the operating point
    p0: np.ndarray | float | None  # input parameter value
    T: np.ndarray
    A_red: np.ndarray
    B_red: np.ndarray | None
    C_red: np.ndarray | None
    law_gradients: np.ndarray  # (m, nx) or (B, m, nx)
    state_names: list
    outputs: list = field(default_factory=list)
    input: str | None = None
    t: float = 0.0


def input_path(circuit, name):
    """A source id -> 'ID.<its drive parameter>' (Component.drive; a pressure source 'Pa' ->
    'Pa.value'); 'ID.PARAM' is taken as it is (and checked); None stays None (no input)."""
    if name is None:
        return None
    from ..outputs import input_path as _path
    return _path(circuit, name)


def state_jacobian(circuit, x, t=0.0, eps=EPS):
    """Jacobian df/dx of ``circuit`` (use the steady variant) at x (hemocircuit.derivatives:
    analytic where the components provide it, central differences otherwise).

    x (nx,) -> (nx, nx); x (B, nx) for a batch circuit -> (B, nx, nx)."""
    return derivatives.state_jacobian(circuit, x, t, rel=eps)


def law_gradients(circuit, x, t=0.0, eps=EPS):
    """Gradients c (m, nx) (or (B, m, nx)) of the conserved combinations (see
    hemocircuit.derivatives.law_gradients)."""
    return derivatives.law_gradients(circuit, x, t, rel=eps)


def reduction_basis(c):
    """Orthonormal basis T (nx, nx - m) of the subspace orthogonal to the rows of c (m, nx);
    batched for c (B, m, nx)."""
    c = np.asarray(c, dtype=float)
    nx = c.shape[-1]
    m = c.shape[-2]
    if m == 0:
        eye = np.eye(nx)
        return eye if c.ndim == 2 else np.broadcast_to(eye, c.shape[:-2] + (nx, nx)).copy()
    _, s, vh = np.linalg.svd(c, full_matrices=True)
    return np.swapaxes(vh[..., m:, :], -1, -2)


def reduce_laws(T, A, B=None, C=None):
    """(T^T A T, T^T B, C T) -- the dynamics on the conserved subspace."""
    Tt = np.swapaxes(T, -1, -2)
    A_red = Tt @ A @ T
    B_red = None if B is None else (Tt @ B[..., None])[..., 0]
    C_red = None if C is None else C @ T
    return A_red, B_red, C_red


def linearize(circuit, x=None, input=None, outputs=(), t=0.0, eps=EPS, op=None) -> Linearization:
    """Linearise ``circuit`` about the states ``x`` (default: its operating point).

    input:   a source id (its drive parameter: 'Pa' means 'Pa.value') or any 'ID.PARAM' -- the
             input p of B and D; None: no input (A and C only).
    outputs: output columns ('Q(Rla)', 'P(alpha)', 'V(Ca)', 'art.r', derived names).
    Works on ``circuit.steady_variant()`` (see the module docstring).
    """
    from .op import operating_point

    if x is None:
        op = op or operating_point(circuit, t)
        x = op.x
    sv = circuit.steady_variant()
    single = np.ndim(x) == 1
    X = np.atleast_2d(np.asarray(x, dtype=float))
    Bm, nx = X.shape
    if Bm != sv.B:
        raise HemocircuitError(f"linearize: {Bm} state rows for a batch of {sv.B} parameter sets")
    A = state_jacobian(sv, X, t, eps)
    outputs = list(outputs or [])
    path = input_path(sv, input)
    Bv = C = D = y0 = p0 = None
    if outputs:
        C, y0 = derivatives.central_jacobian(lambda rows: derivatives.output_values(sv, t, rows, outputs), X,
                                             sv.state_scales, eps, with_value=True)  # (B, ny, nx)
    if path is not None:
        sens = derivatives.parameter_sensitivity(sv, [path], X, t, outputs, rel=eps)
        p0 = sens.p0[:, 0]  # (B,)
        Bv = sens.rhs[:, :, 0]
        if outputs:
            D = sens.outputs[:, :, 0]
    c = law_gradients(sv, X, t, eps)
    T = reduction_basis(c)
    A_red, B_red, C_red = reduce_laws(T, A, Bv, C)

    def one(a):
        return a if a is None or not single else a[0]

    return Linearization(x=one(X), A=one(A), B=one(Bv), C=one(C), D=one(D), y0=one(y0),
                         p0=None if p0 is None else (float(p0[0]) if single else p0),
                         T=one(T), A_red=one(A_red), B_red=one(B_red), C_red=one(C_red),
                         law_gradients=one(c), state_names=list(sv.state_names), outputs=outputs,
                         input=path, t=t)


def limit_flags(circuit, x, rtol=1e-6):
    """Names of the states of x (nx,) sitting at a hard limit of the *dynamic* circuit
    (Component.limited_states: e.g. a clamped compliance collapsed to V <= 0, which the steady
    variant continues below 0, or a state at a declared floor such as second-order Ca)."""
    x = np.asarray(x, dtype=float)
    hit = np.zeros(circuit.nx, dtype=bool)
    for g in circuit.groups:
        if g.S == 0:
            continue
        mask = g.comp.limited_states(g.p, x[g.sidx][None], rtol)  # (1, E, S)
        hit[g.sidx[np.asarray(mask[0], dtype=bool)]] = True
    return [circuit.state_names[k] for k in np.nonzero(hit)[0]]
