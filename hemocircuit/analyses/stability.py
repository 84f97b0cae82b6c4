"""Stability of equilibria along a parameter sweep; Hopf (and other) bifurcations.

At every sweep value the operating point is continued from the previous one (as in a DC sweep),
the circuit is linearised there (:mod:`.linearize`: central differences on the steady variant,
so a state at a hard limit gives no false one-sided-difference eigenvalue), the structural zero
eigenvalues of conservation laws are projected out, and the remaining eigenvalues classify the
equilibrium:

  'stable node'     every Re < 0, all eigenvalues real
  'stable focus'    every Re < 0, at least one complex pair (damped oscillation)
  'unstable node'   some Re > 0, all of them real (includes saddles; see n_unstable)
  'unstable focus'  some Re > 0, among them a complex pair (growing oscillation)

"Re > 0" means above a round-off tolerance (1e-9 of the largest |lambda|); an eigenvalue is
complex when |Im| > 1e-7 |lambda|.  The least-damped complex pair is the one with the smallest
damping ratio zeta = -Re/|lambda|; its frequency is Im/(2 pi) Hz.

Events between neighbouring sweep points are located by bracketing in the parameter, with the
operating point continued from the nearer bracket end:
  'hopf'            the number of eigenvalues with Re > 0 changes (the spectral abscissa
                    crosses zero, or a further pair does) through a complex pair (frequency
                    reported); the crossing real part is bracketed with Brent's method;
                    'unstable above' when the count grows with the parameter
  'real crossing'   it changes sign through a real eigenvalue (fold / branch point)
  'complex onset'   the number of complex pairs changes (two real eigenvalues collide and
                    leave the real axis, or a pair lands on it); bisection
"""
from __future__ import annotations

import argparse

import sys

import numpy as np

from ..errors import HemocircuitError, SolverError
from .linearize import limit_flags, linearize
from ..io import pyplot, save_figure
from ..provenance import clock, stamp
from ..results import Result

RE_TOL = 1e-9
IM_TOL = 1e-7
CLASSES = ("stable node", "stable focus", "unstable node", "unstable focus")


# ------------------------------------------------------------------------ one point -------
def sort_eigenvalues(lam):
    """Largest real part first; of a conjugate pair the positive imaginary part first."""
    lam = np.asarray(lam, dtype=complex)
    return lam[np.lexsort((-lam.imag, -lam.real))]


def analyse_eigenvalues(lam):
    """Classification and least-damped pair of one equilibrium's eigenvalues (structural zeros
    already removed).  Returns a dict."""
    lam = sort_eigenvalues(lam)
    if lam.size == 0:
        return {"eigenvalues": lam, "classification": "stable node", "n_unstable": 0, "abscissa": -np.inf,
                "n_pairs": 0, "pair": None, "pair_zeta": np.nan, "pair_freq": np.nan}
    scale = max(np.max(np.abs(lam)), 1e-300)
    cplx = np.abs(lam.imag) > IM_TOL * np.maximum(np.abs(lam), 1e-300)
    unstable = lam.real > RE_TOL * scale
    n_pairs = int(np.sum(cplx & (lam.imag > 0)))
    if unstable.any():
        cls = "unstable focus" if np.any(unstable & cplx) else "unstable node"
    else:
        cls = "stable focus" if n_pairs else "stable node"
    pair, zeta, freq = None, np.nan, np.nan
    if n_pairs:
        upper = lam[cplx & (lam.imag > 0)]
        z = -upper.real / np.abs(upper)
        k = int(np.argmin(z))
        pair, zeta, freq = upper[k], float(z[k]), float(upper[k].imag / (2 * np.pi))
    return {"eigenvalues": lam, "classification": cls, "n_unstable": int(unstable.sum()),
            "abscissa": float(lam.real.max()), "n_pairs": n_pairs, "pair": pair, "pair_zeta": zeta,
            "pair_freq": freq}


def eigenvalues(circuit, x, t=0.0):
    """Eigenvalues at states x (nx,) with the conservation laws' structural zeros removed."""
    lin = linearize(circuit, x, t=t)
    return np.linalg.eigvals(lin.A_red)


