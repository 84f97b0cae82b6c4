"""The nodal system of a circuit with values: its constant part (prepared once), the stamps of
the other groups at a state, and the solve for node pressures and branch flows.

At every right-hand-side evaluation the node pressures and the flows of pressure-defining
branches are found from the linear MNA system ``A u = b`` given the states (one batched dense
solve; Newton on it for elements nonlinear in the pressures).  Elements are evaluated per
*group* (all elements of one type and options), vectorised over elements and over a batch of
B parameter sets, so there is no per-element Python in the hot path.

Parts that cannot change are kept apart (svZeroDSolver style): the matrix of groups whose
stamps depend neither on states nor on time is built once per parameter set; when every group
is like that, the inverse of A (dense path) or its factorisation (sparse path) is cached and
each evaluation is one product or solve.

Dense path: the flattened (n+1)^2 matrix, local stamps added with :func:`scatter_add` (numpy
only, so a small circuit never imports scipy).  Sparse path (more than
``SPARSE_MIN_UNKNOWNS`` unknowns): the matrix's values on a fixed CSC pattern, splu
factorisations (:mod:`hemocircuit.sparse`, imported on that path only).
"""
from __future__ import annotations

import numpy as np

from ..errors import SolverError, TopologyError
from ..linalg import solve_batched

#: the sparse path (splu factorisations, coloured sparse Jacobians) is taken when the nodal
#: system has more unknowns than this (Circuit.with_sparse_threshold sets another)
SPARSE_MIN_UNKNOWNS = 64

SINGULAR = "the nodal equations are singular (a pressure is undefined)"
SINGULAR_AT_STATE = "the nodal equations are singular at this state (a pressure is undefined)"


def scatter_add(index, size, local):
    """Global contributions (rows, size) of local stamps (rows, ...): entry j of a row is added
    to position index[j], duplicates in order (np.bincount; the same sums, term by term, as a
    sparse 0/1 scatter matrix's product).  Returned as the transpose of a (size, rows) array,
    the layout that product had: numpy's reductions downstream (einsum, the batched solves)
    round by layout, and this keeps every result bit for bit what it was."""
    rows = local.shape[0]
    w = local.reshape(rows, -1)
    if rows == 1:
        return np.bincount(index, weights=w[0], minlength=size)[None]
    off = (index[:, None] * rows + np.arange(rows)[None, :]).reshape(-1)
    return np.bincount(off, weights=w.T.reshape(-1), minlength=rows * size).reshape(size, rows).T


def scatter_rows(index, local, Bx, size):
    """scatter_add for Bx rows of local stamps given as 1 or Bx rows (1 is used for every row)."""
    w = local if local.shape[0] == Bx else np.broadcast_to(local, (Bx,) + local.shape[1:])
    return scatter_add(index, size, w)


def scatter_product(ST, local):
    """Global contributions (rows, N) of local stamps (rows, ...) through a sparse scatter
    matrix (the sparse path's pattern positions, Group.SP_A)."""
    flat = local.reshape(local.shape[0], -1)
    return np.asarray((ST @ flat.T).T)


