# Engine template, part 1 of 4: the nodal solve and the right-hand side.  NOT imported on its own.
#
# hemocircuit.kernels.codegen writes one module per set of component types: a header (imports,
# the shared compiled functions of hemocircuit.linalg, kernels.dense and kernels.runs, and the
# dispatchers elem_stamp / elem_derivs / elem_observe / elem_derivs_jac that call each type's
# Kernel functions by a type code) followed by the template files in the order of
# codegen.TEMPLATES: this one (scratch buffers, element loading, static condensation, nodal
# solve, right-hand side, outputs), engine_jacobian.py, engine_rosenbrock.py, engine_bdf.py.
# Everything here is numba nopython code with no per-call Python.
#
# Layout ``lay`` (the fields of kernels.layout.EngineLayout as a plain tuple, built from an
# assembled circuit; the functions unpack them by name):
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
#   td (E,)          1 if its stamp or derivatives may change with t at fixed states (a
#                    time-dependent type, a waveform or an expression on its parameters), else 0
# Units: as the numpy path -- pressures mmHg, flows mL/s, time s, states in declared units.
#
# Entry points called from Python: rhs, rhs_batch, nodal_outputs, jacobian_parts,
# integrate_batch(_bdf).
# Every other compiled function is ``internal=True`` (the header's njit): numba then builds no
# Python/C wrapper for it, whose unboxing of the layout and work tuples cost ~15 % of the first
# compilation.
#
# _nrt=False on the functions that never allocate (and return no array): no reference counting
# of the arrays they touch.  With it on, NRT's atomic increments/decrements of the layout's and
# work tuple's arrays took 43 % of the vasomotion run's samples (perf); without it the run
# takes 3.1x less CPU (docs/performance.md).
# (Functions inlined with inline="always" take their caller's setting.)
from collections import namedtuple  # noqa: E402

NEWTON_TOL = 1e-12
NEWTON_MAXIT = 50

#: The scratch arrays of one evaluation (make_work), by name.  Sizes: n + 1 for the nodal
#: unknowns (ground last), Lm / Sm / Pm / Im / Om the largest element's local unknowns, states,
#: parameters, options and observables.
Work = namedtuple("Work", (
    "Pe",          # (nP,) effective parameters: P with waveforms added, expressions evaluated
    "O",           # state-only observables the expressions read (at the eb offsets)
    # the nodal system
    "A",           # (n+1, n+1) the matrix being solved (dense path), then its LU
    "b",           # (n+1,) its right-hand side
    "u",           # (n+1,) the solution: the current Newton iterate
    "un",          # (n+1,) the next iterate
    "piv",         # (n+1,) int: pivots of A's (or, condensed, Sw's) LU
    "A0",          # (n+1, n+1) the constant matrix stamps (prepare_static)
    "b0",          # (n+1,) the static elements' right-hand sides (prepare_static)
    "A1",          # (n+1, n+1) a Newton solve's iterate-independent matrix (solve_nodes) ...
    "Sw1",         # ... condensed ...
    "b1",          # ... and right-hand side
    # one element's buffers: whole arrays, not slices (a slice is a new array view whose
    # reference counting costs more than a small element's equations: 70 ns a call against 2 ns)
    "pl",          # (Pm,) parameters
    "xl",          # (Sm,) states
    "ul",          # (Lm,) local unknowns
    "il",          # (Im,) int: options
    "dl",          # (Sm,) derivatives
    "ol",          # (Om,) observables
    "Al",          # (Lm, Lm) local stamp matrix
    "bl",          # (Lm,) local stamp right-hand side
    # static condensation (condense): C the unknowns only constant stamps touch, V the rest
    "Fc",          # (n+1, n+1) LU of Acc
    "pivc",        # (n+1,) int: its pivots
    "Z",           # (n+1, n+1) Acc^-1 Acv
    "S0",          # (n+1, n+1) the Schur complement Avv - Avc Z
    "Avc",         # (n+1, n+1)
    "Sw",          # (n+1, n+1) S0 plus the varying stamps: the condensed matrix solved, its LU
    "order",       # (n+1,) int: the unknowns, C first, then V
    "vpos",        # (n+1,) int: an unknown's position in V, -1 in C
    "nc",          # (1,) int: the number of C unknowns
    "nv",          # (1,) int: the number of V unknowns
    "condensed",   # (1,) int: 1 when the condensation applies (else the dense path)
    "y",           # (n+1,) Acc^-1 b_C
    "rv",          # (n+1,) the condensed right-hand side, then u_V
    # scratch of the waveform sums and the expression programs (no allocation in the
    # functions compiled without numba's runtime)
    "wave_sum",    # (WAVE_SUM_DEPTH,)
    "wave_term",   # (WAVE_SUM_DEPTH,) int
    "expr_stack",  # (EXPR_STACK,)
))


