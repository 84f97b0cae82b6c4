"""The model's counterpart of a dataset, for a batch of B parameter sets at once.

* :class:`SteadyExperiment` (``op`` and ``dc``): the operating point at every data row's inputs.
  B parameter sets x n rows are ONE batch circuit of B*n members, solved together (the
  operating point is vectorised over the batch), warm-started from the last solution.
* :class:`TransientExperiment` (``tran``): a protocol run for every parameter set, compared at
  the data's times.  The B runs are integrated together (``hemocircuit.batch_integrator``),
  one call per protocol segment; a fitted epoch value (``art.tau_Ca@239s``) replaces the value
  the protocol sets at that time.

``evaluate(assign, epochs, B)`` returns the observed quantity (B, n) in the observed column's
unit (NaN where a member failed).  Every parameter change goes through
:func:`with_values`.
"""
from __future__ import annotations

import numpy as np

from ..derived import evaluate_derived
from ..errors import FitSpecError, HemocircuitError


def with_values(circuit, mapping, B=None):
    """``circuit`` with parameters changed: mapping {ID.PARAM: quantity string, number in the
    declared unit, or array of B values}; ``B`` makes a single circuit a batch of B members."""
    B = circuit.B if B is None else int(B)
    c = circuit if B == circuit.B else circuit.batch(B)
    return c.with_values(mapping) if mapping else c


def _observed(circuit, observe, values, spec_file, key):
    """The observed quantity from output columns (or a derived quantity of the netlist)."""
    if observe in values:
        return np.asarray(values[observe], dtype=float)
    derived = circuit.netlist.derived or {}
    if observe in derived:
        return np.asarray(evaluate_derived({observe: derived[observe]}, values, circuit.file)[observe], dtype=float)
    raise FitSpecError(f"{observe!r} is neither an output column nor a derived quantity of the netlist "
                       f"(columns: {', '.join(sorted(values)[:25])} ...)", file=spec_file, key=key)


def observed_unit(circuit, observe):
    units = circuit.column_units()
    if observe in units:
        return units[observe]
    derived = circuit.netlist.derived or {}
    if observe in derived:
        return str(derived[observe].get("unit", ""))
    return None


def solve_steady(circuit, X0=None):
    """Operating points of every member of a batch circuit: (X (B, nx), {column: (B,)}, ok (B,)).

    Warm start from X0 (B, nx) if given, else the DC guess; Newton on the whole batch, the
    fallbacks only on the members it did not solve (members that fail are NaN, not fatal).
    A warm start that fails for some members is retried cold for those members."""
    from ..analyses.op import operating_points

    B = circuit.B
    X, vals, errors = operating_points(circuit, x0=X0)
    ok = np.array([e is None for e in errors], dtype=bool)
    if X0 is not None and not ok.all():
        idx = np.nonzero(~ok)[0]
        Xc, vc, ec = operating_points(circuit.subset(idx) if len(idx) < B else circuit)
        X[idx] = Xc
        for k, v in vc.items():
            vals.setdefault(k, np.full(B, np.nan))[idx] = v
        ok[idx] = [e is None for e in ec]
    # every member failed: no column was filled
    vals = {k: vals.get(k, np.full(B, np.nan)) for k in circuit.column_units()}
    return X, vals, ok


class WarmStarts:
    """States of recent single-set solutions, keyed by the parameter values that produced them.

    A batch is warm-started only if every member has a stored solution whose parameters differ
    by less than ``rel`` (relative, per parameter): from far away, Newton may land on another
    root of the equations (measured: a passive arteriole collapsed to r ~ 3 um when started
    from the solution of a distant parameter set).  Otherwise the operating point starts cold.
    """

    def __init__(self, size=8, rel=0.02):
        self.size, self.rel, self.items = size, rel, []

    @staticmethod
    def keys(assign, epochs, B):
        cols = [np.broadcast_to(np.asarray(assign[p], float), (B,)) for p in sorted(assign)]
        cols += [np.broadcast_to(np.asarray(epochs[k], float), (B,)) for k in sorted(epochs)]
        return np.stack(cols, axis=1) if cols else np.zeros((B, 0))

    def lookup(self, keys):
        """[X of the nearest stored solution] per member, or None if any member has none."""
        out = []
        for k in keys:
            best, dist = None, self.rel
            for key, X in self.items:
                d = np.max(np.abs(k - key) / np.maximum(np.abs(key), 1e-300), initial=0.0)
                if d < dist:
                    best, dist = X, d
            if best is None:
                return None
            out.append(best)
        return out

    def store(self, key, X):
        self.items.insert(0, (np.array(key, float), np.array(X, float)))
        del self.items[self.size:]


