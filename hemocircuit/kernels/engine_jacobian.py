# Engine template, part 2 of 4: the state Jacobian.  NOT imported on its own (kernels.codegen
# appends it after engine_nodal.py, whose functions it calls).
#
# Element-local (local_jacobian_into_at: each element's derivatives differenced, or taken from its
# kernel's derivs_jac, composed through the nodal solve) or whole right-hand sides differenced
# (jacobian_into), and df/dt for non-autonomous circuits.  The step rule is FD_REL
# (hemocircuit.derivatives): relative to max(|x|, the state's scale).

#: The scratch arrays of local_jacobian_into_at (make_jac_work), by name.  nu = the number of
#: local unknowns of all elements (ui), Lm / Sm the largest element's local unknowns and states.
JacWork = namedtuple("JacWork", (
    "Pb",          # (nP,) the base parameters (effective, at x)
    "A",           # (n+1, n+1) the full nodal matrix, then its LU
    "piv",         # (n+1,) int: its pivots
    "ub",          # (n+1,) the base unknowns u
    "rb",          # (nu,) the base local residuals (at the eu offsets)
    "M",           # (nx, n+1) dD/du
    "col",         # (n+1,) one column dR/dx_j
    "Db",          # (nx,) the base derivatives
    "Ab",          # (nu, Lm) the elements' local matrices (at the eu offsets)
    "bb",          # (nu,) their local right-hand sides
    "has_expr",    # (E,) int: 1 if the element has an expression parameter (layout only)
    "observed",    # (E,) int: 1 if expressions read the element's observables (layout only)
    "analytic",    # (E,) int: 1 if its partials came from its kernel's derivs_jac at this call
    "Jxs",         # (nx, Sm) those partials d dx / d x_own (at the ex offsets)
    "Jx",          # (Sm, Sm) one element's d dx / d x (derivs_jac's Jx)
    "Ju",          # (Sm, Lm) one element's d dx / d u (derivs_jac's Ju)
    "C",           # (n+1, nx+1) the columns dR/dx_j that move a stamp, and dR/dt, side by side
    "cj",          # (nx+1,) int: the state j of each of those columns (-1: t)
    "MC",          # (nx, nx+1) dD/du times A^-1 times them
))


@njit(cache=True, nogil=True, internal=True)
def make_jac_work(lay):
    """The scratch arrays of local_jacobian_into_at (JacWork)."""
    (n, nx, et, L, S, ep, ex, eu, ui, eo, io, eb, ws, w0, wd, xs, xc, xk, xcode, xconst, oe, nonlin, cm, st, td) = lay
    Lm = 1
    for e in range(et.shape[0]):
        Lm = max(Lm, L[e])
    nu = max(ui.shape[0], 1)
    has_expr = np.zeros(et.shape[0], dtype=np.int64)
    for k in range(xs.shape[0]):
        for e in range(et.shape[0]):
            if ep[e] <= xs[k] < ep[e + 1]:
                has_expr[e] = 1
    observed = np.zeros(et.shape[0], dtype=np.int64)
    if xs.shape[0] > 0:
        for k in range(oe.shape[0]):
            observed[oe[k]] = 1
    Sm = 1
    for e in range(et.shape[0]):
        Sm = max(Sm, S[e])
    return JacWork(Pb=np.zeros(max(ep[-1], 1)), A=np.zeros((n + 1, n + 1)), piv=np.zeros(n + 1, dtype=np.int64),
                   ub=np.zeros(n + 1), rb=np.zeros(nu), M=np.zeros((max(nx, 1), n + 1)), col=np.zeros(n + 1),
                   Db=np.zeros(max(nx, 1)), Ab=np.zeros((nu, Lm)), bb=np.zeros(nu), has_expr=has_expr,
                   observed=observed, analytic=np.zeros(et.shape[0], dtype=np.int64),
                   Jxs=np.zeros((max(nx, 1), Sm)), Jx=np.zeros((Sm, Sm)), Ju=np.zeros((Sm, Lm)),
                   C=np.zeros((n + 1, nx + 1)), cj=np.zeros(nx + 1, dtype=np.int64),
                   MC=np.zeros((max(nx, 1), nx + 1)))


