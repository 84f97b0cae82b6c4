"""Every output column of a circuit (pressures, flows, states, observables) for a series of
states: the numpy evaluation, the compiled engine's nodal solve when this process already runs
compiled code, or, for large circuits, a chunked group-by-group fill.  The columns and their
order are ``Circuit.columns()``."""
from __future__ import annotations

import sys

import numpy as np

from ..errors import HemocircuitError

#: outputs() of at least this many rows take the nodal solution from the compiled engine when
#: it is built (below, a call's fixed cost outweighs what it saves)
COMPILED_OUTPUT_ROWS = 64

#: numbers in the arrays of one chunk of the large-circuit outputs (~64 MB of floats, in all)
OUTPUT_ELEMENTS = 8_000_000


class Outputs:
    """outputs() (mixed into :class:`hemocircuit.system.System`)."""

    def outputs(self, t, x, engine="auto") -> dict:
        """All outputs for states x (T, nx) at times t (T,) -> {column name: (T,) array}.

        Evaluated for all times at once (the time series is treated as a batch).  ``engine``
        'auto': from COMPILED_OUTPUT_ROWS rows on, the nodal solution and flows come from the
        compiled engine when this process already runs compiled code and the function is compiled
        (kernels.system.CompiledSystem.nodal_outputs; the same values to rounding, vasomotion's
        10 001 rows in 17 ms instead of 30 ms); 'numpy': always the numpy evaluation.
        """
        x = np.atleast_2d(np.asarray(x, dtype=float))
        T = x.shape[0]
        if self.sparse and self.B == 1 and T > 1:  # large circuits: vectorised, in bounded chunks
            out = self._outputs_sparse(t, x)
            if out is not None:
                return out
        tt = np.broadcast_to(np.asarray(t, dtype=float), (T,)).reshape(T, 1) if np.ndim(t) else float(t)
        if self.B != 1 and T % self.B:
            raise HemocircuitError("outputs() of a batch circuit needs one member's parameters: use member(k)")
        if engine not in ("auto", "numpy"):
            raise ValueError(f"engine {engine!r}: choose 'auto' or 'numpy'")
        nodal = self._compiled_nodal(tt, x) if engine == "auto" and T >= COMPILED_OUTPUT_ROWS else None
        if nodal is None:
            u, plist, stamps = self.evaluate(tt, x, want="u")
        else:  # the same u and flows from the compiled engine
            u, F = nodal
            plist, stamps = self.bound_params(x, self._params_for(T), tt), [None] * len(self.groups)
        out = {}
        for j, n in enumerate(self.nodes):
            if ":" not in n:
                out[f"P({n})"] = u[:, j]
        e0 = 0  # the group's first element in the compiled engine's numbering (group order)
        for g, p, st in zip(self.groups, plist, stamps):
            ul = u[:, g.uidx]
            if nodal is not None:
                flows, src = nodal[1][:, e0:e0 + g.E], (g.source_values(tt, T) if g.waves else None)
            else:
                if st is None:  # static group: stamp it for the flows
                    st = g.comp.stamp(p, x[:, g.sidx], None, tt, None) + (None,)
                A_loc, b_loc, src = st
                # the branch flow: the first row of the local residual A u - b (only it is reported)
                flows = None
                if g.K:
                    A_row = A_loc[:, :, 0, :]
                    flows = (np.einsum("bej,bej->be", np.broadcast_to(A_row, (T,) + A_row.shape[1:]), ul)
                             - b_loc[..., 0])
            e0 += g.E
            xl = x[:, g.sidx]
            obs = g.comp.observe(p, xl, ul, tt, src)
            store_vols = set(g.comp.volume_observables())  # volumes are V(id)
            obs_names = [o.name for o in g.observables]
            for i, e in enumerate(g.ids):
                out[f"Q({e})"] = flows[:, i] if g.K else np.zeros(T)
                for j, s in enumerate(g.states):
                    if s.name not in obs_names:
                        out[f"{e}.{s.name}"] = xl[:, i, j]
                for o in g.observables:
                    key = f"V({e})" if o.name in store_vols else f"{e}.{o.name}"
                    out[key] = np.broadcast_to(obs[o.name][:, i] if np.ndim(obs[o.name]) == 2 else obs[o.name], (T,))
        return out

    def _compiled_nodal(self, tt, x):
        """(u, element flows) for outputs() from the compiled engine, or None: a sparse circuit,
        no engine for its types, or an engine this process would have to compile first (outputs
        never wait for a compilation)."""
        # only where compiled engines are in use already: never import numba or write an
        # engine module for outputs alone (codegen keeps the engine modules this process loaded;
        # a lookup, not a scan of sys.modules: a frequency response asks once per block)
        codegen = sys.modules.get("hemocircuit.kernels.codegen")
        if self.sparse or codegen is None or not codegen.loaded_any():
            return None
        system = self.compiled()
        if system is None or not system.nodal_outputs_ready():
            return None
        return system.nodal_outputs(tt, x, system.params(self.circuit))

    def _outputs_sparse(self, t, x):
        """outputs() for large circuits: the same columns, in the same order, filled group by
        group (no per-element Python) into one (columns, T) array, time chunk by time chunk so
        that one evaluation's arrays stay under about OUTPUT_ELEMENTS numbers.  Checked against
        the general path on the first time point (names, order, values): None if they differ
        (then outputs() takes its general path)."""
        keys = [f"P({n})" for n in self.nodes if ":" not in n]
        p_nodes = np.array([j for j, n in enumerate(self.nodes) if ":" not in n], dtype=int)
        lay = []
        for g in self.groups:
            store_vols = set(g.comp.volume_observables())  # volumes are V(id)
            obs_names = [o.name for o in g.observables]
            st_j = [j for j, s in enumerate(g.states) if s.name not in obs_names]
            lay.append((len(keys), 1 + len(st_j) + len(g.observables), st_j))
            for e in g.ids:
                keys.append(f"Q({e})")
                keys += [f"{e}.{g.states[j].name}" for j in st_j]
                keys += [f"V({e})" if o.name in store_vols else f"{e}.{o.name}" for o in g.observables]
        if len(set(keys)) != len(keys):
            return None
        T = x.shape[0]
        width = self.n + 1 + sum(g.E * g.L * (g.L + 2) for g in self.groups)
        chunk = max(1, OUTPUT_ELEMENTS // width)
        M = np.empty((len(keys), T))  # column-major result: each column a contiguous row
        for i0 in range(0, T, chunk):
            i1 = min(T, i0 + chunk)
            Tc = i1 - i0
            xc = x[i0:i1]
            tt = np.broadcast_to(np.asarray(t, dtype=float), (T,))[i0:i1].reshape(Tc, 1) if np.ndim(t) else float(t)
            u, plist, stamps = self.evaluate(tt, xc, want="u")
            buf = np.empty((Tc, len(keys)))  # time-major chunk (contiguous writes), transposed once
            buf[:, :len(p_nodes)] = u[:, p_nodes]
            for g, p, st, (base, w, st_j) in zip(self.groups, plist, stamps, lay):
                if st is None:  # static group: stamp it for the flows
                    st = g.comp.stamp(p, xc[:, g.sidx], None, tt, None) + (None,)
                A_loc, b_loc, src = st
                ul = u[:, g.uidx]
                Bg = buf[:, base:base + w * g.E].reshape(Tc, g.E, w)  # (time, element, slot)
                if g.K:  # flow leaving the first terminal into the element
                    A0 = np.broadcast_to(A_loc, (Tc,) + A_loc.shape[1:])[:, :, 0, :]
                    Bg[:, :, 0] = (np.einsum("bej,bej->be", A0, ul)
                                   - np.broadcast_to(b_loc, (Tc,) + b_loc.shape[1:])[:, :, 0])
                else:
                    Bg[:, :, 0] = 0.0
                xl = xc[:, g.sidx]
                for k, j in enumerate(st_j):
                    Bg[:, :, 1 + k] = xl[:, :, j]
                obs = g.comp.observe(p, xl, ul, tt, src)
                for k, o in enumerate(g.observables):
                    v = obs[o.name]
                    Bg[:, :, 1 + len(st_j) + k] = (v if np.ndim(v) == 2 else np.broadcast_to(v, (Tc,))[:, None])
            M[:, i0:i1] = buf.T
        ref = self.outputs(np.ravel(t)[:1] if np.ndim(t) else t, x[:1])
        if list(ref) != keys:
            return None
        ref = np.array([np.ravel(ref[k])[0] for k in keys], dtype=float)
        big = np.max(np.abs(ref[np.isfinite(ref)]), initial=0.0)
        if not np.all(np.isclose(M[:, 0], ref, rtol=1e-6, atol=1e-12 * big, equal_nan=True)):
            return None
        return {k: M[r] for r, k in enumerate(keys)}