def analyse_point(circuit, x, t=0.0):
    """Eigen-analysis of the equilibrium x of ``circuit`` (dict, see analyse_eigenvalues),
    plus 'at_limit' (states at a hard limit) and 'x'."""
    out = analyse_eigenvalues(eigenvalues(circuit, x, t))
    out["at_limit"] = limit_flags(circuit, x)
    out["x"] = np.asarray(x, dtype=float)
    return out


def equilibrium(c, x0=None, t=0.0, tol=1e-10):
    """States of the operating point of ``c``, continued from x0.

    If x0 already balances (scaled residual below ``tol``, e.g. when the swept parameter does
    not move the equilibrium: zeta, omega_n, tau_Ca), it is returned as it is -- Newton started
    on a converged point can spend a long time in its line search at round-off level."""
    from .op import conserved_totals, operating_point, residual

    if x0 is not None:
        sv = c.steady_variant()
        try:
            totals = [np.atleast_1d(v) for v in conserved_totals(c, t)]
            F = residual(sv, t, np.asarray(x0, dtype=float)[None, :], totals)
            if np.all(np.isfinite(F)) and np.max(np.abs(F) / sv.state_scales) < tol:
                return np.asarray(x0, dtype=float).copy()
        except HemocircuitError:
            pass
    try:
        return operating_point(c, t, x0=x0).x
    except SolverError:
        if x0 is None:
            raise
        return operating_point(c, t).x


def _solve_at(circuit, param, value, x0, t=0.0):
    """(circuit with param = value, its equilibrium continued from x0)."""
    c = circuit.with_values({param: float(value)})
    return c, equilibrium(c, x0, t)