@njit(cache=True, nogil=True, pointer=True, _nrt=False)
def local_jacobian_into_at(t, x, P, lay_ref, work_ref, jw_ref, scales, J, xt, analytic, ft, want_ft):
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
    With ``want_ft`` also df/dt into ft the same way: dR/dt and dD/dt differenced in t over the
    elements that depend on t (td), composed as one more column (instead of a whole
    right-hand side at t + dt).
    Elements nonlinear in the pressures (st 2; nonlin): R is then nonlinear in u, and A is its
    Jacobian dR/du at the nodal solution, which work.u must hold for (t, x) (jacobian_into
    solves it first, unless its last right-hand side was there): such an element's columns of
    dR/du are central differences of its local residual A_e(u) u - b_e(u) in its local unknowns
    (residual_u_columns; whatever linearisation its stamp uses for Newton's iteration), and its
    dR/dx the change of that residual at u fixed.  A valve
    circuit's Jacobian then costs one nodal solve and element stamps instead of one nodal
    Newton solve per state.
    Returns 0, or -1 when it does not apply (a singular nodal matrix): the caller then
    differences whole right-hand sides."""
    lay = lay_ref[0]
    work = work_ref[0]
    jw = jw_ref[0]
    (n, nx, et, L, S, ep, ex, eu, ui, eo, io, eb, ws, w0, wd, xs, xc, xk, xcode, xconst, oe, nonlin, cm, st, td) = lay
    Pb, A, piv, ub, rb, M, col, Db, Ab, bb = jw.Pb, jw.A, jw.piv, jw.ub, jw.rb, jw.M, jw.col, jw.Db, jw.Ab, jw.bb
    C, cj, MC = jw.C, jw.cj, jw.MC
    hasx, obs, an, Jxs, Jxl, Jul = jw.has_expr, jw.observed, jw.analytic, jw.Jxs, jw.Jx, jw.Ju
    u, Al, bl, ul, pl, xl, il, dl, A0, b0 = (work.u, work.Al, work.bl, work.ul, work.pl, work.xl, work.il, work.dl,
                                             work.A0, work.b0)
    E = et.shape[0]
    effective_params_at(t, x, P, lay_ref, work_ref)
    Pe = work.Pe
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
        stamp_element(e, t, x, Pb, lay_ref, work_ref)
        for i in range(L[e]):
            r = ui[eu[e] + i]
            ub[r] += bl[i]
            bb[eu[e] + i] = bl[i]
            for k in range(L[e]):
                Ab[eu[e] + i, k] = Al[i, k]
                if cm[e] == 0 and st[e] != 2:
                    A[r, ui[eu[e] + k]] += Al[i, k]
        if st[e] == 2:
            residual_u_columns(e, t, x, Pb, L, eu, ui, u, A, n, lay_ref, work_ref)
    if not lu_factor(A, piv, n):
        return -1
    if nonlin != 0:  # the solution is work.u (A is Newton's matrix at it, not the system's)
        for i in range(n + 1):
            ub[i] = u[i]
    else:
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
    nm = 0  # columns of dR/dx kept in C (the states that move some stamp)
    for e0 in range(E):
        observed = obs[e0] == 1
        for j in range(ex[e0], ex[e0 + 1]):
            hj = FD_REL * max(abs(x[j]), scales[j])
            xt[j] = x[j] + hj
            hj = xt[j] - x[j]
            Pt = Pb
            if observed:  # expressions read e0's observables: parameters at the moved state
                effective_params_at(t, xt, P, lay_ref, work_ref)
                Pt = work.Pe
            for i in range(n + 1):
                col[i] = 0.0
            for i in range(nx):
                J[i, j] = 0.0
            moved = False  # does x_j enter a stamp?  If not, du/dx_j = 0: no solve
            for e in range(E):
                if e != e0 and not (observed and hasx[e] == 1):
                    continue
                stamp_element(e, t, xt, Pt, lay_ref, work_ref)
                moved |= residual_change(e, L, eu, ui, Al, bl, ub, rb, hj, col, n)
                if S[e] > 0 and e == e0 and an[e] == 1:  # its own state: the kernel's partials
                    for i in range(S[e]):
                        J[ex[e] + i, j] += Jxs[ex[e] + i, j - ex[e0]]
                elif S[e] > 0:
                    derivs_at_base(e, t, xt, Pt, et, L, ep, ex, eu, ui, eo, io, ub, ul, pl, xl, il, dl)
                    for i in range(S[e]):
                        J[ex[e] + i, j] += (dl[i] - Db[ex[e] + i]) / hj
            if moved:
                nm = keep_column(C, cj, col, nm, j, n)
            xt[j] = x[j]
    if want_ft:
        # the time column: FD_REL seconds as represented at t (derivatives.time_step)
        ht = (t + FD_REL) - t
        effective_params_at(t + ht, x, P, lay_ref, work_ref)  # waveforms at t + ht
        Pt = work.Pe
        for i in range(n + 1):
            col[i] = 0.0
        for i in range(nx):
            ft[i] = 0.0
        moved = False
        for e in range(E):
            if td[e] == 0:
                continue
            if st[e] != 1:
                stamp_element(e, t + ht, x, Pt, lay_ref, work_ref)
                moved |= residual_change(e, L, eu, ui, Al, bl, ub, rb, ht, col, n)
            if S[e] > 0:
                derivs_at_base(e, t + ht, x, Pt, et, L, ep, ex, eu, ui, eo, io, ub, ul, pl, xl, il, dl)
                for i in range(S[e]):
                    ft[ex[e] + i] = (dl[i] - Db[ex[e] + i]) / ht
        if moved:
            nm = keep_column(C, cj, col, nm, -1, n)
    if nm > 0:
        compose_columns(A, piv, C, M, MC, cj, J, ft, n, nx, nm)
    return 0


#: central-difference step (relative to max(|u|, 1)) of an element's local unknowns in dR/du
#: for elements nonlinear in the pressures: a tanh valve switches within 1/k (their
#: chamber_elastance_inductor: 7.5e-6 mmHg), so a forward step of FD_REL (1e-7 mmHg) would be 1 %
#: of the switch; central at 1e-10 leaves truncation ~(1e-10 k)^2 and rounding ~1e-6 relative
U_STEP_REL = 1e-10


@njit(cache=True, nogil=True, inline="always")
def residual_u_columns(e, t, x, Pb, L, eu, ui, u, A, n, lay_ref, work_ref):
    """Add d r_e / d u of element e (nonlinear in the pressures) into A: central differences of
    its local residual r_e(u) = A_e(u) u - b_e(u) (its stamp at the point u) in each of its local
    unknowns, step U_STEP_REL max(|u_g|, 1)."""
    work = work_ref[0]
    Al, bl = work.Al, work.bl
    for k in range(L[e]):
        g = ui[eu[e] + k]
        if g >= n:
            continue
        ug = u[g]
        hk = U_STEP_REL * max(abs(ug), 1.0)
        for side in range(2):
            u[g] = ug + hk if side == 0 else ug - hk
            stamp_element(e, t, x, Pb, lay_ref, work_ref)
            for i in range(L[e]):
                r = ui[eu[e] + i]
                if r >= n:
                    continue
                acc = -bl[i]
                for m in range(L[e]):
                    acc += Al[i, m] * u[ui[eu[e] + m]]
                A[r, g] += acc / (2.0 * hk) if side == 0 else -acc / (2.0 * hk)
        u[g] = ug


@njit(cache=True, nogil=True, inline="always")
def residual_change(e, L, eu, ui, Al, bl, ub, rb, h, col, n):
    """Add element e's change of local residual (Al ub - bl, stamped at the moved point, minus
    the base rb) over the step h into the column col; True if some row moved."""
    moved = False
    for i in range(L[e]):
        r = ui[eu[e] + i]
        if r < n:
            acc = -bl[i]
            for k in range(L[e]):
                acc += Al[i, k] * ub[ui[eu[e] + k]]
            d = (acc - rb[eu[e] + i]) / h
            if d != 0.0:
                col[r] += d
                moved = True
    return moved


@njit(cache=True, nogil=True, inline="always")
def derivs_at_base(e, t, x, Pe, et, L, ep, ex, eu, ui, eo, io, ub, ul, pl, xl, il, dl):
    """Element e's derivatives into dl at (t, x, parameters Pe) with its local unknowns at the
    base solution ub."""
    for i in range(L[e]):
        ul[i] = ub[ui[eu[e] + i]]
    load_element(e, x, Pe, ep, ex, eo, io, pl, xl, il)
    elem_derivs(et[e], pl, xl, ul, t, il, dl)


@njit(cache=True, nogil=True, inline="always")
def keep_column(C, cj, col, nm, j, n):
    """Store col as column nm of C for state j (-1: t); returns the next column's index."""
    for i in range(n):
        C[i, nm] = col[i]
    cj[nm] = j
    return nm + 1


