"""svZeroDSolver ``ClosedLoopCoronaryLeft`` / ``ClosedLoopCoronaryRight``: a coronary bed whose
intramyocardial pressure is a fraction of the heart's ventricular pressure, draining into the
right atrium of a closed loop.

Equations (SimVascular/svZeroDSolver src/model/ClosedLoopCoronaryBC.cpp ``update_constant``,
``update_solution``; ClosedLoopCoronaryLeftBC.cpp / RightBC.cpp ``setup_model_dependent_params``):
their residuals, with P_a = P_in - Ra Q_in,
    P_in - (Ra + Ram) Q_in + Ram Ca dP_a/dt - P_out - Rv Q_out = 0
    Q_in - Ca dP_a/dt - dV_im/dt - Q_out = 0
    V_im = Cim (P_out + Rv Q_out - P_im),   P_im = im * P_vent
are the circuit  in -> Ra -> a (Ca to the reference) -> Ram -> m (Cim to P_im) -> Rv -> out.
Left: P_vent = P_LV, im = iml; right: P_vent = P_RV, im = imr (their heart block "CLH").
Their P_LV (P_RV) is the heart's Elv_s F(t) (V_LV - Vlv_u) (Erv_s, V_RV, Vrv_u), F the raw
25-mode Fourier series (activation.fourier_raw); here the block computes it from parameters the
importer ties to the heart with netlist expressions: ``im: "= CLH.iml"``, ``E_s: "= CLH.Elv_s"``,
``V_u: "= CLH.Vlv_u"``, ``period: "= CLH.period"`` and the state-only observable
``V_vent: "= CLH.V_LV"``, so P_im follows the ventricle's state at every evaluation, as theirs.
Units: Ra [mmHg*s/mL] >= 0, Ram, Rv [mmHg*s/mL] > 0, Ca, Cim [mL/mmHg] > 0, im
dimensionless, E_s [mmHg/mL], V_u, V_vent [mL], period [s].  States (volume stores, so the
closed loop conserves them): V_a = Ca P_a and V_im = Cim (P_m - P_im) [mL] (their volume_im).
Local unknowns [P_in, P_out, P_ref, P_a, P_m, q_ra, q_ca, q_cim]: internal nodes a, m;
branch (in, a) P_in - P_a - Ra q_ra = 0 (Ra may be 0); branch (a, ref) P_a - P_ref = V_a/Ca
carrying dV_a/dt; branch (m, ref) P_m - P_ref = V_im/Cim + P_im carrying dV_im/dt;
conductances 1/Ram (a, m) and 1/Rv (m, out).
"""
from __future__ import annotations

import numpy as np

from hemocircuit.component import Component, Observable, Param, State, Storage

from ._common import batch_shape, C_UNIT, E_UNIT, R_UNIT, jit
from .activation import fourier_raw


