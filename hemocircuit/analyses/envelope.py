"""Oscillation envelopes (thesis chapter 6, figures figzetaVariations, figomegaVariations,
figflowWithOscillation): for every member of a sweep x grid, start at the operating point
(which may be unstable), integrate for ``t_end`` (thesis: 1000 s), and report over the
settled window (the last ``window`` fraction of the run): min/max/mean of chosen outputs,
whether a sustained oscillation developed, its period, and the time-averaged flow next to
the steady-state flow.

Start: the operating point plus a small kick (``kick`` x state scale on the states that are
not held by a conservation law), so that an unstable equilibrium visibly departs whatever
the tolerance; the thesis relied on its 1e-15 m equilibrium error instead.
Sustained oscillation: the output's peak-to-peak over the window exceeds ``osc_tol`` of its
mean and the second half of the window has at least half the peak-to-peak of the first half.
"""
from __future__ import annotations

import sys
from functools import partial

import numpy as np

from ..batch import build_batches, expand_grid, grid_columns, member_operating_points, parse_grid_arg, resolve_values
from ..batch_integrator import integrate
from .. import plausibility
from ..errors import HemocircuitError
from ..execution import default_workers, finish_batch, member_results, run_chunks, split
from ..derived import derived_units
from ..io import pyplot, save_figure
from ..provenance import clock, stamp
from ..labels import label_value
from ..results import Result
from ..system.outputs import COMPILED_OUTPUT_ROWS


def law_states(c):
    held = set()
    for s in c.law_specs:
        for g, i, vol, sign in s["terms"]:
            held.update(int(j) for j in g.sidx[i])
    return held


#: before the window, the outputs' plausibility is checked at every SETTLING_STRIDE-th output time
SETTLING_STRIDE = 10


def _run_chunk(job):
    """Worker: one batch.  job = (batch circuit, start states (B, nx), {output: (B,) values at
    the operating point}, options)."""
    bc, X0, steady, opt = job
    grid = np.arange(0.0, opt["t_end"] + 0.5 * opt["dt"], opt["dt"])
    r = integrate(bc, X0, **_per_member(bc.B, grid), rtol=opt["rtol"], atol=opt["rtol"])
    out = []
    for k in range(bc.B):
        try:
            out.append(_summary(bc, k, r, grid, steady, opt))
        except HemocircuitError as exc:  # this member only
            out.append({"error": str(exc)})
    return out


def _warm_run(bc, X0, steady, opt):
    """execution.run_chunks' ``warm``: a zero-length integration of a chunk's members as the
    chunk makes it, and a summary's worth of output rows: loads the compiled integrator and the
    compiled nodal outputs into the parent, whose forked workers inherit them instead of each
    loading them from numba's cache (~0.08 s a worker, before its first summary)."""
    integrate(bc, X0, **_per_member(bc.B, [0.0]), rtol=opt["rtol"], atol=opt["rtol"])
    rows = COMPILED_OUTPUT_ROWS
    bc.subset([0]).outputs(np.zeros(rows), np.repeat(np.asarray(X0[:1], dtype=float), rows, axis=0))


def _per_member(B, grid):
    """integrate()'s t_out and h_max as arrays per member, (B, T) and (B,): the compiled integrator is
    then called with the same argument types whatever the chunk's size (numba keeps one
    specialisation per argument types, read-only flags included, each loaded at first use)."""
    return {"t_out": np.repeat(np.asarray(grid, dtype=float)[None], B, axis=0), "h_max": np.full(B, np.inf)}