@njit(cache=True, nogil=True, inline="always")
def compose_columns(A, piv, C, M, MC, cj, J, ft, n, nx, nm):
    """J[:, cj[k]] -= M A^-1 C[:, k] (ft where cj[k] = -1: the time column) for the nm columns
    of C at once (C overwritten): the
    triangular solves and the product run along the rows of C and MC, over all columns together
    (vectorised), instead of one solve and one product per column (5 of the body model's 19 us a
    Jacobian, docs/performance.md)."""
    for c in range(n):  # the LU's row swaps
        p = piv[c]
        if p != c:
            for k in range(nm):
                tmp = C[c, k]
                C[c, k] = C[p, k]
                C[p, k] = tmp
    for i in range(n):  # L (unit diagonal)
        for r in range(i):
            a = A[i, r]
            if a != 0.0:
                for k in range(nm):
                    C[i, k] -= a * C[r, k]
    for i in range(n - 1, -1, -1):  # U
        for r in range(i + 1, n):
            a = A[i, r]
            if a != 0.0:
                for k in range(nm):
                    C[i, k] -= a * C[r, k]
        d = 1.0 / A[i, i]
        for k in range(nm):
            C[i, k] *= d
    for i in range(nx):
        for k in range(nm):
            MC[i, k] = 0.0
        for g in range(n):
            a = M[i, g]
            if a != 0.0:
                for k in range(nm):
                    MC[i, k] += a * C[g, k]
        for k in range(nm):
            if cj[k] >= 0:
                J[i, cj[k]] -= MC[i, k]
            else:
                ft[i] -= MC[i, k]


