"""Command line: ``hemocircuit check|op|dc|tran|graph|... NETLIST [options]``.

Every command gets its circuit from :func:`load_circuit` (netlist, ``--set``, ``--protocol``).

Errors the user can cause (netlist, units, topology, solver) print one clear message and
exit with status 2; they never show a traceback.

Exit status (docs/analyses.md, "Exit status and partial outputs"): 0 done (warnings about
implausible values, if any, on stderr); 2 error; 3 a batch finished but some members failed
(each named on stderr and in the output's ``error`` column and ``metadata['failed']``);
130 / 143 stopped by SIGINT / SIGTERM (what had finished written to NAME.partial.EXT).
"""
from __future__ import annotations

import argparse
import gc
import os
import shlex
import sys

from .arguments import assignments, parse_sets, quantity_to, range_spacing
from .commands import circuit_of_args, computed, load_args, record, report_grid, save_outputs
from .errors import HemocircuitError, Interrupted
from .loading import events_only

EXIT_ERROR = 2            # an error the user can fix (message on stderr)
EXIT_FAILED_MEMBERS = 3   # a batch completed, but some members failed (each reported)


def cmd_check(args):
    c, proto = load_args(args, uses_events=True)
    print(c.describe())
    print("ok: the netlist is valid" + (" and so is the protocol" if proto else ""))


def partial_path(path):
    """'run.csv' -> 'run.partial.csv': where a failed run's computed part goes."""
    stem, ext = os.path.splitext(path)
    return f"{stem}.partial{ext or '.csv'}"


def compute_op(args, sets):
    """One --grid member (:func:`computed`)."""
    c, _ = circuit_of_args(args, sets)
    return c.operating_point()


def cmd_op(args):
    if args.plot and not args.grid:
        raise HemocircuitError("op --plot: an operating point is one steady state, nothing to plot; "
                               "use 'dc --sweep ... --plot' for curves, or op --grid ... --plot")
    if args.grid:
        return report_grid(args, computed(args, compute_op))
    op = load_args(args)[0].operating_point()
    print(op.summary(show=args.show))
    save_outputs(args, op)


def _dc(args, c):
    param, rng = args.sweep.split("=", 1)
    return c.dc_sweep(param.strip(), range_spacing(rng))


def compute_dc(args, sets):
    """One --grid member (:func:`computed`)."""
    return _dc(args, circuit_of_args(args, sets)[0])


def cmd_dc(args):
    if not args.sweep or "=" not in args.sweep:
        raise HemocircuitError("dc needs --sweep ID.PARAM=START:STOP:STEP UNIT (e.g. Pa.value=20:200:5mmHg)")
    param = args.sweep.split("=", 1)[0].strip()
    c = None if args.grid else load_args(args)[0]
    res = computed(args, compute_dc) if args.grid else _dc(args, c)
    cols = res.columns
    # the netlist's outputs of interest (what the plots draw), else the first flows and pressures,
    # a source's own flow last (a pressure source's Q is minus the flow it delivers)
    interest = [k for k in (res.metadata.get("interest") or {}).get("outputs", []) if k in cols]
    sources = {e.id for e in c.netlist.elements if e.type.endswith("_source")} if c is not None else set()
    flows = sorted((k for k in cols if k.startswith("Q(")), key=lambda k: k[2:-1] in sources)
    show = args.show or interest or (flows[:2] + [k for k in cols if k.startswith("P(")][:3])
    if args.grid:
        return report_grid(args, res, show)
    print(res.summary(show=show, max_rows=0, where=args.out))
    for v, why in res.failed:
        print(f"failed at {param}={v:g}: {why}", file=sys.stderr)
    save_outputs(args, res)