@njit(cache=True, nogil=True, internal=True)
def make_work(lay):
    """The scratch arrays for one evaluation (Work)."""
    (n, nx, et, L, S, ep, ex, eu, ui, eo, io, eb, ws, w0, wd, xs, xc, xk, xcode, xconst, oe, nonlin, cm, st, td) = lay
    Lm, Sm, Pm, Im, Om = 1, 1, 1, 1, 1
    for e in range(et.shape[0]):
        Lm = max(Lm, L[e])
        Sm = max(Sm, S[e])
        Pm = max(Pm, ep[e + 1] - ep[e])
        Im = max(Im, eo[e + 1] - eo[e])
        Om = max(Om, eb[e + 1] - eb[e])
    return Work(Pe=np.zeros(ep[-1]), O=np.zeros(max(eb[-1], 1)),
                A=np.zeros((n + 1, n + 1)), b=np.zeros(n + 1), u=np.zeros(n + 1), un=np.zeros(n + 1),
                piv=np.zeros(n + 1, dtype=np.int64), A0=np.zeros((n + 1, n + 1)), b0=np.zeros(n + 1),
                A1=np.zeros((n + 1, n + 1)), Sw1=np.zeros((n + 1, n + 1)), b1=np.zeros(n + 1),
                pl=np.zeros(Pm), xl=np.zeros(Sm), ul=np.zeros(Lm), il=np.zeros(Im, dtype=np.int64),
                dl=np.zeros(Sm), ol=np.zeros(Om), Al=np.zeros((Lm, Lm)), bl=np.zeros(Lm),
                Fc=np.zeros((n + 1, n + 1)), pivc=np.zeros(n + 1, dtype=np.int64), Z=np.zeros((n + 1, n + 1)),
                S0=np.zeros((n + 1, n + 1)), Avc=np.zeros((n + 1, n + 1)), Sw=np.zeros((n + 1, n + 1)),
                order=np.zeros(n + 1, dtype=np.int64), vpos=np.zeros(n + 1, dtype=np.int64),
                nc=np.zeros(1, dtype=np.int64), nv=np.zeros(1, dtype=np.int64),
                condensed=np.zeros(1, dtype=np.int64), y=np.zeros(n + 1), rv=np.zeros(n + 1),
                wave_sum=np.zeros(WAVE_SUM_DEPTH), wave_term=np.zeros(WAVE_SUM_DEPTH, dtype=np.int64),
                expr_stack=np.zeros(EXPR_STACK))


# inline="always" (numba IR inlining) on the small helpers called inside the per-evaluation
# loops: a call from a function compiled with reference counting costs one per array member of
# the layout and work tuples (~1 us per evaluation in all).  Not on rhs_into: inlining it at its
# six call sites quadruples the compile time (25 s -> 100 s) for 14 % speed.  Nor on
# effective_params_at and stamp_element, called from several places in the nodal solve and the
# Jacobian: each inlined copy was typed and lowered again (local_jacobian_into held two of each);
# as functions of their own, compiled without reference counting as all their callers, they are
# compiled once (the same machine speed, the first compile 8 s less CPU on the project's
# machine), and they take the layout and work tuples by reference (kernels.refs).
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