# inlined (numba IR) into integrate_batch, its one caller: numba links a callee's machine code into
# every caller and LLVM optimises it again there, so each call level costs compile time
@njit(cache=True, nogil=True, inline="always")
def jacobian_into(t, x, f0, P, lay_ref, work_ref, jw_ref, scales, J, ft, xt, ftmp, autonomous, local, rhs_fn, jac_fn,
                  solved):
    """Jacobian J (nx, nx) and df/dt ft (nx,) at (t, x) with f0 = f(t, x): element-local
    (local_jacobian_into_at; ``local`` 1: with the kernels' analytic partials where they have
    them, 2: differences only; ft with it, its time column) when ``local`` and
    it applies, otherwise forward differences of whole right-hand sides and ft by a forward
    difference of one more in t (ft untouched when the circuit is autonomous).  The tuples by
    reference (kernels.refs), as the integrators hold them; ``rhs_fn``, ``jac_fn``: rhs_into_at and
    local_jacobian_into_at, or their addresses (the Rosenbrock integrator's, kernels.pointers).
    ``solved``: work.u holds the nodal solution at (t, x) (the last right-hand side was
    there), so a circuit nonlinear in the pressures needs no nodal solve first.
    Returns the number of right-hand-side evaluations, or -1 if one failed (singular nodal
    system)."""
    nx = x.shape[0]
    nev = 0
    if local != 0:
        (n, nx_, et, L, S, ep, ex, eu, ui, eo, io, eb, ws, w0, wd, xs, xc, xk, xcode, xconst, oe, nonlin, cm, st,
         td) = lay_ref[0]
        if nonlin != 0 and not solved:  # the local Jacobian linearises at work.u, which a
            # rejected step's stages leave elsewhere: the nodal solution at (t, x) first
            nev = 1
            if not rhs_fn(t, x, P, lay_ref, work_ref, ftmp):
                return -1
        if jac_fn(t, x, P, lay_ref, work_ref, jw_ref, scales, J, xt, local == 1, ft, not autonomous) == 0:
            return nev  # J and (non-autonomous) ft element-locally
    for i in range(nx):
        xt[i] = x[i]
    for j in range(nx):
        hj = FD_REL * max(abs(x[j]), scales[j])
        xt[j] = x[j] + hj
        hj = xt[j] - x[j]
        if not rhs_fn(t, xt, P, lay_ref, work_ref, ftmp):
            return -1
        for i in range(nx):
            J[i, j] = (ftmp[i] - f0[i]) / hj
        xt[j] = x[j]
    nev += nx
    if autonomous:
        return nev
    # FD_REL seconds as represented at t (derivatives.time_step: absolute, not relative to t)
    ht = (t + FD_REL) - t
    if not rhs_fn(t + ht, x, P, lay_ref, work_ref, ftmp):
        return -1
    for i in range(nx):
        ft[i] = (ftmp[i] - f0[i]) / ht
    return nev + 1


