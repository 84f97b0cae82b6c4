"""Input limits: how large and how deep a netlist, a protocol or an expression may be.

A netlist is data from anywhere (a colleague, a download, a generator gone wrong), so reading it
must take bounded time and memory: YAML alias bombs ("billion laughs"), nesting thousands deep,
files of hundreds of megabytes, ``${}`` parameters that double at each reference and expressions
of tens of thousands of terms are refused with an error that names the file and the limit.

Every limit has a generous default and is raised with an environment variable
``HEMOCIRCUIT_MAX_<NAME>`` (e.g. ``HEMOCIRCUIT_MAX_ELEMENTS=1000000``); see docs/netlist.md.
"""
from __future__ import annotations

import os

import yaml

from .errors import NetlistError

# usable cores (the default number of worker processes, hemocircuit.execution.default_workers)
_CORES = max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1))

DEFAULTS = {
    "FILE_MB": 16,            # size of one netlist / protocol / table file [MiB]
    "ELEMENTS": 200_000,      # elements of a circuit (the whole extends chain)
    "YAML_DEPTH": 40,         # nesting of YAML mappings and sequences
    "YAML_ALIASES": 100,      # YAML aliases (*name) in one file
    "YAML_NODES": 5_000_000,  # YAML nodes of one file, with every alias expanded
    "VALUE_CHARS": 10_000,    # characters of one value (also after ${} substitution)
    "QUANTITY_CHARS": 1_000,  # characters of one quantity with its unit (not an expression)
    "EXPR_NODES": 10_000,     # syntax-tree nodes of one expression
    "EXPR_DEPTH": 250,        # nesting depth of one expression (a sum of N terms is N deep)
    "TABLE_ROWS": 1_000_000,  # rows of one waveform table
    "RESULT_MB": 1024,        # size of one result file read back (show, conformance) [MiB]
    # worker processes of one batch (--workers, workers=): 4 per usable core.  A member is
    # CPU-bound, so processes beyond the cores only add memory (a forked worker with the
    # compiled engine loaded holds a few hundred MB) and start-up time; 4x still leaves room to
    # experiment, while a slip (--workers 42 on 2 cores started 42 processes) cannot fill the
    # machine with processes
    "WORKERS": 4 * _CORES,
    "FIT_STARTS": 10_000,     # multi-starts of one fit (settings.starts, --starts)
    "FIT_ROWS": 100_000,      # data rows of one fit, all datasets (a Jacobian solves (p + 1) x rows)
    "SENS_RUNS": 1_000_000,   # model evaluations of one sensitivity analysis (n (k + 1), r (k + 1), ...)
    "SENS_OUTPUTS": 100_000,  # output components of one sensitivity analysis (columns x settings x times)
    "SENS_VALUES": 20_000_000,  # model evaluations x output components of one sensitivity analysis
    "SENS_DESIGNS": 10_000,   # Latin hypercubes a constellation design chooses from
    "SENS_DESIGN_POINTS": 10_000_000,  # points of a constellation design (designs x n)
    "SENS_RESAMPLES": 10_000,  # Sobol bootstrap resamples
    "SENS_TIME_POINTS": 10_000_000,  # time points of one envelope run of a sensitivity output (t_end / dt)
    "SVZEROD_POINTS": 10_000_000,   # time points of one svZeroDSolver run (cycles x points per cycle)
    "SVZEROD_PERIOD_S": 1_000_000,  # cardiac period of an svZeroDSolver model [s]
    "SVZEROD_NAME_CHARS": 256,      # characters of one svZeroDSolver block name
}


def limit(name: str) -> int:
    """The limit ``name`` (a key of DEFAULTS), or the value of HEMOCIRCUIT_MAX_<name>."""
    env = os.environ.get(f"HEMOCIRCUIT_MAX_{name}")
    if env:
        try:
            value = int(float(env))
        except ValueError:
            raise NetlistError(f"HEMOCIRCUIT_MAX_{name}={env!r} is not a number") from None
        if value > 0:
            return value
    return DEFAULTS[name]


def how_to_raise(name: str) -> str:
    return f"(limit {limit(name):,}; set the environment variable HEMOCIRCUIT_MAX_{name} to raise it)"


def check_file_size(path, what="file"):
    """Refuse a file larger than the FILE_MB limit before reading it."""
    try:
        size = os.path.getsize(path)
    except OSError:
        return  # the read reports it
    if size > limit("FILE_MB") * 2 ** 20:
        raise NetlistError(f"{what} is {size / 2 ** 20:.1f} MiB, larger than allowed {how_to_raise('FILE_MB')}",
                           file=str(path))


def check_yaml(text: str, path, loader=None):
    """Scan the YAML event stream (iterative, no objects built) for the limits on depth,
    aliases, expanded size and value length, so that building the document cannot recurse
    without bound or multiply through aliases.  Syntax errors are left to the real load."""
    depth = aliases = nodes = 0
    anchor_start: dict = {}  # anchor -> node count when its node started
    anchor_size: dict = {}
    open_anchors: list = []  # (anchor, depth at start) of collections being read
    max_depth, max_aliases, max_nodes, max_chars = (limit(k) for k in
                                                    ("YAML_DEPTH", "YAML_ALIASES", "YAML_NODES", "VALUE_CHARS"))
    try:
        for ev in yaml.parse(text, Loader=loader or yaml.SafeLoader):
            if isinstance(ev, (yaml.MappingStartEvent, yaml.SequenceStartEvent)):
                depth += 1
                nodes += 1
                if depth > max_depth:
                    raise NetlistError(f"YAML nested {depth} levels deep at line {ev.start_mark.line + 1}, deeper "
                                       f"than allowed {how_to_raise('YAML_DEPTH')}", file=str(path))
                if ev.anchor is not None:
                    anchor_start[ev.anchor] = nodes - 1
                    open_anchors.append((ev.anchor, depth))
            elif isinstance(ev, (yaml.MappingEndEvent, yaml.SequenceEndEvent)):
                if open_anchors and open_anchors[-1][1] == depth:
                    name, _ = open_anchors.pop()
                    anchor_size[name] = nodes - anchor_start[name]
                depth -= 1
            elif isinstance(ev, yaml.ScalarEvent):
                nodes += 1
                if ev.anchor is not None:
                    anchor_size[ev.anchor] = 1
                if len(ev.value) > max_chars:
                    raise NetlistError(f"a value of {len(ev.value):,} characters at line {ev.start_mark.line + 1}, "
                                       f"longer than allowed {how_to_raise('VALUE_CHARS')}", file=str(path))
            elif isinstance(ev, yaml.AliasEvent):
                aliases += 1
                if aliases > max_aliases:
                    raise NetlistError(f"more than {max_aliases} YAML aliases (*name) {how_to_raise('YAML_ALIASES')}",
                                       file=str(path))
                nodes += anchor_size.get(ev.anchor, 1)
            if nodes > max_nodes:
                raise NetlistError(f"the YAML document expands to more than {max_nodes:,} values (aliases "
                                   f"included) {how_to_raise('YAML_NODES')}", file=str(path))
    except yaml.YAMLError:
        return  # reported by the load itself, with its line


def check_elements(count, path):
    if count > limit("ELEMENTS"):
        raise NetlistError(f"{count:,} elements, more than allowed {how_to_raise('ELEMENTS')}", file=str(path))


def check_value_length(text: str, where: dict, what="value"):
    if len(text) > limit("VALUE_CHARS"):
        raise NetlistError(f"{what} is {len(text):,} characters long, longer than allowed "
                           f"{how_to_raise('VALUE_CHARS')}", **where)