# ------------------------------------------------------------------------ result ----------
class StabilityResult(Result):
    """Per sweep point: ``values``, ``eigenvalues`` (N, n) complex (NaN where the operating
    point failed), ``classification``, ``n_unstable``, ``abscissa`` (max Re), ``n_pairs``,
    ``pair`` (least-damped complex pair, NaN if none), ``pair_zeta``, ``pair_freq`` [Hz],
    ``at_limit`` (list of state names per point), ``x`` (N, nx); ``events`` (list of dicts
    kind/value/eigenvalue/frequency); ``failed`` [(value, reason)]."""

    def __init__(self, param, unit, values, points, events, failed, state_names):
        self.param, self.unit = param, unit
        self.values = np.asarray(values, dtype=float)
        self.points = points
        self.events = events
        self.failed = failed
        self.state_names = state_names
        n = max((len(p["eigenvalues"]) for p in points if p is not None), default=0)
        N = len(points)
        self.eigenvalues = np.full((N, n), np.nan + 0j)
        self.x = np.full((N, len(state_names)), np.nan)
        self.classification, self.at_limit = [], []
        self.n_unstable = np.full(N, -1)
        self.n_pairs = np.full(N, -1)
        self.abscissa = np.full(N, np.nan)
        self.pair = np.full(N, complex(np.nan, np.nan))
        self.pair_zeta = np.full(N, np.nan)
        self.pair_freq = np.full(N, np.nan)
        for i, p in enumerate(points):
            if p is None:
                self.classification.append("failed")
                self.at_limit.append([])
                continue
            lam = p["eigenvalues"]
            self.eigenvalues[i, :len(lam)] = lam
            self.x[i] = p["x"]
            self.classification.append(p["classification"])
            self.at_limit.append(p["at_limit"])
            self.n_unstable[i], self.n_pairs[i], self.abscissa[i] = p["n_unstable"], p["n_pairs"], p["abscissa"]
            if p["pair"] is not None:
                self.pair[i], self.pair_zeta[i], self.pair_freq[i] = p["pair"], p["pair_zeta"], p["pair_freq"]
        cols, units = self._table()
        super().__init__(cols, units, index=[param])
        self.metadata["events"] = events
        self.metadata["failed"] = [[v, why] for v, why in failed]
        self.metadata["measures"] = {"hopf": self.hopf, "complex_ranges": self.complex_ranges()}

    @property
    def stable(self):
        return np.array([c.startswith("stable") for c in self.classification])

    @property
    def hopf(self):
        """Parameter values of the located Hopf points."""
        return [e["value"] for e in self.events if e["kind"] == "hopf"]

    def complex_ranges(self):
        """[(start, end)] parameter intervals with at least one complex pair; ends located by
        bisection where a boundary lies inside the sweep (else the sweep's end)."""
        onsets = [e["value"] for e in self.events if e["kind"] == "complex onset"]
        return complex_ranges(self.values, self.n_pairs > 0, onsets)

    def _table(self):
        """Columns and units: the parameter, ``classification``, ``n_unstable``,
        ``max_re(lambda)`` (spectral abscissa), ``n_complex_pairs``, the least-damped pair
        (``re(pair)``, ``im(pair)``, ``zeta(pair)``, ``frequency(pair)``), ``at_limit``, and
        every eigenvalue ``re(lambdaK)``, ``im(lambdaK)`` (largest real part first)."""
        reasons = dict(self.failed)
        cols = {self.param: self.values, "classification": np.array(self.classification, dtype=object),
                "n_unstable": self.n_unstable, "max_re(lambda)": self.abscissa, "n_complex_pairs": self.n_pairs,
                "re(pair)": self.pair.real, "im(pair)": self.pair.imag, "zeta(pair)": self.pair_zeta,
                "frequency(pair)": self.pair_freq,
                "at_limit": np.array([";".join(a) for a in self.at_limit], dtype=object)}
        units = {self.param: self.unit, "n_unstable": "1", "max_re(lambda)": "1/s", "n_complex_pairs": "1",
                 "re(pair)": "1/s", "im(pair)": "rad/s", "zeta(pair)": "1", "frequency(pair)": "Hz"}
        for k in range(self.eigenvalues.shape[1]):
            cols[f"re(lambda{k + 1})"] = self.eigenvalues[:, k].real
            cols[f"im(lambda{k + 1})"] = self.eigenvalues[:, k].imag
            units[f"re(lambda{k + 1})"], units[f"im(lambda{k + 1})"] = "1/s", "rad/s"
        if self.failed:
            cols["error"] = np.array([reasons.get(float(v), "") if p is None else ""
                                      for v, p in zip(self.values, self.points)], dtype=object)
        return cols, units

    def summary(self, max_cols=6, max_rows=12, show=None, where=None):
        """The table (see :meth:`hemocircuit.results.Result.summary`) and the verdict: counts
        per class, complex ranges, Hopf points and real crossings, states at a limit."""
        return super().summary(max_cols, max_rows, show, where) + "\n" + self.verdict()

    def verdict(self):
        lines = []
        ok = [c for c in self.classification if c != "failed"]
        counts = {k: ok.count(k) for k in CLASSES if ok.count(k)}
        lines.append(f"{len(self.values)} points: " + ", ".join(f"{v} {k}" for k, v in counts.items())
                     + (f", {len(self.failed)} failed" if self.failed else ""))
        for lo, hi in self.complex_ranges():
            lines.append(f"complex pair for {self.param} in [{lo:.6g}, {hi:.6g}] {self.unit}")
        for e in self.events:
            if e["kind"] == "hopf":
                lines.append(f"Hopf point at {self.param} = {e['value']:.6g} {self.unit}: lambda = "
                             f"{e['eigenvalue'].real:+.3g} {e['eigenvalue'].imag:+.5g}j /s, "
                             f"frequency {e['frequency']:.5g} Hz ({e['direction']})")
            elif e["kind"] == "real crossing":
                lines.append(f"real eigenvalue crosses zero at {self.param} = {e['value']:.6g} {self.unit} "
                             f"({e['direction']})")
        lim = sorted({n for a in self.at_limit for n in a})
        if lim:
            where = [self.values[i] for i, a in enumerate(self.at_limit) if a]
            lines.append(f"states at a hard limit (linearised on the smooth steady variant): {', '.join(lim)} "
                         f"for {self.param} in [{min(where):.6g}, {max(where):.6g}] {self.unit}")
        return "\n".join(lines)


