"""``hemocircuit reproduce [--quick] [--only SECTION...] --out report/``: every figure and number
of thesis chapters 4-6 that the model produces, regenerated into one self-contained HTML report
(report/index.html, figures, data CSVs with provenance, statements.csv); see docs/reproduce.md
and :mod:`hemocircuit.reproduce`."""
from __future__ import annotations


def cmd_reproduce(args):
    from ..io import prepare_folder
    from ..reproduce import build

    prepare_folder(args.out_dir)
    rep = build(args.out_dir, quick=args.quick, only=args.only, progress=not args.no_progress, argv=args.argv)
    c = rep.counts
    print(f"wrote {rep.index}")
    print(f"{len(rep.rows)} statements: {c.get('ok', 0)} agree, {c.get('bad', 0)} differ, "
          f"{c.get('fail', 0)} not computed, {c.get('skip', 0)} not run; "
          f"{sum(r.status == 'failed' for r in rep.runs.values())} section(s) failed "
          f"({rep.provenance['wall_time_s']:.0f} s, {rep.provenance['mode']})")
    return 1 if any(r.status == "failed" for r in rep.runs.values()) else 0


def register_cli(sub, common):
    from ..reproduce.registry import SECTIONS

    sp = sub.add_parser("reproduce", help="regenerate the figures and numbers of thesis chapters 4-6 into an HTML "
                                          "report (docs/reproduce.md)")
    sp.add_argument("--out", dest="out_dir", required=True, help="output folder (index.html, figures/, data/, statements.csv)")
    sp.add_argument("--quick", action="store_true", help="coarser grids and shorter runs (< 3 min), marked as such")
    sp.add_argument("--only", nargs="+", metavar="SECTION", help=f"run only these sections: {', '.join(SECTIONS)}")
    sp.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    sp.set_defaults(func=cmd_reproduce)