def _summary(bc, k, r, grid, steady, opt):
    """Statistics of member k of the integrated batch over the settled window (``steady``:
    {output: (B,) values at the operating point})."""
    n_win = min(max(int(len(grid) * opt["window"]), 4), len(grid))
    if not r.ok[k]:
        return {"error": r.message[k]}
    # the outputs at every time of the window; before it (the run settling) at every
    # SETTLING_STRIDE-th, for the plausibility checks only: a nodal solve per output time
    # is a sixth of a member's cost, and the statistics read the window alone
    rows = np.r_[np.arange(0, len(grid) - n_win, SETTLING_STRIDE), np.arange(len(grid) - n_win, len(grid))]
    cols = bc.subset([k]).outputs(grid[rows], r.x[k][rows])
    findings = plausibility.check(bc, cols, t=grid[rows])
    if plausibility.errors(findings):
        return {"error": "; ".join(map(str, plausibility.errors(findings)))}
    cols = {name: v[-n_win:] for name, v in cols.items()}
    tw = grid[-n_win:]
    osc = {}
    for o in opt["outputs"]:
        y = cols[o]
        half = len(y) // 2
        osc[o] = bool(np.ptp(y) > opt["osc_tol"] * abs(np.mean(y)) and np.ptp(y[half:]) >= 0.5 * np.ptp(y[:half]))
    y0 = cols[opt["outputs"][0]]
    # means over whole periods: between the first and last upward crossing of the mean
    z = y0 - y0.mean()
    up = np.nonzero((z[:-1] < 0) & (z[1:] >= 0))[0]
    sel = slice(up[0], up[-1] + 1) if any(osc.values()) and len(up) >= 2 else slice(None)
    row = {}
    for o in opt["outputs"]:
        y = cols[o]
        row.update({f"{o} min": float(y.min()), f"{o} max": float(y.max()), f"{o} mean": float(y[sel].mean()),
                    f"{o} steady": float(steady[o][k])})
    row["oscillating"] = bool(any(osc.values()))
    row["period [s]"] = period_of(tw, y0) if row["oscillating"] else float("nan")
    row["warnings"] = [str(f) for f in plausibility.warnings(findings)]
    if opt.get("keep_series"):
        row["series"] = {o: cols[o] for o in opt["keep_series"] if o in cols}
        row["t"] = tw
    return row


def period_of(t, y):
    """Mean spacing of upward crossings of the mean (NaN if fewer than two)."""
    z = y - y.mean()
    up = np.nonzero((z[:-1] < 0) & (z[1:] >= 0))[0]
    if len(up) < 2:
        return float("nan")
    tc = t[up] - z[up] * (t[up + 1] - t[up]) / (z[up + 1] - z[up])
    return float(np.mean(np.diff(tc)))


def envelope(circuit, sweep, grid=None, outputs=None, t_end=1000.0, dt=0.1, window=0.3,
             kick=1e-3, osc_tol=1e-3, rtol=1e-5, keep_series=None, scheduler=None, workers=None, progress=None,
             members=None):
    """sweep: (ID.PARAM, values) ; grid: [(ID.PARAM, values)]; or ``members``: an explicit list
    of parameter sets [{ID.PARAM: value}] in place of the sweep x grid product.  Returns an
    :class:`EnvelopeResult` (one row per point or member).

    outputs: columns to report, the first giving the period; default the netlist's
    ``outputs:`` for 'envelope' (:func:`hemocircuit.outputs.default_outputs`)."""
    from ..outputs import default_outputs

    started = clock()
    outputs = list(default_outputs(circuit, "envelope") if outputs is None else outputs)
    grids = resolve_values(circuit, ([sweep] if sweep else []) + list(grid or []))
    assignments = expand_grid(grids) if members is None else list(members)
    opt = dict(outputs=outputs, t_end=float(t_end), dt=float(dt), window=float(window), osc_tol=osc_tol,
               rtol=rtol, keep_series=keep_series)
    jobs, where = [], []
    before = {}  # members without an operating point: {member: {'error': reason}}
    stopped, results = None, []
    try:
        for bc, idx in build_batches(circuit, assignments):
            # the operating points of the whole batch at once (vectorised), here rather than
            # in each chunk; the start: plus the kick on the states no law holds
            X0, opv, errors = member_operating_points(bc)
            held = law_states(bc)
            free = [j for j in range(bc.nx) if j not in held]
            X0[:, free] += kick * bc.state_scales[free]
            before.update({idx[j]: {"error": e} for j, e in enumerate(errors) if e is not None})
            good = [j for j, e in enumerate(errors) if e is None]
            # a few interleaved chunks per worker: the bar (runs done / total) moves while runs
            # last minutes, and members of unequal cost (oscillating or not) spread evenly
            n = 4 * (workers or default_workers()) if scheduler != "serial" else 1
            for chunk in split(good, n, interleave=True):
                steady = {o: np.asarray(opv[o])[chunk] for o in outputs if o in opv}
                jobs.append((bc.subset(chunk), X0[chunk], steady, opt))  # pickles without caches
                where.append([idx[j] for j in chunk])
        results = run_chunks(_run_chunk, jobs, scheduler=scheduler, workers=workers, progress=progress,
                             desc="envelope", sizes=[len(w) for w in where], failures="collect",
                             warm=partial(_warm_run, *jobs[0]) if jobs else None)
    except KeyboardInterrupt as exc:  # SIGINT/SIGTERM: keep the finished chunks
        stopped, results = exc, getattr(exc, "chunk_results", None) or [None] * len(jobs)
    by_member = member_results(len(assignments), where, results)
    by_member = [before.get(k, r) for k, r in enumerate(by_member)]
    paths = ([p for p, _ in grids] if members is None
             else list(dict.fromkeys(k for m in assignments for k in m)))
    res = EnvelopeResult(circuit, paths, assignments, by_member, outputs)
    settings = dict(sweep=[sweep[0], [str(v) for v in grids[0][1]]] if sweep else None,
                    grid={p: [str(v) for v in vals] for p, vals in grids[1 if sweep else 0:]}, outputs=outputs,
                    t_end=float(t_end), dt=float(dt), window=float(window), kick=kick, osc_tol=osc_tol, rtol=rtol,
                    atol=rtol)
    stamp(res, "envelope", circuit, settings, started)
    return finish_batch(res, stopped)