def nearby_anchors(keys, rel=0.02, window=32):
    """Within one batch of parameter sets (keys (B, p)): ``anchor[i]`` = the index of an
    earlier set whose parameters all differ from set i's by less than ``rel`` (relative), or i
    itself (an anchor, solved cold).  Greedy in batch order, comparing with the ``window``
    most recent anchors: the batches this serves keep related sets together (a sensitivity
    star: a point and its one-at-a-time steps; a Jacobian: a point and its perturbations)."""
    B = len(keys)
    anchor = np.arange(B)
    recent = []
    for i in range(B):
        if recent:
            ref = keys[recent]
            d = np.max(np.abs(keys[i] - ref) / np.maximum(np.abs(ref), 1e-300), axis=1, initial=0.0)
            j = int(np.argmin(d))
            if d[j] < rel:
                anchor[i] = recent[j]
                continue
        recent.append(i)
        del recent[:-window]
    return anchor


class SteadyExperiment:
    """Operating points at the data rows' inputs (``op``; ``dc`` is a one-input sweep)."""

    def __init__(self, base, inputs, observe, spec_file, key):
        self.base = base            # circuit with the experiment's options and settings
        self.inputs = inputs        # {ID.PARAM: (n,) values in the declared unit}
        self.n = len(next(iter(inputs.values())))
        self.observe, self.spec_file, self.key = observe, spec_file, key
        self._warm = WarmStarts()

    def evaluate(self, assign, epochs, B):

        n = self.n
        mapping = {p: np.repeat(np.broadcast_to(np.asarray(v, float), (B,)), n) for p, v in assign.items()}
        mapping.update({p: np.tile(v, B) for p, v in self.inputs.items()})
        c = with_values(self.base, mapping, B * n)
        keys = WarmStarts.keys(assign, epochs, B)
        warm = self._warm.lookup(keys)
        if warm is not None:
            X, vals, ok = solve_steady(c, np.concatenate(warm, axis=0))
        else:
            X, vals, ok = self._solve_anchored(c, keys, B)
        y = _observed(c, self.observe, vals, self.spec_file, self.key).reshape(B, n).copy()
        good = ok.reshape(B, n).all(axis=1) & np.all(np.isfinite(y), axis=1)
        y[~good] = np.nan
        if B == 1 and good[0]:
            self._warm.store(keys[0], X.reshape(n, -1))
        return y

    def _solve_anchored(self, c, keys, B):
        """Sets within ``WarmStarts.rel`` of an earlier set of the batch (nearby_anchors) start
        from that set's solution; the others (and those whose anchor failed) start cold.
        Measured on the arteriole: a warm-started operating point costs 1/15 of a cold one
        (whose DC guess solves the steady state on a radius grid)."""
        n = self.n
        anchor = nearby_anchors(keys, self._warm.rel)
        rows = lambda sets: (np.asarray(sets)[:, None] * n + np.arange(n)).ravel()  # noqa: E731
        cold = np.nonzero(anchor == np.arange(B))[0]
        if len(cold) == B:
            return solve_steady(c)
        X = np.full((B * n, c.nx), np.nan)
        ok = np.zeros(B * n, bool)
        vals = {}

        def solve(sets, X0=None):
            r = rows(sets)
            Xs, vs, oks = solve_steady(c.subset(r), X0)
            X[r], ok[r] = Xs, oks
            for k, v in vs.items():
                vals.setdefault(k, np.full(B * n, np.nan))[r] = v

        solve(cold)
        set_ok = ok.reshape(B, n).all(axis=1)
        warm = np.nonzero((anchor != np.arange(B)) & set_ok[anchor])[0]
        if len(warm):
            solve(warm, X[rows(anchor[warm])])
        orphans = np.nonzero((anchor != np.arange(B)) & ~set_ok[anchor])[0]
        if len(orphans):
            solve(orphans)
        return X, {k: vals.get(k, np.full(B * n, np.nan)) for k in c.column_units()}, ok