def compute_tran(args, sets):
    """One run (a --grid member, :func:`computed`)."""
    import numpy as np

    c, proto = circuit_of_args(args, sets)
    t_end = float(quantity_to(args.t_end, "s")) if args.t_end else None
    dt = float(quantity_to(args.dt, "s")) if args.dt else None
    ic = assignments(args.ic, "--ic", "ID.STATE=VALUE", "Cv.V=20mL")
    max_step = float(quantity_to(args.max_step, "s")) if args.max_step else np.inf
    x0 = None
    if getattr(args, "periodic_start", False):  # the orbit's state at phase 0; --ic applies to the shooting's start
        from .analyses.periodic import periodic_start
        x0, orb = periodic_start(c, ic)
        ic = None
        print(f"periodic start: the orbit of period {orb.period:g} s by shooting ({orb.iterations} periods, "
              f"residual {orb.residual:.2g})", file=sys.stderr)
    return c.simulate(t_end, dt=dt, protocol=events_only(proto), integrator=args.integrator, rtol=args.rtol,
                      atol=args.atol, max_step=max_step, ic=ic, x0=x0, compile=args.compile)


def cmd_tran(args):
    from .errors import SolverError

    if getattr(args, "svzerod_output", None):
        return cmd_tran_svzerod(args)
    if args.grid:
        return report_grid(args, computed(args, compute_tran))
    try:
        res = compute_tran(args, parse_sets(args.set))
    except SolverError as exc:
        part = exc.partial
        if args.out and part is not None and part.n_rows:
            record(args, part)
            path = part.save(partial_path(args.out))
            print(f"error: {exc}", file=sys.stderr)
            print(f"the part computed (t = {part.t[0]:g} .. {part.t[-1]:g} s, {part.n_rows} points) is in "
                  f"{path}, marked partial", file=sys.stderr)
            raise _Reported() from None
        raise
    print(f"{len(res.t)} points, t = {res.t[0]:g} .. {res.t[-1]:g} s; solver {res.stats}")
    names = args.show or list(res.columns)[:12]
    res.check_columns(names)
    for k in names:
        print(f"  {res.label(k)} at end: {res[k][-1]:.6g}")
    if len(names) < len(res.columns):
        print(f"  (showing {len(names)} of {len(res.columns)} columns; "
              + (f"all in {args.out})" if args.out else "all with --out FILE.csv)"))
    save_outputs(args, res)


def cmd_tran_svzerod(args):
    """``tran MODEL.json --svzerod-output RESULT.json``: their simulation settings (the time
    span and grid come from their simulation_parameters, so --t-end, --dt, --ic, --protocol
    and --grid do not apply) and their result layout (hemocircuit.svzerod.output); --out and
    --plot get the whole run as usual."""
    from .inputs import read_json
    from .svzerod.importer import import_svzerod, is_svzerod_model
    from .svzerod.output import simulate_svzerod, write_svzerod_output

    given = [f"--{k.replace('_', '-')}" for k in ("t_end", "dt", "ic", "protocol", "grid") if getattr(args, k, None)]
    if given:
        raise HemocircuitError(f"--svzerod-output runs their simulation settings; {', '.join(given)} cannot be "
                               "combined with it (change number_of_cardiac_cycles etc. in the model)")
    cfg = None
    if str(args.netlist).lower().endswith(".json"):  # read once, under the input policy
        cfg = read_json(args.netlist, "svZeroDSolver model file")
    if not is_svzerod_model(cfg):
        raise HemocircuitError(f"--svzerod-output: {args.netlist} is not an svZeroDSolver JSON model "
                               "(simulation_parameters and blocks)")
    model = import_svzerod(cfg, units=getattr(args, "svzerod_units", None),
                           name=os.path.splitext(os.path.basename(str(args.netlist)))[0], source=args.netlist)
    c, res = simulate_svzerod(model, sets=parse_sets(args.set), start=args.svzerod_start, cfg=cfg)
    path = write_svzerod_output(args.svzerod_output, model, c, res, cfg)
    layout = "per variable" if model.sim.get("output_variable_based") else "per block"
    ran = res.metadata["svzerod_run"]  # their rule's count and extra cycles (the model is left as given)
    extra = f" (+{ran['extra_cycles']} by their cycle-to-cycle criterion)" if ran["extra_cycles"] else ""
    print(f"{ran['cycles']} cycles{extra} of {model.period:g} s, {model.points} points per cycle; solver {res.stats}")
    print(f"wrote {path} (their result layout, {layout}, units {model.units['P']}, {model.units['Q']})")
    args.computed_result = res
    save_outputs(args, res)


