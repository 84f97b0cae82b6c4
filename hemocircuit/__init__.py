"""hemocircuit: lumped-parameter (0D) hemodynamic circuits.

    import hemocircuit as hc
    c = hc.load("netlists/payne06_passive.yaml")
    op = c.operating_point()          # steady state
    sw = c.dc_sweep("Pa.value", "20:200:5 mmHg")
    tr = c.simulate(t_end=100)        # transient

Circuit units: pressure mmHg, flow mL/s, volume mL, time s (see hemocircuit.units).
"""
from .circuit import Circuit, assemble, load  # noqa: F401
from .errors import HemocircuitError, NetlistError, SolverError, TopologyError  # noqa: F401
from . import analyses as _analyses  # noqa: F401  (attaches analysis methods to Circuit)

__version__ = "0.1.0"
