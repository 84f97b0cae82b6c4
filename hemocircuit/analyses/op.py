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
        from .. import sparse as sparse_la  # scipy.sparse: large circuits only

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
    """Damped Newton (or pseudo-transient continuation) on the batch X (B, nx).

    Returns (X, ok, residual): ``ok`` True if every member converged (see
    :func:`newton_members` for the per-member flags)."""
    X, ok, res = newton_members(circuit, X, law_totals, t, tol, max_iter, ptc)
    return X, bool(np.all(ok)), res


def newton_members(circuit, X, law_totals, t=0.0, tol=1e-10, max_iter=50, ptc=False):
    """Damped Newton (or pseudo-transient continuation) on the batch X (B, nx), convergence
    tracked per member: (X, ok (B,), scaled residual (B,)).  A member that converges is
    frozen and a member whose residual becomes non-finite is dropped (ok False); the others go
    on.  Once half of the members still iterating have finished, the rest continue as a
    smaller batch (a subset circuit), so that a few slow or failing members do not cost the
    whole batch's Jacobians (not on the sparse path, whose Jacobian plan is per circuit, nor
    while a calibration is being solved, whose target evaluates the whole batch)."""
    X = X.copy()
    B, nx = X.shape
    if nx == 0:  # a purely resistive circuit: nothing to solve
        return X, np.ones(B, bool), np.zeros(B)
    scales = circuit.state_scales
    compact = not getattr(circuit, "sparse", False) and not any(callable(v) for v in law_totals)
    dt_all = np.full(B, 1e-3)
    at_floor = np.zeros(B, int)        # ptc: consecutive iterations at the smallest time step
    ok = np.zeros(B, bool)
    res = np.full(B, np.inf)
    act = np.arange(B)                 # members still iterating
    c, totals = circuit, law_totals
    for it in range(max_iter if not ptc else 400):
        Xa, dt = X[act], dt_all[act]
        Ba = len(act)
        try:
            J, F = _jac(c, t, Xa, totals)
        except HemocircuitError:  # raised for the whole (sub)batch: no member can be attributed
            return X, ok, res
        norm = np.max(np.abs(F) / scales, axis=1)
        dead = ~np.all(np.isfinite(F), axis=1)
        if isinstance(J, list):
            dead |= np.array([not np.all(np.isfinite(j.data)) for j in J])
        else:
            dead |= ~np.all(np.isfinite(J), axis=(1, 2))
        floor = ~dead & (norm < 1e-13) & (not ptc)   # at the residual floor: nothing to improve
        live = ~dead & ~floor & (at_floor[act] < 25)
        if not live.any():
            ok[act[floor]], res[act] = True, norm
            return X, ok, res
        Fs = np.where(live[:, None], F, 0.0)
        if isinstance(J, list):  # sparse path
            dX = _sparse_step(J, Fs, dt if ptc else None, skip=~live)
        else:
            M = np.where(live[:, None, None], J, np.eye(nx)[None])  # the others: dX = 0
            if ptc:
                M = np.where(live[:, None, None], np.eye(nx)[None] / dt[:, None, None] - J, M)
            dX = _dense_step(M, Fs)
        step_small = np.max(np.abs(dX) / (np.abs(Xa) + scales), axis=1) < tol
        # line search on the scaled residual
        lam = np.ones(Ba)
        nn = norm.copy()
        for _ in range(12):
            Xn = Xa + lam[:, None] * dX
            try:
                Fn = residual(c, t, Xn, totals)
                nn = np.max(np.abs(Fn) / scales, axis=1)
            except HemocircuitError:  # a trial point outside the physical domain
                nn = np.full(Ba, np.inf)
            # near the residual floor (rounding) no decrease can be demanded: take the step
            bad = live & (~np.isfinite(nn) | ((nn > norm * (1 - 1e-4 * lam)) & ~ptc & (norm > 1e-9)))
            if not bad.any():
                break
            lam = np.where(bad, lam * 0.5, lam)
        X[act] = Xa + np.where(live, lam, 0.0)[:, None] * dX
        if ptc:
            dt = np.where(np.isfinite(nn) & (nn < norm), dt * 2.0, dt * 0.5)
            dt_all[act] = np.clip(dt, 1e-6, 1e12)
            # stagnation: a member whose pseudo-time step has stayed at its floor for 25 steps
            # moves by ~1e-6 f per step and will not reach a steady state (measured on an
            # arteriole without equilibrium: it crept along its collapse for all 400 steps)
            at_floor[act] = np.where(dt_all[act] <= 1e-6, at_floor[act] + 1, 0)
            live &= at_floor[act] < 25
        done = live & step_small & ((lam == 1.0) | (norm < 1e-9))
        if ptc:
            done &= dt_all[act] > 1e6
        res[act] = np.where(live, nn, norm)
        ok[act[done | floor]] = True
        remaining = live & ~ok[act]   # without compaction, finished members take steps of ~0
        if not remaining.any():
            return X, ok, res
        if compact and remaining.sum() <= Ba // 2:
            act = act[remaining]
            c, totals = circuit.subset(act), _subset_totals(law_totals, act)
    # out of iterations: a member whose residual is at the tolerance still counts
    ok[act] |= np.isfinite(res[act]) & (res[act] < 1e-8)
    return X, ok, res