class _Reported(HemocircuitError):
    """An error already reported on stderr (exit status 2, nothing more printed)."""


def cmd_show(args):
    """Reload a result file: its provenance, a summary, optionally a plot or a re-run."""
    from .provenance import describe
    from .results import Result

    res = Result.load(args.result)
    print(describe(res.metadata))
    print(f"{res.n_rows} rows x {len(res)} columns; index {res.index}")
    print(res.summary(show=args.show, where=args.result))
    if args.plot:
        res.plot(args.plot, select=args.show)
        print(f"wrote {args.plot}")
    if args.rerun is not None:
        from .rerun import rerun_argv
        new, notes = rerun_argv(res.metadata, args.result, args.rerun, lambda cmd: build_parser(cmd).commands[cmd],
                                RESULT_COMMANDS, args.allow_path)
        for n in notes:
            print(f"note: {n}", file=sys.stderr)
        print("re-running: " + shlex.join(["hemocircuit", *new]))
        return main(new)
    return 0


def cmd_graph(args):
    c, _ = load_args(args)
    from .plotting import draw_circuit
    out = args.out or args.plot or "circuit.png"
    draw_circuit(c, out)
    print(f"wrote {out}")


BUILTIN = ("check", "op", "dc", "tran", "graph", "show")


def build_parser(command=None):
    """The argument parser.  ``command``: the command about to run -- only the analysis
    module that defines it is imported (``hemocircuit CMD`` starts without importing the
    others); None: every command (also ``--help``, which lists the analysis commands from
    their sources without importing them)."""
    from .version import __version__

    p = argparse.ArgumentParser(prog="hemocircuit", description="Lumped-parameter hemodynamic circuits.")
    p.add_argument("--version", action="version", version=f"hemocircuit {__version__}")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    def common(sp, outputs=True, netlist=True, grid=True):
        """The loader's arguments (netlist, --set, --protocol: see load_circuit) and --quiet,
        shared by every command; with ``grid`` also --grid, --workers and --measure
        (:func:`computed`, :func:`apply_measures`); with ``outputs`` also --out, --plot, --show."""
        if netlist:
            sp.add_argument("netlist", help="netlist YAML file")
        sp.add_argument("--set", action="append", metavar="ID.PARAM=VALUE",
                        help="set a parameter (units allowed, e.g. Pa.value=90mmHg) or a structural option "
                             "(e.g. art.ca_order=2); repeatable")
        sp.add_argument("--protocol", help="protocol YAML: its 'initial' settings (and events at t = 0) apply "
                                           "to every command, its later events to tran")
        sp.add_argument("--allow-path", action="append", metavar="DIR",
                        help="let the netlist read files (extends, tables) in DIR too; by default only its "
                             "project folder and the bundled netlists (repeatable)")
        # no choices= here: the importer checks the name against svzerod.model.UNIT_SYSTEMS (importing it
        # for --help would cost start-up time)
        sp.add_argument("--svzerod-units", metavar="SYSTEM",
                        help="for an svZeroDSolver JSON model: the unit system of its numbers, cgs (default, "
                             "their convention; SI when the model says m^3), mmHg (mmHg, mL, s) or SI")
        sp.add_argument("--quiet", action="store_true", help="no progress bars (and, for ac, no table)")
        if grid:
            sp.add_argument("--grid", action="append", metavar="ID.PARAM=V1,V2,...",
                            help="nested sweep: run the command for each value (units allowed, e.g. "
                                 "art.tau_Ca=1,10s or Pa.value=60:120:20mmHg; structural options too); "
                                 "repeatable, Cartesian product; one result, grid columns first")
            sp.add_argument("--workers", type=int, help="worker processes for --grid (default: all cores)")
            sp.add_argument("--measure", action="append", metavar="SPEC",
                            help="a measure of the result (repeatable), e.g. 'plateau Q(Rla) 10%% ref=100mmHg', "
                                 "'resonance P(a)', 'mean P(a) from=10s' (docs/analyses.md, Measures)")
        if outputs:
            sp.add_argument("--out", help="output file (CSV for series/sweeps, JSON for op, PNG for graph)")
            sp.add_argument("--plot", help="PNG plot file")
            sp.add_argument("--show", action="append", help="column to print/plot (repeatable)")
        return sp

    common(sub.add_parser("check", help="validate a netlist (and protocol)"), grid=False).set_defaults(func=cmd_check)
    common(sub.add_parser("op", help="operating point (steady state)")).set_defaults(func=cmd_op)
    sp = common(sub.add_parser("dc", help="DC sweep of a parameter"))
    sp.add_argument("--sweep", help="ID.PARAM=START:STOP:STEP UNIT, e.g. Pa.value=20:200:5mmHg")
    sp.set_defaults(func=cmd_dc)
    sp = common(sub.add_parser("tran", help="transient simulation"))
    sp.add_argument("--t-end", help="end time (e.g. 100 or '100 s')")
    sp.add_argument("--dt", help="output interval (e.g. 0.1 s)")
    sp.add_argument("--integrator", choices=("rodas5p", "rodas4", "ros34pw2", "bdf", "scipy-bdf", "scipy-radau",
                                             "lsoda"),
                    help="the integrator: rodas5p (default; Rosenbrock order 5), rodas4, ros34pw2 or bdf on the "
                         "compiled engine, or scipy's solve_ivp BDF, Radau or LSODA; recorded in the result's "
                         "provenance with its tolerances")
    sp.add_argument("--rtol", type=float, default=1e-6, help="relative tolerance (default 1e-6)")
    sp.add_argument("--atol", type=float,
                    help="absolute tolerance per unit of each state's scale (default rtol * 1e-3)")
    sp.add_argument("--max-step", help="largest step (e.g. 0.1 s; default: no limit)")
    sp.add_argument("--periodic-start", action="store_true",
                    help="start on the periodic steady state of the netlist's own period (its periodic waveforms, "
                         "a heart's beat), found by shooting from the usual start, instead of the operating point")
    sp.add_argument("--ic", action="append", metavar="ID.STATE=VALUE",
                    help="start with this state overridden (units allowed, e.g. Cv.V=20mL, art.Ca=1e-7M); "
                         "the others at the operating point; repeatable")
    sp.add_argument("--compile", choices=("background", "wait"),
                    default=os.environ.get("HEMOCIRCUIT_COMPILE", "background"),
                    help="first run of a set of component types: build the compiled engine in the background "
                         "and integrate on the scipy path meanwhile (default; $HEMOCIRCUIT_COMPILE), or wait "
                         "for the build")
    sp.add_argument("--svzerod-output", metavar="RESULT.json",
                    help="an svZeroDSolver model: run it with their simulation settings (cycles, points per "
                         "cycle, output options) and write their result layout (pandas to_json) here")
    sp.add_argument("--svzerod-start", choices=("operating-point", "their-steady"), default="operating-point",
                    help="with --svzerod-output: start from the true operating point (default) or their "
                         "steady_initial procedure (31 pseudo-time steps)")
    sp.set_defaults(func=cmd_tran)
    common(sub.add_parser("graph", help="draw the circuit graph to PNG"), grid=False).set_defaults(func=cmd_graph)
    sp = sub.add_parser("show", help="reload a result file: provenance, summary, re-plot, re-run")
    sp.add_argument("result", help="a CSV or JSON file written by a hemocircuit command (--out)")
    sp.add_argument("--plot", help="draw it again to this PNG file")
    sp.add_argument("--show", action="append", help="column to print/plot (repeatable)")
    sp.add_argument("--rerun", metavar="OUT", help="run the analysis stored in its provenance again, writing OUT: "
                                                   "its settings only (no stored output file, --allow-path or "
                                                   "--scheduler), its netlist inside the result's project")
    sp.add_argument("--allow-path", action="append", metavar="DIR",
                    help="with --rerun: let the stored netlist or protocol lie in DIR too (repeatable)")
    sp.add_argument("--set", action="append", help=argparse.SUPPRESS)
    sp.add_argument("--protocol", help=argparse.SUPPRESS)
    sp.add_argument("--quiet", action="store_true", help="no progress bars (for --rerun)")
    sp.set_defaults(func=cmd_show)
    p.commands = sub.choices  # {name: parser}
    index = command_index()
    if command == "--help":  # names and one-line help only: nothing imported
        for name, (_, text) in index.items():
            sub.add_parser(name, help=text)
        return p
    if command in BUILTIN:
        return p
    for register in _extra_commands(index[command][0] if command in index else None):
        register(sub, common)
    return p


