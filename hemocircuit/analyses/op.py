"""Operating point (steady state), SPICE-style.

1. DC guess: stores open (no flow), inductors shorted; the network is solved for the node
   pressures and every element derives its states from them (``initial_states``).  Elements
   whose conductance depends on their state (the arteriole) are iterated to a fixed point
   with under-relaxation 1/2 (the thesis's own scheme, section brainSS).
2. Newton on the reduced system f(x) = 0 (finite-difference Jacobian from one batched
   evaluation), with one row per conservation law replaced by its constraint.
3. Fallbacks if Newton fails: pseudo-transient continuation, then source stepping.
All three run vectorised over the batch of parameter sets.  If everything fails, the error
names the worst-balanced state.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import lsqr, splu

from .. import sparse as sparse_la
from ..derivatives import dense_jacobian
from ..errors import HemocircuitError, SolverError
from ..provenance import clock, stamp
from ..results import Result


class OperatingPoint(Result):
    """The steady state: a one-row :class:`hemocircuit.results.Result` (a batch circuit: one
    row per member, indexed by ``member``).  ``op["P(a)"]`` is a number (an array for a
    batch); ``x`` the states, ``values`` {column: value}, ``method``, ``residual`` (scaled)."""

    def __init__(self, circuit, x, values, units, method, residual):
        single = np.ndim(x) == 1
        cols = dict(values) if single else {"member": np.arange(np.shape(x)[0]), **values}
        super().__init__(cols, units, index=[] if single else ["member"])
        self.circuit, self.x, self.method, self.residual = circuit, x, method, residual
        self.metadata["solver"] = {"method": method, "residual": residual}

    @property
    def values(self):
        """{column: value} (numbers; arrays over the members of a batch)."""
        single = not self.index
        return {k: (float(v[0]) if single and v.dtype.kind == "f" else (v[0] if single else v))
                for k, v in self.columns.items()}

    def __getitem__(self, key):
        col = super().__getitem__(key)
        return col[0].item() if not self.index else col


def residual(circuit, t, X, law_totals):
    """f(x) with the conservation-law rows replaced by their constraints.  law_totals: per
    law its total (array), or a function of X whose zero the row is (a calibration)."""
    F = circuit.evaluate(t, X)
    if circuit.law_specs:
        vols = circuit.law_volumes(X)
        Bx = X.shape[0]
        for spec, total, vol in zip(circuit.law_specs, law_totals, vols):
            if callable(total):  # a calibration being solved: its target replaces the row
                F[:, spec["row"]] = total(X) * circuit.state_scales[spec["row"]]
                continue
            rep = Bx // np.size(total) if np.size(total) else 1
            F[:, spec["row"]] = (vol - np.repeat(np.atleast_1d(total), rep)) * 1.0
    return F


def _jac(circuit, t, X, law_totals):
    """(J, F(X)): J dense (B, nx, nx), or on the sparse path a list of B csc matrices from
    coloured finite differences (pattern derived once per circuit and parameter set)."""
    if getattr(circuit, "sparse", False):
        B = X.shape[0]

        def fun(rows):
            return residual(circuit, t, rows, _rep(law_totals, rows.shape[0] // B))

        # conservation-law rows: the stored volumes of the law's stores, or (calibration) the
        # pressure of its node
        reads = {}
        for spec, total in zip(circuit.law_specs, law_totals):
            if callable(total):
                reads[spec["row"]] = ((), (circuit.nodes.index(spec["node"]),))
            else:
                reads[spec["row"]] = (tuple(g.ids[i] for g, i, _, _ in spec["terms"]), ())
        key = ("residual", tuple(callable(total) for total in law_totals))
        plan = circuit.jacobian_plan(key, fun, X, t, row_reads=reads)
        return sparse_la.coloured_jacobian(fun, X, circuit.state_scales, plan)
    nx = X.shape[1]
    return dense_jacobian(lambda rows: residual(circuit, t, rows, _rep(law_totals, nx + 1)), X,
                          circuit.state_scales)


def _rep(totals, k):
    return [t if t is None or callable(t) else np.repeat(np.atleast_1d(t), k) for t in totals]


def newton(circuit, X, law_totals, t=0.0, tol=1e-10, max_iter=50, ptc=False):
    """Damped Newton (or pseudo-transient continuation) on the batch X (B, nx)."""
    X = X.copy()
    B, nx = X.shape
    if nx == 0:  # a purely resistive circuit: nothing to solve
        return X, True, np.zeros(B)
    scales = circuit.state_scales
    dt = np.full(B, 1e-3)
    done = np.zeros(B, bool)
    for it in range(max_iter if not ptc else 400):
        try:
            J, F = _jac(circuit, t, X, law_totals)
        except HemocircuitError:
            return X, False, np.full(B, np.inf)
        norm = np.max(np.abs(F) / scales, axis=1)
        if not np.all(np.isfinite(F)):
            return X, False, norm
        if not ptc and np.all(norm < 1e-13):  # already at the residual floor: nothing to improve
            return X, True, norm
        if isinstance(J, list):  # sparse path
            dX = _sparse_step(J, F, dt if ptc else None)
        else:
            if ptc:
                M = np.eye(nx)[None] / dt[:, None, None] - J
            else:
                M = J
            try:
                dX = np.linalg.solve(M, -F[..., None])[..., 0]
            except np.linalg.LinAlgError:
                dX = np.linalg.lstsq(M[0], -F[0], rcond=None)[0][None] if B == 1 else np.zeros_like(X)
        step_small = np.max(np.abs(dX) / (np.abs(X) + scales), axis=1) < tol
        # line search on the scaled residual
        lam = np.ones(B)
        for _ in range(12):
            Xn = X + lam[:, None] * dX
            try:
                Fn = residual(circuit, t, Xn, law_totals)
                nn = np.max(np.abs(Fn) / scales, axis=1)
            except HemocircuitError:  # a trial point outside the physical domain
                nn = np.full(B, np.inf)
            # near the residual floor (rounding) no decrease can be demanded: take the step
            bad = ~np.isfinite(nn) | ((nn > norm * (1 - 1e-4 * lam)) & ~ptc & (norm > 1e-9))
            if not bad.any():
                break
            lam = np.where(bad, lam * 0.5, lam)
        X = X + lam[:, None] * dX
        if ptc:
            dt = np.where(np.isfinite(nn) & (nn < norm), dt * 2.0, dt * 0.5)
            dt = np.clip(dt, 1e-6, 1e12)
        done = step_small & ((lam == 1.0) | (norm < 1e-9))
        if np.all(done) and (not ptc or np.all(dt > 1e6)):
            Fn = residual(circuit, t, X, law_totals)
            return X, True, np.max(np.abs(Fn) / scales, axis=1)
    Fn = residual(circuit, t, X, law_totals)
    nn = np.max(np.abs(Fn) / scales, axis=1)
    return X, bool(np.all(nn < 1e-8)), nn


def _sparse_step(Js, F, dt=None):
    """Newton (dt None) or pseudo-transient (I/dt - J) steps, one sparse LU per member; a
    singular member falls back to least squares (LSQR) if it is alone, else takes no step."""
    B, nx = F.shape
    dX = np.zeros_like(F)
    eye = sp.identity(nx, format="csc") if dt is not None else None
    for b in range(B):
        M = Js[b] if dt is None else (eye / dt[b] - Js[b])
        M = sp.csc_matrix(M)
        try:
            dX[b] = splu(M).solve(-F[b])
        except RuntimeError:  # exactly singular
            if B == 1:
                dX[b] = lsqr(M, -F[b], atol=1e-14, btol=1e-14)[0]
    return dX


def dc_guess(circuit, t=0.0, max_iter=200, tol=1e-12):
    """States from the DC network (stores open, inductors shorted), fixed-point iterated."""
    B = circuit.B
    X = np.zeros((B, circuit.nx))
    if circuit.nx == 0:
        return X
    plist = circuit.group_params()
    for g, p in zip(circuit.groups, plist):
        if g.S:
            X[:, g.sidx] = np.broadcast_to(g.comp.default_states(p), (B, g.E, g.S))
    # anchors of conservation laws start at the calibration pressure (or 10 mmHg)
    for spec in circuit.law_specs:
        g, i = spec["anchor"]
        target = spec.get("pressure", 10.0)
        u = np.zeros((B, g.E, g.L))
        u[:, i, 0] = target
        X[:, g.sidx[i]] = g.comp.initial_states(plist[circuit.groups.index(g)], u)[:, i]
    anchors = {(id(s["anchor"][0]), s["anchor"][1]) for s in circuit.law_specs}
    relax = 1.0 if circuit.all_constant else 0.5
    Xn_prev = None
    for it in range(max_iter):
        u, plist_b, stamps = _dc_u(circuit, t, X)
        Xn = X.copy()
        for g, p, (A_loc, b_loc, src) in zip(circuit.groups, plist_b, stamps):
            if g.S == 0:
                continue
            ul = u[:, g.uidx]
            flows = np.einsum("beij,bej->bei", np.broadcast_to(A_loc, (B,) + A_loc.shape[1:]), ul) - b_loc
            new = g.comp.initial_states(p, ul, flows, X[:, g.sidx])
            free = np.array([(id(g), i) not in anchors for i in range(g.E)], dtype=bool)
            Xn[:, g.sidx[free]] = new[:, free]
        step = Xn - X
        # the map's image stopped moving (the states do not feed back on the pressures, as
        # when sources fix every node): it is the fixed point, no need to relax towards it
        if Xn_prev is not None and np.max(np.abs(Xn - Xn_prev) / (np.abs(Xn) + circuit.state_scales)) < tol:
            return Xn
        Xn_prev = Xn
        X = X + relax * step
        if np.max(np.abs(step) / (np.abs(X) + circuit.state_scales)) < tol:
            break
    return X


def _dc_u(circuit, t, X):
    return circuit.dc_unknowns(t, X)


def conserved_totals(circuit, t=0.0):
    """Totals of the conservation laws of ``circuit`` ([array or None] per law): a volume
    constraint's number, or a calibration's total solved with P(node) = target at its 'when'
    values (on the steady variant).  Computed once per circuit (Circuit.cached)."""
    sv = circuit.steady_variant()
    return sv.cached(("conserved_totals", float(t)), lambda: _calibrate(sv, t))


def _calibrate(circuit, t):
    totals = list(circuit.law_totals)
    for k, spec in enumerate(circuit.law_specs):
        if spec["kind"] != "calibration" or totals[k] is not None:
            continue
        cal = circuit.with_values(spec["when"])
        node_j = cal.nodes.index(spec["node"])

        def target(X, cal=cal, node_j=node_j, spec=spec):
            u, _, _ = cal.evaluate(t, X, want="u")
            return (u[:, node_j] - spec["pressure"]) / 1.0

        def solve(cal=cal, k=k, target=target, spec=spec, known=list(totals)):
            X0 = dc_guess(cal, t)
            X, ok, res = _solve_with_fallbacks(cal, X0, [target if j == k else known[j] for j in range(len(known))], t)
            if not ok:
                raise SolverError(f"calibration of the conserved volume at node '{spec['node']}' "
                                  f"({spec['pressure']} mmHg when {spec['when']}) did not converge",
                                  where="computing the operating point")
            return cal.law_volumes(X)[k]

        # the total depends only on the calibration circuit (its values with 'when' applied):
        # sweeping a parameter that 'when' fixes reuses it
        known = tuple(None if v is None else np.asarray(v).tobytes() for v in totals)
        totals[k] = cal.structure.cached(("calibration", k, float(t), cal.parameters.fingerprint(), known), solve)
    return totals


def _solve_with_fallbacks(circuit, X0, totals, t):
    X, ok, res = newton(circuit, X0, totals, t)
    method = "newton"
    if not ok:
        X, ok, res = newton(circuit, X0, totals, t, ptc=True)
        method = "pseudo-transient"
        if ok:
            X, ok, res = newton(circuit, X, totals, t)
    if not ok:
        X, ok, res, method = _source_stepping(circuit, totals, t)
    return X, ok, res if not ok else res


def _source_stepping(circuit, totals, t):
    """Ramp every source's drive parameter (Component.drive: a pressure or flow source's value)
    from 30 % to 100 %, continuing the solution."""
    paths = [f"{e}.{g.comp.drive.value}" for g in circuit.groups if g.comp.drive is not None for e in g.ids]
    base = {p: circuit.parameters.values[p] for p in paths}
    X = None
    ok = False
    res = np.inf
    for lam in np.linspace(0.3, 1.0, 15):
        c = circuit.with_values({p: base[p] * lam if circuit.B > 1 else float(base[p][0] * lam) for p in paths})
        X0 = dc_guess(c, t) if X is None else X
        X, ok, res = newton(c, X0, totals, t, ptc=True)
        if not ok:
            break
    return X, ok, res, "source-stepping"


def operating_point(circuit, t: float = 0.0, x0=None) -> OperatingPoint:
    """Steady state of the circuit (every parameter set of a batch at once)."""
    started = clock()
    op = _operating_point(circuit, t, x0)
    return stamp(op, "op", circuit, {"t": t, "x0": None if x0 is None else "given", "tol": 1e-10}, started)


def _operating_point(circuit, t, x0):
    totals = [np.atleast_1d(v) if v is not None else None for v in conserved_totals(circuit, t)]
    circuit = circuit.steady_variant()
    X0 = dc_guess(circuit, t) if x0 is None else np.atleast_2d(np.asarray(x0, float)).copy()
    X, ok, res = newton(circuit, X0, totals, t)
    method = "newton"
    if not ok:
        X2, ok, res = _solve_with_fallbacks(circuit, X0, totals, t)
        X, method = X2, "fallback"
    if not ok:
        F = residual(circuit, t, X, totals)
        scaled = np.abs(F) / circuit.state_scales
        b, j = np.unravel_index(np.nanargmax(np.where(np.isfinite(scaled), scaled, np.inf)), scaled.shape)
        raise SolverError(f"no operating point found (Newton, pseudo-transient continuation and source "
                          f"stepping failed); worst-balanced state '{circuit.state_names[j]}' with "
                          f"d/dt = {F[b, j]:.3g} {circuit.state_units[j]}/s"
                          + (f" in batch member {b}" if circuit.B > 1 else ""),
                          state=circuit.state_dict(X[b]), where="computing the operating point")
    # outputs from the steady variant (collapsed stores report V = 0), laws shared
    single = circuit.B == 1
    if single:
        vals = {k: float(v[0]) for k, v in circuit.outputs(t, X).items()}
    else:  # one row per member: outputs() evaluates the whole batch at once
        vals = {k: np.array(v, dtype=float) for k, v in circuit.outputs(t, X).items()}
    return OperatingPoint(circuit, X[0] if single else X, vals, circuit.column_units(), method,
                          float(np.max(res)))


def operating_points(circuit):
    """Operating points of every member of a batch circuit, failures kept per member.

    Returns (X (B, nx) with NaN rows for failed members, {column: (B,) array}, [error or None]).
    The whole batch is solved together; if that fails, member by member, so one bad
    parameter set does not lose the others.
    """
    B = circuit.B
    try:
        op = operating_point(circuit)
        X = np.atleast_2d(op.x)
        vals = {k: np.broadcast_to(np.atleast_1d(v), (B,)).copy() for k, v in op.values.items()}
        return X, vals, [None] * B
    except HemocircuitError:
        pass
    X = np.full((B, circuit.nx), np.nan)
    vals, errors = {}, []
    for k in range(B):
        try:
            op = operating_point(circuit.subset([k]))
        except HemocircuitError as exc:
            errors.append(f"operating point: {exc}")
            continue
        errors.append(None)
        X[k] = np.atleast_2d(op.x)[0]
        for key, v in op.values.items():
            vals.setdefault(key, np.full(B, np.nan))[k] = float(np.atleast_1d(v)[0])
    return X, vals, errors
