"""Chapter 4, the 4-state kinetics fitted to Lee97: relative phosphorylation Mp + AMp against
[Ca] for [cGMP] from 0.1 nM to 10 uM and the two Lee97 conditions
(examples/lee97_phosphorylation.py).  The curves are the 4-state cross-bridge kinetics (eqs
phos, dephos, 4stateSS) at steady state; fractions [-], concentrations [M]."""
from __future__ import annotations

import numpy as np

from ..components.arteriole import equations as eq
from ..components.arteriole.parameters import make_params
from .core import plt

TITLE = "Myosin phosphorylation of the 4-state kinetics (Lee97)"
CHAPTER = 4
LABELS = ["figrPhospCa", "figFccGMP"]


def relative_phosphorylation(Ca, cGMP, params):
    """Mp + AMp [-] at kinetic steady state (figure figrPhospCa), for [Ca], [cGMP] in M."""
    p = eq.vector(params)
    with np.errstate(divide="ignore"):
        _, Mp, AMp, _ = eq.quasi_steady(*eq.rates(np.asarray(Ca, dtype=float), np.asarray(cGMP, dtype=float),
                                                  p, False), p)
    return Mp + AMp


def phosphorylation_curves(params=None, Ca=None, cGMP=None):
    """(Ca [M], cGMP [M], phos [-] of shape (len(cGMP), len(Ca))) with phos = Mp + AMp at
    kinetic steady state.  Defaults: Ca 1e-8..1e-4 M (81 points), cGMP 1e-10..1e-5 M (6 decades),
    the kuo91 kinetic parameters (tab4State)."""
    p = make_params("kuo91") if params is None else params
    Ca = np.logspace(-8, -4, 81) if Ca is None else np.asarray(Ca, dtype=float)
    cGMP = np.logspace(-10, -5, 6) if cGMP is None else np.asarray(cGMP, dtype=float)
    return Ca, cGMP, relative_phosphorylation(Ca[None, :], cGMP[:, None], p)


def run(ctx):
    p = make_params("kuo91")
    Ca, cg, phos = phosphorylation_curves(p, np.logspace(-8, -4, ctx.setting("Ca points", 41, 161)))
    # figFccGMP: the same surface cut at [Ca] = 1 uM for [cGMP] 0.1 nM .. 10 uM, and at the
    # thesis's other [Ca] values (10 nM .. 100 uM); shown as phosphorylation (the Lee97
    # phosphorylation-to-force conversion is not in the thesis)
    cg_axis = np.logspace(-10, -5, ctx.pick(41, 161))
    ca_cut = np.array([1e-8, 1e-7, 1e-6, 1e-5, 1e-4])
    _, _, cut = phosphorylation_curves(p, ca_cut, cg_axis)   # (len(cg_axis), len(ca_cut))
    cols = {"Ca": np.repeat(Ca, len(cg)), "cGMP": np.tile(cg, len(Ca)), "phos": phos.T.reshape(-1)}
    ctx.table("phosphorylation_vs_Ca", cols, {"Ca": "M", "cGMP": "M", "phos": "1"}, index=["Ca", "cGMP"],
              settings=dict(ctx.settings))
    cols = {"cGMP": np.repeat(cg_axis, len(ca_cut)), "Ca": np.tile(ca_cut, len(cg_axis)), "phos": cut.reshape(-1)}
    ctx.table("phosphorylation_vs_cGMP", cols, {"Ca": "M", "cGMP": "M", "phos": "1"}, index=["cGMP", "Ca"])

    pl = plt()
    fig, ax = pl.subplots(figsize=(6.4, 4.6))
    colours = pl.cm.viridis(np.linspace(0, 0.9, len(cg)))
    for i, c in enumerate(cg):
        ax.semilogx(Ca, phos[i], "--", color=colours[i], label=f"[cGMP] = {c:.0e} M")
    _, _, lee = phosphorylation_curves(p, Ca, np.array([0.0, 2e-6]))
    ax.semilogx(Ca, lee[0], "-", color="0.4", lw=2.5, label="[cGMP] = 0 (Lee97 control)")
    ax.semilogx(Ca, lee[1], "-", color="tab:red", lw=2.5, label="[cGMP] = 2 uM (Lee97 8Br-cGMP)")
    ax.set(xlabel="[Ca$^{2+}$] (M)", ylabel="relative phosphorylation Mp + AMp", ylim=(0, 1))
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7)
    ctx.figure("phos_vs_Ca", fig, "Relative phosphorylation against [Ca] for [cGMP] per decade (dashed) and the "
                                  "two Lee97 conditions (solid); tab4State kinetics at steady state.", "figrPhospCa")

    fig, ax = pl.subplots(figsize=(6.4, 4.6))
    for j, ca in enumerate(ca_cut):
        style = "-" if ca == 1e-6 else "--"
        ax.semilogx(cg_axis, cut[:, j], style, lw=2.5 if ca == 1e-6 else 1.2, label=f"[Ca] = {ca:.0e} M")
    ax.axvspan(1e-9, 1e-7, color="0.9", zorder=0, label="cGMP range of the NO-cGMP sigmoid")
    ax.set(xlabel="[cGMP] (M)", ylabel="relative phosphorylation Mp + AMp", ylim=(0, 1))
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7)
    ctx.figure("phos_vs_cGMP", fig, "Phosphorylation against [cGMP] at [Ca] = 1 uM (solid, the Lee97 condition) "
                                    "and 10 nM..100 uM (dashed). The thesis plots force; its phosphorylation-to-force "
                                    "conversion (Lee97's fig. 3 caption) is not in the thesis, so phosphorylation is "
                                    "shown.", "figFccGMP")