def command_index():
    """{command: (module, help)} of the analysis modules' commands, read from their sources
    (``sub.add_parser("NAME", help="...")`` in ``register_cli``) without importing them."""
    import re
    from pathlib import Path
    out = {}
    for path in sorted((Path(__file__).parent / "analyses").glob("*.py")):
        text = path.read_text(encoding="utf-8")
        if "def register_cli" not in text:
            continue
        for m in re.finditer(r'add_parser\(\s*"([\w-]+)",\s*help="([^"]*)"', text):
            out[m.group(1)] = (path.stem, m.group(2))
    return out


def _extra_commands(only=None):
    """Commands contributed by analysis modules: every module of ``hemocircuit.analyses`` that
    defines ``register_cli(subparsers, common)`` (found by scanning the package, like the
    components), then third-party ones registered under the entry-point group
    ``hemocircuit.analyses`` (the entry point names such a module or function)."""
    import importlib
    import pkgutil
    from importlib import metadata

    from . import analyses

    out = []
    for info in sorted(pkgutil.iter_modules(analyses.__path__), key=lambda i: i.name):
        if only is not None and info.name != only:
            continue
        spec = info.module_finder.find_spec(info.name)
        origin = getattr(spec, "origin", None)
        if origin and origin.endswith(".py"):
            with open(origin, encoding="utf-8") as fh:  # import only the modules that add a command:
                if "def register_cli" not in fh.read():  # the others pull in scipy for nothing
                    continue
        m = importlib.import_module(f"{analyses.__name__}.{info.name}")
        if callable(getattr(m, "register_cli", None)):
            out.append(m.register_cli)
    if only is not None:
        return out
    for ep in metadata.entry_points(group="hemocircuit.analyses"):
        try:
            obj = ep.load()
            out.append(obj if callable(obj) and not hasattr(obj, "register_cli") else obj.register_cli)
        except Exception as exc:  # noqa: BLE001 - one broken plug-in must not take the CLI down
            print(f"warning: analysis plug-in {ep.name!r} ({ep.value}) could not be loaded: {exc}",
                  file=sys.stderr)
    return out


