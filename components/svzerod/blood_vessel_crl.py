"""svZeroDSolver ``BloodVesselCRL``: capacitor at the inlet, then resistor (with stenosis) and
inductor.

Equations (SimVascular/svZeroDSolver src/model/BloodVesselCRL.cpp, ``update_gradient``):
    P_in - (R + S|Q_out|) Q_out - P_out - L dQ_out/dt = 0
    Q_in - Q_out - C dP_in/dt = 0
Units and the options ``capacitive`` / ``inductive`` as for ``blood_vessel``; without the
capacitor the block is a ``blood_vessel`` without capacitor (same equations).
States: V = C * P_in [mL] when capacitive, Q_out [mL/s] when inductive.  Local unknowns
(terminals in, out, ref), capacitive forms:
  CRL : branch (in, ref) with P_in - P_ref = V/C carrying the capacitor's flow; Q_out
        (state) imposed from in to out
  CR  : that branch plus a branch (in, out) carrying Q_out (resistor with stenosis)
"""
from __future__ import annotations

import numpy as np

from ._common import batch_shape, jit, k_stenosis_linearised, stenosis_linearised
from .blood_vessel import BloodVessel, _Vessel, vessel_derivs, vessel_observe, vessel_stamp


class BloodVesselCRL(_Vessel):
    __doc__ = __doc__
    type_name = "blood_vessel_crl"
    svzerod_blocks = ("BloodVesselCRL",)

    def branches(self):
        if self.cap:
            return (("in", "ref"),) if self.ind else (("in", "ref"), ("in", "out"))
        return BloodVessel.branches(self)

    def _store_edge(self):
        return BloodVessel._store_edge(self) if not self.cap else ("in", "ref")

    def edges(self):
        if not self.cap:
            return BloodVessel.edges(self)
        return (("in", "ref", "pressure"), ("in", "out", "flow" if self.ind else "conductive"))

    def stamp(self, p, x, u, t, src=None):
        if not self.cap:
            return BloodVessel.stamp(self, p, x, u, t, src)
        R, S = p["R_poiseuille"], p["stenosis_coefficient"]
        L = len(self.local_nodes) + len(self.branches())
        A = np.zeros(batch_shape(p, x.shape[:2]) + (L, L))
        b = np.zeros(batch_shape(p, x.shape[:2]) + (L,))
        A[..., 0, 3], A[..., 2, 3] = 1.0, -1.0
        A[..., 3, 0], A[..., 3, 2] = 1.0, -1.0
        b[..., 3] = x[..., 0] / p["C"]
        if self.ind:
            q = x[..., 1]
            b[..., 0], b[..., 1] = -q, q
        else:
            slope, off = stenosis_linearised(R, S, 0.0 if u is None else u[..., 4])
            A[..., 0, 4], A[..., 1, 4] = 1.0, -1.0
            A[..., 4, 0], A[..., 4, 1], A[..., 4, 4] = 1.0, -1.0, -slope
            b[..., 4] = off
        return A, b

    def derivatives(self, p, x, u, t, src=None):
        if not self.cap:
            return BloodVessel.derivatives(self, p, x, u, t, src)
        R, S = p["R_poiseuille"], p["stenosis_coefficient"]
        dx = np.zeros(x.shape)
        dx[..., 0] = u[..., 3]
        if self.ind:
            q = x[..., 1]
            dx[..., 1] = (x[..., 0] / p["C"] - (u[..., 1] - u[..., 2]) - (R + S * np.abs(q)) * q) / p["L"]
        return dx

    def observe(self, p, x, u, t, src=None):
        if not self.cap:
            return BloodVessel.observe(self, p, x, u, t, src)
        if u is None:
            return {"V": x[..., 0]}
        q_out = x[..., 1] if self.ind else u[..., 4]
        return {"V": x[..., 0], "Q_in": u[..., 3] + q_out, "Q_out": q_out}

    def dc_stamp(self, p, A_loc, b_loc, keep):
        """Steady state without stenosis: the capacitor open, the inductor a short."""
        if not self.cap:
            return BloodVessel.dc_stamp(self, p, A_loc, b_loc, keep)
        R = p["R_poiseuille"]
        orig = (A_loc.copy(), b_loc.copy())
        A_loc[...] = 0.0
        b_loc[...] = 0.0
        A_loc[..., 3, 3] = 1.0  # capacitor flow 0
        if self.ind:
            g = 1.0 / np.maximum(R, 1e-6)
            A_loc[..., 0, 0], A_loc[..., 0, 1], A_loc[..., 1, 0], A_loc[..., 1, 1] = g, -g, -g, g
        else:
            A_loc[..., 0, 4], A_loc[..., 1, 4] = 1.0, -1.0
            A_loc[..., 4, 0], A_loc[..., 4, 1], A_loc[..., 4, 4] = 1.0, -1.0, -R
        return self._restore_kept(keep, orig, A_loc, b_loc)

    def initial_states(self, p, u, flows=None, x=None):
        if not self.cap:
            return BloodVessel.initial_states(self, p, u, flows, x)
        out = np.zeros(u.shape[:2] + (len(self.states()),))
        out[..., 0] = p["C"] * (u[..., 0] - u[..., 2])
        if self.ind:
            out[..., 1] = flows[..., 0] if flows is not None else 0.0
        return out

    def kernel(self):
        from hemocircuit.kernels import Kernel
        return Kernel(stamp=crl_stamp, derivs=crl_derivs, observe=vessel_observe,
                      observables=("V",) if self.cap else ())


# --- compiled path: p = [R_poiseuille, C, L, stenosis_coefficient], iopt = [capacitive, inductive, stenotic]
@jit
def crl_stamp(p, x, u, t, iopt, A, b):
    if iopt[0] == 0:
        vessel_stamp(p, x, u, t, iopt, A, b)
        return
    A[0, 3] = 1.0
    A[2, 3] = -1.0
    A[3, 0] = 1.0
    A[3, 2] = -1.0
    b[3] = x[0] / p[1]
    if iopt[1] != 0:
        b[0] = -x[1]
        b[1] = x[1]
    else:
        slope, off = k_stenosis_linearised(p[0], p[3] if iopt[2] != 0 else 0.0, u[4])
        A[0, 4] = 1.0
        A[1, 4] = -1.0
        A[4, 0] = 1.0
        A[4, 1] = -1.0
        A[4, 4] = -slope
        b[4] = off


@jit
def crl_derivs(p, x, u, t, iopt, dx):
    if iopt[0] == 0:
        vessel_derivs(p, x, u, t, iopt, dx)
        return
    dx[0] = u[3]
    if iopt[1] != 0:
        q = x[1]
        dx[1] = (x[0] / p[1] - (u[1] - u[2]) - (p[0] + p[3] * abs(q)) * q) / p[2]