def _dense_step(M, F):
    """Solve M dX = -F for every member; if the batched LU fails (a singular member), member
    by member: a singular member takes the least-squares step if it is alone, else none."""
    try:
        return np.linalg.solve(M, -F[..., None])[..., 0]
    except np.linalg.LinAlgError:
        pass
    dX = np.zeros_like(F)
    for b in range(F.shape[0]):
        try:
            dX[b] = np.linalg.solve(M[b], -F[b])
        except np.linalg.LinAlgError:
            if F.shape[0] == 1:
                try:
                    dX[b] = np.linalg.lstsq(M[b], -F[b], rcond=None)[0]
                except np.linalg.LinAlgError:  # SVD did not converge (extreme values): no step
                    pass
    return dX


def _sparse_step(Js, F, dt=None, skip=None):
    """Newton (dt None) or pseudo-transient (I/dt - J) steps, one sparse LU per member; a
    singular member falls back to least squares (LSQR) if it is alone, else takes no step.
    Members flagged in ``skip`` take no step."""
    import scipy.sparse as sp
    from scipy.sparse.linalg import lsqr, splu

    B, nx = F.shape
    dX = np.zeros_like(F)
    eye = sp.identity(nx, format="csc") if dt is not None else None
    for b in range(B):
        if skip is not None and skip[b]:
            continue
        M = Js[b] if dt is None else (eye / dt[b] - Js[b])
        M = sp.csc_matrix(M)
        try:
            dX[b] = splu(M).solve(-F[b])
        except RuntimeError:  # exactly singular
            if B == 1:
                dX[b] = lsqr(M, -F[b], atol=1e-14, btol=1e-14)[0]
    return dX


def default_states(circuit):
    """Every element's ``default_states`` (B, nx): where the DC guess starts."""
    B = circuit.B
    X = np.zeros((B, circuit.nx))
    for g, p in zip(circuit.groups, circuit.group_params()):
        if g.S:
            X[:, g.sidx] = np.broadcast_to(g.comp.default_states(p), (B, g.E, g.S))
    return X


#: relative step at which the DC fixed point stops: it only starts Newton, which converges
#: quadratically from there.  Iterating the (relaxed, linearly converging) map to 1e-12 took
#: 20-40 % of an operating point, to 1e-6 still half of a batch's: 1e-4 changed no result
#: beyond rounding (batches of 10 Pa values on six bundled netlists: < 1e-14 relative).
DC_GUESS_TOL = 1e-4


