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
P_vent = F(t) E_s (V_vent - V_u) as the heart's (F: activation.fourier_raw), from parameters the
importer ties to the heart by expressions (``im: "= CLH.iml"``, ``V_vent: "= CLH.V_LV"``, ...).
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

from hemocircuit.component import Component, Observable, Param, State, Storage, batch_shape, kernel_method, open_branches
from hemocircuit.elementwise import per_element
from hemocircuit.kernels.stamps import branch, conductance

from ..common import C_UNIT, E_UNIT, flow_observables, jit, R_UNIT
from .activation import fourier_raw
from .closed_loop_heart_pulmonary import ventricle_pressure


# --- the equations: p = [Ra, Ram, Rv, Ca, Cim, im, E_s, V_u, V_vent, period]; states [V_a, V_im];
# local unknowns [P_in, P_out, P_ref, P_a, P_m, q_ra, q_ca, q_cim]
@jit
def clcor_pim(p, t, iopt):
    """P_im = im P_vent: the heart's ventricular pressure at time t from its volume V_vent."""
    return p[5] * ventricle_pressure(fourier_raw(np.fmod(t, p[9]), p[9]), p[6], p[8], p[7])


@jit
def clcor_stamp(p, x, u, t, iopt, A, b):
    branch(A, b, 0, 3, 5, 0.0, p[0])  # P_in - P_a - Ra q_ra = 0
    branch(A, b, 3, 2, 6, x[0] / p[3])
    branch(A, b, 4, 2, 7, x[1] / p[4] + clcor_pim(p, t, iopt))
    conductance(A, 3, 4, 1.0 / p[1])
    conductance(A, 4, 1, 1.0 / p[2])


@jit
def clcor_derivs(p, x, u, t, iopt, dx):
    dx[0] = u[6]
    dx[1] = u[7]


@jit
def clcor_observe(p, x, iopt, out):
    out[0] = x[0]
    out[1] = x[1]


@jit
def clcor_report(p, x, u, t, iopt, out):
    clcor_observe(p, x, iopt, out)  # V_a, V_im
    out[2] = clcor_pim(p, t, iopt) + 0.0 * u[0]  # P_im
    out[3] = u[5]  # Q_in
    out[4] = (u[4] - u[1]) / p[2]  # Q_out


class ClosedLoopCoronary(Component):
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
    kernel = kernel_method(clcor_stamp, clcor_derivs, clcor_observe, ("V_a", "V_im"), report=clcor_report)
    INTERNAL_NODES = ("a", "m")
    BRANCHES = (("in", "a"), ("a", "ref"), ("m", "ref"))
    EDGES = (("in", "a", "conductive"), ("a", "ref", "pressure"), ("a", "m", "conductive"),
             ("m", "ref", "pressure"), ("m", "out", "conductive"))
    STATES = (State("V_a", "mL", 1.0, "volume of Ca (Ca * P_a)"),
              State("V_im", "mL", 1.0, "intramyocardial volume Cim (P_m - P_im)"))
    STORAGES = (Storage("a", "ref", "V_a", state="V_a"), Storage("m", "ref", "V_im", state="V_im"))
    OBSERVABLES = (Observable("V_a", "mL", "volume of Ca", state_only=True),
                   Observable("V_im", "mL", "intramyocardial volume", state_only=True),
                   Observable("P_im", "mmHg", "intramyocardial pressure im * P_vent"),
                   *flow_observables())

    def volume_observables(self):
        """Two stores: both reported as ID.V_a, ID.V_im (one V(ID) column cannot hold both)."""
        return ()

    def dc_stamp(self, p, A_loc, b_loc, keep):
        """Steady state: both capacitors open (no flow) unless the element anchors a
        conservation law, where Ca keeps its stamp (it pins the group's pressure)."""
        open_branches(A_loc, b_loc, (6,), keep)
        return open_branches(A_loc, b_loc, (7,))

    def initial_states(self, p, u, flows=None, x=None):
        out = np.zeros(batch_shape(p, u.shape[:2]) + (2,))
        out[..., 0] = p["Ca"] * (u[..., 3] - u[..., 2])
        out[..., 1] = p["Cim"] * (u[..., 4] - u[..., 2] - per_element(clcor_pim, self, p, 0.0))
        return out