def complex_ranges(values, has_pair, onsets):
    """[(start, end)] of the runs of sweep points with a complex pair; an end is the located
    'complex onset' between the run's last point and its neighbour when there is one."""
    out = []
    i, N = 0, len(has_pair)
    while i < N:
        if not has_pair[i]:
            i += 1
            continue
        j = i
        while j + 1 < N and has_pair[j + 1]:
            j += 1
        lo, hi = values[i], values[j]
        lo_b = [v for v in onsets if (i > 0 and min(values[i - 1], lo) <= v <= max(values[i - 1], lo))]
        hi_b = [v for v in onsets if (j + 1 < N and min(hi, values[j + 1]) <= v <= max(hi, values[j + 1]))]
        out.append((float(lo_b[0] if lo_b else lo), float(hi_b[0] if hi_b else hi)))
        i = j + 1
    return out


# ------------------------------------------------------------------------ sweep -----------
def stability_sweep(circuit, param=None, values=None, t=0.0, locate=True, xtol=None,
                    progress=None) -> StabilityResult:
    """Eigen-analysis of the equilibria of ``circuit`` over ``param`` = ``values`` (array in the
    parameter's declared unit, or a range string '10:200:2 mmHg'), continuing the operating point
    from point to point.  ``param`` defaults to the netlist's input (a source's drive parameter,
    :func:`hemocircuit.outputs.default_input`); ``values`` are required.  With ``locate``, Hopf points, real crossings and complex-pair onsets
    between sweep points are located in the parameter to ``xtol`` (default 1e-6 of the sweep's
    step for Hopf/real crossings, 1e-3 of it for complex onsets)."""
    from ..outputs import default_input, input_path
    from .dc import parse_range

    started = clock()
    param = input_path(circuit, default_input(circuit) if param is None else param)
    if values is None:
        raise HemocircuitError(f"stability_sweep: give the values of {param} to sweep (e.g. '10:200:2 UNIT')")
    unit = circuit.param_unit(param)
    vals = parse_range(values, unit) if isinstance(values, str) else np.atleast_1d(np.asarray(values, dtype=float))
    if circuit.B != 1:
        raise HemocircuitError("stability_sweep runs on a single circuit (the sweep is the batch)")
    points, failed = [], []
    x_prev = None
    from ..progress import bar
    stopped = None
    try:
        with bar(len(vals), "stability", unit="point", progress=progress) as b:
            for v in vals:
                b.update(1)
                try:
                    c = circuit.with_values({param: float(v)})
                    x = equilibrium(c, x_prev, t)
                    pt = analyse_point(c, x, t)
                except HemocircuitError as exc:  # this point only; the sweep goes on
                    failed.append((float(v), str(exc)))
                    points.append(None)
                    continue
                x_prev = x
                points.append(pt)
    except KeyboardInterrupt as exc:  # SIGINT/SIGTERM: keep the points done
        from ..execution import NOT_RUN
        stopped = exc
        failed += [(float(v), NOT_RUN) for v in vals[len(points):]]
        points += [None] * (len(vals) - len(points))
    events = []
    if locate and len(vals) > 1 and stopped is None:
        gaps = np.abs(np.diff(vals))
        gaps = gaps[gaps > 0]  # a repeated value is no interval to bisect
        step = float(np.min(gaps)) if gaps.size else 1.0
        events = _locate_events(circuit, param, vals, points, t, xtol or 1e-6 * step, 1e-3 * step)
    res = StabilityResult(param, unit, vals, points, events, failed, list(circuit.state_names))
    stamp(res, "stability", circuit, {"param": param, "values": values if isinstance(values, str) else None,
                                      "t": t, "locate": locate, "xtol": xtol, "re_tol": RE_TOL,
                                      "im_tol": IM_TOL}, started)
    from ..execution import finish_batch
    return finish_batch(res, stopped)


