"""svZeroDSolver ``BloodVessel``: resistor (with stenosis), capacitor and inductor.

Equations (SimVascular/svZeroDSolver src/model/BloodVessel.cpp, ``update_gradient`` residual):
    P_in - (R + S|Q_in|) Q_in - P_out - L dQ_out/dt = 0
    Q_in - Q_out - C d/dt[P_in - (R + S|Q_in|) Q_in] = 0
i.e. inlet -> R (+ stenosis S|Q|) -> node c -> L -> outlet, with C from c to ``ref`` (ground in
imported models).  Units: R_poiseuille [mmHg*s/mL], C [mL/mmHg], L [mmHg*s^2/mL],
stenosis_coefficient S [mmHg*s^2/mL^2].  Options (set by the importer from the values):
``capacitive`` (C > 0), ``inductive`` (L > 0) and ``stenotic`` (S > 0; without it the vessel
is affine in the pressures with a constant matrix).  States: V = C P_c [mL] when capacitive,
Q_out [mL/s] when inductive.  Local unknowns (terminals in, out, ref):
  R   : branch (in, out) carrying q = Q_in = Q_out
  RC  : branches (in, ref) carrying Q_in and (out, ref) with P_out = P_c (carrying -Q_out)
  RL  : no branch; the state Q_out is imposed from in to out
  RCL : branch (in, ref) carrying Q_in; Q_out imposed from ref to out
"""
from __future__ import annotations

import numpy as np

from hemocircuit.component import Component, Observable, Option, Param, State, Storage, short
from hemocircuit.kernels import Kernel
from hemocircuit.kernels.stamps import branch, imposed_flow

from ..common import C_UNIT, flow_observables, jit, L_UNIT, R_UNIT, S_UNIT, stenosis_drop, stenosis_linearised

PARAMS = {
    "R_poiseuille": Param(R_UNIT, lower=0.0, doc="Poiseuille resistance"),
    "C": Param(C_UNIT, default=f"0 {C_UNIT}", lower=0.0, doc="capacitance (used when capacitive)"),
    "L": Param(L_UNIT, default=f"0 {L_UNIT}", lower=0.0, doc="inductance (used when inductive)"),
    "stenosis_coefficient": Param(S_UNIT, default=f"0 {S_UNIT}", lower=0.0,
                                  doc="stenosis coefficient: extra resistance S|Q|"),
}


# --- the equations: p = [R_poiseuille, C, L, stenosis_coefficient]; iopt = [capacitive, inductive,
# stenotic]; layout as above.  The stenosis term is linearised at the iterate's flow only for a
# stenotic vessel (an affine one is stamped once per nodal solve, its iterate not read)
@jit
def vessel_stamp(p, x, u, t, iopt, A, b):
    R, S = p[0], (p[3] if iopt[2] != 0 else 0.0)
    if iopt[0] != 0:
        Pc = x[0] / p[1]
        slope, off = stenosis_linearised(R, S, u[3])
        branch(A, b, 0, 2, 3, Pc + off, slope)  # Q_in: in -> (R) -> c -> ref
        if iopt[1] != 0:
            imposed_flow(b, 2, 1, x[1])  # Q_out delivered at out, drawn from ref
        else:
            branch(A, b, 1, 2, 4, Pc)  # P_out - P_ref = P_c
    elif iopt[1] != 0:
        imposed_flow(b, 0, 1, x[0])
    else:
        slope, off = stenosis_linearised(R, S, u[3])
        branch(A, b, 0, 1, 3, off, slope)


@jit
def vessel_derivs(p, x, u, t, iopt, dx):
    if iopt[0] != 0:
        Pc = x[0] / p[1]
        if iopt[1] != 0:
            dx[0] = u[3] - x[1]  # C dP_c/dt = Q_in - Q_out
            dx[1] = (Pc - (u[1] - u[2])) / p[2]  # L dQ_out/dt = P_c - P_out
        else:
            dx[0] = u[3] + u[4]
    elif iopt[1] != 0:
        dx[0] = (u[0] - u[1] - stenosis_drop(p[0], p[3], x[0])) / p[2]


@jit
def vessel_observe(p, x, iopt, out):
    if iopt[0] != 0:
        out[0] = x[0]


@jit
def vessel_report(p, x, u, t, iopt, out):
    """[V (capacitive),] Q_in, Q_out."""
    if iopt[0] != 0:
        out[0] = x[0]
        out[1] = u[3]
        out[2] = x[1] if iopt[1] != 0 else -u[4]
    else:
        q = x[0] if iopt[1] != 0 else u[3]
        out[0] = q
        out[1] = q


def dc_series(A, c, R):
    """DC guess: branch row c carries the flow from in (0) to out (1) through R."""
    A[..., 0, c], A[..., 1, c] = 1.0, -1.0
    A[..., c, 0], A[..., c, 1], A[..., c, c] = 1.0, -1.0, -R


