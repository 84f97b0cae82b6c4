"""Provenance: what produced a result, recorded in ``result.metadata['provenance']``.

Filled in three steps:

1. :func:`stamp` (by every analysis, when it returns): the analysis name, its settings and
   tolerances, the status, and provenance fields that cost nothing -- hemocircuit, python,
   numpy and scipy versions, the netlist path, the date and time (ISO 8601, UTC) and the
   analysis's wall time.
2. :func:`add_invocation` (by the command line): the exact command line (``command`` as one
   shell line, ``argv`` as a list, ``cwd``), the ``--set`` overrides (numeric values and
   structural options alike) and the ``--protocol`` file.
3. :func:`complete` (when a result is written): ``netlist_files`` -- the netlist, every file
   of its ``extends`` chain and every data file they name (``file:`` tables), in that order --
   and ``netlist_sha256``, one SHA-256 over their contents; the same for the protocol
   (``protocol_files``, ``protocol_sha256``).  A change to any parent or table changes the hash.

``hemocircuit show RESULT --rerun NEW`` runs the stored command line again (see cli.py).
"""
from __future__ import annotations

import datetime as _dt
import hashlib
import os
import platform
import time


def clock():
    """Start time for :func:`stamp`'s wall time."""
    return time.perf_counter()


def versions():
    import numpy
    import scipy

    from . import __version__
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
    if circuit is not None and "interest" not in md:  # what the default plots draw (hemocircuit.plotting)
        from .plotting import interest_of
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


def complete(metadata):
    """Add the file hashes to ``metadata['provenance']`` (in place) if not there yet."""
    prov = metadata.setdefault("provenance", {})
    for key in ("netlist", "protocol"):
        path = prov.get(key)
        if path and f"{key}_sha256" not in prov:
            files = source_files(path)
            prov[f"{key}_files"] = [os.path.relpath(f) if not os.path.isabs(path) else f for f in files]
            prov[f"{key}_sha256"] = sha256_files(files)
    if "netlists" in prov and "netlists_sha256" not in prov:
        prov["netlists_sha256"] = {n: sha256_files(source_files(n)) for n in prov["netlists"]}
    return metadata


def source_files(path):
    """The YAML file ``path``, the files of its ``extends`` chain and the data files they name
    (``file:`` entries), each resolved against the folder of the file naming it; files that
    cannot be read are skipped (the netlist loader reports them, not the provenance)."""
    import yaml

    out, todo = [], [os.path.abspath(path)]
    while todo:
        p = todo.pop(0)
        if p in out or not os.path.isfile(p):
            continue
        out.append(p)
        if not p.lower().endswith((".yaml", ".yml")):
            continue
        try:
            with open(p, encoding="utf-8") as fh:
                data = yaml.safe_load(fh)
        except (OSError, yaml.YAMLError, UnicodeDecodeError):
            continue
        base = os.path.dirname(p)
        if isinstance(data, dict) and isinstance(data.get("extends"), str):
            todo.append(os.path.join(base, data["extends"]))
        todo.extend(os.path.join(base, f) for f in _named_files(data))
    return out


def _named_files(value, depth=0):
    if depth > 50:
        return []
    found = []
    if isinstance(value, dict):
        for k, v in value.items():
            if k == "file" and isinstance(v, str) and v and "${" not in v:
                found.append(v)
            else:
                found += _named_files(v, depth + 1)
    elif isinstance(value, list):
        for v in value:
            found += _named_files(v, depth + 1)
    return found


def sha256_files(paths):
    """One SHA-256 over the contents of ``paths`` in order (each length-prefixed, so moving a
    byte from one file to the next changes it; file names do not enter: a moved project keeps
    its hash)."""
    h = hashlib.sha256()
    for p in paths:
        with open(p, "rb") as fh:
            data = fh.read()
        h.update(len(data).to_bytes(8, "little"))
        h.update(data)
    return h.hexdigest()


def command_of(metadata):
    """(argv list, cwd) stored by :func:`add_invocation`, or (None, None)."""
    prov = (metadata or {}).get("provenance", {}) or {}
    argv = prov.get("argv")
    return (list(argv), prov.get("cwd")) if isinstance(argv, list) else (None, None)


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

