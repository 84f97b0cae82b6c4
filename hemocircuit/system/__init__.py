"""The System: a circuit's equations with values, between the immutable
:class:`~hemocircuit.circuit.Circuit` (structure, values, variants) and the integrators.

One interface for every path that evaluates a circuit:

* parameters: the per-group parameter dicts of a batch (:meth:`System.group_params`), with
  expression-bound values filled in at a state; the compiled engine's parameter matrix
  (``compiled().params(circuit)``);
* ``rhs`` / ``evaluate`` (dx/dt of a stacked batch), ``jacobian`` (dense, or coloured sparse
  on the sparse path) and ``jacobian_plan``, ``outputs`` (every output column), the nodal
  unknowns of the DC network (``dc_unknowns``) and the nodal matrix (``nodal_matrix``);
* the choice of engine (:meth:`System.compiled`): the compiled engine
  (``hemocircuit.kernels.system.CompiledSystem``, numba) when every component type has a
  kernel and the nodal system is small enough, else None and these numpy evaluations (with
  scipy's or the batch integrator's steps).  The transient analysis, the batch integrator
  and the outputs ask here; what a run may wait for (a first compilation) they decide.

A System is made once per circuit object (``Circuit.system``) and prepares what follows from
the values: the constant part of the nodal matrix and its inverse or factorisations (see
:mod:`.assembly`).  Its caches (Jacobian patterns, repeated parameter layouts) die with it.
Modules: ``assembly`` (nodal system), ``jacobians``, ``outputs``.
"""
from __future__ import annotations

import numpy as np

from ..errors import HemocircuitError
from .assembly import SPARSE_MIN_UNKNOWNS, Assembly
from .jacobians import Jacobians
from .outputs import COMPILED_OUTPUT_ROWS, Outputs

__all__ = ["System", "SPARSE_MIN_UNKNOWNS", "COMPILED_OUTPUT_ROWS"]


