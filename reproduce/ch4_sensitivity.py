"""Chapter 4, sensitivity analysis (section sensitivity) with hemocircuit.sensitivity: the
constellation method, multiplicative +/-10 % and +/-50 %, on the steady radius of the Kuo91
arteriole (examples/sensitivity/arteriole_op.yaml), and the dynamic analysis of experiment A
(examples/sensitivity/kuo91_A_dynamic.yaml).

Differences from the thesis: its output is the 17-parameter rms fit error, whose operating
points make a 1000-point constellation take hours here (docs/sensitivity.md, "Cost"); the
steady radius at 40, 80 and 120 cmH2O stands in for it.  The additive scheme needs the
tabBounds space of the fit error and is not drawn."""
from __future__ import annotations

from .core import repo_path

TITLE = "Sensitivity analysis (constellation method, multiplicative and dynamic)"
CHAPTER = 4
LABELS = ["figsensitivityMultiplicative10", "figsensitivityMultiplicative50", "figdynSensitivity50radius",
          "figdynSensitivity50"]


def run(ctx):
    from ..analyses.sensitivity import sensitivity, write_outputs

    c = ctx.load("isolated_arteriole")
    netlist = repo_path("netlists", "isolated_arteriole.yaml")
    op_spec = repo_path("examples", "sensitivity", "arteriole_op.yaml")
    n = ctx.setting("constellation points", 2, 20)
    for rng, label in ((10, "figsensitivityMultiplicative10"), (50, "figsensitivityMultiplicative50")):
        res = sensitivity(c, op_spec, netlist, scheduler="serial", overrides={"range": rng, "n": n})
        write_outputs(res, plot=ctx.figure_path(f"mult{rng}"))
        ctx.rows(f"mult{rng}", res.table, res.columns, c, {"range %": rng, "n": n, "spec": op_spec})
        ctx.existing_figure(f"mult{rng}", f"Multiplicative +/-{rng} %: sigma against mu* of the elementary effects "
                                          "(%/%) on the steady radius at 40, 80, 120 cmH2O, "
                                          f"{res.n_runs} model runs.", label)
    # the statement: where the Ca bounds of the myogenic response rank, by the normalised
    # derivatives at the centre (deterministic, so --quick and full agree)
    loc = sensitivity(c, op_spec, netlist, scheduler="serial", overrides={"name": "local"})
    j = [k for k, lab in enumerate(loc.labels) if "80" in str(lab)] or [1]
    ranking = loc.ranking(j[0])
    ctx.value("ch4.sens.pCa_rank", max(ranking.index("art.pCa_L"), ranking.index("art.pCa_U")) + 1)
    ctx.note(f"Local normalised sensitivities at 80 cmH2O rank: {', '.join(ranking)}.")

    dyn = sensitivity(c, repo_path("examples", "sensitivity", "kuo91_A_dynamic.yaml"), netlist, scheduler="serial",
                      overrides={"n": ctx.setting("dynamic points", 4, 100)})
    write_outputs(dyn, plot=ctx.figure_path("dynamic"))
    ctx.rows("dynamic", dyn.table, dyn.columns, c, {"n": ctx.settings["dynamic points"]})
    ctx.rows("dynamic_series", dyn.extra["series"], dyn.extra["series_columns"], c)
    ctx.existing_figure("dynamic", f"Dynamic sensitivity of the radius during Kuo91 A, +/-50 % around v, f2, tau_Ca1, "
                                   f"tau_Ca2, NO speed (f1 tied to 1/v); {dyn.n_runs} transients; baseline responses "
                                   "in grey.", "figdynSensitivity50radius, figdynSensitivity50")