class EnvelopeResult(Result):
    """One row per member of the sweep x grid, indexed by the swept and grid parameters.  Per
    output ``o``: ``min(o)``, ``max(o)``, ``mean(o)`` (over whole periods of the window) and
    ``steady(o)`` (the operating point), in ``o``'s unit; per member ``oscillating``,
    ``period`` [s] (NaN when steady) and ``error`` (empty if it ran).  ``series`` (with
    ``keep_series``): per row {column: values over the window} and ``t`` its times (not written
    to files)."""

    def __init__(self, circuit, paths, assignments, by_member, outputs):
        self.outputs = list(outputs)
        cols, units = grid_columns(circuit, paths, assignments)
        cu = {**circuit.column_units(), **derived_units(circuit.netlist.derived or {})}
        n = len(assignments)
        for o in outputs:
            for q in ("min", "max", "mean", "steady"):
                cols[f"{q}({o})"], units[f"{q}({o})"] = np.full(n, np.nan), cu.get(o, "")
        cols["oscillating"] = np.zeros(n, bool)
        cols["period"], units["period"] = np.full(n, np.nan), "s"
        cols["error"] = np.array([""] * n, dtype=object)
        self.series, self.t = [None] * n, [None] * n
        for k, r in enumerate(by_member):
            if "error" in r:
                cols["error"][k] = r["error"]
                continue
            for o in outputs:
                for q in ("min", "max", "mean", "steady"):
                    cols[f"{q}({o})"][k] = r[f"{o} {q}"]
            cols["oscillating"][k] = r["oscillating"]
            cols["period"][k] = r["period [s]"]
            self.series[k], self.t[k] = r.get("series"), r.get("t")
        super().__init__(cols, units, index=list(paths))
        self.metadata["failed"] = [[{p: str(a[p]) for p in paths}, r["error"]]
                                   for a, r in zip(assignments, by_member) if "error" in r]
        warnings = [f"{', '.join(f'{p}={a[p]}' for p in paths)}: {w}" for a, r in zip(assignments, by_member)
                    for w in r.get("warnings", [])]
        if warnings:
            self.metadata["warnings"] = warnings


def plot_result(res, path, select=None, title=None):
    """Envelope of the first output (or ``select[0]``) against the swept parameter: the steady
    value as a line, the [min, max] range shaded, one per grid member (fresh or reloaded)."""
    plt = pyplot()

    outs = [k[4:-1] for k in res.keys() if k.startswith("min(")]
    output = next((o for o in (select or []) if o in outs), outs[0])
    sweep_param, grid = res.index[0], res.index[1:]
    from ..labels import members
    ok = np.array([not e for e in res["error"]], bool)
    fig, ax = plt.subplots(figsize=(8, 5))
    for g, (lab, mask) in enumerate(members(res, grid)):
        sel = ok & mask
        x = np.asarray(res[sweep_param][sel], dtype=float)
        order = np.argsort(x)
        color = f"C{g % 10}"
        ax.fill_between(x[order], res[f"min({output})"][sel][order], res[f"max({output})"][sel][order], alpha=0.2,
                        color=color, lw=0, label=f"min..max {lab}".strip())
        ax.plot(x[order], res[f"steady({output})"][sel][order], ["-", "--", ":", "-."][g % 4], color=color,
                lw=max(2.2 - 0.4 * g, 1.0), marker=".", label=f"steady state {lab}".strip())
    ax.set_xlabel(res.label(sweep_param))
    ax.set_ylabel(f"{output} [{res.units.get(f'min({output})', '')}]")
    win = (res.metadata.get("settings") or {}).get("window")
    last = f"the last {100 * float(win):.0f} % of each run" if win else "the last part of each run"
    ax.set_title(title or f"{res.figure_title()}: {output}, steady state and range over {last}", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0)
    save_figure(fig, path)
    return str(path)


