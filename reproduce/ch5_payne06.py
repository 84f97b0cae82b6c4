"""Chapter 5, the arteriole in the Payne06 vasculature (section autoregFirst): the steady state
over Pa (flow, radius, arteriolar volume fraction) and the 10 % step and 0.1 Hz sine responses
with tau_Ca = 5 s, with the bed's volume flow as written and neglected (MODEL_NOTES)."""
from __future__ import annotations

import numpy as np
from scipy.optimize import brentq

from .core import plt

TITLE = "Payne06 vasculature with the active arteriole: steady state, step and sine"
CHAPTER = 5
LABELS = ["figcombiSS", "figautoregSSr", "figautoregVolFrac", "figautoregStepDn5", "figautoregSine5"]
Q1, Q2 = "Q(Rla)", "Q(Rsv)"


def run(ctx):
    c = ctx.load("payne06")
    pa = np.arange(20.0, 200.0 + 1e-9, ctx.setting("Pa step [mmHg]", 10.0, 2.0))
    sw = c.dc_sweep("Pa.value", pa)
    ctx.save("steady", sw, c)
    x = np.asarray(sw["Pa.value"])
    with np.errstate(divide="ignore", invalid="ignore"):  # V_v = 0 where the veins collapse (low Pa)
        frac = np.asarray(sw["V(art)"]) / np.asarray(sw["V(Cv)"])
    pl = plt()
    fig, axs = pl.subplots(1, 3, figsize=(13, 3.8))
    axs[0].plot(x, sw[Q1], "k-")
    axs[0].set(xlabel="Pa (mmHg)", ylabel="q (mL/s)", title="flow (cf. figcombiSS)")
    axs[1].plot(x, sw["art.r"], "r-")
    axs[1].set(xlabel="Pa (mmHg)", ylabel="r (um)", title="bed radius (figautoregSSr)")
    axs[2].plot(x, frac, "b-")
    axs[2].set(xlabel="Pa (mmHg)", ylabel="V_sa / V_v", title="volume fraction (figautoregVolFrac)")
    for ax in axs:
        ax.grid(alpha=0.3)
    ctx.figure("steady", fig, "Steady state of netlists/payne06.yaml against Pa: flow, arteriolar radius and "
                              "arteriolar volume fraction V_sa/V_v (the Ursino98 data are not in the thesis).",
               "figcombiSS, figautoregSSr, figautoregVolFrac")

    op = c.operating_point()
    ctx.value("ch6.Pim80", 0.5 * (op["P(alpha)"] + op["P(beta)"]))
    ctx.value("ch6.dP80", op["P(alpha)"] - op["P(beta)"])
    ctx.value("ch5.Cw_over_NOU", op["art.Cw"] / float(c.parameters.values["art.NO_U"][0]))
    ctx.value("ch5.volfrac80", op["V(art)"] / op["V(Cv)"])

    def drop(p):
        o = c.with_values({"Pa.value": p}).operating_point()
        return o["P(alpha)"] - o["P(beta)"] - 2.4
    ctx.value("ch6.Pa_for_2p4", brentq(drop, 5.0, 20.0, xtol=1e-4))

    # step 80 -> 72 mmHg and sine 80 + 4 + 4 sin(2 pi 0.1 t), tau_Ca = 5 s, volume flow on/off
    t_end = ctx.setting("step/sine duration [s]", 60.0, 120.0)
    runs = {}
    for vf in (True, False):
        cv = c.with_options({"art.volume_flow": vf}).with_values({"art.tau_Ca": 5.0})
        x0 = cv.operating_point().x
        runs["step", vf] = cv.with_values({"Pa.value": 72.0}).simulate(t_end, dt=0.05, x0=x0, rtol=1e-8)
        s = cv.with_values({"Pa.value": 84.0})
        s = s.with_values({"Pa.amplitude": 4.0})
        s = s.with_values({"Pa.frequency": 0.1})
        runs["sine", vf] = s.simulate(t_end, dt=0.05, x0=x0, rtol=1e-8)
        runs["step4", vf] = cv.with_values({"Pa.value": 84.0}).simulate(t_end, dt=0.05, x0=x0, rtol=1e-8)
    for vf, reading in ((True, "as implemented"), (False, "thesis reading")):
        r = runs["step", vf]
        q = np.asarray(r[Q1])
        ctx.value("ch5.q1q2", 100 * np.max(np.abs(q - np.asarray(r[Q2]))) / q[0], reading)
    for kind, title, label in (("step", "10 % step 80 -> 72 mmHg", "figautoregStepDn5"),
                               ("sine", "80 + 4 + 4 sin(2 pi 0.1 t) mmHg (dashed: 4 mmHg step alone)",
                                "figautoregSine5")):
        fig, axs = pl.subplots(3, 1, figsize=(7.5, 7), sharex=True)
        for vf, col in ((True, "C0"), (False, "C3")):
            r = runs[kind, vf]
            name = "volume flow as written" if vf else "volume flow neglected"
            axs[0].plot(r.t, r[Q1], "-", color=col, label=f"q1, {name}")
            axs[0].plot(r.t, r[Q2], ":", color=col, lw=2, label=f"q2, {name}")
            axs[1].plot(r.t, r["art.r"], "-", color=col)
            axs[2].plot(r.t, r["Q(Cv)"], "-", color=col, label=f"dV_v/dt, {name}")
            axs[2].plot(r.t, np.asarray(r[Q1]) - np.asarray(r[Q2]), "--", color=col, label=f"dV_sa/dt, {name}")
            if kind == "sine":
                s4 = runs["step4", vf]
                axs[0].plot(s4.t, s4[Q1], "k--", lw=0.8)
        axs[0].set(ylabel="flow (mL/s)", title=f"payne06, tau_Ca = 5 s: {title}")
        axs[1].set(ylabel="r (um)")
        axs[2].set(ylabel="volume flows (mL/s)", xlabel="time (s)")
        for ax in axs:
            ax.grid(alpha=0.3)
        axs[0].legend(fontsize=7)
        axs[2].legend(fontsize=7)
        ctx.figure(kind, fig, f"Response to {title}; q1 (solid) and q2 (dotted), with the bed's volume flow as written "
                              "(blue) and neglected (red): the thesis's q1 and q2 lie atop one another only in the "
                              "latter (MODEL_NOTES).", label)
        r = runs[kind, True]
        ctx.table(kind, {"t": r.t, "q1": r[Q1], "q2": r[Q2], "r": r["art.r"], "dVv": r["Q(Cv)"]},
                  {"t": "s", "q1": "mL/s", "q2": "mL/s", "r": "um", "dVv": "mL/s"}, index=["t"], circuit=c,
                  settings={"tau_Ca": 5.0, "volume_flow": True})
