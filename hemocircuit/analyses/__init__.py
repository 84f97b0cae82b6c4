"""Analyses.  Each module is one analysis; they are attached to Circuit as methods here."""
from ..circuit import Circuit
from .op import operating_point
from .dc import dc_sweep
from .transient import simulate

Circuit.operating_point = operating_point
Circuit.dc_sweep = dc_sweep
Circuit.simulate = simulate