class ClosedLoopCoronary(Component):
    __doc__ = __doc__
    type_name = "closed_loop_coronary"
    svzerod_blocks = ("ClosedLoopCoronaryLeft", "ClosedLoopCoronaryRight")
    terminals = ("in", "out", "ref")
    parameters = {"Ra": Param(R_UNIT, lower=0.0, doc="small-artery resistance"),
                  "Ram": Param(R_UNIT, lower=0.0, lower_open=True, doc="microvascular resistance"),
                  "Rv": Param(R_UNIT, lower=0.0, lower_open=True, doc="venous resistance"),
                  "Ca": Param(C_UNIT, lower=0.0, lower_open=True, doc="small-artery capacitance"),
                  "Cim": Param(C_UNIT, lower=0.0, lower_open=True, doc="intramyocardial capacitance"),
                  "im": Param("dimensionless", doc="P_im / P_vent (the heart's iml or imr)"),
                  "E_s": Param(E_UNIT, doc="ventricular elastance scale (the heart's Elv_s or Erv_s)"),
                  "V_u": Param("mL", doc="ventricular unstressed volume (the heart's Vlv_u or Vrv_u)"),
                  "V_vent": Param("mL", doc="ventricular volume (the heart's V_LV or V_RV)"),
                  "period": Param("s", lower=0.0, lower_open=True, doc="cardiac period (the heart's)")}
    time_dependent = True

    def internal_nodes(self):
        return ("a", "m")

    def branches(self):
        return (("in", "a"), ("a", "ref"), ("m", "ref"))

    def edges(self):
        return (("in", "a", "conductive"), ("a", "ref", "pressure"), ("a", "m", "conductive"),
                ("m", "ref", "pressure"), ("m", "out", "conductive"))

    def states(self):
        return (State("V_a", "mL", 1.0, "volume of Ca (Ca * P_a)"),
                State("V_im", "mL", 1.0, "intramyocardial volume Cim (P_m - P_im)"))

    def storages(self):
        return (Storage("a", "ref", "V_a", state="V_a"), Storage("m", "ref", "V_im", state="V_im"))

    def volume_observables(self):
        """Two stores: both reported as ID.V_a, ID.V_im (one V(ID) column cannot hold both)."""
        return ()

    def observables(self):
        return (Observable("V_a", "mL", "volume of Ca", state_only=True),
                Observable("V_im", "mL", "intramyocardial volume", state_only=True),
                Observable("P_im", "mmHg", "intramyocardial pressure im * P_vent"),
                Observable("Q_in", "mL/s", "flow into the inlet"),
                Observable("Q_out", "mL/s", "flow out of the outlet"))

    def _pim(self, p, t):
        shape = batch_shape(p, np.shape(t))
        T = np.broadcast_to(np.asarray(p["period"], float), shape)
        tt = np.broadcast_to(np.asarray(t, float), shape)
        F = np.empty(shape)
        for idx in np.ndindex(shape):
            F[idx] = fourier_raw(np.fmod(float(tt[idx]), float(T[idx])), float(T[idx]))
        return p["im"] * p["E_s"] * F * (p["V_vent"] - p["V_u"])

    def stamp(self, p, x, u, t, src=None):
        shape = batch_shape(p, x.shape[:2])
        A = np.zeros(shape + (8, 8))
        b = np.zeros(shape + (8,))
        ga, gv = 1.0 / p["Ram"], 1.0 / p["Rv"]
        A[..., 0, 5], A[..., 3, 5] = 1.0, -1.0
        A[..., 5, 0], A[..., 5, 3], A[..., 5, 5] = 1.0, -1.0, -p["Ra"]
        A[..., 3, 6], A[..., 2, 6], A[..., 6, 3], A[..., 6, 2] = 1.0, -1.0, 1.0, -1.0
        A[..., 4, 7], A[..., 2, 7], A[..., 7, 4], A[..., 7, 2] = 1.0, -1.0, 1.0, -1.0
        A[..., 3, 3], A[..., 3, 4], A[..., 4, 3] = ga, -ga, -ga
        A[..., 4, 4] = ga + gv
        A[..., 4, 1], A[..., 1, 4], A[..., 1, 1] = -gv, -gv, gv
        b[..., 6] = x[..., 0] / p["Ca"]
        b[..., 7] = x[..., 1] / p["Cim"] + self._pim(p, t)
        return A, b

    def derivatives(self, p, x, u, t, src=None):
        dx = np.zeros(batch_shape(p, x.shape[:2], u.shape[:2]) + (2,))
        dx[..., 0] = u[..., 6]
        dx[..., 1] = u[..., 7]
        return dx

    def observe(self, p, x, u, t, src=None):
        out = {"V_a": x[..., 0], "V_im": x[..., 1]}
        if u is not None:
            out.update(P_im=self._pim(p, t) + 0.0 * u[..., 0], Q_in=u[..., 5], Q_out=(u[..., 4] - u[..., 1]) / p["Rv"])
        return out

    def dc_stamp(self, p, A_loc, b_loc, keep):
        """Steady state: both capacitors open (no flow) unless the element anchors a
        conservation law, where Ca keeps its stamp (it pins the group's pressure)."""
        opened = ~np.asarray(keep, dtype=bool)
        A_loc[:, opened, 6, :] = 0.0
        A_loc[:, opened, 6, 6] = 1.0
        b_loc[:, opened, 6] = 0.0
        A_loc[..., 7, :] = 0.0
        A_loc[..., 7, 7] = 1.0
        b_loc[..., 7] = 0.0
        return A_loc, b_loc

    def initial_states(self, p, u, flows=None, x=None):
        out = np.zeros(batch_shape(p, u.shape[:2]) + (2,))
        out[..., 0] = p["Ca"] * (u[..., 3] - u[..., 2])
        out[..., 1] = p["Cim"] * (u[..., 4] - u[..., 2] - self._pim(p, 0.0))
        return out

    def kernel(self):
        from hemocircuit.kernels import Kernel
        return Kernel(stamp=clcor_stamp, derivs=clcor_derivs, observe=clcor_observe, observables=("V_a", "V_im"))


# --- compiled path: p = [Ra, Ram, Rv, Ca, Cim, im, E_s, V_u, V_vent, period]; states [V_a, V_im];
# local unknowns [P_in, P_out, P_ref, P_a, P_m, q_ra, q_ca, q_cim]
@jit
def clcor_stamp(p, x, u, t, iopt, A, b):
    ga = 1.0 / p[1]
    gv = 1.0 / p[2]
    A[0, 5] = 1.0
    A[3, 5] = -1.0
    A[5, 0] = 1.0
    A[5, 3] = -1.0
    A[5, 5] = -p[0]
    A[3, 6] = 1.0
    A[2, 6] = -1.0
    A[6, 3] = 1.0
    A[6, 2] = -1.0
    A[4, 7] = 1.0
    A[2, 7] = -1.0
    A[7, 4] = 1.0
    A[7, 2] = -1.0
    A[3, 3] = ga
    A[3, 4] = -ga
    A[4, 3] = -ga
    A[4, 4] = ga + gv
    A[4, 1] = -gv
    A[1, 4] = -gv
    A[1, 1] = gv
    pim = p[5] * p[6] * fourier_raw(np.fmod(t, p[9]), p[9]) * (p[8] - p[7])
    b[6] = x[0] / p[3]
    b[7] = x[1] / p[4] + pim


@jit
def clcor_derivs(p, x, u, t, iopt, dx):
    dx[0] = u[6]
    dx[1] = u[7]


@jit
def clcor_observe(p, x, iopt, out):
    out[0] = x[0]
    out[1] = x[1]