class System(Assembly, Jacobians, Outputs):
    """The equations of one circuit object (structure and values) and how to evaluate them."""

    def __init__(self, circuit, prepared=None, members=None):
        """``prepared``/``members``: a subset of another system's batch members, sharing its
        prepared matrices (sliced) instead of preparing them again."""
        self.circuit = circuit
        self.structure = circuit.structure
        self.groups = circuit.groups
        self.law_specs = circuit.law_specs
        self.B, self.n, self.nx = circuit.B, circuit.n, circuit.nx
        self.file, self.nodes, self.state_scales = circuit.file, circuit.nodes, circuit.state_scales
        self.sparse = circuit.sparse
        self.jac_plans = {}  # Jacobian sparsity patterns (sparse path) for these parameters
        self.rep_cache = {}
        if prepared is None:
            self._prepare()
        else:
            self._take_subset(prepared, members)

    def subset(self, circuit, members) -> "System":
        """The system of ``circuit``, the batch members ``members`` of this one (same flags,
        the prepared matrices sliced)."""
        return System(circuit, self, members)

    def _take_subset(self, full, members):
        for ng, g in zip(self.groups, full.groups):  # prepared from the whole batch: same flags
            ng.static = g.static
        self.all_constant = full.all_constant
        self.dynamic_groups = [self.groups[g.index] for g in full.dynamic_groups]
        self.A_const = full.A_const[members] if full.A_const.shape[0] > 1 else full.A_const
        self.b_const = full.b_const[members] if full.b_const.shape[0] > 1 else full.b_const
        self._dc_replaced = {k: (a[members] if a.shape[0] > 1 else a) for k, a in full._dc_replaced.items()}
        Ainv = full.Ainv
        self.Ainv = None if Ainv is None else (Ainv[members] if Ainv.shape[0] > 1 else Ainv)
        self.lu = None if full.lu is None else full.lu.subset(members)

    def __getstate__(self):
        return {**self.__dict__, "jac_plans": {}, "rep_cache": {}}

    # ---------------------------------------------------------------- engines ----------
    def compiled(self):
        """The compiled engine of this circuit (``hemocircuit.kernels.system.CompiledSystem``:
        rhs, Jacobian, nodal outputs and the integrators in numba, with the values as a
        parameter matrix), or None when a component type has no kernel or the nodal system is
        too large.  Building it writes (or finds) the engine module; compiling happens on its
        first call."""
        from ..kernels.system import CompiledSystem

        return CompiledSystem.of(self.circuit)

    # ------------------------------------------------------------- parameters ----------
    def group_params(self, rows=None):
        """Per-group parameter dicts laid out for ``rows`` state rows (a multiple of the batch
        size B; default B)."""
        return self._params(1) if rows is None or rows == self.B else self._params_for(rows)

    def _params(self, rep):
        """Parameter dicts for a stacked batch in which each member appears ``rep`` times."""
        if rep == 1:
            return [g.p for g in self.groups]
        if rep not in self.rep_cache:
            self.rep_cache[rep] = [{k: (np.repeat(v, rep, axis=0) if v.shape[0] > 1 else v) for k, v in g.p.items()}
                                   for g in self.groups]
        return self.rep_cache[rep]

    def _params_for(self, Bx):
        if Bx % self.B:
            raise HemocircuitError(f"state batch {Bx} is not a multiple of the parameter batch {self.B}")
        return self._params(Bx // self.B)

    def bound_params(self, x, plist, t):
        """Parameters ``plist`` with expression-bound values filled in for states x."""
        if not any(g.exprs for g in self.groups):
            return plist
        locate = self.circuit.element_group
        Bx = x.shape[0]
        need = {}
        for g in self.groups:
            for _, _, ex in g.exprs:
                for key, ref in ex.refs.items():
                    if ref.kind == "observable":
                        need[ref.element] = True
        obs = {}
        for eid in need:
            g, i = locate(eid)
            p = plist[self.groups.index(g)]
            obs[eid] = (g.comp.observe(p, x[:, g.sidx], None, t), i)
        out = []
        for g, p in zip(self.groups, plist):
            if not g.exprs:
                out.append(p)
                continue
            p = dict(p)
            for i, name, ex in g.exprs:
                vals = {}
                for key, ref in ex.refs.items():
                    if ref.kind == "param":
                        og, oi = locate(ref.element)
                        vals[key] = plist[self.groups.index(og)][ref.name][:, oi]
                        # a waveform's value adds to the parameter it is on before an expression
                        # reads it (as the engine's effective_params does)
                        if og.waves and ref.name in og.comp.waveform_params:
                            vals[key] = vals[key] + og.source_values(t, Bx)[:, oi]
                    elif ref.kind == "observable":
                        o, oi = obs[ref.element]
                        vals[key] = o[ref.name][:, oi]
                v = np.broadcast_to(ex.evaluate(vals), (Bx,))
                arr = np.array(np.broadcast_to(p[name], (Bx, g.E)))
                arr[:, i] = v
                p[name] = arr
            out.append(p)
        return out

    # ------------------------------------------------------------- evaluation ----------
    def evaluate(self, t, x, dc=False, want="rhs"):
        """Core evaluation for a stacked batch x (Bx, nx).

        Returns dx/dt (Bx, nx) for want='rhs', or for want='u' (u (Bx, n+1), bound
        parameters, per-group stamps) for outputs.
        """
        x = np.asarray(x, dtype=float)
        if x.ndim == 1:
            x = x[None, :]
        Bx = x.shape[0]
        plist = self.bound_params(x, self._params_for(Bx), t)
        A, b, stamps = self._assemble(t, x, plist, dc=dc)
        u = self._solve(A, b)
        if self.nonlinear:
            u, stamps = self._newton_pressures(t, x, plist, dc, u)
        if want == "u":
            return u, plist, stamps
        dx = np.empty((Bx, self.nx))
        for g, p, st in zip(self.groups, plist, stamps):
            if g.S == 0:
                continue
            dx[:, g.sidx] = g.comp.derivatives(p, x[:, g.sidx], u[:, g.uidx], t, st[2])
        return dx

    def rhs(self, t, x):
        """dx/dt for a single run (x of shape (nx,)) or a batch (B, nx)."""
        if np.ndim(x) == 1:
            return self.evaluate(t, x)[0]
        return self.evaluate(t, x)

    def dc_unknowns(self, t, X):
        """Nodal unknowns of the DC network (stores open, inductors shorted: each component's
        ``dc_stamp``) for states X (B, nx).  Returns (u (B, n+1), bound parameters, stamps)."""
        plist = self.bound_params(X, self._params(1), t)
        A, b, stamps = self._assemble(t, X, plist, dc=True)
        return self._solve(A, b), plist, stamps

    def nodal_matrix(self, t, X):
        """The nodal matrix A (Bx, n, n) of A u = b at states X (Bx, nx) (dense path; for
        hemocircuit.derivatives)."""
        X = np.atleast_2d(np.asarray(X, dtype=float))
        Bx, n, N1 = X.shape[0], self.n, self.n + 1
        if self.sparse:
            raise HemocircuitError("nodal_matrix: this circuit runs on the sparse path")
        if self.all_constant:
            A = self._rep(self.A_const, Bx).reshape(-1, N1, N1)[:, :n, :n]
            return np.broadcast_to(A, (Bx, n, n))
        A, _, _ = self._assemble(t, X, self.bound_params(X, self._params_for(Bx), t))
        return A

    def state_observables(self, x, plist, t=0.0):
        """{id(group): the group's observables without pressures} for states x."""
        out = {}
        for g, p in zip(self.groups, plist):
            xl = x[:, g.sidx]
            out[id(g)] = g.comp.observe(p, xl, None, t)
        return out

    def law_volumes(self, x):
        """Conserved combinations sum(sign * V) for states x (B', nx) -> list of (B',) arrays."""
        out = []
        if not self.law_specs:
            return out
        x = np.atleast_2d(x)
        obs = self.state_observables(x, self._params(1) if x.shape[0] == self.B else self._params_for(x.shape[0]))
        for s in self.law_specs:
            total = 0.0
            for g, i, vol, sign in s["terms"]:
                total = total + sign * obs[id(g)][vol][:, i]
            out.append(total)
        return out