def dc_guess(circuit, t=0.0, max_iter=200, tol=DC_GUESS_TOL, start=None):
    """States from the DC network (stores open, inductors shorted), fixed-point iterated from
    the elements' default states (``start``: those, if already computed) until a step moves
    them by less than ``tol`` (relative): a start for Newton, not the operating point."""
    B = circuit.B
    if circuit.nx == 0:
        return np.zeros((B, 0))
    X = default_states(circuit) if start is None else np.array(start, float)
    plist = circuit.group_params()
    # anchors of conservation laws start at the calibration pressure (or 10 mmHg)
    for spec in circuit.law_specs:
        g, i = spec["anchor"]
        target = spec.get("pressure", 10.0)
        u = np.zeros((B, g.E, g.L))
        u[:, i, 0] = target
        X[:, g.sidx[i]] = g.comp.initial_states(plist[circuit.groups.index(g)], u)[:, i]
    anchors = {(id(s["anchor"][0]), s["anchor"][1]) for s in circuit.law_specs}
    # full steps while they shrink fast (the map contracts: half the iterations of a fixed 0.5
    # on the bundled netlists), damped by half from the first step that does not shrink by at
    # least half (e.g. an iteration that alternates with a slowly decaying amplitude)
    relax, last = 1.0, np.inf
    Xn_prev = None
    for it in range(max_iter):
        u, plist_b, stamps = _dc_u(circuit, t, X)
        Xn = X.copy()
        for g, p, st in zip(circuit.groups, plist_b, stamps):
            if g.S == 0:  # (a static group's stamp is None: not stamped again)
                continue
            A_loc, b_loc, src = st
            if src is not None:  # a waveform adds to its parameter (an arteriole's pCa_shift)
                name = g.comp.waveform_params[0]
                p = {**p, name: p[name] + src}
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
        size = np.max(np.abs(step) / (np.abs(X) + circuit.state_scales))
        if size > 0.5 * last:
            relax = 0.5
        last = size
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
    """The totals of the calibrated laws.  Calibrations with the same 'when' are solved
    together (each law's total such that its node sits at its pressure); calibrations at
    different 'when's take turns, each solve using the others' latest totals (the first round
    treats a law not yet calibrated as a calibration at this 'when' too), until the totals
    stop moving."""
    import json

    totals = list(circuit.law_totals)
    specs = circuit.law_specs
    pending = [k for k, spec in enumerate(specs) if spec["kind"] == "calibration" and totals[k] is None]
    groups: dict = {}
    for k in pending:
        groups.setdefault(json.dumps(specs[k]["when"], sort_keys=True, default=str), []).append(k)
    rounds = 1 if len(groups) <= 1 else 20
    for _ in range(rounds):
        before = [None if v is None else np.array(v, dtype=float) for v in totals]
        for ks in groups.values():
            new = _calibrate_group(circuit, t, ks, pending, totals)
            for k in ks:
                totals[k] = new[k]
        if rounds == 1 or all(b is not None and np.allclose(b, totals[k], rtol=1e-12, atol=0)
                              for k, b in enumerate(before) if k in pending):
            break
    return totals


def _calibrate_group(circuit, t, ks, pending, totals):
    """Law volumes with every law of ``ks`` (one 'when') at its node pressure; the other
    pending laws at their current totals, or at their own pressure while they have none."""
    spec0 = circuit.law_specs[ks[0]]
    cal = circuit.with_values(spec0["when"])
    aims = [k for k in pending if k in ks or totals[k] is None]

    def target(X, k):
        spec = circuit.law_specs[k]
        u, _, _ = cal.evaluate(t, X, want="u")
        return (u[:, cal.nodes.index(spec["node"])] - spec["pressure"]) / 1.0

    def solve():
        X0 = dc_guess(cal, t)
        laws = [(lambda X, k=j: target(X, k)) if j in aims else totals[j] for j in range(len(totals))]
        X, ok, res = _solve_with_fallbacks(cal, X0, laws, t)
        if not ok:
            where = ", ".join(f"node '{circuit.law_specs[k]['node']}' ({circuit.law_specs[k]['pressure']} mmHg)"
                              for k in ks)
            raise SolverError(f"calibration of the conserved volume at {where} when {spec0['when']} did not "
                              "converge", where="computing the operating point")
        # where 'when' changes no value this state is the operating point itself: _solve starts there
        cal.structure.cached(_calibrated_key(cal, t), lambda: X.copy())
        return cal.law_volumes(X)

    # the totals depend only on the calibration circuit (its values with 'when' applied) and the
    # other laws' totals: sweeping a parameter that 'when' fixes reuses them
    known = tuple(None if v is None else np.asarray(v).tobytes() for v in totals)
    return cal.structure.cached(("calibration", tuple(ks), float(t), cal.parameters.fingerprint(), known), solve)


def _calibrated_key(circuit, t):
    """The memo key of the state a calibration solved for these values (see _solve)."""
    return ("calibrated state", float(t), circuit.parameters.fingerprint())


