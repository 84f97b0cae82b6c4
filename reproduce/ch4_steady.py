"""Chapter 4, steady state of the isolated arteriole: Kuo91 fig. 4 and Falcone91 fig. 1 model
curves (passive, active without flow, active with dP = 4 cmH2O), one batched operating point
per curve (examples/steady_state_curves.py)."""
from __future__ import annotations

import numpy as np

from .core import example

TITLE = "Steady-state curves of the isolated arteriole (Kuo91, Falcone91)"
CHAPTER = 4
LABELS = ["figPassiveFitBoth", "figActiveFitKuo", "figActiveFitFalcone"]


def run(ctx):
    ex = example("steady_state_curves")
    step = ctx.setting("P step [cmH2O]", 10.0, 2.0)
    P = np.arange(20.0, 140.0 + 1e-9, step)
    base = ctx.load("isolated_arteriole")
    data, units = {}, None
    for preset in ex.PRESETS:
        for case, opts, dP in ex.CASES:
            data[(preset, case)], units = ex.curve(base, preset, opts, dP, P=P)
    ex.P_CMH2O = P  # the example's plotting functions draw over its module grid
    for preset, label in (("kuo91", "figActiveFitKuo"), ("falcone91", "figActiveFitFalcone")):
        ex.plot(preset, data, ctx.figure_path(preset))
        ctx.existing_figure(preset, f"Steady-state radius vs intramural pressure, preset {preset}: passive "
                                    "(Ca = 0), active without flow and with dP = 4 cmH2O.", label)
    ex.plot_passive_both(data, ctx.figure_path("passive_both"))
    ctx.existing_figure("passive_both", "Passive and active no-flow curves of both presets, with the set point "
                                        "r = 60 um at P = 60 mmHg.", "figPassiveFitBoth")

    cols, cu = {"P": np.tile(P, 6)}, {"P": "cmH2O"}
    cols["preset"] = np.repeat([p for p in ex.PRESETS for _ in ex.CASES], len(P)).astype(object)
    cols["case"] = np.repeat([c for _ in ex.PRESETS for c, _, _ in ex.CASES], len(P)).astype(object)
    for k in ("r", "Ca", "Cw", "cGMP", "AMp"):
        cols[k] = np.concatenate([data[(p, c)][k] for p in ex.PRESETS for c, _, _ in ex.CASES])
        cu[k] = units[f"art.{k}"]
    ctx.table("curves", cols, cu, circuit=base, settings=dict(ctx.settings))

    c = base.with_values({"Pup.value": "60 mmHg"})
    c = c.with_values({"Pdown.value": "60 mmHg"})
    ctx.value("ch4.set_point", c.operating_point()["art.r"])
    # autoregulation: the active no-flow radius falls between 60 and 120 cmH2O (kuo91)
    act = data[("kuo91", "active_no_flow")]["r"]
    m = (P >= 60) & (P <= 120)
    ctx.value("ch4.plateau", act[m][-1] - act[m][0])
    flow = data[("kuo91", "active_flow")]["r"] - act
    ctx.value("ch4.flow_dilates", flow.min())
