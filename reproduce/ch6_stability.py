"""Chapter 6, stability analysis: eigenvalues of the arterial-compliance model against Pa
(tau_Ca = 1 s, MODEL_NOTES), and the ICP and inertia variants (sections addICCap,
addInertia): their volumes against Pa and the absence of unstable equilibria."""
from __future__ import annotations

import numpy as np

from .core import plt

TITLE = "Stability: eigenvalues vs Pa, ICP and inertia variants"
CHAPTER = 6
LABELS = ["(stability analysis, no figure)", "figautoregICCapVol"]


def run(ctx):
    from ..analyses.stability import plot_result, stability_sweep

    c = ctx.load("arterial_compliance").with_values({"art.tau_Ca": 1.0})
    step = ctx.setting("Pa step [mmHg]", 10.0, 2.0)
    r = stability_sweep(c, "Pa.value", np.arange(20.0, 200.0 + 1e-9, step))
    ctx.save("eigenvalues_artcomp", r, c)
    plot_result(r, ctx.figure_path("eigen"))
    ctx.existing_figure("eigen", "Eigenvalues of the arterial-compliance model (tau_Ca = 1 s) against Pa; the range "
                                 "with a complex pair is located by bisection.", "")
    (lo, hi), = r.complex_ranges() or [(np.nan, np.nan)]
    ctx.value("ch6.complex_lo", lo)
    ctx.value("ch6.complex_hi", hi)
    ctx.value("ch6.max_re", float(np.max(r.abscissa)))

    pa = np.arange(20.0, 200.0 + 1e-9, step)
    icp = ctx.load("icp")
    sw = icp.dc_sweep("Pa.value", pa)
    ctx.save("volumes_icp", sw, icp)
    pl = plt()
    fig, ax = pl.subplots(figsize=(6.5, 4))
    for k, lab in (("V(Ca)", "arterial V_a"), ("V(Cv)", "venous V_v"), ("V(Cic)", "intracranial V_ic")):
        ax.plot(pa, sw[k], label=lab)
    ax.set(xlabel="Pa (mmHg)", ylabel="volume (mL)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ctx.figure("icp_volumes", fig, "Arterial, venous and intracranial volumes of the ICP variant against Pa (P_ic = "
                                   "10 mmHg at Pa = 80); the compartments no longer collapse.", "figautoregICCapVol")
    ctx.value("ch6.icp_min_Vv", float(np.min(sw["V(Cv)"])))
    n_unstable = 0
    for name in ("icp", "inertia"):
        for tau in (1.0, 10.0):
            cc = ctx.load(name).with_values({"art.tau_Ca": tau})
            s = stability_sweep(cc, "Pa.value", np.arange(20.0, 200.0 + 1e-9, 20.0), locate=False)
            n_unstable += int(np.sum(~s.stable))
    ctx.value("ch6.icp_inertia_unstable", n_unstable)
