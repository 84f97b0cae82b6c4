"""Nonlinear frequency response (thesis section artComp): step + sine forcing, batched.

For every member (frequency x grid point): start at the operating point with the input
source at its baseline P0, then apply P0 (1 + step) + amplitude P0 sin(2 pi f t) through the
source's drive parameters (Component.drive: its value and built-in sine term) (thesis:
10 % and 10 %; MODEL_NOTES "Analyses").  Integration proceeds in blocks of whole periods
until the fundamental of every output over the last period differs from that of the period
before by less than ``settle_tol`` (relative) - the transient has settled, detected not
guessed.  Then, over the last ``n_periods`` whole periods, the fundamental of each output
and of the input are found by DFT:
  rel_amplitude = |Y1| / y0           (amplitude over the steady output y0 at P0, thesis's
                                        'magnitude relative to steady state value')
  gain          = (|Y1| / y0) / (|X1| / P0)   (relative gain, comparable with AC)
  phase         = angle(Y1 / X1) in degrees, positive when the output leads the input
  thd           = sqrt(sum_{k=2..5} |Yk|^2) / |Y1|  (harmonic distortion)
All members integrate together in the vectorised batch integrator; chunks run in parallel.
Outputs, and their plausibility (hemocircuit.plausibility), are evaluated over the periods
each block's settle test and DFT use (the last max(2, n_periods) periods of the block).
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
from ..progress import advance
from ..provenance import clock, stamp
from ..labels import label_value
from ..results import Result

SAMPLES = 64  # per period
#: the compiled integrator of the forced runs: variable-order BDF.  Against a roadrunner rtol
#: 1e-11 reference (benchmarks/bench_peers.py --only freq, rtol 1e-8) it is closer than RODAS5P
#: (amplitude 6.0e-6 / phase 2.2e-4 deg, against 9.7e-6 / 4.2e-4 deg) for ~1.7x less CPU: the
#: forced, damped runs do not meet the growing oscillations BDF damps (kernels.tableaus)
METHOD = "bdf"


def _dft(y, n_per, k):
    """k-th harmonic (complex amplitude, sine-phase convention) over whole periods."""
    n = y.shape[-1]
    ph = np.exp(-2j * np.pi * k * np.arange(n) / n_per)
    return 2.0 / n * np.sum(y * ph, axis=-1)


def _block_outputs(sub, js, T, X):
    """Output columns of members ``js`` of the batch ``sub`` over their rows T (k, W) and
    states X (k, W, nx), in one stacked evaluation (member-major rows: Circuit.outputs repeats
    each member's parameters W times): {column: (k, W)}.  One call per block instead of one
    per member saves the ~1 ms fixed cost of an evaluation per member and block.  Raises what
    Circuit.outputs raises (the caller then evaluates member by member to say which failed)."""
    k, W = T.shape
    m = sub.subset(js)  # a view (member() deep-copies the circuit: ~10 ms a call)
    cols = m.outputs(T.reshape(-1), X.reshape(k * W, -1))
    return {name: np.broadcast_to(v, (k * W,)).reshape(k, W) for name, v in cols.items()}


def _member_columns(sub, j, t, X):
    """Output columns of member j alone: {column: (W,)}."""
    return sub.subset([j]).outputs(t, X)


def _run_chunk(job):
    """Worker: one vectorised batch.  job = (batch circuit, list of member descriptors, the
    members' baseline operating points (B, nx) and outputs there (B, outputs), options).
    Overflow in a member (values beyond floating-point range) is reported as its failure."""
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        return _run_chunk_members(job)


def _warm(job):
    """A zero-length integration of a chunk's members as the chunk makes it, and one block's
    worth of output rows (execution.run_chunks' ``warm``): loads the compiled integrator and
    the compiled nodal outputs into the parent, whose forked workers inherit them instead of
    each loading them from numba's cache on every call.  Same argument kinds as in the chunk
    (a grid per member, h_max per member): numba keeps one specialisation per argument
    types, read-only flags included."""
    bc, _, X0, _, opt = job
    return partial(_warm_run, bc, X0, opt)


def _warm_run(bc, X0, opt):
    integrate(bc, X0, np.zeros((bc.B, 1)), rtol=opt["rtol"], atol=opt["rtol"], h_max=np.ones(bc.B), method=METHOD)
    rows = max(2, opt["n_periods"]) * SAMPLES
    _block_outputs(bc, [0], np.zeros((1, rows)), np.repeat(np.asarray(X0[:1], dtype=float)[:, None, :], rows, axis=1))


def _run_chunk_members(job):
    bc, members, X0, y0, opt = job
    B = bc.B
    outputs, inp, drive = opt["outputs"], opt["input"], opt["drive"]
    inp_node_col = opt["input_col"]
    res = [None] * B
    # from the baseline operating point X0 (input at P0; outputs y0 there), the step + sine
    P0 = bc.parameters.values[f"{inp}.{drive.value}"]
    f = np.array([m["frequency"] for m in members])
    bc = bc.with_values({f"{inp}.{drive.value}": P0 * (1 + opt["step"]),
                         f"{inp}.{drive.amplitude}": P0 * opt["rel_amplitude"],
                         f"{inp}.{drive.frequency}": f,
                         f"{inp}.{drive.phase}": np.zeros(B),
                         f"{inp}.{drive.start}": np.zeros(B)})
    period = 1.0 / f
    t = np.zeros(B)
    x = np.array(X0, dtype=float)
    settled = np.zeros(B, bool)
    failed = np.zeros(B, bool)
    total_periods = np.zeros(B, int)
    block = opt["block_periods"]
    # outputs over the periods analysed (the last two, or n_periods): the outputs of the earlier
    # periods of a block are never used (their states are finite: the integrator stops on a
    # non-finite state), and they cost as much as integrating
    win = slice(-(max(2, opt["n_periods"]) * SAMPLES), None)
    while True:
        idx = np.nonzero(~settled & ~failed)[0]
        if idx.size == 0:
            break
        sub = bc.subset(idx)
        n_pts = block * SAMPLES
        grid = t[idx, None] + period[idx, None] * np.arange(n_pts + 1)[None, :] / SAMPLES
        # at most 1/32 period per step: the forcing and the output grid stay resolved
        r = integrate(sub, x[idx], grid, rtol=opt["rtol"], atol=opt["rtol"], h_max=period[idx] / 32, method=METHOD)
        js = [j for j in range(idx.size) if r.ok[j]]
        pos = {j: i for i, j in enumerate(js)}
        block_cols, block_findings = None, []
        if js:
            try:
                block_cols = _block_outputs(sub, js, grid[js][:, win], r.x[js][:, win])
                block_findings = plausibility.check(bc, {n: v.reshape(-1) for n, v in block_cols.items()})
            except HemocircuitError:  # some member's outputs cannot be evaluated: each on its own below
                block_cols = None
        for j, m in enumerate(idx):
            if not r.ok[j]:
                failed[m] = True
                res[m] = {"error": r.message[j]}
                advance()
                continue
            tt = grid[j]
            if block_cols is not None:
                cols = {n: v[pos[j]] for n, v in block_cols.items()}
            else:
                try:
                    cols = _member_columns(sub, j, tt[win], r.x[j][win])
                except HemocircuitError as exc:  # this member only
                    failed[m] = True
                    res[m] = {"error": str(exc)}
                    advance()
                    continue
            Y, X_in = np.array([cols[o] for o in outputs]), cols[inp_node_col]
            # no finding in the block's rows: none in this member's; else check its own rows
            findings = plausibility.check(bc, cols) if block_cols is None or block_findings else []
            if plausibility.errors(findings):
                failed[m] = True
                res[m] = {"error": "; ".join(map(str, plausibility.errors(findings)))}
                advance()
                continue
            # fundamental of each of the last two periods of this block
            a1 = _dft(Y[:, -SAMPLES:], SAMPLES, 1)
            a0 = _dft(Y[:, -2 * SAMPLES:-SAMPLES], SAMPLES, 1)
            total_periods[m] += block
            # change of the fundamental between the last two periods, relative to its size (or
            # to 1 % of the steady output, so a vanishing response does not block settling)
            rel = np.abs(a1 - a0) / np.maximum(np.abs(a1), 0.01 * np.abs(y0[m]) + 1e-300)
            # a slow mode shifts the mean of both periods alike and leaks equally into both
            # fundamentals: require the mean's drift per period to be small as well
            drift = np.abs(Y[:, -SAMPLES:].mean(axis=1) - Y[:, -2 * SAMPLES:-SAMPLES].mean(axis=1))
            rel = np.maximum(rel, drift / np.maximum(np.abs(a1), 0.01 * np.abs(y0[m]) + 1e-300))
            if np.all(rel < opt["settle_tol"]) or total_periods[m] >= opt["max_periods"]:
                settled[m] = True
                n = opt["n_periods"] * SAMPLES
                yw, xw = Y[:, -n:], X_in[-n:]
                X1 = _dft(xw, SAMPLES, 1)
                Y1 = _dft(yw, SAMPLES, 1)
                harm = np.array([_dft(yw, SAMPLES, h) for h in range(2, 6)])
                res[m] = {
                    "settle_change": float(np.max(rel)),
                    "Y1": Y1, "X1": X1, "y0": y0[m], "P0": P0[m], "mean": yw.mean(axis=1),
                    "thd": np.sqrt(np.sum(np.abs(harm) ** 2, axis=0)) / np.abs(Y1),
                    "periods": int(total_periods[m]), "settled": bool(np.all(rel < opt["settle_tol"])),
                    "warnings": [str(f) for f in plausibility.warnings(findings)],
                }
                overflow = [f"{name}({o})" for name in ("thd", "mean") for o, v in zip(outputs, res[m][name])
                            if not np.isfinite(v)] + [f"fundamental of {o}" for o, v in zip(outputs, Y1)
                                                      if not np.isfinite(v)]
                if overflow or not np.isfinite(X1):
                    res[m] = {"error": f"the response is not finite ({', '.join(overflow or ['input fundamental'])}"
                                       f"): values beyond floating-point range"
                                       + "".join(f"; {w}" for w in res[m]["warnings"])}
                advance()
            t[m] = tt[-1]
            x[m] = r.x[j, -1]
    return res


def frequency_response(circuit, freqs, outputs=None, input=None, step=0.1, amplitude=0.1,
                       grid=None, settle_tol=1e-3, n_periods=2, block_periods=4, max_periods=400, rtol=1e-8,
                       scheduler=None, workers=None, progress=None, members=None):
    """Batched nonlinear frequency response.  ``grid``: [(ID.PARAM, [values])]; or ``members``:
    an explicit list of parameter sets [{ID.PARAM: value}] (e.g. sensitivity samples) in place
    of the grid's cartesian product.

    ``input``: a source element with a built-in sine term (Component.drive); default the
    netlist's ``input:``.  ``outputs``: default the netlist's ``outputs:`` for 'freq'.
    Returns a :class:`FreqResult` (one row per grid point x frequency)."""
    from ..outputs import default_input, default_outputs, drive_of, input_element

    outputs = list(default_outputs(circuit, "freq") if outputs is None else outputs)
    grid = resolve_values(circuit, grid or [])
    assignments, descr = [], []
    for g in (expand_grid(grid) if members is None else members):
        for f in np.atleast_1d(freqs):
            assignments.append(dict(g))
            descr.append({"grid": g, "frequency": float(f)})
    input = input_element(circuit, default_input(circuit) if input is None else input)
    comp, drive = drive_of(circuit, input)
    if not drive.has_sine:
        raise HemocircuitError(f"input {input!r}: a '{comp.type_name}' has no built-in sine term "
                               "(the frequency response needs a source that declares one)")
    inp_col = comp.drive_output(input, circuit.elements[input].nodes)
    if inp_col is None:
        raise HemocircuitError(f"input {input!r}: no output column holds its driven quantity "
                               "(a pressure source needs its reference on ground)")
    opt = dict(outputs=outputs, input=input, drive=drive, input_col=inp_col, step=step, rel_amplitude=amplitude,
               settle_tol=settle_tol, n_periods=n_periods, block_periods=max(block_periods, n_periods + 1),
               max_periods=max_periods, rtol=rtol)
    started = clock()
    jobs, where = [], []
    before = {}  # members that failed before integrating: {member: {'error': reason}}
    stopped, results = None, []
    try:
        for bc, idx in build_batches(circuit, assignments):
            # the baseline operating points, once per distinct grid point (every frequency of
            # a grid point starts from the same one), here rather than in each chunk
            X0, opv, errors = member_operating_points(bc)
            y0 = np.stack([opv.get(o, np.full(bc.B, np.nan)) for o in outputs], axis=1) if opv \
                else np.full((bc.B, len(outputs)), np.nan)
            before.update({idx[j]: {"error": e} for j, e in enumerate(errors) if e is not None})
            good = [j for j, e in enumerate(errors) if e is None]
            # interleaved chunks, one per worker: frequencies (and grid points) of unequal cost
            # spread over all of them, so the workers finish together.  One each, not a few:
            # every chunk pays a block's Python overhead per block it runs (benchmarks/
            # bench_peers.py --only freq: 30 x 2 runs on 2 workers, 4 chunks 0.30-0.34 s, 2 chunks 0.26-0.29 s)
            n = (workers or default_workers()) if scheduler != "serial" else 1
            for chunk in split(good, n, interleave=True):
                jobs.append((bc.subset(chunk), [descr[idx[j]] for j in chunk], X0[chunk], y0[chunk], opt))
                where.append([idx[j] for j in chunk])  # bc.subset pickles without caches
        results = run_chunks(_run_chunk, jobs, scheduler=scheduler, workers=workers, progress=progress,
                             desc="frequency response", sizes=[len(w) for w in where], failures="collect",
                             warm=_warm(jobs[0]) if jobs else None)
    except KeyboardInterrupt as exc:  # SIGINT/SIGTERM: keep the finished chunks
        stopped, results = exc, getattr(exc, "chunk_results", None) or [None] * len(jobs)
    by_member = member_results(len(descr), where, results)
    by_member = [before.get(k, r) for k, r in enumerate(by_member)]
    inp_path = f"{input}.{drive.value}"
    paths = [p for p, _ in grid] if members is None else list(dict.fromkeys(k for m in members for k in m))
    res = FreqResult(circuit, paths, assignments, descr, by_member, outputs, inp_path)
    settings = dict(input=inp_path, outputs=outputs, frequencies=[float(f) for f in np.atleast_1d(freqs)],
                    grid={p: [str(v) for v in vals] for p, vals in grid}, step=step, amplitude=amplitude,
                    settle_tol=settle_tol, n_periods=n_periods, block_periods=opt["block_periods"],
                    max_periods=max_periods, rtol=rtol, atol=rtol, samples_per_period=SAMPLES)
    stamp(res, "freq", circuit, settings, started)
    return finish_batch(res, stopped)


class FreqResult(Result):
    """The nonlinear frequency response: one row per run (grid member x frequency), indexed by
    the grid parameters and ``frequency`` [Hz].  Per output ``o`` (input ``p``, its drive
    parameter, e.g. ``Pa.value``): ``rel_amplitude(o)`` [1] = |Y1|/y0, ``rel_gain(o/p)`` [1] =
    (|Y1|/y0)/(|X1|/P0), ``gain(o/p)`` [o unit/p unit] = |Y1|/|X1|, ``phase(o/p)`` [deg]
    (positive: the output leads), ``thd(o)`` [1], ``steady(o)`` and ``mean(o)`` [o unit]; per
    run ``periods`` [1], ``settled``, ``settle_change`` [1] and ``error`` (empty if it ran)."""

    def __init__(self, circuit, paths, assignments, descr, by_member, outputs, inp_path):
        self.outputs, self.input = list(outputs), inp_path
        cols, units = grid_columns(circuit, paths, assignments)
        cols["frequency"], units["frequency"] = np.array([d["frequency"] for d in descr]), "Hz"
        cu = {**circuit.column_units(), **derived_units(circuit.netlist.derived or {})}
        iu = circuit.param_unit(inp_path)
        n = len(descr)
        nan = np.full(n, np.nan)
        for o in outputs:
            ou = cu.get(o, "")
            for name, unit in ((f"rel_amplitude({o})", "1"), (f"rel_gain({o}/{inp_path})", "1"),
                               (f"gain({o}/{inp_path})", f"{ou}/{iu}"), (f"phase({o}/{inp_path})", "deg"),
                               (f"thd({o})", "1"), (f"steady({o})", ou), (f"mean({o})", ou)):
                cols[name], units[name] = nan.copy(), unit
        cols["periods"], units["periods"] = nan.copy(), "1"
        cols["settled"] = np.zeros(n, bool)
        cols["settle_change"], units["settle_change"] = nan.copy(), "1"
        cols["error"] = np.array([""] * n, dtype=object)
        for k, r in enumerate(by_member):
            if "error" in r:
                cols["error"][k] = r["error"]
                continue
            for i, o in enumerate(outputs):
                Y1, X1, y0 = r["Y1"][i], r["X1"], r["y0"][i]
                cols[f"rel_amplitude({o})"][k] = abs(Y1) / abs(y0)
                cols[f"rel_gain({o}/{inp_path})"][k] = (abs(Y1) / abs(y0)) / (abs(X1) / abs(r["P0"]))
                cols[f"gain({o}/{inp_path})"][k] = abs(Y1) / abs(X1)
                cols[f"phase({o}/{inp_path})"][k] = np.degrees(np.angle(Y1 / X1))
                cols[f"thd({o})"][k] = r["thd"][i]
                cols[f"steady({o})"][k] = y0
                cols[f"mean({o})"][k] = r["mean"][i]
            cols["periods"][k] = r["periods"]
            cols["settled"][k] = r["settled"]
            cols["settle_change"][k] = r["settle_change"]
        super().__init__(cols, units, index=list(paths) + ["frequency"])
        self.metadata["failed"] = [[{p: str(a[p]) for p in paths} | {"frequency": d["frequency"]}, r["error"]]
                                   for a, d, r in zip(assignments, descr, by_member) if "error" in r]
        warnings = [f"{_label(paths, a, d)}: {w}" for a, d, r in zip(assignments, descr, by_member)
                    for w in r.get("warnings", [])]
        if warnings:
            self.metadata["warnings"] = warnings


def _label(paths, a, d):
    return ", ".join([f"{p}={a[p]}" for p in paths] + [f"frequency={d['frequency']:g} Hz"])


def plot_result(res, path, select=None, title=None):
    """Bode plot from a result's columns (fresh or reloaded): relative gain and phase against
    frequency, one line per grid member and output."""
    plt = pyplot()

    grid = [k for k in res.index if k != "frequency"]
    outs = [k[len("rel_gain("):-1] for k in res.keys() if k.startswith("rel_gain(")]
    if select:
        outs = [o for o in outs if o.split("/")[0] in select] or outs
    ok = np.array([not e for e in res["error"]], bool) if "error" in res else np.ones(res.n_rows, bool)
    keys = sorted({tuple(res[g][i] for g in grid) for i in np.nonzero(ok)[0]}, key=str)
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(8, 6.5), sharex=True)
    styles = ["-", "--", ":", "-."]
    for j, o in enumerate(outs):
        for key in keys:
            sel = ok & np.all([res[g] == v for g, v in zip(grid, key)], axis=0) if grid else ok
            f = res["frequency"][sel]
            order = np.argsort(f)
            lab = o.split("/")[0] + ("" if not grid else " " + ", ".join(
                f"{g}={label_value(v)} {res.units.get(g, '')}".rstrip() for g, v in zip(grid, key)))
            line, = a1.semilogx(f[order], res[f"rel_gain({o})"][sel][order], styles[j % 4], marker=".", label=lab)
            a2.semilogx(f[order], res[f"phase({o})"][sel][order], styles[j % 4], marker=".", color=line.get_color(),
                        label=lab)
    a1.set_ylabel("relative gain (|Y1|/y0)/(|X1|/P0) [1]")
    a2.set_ylabel("phase [deg] (+ = output leads)")
    a2.set_xlabel("frequency [Hz]")
    for a in (a1, a2):
        a.grid(alpha=0.3, which="both")
    a1.legend(fontsize=7)
    a1.set_title(title or res.figure_title())
    save_figure(fig, path)
    return str(path)


def register_cli(sub, common):
    sp = common(sub.add_parser("freq", help="nonlinear frequency response (step + sine), batched"), outputs=False)
    sp.add_argument("--input", help="source element with a sine term (default: the netlist's 'input:', "
                                    "or its only source)")
    sp.add_argument("--output", action="append",
                    help="output column (repeatable; default: the netlist's 'outputs:')")
    sp.add_argument("--freq", default="0.001:1Hz", help="START:STOP[Hz] (log spaced) or a list 0.01,0.1Hz")
    sp.add_argument("--per-decade", type=float, default=10.0)
    sp.add_argument("--step", type=float, default=10.0, help="step in percent of the baseline (default 10)")
    sp.add_argument("--amplitude", type=float, default=10.0, help="sine amplitude in percent (default 10)")
    sp.add_argument("--scheduler", help="Dask scheduler address tcp://HOST:PORT (default: local processes)")
    sp.add_argument("--rtol", type=float, default=1e-8)
    sp.add_argument("--out", help="result CSV (one row per run; or .json)")
    sp.add_argument("--plot", help="Bode plot PNG")
    sp.add_argument("--show", action="append", help="column to print (repeatable)")
    sp.set_defaults(func=cmd_freq)


def cmd_freq(args):
    from ..commands import load_args, save_outputs

    c, _ = load_args(args)
    from ..outputs import default_outputs

    outputs = args.output or default_outputs(c, "freq")
    from .ac import parse_freqs
    freqs = parse_freqs(args.freq, args.per_decade)
    grid = [parse_grid_arg(g) for g in (args.grid or [])]
    res = frequency_response(c, freqs, outputs, args.input, args.step / 100, args.amplitude / 100, grid,
                             rtol=args.rtol, scheduler=args.scheduler, workers=args.workers)
    show = [k for o in res.outputs for k in (f"rel_amplitude({o})", f"rel_gain({o}/{res.input})",
                                             f"phase({o}/{res.input})", f"thd({o})")]
    print(res.summary(show=args.show or show, max_rows=0, max_cols=0, where=args.out))
    for where, why in res.metadata["failed"]:
        print(f"failed: {where}: {why}", file=sys.stderr)
    save_outputs(args, res)