@njit(cache=True, nogil=True, internal=True, _nrt=False)
def effective_params_at(t, x, P, lay_ref, work_ref):
    """Parameters with waveforms added and expressions evaluated (into work.Pe); the layout and
    work tuples by reference (kernels.refs)."""
    lay = lay_ref[0]
    work = work_ref[0]
    (n, nx, et, L, S, ep, ex, eu, ui, eo, io, eb, ws, w0, wd, xs, xc, xk, xcode, xconst, oe, nonlin, cm, st, td) = lay
    Pe, O, pl, xl, il, ol = work.Pe, work.O, work.pl, work.xl, work.il, work.ol
    for i in range(P.shape[0]):
        Pe[i] = P[i]
    for w in range(ws.shape[0]):
        Pe[ws[w]] += wave_value_with(wd, w0[w], t, work.wave_sum, work.wave_term)
    if xs.shape[0] > 0:
        for j in range(oe.shape[0]):
            e = oe[j]
            load_element(e, x, Pe, ep, ex, eo, io, pl, xl, il)
            elem_observe(et[e], pl, xl, il, ol)
            for i in range(eb[e], eb[e + 1]):
                O[i] = ol[i - eb[e]]
        for k in range(xs.shape[0]):
            Pe[xs[k]] = eval_expr_with(xcode, xc[k], xconst, xk[k], Pe, O, work.expr_stack)


@njit(cache=True, nogil=True, internal=True, _nrt=False)
def stamp_element(e, t, x, Pe, lay_ref, work_ref):
    """Element e's local stamp into the scratch work.Al, work.bl (at the current iterate work.u),
    with parameters Pe; the layout and work tuples by reference (kernels.refs): a call passes two
    pointers, and only the fields used are read."""
    lay = lay_ref[0]
    work = work_ref[0]
    (n, nx, et, L, S, ep, ex, eu, ui, eo, io, eb, ws, w0, wd, xs, xc, xk, xcode, xconst, oe, nonlin, cm, st, td) = lay
    u, Al, bl, ul, pl, xl, il = work.u, work.Al, work.bl, work.ul, work.pl, work.xl, work.il
    Lm = ul.shape[0]
    Le = L[e]
    for i in range(Lm):
        bl[i] = 0.0
        ul[i] = u[ui[eu[e] + i]] if i < Le else 0.0
        for j in range(Lm):
            Al[i, j] = 0.0
    load_element(e, x, Pe, ep, ex, eo, io, pl, xl, il)
    elem_stamp(et[e], pl, xl, ul, t, il, Al, bl)


@njit(cache=True, nogil=True, pointer=True, _nrt=False)
def prepare_static(t, x, P, lay, work):
    """A0 = the constant matrix stamps, b0 = the static elements' right-hand sides, for the
    parameters P (call again whenever P changes)."""
    (n, nx, et, L, S, ep, ex, eu, ui, eo, io, eb, ws, w0, wd, xs, xc, xk, xcode, xconst, oe, nonlin, cm, st, td) = lay
    lay_ref = ref(lay)  # the tuples by reference (kernels.refs)
    work_ref = ref(work)
    effective_params_at(t, x, P, lay_ref, work_ref)
    Pe = work.Pe
    A0, b0 = work.A0, work.b0
    Al, bl = work.Al, work.bl
    A0[:, :] = 0.0
    b0[:] = 0.0
    for e in range(et.shape[0]):
        if cm[e] == 0:
            continue
        stamp_element(e, t, x, Pe, lay_ref, work_ref)
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
    Used when that costs fewer operations a solve than the dense LU (below) and Acc is regular;
    otherwise the dense path (chamber_elastance_inductor: 7 of 11 unknowns varying, condensed
    8 % faster than dense)."""
    (n, nx, et, L, S, ep, ex, eu, ui, eo, io, eb, ws, w0, wd, xs, xc, xk, xcode, xconst, oe, nonlin, cm, st, td) = lay
    A0, Fc, Z, S0, Avc, pivc, order, vpos, y = (work.A0, work.Fc, work.Z, work.S0, work.Avc, work.pivc, work.order,
                                                work.vpos, work.y)
    work.condensed[0] = 0
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
        # condensed when its work per solve (the LU of nv, the Schur products) is below the
        # dense LU's: nv^3/3 + 2 nc nv + nc^2 < n^3/3
        if nv == 0 or 3 * (2 * nc * nv + nc * nc) + nv * nv * nv >= n * n * n:
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
    work.nc[0] = nc
    work.nv[0] = nv
    work.condensed[0] = 1


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
def zero_start(u, n):
    """The nodal unknowns' start after a failed solve (and for linear systems): zeros."""
    for i in range(n + 1):
        u[i] = 0.0


