"""Chapter 5, phase of the flow against the Ca time constant at 0.1 Hz (figautoregPhase):
payne06 forced with Pa = 80 + 4 + 4 sin(2 pi 0.1 t) mmHg, one batched nonlinear frequency
response over tau_Ca x volume flow (examples/payne06_phase_vs_tau.py), and the reversal from
lead to lag located by bisection in tau_Ca (independent of the figure's grid)."""
from __future__ import annotations

import numpy as np
from scipy.optimize import brentq

from .core import example, plt

TITLE = "Phase of flow vs tau_Ca at 0.1 Hz (payne06)"
CHAPTER = 5
LABELS = ["figautoregPhase"]
Q1 = "Q(Rla)"


def phase(c, taus, vf, no_speed=None):
    from ..analyses.freq import frequency_response
    grid = [("art.volume_flow", [vf]), ("art.tau_Ca", list(taus))]
    if no_speed is not None:
        grid.append(("art.no_speed", [no_speed]))
    res = frequency_response(c, [0.1], outputs=[Q1, "Q(Rsv)"], input="Pa", step=0.05, amplitude=0.05, grid=grid,
                             scheduler="serial")
    return res


def run(ctx):
    ex = example("payne06_phase_vs_tau")
    c = ctx.load("payne06")
    taus = np.logspace(np.log10(0.5), np.log10(20.0), ctx.setting("tau_Ca points", 6, 12))
    from ..analyses.freq import frequency_response
    res = frequency_response(c, [0.1], outputs=[Q1, "Q(Rsv)"], input="Pa", step=0.05, amplitude=0.05,
                             grid=[("art.volume_flow", [True, False]), ("art.tau_Ca", list(taus))], workers=2)
    ctx.save("phase_vs_tau", res, c)
    rows = res.rows()
    table, summary = {}, {}
    for vf, _ in ex.CASES:
        for o in ex.OUTPUTS:
            rs = sorted((r for r in rows if r["art.volume_flow"] == vf and not r["error"]), key=lambda r: r["art.tau_Ca"])
            table[vf, o] = tuple(np.array([r[k] for r in rs]) for k in
                                 ("art.tau_Ca", f"phase({o}/Pa.value)", f"rel_amplitude({o})", "periods", "settled"))
            summary[vf, o] = ex.reversals(table[vf, o][0], table[vf, o][1])
    ex.plot(ctx.figure_path("phase"), table, summary)
    ctx.existing_figure("phase", "Phase of q1 and q2 against Pa at 0.1 Hz (positive: flow leads) for tau_Ca, with the "
                                 "bed's volume flow as written and neglected.", "figautoregPhase")

    # the reversal, located by bisection in log tau_Ca on the q1 phase (same in quick and full)
    def ph(tau, vf):
        r = phase(c, [tau], vf).rows()[0]
        return r[f"phase({Q1}/Pa.value)"]
    for vf, reading in ((False, "thesis reading"), (True, "as implemented")):
        lo, hi = 0.5, 20.0
        if ph(lo, vf) > 0 >= ph(hi, vf):
            ctx.value("ch5.reversal", np.exp(brentq(lambda lt: ph(np.exp(lt), vf), np.log(lo), np.log(hi),
                                                    xtol=1e-3)), reading)
        else:
            ctx.note(f"volume flow {'on' if vf else 'off'}: no reversal from lead to lag in tau_Ca = 0.5..20 s.")
            ctx.value("ch5.reversal", float("nan"), reading)
    # NO speed has no effect on the phase (cGMP saturated): tau_Ca = 5 s, no_speed 1 vs 200
    a = phase(c, [5.0], False).rows()[0][f"phase({Q1}/Pa.value)"]
    b = phase(c, [5.0], False, no_speed=200.0).rows()[0][f"phase({Q1}/Pa.value)"]
    ctx.value("ch5.no_speed_phase", abs(a - b))