def _locate_events(circuit, param, vals, points, t, xtol, xtol_onset):
    from scipy.optimize import brentq

    events = []
    for i in range(len(vals) - 1):
        a, b = points[i], points[i + 1]
        if a is None or b is None:
            continue
        va, vb = float(vals[i]), float(vals[i + 1])
        cache = {}

        def at(v, a=a, b=b, va=va, vb=vb, cache=cache):
            if v not in cache:
                x0 = a["x"] if abs(v - va) <= abs(v - vb) else b["x"]
                cc, x = _solve_at(circuit, param, v, x0, t)
                cache[v] = analyse_point(cc, x, t)
            return cache[v]

        na_u, nb_u = a["n_unstable"], b["n_unstable"]
        if na_u != nb_u:
            # the real part of rank min(na_u, nb_u) (largest first) crosses zero: the
            # spectral abscissa when the equilibrium loses stability, the next eigenvalue(s)
            # when a second pair or eigenvalue crosses
            rank = min(na_u, nb_u)

            def g(v, rank=rank):
                return float(np.sort(at(v)["eigenvalues"].real)[::-1][rank])

            try:
                ga = float(np.sort(a["eigenvalues"].real)[::-1][rank])
                gb = float(np.sort(b["eigenvalues"].real)[::-1][rank])
                if np.sign(ga) != np.sign(gb) and ga != 0 and gb != 0:
                    root = brentq(g, va, vb, xtol=xtol, rtol=4 * np.finfo(float).eps, maxiter=100)
                else:  # within the round-off band of zero: bisect on the count
                    root = _bisect(lambda v: at(v)["n_unstable"] == na_u, va, vb, True, xtol)
                p = at(root)
                lam = p["eigenvalues"]
                crit = lam[np.argmin(np.abs(lam.real - g(root)))]
                hopf = abs(crit.imag) > IM_TOL * max(abs(crit), 1e-300)
                events.append({"kind": "hopf" if hopf else "real crossing", "value": float(root),
                               "eigenvalue": complex(crit.real, abs(crit.imag)),
                               "frequency": abs(crit.imag) / (2 * np.pi) if hopf else 0.0,
                               "direction": "unstable above" if (nb_u > na_u) == (vb > va) else "unstable below",
                               "n_unstable": (na_u, nb_u), "between": (va, vb)})
            except HemocircuitError as exc:
                events.append({"kind": "failed", "value": np.nan, "between": (va, vb), "reason": str(exc)})
        if a["n_pairs"] != b["n_pairs"]:
            try:
                na = a["n_pairs"]
                root = _bisect(lambda v: at(v)["n_pairs"] == na, va, vb, True, xtol_onset)
                events.append({"kind": "complex onset", "value": float(root), "between": (va, vb),
                               "pairs": (a["n_pairs"], b["n_pairs"])})
            except HemocircuitError as exc:
                events.append({"kind": "failed", "value": np.nan, "between": (va, vb), "reason": str(exc)})
    return events


def _bisect(pred, a, b, pred_a, xtol):
    """Point where pred changes from pred_a (at a) to not pred_a (at b), to xtol."""
    while abs(b - a) > xtol:
        m = 0.5 * (a + b)
        if pred(m) == pred_a:
            a = m
        else:
            b = m
    return 0.5 * (a + b)


