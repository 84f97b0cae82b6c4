"""The compiled evaluator of an assembled circuit: right-hand side, nodal solve and the stiff
integrator, all in numba (the engine: kernels.codegen and its template files engine_*.py).  Python is entered once per call, not per
step: a 1000 s run is one call."""
from __future__ import annotations

import os

import numpy as np

from .codegen import engine_module
from .layout import ENGINE_TYPES_VAR, build_layout, param_matrix
from . import pointers, prebuild, runs, tableaus

STATUS = {0: "done", -1: "step size too small", -2: "step limit reached",
          -3: "non-finite state or singular nodal system"}


class CompiledSystem:
    """Compiled right-hand side and integrator for one circuit structure.

    Build with :meth:`of` (None when the circuit has a component type without a kernel).
    Parameter values are passed as a matrix P (members x slots, :meth:`params`), so one
    compiled system serves every parameter set of the structure.
    """

    def __init__(self, layout, module, scales, limits):
        self.layout = layout
        self.mod = module
        self.lay = layout.lay
        self.scales = np.asarray(scales, dtype=float)
        self.lim_i = np.array([li for li, _, _ in limits], dtype=np.int64)
        self.lim_b = np.array([b for _, b, _ in limits], dtype=float)
        self.lim_r = np.array([-1 if r is None else r for _, _, r in limits], dtype=np.int64)
        self._lays = {}  # lay_for's layouts, by which time switches are off
        self._addresses = {}  # id(lay) -> [lay, the Rosenbrock integrator's addresses, its entry]

    @classmethod
    def of(cls, circuit) -> "CompiledSystem | None":
        """The compiled system of ``circuit``'s structure and waveforms (its values are the
        parameter matrix, :meth:`params`).  Kept per structure for the waveforms it was built
        with: every integrate call of a batch (each block of a frequency response, each chunk)
        asks for it, and building the layout costs ~1 ms."""
        ps = circuit.parameters
        waves = tuple(ps.group_waves(k) for k in range(len(circuit.groups)))
        # the engine's type set follows $HEMOCIRCUIT_ENGINE_TYPES (layout.engine_kernels); the
        # entry keeps the waveform tuples alive, so their ids in the key cannot be reused
        key = ("compiled_system", os.environ.get(ENGINE_TYPES_VAR, "used")) + tuple(id(w) for w in waves)
        return circuit.structure.cached(key, lambda: (waves, cls._build(circuit)))[1]

    @classmethod
    def _build(cls, circuit) -> "CompiledSystem | None":
        layout = build_layout(circuit)
        if layout is None:
            return None
        return cls(layout, engine_module(layout.kernels), circuit.state_scales, circuit.hard_limits())

    def params(self, circuit) -> np.ndarray:
        """P (B, slots) of ``circuit`` (same structure as the one this system was built from):
        kept on the (immutable) circuit, since every integrate call asks for it (0.1 ms; a
        shooting run makes one call per period); the caller gets its own writable copy (numba
        specialises on the flag: a read-only P would compile rhs and jacobian again)."""
        layout = self.layout
        kept = circuit.cached(("param_matrix", id(layout)), lambda: (layout, param_matrix(circuit, layout)))
        return kept[1].copy()

    def lay_for(self, P):
        """(layout tuple, autonomous) for the parameter rows P (slots,) or (B, slots): the
        elements of a time-dependent type whose time switch (Component.time_switch, a
        source's sine amplitude) is 0 in every row are static -- stamped once per parameter set,
        not at every evaluation -- and without another time-dependent element or a waveform
        the circuit is autonomous (the integrator's Jacobian then skips df/dt).  The same
        arrays' types, so the same compiled engine."""
        layout = self.layout
        off = ~self._switched_on(P).any(axis=0)
        if not off.any():
            return self.lay, layout.autonomous
        key = off.tobytes()
        if key not in self._lays:
            f, static = layout.fields, layout.switches[off, 0]
            st, td = f.st.copy(), f.td.copy()
            st[static], td[static] = 1, 0
            autonomous = not len(f.ws) and bool(np.isin(layout.timed, static).all())
            self._lays[key] = (layout.lay_with(st=st, td=td), autonomous)
        return self._lays[key]

    def _switched_on(self, P):
        """(rows, switches) bool: which time switches (Layout.switches) each row of P turns on."""
        P = np.asarray(P, dtype=float)
        return P.reshape(-1, P.shape[-1])[:, self.layout.switches[:, 1]] != 0

    def rhs(self, t, x, P):
        """dx/dt for x (nx,) or rows (m, nx); P (1 or m, slots)."""
        x = np.asarray(x, dtype=float)
        P = np.atleast_2d(P)
        lay = self.lay_for(P)[0]
        if x.ndim == 1:
            return self.mod.rhs(float(t), x, P[0], lay)
        return self.mod.rhs_batch(float(t), np.ascontiguousarray(x), P, lay)

    def nodal_outputs(self, t, X, P):
        """(u (m, n+1), element flows (m, E)) for rows X (m, nx) at times t (m,) with P (B,
        slots), rows member-major (engine_nodal.nodal_outputs); None when a row's nodal
        system fails or a value is not finite (the numpy path then says why)."""
        X = np.array(X, dtype=float, order="C")
        m = X.shape[0]
        T = np.array(np.broadcast_to(np.asarray(t, dtype=float).reshape(-1), (m,)), order="C")
        P = np.array(P, dtype=float, order="C", ndmin=2)
        P.setflags(write=False)  # read-only rows, as the integrator's: its rhs_into compilation serves
        fields = self.layout.fields
        U, F = np.empty((m, fields.n + 1)), np.empty((m, fields.et.shape[0]))
        if self.mod.nodal_outputs(T, X, P, self.lay_for(P)[0], U, F) >= 0 or not (np.all(np.isfinite(U))
                                                                        and np.all(np.isfinite(F))):
            return None
        return U, F

    def nodal_outputs_ready(self) -> bool:
        """True when :meth:`nodal_outputs` runs without compiling: it is compiled in this process
        or in numba's cache (the prebuild helper and the background builder put it there)."""
        fn = self.mod.nodal_outputs
        return bool(fn.overloads) or prebuild.in_cache(fn)

    def jacobian(self, t, x, P, local=True):
        """State Jacobian d(dx/dt)/dx (nx, nx) at (t, x) for one parameter row P (slots,):
        element-local, composed through the nodal solve (``local`` True or 1: with the kernels'
        analytic partials where they have them; 2: element-local differences only; where it
        applies) or (False / 0) one whole right-hand side per state -- the integrator's ways."""
        return self._parts(t, x, P, local, False)[0]

    def time_derivative(self, t, x, P, local=True):
        """df/dt (nx,) at (t, x) with the states held: the integrator's (the element-local
        Jacobian's time column where it applies, ``local`` as in :meth:`jacobian`) or (False / 0)
        a whole right-hand side differenced in t."""
        return self._parts(t, x, P, local, True)[1]

    def _parts(self, t, x, P, local, want_ft):
        """engine_jacobian.jacobian_parts: one compiled entry for both."""
        P = np.asarray(P, dtype=float)
        return self.mod.jacobian_parts(float(t), np.asarray(x, dtype=float), P, self.lay_for(P)[0],
                                       self.scales, int(local), bool(want_ft))

    def integrate(self, t_out, x0, P, rtol=1e-6, atol=None, breaks=(), h0=1e-3, hmax=np.inf,
                  max_steps=10_000_000, method=None, kinks=(), **tab_options):
        """States on the grid t_out (T,) from x0 at t_out[0] for one parameter row P (slots,).
        Steps end on ``breaks`` (where a source may jump) and on ``kinks`` (where only a
        source's slope jumps: its value, and so f, is continuous, so f is not re-evaluated).
        ``method``: 'bdf' (engine_bdf.integrate_batch_bdf, variable-order BDF; it restarts at
        kinks as at breaks) or a Rosenbrock tableau of hemocircuit.kernels.tableaus (None:
        tableaus.DEFAULT); ``tab_options`` go to the tableau's ``packed`` (the BDF method takes
        ``local_jacobian`` only).

        Returns (X (T, nx), stats dict).  Rows after a failure are NaN; stats['status'] < 0
        says why (see STATUS)."""
        # one member of the batch entry point: a process compiles one integrator, not two
        X, st = self.integrate_batch(np.asarray(t_out, dtype=float)[None], np.asarray(x0, dtype=float)[None],
                                     np.asarray(P, dtype=float)[None], rtol=rtol, atol=atol, breaks=breaks, h0=h0,
                                     hmax=hmax, max_steps=max_steps, method=method, kinks=kinks, **tab_options)
        row = dict(zip(runs.STATS, st[0]))  # the stats columns by name (kernels.runs.finish_member)
        out = {name: int(v) for name, v in row.items()}
        out.update(message=STATUS[out["status"]], t=float(row["t"]))
        return X[0], out

    def integrate_batch(self, t_out, X0, P, rtol=1e-6, atol=None, breaks=(), h0=1e-3, hmax=np.inf,
                        max_steps=10_000_000, method=None, kinks=(), **tab_options):
        """The compiled integrator for every member: t_out (T,) or (B, T), X0 (B, nx), P (B, slots), hmax
        scalar or (B,); ``breaks`` and ``kinks`` one sequence for every member, or a list of B
        sequences (each member's own).
        Returns (X (B, T, nx), stats (B, 6): status, t, steps, rejected, nfev, limit events)."""
        X0 = np.array(X0, dtype=float, order="C")  # writable always (a copy)
        B = X0.shape[0]
        # t_out, P and hmax read-only always (views: the caller's arrays keep their flags):
        # numba specialises on the flag, and a broadcast single row is read-only while B > 1
        # rows are writable copies -- whose integrator would compile again (~10 s), as would
        # rhs_into_at, prepare_static and local_jacobian_into_at instead of the helper's
        t_out = _read_only(np.broadcast_to(np.asarray(t_out, dtype=float), (B, np.shape(t_out)[-1])))
        P = _read_only(np.broadcast_to(P, (B, P.shape[-1])))
        if X0.shape[1] == 0:  # no states (e.g. every capacitor under an ideal source): nothing to integrate
            stats = np.zeros((B, len(runs.STATS)))
            stats[:, runs.STATS.index("t")] = t_out[:, -1]
            return np.zeros((B, t_out.shape[1], 0)), stats
        # a writable float64 vector always (a copy: the type pointers.single_run gives the helper):
        # after its first call the integrator's compiled entry is called directly (_integrate), and
        # numba's entry reads any array as the type it was compiled for
        atol_v = np.array(np.broadcast_to((rtol * 1e-3 if atol is None else atol) * self.scales, self.scales.shape),
                          dtype=float)
        hmax = _read_only(np.broadcast_to(np.asarray(hmax, dtype=float), (B,)))
        method = method or tableaus.DEFAULT
        brk, jump = member_breaks(B, breaks, kinks)
        if method == tableaus.BDF:
            unknown = set(tab_options) - {"local_jacobian"}
            if unknown:
                raise ValueError(f"options {sorted(unknown)} apply to the Rosenbrock methods, not to {method!r}")
        prebuild.start(self)  # a first compile: part of it in a second process
        prebuild.before_integrator(self, method != tableaus.BDF)  # ... and the rest here, before the integrator
        args = (t_out, X0, P, brk, jump, hmax)
        if B <= 1:
            return self._integrate(*args, rtol, atol_v, h0, max_steps, method, tab_options)
        kinds = np.unique(self._switched_on(P), axis=0, return_inverse=True)[1].reshape(-1)
        if np.all(kinds == kinds[0]):
            return self._integrate(*args, rtol, atol_v, h0, max_steps, method, tab_options)
        # members whose time switches differ run apart (each its own lay_for): a member's
        # numbers do not depend on the batch it runs in
        X, stats = np.empty((B, t_out.shape[1], X0.shape[1])), np.empty((B, len(runs.STATS)))
        for k in np.unique(kinds):
            rows = np.flatnonzero(kinds == k)
            part = [np.ascontiguousarray(a[rows]) for a in args]
            for a, whole in zip(part, args):  # the same flags (P read-only): the same compiled integrator
                a.setflags(write=whole.flags.writeable)
            X[rows], stats[rows] = self._integrate(*part, rtol, atol_v, h0, max_steps, method, tab_options)
        return X, stats

    def _integrate(self, t_out, X0, P, brk, jump, hmax, rtol, atol_v, h0, max_steps, method, tab_options):
        """integrate_batch's call of the compiled integrator, for members of one lay_for."""
        lay, autonomous = self.lay_for(P)
        if method == tableaus.BDF:
            return self.mod.integrate_batch_bdf(t_out, X0, P, lay, self.scales, self.lim_i, self.lim_b,
                                                self.lim_r, brk, float(rtol), atol_v, float(h0), hmax,
                                                int(max_steps), int(tab_options.get("local_jacobian", 1)))
        found = self._addresses.get(id(lay))
        if found is None:  # once per layout: the signatures cost ~0.8 ms, a short run's time
            sigs = pointers.signatures(self.mod, lay, self.scales.size, P, self.scales, self.lim_i, self.lim_b,
                                       self.lim_r, atol_v)
            found = self._addresses[id(lay)] = [lay, pointers.addresses(self.mod, sigs), None]  # lay kept: its id
        args = (t_out, X0, P, lay, self.scales, self.lim_i, self.lim_b, self.lim_r, brk, jump, float(rtol), atol_v,
                float(h0), hmax, int(max_steps),
                tableaus.packed(method, **{"autonomous": int(autonomous), **tab_options}), *found[1])
        if found[2] is not None:
            return found[2](*args)
        out = self.mod.integrate_batch(*args)
        found[2] = _entry_point(self.mod.integrate_batch, args)
        return out


