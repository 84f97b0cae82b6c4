# Template of the compiled circuit engine: NOT imported on its own.
#
# hemocircuit.kernels.codegen writes one module per set of component types, made of a header
# (imports, and the dispatchers elem_stamp / elem_derivs / elem_observe that call each type's
# Kernel functions by a type code) followed by this text.  Everything here is numba nopython
# code with no per-call Python: the nodal solve, the right-hand side, the finite-difference
# Jacobian and a stiff Rosenbrock-W integrator with hard-limit events and dense output.
#
# Layout tuple ``lay`` (built by hemocircuit.kernels.layout from an assembled circuit):
#   n, nx            unknowns of the nodal system (pressures, branch flows), states
#   et (E,)          type code of element e;  L (E,) local unknowns;  S (E,) states
#   ep (E+1,)        offsets of each element's parameters in the flat parameter vector P
#   ex (E+1,)        offsets of each element's states in x (states of an element are contiguous)
#   eu (E+1,), ui    offsets into ui: global index of each local unknown (n = the ground slot)
#   eo (E+1,), io    offsets into io: the element's integer options (Component.kernel_options)
#   eb (E+1,)        offsets of each element's state-only observables in the vector O
#   ws, w0, wd       waveforms: parameter slot, start of the record in wd (kernels.waveforms)
#   xs, xc, xk       expressions: parameter slot, start in the code / constants arrays
#   xcode, xconst    expression programs (kernels.expressions)
#   oe               elements whose observables expressions read (evaluated before them)
#   nonlin           1 if some element is nonlinear in the pressures (Newton on the nodes)
#   cm (E,)          1 if the element's matrix stamp is constant (summed once into A0)
#   st (E,)          1 if its whole stamp is constant ("static": stamped once, into A0 and b0),
#                    2 if it is nonlinear in the pressures (stamped at every Newton iterate), else 0
# Units: as the numpy path -- pressures mmHg, flows mL/s, time s, states in declared units.
#
# Entry points called from Python: rhs, rhs_batch, nodal_outputs, integrate_batch(_bdf).  Every other compiled
# function is ``internal=True`` (the header's njit): numba then builds no Python/C wrapper for it,
# whose unboxing of the layout and work tuples cost ~15 % of the first compilation.

# _nrt=False on the functions that never allocate (and return no array): no reference counting
# of the arrays they touch.  With it on, NRT's atomic increments/decrements of the layout's and
# work tuple's arrays took 43 % of the vasomotion run's samples (perf); without it the run
# takes 3.1x less CPU (docs/performance.md).
# (Functions inlined with inline="always" take their caller's setting.)
NEWTON_TOL = 1e-12
NEWTON_MAXIT = 50


@njit(cache=True, nogil=True, internal=True)
def make_work(lay):
    """Scratch arrays for one evaluation.  Elements get whole scratch buffers (pl, xl, ul, Al,
    bl, il, dl, ol) rather than slices: a slice is a new array view whose reference counting
    costs more than the element's equations (measured 70 ns a call against 2 ns)."""
    (n, nx, et, L, S, ep, ex, eu, ui, eo, io, eb, ws, w0, wd, xs, xc, xk, xcode, xconst, oe, nonlin, cm, st) = lay
    Lm, Sm, Pm, Im, Om = 1, 1, 1, 1, 1
    for e in range(et.shape[0]):
        Lm = max(Lm, L[e])
        Sm = max(Sm, S[e])
        Pm = max(Pm, ep[e + 1] - ep[e])
        Im = max(Im, eo[e + 1] - eo[e])
        Om = max(Om, eb[e + 1] - eb[e])
    return (np.zeros(ep[-1]), np.zeros(max(eb[-1], 1)), np.zeros((n + 1, n + 1)), np.zeros(n + 1),
            np.zeros(n + 1), np.zeros((Lm, Lm)), np.zeros(Lm), np.zeros(Lm), np.zeros(n + 1),
            np.zeros(Pm), np.zeros(Sm), np.zeros(Im, dtype=np.int64), np.zeros(Sm), np.zeros(Om),
            np.zeros((n + 1, n + 1)), np.zeros(n + 1), np.zeros(n + 1, dtype=np.int64),
            # static condensation (prepare_static): 17 Acc's LU, 18 Z = Acc^-1 Acv, 19 S0, 20 Avc,
            # 21 S, 22 pivots of Acc, 23 order (C unknowns, then V), 24 slot in V (-1: in C),
            # 25 [nc, nv, on], 26 y, 27 rv
            np.zeros((n + 1, n + 1)), np.zeros((n + 1, n + 1)), np.zeros((n + 1, n + 1)),
            np.zeros((n + 1, n + 1)), np.zeros((n + 1, n + 1)), np.zeros(n + 1, dtype=np.int64),
            np.zeros(n + 1, dtype=np.int64), np.zeros(n + 1, dtype=np.int64), np.zeros(3, dtype=np.int64),
            np.zeros(n + 1), np.zeros(n + 1),
            # 28-30: scratch of the waveform sums and the expression programs (no allocation in
            # the functions compiled without numba's runtime)
            np.zeros(WAVE_SUM_DEPTH), np.zeros(WAVE_SUM_DEPTH, dtype=np.int64), np.zeros(EXPR_STACK),
            # 31-33: the nodal system's iterate-independent part A1 (Sw1 condensed), b1 (solve_nodes)
            np.zeros((n + 1, n + 1)), np.zeros((n + 1, n + 1)), np.zeros(n + 1))


# inline="always" (numba IR inlining) on the small helpers called inside the per-evaluation
# loops: passing the layout and work tuples to a separate function costs a reference count per
# member (~1 us per evaluation in all).  Not on rhs_into: inlining it at its six call sites
# quadruples the compile time (25 s -> 100 s) for 14 % speed.
@njit(cache=True, nogil=True, inline="always")
def load_element(e, x, Pe, ep, ex, eo, io, pl, xl, il):
    """Copy element e's parameters, states and options into the scratch buffers.  (Arrays, not
    the layout tuple: passing the tuple costs a reference count per member, ~70 ns.)"""
    for i in range(ep[e], ep[e + 1]):
        pl[i - ep[e]] = Pe[i]
    for i in range(ex[e], ex[e + 1]):
        xl[i - ex[e]] = x[i]
    for i in range(eo[e], eo[e + 1]):
        il[i - eo[e]] = io[i]


@njit(cache=True, nogil=True, inline="always")
def effective_params(t, x, P, lay, work):
    """Parameters with waveforms added and expressions evaluated (into work[0])."""
    (n, nx, et, L, S, ep, ex, eu, ui, eo, io, eb, ws, w0, wd, xs, xc, xk, xcode, xconst, oe, nonlin, cm, st) = lay
    Pe, O, pl, xl, il, ol = work[0], work[1], work[9], work[10], work[11], work[13]
    for i in range(P.shape[0]):
        Pe[i] = P[i]
    for w in range(ws.shape[0]):
        Pe[ws[w]] += wave_value_with(wd, w0[w], t, work[28], work[29])
    if xs.shape[0] > 0:
        for j in range(oe.shape[0]):
            e = oe[j]
            load_element(e, x, Pe, ep, ex, eo, io, pl, xl, il)
            elem_observe(et[e], pl, xl, il, ol)
            for i in range(eb[e], eb[e + 1]):
                O[i] = ol[i - eb[e]]
        for k in range(xs.shape[0]):
            Pe[xs[k]] = eval_expr_with(xcode, xc[k], xconst, xk[k], Pe, O, work[30])
    return Pe


@njit(cache=True, nogil=True, inline="always")
def stamp_element(e, t, x, Pe, et, L, ep, ex, eu, ui, eo, io, u, Al, bl, ul, pl, xl, il):
    """Element e's local stamp into the scratch Al, bl (at the current iterate u).  Arrays, not
    the layout and work tuples: passing a tuple costs a reference count per member."""
    Lm = ul.shape[0]
    Le = L[e]
    for i in range(Lm):
        bl[i] = 0.0
        ul[i] = u[ui[eu[e] + i]] if i < Le else 0.0
        for j in range(Lm):
            Al[i, j] = 0.0
    load_element(e, x, Pe, ep, ex, eo, io, pl, xl, il)
    elem_stamp(et[e], pl, xl, ul, t, il, Al, bl)


