"""Sensitivity analysis: ``hemocircuit sensitivity NETLIST SPEC.yaml`` (docs/sensitivity.md).

The spec names the parameters and their space, the method (constellation, morris, sobol,
local, dynamic) and the output measured (op, dc, tran, freq, envelope or a fit spec's rms
error); see :mod:`hemocircuit.sensitivity`.
"""
from __future__ import annotations

import os
import re


def sensitivity(circuit, spec, netlist_path=None, scheduler=None, workers=None, progress=False, overrides=None,
                allow_paths=None):
    """Run a sensitivity spec (path or Spec) on ``circuit``.  Returns a Result.

    The files the spec names (a tran ``protocol``, a ``fit_error`` spec and that spec's data)
    must lie in the spec's project, the netlist's project, the bundled netlists or
    ``allow_paths`` (``--allow-path``)."""
    from ..sensitivity import run
    from ..sensitivity.outputs import make_objective
    from ..sensitivity.spec import load_spec
    from ..spec_inputs import integer, spec_access

    netlist_path = netlist_path or circuit.file
    if isinstance(scheduler, str) and scheduler not in ("serial", "processes") and \
            not re.match(r"^[a-z]+://[^\s/:]+:\d+$", scheduler):
        from ..errors import HemocircuitError
        raise HemocircuitError(f"--scheduler {scheduler[:80]!r}: give 'serial' (this process), 'processes' (local "
                               "worker processes, the default) or a Dask scheduler's address tcp://HOST:PORT")
    if workers is not None:
        workers = integer(workers, None, "workers", lo=1, flag="--workers")
    if isinstance(spec, (str, os.PathLike)):
        spec = load_spec(str(spec), overrides, spec_access(spec, netlist_path, allow_paths))
    objective = make_objective(spec, circuit, netlist_path, scheduler, workers, allow_paths)
    return run(spec, objective, scheduler=scheduler, workers=workers, progress=progress)


def write_outputs(result, out=None, plot=None, series=None, failures=None):
    """The table CSV, plot, time-resolved series CSV (dynamic) and failure list, as asked."""
    from ..sensitivity import report

    written = []
    if out:
        report.write_table(out, result.table, result.columns)
        written.append(out)
    if series and result.method == "dynamic":
        report.write_table(series, result.extra["series"], result.extra["series_columns"])
        written.append(series)
    if plot:
        report.plot(result, plot)
        written.append(plot)
    if failures and result.failures:
        report.write_failures(failures, result.failures)
        written.append(failures)
    return written


def register_cli(sub, common):
    sp = common(sub.add_parser("sensitivity", help="sensitivity analysis of an output (constellation, Morris, "
                                                   "Sobol, local, dynamic) from a spec YAML"), outputs=False,
                grid=False)
    sp.add_argument("spec", help="sensitivity spec YAML (docs/sensitivity.md)")
    sp.add_argument("--method", help="override the spec's method (constellation, morris, sobol, local, dynamic)")
    sp.add_argument("--scheme", choices=("additive", "multiplicative"), help="override the parameter space scheme")
    sp.add_argument("--range", type=float, help="multiplicative range in percent (e.g. 10)")
    sp.add_argument("--n", type=int, help="points (constellation, dynamic) or base samples (sobol)")
    sp.add_argument("--trajectories", type=int, help="Morris trajectories")
    sp.add_argument("--seed", type=int)
    sp.add_argument("--scheduler", help="'serial', or a Dask scheduler tcp://HOST:PORT (default: local processes)")
    sp.add_argument("--workers", type=int, help="local worker processes (default: all cores)")
    sp.add_argument("--out", help="result table CSV (units in the headers)")
    sp.add_argument("--plot", help="PNG: sigma vs mu* (log), Sobol bars, local bars, or time-resolved mean/variance")
    sp.add_argument("--series", help="dynamic method: time-resolved mean/variance CSV")
    sp.add_argument("--failures", help="CSV of failed samples and their reasons")
    sp.set_defaults(func=cmd_sensitivity)


def cmd_sensitivity(args):
    import sys

    from ..commands import load_args

    from .. import io

    for flag, path in (("--series", args.series), ("--failures", args.failures)):
        if path is not None:  # checked before the run, as --out and --plot
            io.prepare_output(path, flag)
    c, _ = load_args(args)
    over = {"name": args.method, "scheme": args.scheme, "range": args.range, "n": args.n,
            "trajectories": args.trajectories, "seed": args.seed}
    res = sensitivity(c, args.spec, os.path.abspath(args.netlist), scheduler=args.scheduler, workers=args.workers,
                      progress=None, overrides=over, allow_paths=getattr(args, "allow_path", None))
    s = res.space
    print(f"{res.method} ({s.scheme}{', +/-%g %%' % s.range_pct if s.scheme == 'multiplicative' else ''}): "
          f"{res.n_runs} model evaluations, {len(res.failures)} failed")
    for reason in res.failures[:5]:
        print(f"  failed: {reason[0]}: {reason[1]}", file=sys.stderr)
    key = res.extra.get("rank_key", "mu_star")
    if res.method != "dynamic":
        for j, lab in enumerate(res.labels[:6]):
            print(f"ranking by {key} for {lab}:")
            vals = res.values(key, j)
            for rank, name in enumerate(res.ranking(j), 1):
                print(f"  {rank:2d}. {name:<24} {vals[name]:.4g}")
    else:
        print(f"{len(res.extra['times'])} times; peak |mean effect| per parameter:")
        import numpy as np
        for i, name in enumerate(s.names):
            m = np.abs(res.extra["mean"][i, :, 0])
            if np.isfinite(m).any():
                k = int(np.nanargmax(m))
                print(f"  {name:<24} {m[k]:.4g} at t = {res.extra['times'][k]:g} s")
    for path in write_outputs(res, args.out, args.plot, args.series, args.failures):
        print(f"wrote {path}")