def _entry_point(dispatcher, args):
    """The compiled entry of ``dispatcher`` for these arguments' types, called directly by the
    next calls with the same types (integrate_batch's: each always the same type, see above;
    the entry does not check them, it reads an array as the type it was compiled for):
    numba's dispatch types every argument on every call, and the integrator's four addresses
    (their signatures hold the layout's type) made that ~0.2 ms a call.  None where numba keeps
    no such entry."""
    import numba

    try:
        return dispatcher.overloads[tuple(numba.typeof(a) for a in args)].entry_point
    except (AttributeError, KeyError, TypeError, ValueError):
        return None


def _read_only(a):
    """``a`` as a read-only C-contiguous float64 array (a read-only view of it or of its copy)."""
    a = np.ascontiguousarray(a, dtype=float).view()
    a.setflags(write=False)
    return a


def member_breaks(B, breaks, kinks=()):
    """(times (B, K), jump flags (B, K)) for integrate_batch: ``breaks`` and ``kinks`` either
    one sequence of times for every member or a list of B sequences, merged per member
    (merge_breaks) and padded with +inf (a time never reached)."""
    def per_member(v):
        rows = list(v)
        if rows and all(np.ndim(r) == 1 for r in rows):  # a sequence of times per member
            if len(rows) != B:
                raise ValueError(f"breakpoints for {len(rows)} members, the batch has {B}")
            return rows
        return [rows] * B

    merged, rows = {}, []  # members with the same times share one merge (a batch's usual case)
    for b, k in zip(per_member(breaks), per_member(kinks)):
        key = (tuple(b), tuple(k))
        if key not in merged:
            merged[key] = merge_breaks(b, k)
        rows.append(merged[key])
    K = max([1] + [r[0].size for r in rows])
    times, jump = np.full((B, K), np.inf), np.ones((B, K))
    for m, (t, j) in enumerate(rows):
        times[m, :t.size], jump[m, :t.size] = t, j
    return times, jump


def merge_breaks(breaks, kinks=()):
    """(times (K,), jump flags (K,)): ``breaks`` and ``kinks`` sorted into one array, flag 1
    where a source may jump (a time in ``breaks``, whether or not also a kink), 0 at a kink."""
    # sets, not np.isin and argsort: a call's few times cost 0.1 ms that way, once per integrate call
    jumps = {float(v) for v in np.asarray(breaks, dtype=float).reshape(-1)}
    times = sorted(jumps.union(float(v) for v in np.asarray(kinks, dtype=float).reshape(-1)))
    return np.array(times, dtype=float), np.array([1.0 if v in jumps else 0.0 for v in times])
