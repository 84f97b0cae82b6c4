"""The ``arteriole`` circuit element: a bed of n identical active arterioles in parallel.

Nodes ``[in, out, ref]``.  The vessel physics (thesis chapter 3, fitted values of chapter 4)
lives in the sibling modules, in SI; this module is the one place where the circuit's units
(mmHg, mL, s) meet the arteriole's (Pa, m^3, s), through ``hemocircuit.units``.

Hydraulics (thesis eqs. Rsa, Vsa, dVsadt, Pab2Pim, Pab2DP):
  R = 8 mu_b L / (pi r^4 n),  V = pi r^2 L n,  P_im = (P_in + P_out)/2,  dP = P_in - P_out.
``volume_flow: false`` -- a pure variable resistor between in and out (section artComp).
``volume_flow: true``  -- the bed is two halves R/2 in series with a midpoint from which the
  volume rate dV/dt = 2 pi r L n dr/dt leaves into ``ref`` (section autoregFirst).  dr/dt is
  affine in P_im (mechanics: dlambda/dt = a + b P), so the nodal equations solve the flow
  and the pressures together, exactly (MODEL_NOTES; not the thesis's relaxation iteration).
``pim_reference``: 'gauge' (default; wall stress against zero extramural pressure, as the
  thesis computes it) or 'ref' (P_im - P(ref), the physically consistent alternative).
"""
from __future__ import annotations

import numpy as np

from hemocircuit.component import Component, Observable, Option, Param, State, Storage
from hemocircuit.units import M3_PER_ML, PA_PER_MMHG

from . import model
from .geometry import bed_volume, l2r, lumen_area, resistance
from .myogenic import CA_FLOOR
from .no_transport import _cb_inf
from .parameters import PARAMETERS, PRESETS, check_params, effective
from .steady_state import solve_steady

_UNITS = {"mol/L": "M", "mol/L/s": "M/s"}
# observables: name -> (unit shown, factor from the model's SI unit, doc)
_OBS = {
    "r": ("um", 1e6, "internal radius"),
    "lambda": ("dimensionless", 1.0, "normalised cell length"),
    "Ca": ("M", 1.0, "[Ca2+]"),
    "dCa": ("M/s", 1.0, "d[Ca2+]/dt (second-order Ca)"),
    "Cw": ("M", 1.0, "wall [NO]"),
    "Cb_mean": ("M", 1.0, "spatially averaged blood [NO] (eq. cbbar)"),
    "cGMP": ("M", 1.0, "[cGMP]"),
    "M": ("dimensionless", 1.0, "free myosin fraction"),
    "Mp": ("dimensionless", 1.0, "phosphorylated myosin fraction"),
    "AMp": ("dimensionless", 1.0, "attached phosphorylated fraction"),
    "AM": ("dimensionless", 1.0, "attached dephosphorylated (latch) fraction"),
    "sigma": ("Pa", 1.0, "wall stress P r / t_w"),
    "tau_hat": ("dimensionless", 1.0, "normalised shear stress"),
    "Q": ("mL/s", 1.0 / M3_PER_ML, "Poiseuille flow of the bed (n vessels)"),
    "R": ("mmHg*s/mL", M3_PER_ML / PA_PER_MMHG, "resistance of the bed"),
    "V": ("mL", 1.0 / M3_PER_ML, "blood volume of the bed"),
    "F_a": ("N", 1.0, "active force per cell"),
    "F_p": ("N", 1.0, "passive force per cell"),
    "q_out": ("mL/s", 1.0, "flow leaving at the out terminal"),
    # NO carried out of the bed (eq. cinv; read by downstream tracer pools, docs/downstream_no.md)
    "Cb_inf": ("M", 1.0, "far-downstream blood [NO], h_w C_we / (h_w + r_db A_b) (eqs. cbbar, cinv)"),
    "k_NO": ("m**2/s", 1.0, "blood NO loss per unit vessel length, h_w + r_db A_b (exponent of eq. cinv)"),
}
_STATE_ONLY = ("r", "lambda", "Ca", "dCa", "Cw", "V", "R", "Cb_inf", "k_NO")


def _outlet_no(Cw, r, p):
    """State-only terms of eq. cinv: {'Cb_inf' [M], 'k_NO' [m^2/s]} (no_speed applied)."""
    pe = effective(p)
    return {"Cb_inf": _cb_inf(Cw, r, pe), "k_NO": pe["h_w"] + pe["r_db"] * lumen_area(r)}


