# Engine template, part 3 of 4: the Rosenbrock(-W) integrator.  NOT imported on its own
# (kernels.codegen appends it after engine_nodal.py and engine_jacobian.py, whose functions it
# calls).  The method is a run-time argument (``tab``, a tableaus.RosenbrockMethod: RODAS5P by
# default, ROS34PW2, ROS34PW3, RODAS4), so choosing a method never recompiles.  Dense output
# and event location: hemocircuit.kernels.dense; the end of a member's run and the hard-limit
# rule: hemocircuit.kernels.runs; the LU: hemocircuit.linalg.


# held_on_bound, any_released and release_fraction are called only from the integrator:
# internal (no Python entry wrapper unboxing the layout and work tuples: 3 s of a first compile)
@njit(cache=True, nogil=True, internal=True, _nrt=False)
def held_on_bound(k, x, f, lim_i, lim_b, lim_r, atol):
    """Whether limited state k sits on its bound (to LIMIT_ON_BOUND x atol) without rising: held
    there (a closed valve).  Not a limit with a reset state (lim_r >= 0: the second-order Ca
    floor, whose rate dCa is a state reset to 0 on the bound and leaves it smoothly): its own
    derivative is that state, 0 at once, and would count as held while already released."""
    li = lim_i[k]
    return lim_r[k] < 0 and x[li] <= lim_b[k] + LIMIT_ON_BOUND * atol[li] and f[li] <= 0.0


@njit(cache=True, nogil=True, internal=True, _nrt=False)
def any_released(held, lim_i, fv):
    """Whether a held state's derivative in fv is positive."""
    for k in range(lim_i.shape[0]):
        if held[k] and fv[lim_i[k]] > 0.0:
            return True
    return False


@njit(cache=True, nogil=True, pointer=True, _nrt=False)
def release_fraction(t, hh, tlim, x, f, xn, P, lay, work, lim_i, lim_b, lim_r, atol, held, xe, fe, xh, fh):
    """Where in the step t -> t + hh a state held on its hard limit at t is released: the
    earliest fraction of the step at which one of them, kept on its bound, has a positive
    derivative (a closed valve whose pressure difference turns positive), located by bisection
    on the cubic Hermite path of the other states from (x, f) to the step's proposal xn.
    ``held`` (one flag per limit): scratch.
    Returns (fraction, f evaluations): the upper end of the last bracket (just past the
    release), or 2.0 when no held state is released in the step or the release is at its start
    (a bracket at the first halving's resolution: there is nothing to land on).

    Why: the release is a kink of the solution (the flow starts with a zero slope), which the
    error estimate of a step across it rejects, and the step-size controller alone creeps up
    to it with steps down to 1e-7 s and ~25 extra steps per valve opening (the whole-body
    model: four openings a beat, docs/performance.md).  A step that ends on the release
    and the next that starts there are both smooth."""
    nx = x.shape[0]
    n_held = 0
    for k in range(lim_i.shape[0]):
        held[k] = held_on_bound(k, x, f, lim_i, lim_b, lim_r, atol)
        n_held += held[k]
    if n_held == 0:
        return 2.0, 0
    # the step's end and, below, each bisection point with every held state on its bound:
    # released where one of them has a positive derivative there
    for i in range(nx):
        xe[i] = xn[i]
    for k in range(lim_i.shape[0]):
        if held[k]:
            xe[lim_i[k]] = lim_b[k]
    nf = 1
    lay_ref = ref(lay)  # the tuples by reference, once (kernels.refs)
    work_ref = ref(work)
    if not rhs_into_at(min(t + hh, tlim), xe, P, lay_ref, work_ref, fe) or not any_released(held, lim_i, fe):
        return 2.0, nf
    lo = 0.0
    hi = 1.0
    for _ in range(RELEASE_HALVINGS):
        m = 0.5 * (lo + hi)
        hermite(x, f, xe, fe, hh, m, xh)
        for k in range(lim_i.shape[0]):
            if held[k]:
                xh[lim_i[k]] = lim_b[k]
        nf += 1
        if not rhs_into_at(min(t + m * hh, tlim), xh, P, lay_ref, work_ref, fh):
            return 2.0, nf
        if any_released(held, lim_i, fh):
            hi = m
        else:
            lo = m
    if lo == 0.0:  # released at the step's start: nothing to land on
        return 2.0, nf
    return hi, nf


