"""Parameter estimation: fit specs, datasets, the fit problem and its report
(``hemocircuit fit NETLIST SPEC.yaml``; docs/fitting.md)."""
from .problem import FitProblem, load_problem  # noqa: F401
from .spec import FitSpec, load_spec  # noqa: F401