OUTPUT_OPTIONS = ("out", "plot", "phase_plot", "svzerod_output", "rerun")
FIGURE_OPTIONS = ("plot", "phase_plot")
#: the commands whose --out is one result file (hemocircuit.results); show --rerun re-runs these
RESULT_COMMANDS = ("op", "dc", "tran", "ac", "freq", "stability", "envelope", "periodic", "compare")


def _check_outputs(args):
    """Every output file's folder is checked (or created) before anything is computed."""
    from . import io
    for key in OUTPUT_OPTIONS:
        path = getattr(args, key, None)
        if path is not None:  # '' too: an empty name is an error, not a silent no-write
            flag = "--" + key.replace("_", "-")
            io.prepare_output(path, flag)
            if key in FIGURE_OPTIONS:
                io.figure_format(path, flag)
            elif key in ("out", "rerun") and args.command in ("show",) + RESULT_COMMANDS:
                from .results import file_format
                file_format(path, flag)  # .csv, .json, .npz, .parquet: known before computing


def main(argv=None):
    argv = sys.argv[1:] if argv is None else [str(a) for a in argv]
    first = next((a for a in argv if not a.startswith("-")), None)
    if first is None or first == "help":
        parser = build_parser("--help")  # --help, --version, or no command: nothing heavy imported
    else:
        parser = build_parser(first)
        if first not in parser.commands:  # maybe a plug-in's command: load them all
            parser = build_parser()
        if first not in parser.commands:
            import difflib
            known = sorted(parser.commands)
            near = difflib.get_close_matches(first, known, n=2)
            print(f"hemocircuit: error: unknown command {first!r}" +
                  (f"; did you mean {' or '.join(near)}?" if near else f"; commands: {', '.join(sorted(known))}"),
                  file=sys.stderr)
            return 2
    args = parser.parse_args(argv)
    args.argv = argv
    from . import progress
    progress.enable(not getattr(args, "quiet", False))
    from .execution import catch_signals, leave_if_stuck, restore_signals
    previous = catch_signals()
    try:
        _check_outputs(args)
        rc = args.func(args)
    except _Reported:
        return EXIT_ERROR
    except HemocircuitError as exc:
        for w in (getattr(getattr(args, "computed_result", None), "metadata", None) or {}).get("warnings", []):
            print(f"warning: {w}", file=sys.stderr)  # e.g. why a measure found nothing
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_ERROR
    except KeyboardInterrupt as exc:  # SIGINT, or SIGTERM (execution.catch_signals)
        return leave_if_stuck(_interrupted(args, Interrupted.of(exc)))  # exit cannot hang on a stopped pool
    except BrokenPipeError:  # output piped into a command that stopped reading (| head)
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    finally:
        restore_signals(previous)
    if isinstance(rc, int) and rc:
        return rc
    return _report(args)


