# Engine template, part 4 of 4: the variable-order BDF integrator.  NOT imported on its own
# (kernels.codegen appends it after engine_nodal.py and engine_jacobian.py, whose functions it
# calls; its dense output, bdf_dense, is in hemocircuit.kernels.dense).
#
# Variable-order BDF (NDF): the method of scipy's solve_ivp 'BDF' (Shampine &
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
#: (measured on freq's forced runs)
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
def bdf_newton(t_new, ypred, c, psi, W, piv, scale, tol, P, lay_ref, work_ref, y, d, f, dy):
    """Newton's iteration of one BDF step (scipy bdf.solve_bdf_system).  Returns the number of
    iterations, negative when it did not converge."""
    nx = y.shape[0]
    for i in range(nx):
        y[i] = ypred[i]
        d[i] = 0.0
    dy_norm_old = -1.0
    for k in range(BDF_NEWTON_MAXITER):
        if not rhs_into_at(t_new, y, P, lay_ref, work_ref, f):
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
        lay_ref = ref(lay)  # the tuples by reference for the right-hand sides and Jacobians (kernels.refs)
        work_ref = ref(work)
        jw_ref = ref(jw)
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
        if not rhs_into_at(t, x, P, lay_ref, work_ref, f):
            finish_member(out, 1, stats, mb, -3, t, 0, 0, nfev, 0)
            continue
        nj = jacobian_into(t, x, f, P, lay_ref, work_ref, jw_ref, scales, J, ft, xt, ftmp, True, local_jac,
                           rhs_into_at, local_jacobian_into_at, False)
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
                        n_iter = bdf_newton(t_new, ypred, c, psi, W, piv, scale, newton_tol, P, lay_ref, work_ref,
                                            ynew, d, fp, dy)
                        nfev += abs(n_iter)
                        if n_iter > 0:
                            break
                    if jac_current:
                        break
                    # Newton failed with an older Jacobian: a new one at the predicted state
                    nfev += 1
                    if not rhs_into_at(t_new, ypred, P, lay_ref, work_ref, ftmp):
                        break
                    nj = jacobian_into(t_new, ypred, ftmp, P, lay_ref, work_ref, jw_ref, scales, J, ft, xt, fp, True,
                                       local_jac, rhs_into_at, local_jacobian_into_at, False)
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
                if not rhs_into_at(t, x, P, lay_ref, work_ref, f):
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
                if not rhs_into_at(t, x, P, lay_ref, work_ref, f):
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
        keep_alive(work)  # the references' tuples live to here (kernels.refs)
        keep_alive(jw)
    return out_all, stats
