"""svZeroDSolver interoperability: import their JSON models (importer.py), run them with their
simulation semantics and compare with their results (conformance.py), write their result
layout (output.py), their steady_initial procedure (steady_initial.py) and cycle-to-cycle
criterion (cycles.py).  docs/svzerod.md."""
from .importer import SvzModel, import_svzerod, write_netlist
from .loading import load_svzerod

__all__ = ["SvzModel", "import_svzerod", "load_svzerod", "write_netlist"]
