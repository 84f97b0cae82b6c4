"""Provenance: what produced a result, recorded in ``result.metadata['provenance']``.

Filled in three steps:

1. :func:`stamp` (by every analysis, when it returns): the analysis name, its settings and
   tolerances, the status, and provenance fields that cost nothing -- hemocircuit, python,
   numpy and scipy versions, the netlist path, the date and time (ISO 8601, UTC) and the
   analysis's wall time.
2. :func:`add_invocation` (by the command line): the exact command line (``command`` as one
   shell line, ``argv`` as a list, ``cwd``), the ``--set`` overrides (numeric values and
   structural options alike) and the ``--protocol`` file.
3. :func:`complete` (when a result is written): ``netlist_files`` -- the files the loader
   read: the netlist, every file of its ``extends`` chain and every table it loaded, in that
   order (hemocircuit.inputs records them; nothing the loader did not read) -- and
   ``netlist_sha256``, one SHA-256 over them; the same for the protocol (``protocol_files``,
   ``protocol_sha256``).  A change to any parent or table changes the hash.

``hemocircuit show RESULT --rerun NEW`` rebuilds the run from the stored settings (hemocircuit.rerun).
"""
from __future__ import annotations

import datetime as _dt
import os
import platform
import time


def clock():
    """Start time for :func:`stamp`'s wall time."""
    return time.perf_counter()


def versions():
    import numpy
    import scipy

    from .version import __version__
    return {"hemocircuit": __version__, "python": platform.python_version(), "numpy": numpy.__version__,
            "scipy": scipy.__version__}


def stamp(result, analysis, circuit=None, settings=None, started=None, status=None):
    """Record the analysis, its settings and the cheap provenance fields on ``result``; returns it."""
    md = result.metadata
    md["analysis"] = analysis
    if status is not None:
        md["status"] = status
    md.setdefault("status", "complete")
    md["settings"] = {k: v for k, v in (settings or {}).items()}
    prov = md.setdefault("provenance", {})
    prov.update(versions())
    if circuit is not None and getattr(circuit, "file", None):
        prov["netlist"] = str(circuit.file)
        sources = getattr(circuit.netlist, "sources", None)  # what its load read (hemocircuit.inputs)
        if sources is not None and sources.files:
            record_sources(prov, "netlist", sources, circuit.file)
    if circuit is not None and "interest" not in md:  # what the default plots draw (hemocircuit.plotting)
        from .outputs import interest_of
        md["interest"] = interest_of(circuit)
    prov["date"] = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    if started is not None:
        prov["wall_time_s"] = round(time.perf_counter() - started, 6)
    return result


def add_invocation(metadata, argv, sets=None, protocol=None, netlists=None):
    """The command line that produced a result (the CLI calls this before writing)."""
    import shlex
    prov = metadata.setdefault("provenance", {})
    prov["command"] = shlex.join(["hemocircuit", *argv])
    prov["argv"] = list(argv)
    prov["cwd"] = os.getcwd()
    prov["sets"] = dict(sets or {})
    prov["protocol"] = str(protocol) if protocol else None
    if netlists and len(netlists) > 1:
        prov["netlists"] = [str(n) for n in netlists]
    return metadata


def complete(metadata, circuit=None):
    """Add the input files and their hashes to ``metadata['provenance']`` (in place) if not
    there yet: the files the loader read (hemocircuit.inputs records them), never files it did
    not; from ``circuit`` (or the protocol object) when given, else by loading the stored path
    again through the loader."""
    prov = metadata.setdefault("provenance", {})
    for key in ("netlist", "protocol"):
        path = prov.get(key)
        if path and f"{key}_sha256" not in prov:
            src = netlist_sources(path) if key == "netlist" else protocol_sources(path)
            prov[f"{key}_files"] = [os.path.relpath(f) if not os.path.isabs(path) else f for f in src.paths]
            prov[f"{key}_sha256"] = src.sha256()
    if "netlists" in prov and "netlists_sha256" not in prov:
        prov["netlists_sha256"] = {n: netlist_sources(n).sha256() for n in prov["netlists"]}
    return metadata


def record_sources(prov, key, sources, path):
    """``{key}_files`` and ``{key}_sha256`` from a loader's :class:`~hemocircuit.inputs.Sources`."""
    prov[f"{key}_files"] = [os.path.relpath(f) if not os.path.isabs(str(path)) else f for f in sources.paths]
    prov[f"{key}_sha256"] = sources.sha256()


def netlist_sources(path, allow_paths=None):
    """The files the loader reads for the netlist ``path`` (the netlist, its ``extends`` chain,
    its tables: hemocircuit.inputs.Sources), under the input policy.  A netlist that no longer
    loads gives the files read before the error."""
    from .circuit import load
    from .errors import HemocircuitError
    from .inputs import recording

    with recording() as src:
        try:
            load(str(path), allow_paths=allow_paths)
        except HemocircuitError:
            pass
    return src


def protocol_sources(path):
    """The files a protocol was read from (its YAML and the tables it names)."""
    from .errors import HemocircuitError
    from .inputs import recording
    from .protocol import Protocol

    with recording() as src:
        try:
            Protocol.load(str(path))
        except HemocircuitError:
            pass
    return src


def describe(metadata):
    """Printable lines: status, analysis, settings and provenance."""
    lines = [f"analysis: {metadata.get('analysis', '?')} ({metadata.get('status', 'complete')})"]
    for section in ("provenance", "settings", "measures", "solver"):
        d = metadata.get(section)
        if isinstance(d, dict) and d:
            lines.append(f"{section}:")
            lines += [f"  {k}: {v}" for k, v in d.items() if k != "argv"]
    failed = metadata.get("failed")
    if failed:
        lines.append(f"failed members: {len(failed)}")
    return "\n".join(lines)

