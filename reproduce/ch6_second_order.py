"""Chapter 6, second-order Ca dynamics: the Kuo91 experiments with the omega_n, zeta epochs of
tabOmegaZeta (protocols kuo91_*_2nd.yaml) against the first-order model, and the sine onset of
the second-order whole-brain model (80 + 4 + 4 sin(2 pi 0.1 t) mmHg)."""
from __future__ import annotations

import numpy as np

from .ch4_kuo91 import runs
from .core import plt

TITLE = "Second-order Ca: Kuo91 refit and sine response"
CHAPTER = 6
LABELS = ["fig2ndOCaKuo91Fig2A", "fig2ndOCaKuo91Fig2B", "fig2ndOCaKuo91Fig2C", "fig2ndOCaKuo91Fig2D", "fig2ndOCaSine"]
Q1, Q2 = "Q(Rla)", "Q(Rsv)"


def run(ctx):
    from ..analyses.freq import frequency_response

    ex, circuit, d, protos = runs(ctx, (1, 2))
    pl = plt()
    fig, axs = pl.subplots(2, 2, figsize=(11, 6.5))
    worst = 0.0
    for ax, e in zip(axs.ravel(), ex.EXPERIMENTS):
        d1, d2 = d[(e, 1)], d[(e, 2)]
        ax.plot(d1["t"], d1["r"], "r-", lw=1.5, label="1st order (tabTauCaVals)")
        ax.plot(d2["t"], d2["r"], "b--", lw=1.5, label="2nd order (tabOmegaZeta)")
        worst = max(worst, float(np.max(np.abs(d1["r"] - d2["r"]))))
        ax.set(title=f"Kuo91 fig. 2{e}", xlabel="time (s)", ylabel="r (um)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    ctx.figure("kuo91_2nd", fig, "Kuo91 A-D with second-order Ca (omega_n, zeta epochs of tabOmegaZeta) against the "
                                 "first-order model.", "fig2ndOCaKuo91Fig2A-D")
    ctx.note(f"Largest radius difference between the first- and second-order fits over A-D: {worst:.2f} um.")

    c = ctx.load("second_order_ca")
    x0 = c.operating_point().x
    t_end = ctx.setting("sine duration [s]", 60.0, 120.0)
    s = c.with_values({"Pa.value": 84.0})
    s = s.with_values({"Pa.amplitude": 4.0})
    s = s.with_values({"Pa.frequency": 0.1})
    sine = s.simulate(t_end, dt=0.05, x0=x0, rtol=1e-8)
    step = c.with_values({"Pa.value": 84.0}).simulate(t_end, dt=0.05, x0=x0, rtol=1e-8)
    fig, axs = pl.subplots(2, 1, figsize=(7.5, 5.5), sharex=True)
    axs[0].plot(sine.t, sine[Q1], "C3-", label="q1, step + sine")
    axs[0].plot(sine.t, sine[Q2], "C0-", label="q2, step + sine")
    axs[0].plot(step.t, step[Q1], "C3:", label="q1, step only")
    axs[0].plot(step.t, step[Q2], "C0:", label="q2, step only")
    axs[0].set(ylabel="flow (mL/s)", title="second_order_ca: Pa = 80 + 4 + 4 sin(2 pi 0.1 t) mmHg")
    axs[1].plot(sine.t, sine["P(in)"], "k-")
    axs[1].set(ylabel="Pa (mmHg)", xlabel="time (s)")
    for ax in axs:
        ax.grid(alpha=0.3)
    axs[0].legend(fontsize=7)
    ctx.figure("sine", fig, "Response of the second-order model to the onset of the 0.1 Hz oscillation (dotted: the "
                            "step alone).", "fig2ndOCaSine")
    ctx.table("sine", {"t": sine.t, "q1": sine[Q1], "q2": sine[Q2], "Pa": sine["P(in)"]},
              {"t": "s", "q1": "mL/s", "q2": "mL/s", "Pa": "mmHg"}, index=["t"], circuit=c)
    fr = frequency_response(c, [0.1], [Q1, Q2], input="Pa", step=0.05, amplitude=0.05, scheduler="serial")
    ctx.value("ch6.sine_phase", fr.rows()[0][f"phase({Q1}/Pa.value)"])