@njit(cache=True, nogil=True, internal=True, _nrt=False)
def prepare_static(t, x, P, lay, work):
    """A0 = the constant matrix stamps, b0 = the static elements' right-hand sides, for the
    parameters P (call again whenever P changes)."""
    (n, nx, et, L, S, ep, ex, eu, ui, eo, io, eb, ws, w0, wd, xs, xc, xk, xcode, xconst, oe, nonlin, cm, st) = lay
    Pe = effective_params(t, x, P, lay, work)
    A0, b0, u, Al, bl, ul, pl, xl, il = work[14], work[15], work[4], work[5], work[6], work[7], work[9], work[10], work[11]
    A0[:, :] = 0.0
    b0[:] = 0.0
    for e in range(et.shape[0]):
        if cm[e] == 0:
            continue
        stamp_element(e, t, x, Pe, et, L, ep, ex, eu, ui, eo, io, u, Al, bl, ul, pl, xl, il)
        for i in range(L[e]):
            r = ui[eu[e] + i]
            if st[e] == 1:
                b0[r] += bl[i]
            for j in range(L[e]):
                A0[r, ui[eu[e] + j]] += Al[i, j]
    condense(lay, work)


@njit(cache=True, nogil=True, internal=True, _nrt=False)
def condense(lay, work):
    """Static condensation of the nodal system: the unknowns V that state-dependent matrix
    stamps touch are kept, the constant rest C is eliminated once per parameter set.  With
    A0 = [[Acc, Acv], [Avc, Avv]]: Acc is factorised, Z = Acc^-1 Acv and the Schur complement
    S0 = Avv - Avc Z stored; an evaluation then solves only S0 + (varying stamps) (nv x nv).
    Used when V is at most half the unknowns and Acc is regular; otherwise the dense path."""
    (n, nx, et, L, S, ep, ex, eu, ui, eo, io, eb, ws, w0, wd, xs, xc, xk, xcode, xconst, oe, nonlin, cm, st) = lay
    A0, Fc, Z, S0, Avc, pivc, order, vpos, meta, y = (work[14], work[17], work[18], work[19], work[20],
                                                      work[22], work[23], work[24], work[25], work[26])
    meta[2] = 0
    for i in range(n + 1):
        vpos[i] = -1
    for e in range(et.shape[0]):
        if cm[e] == 0:
            for i in range(L[e]):
                r = ui[eu[e] + i]
                if r < n:
                    vpos[r] = 0
    # unknowns the constant part alone leaves undetermined (e.g. a node joined to the rest
    # only through a state-dependent element) join V: Acc must be regular
    while True:
        nv = 0
        for i in range(n):
            if vpos[i] >= 0:
                nv += 1
        nc = n - nv
        if nv == 0 or 2 * nv > n:
            return
        k = 0
        for i in range(n):
            if vpos[i] < 0:
                order[k] = i
                k += 1
        for i in range(nc):
            for j in range(nc):
                Fc[i, j] = A0[order[i], order[j]]
        bad = lu_factor_at(Fc, pivc, nc)
        if bad < 0:
            break
        vpos[order[bad]] = 0
    a = 0
    for i in range(n):
        if vpos[i] >= 0:
            order[nc + a] = i
            vpos[i] = a
            a += 1
    for b in range(nv):
        for i in range(nc):
            y[i] = A0[order[i], order[nc + b]]
        lu_apply(Fc, pivc, y, nc)
        for i in range(nc):
            Z[i, b] = y[i]
    for a in range(nv):
        for i in range(nc):
            Avc[a, i] = A0[order[nc + a], order[i]]
        for b in range(nv):
            acc = A0[order[nc + a], order[nc + b]]
            for i in range(nc):
                acc -= Avc[a, i] * Z[i, b]
            S0[a, b] = acc
    meta[0] = nc
    meta[1] = nv
    meta[2] = 1


@njit(cache=True, nogil=True, inline="always")
def add_stamp(e, L, eu, ui, cm, Al, bl, A, Sw, b, schur, vpos, n):
    """Add element e's local stamp (Al, bl) into the nodal right-hand side b and, where its
    matrix is not constant (cm 0; the constant ones are in A0), into A (dense path) or into
    the condensed Sw (its V unknowns: a varying stamp touches only those)."""
    for i in range(L[e]):
        r = ui[eu[e] + i]
        b[r] += bl[i]
        if cm[e] == 0:
            if schur:
                if r < n:
                    for j in range(L[e]):
                        c = ui[eu[e] + j]
                        if c < n:
                            Sw[vpos[r], vpos[c]] += Al[i, j]
            else:
                for j in range(L[e]):
                    A[r, ui[eu[e] + j]] += Al[i, j]


@njit(cache=True, nogil=True, inline="always")
def copy_nodal(As, Ss, bs, A, Sw, b, schur, nv, n):
    """(A or, condensed, Sw; b) = (As or Ss; bs): the nodal system's matrix and right-hand side."""
    for i in range(n + 1):
        b[i] = bs[i]
    if schur:
        for a in range(nv):
            for c in range(nv):
                Sw[a, c] = Ss[a, c]
    else:
        for i in range(n + 1):
            for j in range(n + 1):
                A[i, j] = As[i, j]


@njit(cache=True, nogil=True, inline="always")
def solve_nodes(t, x, Pe, lay, work):
    """Node pressures and branch flows u (n+1,; u[n] = 0 is ground) for states x: the MNA
    system A0 + (varying stamps) and b0 + (non-static right-hand sides), solved densely
    (Newton for elements nonlinear in the pressures).  prepare_static must have run for these
    parameters.  Returns False if the system is singular or Newton fails.

    With Newton (nonlin), the stamps that do not depend on the iterate (st 0: elements affine
    in the pressures; they depend on t and x only, e.g. a pressure table or a chamber's
    elastance) are summed once per solve into A1 (or Sw1) and b1, and only the elements
    nonlinear in the pressures (st 2) are stamped again at every iterate (svZeroDSolver's
    split of a block's contributions by what they depend on)."""
    (n, nx, et, L, S, ep, ex, eu, ui, eo, io, eb, ws, w0, wd, xs, xc, xk, xcode, xconst, oe, nonlin, cm, st) = lay
    A, b, u, Al, bl, un, A0, b0 = work[2], work[3], work[4], work[5], work[6], work[8], work[14], work[15]
    ul, pl, xl, il, piv = work[7], work[9], work[10], work[11], work[16]
    Fc, Z, S0, Avc, Sw, pivc, order, vpos, meta, y, rv = (work[17], work[18], work[19], work[20], work[21],
                                                          work[22], work[23], work[24], work[25], work[26],
                                                          work[27])
    A1, Sw1, b1 = work[31], work[32], work[33]
    schur = meta[2] == 1
    nc = meta[0]
    nv = meta[1]
    if nonlin == 0:
        for i in range(n + 1):
            u[i] = 0.0
    for it in range(NEWTON_MAXIT):
        # the system's base: A0, b0 at the first iterate, then A1, b1 (the base plus the
        # iterate-independent stamps, kept from the first)
        if it == 0:
            copy_nodal(A0, S0, b0, A, Sw, b, schur, nv, n)
        else:
            copy_nodal(A1, Sw1, b1, A, Sw, b, schur, nv, n)
        # phase 0 (first iterate only): the stamps that do not depend on the iterate (st 0);
        # phase 1: those nonlinear in the pressures (st 2).  One stamp call site: each inlined
        # copy of the kernels' stamps costs compile time
        for ph in range(2):
            if ph == 0 and it > 0:
                continue
            for e in range(et.shape[0]):
                if st[e] != 2 * ph:
                    continue
                stamp_element(e, t, x, Pe, et, L, ep, ex, eu, ui, eo, io, u, Al, bl, ul, pl, xl, il)
                add_stamp(e, L, eu, ui, cm, Al, bl, A, Sw, b, schur, vpos, n)
            if ph == 0 and nonlin != 0:  # keep the iterate-independent sum for the next iterates
                copy_nodal(A, Sw, b, A1, Sw1, b1, schur, nv, n)
        if schur:
            # y = Acc^-1 b_C;  (S0 + varying) u_V = b_V - Avc y;  u_C = y - Z u_V
            for i in range(nc):
                y[i] = b[order[i]]
            lu_apply(Fc, pivc, y, nc)
            for a in range(nv):
                acc = b[order[nc + a]]
                for i in range(nc):
                    acc -= Avc[a, i] * y[i]
                rv[a] = acc
            if not lu_factor(Sw, piv, nv):
                return False
            lu_apply(Sw, piv, rv, nv)
            for a in range(nv):
                un[order[nc + a]] = rv[a]
            for i in range(nc):
                acc = y[i]
                for a in range(nv):
                    acc -= Z[i, a] * rv[a]
                un[order[i]] = acc
        else:
            if not lu_factor(A, piv, n):
                return False
            for i in range(n):
                un[i] = b[i]
            lu_apply(A, piv, un, n)
        un[n] = 0.0
        if nonlin == 0:
            for i in range(n + 1):
                u[i] = un[i]
            return True
        change = 0.0
        for i in range(n + 1):
            d = abs(un[i] - u[i]) / (1.0 + abs(un[i]))
            if d > change:
                change = d
            u[i] = un[i]
        if change < NEWTON_TOL:
            return True
    return False


