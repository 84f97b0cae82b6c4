"""Parameter paths ``ID.NAME``: the element id is everything before the last dot, so the
elements of a subcircuit instance (``brain.art``, hemocircuit.subcircuits) address their
parameters as ``brain.art.tau_Ca``; parameter, option and state names never hold a dot."""
from __future__ import annotations


def split_path(path) -> tuple[str, str]:
    """'brain.art.tau_Ca' -> ('brain.art', 'tau_Ca'); 'Pa' (no dot) -> ('Pa', '')."""
    path = str(path)
    eid, dot, name = path.rpartition(".")
    return (eid, name) if dot else (path, "")