class Arteriole(Component):
    """Active arteriolar bed (thesis chapters 3-6).  Parameters in SI (see docs/arteriole.md)."""

    type_name = "arteriole"
    terminals = ("in", "out", "ref")
    parameters = {name: Param(_UNITS.get(spec.unit, spec.unit), default=None, lower=spec.lower, upper=spec.upper,
                              lower_open=spec.lower_open, doc=spec.doc) for name, spec in PARAMETERS.items()}
    options = {
        "preset": Option("kuo91", choices=tuple(PRESETS), doc="parameter set (tables tabPassiveFit, tabActiveFit)"),
        "ca_order": Option(1, choices=(1, 2), kind=int, doc="first- (eq. dCadt) or second-order (eq. dCadt2) Ca"),
        "kinetics": Option("quasi_steady", choices=("quasi_steady", "dynamic"), doc="4-state kinetics"),
        "passive": Option(False, kind=bool, doc="Ca = 0, no myogenic response (passive curves)"),
        "volume_flow": Option(False, kind=bool, doc="the bed's volume rate leaves the midpoint into ref"),
        "pim_reference": Option("gauge", choices=("gauge", "ref"), doc="intramural pressure against 0 or P(ref)"),
    }
    role = "conductive"
    constant_matrix = False

    def defaults(self):
        return dict(PRESETS[self.opts["preset"]])

    @property
    def model_options(self):
        o = self.__dict__.get("_model_options")
        if o is None or any(o[k] != self.opts[k] for k in ("ca_order", "kinetics", "passive")):
            o = model.resolve_options({k: self.opts[k] for k in ("ca_order", "kinetics", "passive")})
            self.__dict__["_model_options"] = o
        return o

    # --- structure --------------------------------------------------------------------
    def internal_nodes(self):
        return ("mid",) if self.opts["volume_flow"] else ()

    def edges(self):
        e = [("in", "out", "conductive")] if not self.opts["volume_flow"] else \
            [("in", "mid", "conductive"), ("mid", "out", "conductive")]
        # ref carries no flow without volume_flow; it still anchors P_im in 'ref' mode
        if self.opts["volume_flow"]:
            e.append(("mid", "ref", "flow"))
        return tuple(e)

    def storages(self):
        return (Storage("mid", "ref", "V"),) if self.opts["volume_flow"] else ()

    def states(self):
        names = model.state_names(self.model_options)
        return tuple(State(n, _UNITS.get(model.STATE_UNITS[n], model.STATE_UNITS[n]), model.STATE_SCALES[n])
                     for n in names)

    def observables(self):
        names = [n for n in _OBS if n != "dCa" or self.opts["ca_order"] == 2]
        return tuple(Observable(n, _OBS[n][0], _OBS[n][2], state_only=n in _STATE_ONLY) for n in names)

    def outputs_of_interest(self):
        return ("r", "Ca")

    def volume_observables(self):
        """The bed's blood volume is V(ID), whether or not it flows (volume_flow)."""
        return ("V",)

    def hard_limits(self):
        """Second-order Ca stops at the floor and its rate is reset (chapter 6 footnotes)."""
        return (("Ca", CA_FLOOR, "dCa"),) if self.opts["ca_order"] == 2 else ()

    def check(self, p):
        return [(0, m) for m in check_params(p)]

    # --- helpers ----------------------------------------------------------------------
    def _pressures(self, u):
        """(P_im, dP) in Pa from local pressures [mmHg]."""
        P_in, P_out, P_ref = u[..., 0], u[..., 1], u[..., 2]
        P_im = 0.5 * (P_in + P_out) - (P_ref if self.opts["pim_reference"] == "ref" else 0.0)
        return P_im * PA_PER_MMHG, (P_in - P_out) * PA_PER_MMHG

    def _states(self, x):
        return model.unpack(x, self.model_options)

    # --- numerical hooks --------------------------------------------------------------
    def stamp(self, p, x, u, t, src=None):
        s = self._states(x)
        r = l2r(s["lambda"], p)
        g = 1.0 / (resistance(r, p) * (M3_PER_ML / PA_PER_MMHG))  # mL/s per mmHg
        shape = g.shape
        if not self.opts["volume_flow"]:
            A = np.zeros(shape + (3, 3))
            A[..., 0, 0] = g
            A[..., 0, 1] = -g
            A[..., 1, 0] = -g
            A[..., 1, 1] = g
            return A, np.zeros(shape + (3,))
        # local nodes: in 0, out 1, ref 2, mid 3
        A = np.zeros(shape + (4, 4))
        g2 = 2.0 * g
        for a, b in ((0, 3), (3, 1)):
            A[..., a, a] += g2
            A[..., b, b] += g2
            A[..., a, b] -= g2
            A[..., b, a] -= g2
        da, db = model.dr_dt_affine(s, p, self.model_options)  # m/s, m/(s Pa)
        k = 2 * np.pi * r * p["L"] * p["n"] / M3_PER_ML  # mL per m of radius
        c0 = k * da  # mL/s
        c1 = k * db * PA_PER_MMHG  # mL/s per mmHg of P_im
        # volume flow q_v = c0 + c1 P_im leaves mid and enters ref
        for j, w in ((0, 0.5), (1, 0.5)) + (((2, -1.0),) if self.opts["pim_reference"] == "ref" else ()):
            A[..., 3, j] += c1 * w
            A[..., 2, j] -= c1 * w
        b = np.zeros(shape + (4,))
        b[..., 3] = -c0
        b[..., 2] = c0
        return A, b

    def derivatives(self, p, x, u, t, src=None):
        P_im, dP = self._pressures(u)
        o = self.model_options
        d, _ = model._evaluate(self._states(x), P_im, dP, p, o)
        out = np.stack([d[n] for n in model.state_names(o)], axis=-1)
        if not np.isfinite(out).all():  # one check for all states (model.derivatives checks each)
            model._check_finite(d, "derivatives")
        return out

    def observe(self, p, x, u, t, src=None):
        s = self._states(x)
        if u is None:
            r = l2r(s["lambda"], p)
            out = {"r": r * 1e6, "lambda": s["lambda"], "Ca": s["Ca"], "Cw": s["Cw"],
                   "V": bed_volume(r, p) / M3_PER_ML, "R": resistance(r, p) * _OBS["R"][1]}
            if self.opts["ca_order"] == 2:
                out["dCa"] = s["dCa"]
            out.update(_outlet_no(s["Cw"], r, p))
            return out
        P_im, dP = self._pressures(u)
        o = model.observables(s, P_im, dP, p, self.model_options)
        out = {n: o[n] * _OBS[n][1] for n in _OBS if n in o}
        out["Q"] = o["Q"] * p["n"] * _OBS["Q"][1]
        out.update(_outlet_no(s["Cw"], o["r"], p))
        if self.opts["volume_flow"]:
            out["q_out"] = 2.0 * (u[..., 3] - u[..., 1]) / (resistance(o["r"], p) * _OBS["R"][1])
        else:
            out["q_out"] = (u[..., 0] - u[..., 1]) / (resistance(o["r"], p) * _OBS["R"][1])
        return out

    # --- compiled path (hemocircuit.kernels; equations in compiled.py) -------------------
    def kernel(self):
        from hemocircuit.kernels import Kernel

        from . import compiled
        return Kernel(stamp=compiled.stamp, derivs=compiled.derivs, observe=compiled.observe,
                      observables=tuple(o.name for o in self.observables() if o.state_only),
                      derivs_jac=compiled.derivs_jac)

    def kernel_options(self):
        """[ca_order (1|2), kinetics dynamic (0|1), passive (0|1), volume_flow (0|1),
        pim_reference 'ref' (0|1)] (the iopt layout of compiled.py)."""
        o = self.opts
        return np.array([int(o["ca_order"]), int(o["kinetics"] == "dynamic"), int(bool(o["passive"])),
                         int(bool(o["volume_flow"])), int(o["pim_reference"] == "ref")], dtype=np.int64)

    def default_states(self, p):
        shape = np.broadcast_shapes(*(np.shape(v) for v in p.values()))
        st = solve_steady(np.full(shape, 60 * PA_PER_MMHG), np.zeros(shape), p, self.model_options, warn=False)
        return model.pack(st, self.model_options)

    def initial_states(self, p, u, flows=None, x=None):
        P_im, dP = self._pressures(u)
        r_guess = None if x is None else l2r(self._states(x)["lambda"], p)
        st = solve_steady(P_im, dP, p, self.model_options, r_guess=r_guess, warn=False)
        new = model.pack(st, self.model_options)
        if x is not None:
            new = np.where(np.isfinite(new), new, x)
        return new