@njit(cache=True, nogil=True, internal=True, _nrt=False)
def rhs_into(t, x, P, lay, work, dx):
    """dx/dt for states x at time t into dx.  Returns False on a singular nodal system
    (dx is then NaN).  An empty dx: the nodal solve only (nodal_outputs_into: the outputs need
    no derivatives, a third of an evaluation; the same compiled function, so no second
    compilation of the inlined nodal solve)."""
    (n, nx, et, L, S, ep, ex, eu, ui, eo, io, eb, ws, w0, wd, xs, xc, xk, xcode, xconst, oe, nonlin, cm, st) = lay
    Pe = effective_params(t, x, P, lay, work)
    if not solve_nodes(t, x, Pe, lay, work):
        for i in range(dx.shape[0]):
            dx[i] = np.nan
        return False
    if dx.shape[0] == 0:
        return True
    u, ul, pl, xl, il, dl = work[4], work[7], work[9], work[10], work[11], work[12]
    for e in range(et.shape[0]):
        if S[e] == 0:
            continue
        for i in range(L[e]):
            ul[i] = u[ui[eu[e] + i]]
        load_element(e, x, Pe, ep, ex, eo, io, pl, xl, il)
        elem_derivs(et[e], pl, xl, ul, t, il, dl)
        for i in range(ex[e], ex[e + 1]):
            dx[i] = dl[i - ex[e]]
    return True


@njit(cache=True, nogil=True)
def rhs(t, x, P, lay):
    """dx/dt (allocating; for tests and single calls)."""
    work = make_work(lay)
    prepare_static(t, x, P, lay, work)
    dx = np.empty(x.shape[0])
    rhs_into(t, x, P, lay, work, dx)
    return dx


@njit(cache=True, nogil=True)
def rhs_batch(t, X, P, lay):
    """dx/dt for rows X (m, nx) with parameter rows P (m or 1, nP)."""
    work = make_work(lay)
    out = np.empty(X.shape)
    for k in range(X.shape[0]):
        p = P[k if P.shape[0] > 1 else 0]
        if k == 0 or P.shape[0] > 1:
            prepare_static(t, X[k], p, lay, work)
        rhs_into(t, X[k], p, lay, work, out[k])
    return out


@njit(cache=True, nogil=True)
def nodal_outputs(T, X, P, lay, U, F):
    """What Circuit.outputs needs from the nodal system, for rows X (m, nx) at times T (m,):
    the solution U (m, n+1; ground last) and every element's flow F (m, E), the first row of its
    local residual Al ul - bl (zero for an element with no local unknowns).  P (B, nP): row k
    belongs to member k // (m // B) (member-major rows, as Circuit.outputs lays them out).
    Returns -1, or the first row whose nodal system is singular or whose Newton fails."""
    return nodal_outputs_into(T, X, P, lay, make_work(lay), np.empty(0), U, F)  # no derivatives (rhs_into)