class Vessel(Component):
    """Common structure of BloodVessel and BloodVesselCRL (options, states, DC stamp)."""

    terminals = ("in", "out", "ref")
    parameters = PARAMS
    options = {"capacitive": Option(False, kind=bool, doc="has the capacitor (C > 0)"),
               "inductive": Option(False, kind=bool, doc="has the inductor (L > 0)"),
               "stenotic": Option(False, kind=bool, doc="has the stenosis term (stenosis_coefficient > 0)")}
    KERNEL = (vessel_stamp, vessel_derivs, vessel_report)

    @property
    def linear_in_pressure(self):
        """Only the stenosis term S|Q|Q is nonlinear (a Newton iteration in the nodal solve)."""
        return not self.opts["stenotic"]

    @property
    def constant_matrix(self):
        return not self.opts["stenotic"]

    @property
    def cap(self):
        return bool(self.opts["capacitive"])

    @property
    def ind(self):
        return bool(self.opts["inductive"])

    def check(self, p):
        out = []
        for i in range(np.shape(p["C"])[-1]):
            if self.cap and np.any(p["C"][..., i] <= 0):
                out.append((i, "capacitive vessel needs C > 0 (set capacitive: false for C = 0)"))
            if self.ind and np.any(p["L"][..., i] <= 0):
                out.append((i, "inductive vessel needs L > 0 (set inductive: false for L = 0)"))
            if not self.opts["stenotic"] and np.any(p["stenosis_coefficient"][..., i] != 0):
                out.append((i, "stenosis_coefficient != 0 needs the option stenotic: true"))
        return out

    def states(self):
        return (((State("V", "mL", 1.0, "volume of the capacitor (C * its pressure)"),) if self.cap else ())
                + ((State("Q_out", "mL/s", 10.0, "outlet flow (inductor)"),) if self.ind else ()))

    def observables(self):
        v = (Observable("V", "mL", "volume of the capacitor", state_only=True),) if self.cap else ()
        return v + flow_observables()

    def storages(self):
        """The capacitor is a volume store (closed loops conserve the blood volume) on the edge
        that carries its flow to the reference."""
        return (Storage(*self.store_edge(), volume="V", state="V"),) if self.cap else ()

    def kernel_options(self):
        return np.array([int(self.cap), int(self.ind), int(self.opts["stenotic"])], dtype=np.int64)

    def kernel(self):
        stamp, derivs, report = self.KERNEL
        return Kernel(stamp=stamp, derivs=derivs, observe=vessel_observe, observables=("V",) if self.cap else (),
                      report=report)

    def dc_short(self):
        return self.ind and not self.cap

    def dc_stamp(self, p, A_loc, b_loc, keep):
        """Steady state without stenosis: the capacitor open, the inductor a short (dc_fill);
        stores anchoring a conservation law keep their normal stamp."""
        orig = (A_loc.copy(), b_loc.copy())
        A_loc[...] = 0.0
        b_loc[...] = 0.0
        self.dc_fill(A_loc, b_loc, p["R_poiseuille"])
        kept = np.asarray(keep, dtype=bool)
        if self.cap and kept.any():
            A_loc[:, kept] = orig[0][:, kept]
            b_loc[:, kept] = orig[1][:, kept]
        return A_loc, b_loc


class BloodVessel(Vessel):
    type_name = "blood_vessel"
    svzerod_blocks = ("BloodVessel", "Resistance", "Capacitance", "Inductance")  # 2-4: two of R, C, L at 0

    def branches(self):
        if self.cap:
            return (("in", "ref"), ("out", "ref")) if not self.ind else (("in", "ref"),)
        return () if self.ind else (("in", "out"),)

    def edges(self):
        if not self.cap:
            return (("in", "out", "flow" if self.ind else "conductive"),)
        if self.ind:  # R + C from in to the reference, L on to out
            return (("in", "ref", "conductive"), ("in", "out", "flow"))
        return (("in", "out", "conductive"), ("out", "ref", "pressure"))  # R, then C at out

    def store_edge(self):
        return ("in", "ref") if self.ind else ("out", "ref")

    def dc_fill(self, A, b, R):
        if self.ind and not self.cap:
            return short(A, b, 1.0 / np.maximum(R, 1e-6))  # the inductor a short: 1/R (large when R = 0)
        dc_series(A, 3, R)  # branch 3 carries in -> out through R
        if self.cap and not self.ind:  # Q_in = Q_out, P_out = P_in - R Q_in
            A[..., 1, 3], A[..., 1, 4] = 0.0, 1.0
            A[..., 4, 3], A[..., 4, 4] = 1.0, 1.0

    def initial_states(self, p, u, flows=None, x=None):
        out = np.zeros(u.shape[:2] + (len(self.states()),))
        q_in = flows[..., 0] if flows is not None else np.zeros(u.shape[:2])
        if self.cap:
            out[..., 0] = p["C"] * (u[..., 1] - u[..., 2])  # P_c ~ P_out
            if self.ind:
                out[..., 1] = q_in
        elif self.ind:
            out[..., 0] = q_in
        return out