@njit(cache=True, nogil=True)
def jacobian_parts(t, x, P, lay, scales, local, want_ft):
    """(J (nx, nx), df/dt (nx,)) at (t, x) (allocating; for tests and single calls), as the
    integrator computes them: element-local if ``local`` (1: with the kernels' analytic
    partials, 2: differences only; where it applies), else (0) whole right-hand sides
    differenced; df/dt (the time column) only with ``want_ft``, else zeros."""
    nx = x.shape[0]
    work = make_work(lay)
    jw = make_jac_work(lay)
    prepare_static(t, x, P, lay, work)
    f0 = np.empty(nx)
    rhs_into(t, x, P, lay, work, f0)
    J = np.zeros((nx, nx))
    ft = np.zeros(nx)
    jacobian_into(t, x, f0, P, ref(lay), ref(work), ref(jw), scales, J, ft, np.empty(nx), np.empty(nx), not want_ft,
                  local, rhs_into_at, local_jacobian_into_at, True)
    keep_alive(work)  # the references' tuples live to here (kernels.refs)
    keep_alive(jw)
    return J, ft


@njit(cache=True, nogil=True)
def gen_alpha_run(x0, h, n_steps, am, af, gamma, t0, P, lay, scales, max_iter, tol):
    """svZeroDSolver's steady_initial pseudo-time steps (svzerod.steady_initial: their
    Integrator::step, first-order generalized-alpha) of x' = f(t, x) from x0 with x'(0) = 0:
    ``n_steps`` steps of h [s], step i evaluated at t0 + (i + af) h; per step Newton on
    r(xd1) = xd + am (xd1 - xd) - f(t, x + af h (xd + gamma (xd1 - xd))) with the engine's
    Jacobian and a halving line search (their valves' steep tanh make the full step leave the
    region where the nodal Newton converges).  One compiled call: from Python each right-hand
    side and Jacobian cost ~15 and ~28 us of call overhead (18 ms of the procedure's 31 steps
    on chamber_elastance_inductor).
    Returns (x (nx,), status, step): status 0 done; 1 Newton did not converge in ``max_iter``
    iterations, 2 no step reduces the residual, 3 a state became non-finite, 4 the right-hand
    side, the Jacobian or Newton's matrix failed at the iterate (a nodal system singular or not
    converging), at pseudo-time step ``step`` (svzerod.steady_initial._FAILURES)."""
    nx = x0.shape[0]
    work = make_work(lay)
    jw = make_jac_work(lay)
    lay_ref, work_ref, jw_ref = ref(lay), ref(work), ref(jw)
    prepare_static(t0, x0, P, lay, work)
    x, xd, xd1 = x0.copy(), np.zeros(nx), np.zeros(nx)
    xa, f, r, xd_try, xa_try, f_try, r_try, d = (np.empty(nx), np.empty(nx), np.empty(nx), np.empty(nx),
                                                 np.empty(nx), np.empty(nx), np.empty(nx), np.empty(nx))
    J, W, ft, xt, ftmp = np.zeros((nx, nx)), np.empty((nx, nx)), np.zeros(nx), np.empty(nx), np.empty(nx)
    piv = np.empty(nx, dtype=np.int64)
    status, step = 0, 0
    for i in range(n_steps):
        step = i
        t = t0 + i * h + af * h
        for k in range(nx):
            xd1[k] = xd[k] * (1.0 - 1.0 / gamma)  # their predictor (x1 = x)
        ok = gen_alpha_residual(t, x, xd, xd1, h, am, af, gamma, P, lay_ref, work_ref, xa, f, r)
        converged = False
        for _ in range(max_iter):
            # the Jacobian at x_af, where the last right-hand side was (the nodal solution held)
            if not ok or jacobian_into(t, xa, f, P, lay_ref, work_ref, jw_ref, scales, J, ft, xt, ftmp, True, 1,
                                       rhs_into_at, local_jacobian_into_at, True) < 0:
                status = 4
                break
            for a in range(nx):
                for b in range(nx):
                    W[a, b] = -af * gamma * h * J[a, b]
                W[a, a] += am
                d[a] = -r[a]
            if not lu_factor(W, piv, nx):
                status = 4
                break
            lu_apply(W, piv, d, nx)
            norm0 = 0.0
            for k in range(nx):
                norm0 = max(norm0, abs(r[k]) * h / scales[k])
            lam, norm = 1.0, np.inf
            found = False
            for _ in range(40):
                for k in range(nx):
                    xd_try[k] = xd1[k] + lam * d[k]
                if gen_alpha_residual(t, x, xd, xd_try, h, am, af, gamma, P, lay_ref, work_ref, xa_try, f_try, r_try):
                    norm = 0.0
                    for k in range(nx):
                        norm = max(norm, abs(r_try[k]) * h / scales[k])
                    if norm < max(norm0, tol) or lam < 1e-3:
                        found = True
                        break
                lam *= 0.5
            if not found:
                status = 2
                break
            change = 0.0
            for k in range(nx):
                xd1[k], xa[k], f[k], r[k] = xd_try[k], xa_try[k], f_try[k], r_try[k]
                change = max(change, abs(gamma * h * lam * d[k]) / scales[k])
            if norm < tol or change < tol:
                converged = True
                break
        if status != 0:
            break
        if not converged:
            status = 1
            break
        finite = True
        for k in range(nx):
            x[k] += h * (xd[k] + gamma * (xd1[k] - xd[k]))
            xd[k] = xd1[k]
            finite = finite and np.isfinite(x[k])
        if not finite:
            status = 3
            break
    keep_alive(work)  # the references' tuples live to here (kernels.refs)
    keep_alive(jw)
    return x, status, step


@njit(cache=True, nogil=True, inline="always")
def gen_alpha_residual(t, x, xd, xd1, h, am, af, gamma, P, lay_ref, work_ref, xa, f, r):
    """r = xd + am (xd1 - xd) - f(t, xa), xa = x + af h (xd + gamma (xd1 - xd)) (gen_alpha_run);
    False when the right-hand side fails or r is not finite."""
    nx = x.shape[0]
    for k in range(nx):
        xa[k] = x[k] + af * h * (xd[k] + gamma * (xd1[k] - xd[k]))
    if not rhs_into_at(t, xa, P, lay_ref, work_ref, f):
        return False
    for k in range(nx):
        r[k] = xd[k] + am * (xd1[k] - xd[k]) - f[k]
        if not np.isfinite(r[k]):
            return False
    return True
