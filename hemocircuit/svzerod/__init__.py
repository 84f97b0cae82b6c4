"""svZeroDSolver interoperability: import their JSON models (importer.py, on model.py,
structure.py, blocks.py and index_reduction.py), run them with their simulation semantics and
compare with their results (conformance.py), write their result layout (output.py), their
steady_initial procedure (steady_initial.py) and cycle-to-cycle criterion (cycles.py).
docs/svzerod.md."""
from .importer import import_svzerod, write_netlist
from .model import SvzModel
from .loading import load_svzerod

__all__ = ["SvzModel", "import_svzerod", "load_svzerod", "write_netlist"]