# ------------------------------------------------------------------------ plots -----------
def plot_result(res, path, select=None, title=None):
    """Real parts of the eigenvalues against the parameter (symlog) and the eigenvalues in the
    complex plane coloured by the parameter; from the result's columns and events (a fresh or
    a reloaded result)."""
    plt = pyplot()

    param = res.index[0]
    unit = res.units.get(param, "")
    v = np.asarray(res[param], dtype=float)
    K = sum(1 for k in res.keys() if k.startswith("re(lambda") and k != "re(lambda)")
    E = np.stack([res[f"re(lambda{k + 1})"] + 1j * res[f"im(lambda{k + 1})"] for k in range(K)], axis=1) \
        if K else np.zeros((len(v), 0), complex)
    events = res.metadata.get("events", []) or []
    onsets = [e["value"] for e in events if e.get("kind") == "complex onset"]
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(13, 5.2))
    lin = max(float(np.nanmin(np.abs(E.real[E.real != 0]))) if np.any(E.real != 0) else 1e-3, 1e-4)
    lin = min(lin, 0.1)
    for lo, hi in complex_ranges(v, np.asarray(res["n_complex_pairs"]) > 0, onsets):
        ax1.axvspan(lo, hi, color="tab:orange", alpha=0.12, lw=0)
    for k in range(E.shape[1]):
        cp = np.abs(E[:, k].imag) > 0
        ax1.plot(v, E[:, k].real, ".", ms=3, color="tab:blue")
        ax1.plot(v[cp], E[cp, k].real, "o", ms=4, mfc="none", color="tab:orange")
    for e in events:
        if e.get("kind") in ("hopf", "real crossing"):
            ax1.axvline(e["value"], color="tab:red", lw=0.8, ls="--")
            ax1.annotate(f"{'Hopf' if e['kind'] == 'hopf' else 'crossing'} {e['value']:.4g}", (e["value"], 0),
                         fontsize=7, rotation=90, va="bottom", ha="right", color="tab:red")
    ax1.axhline(0, color="k", lw=0.7)
    ax1.set_yscale("symlog", linthresh=lin)
    re_all = E.real[np.isfinite(E.real)]
    if re_all.size:  # no empty decades: from the fastest decay to just above the largest real part
        top = re_all.max() * 3 if re_all.max() > 0 else lin * 3
        ax1.set_ylim(min(re_all.min() * 2, -lin), top)
    ax1.set_xlabel(f"{param} [{unit}]")
    ax1.set_ylabel("Re(lambda) [1/s]  (orange: complex pair; shaded: complex range)")
    ax1.grid(alpha=0.3)
    sc = None
    for k in range(E.shape[1]):
        sc = ax2.scatter(E[:, k].real, E[:, k].imag, c=v, s=8, cmap="viridis")
    if sc is not None:
        fig.colorbar(sc, ax=ax2, label=f"{param} [{unit}]")
    ax2.axvline(0, color="k", lw=0.7)
    ax2.axhline(0, color="k", lw=0.4)
    ax2.set_xscale("symlog", linthresh=lin)
    if re_all.size:
        ax2.set_xlim(min(re_all.min() * 2, -lin), re_all.max() * 3 if re_all.max() > 0 else lin)
    ax2.set_xlabel("Re(lambda) [1/s]")
    ax2.set_ylabel("Im(lambda) [rad/s]")
    ax2.grid(alpha=0.3)
    fig.suptitle(title or f"{res.figure_title()}: eigenvalues along {param}")
    save_figure(fig, path)
    return str(path)


# ------------------------------------------------------------------------ CLI -------------
def _stability(args, c):
    from ..arguments import range_spacing
    param, rng = (s.strip() for s in args.sweep.split("=", 1))
    return stability_sweep(c, param, range_spacing(rng), locate=not args.no_locate)


def compute_stability(args, sets):
    """One --grid member (:func:`hemocircuit.commands.computed`)."""
    from ..commands import circuit_of_args
    return _stability(args, circuit_of_args(args, sets)[0])


def cmd_stability(args):
    from ..commands import computed, load_args, report_grid, save_outputs

    if not args.sweep or "=" not in args.sweep:
        raise HemocircuitError("stability needs --sweep ID.PARAM=START:STOP:STEP UNIT (e.g. Pa.value=10:200:2mmHg)")
    param = args.sweep.split("=", 1)[0].strip()
    show = args.show or ["classification", "max_re(lambda)", "zeta(pair)", "frequency(pair)", "at_limit"]
    if args.grid:
        return report_grid(args, computed(args, compute_stability), show)
    res = _stability(args, load_args(args)[0])
    print(res.summary(show=show, max_rows=0, where=args.out))
    for v, why in res.failed:
        print(f"failed at {param}={v:g}: {why}", file=sys.stderr)
    save_outputs(args, res)


def register_cli(sub, common):
    sp = common(sub.add_parser("stability", help="eigenvalues of the equilibria along a sweep; Hopf points"))
    sp.add_argument("--sweep", help="ID.PARAM=START:STOP:STEP UNIT, e.g. Pa.value=10:200:2mmHg")
    sp.add_argument("--no-locate", action="store_true", help="do not locate Hopf points / complex onsets")
    sp.add_argument("--progress", action="store_true", help=argparse.SUPPRESS)  # on by default now (--quiet: off)
    sp.set_defaults(func=cmd_stability)