def _report(args):
    """Warnings and failed members of the command's result on stderr; the exit status."""
    res = getattr(args, "computed_result", None)
    if res is None:
        return 0
    for w in res.metadata.get("warnings", []) or []:
        print(f"warning: {w}", file=sys.stderr)
    failed = res.metadata.get("failed", []) or []
    if failed:
        print(f"{len(failed)} member(s) failed (listed above and in the result's 'failed' metadata"
              + (" and 'error' column" if "error" in res else "") + f"); exit status {EXIT_FAILED_MEMBERS}",
              file=sys.stderr)
        return EXIT_FAILED_MEMBERS
    return 0


def _interrupted(args, exc):
    """Write what finished (``exc.partial``) to NAME.partial.EXT when --out was given, say so,
    and return 128 + the signal number (130 for SIGINT, 143 for SIGTERM)."""
    part = exc.partial
    msg = f"interrupted by {exc.signame}"
    if part is not None:
        part.metadata["status"] = "partial"
        part.metadata["interrupted"] = exc.signame
        done = part.metadata.get("members_done")
        msg += f"; {done}" if done else ""
        if getattr(args, "out", None) and part.n_rows:
            try:
                record(args, part)
                path = part.save(partial_path(args.out))
                msg += f"; what had finished is in {path}, marked partial"
            except HemocircuitError as err:
                msg += f"; could not write the partial result: {err}"
        elif not getattr(args, "out", None):
            msg += "; nothing written (no --out)"
    print(msg, file=sys.stderr)
    return 128 + exc.signum


def run():
    """The console command: :func:`main`, then the interpreter's exit without its last garbage
    collections over every object still alive (``gc.freeze``): with numba's compiled functions
    loaded they took ~0.2 s of every run.  Objects are still released as the modules are;
    what is written is closed already (hemocircuit.io)."""
    code = main()
    gc.freeze()
    sys.exit(code)


if __name__ == "__main__":
    run()