class Assembly:
    """The nodal system (mixed into :class:`hemocircuit.system.System`): prepares the constant
    part from the circuit's values, assembles A and b at a state, solves them."""

    def _prepare(self):
        """Everything that depends only on the structure and the values (once per object).

        Groups whose stamps depend neither on states nor on time ("static": resistors,
        constant sources) are stamped here once, into A_const and b_const, and skipped by
        every right-hand-side evaluation.
        """
        N1 = self.n + 1
        sparse = self.sparse
        # dense path: the flattened (n+1)^2 matrix; sparse path: its values on the CSC pattern
        self.A_const = np.zeros((self.B, self.structure.sparse_pattern().nnz if sparse else N1 * N1))
        self.b_const = np.zeros((self.B, N1))
        self.all_constant = True
        self.dynamic_groups = []
        # the constant groups' local matrices that the DC network replaces (_const_part): every
        # DC-guess iteration takes them out again (their stamps were ~0.1 ms of a small
        # circuit's operating point).  (rows, E, L, L) each: a fifth of A_const's size on
        # body.yaml with 200 members
        self._dc_replaced = {}
        for g in self.groups:
            # the compiled layout's rule (kernels.layout): an expression may move its right-hand side
            g.static = (g.constant and g.S == 0 and not g.waves and not g.exprs
                        and not g.comp.varies_in_time(g.p))
            if g.constant:
                A_loc, b_loc = g.comp.stamp(g.p, np.zeros((1, g.E, g.S)), None, 0.0, None)
                A_loc = np.broadcast_to(A_loc, (A_loc.shape[0], g.E, g.L, g.L))
                self.A_const = self.A_const + self._scatter_A(g, A_loc)
                if g.comp.has_dc_stamp():
                    self._dc_replaced[g.index] = A_loc
                if g.static:
                    b_loc = np.broadcast_to(b_loc, (b_loc.shape[0], g.E, g.L))
                    self.b_const = self.b_const + scatter_add(g.uidx.reshape(-1), N1, b_loc)
            else:
                self.all_constant = False
            if not g.static:
                self.dynamic_groups.append(g)
        n = self.n
        self.Ainv = None
        self.lu = None  # sparse path: hemocircuit.sparse.Factors
        if sparse:
            from .. import sparse as sparse_la

            self.lu = sparse_la.Factors(self._factor_const() if self.all_constant else None)
        elif self.all_constant:
            A = self.A_const.reshape(-1, N1, N1)[:, :n, :n]
            try:
                self.Ainv = np.linalg.inv(A)
            except np.linalg.LinAlgError:
                raise TopologyError(SINGULAR, file=self.file) from None

    def _scatter_A(self, g, A_loc):
        """The group's local matrix stamps (rows, E, L, L) in the global layout of this path."""
        if self.sparse:
            return scatter_product(g.base.SP_A, A_loc)
        return scatter_add(g.flat, g.N1 * g.N1, A_loc)

    def _factor_const(self):
        """Factorisations of the constant nodal matrix (per member), solved through the explicit
        sparse inverse where it is sparser than a few times the LU factors."""
        import scipy.sparse as sp

        from .. import sparse as sparse_la

        lus = self._factor(self.A_const, SINGULAR)
        pat = self.structure.sparse_pattern()
        nz = np.any(self.A_const != 0, axis=0)
        S = sp.csr_matrix((np.ones(int(nz.sum())), (pat.indices[nz], pat.cols[nz])), shape=(self.n, self.n))
        return sparse_la.with_inverses(lus, S, 3 * max(lu.nnz for lu in lus))

    def _factor(self, data, message):
        """splu factorisations of the matrix rows ``data`` (rows, nnz) on the pattern."""
        from .. import sparse as sparse_la

        try:
            lus = sparse_la.factor_rows(self.structure.sparse_pattern(), data)
        except RuntimeError:  # SuperLU: "Factor is exactly singular"
            raise TopologyError(message, file=self.file) from None
        return lus

    def _rep(self, arr, Bx):
        """Parameter-batch array (B, ...) laid out for a stacked batch of Bx rows."""
        if arr.shape[0] == Bx or arr.shape[0] == 1:
            return arr
        return np.repeat(arr, Bx // arr.shape[0], axis=0)

    def _assemble(self, t, x, plist, dc=False, u=None):
        """Stamp the non-static groups onto the cached static part.

        Returns (A (Bx,n,n), or None when the cached inverse applies; b (Bx,n); per-group
        stamps (None for static groups)).
        """
        Bx = x.shape[0]
        N1 = self.n + 1
        b = np.array(np.broadcast_to(self._rep(self.b_const, Bx), (Bx, N1)))
        need_A = dc or not self.all_constant
        sparse = self.sparse
        if sparse:  # values on the pattern, one row, or one per batch row (never copied per row)
            A = self._rep(self.A_const, Bx) if need_A else None
        else:
            A = np.array(np.broadcast_to(self._rep(self.A_const, Bx), (Bx, N1 * N1))) if need_A else None
        stamps = [None] * len(self.groups)
        for k, (g, p) in enumerate(zip(self.groups, plist)):
            # a static group is in A_const and b_const already; in the DC network too, unless
            # its DC stamp differs
            if g.static and not (dc and g.comp.has_dc_stamp()):
                continue
            xl = x[:, g.sidx]
            src = g.source_values(t, Bx) if g.waves else None
            # u: the current pressure iterate, for elements that are nonlinear in the pressures
            ul = None if (u is None or g.comp.linear_in_pressure) else u[:, g.uidx]
            A_loc, b_loc = g.comp.stamp(p, xl, ul, t, src)
            if A_loc.ndim != 4 or A_loc.shape[1] != g.E:
                A_loc = np.broadcast_to(A_loc, (A_loc.shape[0], g.E, g.L, g.L))
            if b_loc.shape[1:] != (g.E, g.L):
                b_loc = np.broadcast_to(b_loc, (b_loc.shape[0], g.E, g.L))
            if dc and g.comp.has_dc_stamp():
                A_loc, b_loc = self._dc_stamp(g, p, A_loc, b_loc)
                A = A + self._scatter_A(g, A_loc)
                if g.constant:
                    A = A - self._const_part(g, Bx)
            elif need_A and not g.constant:
                A = A + self._scatter_A(g, A_loc)
            if not g.static:  # static groups are already in b_const
                if sparse:
                    b += scatter_rows(g.uidx.reshape(-1), b_loc, Bx, N1)
                else:
                    b = b + scatter_add(g.uidx.reshape(-1), N1, b_loc)
            stamps[k] = (A_loc, b_loc, src)
        n = self.n
        if A is not None and not sparse:
            A = A.reshape(Bx, N1, N1)[:, :n, :n]
        return A, b[:, :n], stamps

    @property
    def nonlinear(self):
        """True if some element is nonlinear in the pressures (Newton on the nodal equations)."""
        return any(not g.comp.linear_in_pressure for g in self.groups)

    def _newton_pressures(self, t, x, plist, dc, u, tol=1e-12, max_iter=50):
        """Newton on the nodal equations: such elements stamp their linearisation at the
        current pressures (A_loc = d flow/d P, b_loc so that A_loc u - b_loc = flow(u))."""
        for _ in range(max_iter):
            A, b, stamps = self._assemble(t, x, plist, dc=dc, u=u)
            u_new = self._solve(A, b)
            done = np.max(np.abs(u_new - u) / (1.0 + np.abs(u_new))) < tol
            u = u_new
            if done:
                return u, stamps
        raise SolverError(f"the nodal equations did not converge in {max_iter} Newton iterations "
                          "(an element nonlinear in the pressures)", time=float(np.ravel(t)[0]) if np.ndim(t) else t)

    def _const_part(self, g, Bx):
        """A constant group's part of A_const (its stamp kept by _prepare), for Bx rows."""
        return self._rep(self._scatter_A(g, self._dc_replaced[g.index]), Bx)

    def _dc_stamp(self, g, p, A_loc, b_loc):
        """The group's stamp in the DC-guess network (Component.dc_stamp, on writable copies).
        One store per conservation law keeps its stamp: it anchors the pressure of a node
        group that is otherwise joined to the circuit only through open stores."""
        keep = np.zeros(g.E, dtype=bool)
        for s in self.law_specs:
            gg, i = s["anchor"]
            if gg is g:
                keep[i] = True
        return g.comp.dc_stamp(p, np.array(A_loc), np.array(b_loc), keep)

    def _solve(self, A, b):
        """Node pressures and branch flows (Bx, n + 1; the ground slot last) from the assembled
        system: A None (the cached inverse / factorisation applies), a dense stack (Bx, n, n),
        or on the sparse path the values (1 or Bx, nnz) on the pattern."""
        if self.sparse:
            u = self._solve_sparse(A, b)
        elif A is None:
            Ainv = self.Ainv
            if Ainv.shape[0] != b.shape[0]:
                Ainv = np.repeat(Ainv, b.shape[0] // Ainv.shape[0], axis=0)
            u = np.einsum("bij,bj->bi", Ainv, b)
        else:
            try:
                u = solve_batched(A, b)
            except np.linalg.LinAlgError:
                u = np.full(b.shape, np.nan)
            if not np.all(np.isfinite(u)):
                raise TopologyError(SINGULAR_AT_STATE, file=self.file)
        return np.concatenate([u, np.zeros((u.shape[0], 1))], axis=1)  # + ground slot

    def _solve_sparse(self, A, b):
        """The batch rows of b are the columns of one solve per factorisation."""
        from .. import sparse as sparse_la

        if A is None:
            if self.lu.lus is None:  # unpickled: factorise again
                self.lu = sparse_la.Factors(self._factor_const())
            lus = self.lu.lus
        else:
            lus = self._factor(A, SINGULAR_AT_STATE)
        u = sparse_la.solve_rows(lus, b)
        if not np.all(np.isfinite(u)):
            raise TopologyError(SINGULAR_AT_STATE, file=self.file)
        return u