def plot_phase_plane(path, res, x_col, y_col):
    plt = pyplot()

    curves = [(r, s) for r, s in zip(res.rows(), res.series) if s and x_col in s and y_col in s]
    fig, ax = plt.subplots(figsize=(7, 4.5))
    if len(curves) <= 8:  # few: one legend entry each, beside the axes
        for r, s in curves:
            ax.plot(s[x_col], s[y_col], lw=0.7, label=", ".join(f"{k}={label_value(r[k])}" for k in res.index))
        if curves:
            ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0)
    else:  # many: the sweep's value as colour (a colour bar), the grid's members as line styles
        import matplotlib as mpl
        sweep, rest = res.index[0], list(res.index[1:])
        v = np.array([float(r[sweep]) for r, _ in curves])
        norm = mpl.colors.Normalize(vmin=v.min(), vmax=v.max() if v.max() > v.min() else v.min() + 1)
        cmap = mpl.colormaps["viridis"]
        others = list(dict.fromkeys(tuple(r[k] for k in rest) for r, _ in curves))
        styles = ["-", "--", ":", "-."]
        for (r, s), val in zip(curves, v):
            style = styles[others.index(tuple(r[k] for k in rest)) % 4]
            ax.plot(s[x_col], s[y_col], style, lw=0.6, color=cmap(norm(val)))
        if rest and len(others) > 1:
            for j, o in enumerate(others[:4]):
                ax.plot([], [], styles[j], color="k", lw=0.8, label=", ".join(f"{k}={label_value(x)}"
                                                                              for k, x in zip(rest, o)))
            ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.25, 1.0), borderaxespad=0)
        fig.colorbar(mpl.cm.ScalarMappable(norm=norm, cmap=cmap), ax=ax, label=f"{sweep} [{res.units.get(sweep, '')}]")
    ax.set_xlabel(x_col)
    ax.set_ylabel(y_col)
    ax.grid(alpha=0.3)
    save_figure(fig, path)


def register_cli(sub, common):
    sp = common(sub.add_parser("envelope", help="oscillation envelope over a sweep x grid (batched)"), outputs=False)
    sp.add_argument("--sweep", required=True, help="ID.PARAM=START:STOP:STEP UNIT or V1,V2,...")
    sp.add_argument("--output", action="append",
                    help="outputs to report, the first gives the period (default: the netlist's 'outputs:')")
    sp.add_argument("--t-end", type=float, default=1000.0, help="s (default 1000)")
    sp.add_argument("--dt", type=float, default=0.1, help="output interval, s")
    sp.add_argument("--rtol", type=float, default=1e-5)
    sp.add_argument("--scheduler")
    sp.add_argument("--out", help="result CSV (one row per member; or .json)")
    sp.add_argument("--plot", help="envelope PNG (first output)")
    sp.add_argument("--show", action="append", help="column to print (repeatable)")
    sp.add_argument("--phase-plot", help="phase-plane PNG (the netlist's 'outputs: {phase_plane: [x, y]}')")
    sp.set_defaults(func=cmd_envelope)


def cmd_envelope(args):
    from ..commands import load_args, save_outputs
    from ..errors import HemocircuitError
    from ..outputs import default_outputs

    c, _ = load_args(args)
    outputs = args.output or default_outputs(c, "envelope")
    sweep = parse_grid_arg(args.sweep)
    grid = [parse_grid_arg(g) for g in (args.grid or [])]
    keep = None
    if args.phase_plot:
        keep = default_outputs(c, "phase_plane")
        if len(keep) < 2:
            raise HemocircuitError(f"--phase-plot needs two columns (x, y): declare 'outputs: {{phase_plane: [X, Y]}}' "
                                   f"in the netlist (found {keep})")
        keep = keep[:2]
    res = envelope(c, sweep, grid, outputs, t_end=args.t_end, dt=args.dt, rtol=args.rtol, keep_series=keep,
                   scheduler=args.scheduler, workers=args.workers)
    o = outputs[0]
    show = [f"min({o})", f"max({o})", f"steady({o})", "oscillating", "period"]
    print(res.summary(show=args.show or show, max_rows=0, where=args.out))
    for where, why in res.metadata["failed"]:
        print(f"failed: {where}: {why}", file=sys.stderr)
    save_outputs(args, res)
    if args.phase_plot:
        plot_phase_plane(args.phase_plot, res, keep[0], keep[1])
        print(f"wrote {args.phase_plot}")