@njit(cache=True, nogil=True, inline="always")
def solve_nodes(t, x, Pe, lay_ref, work_ref):
    """Node pressures and branch flows u (n+1,; u[n] = 0 is ground) for states x: the MNA
    system A0 + (varying stamps) and b0 + (non-static right-hand sides), solved densely
    (Newton for elements nonlinear in the pressures).  prepare_static must have run for these
    parameters.  Returns False if the system is singular or Newton fails.

    With Newton (nonlin), the stamps that do not depend on the iterate (st 0: elements affine
    in the pressures; they depend on t and x only, e.g. a pressure table or a chamber's
    elastance) are summed once per solve into A1 (or Sw1) and b1, and only the elements
    nonlinear in the pressures (st 2) are stamped again at every iterate (svZeroDSolver's
    split of a block's contributions by what they depend on).  The layout and work tuples by
    reference (kernels.refs)."""
    lay = lay_ref[0]
    work = work_ref[0]
    (n, nx, et, L, S, ep, ex, eu, ui, eo, io, eb, ws, w0, wd, xs, xc, xk, xcode, xconst, oe, nonlin, cm, st, td) = lay
    A, b, u, un, piv, A0, b0, A1, Sw1, b1 = (work.A, work.b, work.u, work.un, work.piv, work.A0, work.b0, work.A1,
                                             work.Sw1, work.b1)
    Al, bl, ul, pl, xl, il = work.Al, work.bl, work.ul, work.pl, work.xl, work.il
    Fc, Z, S0, Avc, Sw, pivc, order, vpos, y, rv = (work.Fc, work.Z, work.S0, work.Avc, work.Sw, work.pivc,
                                                    work.order, work.vpos, work.y, work.rv)
    schur = work.condensed[0] == 1
    nc = work.nc[0]
    nv = work.nv[0]
    # Newton starts from the last solution (u, warm) and, if that does not converge, once more
    # from zero; a solve that fails leaves zeros, not its last iterate.  A warm start left far
    # away (a rejected stage's state) or not finite (a failed solve; prepare_static's stamps
    # read u too) made every later solve fail, and the step size shrink to nothing (the
    # decomposed heart: "step size too small")
    restart = nonlin == 0
    prev = -1.0  # the last iterate's change (-1: none since the start)
    for it in range(2 * NEWTON_MAXIT):
        if it == NEWTON_MAXIT:
            restart = True
        if restart:
            zero_start(u, n)
            restart = False
            prev = -1.0
        first = it == 0 or it == NEWTON_MAXIT
        # the system's base: A0, b0 at the first iterate, then A1, b1 (the base plus the
        # iterate-independent stamps, kept from the first)
        if first:
            copy_nodal(A0, S0, b0, A, Sw, b, schur, nv, n)
        else:
            copy_nodal(A1, Sw1, b1, A, Sw, b, schur, nv, n)
        # phase 0 (first iterate only): the stamps that do not depend on the iterate (st 0);
        # phase 1: those nonlinear in the pressures (st 2).  One stamp call site: each inlined
        # copy of the kernels' stamps costs compile time
        for ph in range(2):
            if ph == 0 and not first:
                continue
            for e in range(et.shape[0]):
                if st[e] != 2 * ph:
                    continue
                stamp_element(e, t, x, Pe, lay_ref, work_ref)
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
                if nonlin == 0 or it >= NEWTON_MAXIT:
                    break
                restart = True  # singular at this iterate: from zero
                continue
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
                if nonlin == 0 or it >= NEWTON_MAXIT:
                    break
                restart = True  # singular at this iterate: from zero
                continue
            for i in range(n):
                un[i] = b[i]
            lu_apply(A, piv, un, n)
        un[n] = 0.0
        if nonlin == 0:
            for i in range(n + 1):
                u[i] = un[i]
            return True
        change = 0.0
        finite = True
        for i in range(n + 1):
            d = abs(un[i] - u[i]) / (1.0 + abs(un[i]))
            if d > change:
                change = d
            if not np.isfinite(un[i]):  # (a NaN's d is never > change)
                finite = False
            u[i] = un[i]
        if not finite:  # diverged: from zero now, or give up
            if it >= NEWTON_MAXIT:
                break
            restart = True
        elif change < NEWTON_TOL:
            return True
        elif 0.0 < change < prev and change * change < NEWTON_TOL * (prev - change):
            # converging at the rate theta = change / prev: the distance left to the solution
            # is at most theta / (1 - theta) change (Hairer & Wanner II, IV.8), below NEWTON_TOL,
            # so the iterate that would only confirm it is not computed
            return True
        else:
            prev = change
    zero_start(u, n)
    return False


