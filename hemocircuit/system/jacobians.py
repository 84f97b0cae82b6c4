"""State Jacobians of a circuit's right-hand side: dense from one batched evaluation, or on the
sparse path coloured finite differences on a pattern derived once per parameter set
(structurally from the elements' incidence, numerically as a fallback).  The step rule is
:mod:`hemocircuit.derivatives`'s; the sparse machinery is :mod:`hemocircuit.sparse`."""
from __future__ import annotations

import numpy as np


class Jacobians:
    """Jacobians (mixed into :class:`hemocircuit.system.System`)."""

    def jacobian(self, t, x):
        """Finite-difference Jacobian d(dx/dt)/dx, all columns from one batched evaluation.

        x: (nx,) -> (nx, nx); or (B, nx) -> (B, nx, nx).
        On the sparse path (see ``Circuit.sparse``): a ``scipy.sparse.csc_matrix`` (nx, nx), or a
        list of B of them, by coloured finite differences (see :meth:`sparse_jacobian`).
        """
        if self.sparse:
            Js = self.sparse_jacobian(t, x)[0]
            return Js[0] if np.ndim(x) == 1 else Js
        from ..derivatives import dense_jacobian

        single = np.ndim(x) == 1
        J, _ = dense_jacobian(lambda rows: self.evaluate(t, rows), x, self.state_scales)
        return J[0] if single else J

    def jacobian_plan(self, key, fun, X, t=0.0, row_reads=None, how="auto"):
        """The Jacobian sparsity pattern and column colouring of ``fun`` (rows (m, nx) ->
        (m, nx), the right-hand side or the operating point's residual), once per parameter
        set and structural option set under ``key``.

        Structural (how='auto' or 'structural'): from the elements' incidence and the generic
        structure of the nodal matrix's inverse (:func:`hemocircuit.sparse.structural_pattern`),
        valid at every state.  ``row_reads`` {state row: (element ids whose states it reads,
        nodal unknowns it reads)} replaces rows that are not the element's own equation (the
        operating point's conservation-law rows).  Numerical (how='numerical', or when the
        nodal matrix is structurally singular): finite differences at X in column blocks.
        """
        from .. import sparse as sparse_la

        key = (key, how, tuple(tuple(sorted((k, repr(v)) for k, v in g.comp.opts.items())) for g in self.groups))
        plans = self.jac_plans
        if key not in plans:
            X = np.atleast_2d(np.asarray(X, dtype=float))
            rc = self._structural_pattern(t, X, row_reads) if how != "numerical" else None
            if rc is None:
                width = self.n + 1 + sum(g.E * g.L * (g.L + 1) for g in self.groups)
                plans[key] = sparse_la.detect_pattern(fun, X, self.state_scales, width)
            else:
                diag = np.arange(self.nx)
                plans[key] = sparse_la.JacobianPlan(self.nx, np.concatenate([rc[0], diag]),
                                                    np.concatenate([rc[1], diag]), "structural")
        return plans[key]

    def _structural_pattern(self, t, X, row_reads=None):
        """(rows, cols) of the structural Jacobian pattern (see jacobian_plan) or None."""
        import scipy.sparse as sp

        from .. import sparse as sparse_la

        n, nx = self.n, self.nx
        pat = self.structure.sparse_pattern()
        # nonzero structure of the nodal matrix: the constant part's values, and each other
        # group's local nonzeros (at these states, any element) at every element of the group
        A_const = self.A_const if self.sparse else None
        if A_const is not None:
            nzc = np.any(A_const != 0, axis=0)
            rows, cols = [pat.indices[nzc]], [pat.cols[nzc]]
        else:  # dense layout (n+1)^2
            flat = np.nonzero(np.any(self.A_const != 0, axis=0))[0]
            rows, cols = [flat // (n + 1)], [flat % (n + 1)]
        _, _, stamps = self.evaluate(t, X, want="u")
        for g, st in zip(self.groups, stamps):
            if st is None or g.constant:
                continue
            m = np.any(np.asarray(st[0]) != 0, axis=tuple(range(np.ndim(st[0]) - 2)))  # (L, L)
            rows.append(g.rows[:, m].reshape(-1))
            cols.append(g.cols[:, m].reshape(-1))
        r, c = np.concatenate(rows), np.concatenate(cols)
        inside = (r < n) & (c < n)
        S = sp.csr_matrix((np.ones(int(inside.sum())), (r[inside], c[inside])), shape=(n, n))
        own, unk, infl, eidx = self.structure.incidence()
        read = own @ unk  # (nx, n)
        infl_rows = unk.T @ infl  # (n, nx)
        direct = own @ infl  # (nx, nx)
        if row_reads:
            keep = np.ones(nx)
            keep[list(row_reads)] = 0.0
            K = sp.diags(keep)
            rr, rc_, dr, dc_ = [], [], [], []
            for row, (eids, unknowns) in row_reads.items():
                for eid in eids:
                    st = infl[eidx[eid]].indices
                    dr += [row] * st.size
                    dc_ += list(st)
                rr += [row] * len(unknowns)
                rc_ += list(unknowns)
            read = K @ read + sp.csr_matrix((np.ones(len(rr)), (rr, rc_)), shape=(nx, n))
            direct = K @ direct + sp.csr_matrix((np.ones(len(dr)), (dr, dc_)), shape=(nx, nx))
        return sparse_la.structural_pattern(S, read, infl_rows, direct)

    def sparse_jacobian(self, t, x):
        """Coloured finite-difference Jacobians d(dx/dt)/dx at x (nx,) or (B, nx): returns
        ([csc_matrix (nx, nx)] per member, dx/dt (B, nx)).  Same steps as :meth:`jacobian`."""
        from .. import sparse as sparse_la

        X = np.atleast_2d(np.asarray(x, dtype=float))

        def fun(rows):
            return self.evaluate(t, rows)

        plan = self.jacobian_plan("rhs", fun, X, t)
        return sparse_la.coloured_jacobian(fun, X, self.state_scales, plan)
