"""Sparse linear algebra for large circuits: LU factorisations of the nodal matrix and
coloured finite-difference Jacobians.

Used by :class:`hemocircuit.system.System` when the nodal system has more unknowns than
``Circuit.sparse_threshold`` (see ``hemocircuit.system.SPARSE_MIN_UNKNOWNS``) and by the
operating point; imported only then (it loads scipy.sparse).  Nothing here allocates an
n x n (or nx x nx) dense array:

* the nodal matrix lives on a fixed CSC pattern (the union of every element's local stamp
  block); its values are a (rows, nnz) array, factorised with ``scipy.sparse.linalg.splu``;
  many right-hand sides (batch rows) are solved through one factorisation as columns; a
  constant matrix whose inverse is structurally sparse is solved through that explicit sparse
  inverse (one sparse product per evaluation);
* the Jacobian's sparsity pattern is derived structurally (the generic structure of the nodal
  matrix's inverse, see :func:`structural_pattern`; numerically, in column blocks of bounded
  memory, only as a fallback), its columns are grouped so that no two in a group share a row
  (greedy colouring), and each Jacobian is then ``colours + 1`` evaluations of the right-hand
  side, returned as a ``scipy.sparse.csc_matrix``.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from .derivatives import fd_steps

#: rows x columns of the largest array a pattern-detection block may create (~16 MB of floats)
BLOCK_ELEMENTS = 2_000_000
#: relative perturbation used to detect the Jacobian's pattern (larger than the one of the
#: derivative itself, so that a dependence stands well above rounding noise)
PATTERN_STEP = 1e-4
#: entries below this fraction of the largest entry of their row count as rounding noise
PATTERN_RTOL = 1e-11


class Factors:
    """splu factorisations of one matrix per batch member (or one shared by all members).

    Copies share it (the factors are read-only and tied to parameter values that a copy
    shares until its System prepares new ones); pickling drops the factors (SuperLU objects
    do not pickle) and the owner refactorises lazily.
    """

    def __init__(self, lus=None):
        self.lus = lus

    def __deepcopy__(self, memo):
        return self

    def __reduce__(self):
        return (Factors, ())

    def subset(self, members):
        if self.lus is None or len(self.lus) == 1:
            return Factors(self.lus)
        return Factors([self.lus[m] for m in members])


class InverseLU:
    """A factorisation whose solves go through the explicit sparse inverse (see
    sparse_inverse); ``lu`` keeps the SuperLU object."""

    def __init__(self, lu, inv):
        self.lu, self.inv = lu, inv

    def solve(self, rhs):
        return self.inv @ rhs

    def solve_rows(self, b):
        return np.asarray((self.inv @ b.T).T) if b.shape[0] > 1 else (self.inv @ b[0])[None]


def with_inverses(lus, S, max_nnz):
    """lus with each factorisation replaced by an InverseLU where the inverse is sparse enough."""
    seen = {}
    out = []
    for lu in lus:
        if id(lu) not in seen:
            inv = sparse_inverse(S, lu, max_nnz)
            seen[id(lu)] = lu if inv is None else InverseLU(lu, inv)
        out.append(seen[id(lu)])
    return out


class Pattern:
    """A fixed CSC sparsity pattern of an n x n matrix."""

    def __init__(self, n, rows, cols):
        key = np.unique(np.asarray(cols, dtype=np.int64) * n + np.asarray(rows, dtype=np.int64))
        self.n = n
        self.indices = (key % n).astype(np.int32)
        col = key // n
        self.indptr = np.concatenate([[0], np.cumsum(np.bincount(col, minlength=n))]).astype(np.int32)
        self.cols = col.astype(np.int64)
        self.nnz = key.size
        self._key = key

    def position(self, rows, cols):
        """Data index of each (row, col) pair (all must be in the pattern)."""
        return np.searchsorted(self._key, np.asarray(cols, dtype=np.int64) * self.n + rows)

    def matrix(self, data):
        return sp.csc_matrix((data, self.indices, self.indptr), shape=(self.n, self.n))


def factor(pattern, data):
    """splu of the matrix with values ``data`` (nnz,) on ``pattern``.  RuntimeError if singular."""
    return splu(pattern.matrix(np.asarray(data, dtype=float)))


def factor_rows(pattern, data):
    """Factorisations of every row of ``data`` (rows, nnz); identical rows share one."""
    if data.shape[0] == 1:
        return [factor(pattern, data[0])]
    seen, out = {}, []
    for r in range(data.shape[0]):
        key = data[r].tobytes()
        if key not in seen:
            seen[key] = factor(pattern, data[r])
        out.append(seen[key])
    return out


def _solve_columns(lu, b):
    """lu.solve for the rows of b (k, n) as columns, in blocks that keep SuperLU's work array
    in cache (blocks of more than ~64 K numbers are several times slower per column)."""
    if isinstance(lu, InverseLU):
        return lu.solve_rows(b)
    k, n = b.shape
    if k == 1:
        return lu.solve(b[0])[None]
    blk = int(min(64, max(8, 65536 // max(n, 1))))
    out = np.empty((k, n))
    for i in range(0, k, blk):
        out[i:i + blk] = lu.solve(np.asfortranarray(b[i:i + blk].T)).T
    return out


def solve_rows(lus, b):
    """u (Bx, n) with M_r u_r = b_r, where row r uses ``lus[r // (Bx // len(lus))]``."""
    Bx = b.shape[0]
    if len(lus) == 1:
        return _solve_columns(lus[0], b)
    rep = Bx // len(lus)
    u = np.empty_like(b)
    start = 0
    while start < Bx:  # consecutive rows that share one factorisation form one solve
        lu = lus[start // rep]
        stop = start + rep
        while stop < Bx and lus[stop // rep] is lu:
            stop += rep
        u[start:stop] = _solve_columns(lu, b[start:stop])
        start = stop
    return u


# ----------------------------------------------------------------- Jacobians ---------------
def greedy_colouring(P):
    """Column groups of the sparse pattern P (rows x cols) such that no two columns of a group
    have an entry in the same row.  Returns (group index per column, number of groups)."""
    P = sp.csc_matrix(P)
    try:  # scipy's own (compiled) greedy grouping
        from scipy.optimize._numdiff import group_columns
        ncol = P.shape[1]
        best = None
        for order in (np.arange(ncol), 0):  # natural order (optimal for banded), then random
            groups = np.asarray(group_columns(P, order), dtype=np.int64)
            if best is None or groups.max(initial=-1) < best.max(initial=-1):
                best = groups
        return best, int(best.max()) + 1 if best.size else 0
    except Exception:  # pragma: no cover - private scipy API moved
        pass
    ncol = P.shape[1]
    groups = np.full(ncol, -1, dtype=np.int64)
    rows_of = [P.indices[P.indptr[j]:P.indptr[j + 1]] for j in range(ncol)]
    used = []  # per group: boolean row occupancy
    for j in range(ncol):
        for k, occ in enumerate(used):
            if not occ[rows_of[j]].any():
                groups[j] = k
                occ[rows_of[j]] = True
                break
        else:
            occ = np.zeros(P.shape[0], bool)
            occ[rows_of[j]] = True
            used.append(occ)
            groups[j] = len(used) - 1
    return groups, len(used)


class JacobianPlan:
    """The Jacobian's sparsity pattern (CSC) and its column colouring."""

    def __init__(self, nx, rows, cols, how=""):
        self.nx = nx
        self.how = how  # 'structural' or 'numerical'
        self.pattern = Pattern(nx, rows, cols)
        P = self.pattern.matrix(np.ones(self.pattern.nnz))
        self.groups, self.ncolours = greedy_colouring(P)

    @property
    def nnz(self):
        return self.pattern.nnz


def _bool(M):
    M = sp.csr_matrix(M)
    M.sum_duplicates()
    M.data[:] = 1.0
    M.eliminate_zeros()
    return M


def _matched_digraph(S):
    """(G, P) for the generic structure of A^-1 (A of structure S, n x n), or None if A is
    structurally singular: with a perfect matching of rows and columns (row(k) matched to
    column k), u_k depends on b_r iff there is a path row(k) -> ... -> r in the digraph
    G[p, q] = A[p, col(q)] != 0 (Gilbert; exact unless values cancel).  P[k, row(k)] = 1."""
    from scipy.sparse.csgraph import maximum_bipartite_matching

    S = _bool(S)
    n = S.shape[0]
    col_of_row = maximum_bipartite_matching(S, perm_type="column")
    if np.any(col_of_row < 0):
        return None
    row_of_col = np.empty(n, dtype=np.int64)
    row_of_col[col_of_row] = np.arange(n)
    G = _bool(S[:, col_of_row])
    P = sp.csr_matrix((np.ones(n), (np.arange(n), row_of_col)), shape=(n, n))
    return G, P


def _closure(T, G, max_nnz=None):
    """T (I + G + G^2 + ...) as a 0/1 matrix; None once it has more than max_nnz entries."""
    T = _bool(T)
    while True:
        Tn = _bool(T + T @ G)
        if max_nnz is not None and Tn.nnz > max_nnz:
            return None
        if Tn.nnz == T.nnz:
            return T
        T = Tn


def structural_pattern(S, read, infl_rows, direct):
    """Every entry of a Jacobian of the form dF/dx with F_i = f_i(x, u), A(x) u = b(x), that
    can be nonzero for some values (a superset of the numerical pattern, valid at every state).

    S (n, n): nonzero structure of the nodal matrix A.  read (nx, n): unknowns that row i of F
    reads.  infl_rows (n, nx): equations (rows of A, b) that state j enters.  direct (nx, nx):
    states that row i reads directly.  u_k depends on the equations r reachable from row(k)
    (see _matched_digraph).  Returns (rows, cols) of the pattern, or None if A is structurally
    singular.
    """
    gp = _matched_digraph(S)
    if gp is None:
        return None
    G, P = gp
    T = _closure(sp.csr_matrix(read) @ P, G)  # (nx, rows): only from the rows needed
    J = _bool(T @ sp.csr_matrix(infl_rows) + sp.csr_matrix(direct)).tocoo()
    return J.row, J.col


def sparse_inverse(S, lu, max_nnz):
    """The explicit inverse of the factorised matrix on its structural pattern (CSR), when that
    pattern has at most ``max_nnz`` entries and few column colours; else None.

    Columns of A^-1 that share no row are found together (one solve of the sum of their unit
    vectors, as in coloured finite differences, but exact): u = A^-1 b is then one sparse
    matrix-vector product, several times cheaper than SuperLU's triangular solves for the
    very sparse inverses of circuits whose stores fix their node pressures (a ladder: ~2.5 n
    entries).  Entries off the pattern are zero in exact arithmetic.
    """
    gp = _matched_digraph(S)
    if gp is None:
        return None
    G, P = gp
    n = S.shape[0]
    T = _closure(P, G, max_nnz)
    if T is None:
        return None
    groups, k = greedy_colouring(T)
    if k * n > BLOCK_ELEMENTS:
        return None
    rhs = np.zeros((n, k))
    rhs[np.arange(n), groups] = 1.0
    X = lu.solve(rhs)
    T = T.tocoo()
    return sp.csr_matrix((X[T.row, groups[T.col]], (T.row, T.col)), shape=(n, n))


def detect_pattern(fun, X, scales, width):
    """Numerical sparsity pattern of d fun/dx at the batch X (B, nx), union over members.

    ``fun`` maps stacked rows (m, nx) -> (m, nx).  Columns are perturbed in blocks so that no
    evaluation has more than about BLOCK_ELEMENTS numbers per array (``width``: the widest
    per-row array of one evaluation, e.g. the number of nodal unknowns).  The diagonal is
    always included.  Returns a :class:`JacobianPlan`.
    """
    X = np.atleast_2d(np.asarray(X, dtype=float))
    B, nx = X.shape
    F0 = fun(X)
    h = PATTERN_STEP * np.maximum(np.abs(X), scales)
    h = (X + h) - X
    blk = int(max(1, min(nx, BLOCK_ELEMENTS // max(1, B * max(width, nx)))))
    rows, cols, vals = [], [], []
    for j0 in range(0, nx, blk):
        j1 = min(nx, j0 + blk)
        c = j1 - j0
        stack = np.repeat(X[:, None, :], c, axis=1)  # (B, c, nx)
        k = np.arange(c)
        stack[:, k, j0 + k] += h[:, j0:j1]
        F = fun(stack.reshape(B * c, nx)).reshape(B, c, nx)
        D = np.abs(F - F0[:, None, :]) / h[:, j0:j1, None]  # (B, col, row)
        D[~np.isfinite(D)] = np.inf  # a failing evaluation: keep the dependence
        D = D.max(axis=0)
        cc, rr = np.nonzero(D)
        rows.append(rr)
        cols.append(cc + j0)
        vals.append(D[cc, rr])
    rows = np.concatenate(rows) if rows else np.zeros(0, np.int64)
    cols = np.concatenate(cols) if cols else np.zeros(0, np.int64)
    vals = np.concatenate(vals) if vals else np.zeros(0)
    if rows.size:
        rowmax = np.zeros(nx)
        np.maximum.at(rowmax, rows, vals)
        keep = vals > PATTERN_RTOL * rowmax[rows]
        rows, cols = rows[keep], cols[keep]
    diag = np.arange(nx)
    return JacobianPlan(nx, np.concatenate([rows, diag]), np.concatenate([cols, diag]), "numerical")


def coloured_jacobian(fun, X, scales, plan):
    """Finite-difference Jacobians at every member of X (B, nx) from ONE evaluation of
    B * (colours + 1) stacked rows.  Returns ([csc_matrix (nx, nx)] * B, F(X) (B, nx)).

    The steps are hemocircuit.derivatives' (those of the dense Jacobian)."""
    X = np.atleast_2d(np.asarray(X, dtype=float))
    B, nx = X.shape
    h = fd_steps(X, scales)
    K = plan.ncolours
    stack = np.repeat(X[:, None, :], K + 1, axis=1)  # (B, K+1, nx)
    idx = np.arange(nx)
    stack[:, plan.groups + 1, idx] += h
    F = fun(stack.reshape(B * (K + 1), nx)).reshape(B, K + 1, nx)
    pat = plan.pattern
    rows, cols = pat.indices, pat.cols
    out = []
    for b in range(B):
        data = (F[b, plan.groups[cols] + 1, rows] - F[b, 0, rows]) / h[b, cols]
        out.append(pat.matrix(data))
    return out, F[:, 0, :]
