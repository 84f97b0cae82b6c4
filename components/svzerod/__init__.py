"""Blocks of SimVascular's svZeroDSolver as hemocircuit components (one block per module).

Each module cites the svZeroDSolver source file its equations come from
(src/model/*.cpp at commit c7b0ca09).  The importer (hemocircuit.svzerod) maps their JSON
blocks to these types; docs/svzerod.md lists the mapping.
"""
from .blood_vessel import BloodVessel
from .blood_vessel_crl import BloodVesselCRL
from .blood_vessel_rc import BloodVesselRC
from .coronary_bc import CoronaryBC
from .coronary_var_res_bc import CoronaryVarResBC
from .closed_loop_coronary import ClosedLoopCoronary
from .rcr_bc import RCRBC
from .resistance_bc import ResistanceBC
from .valve_tanh import ValveTanh
from .piecewise_valve import PiecewiseValve
from .chamber_elastance_inductor import ChamberElastanceInductor
from .chamber_elastance_inductor_exponential import ChamberElastanceInductorExponential
from .chamber_sphere import ChamberSphere
from .linear_elastance_chamber import LinearElastanceChamber
from .closed_loop_rcr import ClosedLoopRCR
from .closed_loop_heart_pulmonary import ClosedLoopHeartAndPulmonary

__all__ = ["BloodVessel", "BloodVesselCRL", "BloodVesselRC", "ChamberElastanceInductor",
           "ChamberElastanceInductorExponential", "ChamberSphere", "ClosedLoopCoronary", "ClosedLoopHeartAndPulmonary",
           "ClosedLoopRCR", "CoronaryBC", "CoronaryVarResBC", "LinearElastanceChamber", "PiecewiseValve", "RCRBC",
           "ResistanceBC", "ValveTanh"]
