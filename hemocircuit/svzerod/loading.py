"""The assembled Circuit of an svZeroDSolver JSON model (above the importer, which netlist
loading itself uses for a ``.json`` model)."""
from __future__ import annotations

import os

from .importer import import_svzerod, write_netlist


def load_svzerod(path, units: str | None = None, mean: bool = False):
    """The assembled Circuit of an svZeroDSolver JSON model (through a temporary netlist file,
    so it is exactly what ``import-svzerod`` writes).  ``mean``: time series at their means."""
    import tempfile

    from ..circuit import load

    model = import_svzerod(path, units)
    with tempfile.TemporaryDirectory(prefix="hemocircuit_svz_") as d:
        out = os.path.join(d, model.netlist["name"] + ".yaml")
        write_netlist(model.mean_netlist if mean else model.netlist, out)
        return load(out)
