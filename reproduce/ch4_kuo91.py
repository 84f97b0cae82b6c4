"""Chapter 4, the Kuo91 dynamic experiments A-D (first-order Ca, tabTauCaVals), experiment A
with tau_Ca = 230 s throughout and the model states during A (examples/kuo91_dynamics.py and
the protocols examples/protocols/kuo91_*.yaml; pressure levels assumed, docs/kuo91_protocols.md)."""
from __future__ import annotations

import numpy as np

from .core import example

TITLE = "Kuo91 dynamic experiments A-D"
CHAPTER = 4
LABELS = ["figKuo91Fig2ACombo", "figKuo91Fig2AStates", "figKuo91Fig2A", "figKuo91Fig2B", "figKuo91Fig2C",
          "figKuo91Fig2D"]


def runs(ctx, orders):
    """{(experiment, order): series}, {..: protocol} of the example's runs (order 1, 2, 'tau230')."""
    ex = example("kuo91_dynamics")
    circuit = ctx.load("isolated_arteriole")
    ex.DT = 0.25  # output interval [s] (the A features are read on it: not coarsened in --quick)
    out, protos = {}, {}
    for e in ex.EXPERIMENTS:
        for order in orders:
            if order == "tau230":
                if e == "A":
                    out[(e, order)], protos[(e, order)], _ = ex.run(circuit, ex.a_tau230_protocol(circuit))
            else:
                out[(e, order)], protos[(e, order)], _ = ex.run(circuit, ex.protocol_path(e, order))
    return ex, circuit, out, protos


def save_series(ctx, name, d, circuit):
    keys = [k for k in ("t", "Pup", "Pdown", "r", "Ca", "Cw", "cGMP", "AMp") if k in d]
    units = {"t": "s", "Pup": "cmH2O", "Pdown": "cmH2O", **d["_units"]}
    ctx.table(name, {k: d[k] for k in keys}, {k: units.get(k, "") for k in keys}, index=["t"], circuit=circuit)


def run(ctx):
    ex, circuit, d, protos = runs(ctx, (1, 2, "tau230"))
    for e in ex.EXPERIMENTS:
        ex.plot_experiment(e, d, protos, ctx.figure_path(e))
        ctx.existing_figure(e, f"Kuo91 fig. 2{e}: radius (first-order Ca with the tau_Ca epochs of tabTauCaVals, red; "
                               "second-order Ca of tabOmegaZeta, blue dashed" + ("; tau_Ca = 230 s throughout, dotted"
                                                                                 if e == "A" else "")
                            + ") over the intramural pressure and the pressure drop.",
                            "figKuo91Fig2ACombo, figKuo91Fig2A" if e == "A" else f"figKuo91Fig2{e}")
        save_series(ctx, f"{e}", d[(e, 1)], circuit)
    NO_U = float(circuit.parameters.values["art.NO_U"][0])
    NO_L = float(circuit.parameters.values["art.NO_L"][0])
    ex.plot_a_states(d[("A", 1)], NO_U, NO_L, ctx.figure_path("A_states"))
    ctx.existing_figure("A_states", "States during experiment A: radius, wall NO with NO_U (cGMP 95 % saturated), "
                                    "cGMP and Ca.", "figKuo91Fig2AStates")
    f = ex.a_features(d[("A", 1)], NO_U)
    ctx.value("ch4.A_dilation_peak", f["t_peak_step"])
    ctx.value("ch4.A_below_initial", f["r_238"] - f["r_50"])
    ctx.note("Experiment A (first-order Ca): " + ", ".join(
        f"{k} = {v:.4g}" for k, v in f.items()) + " (radii in um, times in s).")