def _solve_with_fallbacks(circuit, X0, totals, t):
    """(X, ok, residual) with ok True only if every member converged (calibration solves)."""
    X, ok, res, _ = solve_members(circuit, X0, totals, t)
    return X, bool(np.all(ok)), res


def _subset_totals(totals, idx):
    return [v if v is None or callable(v) or np.size(v) == 1 else np.asarray(v)[idx] for v in totals]


def solve_members(circuit, X0, totals, t):
    """Newton on the whole batch, then the fallbacks (pseudo-transient continuation, then
    source stepping) on the members that did not converge only, so that a failing member
    costs its own fallbacks, not the batch's.  Returns (X (B, nx), ok (B,), residual (B,),
    method (B,) of 'newton' / 'pseudo-transient' / 'source-stepping' / 'failed').

    A calibration being solved (a callable total evaluates the whole batch) runs the
    fallbacks on the whole batch."""
    B = circuit.B
    X, ok, res = newton_members(circuit, X0, totals, t)
    method = np.where(ok, "newton", "failed").astype(object)
    whole = any(callable(v) for v in totals)
    for name, stage in (("pseudo-transient", _ptc), ("source-stepping", _source_stepping)):
        if ok.all():
            break
        idx = np.arange(B) if whole else np.nonzero(~ok)[0]
        Xs, oks, rs = stage(circuit.subset(idx) if len(idx) < B else circuit, X0[idx],
                            totals if len(idx) == B else _subset_totals(totals, idx), t)
        if whole and not oks.all():
            continue
        won = idx[oks]
        X[won], res[won], ok[won], method[won] = Xs[oks], rs[oks], True, name
    return X, ok, res, method


def _ptc(circuit, X0, totals, t):
    """Pseudo-transient continuation, then Newton from where it ended (members it solved)."""
    X, ok, res = newton_members(circuit, X0, totals, t, ptc=True)
    if ok.any():
        idx = np.nonzero(ok)[0]
        sub = circuit.subset(idx) if len(idx) < circuit.B else circuit
        Xp, okp, rp = newton_members(sub, X[idx], totals if len(idx) == circuit.B else _subset_totals(totals, idx), t)
        X[idx], ok[idx], res[idx] = Xp, okp, rp
    return X, ok, res


def _source_stepping(circuit, X0, totals, t):
    """Ramp every source's drive parameter (Component.drive: a pressure or flow source's value)
    from 30 % to 100 %, continuing the solution from the DC guess at 30 % (X0 is not used);
    a member that fails at a step drops out."""
    paths = [f"{e}.{g.comp.drive.value}" for g in circuit.groups if g.comp.drive is not None for e in g.ids]
    B = circuit.B
    base = {p: np.broadcast_to(np.asarray(circuit.parameters.values[p], float), (B,)) for p in paths}
    alive = np.arange(B)
    X = np.full((B, circuit.nx), np.nan)
    ok = np.zeros(B, bool)
    res = np.full(B, np.inf)
    whole = any(callable(v) for v in totals)
    for k, lam in enumerate(np.linspace(0.3, 1.0, 15)):
        sub = circuit.subset(alive) if len(alive) < B else circuit
        c = sub.with_values({p: base[p][alive] * lam if sub.B > 1 else float(base[p][alive[0]] * lam)
                             for p in paths})
        Xa = dc_guess(c, t) if k == 0 else X[alive]
        Xa, oka, ra = newton_members(c, Xa, totals if len(alive) == B else _subset_totals(totals, alive), t, ptc=True)
        X[alive], res[alive] = Xa, ra
        if whole and not oka.all():
            return X, ok, res
        alive = alive[oka]
        if len(alive) == 0:
            return X, ok, res
    ok[alive] = True
    return X, ok, res


def operating_point(circuit, t: float = 0.0, x0=None) -> OperatingPoint:
    """Steady state of the circuit (every parameter set of a batch at once).  Raises
    SolverError if any member has no operating point (:func:`operating_points` keeps the
    others)."""
    started = clock()
    cs, X, ok, res, method, failures = _solve(circuit, t, x0)
    _raise_failures(circuit, ok, failures)
    op = _result(cs, t, X, res, method)
    _check_plausible(op, circuit)
    return stamp(op, "op", circuit, {"t": t, "x0": None if x0 is None else "given", "tol": 1e-10}, started)


