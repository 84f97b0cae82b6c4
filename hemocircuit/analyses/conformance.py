"""``hemocircuit conformance DIR [--against results|converged]``: run every svZeroDSolver case
of DIR/cases with their semantics and compare with their results (hemocircuit.svzerod.conformance)."""
from __future__ import annotations


def register_cli(sub, common):
    sp = sub.add_parser("conformance", help="run svZeroDSolver test cases and compare with their results")
    sp.add_argument("folder", help="folder with cases/, results/, converged/")
    sp.add_argument("--against", choices=("results", "converged"), default="converged")
    sp.add_argument("--case", action="append", help="run only this case (repeatable)")
    sp.add_argument("--repeat", type=int, default=3, help="timed runs per case (the best is shown)")
    sp.set_defaults(func=cmd_conformance)


def cmd_conformance(args):
    import os

    from ..errors import NetlistError
    from ..svzerod.conformance import format_table, run_folder

    if not os.path.isdir(os.path.join(args.folder, "cases")):
        raise NetlistError(f"{args.folder}: no cases/ folder (expected cases/*.json and results/ or converged/)")
    if args.repeat < 1:
        raise NetlistError(f"--repeat {args.repeat}: give the number of timed runs per case, 1 or more")
    rows = run_folder(args.folder, args.against, args.case, timed_runs=args.repeat)
    print(format_table(rows))
    return 0 if all(r.ok for r in rows) else 1