@njit(cache=True, nogil=True, internal=True, _nrt=False)
def rhs_into(t, x, P, lay, work, dx):
    """dx/dt for states x at time t into dx (rhs_into_at, the tuples by reference).  For single
    calls: a loop takes the references once and calls rhs_into_at."""
    return rhs_into_at(t, x, P, ref(lay), ref(work), dx)


@njit(cache=True, nogil=True, pointer=True, _nrt=False)
def rhs_into_at(t, x, P, lay_ref, work_ref, dx):
    """dx/dt for states x at time t into dx.  Returns False on a singular nodal system
    (dx is then NaN).  An empty dx: the nodal solve only (nodal_outputs_into: the outputs need
    no derivatives, a third of an evaluation; the same compiled function, so no second
    compilation of the inlined nodal solve)."""
    lay = lay_ref[0]
    work = work_ref[0]
    (n, nx, et, L, S, ep, ex, eu, ui, eo, io, eb, ws, w0, wd, xs, xc, xk, xcode, xconst, oe, nonlin, cm, st, td) = lay
    effective_params_at(t, x, P, lay_ref, work_ref)
    Pe = work.Pe
    if not solve_nodes(t, x, Pe, lay_ref, work_ref):
        for i in range(dx.shape[0]):
            dx[i] = np.nan
        return False
    if dx.shape[0] == 0:
        return True
    u, ul, pl, xl, il, dl = work.u, work.ul, work.pl, work.xl, work.il, work.dl
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
    lay_ref = ref(lay)  # the tuples by reference, once (kernels.refs)
    work_ref = ref(work)
    out = np.empty(X.shape)
    for k in range(X.shape[0]):
        p = P[k if P.shape[0] > 1 else 0]
        if k == 0 or P.shape[0] > 1:
            prepare_static(t, X[k], p, lay, work)
        rhs_into_at(t, X[k], p, lay_ref, work_ref, out[k])
    keep_alive(work)  # (kernels.refs)
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
    counting, as rhs_into).  Through rhs_into, which leaves the effective parameters in work.Pe
    and the nodal solution in work.u: its compilation (the integrator's, from the cache) is
    reused instead of typing the inlined nodal solve again (7 s of a first compilation).  An
    empty ``dx`` skips the derivatives there."""
    lay_ref = ref(lay)  # the tuples by reference, once (kernels.refs)
    work_ref = ref(work)
    (n, nx, et, L, S, ep, ex, eu, ui, eo, io, eb, ws, w0, wd, xs, xc, xk, xcode, xconst, oe, nonlin, cm, st, td) = lay
    Pe, u, Al, bl, ul, pl, xl, il = work.Pe, work.u, work.Al, work.bl, work.ul, work.pl, work.xl, work.il
    m = X.shape[0]
    per = m // P.shape[0]
    for k in range(m):
        p = P[k // per]
        if k % per == 0:
            prepare_static(T[k], X[k], p, lay, work)
        if not rhs_into_at(T[k], X[k], p, lay_ref, work_ref, dx):
            return k
        for i in range(n + 1):
            U[k, i] = u[i]
        for e in range(et.shape[0]):
            if L[e] == 0:
                F[k, e] = 0.0
                continue
            # at the converged u, an element nonlinear in the pressures stamps its
            # linearisation there, whose residual is its flow at u
            stamp_element(e, T[k], X[k], Pe, lay_ref, work_ref)
            acc = -bl[0]
            for j in range(L[e]):
                acc += Al[0, j] * ul[j]
            F[k, e] = acc
    return -1
