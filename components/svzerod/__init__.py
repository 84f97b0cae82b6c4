"""Blocks of SimVascular's svZeroDSolver as hemocircuit components (one block per module).

Each module cites the svZeroDSolver source file its equations come from
(src/model/*.cpp at commit c7b0ca09).  The importer (hemocircuit.svzerod) maps their JSON
blocks to these types; docs/svzerod.md lists the mapping.
"""
from .blood_vessel import BloodVessel
from .blood_vessel_crl import BloodVesselCRL
from .coronary_bc import CoronaryBC
from .rcr_bc import RCRBC
from .resistance_bc import ResistanceBC

__all__ = ["BloodVessel", "BloodVesselCRL", "CoronaryBC", "RCRBC", "ResistanceBC"]