def steady_state(circuit, t: float = 0.0, x0=None):
    """The operating point's states only, (nx,) or (B, nx) for a batch: the start of a run
    from it (the svZeroDSolver conformance runner's timed start).  The same solve as
    :func:`operating_point`, without its output columns and their plausibility check (a
    third of a small circuit's operating point).  Raises SolverError as it does."""
    _, X, ok, _, _, failures = _solve(circuit, t, x0)
    _raise_failures(circuit, ok, failures)
    return X[0] if circuit.B == 1 else X


def _raise_failures(circuit, ok, failures):
    """SolverError naming the first member without an operating point (and how many failed)."""
    if ok.all():
        return
    bad = np.nonzero(~ok)[0]
    b = bad[0]
    message, state = failures[b]
    if circuit.B > 1:
        shown = ", ".join(str(k) for k in bad[:10]) + (" ..." if len(bad) > 10 else "")
        message += f" in batch member {b} ({len(bad)} of {circuit.B} members failed: {shown})"
    raise SolverError(message, state=state, where="computing the operating point")


def _check_plausible(op, circuit):
    """hemocircuit.plausibility on the operating point: a non-finite value raises SolverError
    naming the column; implausible values are recorded in ``metadata['warnings']``."""
    from .. import plausibility

    findings = plausibility.check(circuit, op.values, members=circuit.B > 1)
    bad = plausibility.errors(findings)
    if bad:
        raise SolverError("implausible operating point: " + "; ".join(map(str, bad)),
                          where="computing the operating point")
    plausibility.add_warnings(op, findings)


def _solve(circuit, t, x0):
    """Every member's operating point: (steady circuit, X (B, nx), ok (B,), residual (B,),
    method (B,), failures {member: (message, state dict or None)})."""
    totals = [np.atleast_1d(v) if v is not None else None for v in conserved_totals(circuit, t)]
    circuit = circuit.steady_variant()
    B = circuit.B
    failures = {}
    calibrated = circuit.structure.recall(_calibrated_key(circuit, t)) if x0 is None else None
    if calibrated is not None and calibrated.shape == (B, circuit.nx):
        # a calibration solved this very circuit (its 'when' values are these): Newton starts
        # on its solution instead of the DC guess (body.yaml: 1 iteration instead of 20)
        X0 = calibrated.copy()
    elif x0 is None:
        # the DC guess starts Newton, not the elements' default states: from those, Newton on
        # the compiled engine (~20 us against ~0.7 ms here) found other roots of arteriole
        # circuits (payne06 over Pa 20-200 mmHg: flows of 1e-5 .. 1e-7 mL/s instead of ~7)
        X0, failures = _dc_guess_members(circuit, t)
    else:
        X0 = np.atleast_2d(np.asarray(x0, float)).copy()
    X = np.full((B, circuit.nx), np.nan)
    ok, res = np.zeros(B, bool), np.full(B, np.inf)
    method = np.full(B, "failed", dtype=object)
    idx = np.array([k for k in range(B) if k not in failures], dtype=int)
    if len(idx):
        sub = circuit.subset(idx) if len(idx) < B else circuit
        X[idx], ok[idx], res[idx], method[idx] = solve_members(sub, X0[idx], _subset_totals(totals, idx), t)
    bad = np.array([k for k in np.nonzero(~ok)[0] if k not in failures], dtype=int)
    if len(bad):
        failures.update(_explain(circuit, t, X, totals, bad))
    return circuit, X, ok, res, method, failures


