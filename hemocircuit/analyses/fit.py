"""Parameter estimation: ``hemocircuit fit NETLIST SPEC.yaml`` (docs/fitting.md).

Weighted least squares of the spec's datasets over the spec's parameters (multi-start
trust-region reflective least squares, batched finite-difference Jacobians), then a report:
values with units and standard errors, correlations, rms per dataset, bound flags, the fit
plotted over the data and a fitted netlist fragment (hemocircuit.fitting.report).
"""
from __future__ import annotations

import os


def default_out(spec_path):
    """<spec folder>/output/<spec name>/ : where a later stage's ``start_from`` finds it."""
    spec_path = os.path.abspath(str(spec_path))
    return os.path.join(os.path.dirname(spec_path), "output", os.path.splitext(os.path.basename(spec_path))[0])


def fit(netlist, spec, out=None, sets=None, protocol=None, settings=None, workers=None, plot=True,
        progress=False, svzerod_units=None, allow_paths=None):
    """Fit ``spec`` (path of a fit spec) on ``netlist``; write the report into ``out`` (default
    :func:`default_out`; a new or empty folder, or one holding a previous fit's outputs, which
    are replaced).  ``settings`` override the spec's settings (starts, seed, max_nfev, ...);
    ``svzerod_units``: the unit system of an svZeroDSolver JSON netlist; ``allow_paths``: more
    folders the netlist and the spec may read files from (``--allow-path``; by default the
    spec's project, the netlist's project and the bundled netlists).  Returns (problem, result
    dict, {kind: path written})."""
    from ..fitting import load_problem
    from ..fitting.optimizer import fit_problem
    from ..fitting.report import check_out_dir, write
    from ..spec_inputs import integer

    if workers is not None:
        workers = integer(workers, None, "workers", lo=1, flag="--workers")
    problem = load_problem(netlist, spec, sets, protocol, svzerod_units, allow_paths=allow_paths)
    if out is None:
        out = default_out(spec)
        os.makedirs(os.path.dirname(out), exist_ok=True)  # <spec folder>/output
    check_out_dir(out)  # before the fit, not after it
    result = fit_problem(problem, settings, workers=workers, progress=progress)
    paths = write(problem, result, out, plot_png=plot)
    return problem, result, paths


def cmd_fit(args):
    from ..arguments import parse_sets
    from ..fitting.report import text

    settings = {k: v for k, v in (("starts", args.starts), ("seed", args.seed), ("max_nfev", args.max_nfev))
                if v is not None}
    problem, result, paths = fit(args.netlist, args.spec, args.out_dir, parse_sets(args.set), args.protocol, settings,
                                 args.workers, plot=not args.no_plot, progress=args.progress,
                                 svzerod_units=getattr(args, "svzerod_units", None),
                                 allow_paths=getattr(args, "allow_path", None))
    print(text(problem, result))
    for kind, path in paths.items():
        print(f"wrote {kind}: {path}")


def register_cli(sub, common):
    sp = common(sub.add_parser("fit", help="estimate parameters from data (fit spec YAML; docs/fitting.md)"),
                outputs=False, grid=False)
    sp.add_argument("spec", help="fit spec YAML: parameters with bounds, datasets, settings")
    # dest out_dir: a folder, checked by fit() (a previous fit's folder may be written again),
    # not by the command line's check of output files
    sp.add_argument("--out", dest="out_dir", metavar="DIR",
                    help="output folder (default: <spec folder>/output/<spec name>/); a new or empty folder, or a "
                         "previous fit's folder (its outputs are replaced)")
    sp.add_argument("--starts", type=int, help="number of Latin-hypercube starts (overrides the spec)")
    sp.add_argument("--seed", type=int, help="seed of the Latin hypercube (overrides the spec)")
    sp.add_argument("--max-nfev", type=int, help="evaluations per start (overrides the spec)")
    sp.add_argument("--workers", type=int, help="parallel processes for the starts (default: all cores)")
    sp.add_argument("--no-plot", action="store_true", help="do not draw fit.png")
    sp.add_argument("--progress", action="store_true", help="show a progress bar over the starts")
    sp.set_defaults(func=cmd_fit)
