"""svZeroDSolver ``BloodVesselCRL``: capacitor at the inlet, then resistor (with stenosis) and
inductor.

Equations (SimVascular/svZeroDSolver src/model/BloodVesselCRL.cpp, ``update_gradient``):
    P_in - (R + S|Q_out|) Q_out - P_out - L dQ_out/dt = 0
    Q_in - Q_out - C dP_in/dt = 0
Units and options as ``blood_vessel``'s; without the capacitor it is a ``blood_vessel`` without
capacitor (same equations).  States: V = C P_in [mL] when capacitive, Q_out [mL/s] when
inductive.  Local unknowns (terminals in, out, ref), capacitive forms:
  CRL : branch (in, ref) with P_in - P_ref = V/C carrying the capacitor's flow; Q_out
        (state) imposed from in to out
  CR  : that branch plus a branch (in, out) carrying Q_out (resistor with stenosis)
"""
from __future__ import annotations

import numpy as np

from hemocircuit.component import short
from hemocircuit.kernels.stamps import branch, imposed_flow
from ..common import jit, stenosis_drop, stenosis_linearised
from .blood_vessel import BloodVessel, Vessel, dc_series, vessel_derivs, vessel_report, vessel_stamp


# --- the equations: p = [R_poiseuille, C, L, stenosis_coefficient], iopt = [capacitive, inductive, stenotic]
@jit
def crl_stamp(p, x, u, t, iopt, A, b):
    if iopt[0] == 0:
        vessel_stamp(p, x, u, t, iopt, A, b)
        return
    branch(A, b, 0, 2, 3, x[0] / p[1])  # P_in - P_ref = V/C
    if iopt[1] != 0:
        imposed_flow(b, 0, 1, x[1])
    else:
        slope, off = stenosis_linearised(p[0], p[3] if iopt[2] != 0 else 0.0, u[4])
        branch(A, b, 0, 1, 4, off, slope)


@jit
def crl_derivs(p, x, u, t, iopt, dx):
    if iopt[0] == 0:
        vessel_derivs(p, x, u, t, iopt, dx)
        return
    dx[0] = u[3]  # C dP_in/dt = Q_in - Q_out
    if iopt[1] != 0:  # L dQ_out/dt = P_in - (R + S|Q_out|) Q_out - P_out
        dx[1] = (x[0] / p[1] - (u[1] - u[2]) - stenosis_drop(p[0], p[3], x[1])) / p[2]


@jit
def crl_report(p, x, u, t, iopt, out):
    """[V (capacitive),] Q_in, Q_out."""
    if iopt[0] == 0:
        vessel_report(p, x, u, t, iopt, out)
        return
    q_out = x[1] if iopt[1] != 0 else u[4]
    out[0] = x[0]
    out[1] = u[3] + q_out
    out[2] = q_out


class BloodVesselCRL(Vessel):
    type_name = "blood_vessel_crl"
    svzerod_blocks = ("BloodVesselCRL",)
    KERNEL = (crl_stamp, crl_derivs, crl_report)

    def branches(self):
        if self.cap:
            return (("in", "ref"),) if self.ind else (("in", "ref"), ("in", "out"))
        return BloodVessel.branches(self)

    def store_edge(self):
        return ("in", "ref")  # the capacitor's edge (used only when capacitive)

    def edges(self):
        if not self.cap:
            return BloodVessel.edges(self)
        return (("in", "ref", "pressure"), ("in", "out", "flow" if self.ind else "conductive"))

    def dc_fill(self, A, b, R):
        if not self.cap:
            return BloodVessel.dc_fill(self, A, b, R)
        A[..., 3, 3] = 1.0  # capacitor flow 0
        if self.ind:
            short(A, b, 1.0 / np.maximum(R, 1e-6))  # the inductor a short: 1/R
        else:
            dc_series(A, 4, R)

    def initial_states(self, p, u, flows=None, x=None):
        if not self.cap:
            return BloodVessel.initial_states(self, p, u, flows, x)
        out = np.zeros(u.shape[:2] + (len(self.states()),))
        out[..., 0] = p["C"] * (u[..., 0] - u[..., 2])
        if self.ind:
            out[..., 1] = flows[..., 0] if flows is not None else 0.0
        return out
