"""Chapter 5, passive arterial compliance (section artComp): the volumes and the arterial to
venous volume fraction against Pa, and the frequency responses of q1 and q2 for tau_Ca = 1 and
10 s at Pa = 80 and tau_Ca = 1 s at Pa = 30 mmHg (10 % step + 10 % sine, MODEL_NOTES), both
nonlinear (batched, hemocircuit.analyses.freq) and linearised (AC)."""
from __future__ import annotations

import numpy as np

from .core import plt

TITLE = "Arterial compliance: volume fractions and frequency responses"
CHAPTER = 5
LABELS = ["figautoregModVolFrac", "figautoregModVol", "figautoregFSweepMag", "figautoregFSweepPhase"]
Q1, Q2 = "Q(Rla)", "Q(Rsv)"


def run(ctx):
    from ..analyses.ac import ac_response
    from ..analyses.freq import frequency_response

    c = ctx.load("arterial_compliance")
    base = ctx.load("payne06")
    pa = np.arange(20.0, 200.0 + 1e-9, ctx.setting("Pa step [mmHg]", 10.0, 2.0))
    sw = c.dc_sweep("Pa.value", pa)
    ctx.save("volumes", sw, c)
    Va, Vsa, Vv = (np.asarray(sw[k]) for k in ("V(Ca)", "V(art)", "V(Cv)"))
    with np.errstate(divide="ignore", invalid="ignore"):
        frac = (Va + Vsa) / Vv
    pl = plt()
    fig, axs = pl.subplots(1, 2, figsize=(12, 4))
    axs[0].plot(pa, frac, "b-", label="(V_a + V_sa) / V_v")
    axs[0].axhline(1 / 3, color="k", ls="--", lw=1, label="1/3")
    axs[0].set(xlabel="Pa (mmHg)", ylabel="volume fraction", ylim=(0, 1))
    axs[1].plot(pa, Vv, label="veins V_v")
    axs[1].plot(pa, Va, label="arteries V_a")
    axs[1].plot(pa, Vsa, label="small arteries V_sa")
    axs[1].set(xlabel="Pa (mmHg)", ylabel="volume (mL)")
    for ax in axs:
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    ctx.figure("volumes", fig, "Arterial to venous volume fraction (left; dashed 1/3) and the three volumes (right) "
                               "against Pa; compartments collapse (V = 0) at the lowest pressures.",
               "figautoregModVolFrac, figautoregModVol")
    op = c.operating_point()
    ctx.value("ch5.artcomp_frac80", (op["V(Ca)"] + op["V(art)"]) / op["V(Cv)"])
    f60 = (op["V(Ca)"] + op["V(art)"]) / op["V(Cv)"]
    o140 = c.with_values({"Pa.value": 140.0}).operating_point()
    o60 = c.with_values({"Pa.value": 60.0}).operating_point()
    ctx.value("ch5.artcomp_rise", (o140["V(Ca)"] + o140["V(art)"]) / o140["V(Cv)"]
              - (o60["V(Ca)"] + o60["V(art)"]) / o60["V(Cv)"])
    del f60
    q_ref = np.asarray(base.dc_sweep("Pa.value", pa)[Q1])
    ctx.value("ch5.artcomp_same_flow", np.max(np.abs(np.asarray(sw[Q1]) / q_ref - 1)))

    # frequency responses: linear (AC) on a dense grid, nonlinear on a coarser one
    f_ac = np.logspace(-3, 2, ctx.setting("AC points", 101, 251))
    cases = (("q, tau_Ca = 1 s, Pa = 80", {}, "C3"), ("tau_Ca = 10 s, Pa = 80", {"art.tau_Ca": 10.0}, "C0"),
             ("tau_Ca = 1 s, Pa = 30", {"Pa.value": 30.0}, "k"))
    ac = {}
    for name, sets, _ in cases:
        cc = c.with_values(sets) if sets else c
        ac[name] = ac_response(cc, "Pa", [Q1, Q2], f_ac)
    f_nl = ctx.setting("nonlinear frequencies [Hz]", [0.01, 0.03, 0.1, 0.3, 1.0],
                       [0.005, 0.01, 0.02, 0.03, 0.05, 0.07, 0.1, 0.12, 0.15, 0.2, 0.3, 0.5, 1.0])
    nl = frequency_response(c, f_nl, [Q1, Q2], step=0.1, amplitude=0.1,
                            grid=[("art.tau_Ca", [1.0, 10.0]), ("Pa.value", [30.0, 80.0])], workers=2)
    ctx.save("freq_nonlinear", nl, c)
    rows = [r for r in nl.rows() if not r["error"]]
    fig, axs = pl.subplots(2, 1, figsize=(8, 7.5), sharex=True)
    for name, sets, col in cases:
        a = ac[name]
        for o, ls in ((Q1, "-"), (Q2, "--")):
            axs[0].loglog(a.freq, a.rel_gain[o] * 0.1, ls, color=col, lw=1, label=f"{o}, {name} (AC x 0.1)")
            axs[1].semilogx(a.freq, a.phase[o], ls, color=col, lw=1)
        tau, P = sets.get("art.tau_Ca", 1.0), sets.get("Pa.value", 80.0)
        sel = sorted((r for r in rows if r["art.tau_Ca"] == tau and r["Pa.value"] == P), key=lambda r: r["frequency"])
        for o, mk in ((Q1, "o"), (Q2, "s")):
            axs[0].loglog([r["frequency"] for r in sel], [r[f"rel_amplitude({o})"] for r in sel], mk, color=col, ms=4)
            axs[1].semilogx([r["frequency"] for r in sel], [r[f"phase({o}/Pa.value)"] for r in sel], mk, color=col,
                            ms=4)
    axs[0].set(ylabel="flow amplitude / steady flow", title="arterial_compliance: 10 % step + 10 % sine of Pa")
    axs[1].set(ylabel="phase (deg, + = flow leads)", xlabel="frequency (Hz)")
    for ax in axs:
        ax.grid(alpha=0.3, which="both")
    axs[0].legend(fontsize=7)
    ctx.figure("freq", fig, "Frequency response of q1 = Q(Rla) (solid, circles) and q2 = Q(Rsv) (dashed, squares): "
                            "markers nonlinear (10 % + 10 %), lines linearised (AC gain x 0.1 amplitude). Red: "
                            "tau_Ca = 1 s at 80 mmHg; blue: 10 s; black: 1 s at 30 mmHg.",
               "figautoregFSweepMag, figautoregFSweepPhase")

    # statements (AC, dense and independent of the nonlinear grid)
    a80, a10, a30 = (ac[n] for n, _, _ in cases)
    band = (a80.freq >= 0.01) & (a80.freq <= 1.0)
    ctx.value("ch5.peak_f", a80.freq[band][np.argmax(a80.rel_gain[Q2][band])])
    ctx.value("ch5.peak_shift", a10.freq[band][np.argmax(a10.rel_gain[Q2][band])]
              / a80.freq[band][np.argmax(a80.rel_gain[Q2][band])])
    ctx.value("ch5.phase01", np.interp(np.log(0.1), np.log(a80.freq), a80.phase[Q1]))
    lead = frequency_response(c, [0.015, 0.02, 0.03], [Q1], step=0.1, amplitude=0.1, scheduler="serial")
    ctx.value("ch5.max_lead", max(r[f"phase({Q1}/Pa.value)"] for r in lead.rows()))
    ctx.value("ch5.q1_1Hz_ratio", np.interp(0.0, np.log(a30.freq), a30.rel_gain[Q1])
              / np.interp(0.0, np.log(a80.freq), a80.rel_gain[Q1]))
    hf = ac_response(c, "Pa", [Q1], [60.0])
    ctx.value("ch5.q1_hf_peak", 0.1 * float(hf.rel_gain[Q1][0]))