def _dc_guess_members(circuit, t, start=None):
    """The DC guess of every member: (X0 (B, nx), {member: (message, None)} for members whose
    DC network cannot be solved).  The nodal solve raises for a whole batch; a failing batch
    is bisected (the DC guess is cheap) so that the other members keep theirs."""
    B = circuit.B
    X0 = np.full((B, circuit.nx), np.nan)
    failures = {}
    if B > 1:  # members whose elements have no default states (e.g. an arteriole without a
        # steady state at 60 mmHg) make the DC network singular: set them aside at once
        start = default_states(circuit) if start is None else start
        bad = ~np.all(np.isfinite(start), axis=1)
        if bad.any():
            for k in np.nonzero(bad)[0]:
                failures[int(k)] = ("DC guess: the elements' default states are not finite (e.g. no "
                                    "steady state of a component at its default pressure)", None)
            good = np.nonzero(~bad)[0]
            if len(good):
                Xg, fg = _dc_guess_members(circuit.subset(good), t, start[good])
                X0[good] = Xg
                failures.update({int(good[k]): v for k, v in fg.items()})
            return X0, failures
    try:
        return dc_guess(circuit, t, start=start), {}
    except HemocircuitError as exc:
        if B == 1:
            return np.full((1, circuit.nx), np.nan), {0: (f"DC guess: {exc}", None)}
    half = circuit.B // 2
    for idx in (np.arange(half), np.arange(half, circuit.B)):
        Xi, fi = _dc_guess_members(circuit.subset(idx), t, None if start is None else start[idx])
        X0[idx] = Xi
        failures.update({int(idx[k]): v for k, v in fi.items()})
    return X0, failures


def _explain(circuit, t, X, totals, bad):
    """{member: (message naming its worst-balanced state, state dict)} for members in ``bad``."""
    out = {}
    head = "no operating point found (Newton, pseudo-transient continuation and source stepping failed)"
    sub = circuit.subset(bad) if len(bad) < circuit.B else circuit
    try:
        F = residual(sub, t, X[bad], _subset_totals(totals, bad))
    except HemocircuitError:
        return {int(b): (head, None) for b in bad}
    for i, b in enumerate(bad):
        scaled = np.abs(F[i]) / circuit.state_scales
        if not np.any(np.isfinite(X[b])):
            out[int(b)] = (head, None)
            continue
        j = int(np.nanargmax(np.where(np.isfinite(scaled), scaled, np.inf)))
        out[int(b)] = (f"{head}; worst-balanced state '{circuit.state_names[j]}' with "
                       f"d/dt = {F[i, j]:.3g} {circuit.state_units[j]}/s", circuit.state_dict(X[b]))
    return out


def _result(circuit, t, X, res, method):
    """The OperatingPoint of solved states X (all members converged)."""
    # outputs from the steady variant (collapsed stores report V = 0), laws shared
    single = circuit.B == 1
    if single:
        vals = {k: float(v[0]) for k, v in circuit.outputs(t, X).items()}
    else:  # one row per member: outputs() evaluates the whole batch at once
        vals = {k: np.array(v, dtype=float) for k, v in circuit.outputs(t, X).items()}
    label = "newton" if all(m == "newton" for m in method) else "fallback"
    return OperatingPoint(circuit, X[0] if single else X, vals, circuit.column_units(), label,
                          float(np.max(res)))


def operating_points(circuit, t: float = 0.0, x0=None):
    """Operating points of every member of a batch circuit, failures kept per member.

    Returns (X (B, nx) with NaN rows for failed members, {column: (B,) array, NaN for failed
    members}, [error message or None] per member).  Newton runs on the whole batch and the
    fallbacks on the members it did not solve (:func:`solve_members`); a member whose DC
    network cannot be solved is found by bisecting the DC guess.  If the batch still raises as
    a whole (an error that names no member), it is bisected.
    """
    B = circuit.B
    try:
        cs, X, ok, res, method, failures = _solve(circuit, t, x0)
    except HemocircuitError as exc:
        if B == 1:
            return np.full((1, circuit.nx), np.nan), {}, [f"operating point: {exc}"]
        X = np.full((B, circuit.nx), np.nan)
        vals, errors = {}, []
        for idx in (np.arange(B // 2), np.arange(B // 2, B)):
            Xi, v, e = operating_points(circuit.subset(idx), t, None if x0 is None else np.atleast_2d(x0)[idx])
            X[idx] = Xi
            for k, a in v.items():
                vals.setdefault(k, np.full(B, np.nan))[idx] = a
            errors += e
        return X, vals, errors
    errors = [None if ok[b] else f"operating point: {failures[b][0]}" for b in range(B)]
    X[~ok] = np.nan
    vals = {}
    idx = np.nonzero(ok)[0]
    if len(idx):
        sub = cs.subset(idx) if len(idx) < B else cs
        out = sub.outputs(t, X[idx])
        for k, v in out.items():
            col = np.full(B, np.nan)
            col[idx] = np.broadcast_to(np.asarray(v, float), (len(idx),))
            vals[k] = col
    return X, vals, errors
