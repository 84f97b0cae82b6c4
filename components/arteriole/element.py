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

from hemocircuit.component import Component, Observable, Option, State, Storage
from hemocircuit.errors import HemocircuitError
from hemocircuit.units import PA_PER_MMHG

from . import compiled, equations, model
from .parameters import PARAMETERS, PRESETS, check_params
from .steady_state import solve_steady

# observables: name -> (unit in the circuit, doc), in the order compiled.report writes them
_OBS = {
    "r": ("um", "internal radius"),
    "lambda": ("dimensionless", "normalised cell length"),
    "Ca": ("M", "[Ca2+]"),
    "dCa": ("M/s", "d[Ca2+]/dt (second-order Ca)"),
    "Cw": ("M", "wall [NO]"),
    "Cb_mean": ("M", "spatially averaged blood [NO] (eq. cbbar)"),
    "cGMP": ("M", "[cGMP]"),
    "M": ("dimensionless", "free myosin fraction"),
    "Mp": ("dimensionless", "phosphorylated myosin fraction"),
    "AMp": ("dimensionless", "attached phosphorylated fraction"),
    "AM": ("dimensionless", "attached dephosphorylated (latch) fraction"),
    "sigma": ("Pa", "wall stress P r / t_w"),
    "tau_hat": ("dimensionless", "normalised shear stress"),
    "Q": ("mL/s", "Poiseuille flow of the bed (n vessels)"),
    "R": ("mmHg*s/mL", "resistance of the bed"),
    "V": ("mL", "blood volume of the bed"),
    "F_a": ("N", "active force per cell"),
    "F_p": ("N", "passive force per cell"),
    "q_out": ("mL/s", "flow leaving at the out terminal"),
    # NO carried out of the bed (eq. cinv; read by downstream tracer pools, docs/downstream_no.md)
    "Cb_inf": ("M", "far-downstream blood [NO], h_w C_we / (h_w + r_db A_b) (eqs. cbbar, cinv)"),
    "k_NO": ("m**2/s", "blood NO loss per unit vessel length, h_w + r_db A_b (exponent of eq. cinv)"),
}


class ArterioleError(HemocircuitError, ValueError):
    """Non-finite stamp or derivatives: invalid states, inputs or parameters."""


def _finite(result, what):
    arrays = result if isinstance(result, tuple) else (result,)
    if not all(np.all(np.isfinite(a)) for a in arrays):
        raise ArterioleError(f"arteriole {what}: non-finite (invalid states, inputs or parameters)")
    return result


class Arteriole(Component):
    """Active arteriolar bed (thesis chapters 3-6).  Parameters in SI (see docs/arteriole.md)."""

    type_name = "arteriole"
    terminals = ("in", "out", "ref")
    parameters = PARAMETERS
    options = {
        "preset": Option("kuo91", choices=tuple(PRESETS), doc="parameter set (tables tabPassiveFit, tabActiveFit)"),
        **model.OPTIONS,
        "volume_flow": Option(False, kind=bool, doc="the bed's volume rate leaves the midpoint into ref"),
        "pim_reference": Option("gauge", choices=("gauge", "ref"), doc="intramural pressure against 0 or P(ref)"),
    }
    constant_matrix = False
    # a tone input (e.g. seeded noise for CO2 and neural fluctuations, docs/body.md): its
    # waveform adds to the parameter's value
    waveform_params = ("pCa_shift",)

    def defaults(self):
        return dict(PRESETS[self.opts["preset"]])

    @property
    def model_options(self):
        """The options of the vessel model (model.OPTIONS), checked."""
        return model.resolve_options({k: self.opts[k] for k in model.OPTIONS})

    # --- structure --------------------------------------------------------------------
    def internal_nodes(self):
        return ("mid",) if self.opts["volume_flow"] else ()

    def edges(self):
        if not self.opts["volume_flow"]:  # ref carries no flow; it still anchors P_im in 'ref' mode
            return (("in", "out", "conductive"),)
        return (("in", "mid", "conductive"), ("mid", "out", "conductive"), ("mid", "ref", "flow"))

    def storages(self):
        return (Storage("mid", "ref", "V"),) if self.opts["volume_flow"] else ()

    def states(self):
        names = model.state_names(self.model_options)
        return tuple(State(n, model.STATE_UNITS[n], model.STATE_SCALES[n]) for n in names)

    def observables(self):
        names = [n for n in _OBS if n != "dCa" or self.opts["ca_order"] == 2]
        state_only = compiled.observables(self.opts["ca_order"])
        return tuple(Observable(n, _OBS[n][0], _OBS[n][1], state_only=n in state_only) for n in names)

    def outputs_of_interest(self):
        return ("r", "Ca")

    def volume_observables(self):
        """The bed's blood volume is V(ID), whether or not it flows (volume_flow)."""
        return ("V",)

    def hard_limits(self):
        """Second-order Ca stops at the floor and its rate is reset (chapter 6 footnotes)."""
        return (("Ca", equations.CA_FLOOR, "dCa"),) if self.opts["ca_order"] == 2 else ()

    def check(self, p):
        # the framework checks that every parameter is given; an expression-valued one is
        # absent here until evaluated
        return [(0, m) for m in check_params(p, complete=False)]

    # --- the equations: kernel functions in compiled.py, from equations.py ------------------
    def kernel(self):
        from hemocircuit.kernels import Kernel
        return Kernel(stamp=compiled.stamp, derivs=compiled.derivs, observe=compiled.observe,
                      observables=compiled.observables(self.opts["ca_order"]), derivs_jac=compiled.derivs_jac,
                      report=compiled.report)

    # an invalid state, input or parameter is an error naming the arteriole, never a NaN that
    # surfaces later as a singular nodal system (the numpy path; the engine checks its own)
    def stamp(self, p, x, u, t, src=None):
        return _finite(super().stamp(p, x, u, t, src), "stamp (conductance, volume flow)")

    def derivatives(self, p, x, u, t, src=None):
        return _finite(super().derivatives(p, x, u, t, src), "derivatives")

    def kernel_options(self):
        """The iopt layout of compiled.py."""
        o = self.opts
        return np.array([int(o["ca_order"]), int(o["kinetics"] == "dynamic"), int(bool(o["passive"])),
                         int(bool(o["volume_flow"])), int(o["pim_reference"] == "ref")], dtype=np.int64)

    def default_states(self, p):
        shape = np.broadcast_shapes(*(np.shape(v) for v in p.values()))
        st = solve_steady(np.full(shape, 60 * PA_PER_MMHG), np.zeros(shape), p, self.model_options, warn=False)
        return model.pack(st, self.model_options)

    def initial_states(self, p, u, flows=None, x=None):
        P_im, dP = compiled.pressures(np.moveaxis(u, -1, 0), self.kernel_options())
        r_guess = None if x is None else equations.l2r(model.unpack(x, self.model_options)["lambda"],
                                                       equations.vector(p))
        st = solve_steady(P_im, dP, p, self.model_options, r_guess=r_guess, warn=False)
        new = model.pack(st, self.model_options)
        if x is not None:
            new = np.where(np.isfinite(new), new, x)
        return new
