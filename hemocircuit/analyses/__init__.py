"""Analyses.  Each module is one analysis; they are attached to Circuit as methods here."""
from ..circuit import Circuit
from .ac import ac_response
from .dc import dc_sweep
from .envelope import envelope
from .freq import frequency_response
from .op import operating_point
from .stability import stability_sweep
from .transient import simulate

Circuit.operating_point = operating_point
Circuit.dc_sweep = dc_sweep
Circuit.simulate = simulate
Circuit.ac_response = ac_response
Circuit.stability_sweep = stability_sweep
Circuit.frequency_response = frequency_response
Circuit.envelope = envelope