@njit(cache=True, nogil=True, internal=True, _nrt=False)
def nodal_outputs_into(T, X, P, lay, work, dx, U, F):
    """nodal_outputs with the scratch arrays given (no allocation: compiled without reference
    counting, as rhs_into).  Through rhs_into, which leaves the effective parameters in work[0]
    and the nodal solution in work[4]: its compilation (the integrator's, from the cache) is
    reused instead of typing the inlined nodal solve again (7 s of a first compilation).  An
    empty ``dx`` skips the derivatives there."""
    (n, nx, et, L, S, ep, ex, eu, ui, eo, io, eb, ws, w0, wd, xs, xc, xk, xcode, xconst, oe, nonlin, cm, st) = lay
    Pe, u, Al, bl, ul, pl, xl, il = work[0], work[4], work[5], work[6], work[7], work[9], work[10], work[11]
    m = X.shape[0]
    per = m // P.shape[0]
    for k in range(m):
        p = P[k // per]
        if k % per == 0:
            prepare_static(T[k], X[k], p, lay, work)
        if not rhs_into(T[k], X[k], p, lay, work, dx):
            return k
        for i in range(n + 1):
            U[k, i] = u[i]
        for e in range(et.shape[0]):
            if L[e] == 0:
                F[k, e] = 0.0
                continue
            # at the converged u, an element nonlinear in the pressures stamps its
            # linearisation there, whose residual is its flow at u
            stamp_element(e, T[k], X[k], Pe, et, L, ep, ex, eu, ui, eo, io, u, Al, bl, ul, pl, xl, il)
            acc = -bl[0]
            for j in range(L[e]):
                acc += Al[0, j] * ul[j]
            F[k, e] = acc
    return -1


#: a state within this many times its atol above its hard limit counts as on it (held there,
#: not located as a crossing): 1e-3 atol, far below any error the step control admits
LIMIT_ON_BOUND = 1e-3


@njit(cache=True, nogil=True, internal=True, _nrt=False)
def finish_member(out, k_from, stats, m, status, t, nsteps, nrej, nfev, nev):
    """The end of member m's run in both integrators: its output rows from k_from on NaN (not
    reached: the run failed or stopped there) and its stats row (status, t reached, steps,
    rejected steps, f evaluations, limit events)."""
    for k in range(k_from, out.shape[0]):
        for i in range(out.shape[1]):
            out[k, i] = np.nan
    stats[m, 0] = status
    stats[m, 1] = t
    stats[m, 2] = nsteps
    stats[m, 3] = nrej
    stats[m, 4] = nfev
    stats[m, 5] = nev

# --- Rosenbrock(-W) integrator.  The tableau is a run-time argument (``tab``, packed by
# hemocircuit.kernels.tableaus: RODAS5P by default, ROS34PW2, ROS34PW3, RODAS4), so choosing a
# method never recompiles.
from hemocircuit.derivatives import FD_REL  # noqa: E402 - the one step rule: relative to max(|x|, the state's scale)


@njit(cache=True, nogil=True)
def make_jac_work(lay):
    """Scratch arrays of local_jacobian_into: 0 base parameters Pe, 1 the full nodal matrix
    (its LU), 2 its pivots, 3 base unknowns u, 4 base local residuals (at the eu offsets),
    5 dD/du (nx, n+1), 6 one column dR/dx_j, 7 base derivatives, 8 stored local matrices
    (at the eu offsets, Lm columns), 9 stored local right-hand sides, 10 1 if the element has
    an expression parameter, 11 1 if expressions read the element's observables (both depend
    on the layout only), 12 1 if the element's partials came from its kernel's derivs_jac at
    this call, 13 those partials d dx/d x_own (at the ex offsets, Sm columns), 14-15 scratch
    (Sm, Sm) and (Sm, Lm) for one element's Jx, Ju."""
    (n, nx, et, L, S, ep, ex, eu, ui, eo, io, eb, ws, w0, wd, xs, xc, xk, xcode, xconst, oe, nonlin, cm, st) = lay
    Lm = 1
    for e in range(et.shape[0]):
        Lm = max(Lm, L[e])
    nu = max(ui.shape[0], 1)
    hasx = np.zeros(et.shape[0], dtype=np.int64)
    for k in range(xs.shape[0]):
        for e in range(et.shape[0]):
            if ep[e] <= xs[k] < ep[e + 1]:
                hasx[e] = 1
    observed = np.zeros(et.shape[0], dtype=np.int64)
    if xs.shape[0] > 0:
        for k in range(oe.shape[0]):
            observed[oe[k]] = 1
    Sm = 1
    for e in range(et.shape[0]):
        Sm = max(Sm, S[e])
    return (np.zeros(max(ep[-1], 1)), np.zeros((n + 1, n + 1)), np.zeros(n + 1, dtype=np.int64), np.zeros(n + 1),
            np.zeros(nu), np.zeros((max(nx, 1), n + 1)), np.zeros(n + 1), np.zeros(max(nx, 1)),
            np.zeros((nu, Lm)), np.zeros(nu), hasx, observed, np.zeros(et.shape[0], dtype=np.int64),
            np.zeros((max(nx, 1), Sm)), np.zeros((Sm, Sm)), np.zeros((Sm, Lm)))


@njit(cache=True, nogil=True, _nrt=False)
def local_jacobian_into(t, x, P, lay, work, jw, scales, J, xt, analytic):
    """State Jacobian J (nx, nx) at (t, x) from element-local differences composed through the
    nodal solve (as svZeroDSolver composes its blocks' derivatives), without a whole
    right-hand side per column.  With f = D(x, u), R(x, u) = A(x) u - b(x) = 0 the nodal
    system (linear in u):  du/dx = -A^-1 dR/dx  and  J = dD/dx + dD/du du/dx.  Each element
    gives its columns of dR/dx, dD/dx (its own states; the elements with expression parameters
    also those of the states their expressions read) and dD/du (its local unknowns) by forward
    differences of its own stamp and derivs, same step rule as jacobian_into (FD_REL; FD_REL
    max(|u|, 1) for an unknown in mmHg or mL/s) -- or, with ``analytic``, dD/dx of its own
    states and dD/du from its kernel's derivs_jac where it has one (and no expression moves
    its parameters with the states): one call instead of one derivs per state and unknown.
    Returns 0, or -1 when it does not apply (an element nonlinear in the pressures, a singular
    nodal matrix): the caller then differences whole right-hand sides."""
    (n, nx, et, L, S, ep, ex, eu, ui, eo, io, eb, ws, w0, wd, xs, xc, xk, xcode, xconst, oe, nonlin, cm, st) = lay
    if nonlin != 0:
        return -1
    Pb, A, piv, ub, rb, M, col, Db, Ab, bb, hasx, obs, an, Jxs, Jxl, Jul = jw
    u, Al, bl, ul, pl, xl, il, dl, A0, b0 = (work[4], work[5], work[6], work[7], work[9], work[10], work[11],
                                             work[12], work[14], work[15])
    E = et.shape[0]
    Pe = effective_params(t, x, P, lay, work)
    for i in range(Pb.shape[0]):
        Pb[i] = Pe[i]
    # the full nodal system at x (as solve_nodes, without condensation); local stamps kept
    for i in range(n + 1):
        ub[i] = b0[i]
        for k in range(n + 1):
            A[i, k] = A0[i, k]
    for e in range(E):
        if st[e] == 1:
            continue
        stamp_element(e, t, x, Pb, et, L, ep, ex, eu, ui, eo, io, u, Al, bl, ul, pl, xl, il)
        for i in range(L[e]):
            r = ui[eu[e] + i]
            ub[r] += bl[i]
            bb[eu[e] + i] = bl[i]
            for k in range(L[e]):
                Ab[eu[e] + i, k] = Al[i, k]
                if cm[e] == 0:
                    A[r, ui[eu[e] + k]] += Al[i, k]
    if not lu_factor(A, piv, n):
        return -1
    lu_apply(A, piv, ub, n)
    ub[n] = 0.0
    # base residuals, derivatives and dD/du
    for i in range(M.shape[0]):
        for k in range(n + 1):
            M[i, k] = 0.0
    for e in range(E):
        if st[e] == 1:
            continue
        for i in range(L[e]):
            acc = -bb[eu[e] + i]
            for k in range(L[e]):
                acc += Ab[eu[e] + i, k] * ub[ui[eu[e] + k]]
            rb[eu[e] + i] = acc
        an[e] = 0
        if S[e] == 0:
            continue
        for i in range(L[e]):
            ul[i] = ub[ui[eu[e] + i]]
        load_element(e, x, Pb, ep, ex, eo, io, pl, xl, il)
        # the kernel's own partials where it has them (and no expression moves its parameters
        # with the states): one evaluation instead of one per state and local unknown
        if analytic and hasx[e] == 0 and elem_derivs_jac(et[e], pl, xl, ul, t, il, dl, Jxl, Jul) == 1:
            an[e] = 1
            for i in range(S[e]):
                Db[ex[e] + i] = dl[i]
                for k in range(S[e]):
                    Jxs[ex[e] + i, k] = Jxl[i, k]
            for k in range(L[e]):
                g = ui[eu[e] + k]
                if g >= n:
                    continue
                for i in range(S[e]):
                    M[ex[e] + i, g] += Jul[i, k]
            continue
        elem_derivs(et[e], pl, xl, ul, t, il, dl)
        for i in range(S[e]):
            Db[ex[e] + i] = dl[i]
        for k in range(L[e]):
            g = ui[eu[e] + k]
            if g >= n:
                continue
            hk = FD_REL * max(abs(ub[g]), 1.0)
            ul[k] = ub[g] + hk
            hk = ul[k] - ub[g]
            elem_derivs(et[e], pl, xl, ul, t, il, dl)
            for i in range(S[e]):
                M[ex[e] + i, g] += (dl[i] - Db[ex[e] + i]) / hk
            ul[k] = ub[g]
    for i in range(nx):
        xt[i] = x[i]
    for e0 in range(E):
        observed = obs[e0] == 1
        for j in range(ex[e0], ex[e0 + 1]):
            hj = FD_REL * max(abs(x[j]), scales[j])
            xt[j] = x[j] + hj
            hj = xt[j] - x[j]
            Pt = Pb
            if observed:  # expressions read e0's observables: parameters at the moved state
                Pt = effective_params(t, xt, P, lay, work)
            for i in range(n + 1):
                col[i] = 0.0
            for i in range(nx):
                J[i, j] = 0.0
            moved = False  # does x_j enter a stamp?  If not, du/dx_j = 0: no solve
            for e in range(E):
                if e != e0 and not (observed and hasx[e] == 1):
                    continue
                stamp_element(e, t, xt, Pt, et, L, ep, ex, eu, ui, eo, io, u, Al, bl, ul, pl, xl, il)
                for i in range(L[e]):
                    r = ui[eu[e] + i]
                    if r < n:
                        acc = -bl[i]
                        for k in range(L[e]):
                            acc += Al[i, k] * ub[ui[eu[e] + k]]
                        d = (acc - rb[eu[e] + i]) / hj
                        if d != 0.0:
                            col[r] += d
                            moved = True
                if S[e] > 0 and e == e0 and an[e] == 1:  # its own state: the kernel's partials
                    for i in range(S[e]):
                        J[ex[e] + i, j] += Jxs[ex[e] + i, j - ex[e0]]
                elif S[e] > 0:
                    for i in range(L[e]):
                        ul[i] = ub[ui[eu[e] + i]]
                    load_element(e, xt, Pt, ep, ex, eo, io, pl, xl, il)
                    elem_derivs(et[e], pl, xl, ul, t, il, dl)
                    for i in range(S[e]):
                        J[ex[e] + i, j] += (dl[i] - Db[ex[e] + i]) / hj
            if moved:
                lu_apply(A, piv, col, n)  # -du/dx_j
                for i in range(nx):
                    acc = J[i, j]
                    for g in range(n):
                        acc -= M[i, g] * col[g]
                    J[i, j] = acc
            xt[j] = x[j]
    return 0


# inlined (numba IR) into integrate_batch, its one caller: numba links a callee's machine code into
# every caller and LLVM optimises it again there, so each call level costs compile time
@njit(cache=True, nogil=True, inline="always")
def jacobian_into(t, x, f0, P, lay, work, jw, scales, J, ft, xt, ftmp, autonomous, local):
    """Jacobian J (nx, nx) and df/dt ft (nx,) at (t, x) with f0 = f(t, x): element-local
    (local_jacobian_into; ``local`` 1: with the kernels' analytic partials where they have
    them, 2: differences only) when ``local`` and it applies, otherwise forward differences of
    whole right-hand sides; ft by a forward difference in t (ft = 0 without an evaluation
    when the circuit is autonomous).
    Returns the number of right-hand-side evaluations, or -1 if one failed (singular nodal
    system)."""
    nx = x.shape[0]
    nev = 0
    if local == 0 or local_jacobian_into(t, x, P, lay, work, jw, scales, J, xt, local == 1) < 0:
        for i in range(nx):
            xt[i] = x[i]
        for j in range(nx):
            hj = FD_REL * max(abs(x[j]), scales[j])
            xt[j] = x[j] + hj
            hj = xt[j] - x[j]
            if not rhs_into(t, xt, P, lay, work, ftmp):
                return -1
            for i in range(nx):
                J[i, j] = (ftmp[i] - f0[i]) / hj
            xt[j] = x[j]
        nev = nx
    if autonomous:
        return nev
    ht = FD_REL * max(abs(t), 1.0)
    if not rhs_into(t + ht, x, P, lay, work, ftmp):
        return -1
    for i in range(nx):
        ft[i] = (ftmp[i] - f0[i]) / ht
    return nev + 1


@njit(cache=True, nogil=True)
def jacobian(t, x, P, lay, scales, local):
    """State Jacobian (nx, nx) at (t, x) (allocating; for tests and single calls): element-local
    if ``local`` (1: with the kernels' analytic partials, 2: differences only; where it
    applies), else (0) whole right-hand sides differenced."""
    nx = x.shape[0]
    work = make_work(lay)
    jw = make_jac_work(lay)
    prepare_static(t, x, P, lay, work)
    f0 = np.empty(nx)
    rhs_into(t, x, P, lay, work, f0)
    J = np.zeros((nx, nx))
    jacobian_into(t, x, f0, P, lay, work, jw, scales, J, np.zeros(nx), np.empty(nx), np.empty(nx), True, local)
    return J


@njit(cache=True, nogil=True, internal=True, _nrt=False)
def lu_factor(W, piv, m):
    """In-place LU with partial pivoting of the leading m x m block of W; False if singular.
    (The nodal system uses it with m = n, leaving out the ground slot; the integrator's W
    matrix with m = nx.)"""
    return lu_factor_at(W, piv, m) < 0


@njit(cache=True, nogil=True, internal=True, _nrt=False)
def lu_factor_at(W, piv, m):
    """lu_factor, returning -1 on success or the column where no nonzero pivot was left."""
    for c in range(m):
        p = c
        best = abs(W[c, c])
        for r in range(c + 1, m):
            v = abs(W[r, c])
            if v > best:
                best, p = v, r
        piv[c] = p
        if best == 0.0:
            return c
        if p != c:
            for j in range(m):
                tmp = W[c, j]
                W[c, j] = W[p, j]
                W[p, j] = tmp
        inv = 1.0 / W[c, c]
        for r in range(c + 1, m):
            W[r, c] *= inv
            f = W[r, c]
            if f != 0.0:
                for j in range(c + 1, m):
                    W[r, j] -= f * W[c, j]
    return -1


@njit(cache=True, nogil=True, internal=True, _nrt=False)
def lu_apply(W, piv, v, m):
    """Solve with the factors of lu_factor (size m), in place on v[:m]."""
    for c in range(m):
        p = piv[c]
        if p != c:
            tmp = v[c]
            v[c] = v[p]
            v[p] = tmp
    for i in range(m):
        s = v[i]
        for j in range(i):
            s -= W[i, j] * v[j]
        v[i] = s
    for i in range(m - 1, -1, -1):
        s = v[i]
        for j in range(i + 1, m):
            s -= W[i, j] * v[j]
        v[i] = s / W[i, i]


@njit(cache=True, nogil=True, internal=True, _nrt=False)
def hermite(x0, f0, x1, f1, h, s, out):
    a = (1 + 2 * s) * (1 - s) ** 2
    b = s * (1 - s) ** 2 * h
    c = s * s * (3 - 2 * s)
    d = s * s * (s - 1) * h
    for i in range(x0.shape[0]):
        out[i] = a * x0[i] + b * f0[i] + c * x1[i] + d * f1[i]


@njit(cache=True, nogil=True, internal=True, _nrt=False)
def stage_dense(x0, x1, D, nd, s, out):
    """The method's own dense output (tableaus module docstring): (1 - s) x0 +
    s (x1 + (1 - s) (D_0 + s (D_1 + s D_2))), rows of D past nd zero."""
    for i in range(x0.shape[0]):
        p = 0.0
        for m in range(nd - 1, -1, -1):
            p = D[m, i] + s * p
        out[i] = (1 - s) * x0[i] + s * (x1[i] + (1 - s) * p)


@njit(cache=True, nogil=True, internal=True, _nrt=False)
def hermite_root(y0, d0, y1, d1):
    """First fraction s in [0, 1] where the cubic (values y0 > 0 >= y1, scaled slopes d0, d1)
    crosses zero (bisection, 50 halvings)."""
    lo = 0.0
    hi = 1.0
    for _ in range(50):
        m = 0.5 * (lo + hi)
        v = (1 + 2 * m) * (1 - m) ** 2 * y0 + m * (1 - m) ** 2 * d0 + m * m * (3 - 2 * m) * y1 + m * m * (m - 1) * d1
        if v > 0:
            lo = m
        else:
            hi = m
    return hi


@njit(cache=True, nogil=True)
def integrate_batch(t_out_all, X0, P_all, lay, scales, lim_i, lim_b, lim_r, breaks_all, bjump_all, rtol, atol, h0,
                    hmax_all, max_steps, tab):
    """Integrate each member m from t_out[m, 0] to t_out[m, -1], writing its states at every t_out[m] into
    out[m] (t_out (B, T), X0 (B, nx), P (B, nP), hmax (B,), breaks and bjump (B, K): each member's
    breakpoints, padded with +inf) -> (out (B, T, nx), stats (B, 6): status, t reached, steps, rejected
    steps, f evaluations, limit events).  One member's run:

    Integrate from t_out[0] to t_out[-1], writing the states at every t_out into out (T, nx).

    Hard limits (lim_i, lim_b, lim_r): state lim_i[k] may not fall below lim_b[k]; at the
    crossing (located on the step's cubic Hermite interpolant) the state is put on the bound
    and state lim_r[k] (if >= 0) is reset to max(., 0); the next step starts from the size of
    the step that hit the bound (tab[4] = 1), not from the shortened one.  Steps end exactly on
    ``breaks`` (discontinuities of sources, sorted), where f is re-evaluated unless
    ``bjump[k]`` = 0: a slope-only kink (a pwl table's time), where the source's value and so
    f are continuous, the step ends but f(t-) serves as f(t+) (one evaluation less per kink);
    where f does not jump the Jacobian is kept (tab[5] = 1).
    ``tab``: the method (hemocircuit.kernels.tableaus.packed).
    Its stats row (finish_member): (status, t reached, steps, rejected steps, f evaluations,
    limit events), rows not reached NaN; status 0 done, -1 step size too small, -2 step limit, -3 non-finite state or singular system.

    One function, not a per-member function called (or inlined) here: numba's IR inlining deep-copies
    the callee's blocks, each with a copy of the whole scope (5.6 s of a first compilation), and a
    separate function is compiled, linked and code-generated once more (docs/performance.md, session 11)."""
    B = X0.shape[0]
    out_all = np.empty((B, t_out_all.shape[1], X0.shape[1]))
    stats = np.zeros((B, 6))
    for mb in range(B):
        t_out = t_out_all[mb]
        x0 = X0[mb]
        P = P_all[mb]
        breaks = breaks_all[mb]
        bjump = bjump_all[mb]
        hmax = hmax_all[mb]
        out = out_all[mb]
        nx = x0.shape[0]
        T = t_out.shape[0]
        ns = int(tab[0])
        GAMMA = tab[1]
        q = tab[2]
        JAC_REUSE = int(tab[3])
        ev_restart = tab[4] != 0.0
        soft_kinks = tab[5] != 0.0
        autonomous = tab[6] != 0.0  # no waveform or time-dependent element: df/dt = 0
        local_jac = int(tab[7])  # element-local Jacobian (local_jacobian_into) where it applies: 1 analytic parts, 2 FD
        oA = 8  # offsets of A, G (ns x ns, row major), b, e, c, d, reuse (ns) in tab
        oG = oA + ns * ns
        oB = oG + ns * ns
        oE = oB + ns
        oC = oE + ns
        oD = oC + ns
        oR = oD + ns
        oH = oR + ns
        nd = int(tab[oH])  # dense-output rows (0: cubic Hermite), H at oH + 1 (nd x ns)
        ctrl = tab[oH + 1 + nd * ns]  # step-size controller (tableaus.CONTROLLERS)
        predictive = ctrl != 0.0
        cut_max = 0.9 if ctrl == 1.0 else 0.5  # the largest step after a rejection, of the rejected one
        work = make_work(lay)
        jw = make_jac_work(lay)
        x = x0.copy()
        f = np.empty(nx)
        fn = np.empty(nx)
        xn = np.empty(nx)
        xs = np.empty(nx)
        gs = np.empty(nx)
        err = np.empty(nx)
        K = np.empty((ns, nx))
        Dd = np.zeros((max(nd, 1), nx))
        fr = np.empty(nx)
        J = np.zeros((nx, nx))
        ft = np.zeros(nx)
        W = np.empty((nx, nx))
        piv = np.empty(nx, dtype=np.int64)
        xt = np.empty(nx)
        ftmp = np.empty(nx)
        xh = np.empty(nx)
        t = t_out[0]
        t_end = t_out[-1]
        for i in range(nx):
            out[0, i] = x[i]
        k_out = 1
        nfev = 1
        nsteps = 0
        nrej = 0
        nev = 0
        status = 0
        prepare_static(t, x, P, lay, work)
        if not rhs_into(t, x, P, lay, work, f):
            # no step (the loop below is skipped), and the one finish_member call at the end:
            # a call with constants here would compile a second specialisation of it (numba
            # types the constants as literals)
            status = -3
        h = h0
        age = JAC_REUSE
        ib = 0
        while ib < breaks.shape[0] and breaks[ib] <= t:
            ib += 1
        nrej_run = 0
        err_prev = 1.0
        h_prev = 0.0  # the last accepted step (predictive controller; 0 before the first)
        while status == 0 and t < t_end and k_out < T:
            if nsteps >= max_steps:
                status = -2
                break
            tb = t_end
            if ib < breaks.shape[0] and breaks[ib] < t_end:
                tb = breaks[ib]
            if age >= JAC_REUSE:
                nj = jacobian_into(t, x, f, P, lay, work, jw, scales, J, ft, xt, ftmp, autonomous, local_jac)
                if nj < 0:
                    status = -3
                    break
                nfev += nj
                age = 0
            hh = min(h, hmax)
            at_break = False
            tlim = np.inf  # stages never sample a source on the far side of a breakpoint
            if t + hh >= tb - 1e-12 * max(1.0, abs(tb)):
                hh = tb - t
                at_break = True
                tlim = tb - 1e-13 * max(1.0, abs(tb))
                if hh <= 1e-12 * max(1.0, abs(tb)):  # already there (to rounding): cross it
                    t = tb
                    if tb < t_end:
                        ib += 1
                    nfev += 1
                    if not rhs_into(t, x, P, lay, work, f):
                        status = -3
                        break
                    age = JAC_REUSE
                    continue
            for i in range(nx):
                for j in range(nx):
                    W[i, j] = -GAMMA * hh * J[i, j]
                W[i, i] += 1.0
            if not lu_factor(W, piv, nx):
                h = 0.25 * hh
                age = JAC_REUSE
                nrej += 1
                nsteps += 1
                if h < 1e-14 * max(1.0, abs(t)):
                    status = -1
                    break
                continue
            good = True
            for s in range(ns):
                for i in range(nx):
                    xs[i] = x[i]
                    gs[i] = 0.0
                for j in range(s):
                    a_sj = tab[oA + s * ns + j]
                    g_sj = tab[oG + s * ns + j]
                    if a_sj != 0.0:
                        for i in range(nx):
                            xs[i] += a_sj * K[j, i]
                    if g_sj != 0.0:
                        for i in range(nx):
                            gs[i] += g_sj * K[j, i]
                if s == 0:
                    for i in range(nx):
                        fn[i] = f[i]
                elif tab[oR + s] == 0.0:  # else: same point as stage s-1, fn holds its f
                    nfev += 1
                    if not rhs_into(min(t + tab[oC + s] * hh, tlim), xs, P, lay, work, fn):
                        good = False
                        break
                d_s = tab[oD + s]
                for i in range(nx):
                    acc = 0.0
                    for j in range(nx):
                        acc += J[i, j] * gs[j]
                    K[s, i] = hh * fn[i] + hh * acc + hh * hh * d_s * ft[i]
                lu_apply(W, piv, K[s], nx)
            enorm = np.inf
            if good:
                enorm = 0.0
                for i in range(nx):
                    xi = x[i]
                    e = 0.0
                    for s in range(ns):
                        xi += tab[oB + s] * K[s, i]
                        e += tab[oE + s] * K[s, i]
                    xn[i] = xi
                    sc = atol[i] + rtol * max(abs(x[i]), abs(xn[i]))
                    enorm += (e / sc) ** 2
                enorm = np.sqrt(enorm / nx)
                if not np.isfinite(enorm):
                    enorm = np.inf
            nsteps += 1
            if enorm <= 1.0:
                # step-size control (tableaus.CONTROLLERS): Gustafsson's predictive rule or his PI rule
                en = max(enorm, 1e-10)
                if predictive:
                    fac = min(6.0, max(0.2, 0.9 * en ** (-1.0 / q)))
                    if h_prev > 0.0:
                        fac = min(fac, max(0.2, min(6.0, 0.9 * (hh / h_prev) * (err_prev / (en * en)) ** (1.0 / q))))
                    h_prev = hh
                    err_prev = max(en, 1e-2)
                else:
                    fac = 0.9 * en ** (-0.7 / q) * err_prev ** (0.4 / q)
                    fac = min(5.0, max(0.2, fac))
                    err_prev = max(en, 1e-4)
                if nrej_run > 0:  # just after a rejection: no growth (Hairer & Wanner's facmax = 1)
                    fac = min(fac, 1.0)
                tn = tb if at_break else t + hh
                nfev += 1
                ok = rhs_into(min(tn, tlim), xn, P, lay, work, fn)  # left limit at a breakpoint
                # hard limits: end the step at the earliest crossing
                s_hit = 2.0
                k_hit = -1
                held = False
                for k in range(lim_i.shape[0]):
                    li = lim_i[k]
                    # within LIMIT_ON_BOUND x atol of the bound counts as on it: a state that sits
                    # there to rounding (an operating point's closed valve, Q = 3e-16 mL/s) would
                    # otherwise be "crossed" at s ~ 0 by every step, which then advances t by
                    # ~1e-21 s (closedLoopHeart_singleVessel: 10 million steps, 3 minutes)
                    on_bound = x[li] <= lim_b[k] + LIMIT_ON_BOUND * atol[li]
                    if xn[li] < lim_b[k] and on_bound:
                        # already on the bound (just reset): hold it there, as the floor means,
                        # instead of locating the same crossing again at s ~ 0 every step
                        xn[li] = lim_b[k]
                        if lim_r[k] >= 0:
                            xn[lim_r[k]] = max(xn[lim_r[k]], 0.0)
                        held = True
                        continue
                    if xn[li] < lim_b[k] and not on_bound:
                        sk = hermite_root(x[li] - lim_b[k], f[li] * hh, xn[li] - lim_b[k], fn[li] * hh)
                        if sk < s_hit:
                            s_hit, k_hit = sk, k
                h_full = hh
                if k_hit >= 0:
                    hermite(x, f, xn, fn, hh, s_hit, xh)
                    for i in range(nx):
                        xn[i] = xh[i]
                    xn[lim_i[k_hit]] = lim_b[k_hit]
                    if lim_r[k_hit] >= 0:
                        xn[lim_r[k_hit]] = max(xn[lim_r[k_hit]], 0.0)
                    hh = s_hit * hh
                    tn = t + hh
                    at_break = False
                    nfev += 1
                    ok = rhs_into(tn, xn, P, lay, work, fn)
                    age = JAC_REUSE
                    nev += 1
                elif held:
                    nfev += 1
                    ok = rhs_into(min(tn, tlim), xn, P, lay, work, fn)
                if not ok:
                    status = -3
                    break
                # dense output: the method's own where it has one and the step is whole (no
                # bound hit or hold changed its end), else cubic Hermite of (t, x, f), (tn, xn, fn)
                own = nd > 0 and k_hit < 0 and not held
                if own and k_out < T and t_out[k_out] <= tn + 1e-12 * max(1.0, abs(tn)):
                    for m in range(nd):
                        for i in range(nx):
                            acc = 0.0
                            for s in range(ns):
                                acc += tab[oH + 1 + m * ns + s] * K[s, i]
                            Dd[m, i] = acc
                while k_out < T and t_out[k_out] <= tn + 1e-12 * max(1.0, abs(tn)):
                    sfrac = (t_out[k_out] - t) / hh if hh > 0 else 1.0
                    sfrac = min(1.0, max(0.0, sfrac))
                    if own:
                        stage_dense(x, xn, Dd, nd, sfrac, xh)
                    else:
                        hermite(x, f, xn, fn, hh, sfrac, xh)
                    for i in range(nx):
                        out[k_out, i] = xh[i]
                    # a limited state's steps respect its bound; the interpolant between two of
                    # them may dip below it by its error (the heart's valve flows: -2e-10 mL/s)
                    for k in range(lim_i.shape[0]):
                        out[k_out, lim_i[k]] = max(out[k_out, lim_i[k]], lim_b[k])
                    k_out += 1
                t = tn
                for i in range(nx):
                    x[i] = xn[i]
                    f[i] = fn[i]
                h = hh * fac if not at_break else max(h, hh * fac)
                if k_hit >= 0 and ev_restart:
                    # restart after the reset from the step that reached the bound: the shortened
                    # step (s_hit x hh, often tiny) says nothing about the dynamics after the reset
                    h = max(h, h_full * fac)
                if at_break and tb < t_end and bjump[ib] == 0.0:  # a kink: f is continuous here
                    ib += 1
                elif at_break and tb < t_end:  # the source may jump here: continue from its right limit
                    ib += 1
                    nfev += 1
                    if not rhs_into(t, x, P, lay, work, fr):
                        status = -3
                        break
                    jump = not soft_kinks
                    for i in range(nx):
                        # a jump of f that moves x by more than 1e-3 of its tolerance over the next
                        # step is a value discontinuity (new Jacobian); less is a slope-only kink
                        if abs(fr[i] - f[i]) * h > 1e-3 * (atol[i] + rtol * abs(x[i])):
                            jump = True
                        f[i] = fr[i]
                    if jump:
                        age = JAC_REUSE
                age += 1
                nrej_run = 0
            else:
                nrej += 1
                if np.isfinite(enorm):
                    fac = 0.9 * enorm ** (-1.0 / q)
                    h = hh * min(cut_max, max(0.2, fac))
                else:
                    h = 0.25 * hh
                nrej_run += 1
                if nrej_run >= 2 and age > 0:  # a second rejection in a row: the Jacobian is stale
                    age = JAC_REUSE
                if h < 1e-14 * max(1.0, abs(t)):
                    status = -1
                    break
        finish_member(out, k_out, stats, mb, status, t, nsteps, nrej, nfev, nev)
    return out_all, stats


# --- Variable-order BDF (NDF) integrator: the method of scipy's solve_ivp 'BDF' (Shampine &
# Reichelt 1997, SIAM J Sci Comput 18:1; quasi-constant step with the difference array D,
# orders 1-5, NDF coefficients kappa), compiled.  Its Jacobian is kept over many steps and only
# refreshed when Newton's iteration fails to converge: about 2 right-hand sides per step (two
# Newton iterations: the test needs a contraction rate), against the Rosenbrock method's 8
# plus a Jacobian.
BDF_MAX_ORDER = 5
BDF_NEWTON_MAXITER = 4
#: Newton's convergence test of a BDF step: the estimated distance to the solution, in the
#: error test's norm (atol + rtol |y|), below this.  scipy (after Hairer's RADAU5) takes
#: min(0.03, sqrt(rtol)), 1e-4 at rtol 1e-8, which cost freq's forced runs 2.8 right-hand
#: sides a step (Newton's iterations and ~0.15 for Jacobians); CVODE's is 0.1 of its error
#: test (nlscoef) at every rtol.  0.03 (or the round-off floor 10 eps/rtol, larger below
#: rtol 7e-14): 2.0 a step, a forced run's integration 27 % less time, freq's error against
#: a roadrunner rtol 1e-11 reference 6.2e-6 / 2.3e-4 deg against 6.0e-6 / 2.2e-4
#: (docs/performance.md, session 16)
BDF_NEWTON_TOL = 0.03
BDF_MIN_FACTOR = 0.2
BDF_MAX_FACTOR = 10.0


@njit(cache=True, nogil=True, internal=True, _nrt=False)
def bdf_compute_R(order, factor, R):
    """R = cumprod over rows of M (scipy bdf.compute_R) into R[:order+1, :order+1]."""
    for j in range(order + 1):
        R[0, j] = 1.0
    for i in range(1, order + 1):
        R[i, 0] = 0.0
        for j in range(1, order + 1):
            R[i, j] = R[i - 1, j] * (i - 1 - factor * j) / i


@njit(cache=True, nogil=True, internal=True, _nrt=False)
def bdf_change_D(D, order, factor, R, U, tmp):
    """Rescale the difference array D for a step changed by ``factor`` (scipy bdf.change_D):
    D[:order+1] = (R U)^T D[:order+1]."""
    bdf_compute_R(order, factor, R)
    bdf_compute_R(order, 1.0, U)
    nx = D.shape[1]
    for i in range(order + 1):  # tmp = (R U)^T D, row i: sum_k (RU)[k, i] D[k]
        for c in range(nx):
            tmp[i, c] = 0.0
        for k in range(order + 1):
            ru = 0.0
            for m in range(order + 1):
                ru += R[k, m] * U[m, i]
            if ru != 0.0:
                for c in range(nx):
                    tmp[i, c] += ru * D[k, c]
    for i in range(order + 1):
        for c in range(nx):
            D[i, c] = tmp[i, c]


@njit(cache=True, nogil=True, internal=True, _nrt=False)
def bdf_dense(D, order, t_new, h, tq, y, p):
    """The step's interpolating polynomial at tq (scipy BdfDenseOutput) into y."""
    acc = 1.0
    for k in range(order):
        acc *= (tq - (t_new - h * k)) / (h * (1 + k))
        p[k] = acc
    for c in range(y.shape[0]):
        v = D[0, c]
        for k in range(order):
            v += D[k + 1, c] * p[k]
        y[c] = v


@njit(cache=True, nogil=True, internal=True, _nrt=False)
def bdf_newton(t_new, ypred, c, psi, W, piv, scale, tol, P, lay, work, y, d, f, dy):
    """Newton's iteration of one BDF step (scipy bdf.solve_bdf_system).  Returns the number of
    iterations, negative when it did not converge."""
    nx = y.shape[0]
    for i in range(nx):
        y[i] = ypred[i]
        d[i] = 0.0
    dy_norm_old = -1.0
    for k in range(BDF_NEWTON_MAXITER):
        if not rhs_into(t_new, y, P, lay, work, f):
            return -(k + 1)
        for i in range(nx):
            dy[i] = c * f[i] - psi[i] - d[i]
        lu_apply(W, piv, dy, nx)
        s = 0.0
        for i in range(nx):
            s += (dy[i] / scale[i]) ** 2
        dy_norm = np.sqrt(s / nx)
        if not np.isfinite(dy_norm):
            return -(k + 1)
        rate = dy_norm / dy_norm_old if dy_norm_old > 0.0 else -1.0
        if rate >= 0.0 and (rate >= 1.0 or rate ** (BDF_NEWTON_MAXITER - k) / (1.0 - rate) * dy_norm > tol):
            return -(k + 1)
        for i in range(nx):
            y[i] += dy[i]
            d[i] += dy[i]
        if dy_norm == 0.0 or (rate >= 0.0 and rate / (1.0 - rate) * dy_norm < tol):
            return k + 1
        dy_norm_old = dy_norm
    return -BDF_NEWTON_MAXITER


@njit(cache=True, nogil=True)
def integrate_batch_bdf(t_out_all, X0, P_all, lay, scales, lim_i, lim_b, lim_r, breaks_all, rtol, atol, h0, hmax_all,
                        max_steps, local_jac):
    """integrate_batch with the variable-order BDF method, each member on its own (breaks (B, K)):
    (out (B, T, nx), stats (B, 6)).  (A separate entry point, not a method flag of integrate_batch:
    numba compiles, per process, only the integrator used; one function, as integrate_batch.)
    One member's run:

    As integrate_batch's (same arguments except the tableau, same outputs and status codes),
    with the variable-order BDF method.  Breakpoints end a step exactly and restart the
    method at order 1 (the source may jump there); a hard limit crossed within a step is
    located on the step's interpolating polynomial, the state put on the bound (its rate
    state reset to max(., 0)) and the method restarted from there with the same step size;
    a state held on its bound keeps a constant history (its differences zeroed)."""
    B = X0.shape[0]
    out_all = np.empty((B, t_out_all.shape[1], X0.shape[1]))
    stats = np.zeros((B, 6))
    for mb in range(B):
        t_out = t_out_all[mb]
        x0 = X0[mb]
        P = P_all[mb]
        breaks = breaks_all[mb]
        hmax = hmax_all[mb]
        out = out_all[mb]
        nx = x0.shape[0]
        T = t_out.shape[0]
        work = make_work(lay)
        jw = make_jac_work(lay)
        x = x0.copy()
        f = np.empty(nx)
        fp = np.empty(nx)
        J = np.zeros((nx, nx))
        W = np.empty((nx, nx))
        piv = np.empty(nx, dtype=np.int64)
        D = np.zeros((BDF_MAX_ORDER + 3, nx))
        R = np.zeros((BDF_MAX_ORDER + 1, BDF_MAX_ORDER + 1))
        U = np.zeros((BDF_MAX_ORDER + 1, BDF_MAX_ORDER + 1))
        tmp = np.zeros((BDF_MAX_ORDER + 1, nx))
        pw = np.zeros(BDF_MAX_ORDER)
        ypred = np.empty(nx)
        psi = np.empty(nx)
        ynew = np.empty(nx)
        d = np.empty(nx)
        dy = np.empty(nx)
        scale = np.empty(nx)
        yq = np.empty(nx)
        xt = np.empty(nx)
        ftmp = np.empty(nx)
        ft = np.zeros(nx)
        gam = np.zeros(BDF_MAX_ORDER + 2)
        alp = np.zeros(BDF_MAX_ORDER + 2)
        ecst = np.zeros(BDF_MAX_ORDER + 2)
        kappa = np.array([0.0, -0.1850, -1.0 / 9.0, -0.0823, -0.0415, 0.0])
        for k in range(1, BDF_MAX_ORDER + 1):
            gam[k] = gam[k - 1] + 1.0 / k
        for k in range(BDF_MAX_ORDER + 1):
            alp[k] = (1.0 - kappa[k]) * gam[k]
            ecst[k] = kappa[k] * gam[k] + 1.0 / (k + 1)
        newton_tol = max(10.0 * 2.220446049250313e-16 / rtol, BDF_NEWTON_TOL)
        t = t_out[0]
        t_end = t_out[-1]
        for i in range(nx):
            out[0, i] = x[i]
        k_out = 1
        prepare_static(t, x, P, lay, work)
        nfev = 1
        if not rhs_into(t, x, P, lay, work, f):
            finish_member(out, 1, stats, mb, -3, t, 0, 0, nfev, 0)
            continue
        nj = jacobian_into(t, x, f, P, lay, work, jw, scales, J, ft, xt, ftmp, True, local_jac)
        if nj < 0:
            finish_member(out, 1, stats, mb, -3, t, 0, 0, nfev, 0)
            continue
        nfev += nj
        jac_current = True
        h = min(h0, hmax)
        restart = True
        order = 1
        n_equal = 0
        lu_valid = False
        nsteps = 0
        nrej = 0
        nev = 0
        error_norm = 1.0
        safety = 0.9
        ib = 0
        while ib < breaks.shape[0] and breaks[ib] <= t:
            ib += 1
        status = 0
        while t < t_end and k_out < T:
            if nsteps >= max_steps:
                status = -2
                break
            if restart:  # order 1 from (t, x, f): the start, after a breakpoint or a reset at a bound
                for k in range(D.shape[0]):
                    for i in range(nx):
                        D[k, i] = 0.0
                for i in range(nx):
                    D[0, i] = x[i]
                    D[1, i] = h * f[i]
                order = 1
                n_equal = 0
                lu_valid = False
                restart = False
            tb = t_end
            if ib < breaks.shape[0] and breaks[ib] < t_end:
                tb = breaks[ib]
            min_step = 10.0 * (np.nextafter(t, np.inf) - t)
            if h > hmax:
                bdf_change_D(D, order, hmax / h, R, U, tmp)
                h = hmax
                n_equal = 0
                lu_valid = False
            elif h < min_step:
                bdf_change_D(D, order, min_step / h, R, U, tmp)
                h = min_step
                n_equal = 0
                lu_valid = False
            accepted = False
            n_iter = 0
            t_new = t
            h_free = h  # the step before a breakpoint shortens it: the restart after takes it up again
            while not accepted:
                if h < min_step:
                    status = -1
                    break
                t_new = t + h
                if t_new >= tb - 1e-12 * max(1.0, abs(tb)):
                    t_new = tb
                    bdf_change_D(D, order, (t_new - t) / h, R, U, tmp)
                    n_equal = 0
                    lu_valid = False
                h = t_new - t
                for i in range(nx):
                    acc = 0.0
                    ps = 0.0
                    for k in range(order + 1):
                        acc += D[k, i]
                    for k in range(1, order + 1):
                        ps += D[k, i] * gam[k]
                    ypred[i] = acc
                    psi[i] = ps / alp[order]
                    scale[i] = atol[i] + rtol * abs(acc)
                c = h / alp[order]
                n_iter = 0
                while True:
                    if not lu_valid:
                        for i in range(nx):
                            for j in range(nx):
                                W[i, j] = -c * J[i, j]
                            W[i, i] += 1.0
                        lu_valid = lu_factor(W, piv, nx)
                    if lu_valid:
                        n_iter = bdf_newton(t_new, ypred, c, psi, W, piv, scale, newton_tol, P, lay, work, ynew, d,
                                            fp, dy)
                        nfev += abs(n_iter)
                        if n_iter > 0:
                            break
                    if jac_current:
                        break
                    # Newton failed with an older Jacobian: a new one at the predicted state
                    nfev += 1
                    if not rhs_into(t_new, ypred, P, lay, work, ftmp):
                        break
                    nj = jacobian_into(t_new, ypred, ftmp, P, lay, work, jw, scales, J, ft, xt, fp, True, local_jac)
                    if nj < 0:
                        break
                    nfev += nj
                    jac_current = True
                    lu_valid = False
                if n_iter <= 0:  # not converged: halve the step
                    h *= 0.5
                    bdf_change_D(D, order, 0.5, R, U, tmp)
                    n_equal = 0
                    lu_valid = False
                    nrej += 1
                    nsteps += 1
                    continue
                safety = 0.9 * (2 * BDF_NEWTON_MAXITER + 1) / (2 * BDF_NEWTON_MAXITER + n_iter)
                s = 0.0
                for i in range(nx):
                    scale[i] = atol[i] + rtol * abs(ynew[i])
                    s += (ecst[order] * d[i] / scale[i]) ** 2
                error_norm = np.sqrt(s / nx)
                if error_norm > 1.0 or not np.isfinite(error_norm):
                    factor = BDF_MIN_FACTOR
                    if np.isfinite(error_norm):
                        factor = max(BDF_MIN_FACTOR, safety * error_norm ** (-1.0 / (order + 1)))
                    h *= factor
                    bdf_change_D(D, order, factor, R, U, tmp)
                    n_equal = 0
                    nrej += 1
                    nsteps += 1
                else:
                    accepted = True
            if status != 0:
                break
            nsteps += 1
            n_equal += 1
            jac_current = False
            # the differences of the new polynomial (scipy: D^{j+1} y_n = D^j y_n - D^j y_{n-1})
            for i in range(nx):
                D[order + 2, i] = d[i] - D[order + 1, i]
                D[order + 1, i] = d[i]
            for k in range(order, -1, -1):
                for i in range(nx):
                    D[k, i] += D[k + 1, i]
            # hard limits: the earliest crossing within the step, on its polynomial
            t_hit = np.inf
            k_hit = -1
            for k in range(lim_i.shape[0]):
                li = lim_i[k]
                # on the bound to LIMIT_ON_BOUND x atol: held below, not located (see integrate_batch)
                if D[0, li] < lim_b[k] and x[li] > lim_b[k] + LIMIT_ON_BOUND * atol[li]:
                    lo = t
                    hi = t_new
                    for _ in range(60):
                        mid = 0.5 * (lo + hi)
                        bdf_dense(D, order, t_new, h, mid, yq, pw)
                        if yq[li] > lim_b[k]:
                            lo = mid
                        else:
                            hi = mid
                    if hi < t_hit:
                        t_hit, k_hit = hi, k
            tn = t_new if k_hit < 0 else t_hit
            while k_out < T and t_out[k_out] <= tn + 1e-12 * max(1.0, abs(tn)):
                bdf_dense(D, order, t_new, h, min(t_out[k_out], tn), yq, pw)
                for i in range(nx):
                    out[k_out, i] = yq[i]
                for k in range(lim_i.shape[0]):  # as integrate_batch's: on or above a bound
                    out[k_out, lim_i[k]] = max(out[k_out, lim_i[k]], lim_b[k])
                k_out += 1
            if k_hit >= 0:  # on the bound, its rate reset; restart from there with the same step
                bdf_dense(D, order, t_new, h, t_hit, yq, pw)
                for i in range(nx):
                    x[i] = yq[i]
                x[lim_i[k_hit]] = lim_b[k_hit]
                if lim_r[k_hit] >= 0:
                    x[lim_r[k_hit]] = max(x[lim_r[k_hit]], 0.0)
                t = t_hit
                nev += 1
                nfev += 1
                if not rhs_into(t, x, P, lay, work, f):
                    status = -3
                    break
                restart = True
                continue
            # a state held on its bound (already there, pushed below): constant, its rate reset
            for k in range(lim_i.shape[0]):
                li = lim_i[k]
                if D[0, li] < lim_b[k] and x[li] <= lim_b[k] + LIMIT_ON_BOUND * atol[li]:
                    D[0, li] = lim_b[k]
                    for m in range(1, D.shape[0]):
                        D[m, li] = 0.0
                    r = lim_r[k]
                    if r >= 0 and D[0, r] < 0.0:
                        D[0, r] = 0.0
                        for m in range(1, D.shape[0]):
                            D[m, r] = 0.0
            t = t_new
            for i in range(nx):
                x[i] = D[0, i]
            if t >= tb - 1e-12 * max(1.0, abs(tb)) and tb < t_end:  # a breakpoint: restart from its right limit
                t = tb
                ib += 1
                h = max(h, h_free)
                nfev += 1
                if not rhs_into(t, x, P, lay, work, f):
                    status = -3
                    break
                restart = True
                continue
            if n_equal < order + 1:
                continue
            # order and step size for the next step (scipy's rule)
            em = np.inf
            ep = np.inf
            s_m = 0.0
            s_p = 0.0
            for i in range(nx):  # scale: that of the step's error test (atol + rtol |y_new|)
                if order > 1:
                    s_m += (ecst[order - 1] * D[order, i] / scale[i]) ** 2
                if order < BDF_MAX_ORDER:
                    s_p += (ecst[order + 1] * D[order + 2, i] / scale[i]) ** 2
            if order > 1:
                em = np.sqrt(s_m / nx)
            if order < BDF_MAX_ORDER:
                ep = np.sqrt(s_p / nx)
            f_m = em ** (-1.0 / order) if em > 0.0 else np.inf
            f_0 = error_norm ** (-1.0 / (order + 1)) if error_norm > 0.0 else np.inf
            f_p = ep ** (-1.0 / (order + 2)) if ep > 0.0 else np.inf
            best = f_0
            delta = 0
            if f_m > best:
                best = f_m
                delta = -1
            if f_p > best:
                best = f_p
                delta = 1
            order += delta
            factor = min(BDF_MAX_FACTOR, safety * best)
            h *= factor
            bdf_change_D(D, order, factor, R, U, tmp)
            n_equal = 0
            lu_valid = False
        finish_member(out, k_out, stats, mb, status, t, nsteps, nrej, nfev, nev)
    return out_all, stats