@njit(cache=True, nogil=True)
def integrate_batch(t_out_all, X0, P_all, lay, scales, lim_i, lim_b, lim_r, breaks_all, bjump_all, rtol, atol, h0,
                    hmax_all, max_steps, tab, prepare_fn, rhs_fn, jac_fn, release_fn):
    """Integrate each member m from t_out[m, 0] to t_out[m, -1], writing its states at every t_out[m] into
    out[m] (t_out (B, T), X0 (B, nx), P (B, nP), hmax (B,), breaks and bjump (B, K): each member's
    breakpoints, padded with +inf) -> (out (B, T, nx), stats (B, 6): status, t reached, steps, rejected
    steps, f evaluations, limit events).  One member's run:

    Integrate from t_out[0] to t_out[-1], writing the states at every t_out into out (T, nx).

    Hard limits (lim_i, lim_b, lim_r): state lim_i[k] may not fall below lim_b[k]; at the
    crossing (located on the step's cubic Hermite interpolant) the state is put on the bound
    and state lim_r[k] (if >= 0) is reset to max(., 0); the next step starts from the size of
    the step that hit the bound (tab.event_restart = 1), not from the shortened one.  The reverse,
    a held state's release (a closed valve opening), is located in the step the error test
    rejects and the step retried ending just past it (release_fraction; tab.land_releases = 1).
    Steps end exactly on
    ``breaks`` (discontinuities of sources, sorted), where f is re-evaluated unless
    ``bjump[k]`` = 0: a slope-only kink (a pwl table's time), where the source's value and so
    f are continuous, the step ends but f(t-) serves as f(t+) (one evaluation less per kink);
    where f does not jump the Jacobian is kept (tab.soft_kinks = 1).
    ``tab``: the method and its options (hemocircuit.kernels.tableaus.packed).
    ``prepare_fn``, ``rhs_fn``, ``jac_fn``, ``release_fn``: the addresses of prepare_static,
    rhs_into_at, local_jacobian_into_at and release_fraction (kernels.pointers), called through
    them: compiling the integrator needs their types only, not their code, so a first run
    compiles it in its helper process while this one compiles them (kernels.prebuild).
    Its stats row (finish_member): (status, t reached, steps, rejected steps, f evaluations,
    limit events), rows not reached NaN; status 0 done, -1 step size too small, -2 step limit, -3 non-finite state or singular system.

    One function, not a per-member function called (or inlined) here: numba's IR inlining deep-copies
    the callee's blocks, each with a copy of the whole scope (5.6 s of a first compilation), and a
    separate function is compiled, linked and code-generated once more."""
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
        ns = tab.stages
        GAMMA = tab.gamma
        q = tab.q
        JAC_REUSE = tab.jac_reuse
        ev_restart = tab.event_restart != 0
        soft_kinks = tab.soft_kinks != 0
        autonomous = tab.autonomous != 0  # no waveform or time-dependent element: df/dt = 0
        land = tab.land_releases != 0  # a rejected step retried to end on a held state's release
        local_jac = tab.local_jacobian  # element-local Jacobian (local_jacobian_into_at) where it applies: 1 analytic parts, 2 FD
        # the transformed coefficients (tableaus): a, C (ns, ns), m, m_err, c, d, reuse (ns,); H
        # (nd, ns) the dense-output rows (nd 0: cubic Hermite); K holds the stages u_s
        tab_a, tab_C, tab_m, tab_me, tab_c, tab_d = tab.a, tab.C, tab.m, tab.m_err, tab.c, tab.d
        tab_reuse, tab_H = tab.reuse, tab.H
        nd = tab_H.shape[0]
        ctrl = tab.controller  # step-size controller (tableaus.CONTROLLERS)
        predictive = ctrl != 0
        cut_max = 0.9 if ctrl == 1 else 0.5  # the largest step after a rejection, of the rejected one
        work = make_work(lay)
        jw = make_jac_work(lay)
        lay_ref = ref(lay)  # the tuples by reference for the right-hand sides and Jacobians (kernels.refs)
        work_ref = ref(work)
        jw_ref = ref(jw)
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
        xe = np.empty(nx)
        fe = np.empty(nx)
        held_now = np.zeros(lim_i.shape[0], dtype=np.bool_)  # release_fraction's scratch
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
        prepare_fn(t, x, P, lay, work)
        # work.u holds the nodal solution at (t, x) (the last right-hand side was there): the
        # Jacobian of a circuit nonlinear in the pressures linearises at it (jacobian_into)
        u_at_x = True
        if not rhs_fn(t, x, P, lay_ref, work_ref, f):
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
        landed = False  # the step tried ends on a held state's release (release_fraction)
        h_prev = 0.0  # the last accepted step (predictive controller; 0 before the first)
        while status == 0 and t < t_end and k_out < T:
            if nsteps >= max_steps:
                status = -2
                break
            tb = t_end
            if ib < breaks.shape[0] and breaks[ib] < t_end:
                tb = breaks[ib]
            if age >= JAC_REUSE:
                nj = jacobian_into(t, x, f, P, lay_ref, work_ref, jw_ref, scales, J, ft, xt, ftmp, autonomous,
                                   local_jac, rhs_fn, jac_fn, u_at_x)
                # (a Jacobian of whole right-hand sides leaves work.u at its last column's point:
                # one retried after a failed LU below solves the nodes at (t, x) first)
                u_at_x = False
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
                    if not rhs_fn(t, x, P, lay_ref, work_ref, f):
                        status = -3
                        break
                    u_at_x = True
                    age = JAC_REUSE
                    continue
            for i in range(nx):
                for j in range(nx):
                    W[i, j] = -GAMMA * hh * J[i, j]
                W[i, i] += 1.0
            if not lu_factor(W, piv, nx):
                h = 0.25 * hh
                age = JAC_REUSE
                landed = False
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
                    a_sj = tab_a[s, j]
                    c_sj = tab_C[s, j]
                    if a_sj != 0.0:
                        for i in range(nx):
                            xs[i] += a_sj * K[j, i]
                    if c_sj != 0.0:
                        for i in range(nx):
                            gs[i] += c_sj * K[j, i]
                if s == 0:
                    for i in range(nx):
                        fn[i] = f[i]
                elif tab_reuse[s] == 0.0:  # else: same point as stage s-1, fn holds its f
                    nfev += 1
                    u_at_x = False
                    if not rhs_fn(min(t + tab_c[s] * hh, tlim), xs, P, lay_ref, work_ref, fn):
                        good = False
                        break
                # W u_s = gamma (h f + sum_j C_sj u_j + h^2 d_s f_t): no product with J (tableaus)
                gd_s = GAMMA * hh * hh * tab_d[s]
                for i in range(nx):
                    K[s, i] = GAMMA * (hh * fn[i] + gs[i]) + gd_s * ft[i]
                lu_apply(W, piv, K[s], nx)
            enorm = np.inf
            if good:
                enorm = 0.0
                for i in range(nx):
                    xi = x[i]
                    e = 0.0
                    for s in range(ns):
                        xi += tab_m[s] * K[s, i]
                        e += tab_me[s] * K[s, i]
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
                ok = rhs_fn(min(tn, tlim), xn, P, lay_ref, work_ref, fn)  # left limit at a breakpoint
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
                    ok = rhs_fn(tn, xn, P, lay_ref, work_ref, fn)
                    age = JAC_REUSE
                    nev += 1
                elif held:
                    nfev += 1
                    ok = rhs_fn(min(tn, tlim), xn, P, lay_ref, work_ref, fn)
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
                                acc += tab_H[m, s] * K[s, i]
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
                u_at_x = True  # every path above ends on a right-hand side at (tn, xn)
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
                    if not rhs_fn(t, x, P, lay_ref, work_ref, fr):
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
                if landed:
                    # the released state's motion starts here (a valve's flow rising from 0
                    # with its pressure difference): the step size of the smooth approach says
                    # little about it; RELEASE_NEXT of it saves ~3 rejected steps an opening
                    age = JAC_REUSE
                    landed = False
                    if k_hit < 0:  # (a bound hit in the step restarts as such, above)
                        h = min(h, RELEASE_NEXT * hh)
                nrej_run = 0
            else:
                nrej += 1
                s_rel = 2.0
                # one landing per approach: a landed retry that is rejected too is left to the
                # step-size rule (its flag goes: the step that is accepted may end elsewhere)
                retry = landed
                landed = False
                if land and not retry and np.isfinite(enorm) and lim_i.shape[0] > 0:
                    s_rel, nf = release_fn(t, hh, tlim, x, f, xn, P, lay, work, lim_i, lim_b, lim_r, atol,
                                           held_now, xe, fe, xh, fr)
                    nfev += nf
                if s_rel < RELEASE_LAND_BELOW:
                    # retry ending just past the release (no shrink rule, and growth stays
                    # allowed after it: the step was rejected for the kink, not its size); the
                    # Jacobian after it is new (the released state's row changes there)
                    h = s_rel * hh
                    landed = True
                    if h < 1e-14 * max(1.0, abs(t)):
                        status = -1
                        break
                    continue
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
        keep_alive(work)  # the references' tuples live to here (kernels.refs)
        keep_alive(jw)
    return out_all, stats