class TransientExperiment:
    """A protocol run for every parameter set, the observed quantity at the data's times."""

    def __init__(self, base, protocol, times, observe, rtol, spec_file, key):
        self.base = base            # circuit after the protocol's initial settings
        self.protocol = protocol    # hemocircuit.protocol.Protocol (its events are applied here)
        self.times = np.asarray(times, float)
        self.observe, self.rtol, self.spec_file, self.key = observe, rtol, spec_file, key
        self.n = len(self.times)
        self.t_end = max(float(protocol.t_end or 0.0), float(self.times.max()))
        self._warm = WarmStarts()

    def epoch_times(self):
        """{ID.PARAM: [times at which the protocol sets it]} (0 = its 'initial')."""
        out = {}
        for p in self.protocol.initial:
            out.setdefault(p, []).append(0.0)
        for ev in self.protocol.events:
            for p in ev.set:
                out.setdefault(p, []).append(float(ev.at))
        return out

    def evaluate(self, assign, epochs, B):
        """epochs: {(ID.PARAM, time): (B,) values} for the epoch parameters."""
        from ..batch_integrator import integrate

        def member_values(v):
            return np.broadcast_to(np.asarray(v, float), (B,)).copy()

        first = {p: member_values(v) for p, v in assign.items()}
        first.update({p: member_values(v) for (p, t), v in epochs.items() if t == 0.0})
        c = with_values(self.base, first, B)
        keys = WarmStarts.keys(assign, epochs, B)
        warm = self._warm.lookup(keys)
        X, _, ok = solve_steady(c, None if warm is None else np.concatenate(warm, axis=0))
        if B == 1 and ok[0]:
            self._warm.store(keys[0], X)
        y = np.full((B, self.n), np.nan)
        events = [ev for ev in self.protocol.events if 0.0 < ev.at < self.t_end]
        bounds = [0.0] + [float(ev.at) for ev in events] + [self.t_end]
        for k in range(len(bounds) - 1):
            t_a, t_b = bounds[k], bounds[k + 1]
            if k > 0:
                ev = events[k - 1]
                change = dict(ev.set)
                change.update({p: member_values(v) for (p, t), v in epochs.items() if t == float(ev.at)})
                c = with_values(c, change)
            last = k == len(bounds) - 2
            sel = (self.times >= t_a) & ((self.times <= t_b) if last else (self.times < t_b))
            if t_b <= t_a:
                continue
            grid = np.unique(np.concatenate([[t_a], self.times[sel], [t_b]]))
            if ok.any():
                try:
                    res = integrate(c, np.nan_to_num(X), grid, rtol=self.rtol)
                    seg_ok = res.ok & ok
                    states = res.x                                  # (B, T, nx)
                except HemocircuitError:
                    seg_ok = np.zeros(B, bool)
                    states = np.full((B, len(grid), c.nx), np.nan)
            else:
                seg_ok, states = ok, np.full((B, len(grid), c.nx), np.nan)
            if sel.any():
                idx = np.searchsorted(grid, self.times[sel])
                rows = states[:, idx, :]                            # (B, m, nx)
                m = rows.shape[1]
                t_rows = np.tile(self.times[sel], B)
                vals = c.outputs(t_rows, np.nan_to_num(rows.reshape(B * m, -1)))
                obs = _observed(c, self.observe, vals, self.spec_file, self.key).reshape(B, m)
                y[:, sel] = np.where(seg_ok[:, None], obs, np.nan)
            ok = seg_ok
            X = states[:, -1, :]
        return y
