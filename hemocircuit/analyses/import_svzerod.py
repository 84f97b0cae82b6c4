"""``hemocircuit import-svzerod MODEL.json -o MODEL.yaml``: an svZeroDSolver model as a netlist
(hemocircuit.svzerod.importer; docs/svzerod.md)."""
from __future__ import annotations

import sys


def register_cli(sub, common):
    sp = sub.add_parser("import-svzerod", help="convert an svZeroDSolver JSON model to a netlist")
    sp.add_argument("model", help="svZeroDSolver JSON model")
    sp.add_argument("-o", "--out", required=True, help="netlist YAML to write")
    sp.add_argument("--units", help="unit system of their numbers: cgs (default, their convention; SI when the "
                                    "model says m^3), mmHg or SI")
    sp.set_defaults(func=cmd_import_svzerod)


def cmd_import_svzerod(args):
    from ..io import prepare_output
    from ..svzerod import import_svzerod, write_netlist

    prepare_output(args.out, "-o/--out")  # before the import: a name that cannot be written is refused first
    model = import_svzerod(args.model, units=args.units)
    write_netlist(model.netlist, args.out)  # atomic; never through a link leading out of its folder
    print(f"wrote {args.out}: {len(model.netlist['elements'])} elements, cardiac period {model.period:g} s, "
          f"{model.n_cycles} cycles of {model.points} points", file=sys.stderr)
