"""``hemocircuit show RESULT --rerun NEW``: a result file is data, not a command.

A result file records the command line that produced it (hemocircuit.provenance), and such
files are shared.  Re-running one must not let its author choose what the reader's machine
writes, reads or connects to.  So the stored command line is parsed with the command's own
parser (abbreviations such as ``--plo=`` resolve to the option they name) and rebuilt from a
whitelist of analysis settings:

* the command must be an analysis that writes one result (cli.RESULT_COMMANDS);
* kept: the settings in :data:`SETTINGS` (``--set``, ``--grid``, sweeps, times, tolerances,
  inputs and outputs of interest, ...);
* the netlist(s) and ``--protocol``: kept when they lie in the allowed folders (the project of
  the result file, the bundled netlists, and the ``--allow-path`` folders given to ``show``,
  never ones stored in the file); a relative path is taken relative to the stored working
  folder, which is not entered;
* dropped, each named in a note: everything else -- output files (``--out``, ``--plot``,
  ``--series``, ...), folder permissions (``--allow-path``), network addresses
  (``--scheduler``) and options this version does not know.

The new result goes to the file given to ``--rerun``.  The command is printed before it runs.
"""
from __future__ import annotations

import os

from .errors import HemocircuitError, excerpt


#: analysis settings kept from the stored command line (argparse dests)
SETTINGS = ("set", "grid", "measure", "show", "quiet", "workers", "svzerod_units",
            "sweep", "t_end", "dt", "method", "integrator", "atol", "max_step", "ic", "compile", "svzerod_start",
            "tran",
            "input", "output", "freq", "per_decade", "step", "amplitude", "rtol",
            "no_locate", "forced", "cycle_tol", "t_settle")

#: paths kept only inside the allowed folders
PATHS = ("netlist", "netlists", "protocol")


def rerun_argv(metadata, result_path, out, parser_of, commands, allow_paths=None):
    """(argv of the run to make, [notes on what was dropped]) from a result's ``metadata``.
    ``out``: the new result file; ``parser_of(command)``: that command's argparse parser (the
    command line's own); ``commands``: the commands that write one result (the only ones re-run).  Raises a HemocircuitError when the stored command cannot be re-run
    safely, saying why."""
    from .access import Access

    prov = metadata.get("provenance") if isinstance(metadata, dict) else None
    argv = prov.get("argv") if isinstance(prov, dict) else None
    if not isinstance(argv, list) or not argv or not all(isinstance(a, str) for a in argv):
        raise HemocircuitError(f"{result_path}: no command line in its provenance (written by the API?); run the "
                               "analysis yourself")
    command = argv[0]
    if command not in commands:
        raise HemocircuitError(f"{result_path}: its stored command {excerpt(command, 40)} cannot be re-run by "
                               f"show --rerun (only {', '.join(commands)}); run it yourself")
    parser = parser_of(command)
    parser.exit_on_error = False
    try:
        args, unknown = parser.parse_known_args(argv[1:])
    except (Exception, SystemExit) as exc:  # noqa: BLE001 - argparse reports a bad line by exiting
        raise HemocircuitError(f"{result_path}: its stored command line cannot be read ({excerpt(exc, 120)}); "
                               "run the analysis yourself") from None
    notes = [f"ignored {excerpt(u, 40)} (not an option of {command})" for u in unknown]

    cwd = prov.get("cwd")
    access = Access.for_netlist(result_path, allow_paths)
    new = [command]
    for action in parser._actions:  # noqa: SLF001 - argparse has no public list of a parser's actions
        dest = action.dest
        value = getattr(args, dest, None)
        if dest == "help" or value is None or value is False or value == action.default:
            continue
        if dest in PATHS:
            paths = value if isinstance(value, list) else [value]
            checked = [_allowed_path(p, cwd, access, result_path, "--" + dest if action.option_strings else dest)
                       for p in paths]
            if action.option_strings:
                new += [f"{action.option_strings[-1]}={p}" for p in checked]
            else:
                new += checked
        elif dest in SETTINGS:
            flag = action.option_strings[-1]
            if value is True:
                new.append(flag)
            else:
                new += [f"{flag}={v}" for v in (value if isinstance(value, list) else [value])]
        else:
            shown = "--" + dest.replace("_", "-")
            notes.append(f"dropped the stored {shown} (" + ("an output file" if dest in _OUTPUTS else
                                                             "a folder permission" if dest == "allow_path" else
                                                             "a network address" if dest == "scheduler" else
                                                             "not an analysis setting") + ")")
    return new + ["--out", os.path.abspath(out)], notes


_OUTPUTS = ("out", "plot", "phase_plot", "svzerod_output", "series", "failures")


def _allowed_path(path, cwd, access, result_path, flag):
    if "\x00" in path:
        raise HemocircuitError(f"{result_path}: its stored {flag} is not a file name")
    if not os.path.isabs(path):
        if not (isinstance(cwd, str) and os.path.isabs(cwd)):
            raise HemocircuitError(f"{result_path}: its stored {flag} {excerpt(path, 80)} is relative and no "
                                   "working folder was stored; run the analysis yourself")
        path = os.path.join(cwd, path)
    path = os.path.normpath(path)
    if not access.allows(path):
        raise HemocircuitError(f"{result_path}: its stored {flag} {excerpt(path, 200)} is outside the allowed "
                               f"folders {access.folders} (the result file's project and the bundled netlists); "
                               "give show --allow-path DIR to allow its folder, or run the analysis yourself")
    if not os.path.isfile(path):
        raise HemocircuitError(f"{result_path}: its stored {flag} {path} does not exist (any more)")
    return path
