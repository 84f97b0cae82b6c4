"""svZeroDSolver's closed-loop heart (closedLoopHeart_singleVessel: their
ClosedLoopHeartAndPulmonary block, one aortic vessel, a ClosedLoopRCR back to the right atrium):
the periodic steady state by shooting, the left ventricle's pressure-volume loop, and a sweep of
the systemic (distal) resistance Rd of the ClosedLoopRCR (docs/svzerod.md, "Worked example").

Their model is read unchanged (units mmHg, mL, s: the model's own, see the JSON's comments).
For each Rd (scaled by --factors) the periodic state is found by Newton shooting
(hemocircuit.analyses.periodic.shoot, forced by the cardiac period) from a state two cycles
after their initial condition (the baseline) or from the previous member's orbit; reported:
stroke volume SV = max - min of V_LV over the cycle, the aortic valve's flow integrated over
the cycle (equal to SV when the mitral and aortic valves are never open together), cardiac
output SV/T, ejection fraction, mean aortic pressure (at the heart's outlet) and the largest
Floquet multiplier.

Writes OUT/svzerod_closed_loop.csv (one row per Rd) and OUT/svzerod_closed_loop.png (the PV
loops); OUT defaults to examples/out/.  Run:

    python examples/svzerod_closed_loop.py [OUT] [--model PATH/closedLoopHeart_singleVessel.json]
                                                 [--factors 0.5,0.75,1,1.5,2]

(about two minutes; the model is svZeroDSolver's test case, looked for in $SVZEROD_CASES/cases/.
HEMOCIRCUIT_EXAMPLES_QUICK=1: Rd x 1 only and at most 6 Newton iterations by default;
HEMOCIRCUIT_EXAMPLES_OUT=DIR: the default OUT.)
"""
from __future__ import annotations

import argparse
import csv
import os
import time

import numpy as np

DEFAULT_MODEL = os.path.join(os.environ.get("SVZEROD_CASES", "/work/shared/svzerod"), "cases",
                             "closedLoopHeart_singleVessel.json")
RD = "RCR_aorta.Rd"
HERE = os.path.dirname(os.path.abspath(__file__))
QUICK = os.environ.get("HEMOCIRCUIT_EXAMPLES_QUICK", "") not in ("", "0")  # the test suite's smoke run
OUT = os.environ.get("HEMOCIRCUIT_EXAMPLES_OUT") or os.path.join(HERE, "out")


def load(model_path):
    """(circuit, SvzModel) in the model's units (mmHg, mL, s)."""
    from hemocircuit.svzerod import import_svzerod, load_svzerod

    return load_svzerod(model_path, units="mmHg"), import_svzerod(model_path, units="mmHg")


def start_state(c, model, cycles=2):
    """The state ``cycles`` periods after their initial condition (compiled transient)."""
    from hemocircuit.analyses.transient import simulate
    from hemocircuit.ic import apply_ic

    x0 = apply_ic(c, np.zeros(c.nx), model.initial)
    res = simulate(c, cycles * model.period, dt=model.period / 100, x0=x0, rtol=1e-7, progress=False)
    return np.asarray(res.x)[-1]


def trapezoid(y, t):
    return float(np.sum(0.5 * (y[1:] + y[:-1]) * np.diff(t)))


def loop_figures(orb, c):
    """Figures of one periodic orbit (a dict)."""
    t = orb.t
    V, P = orb["CLH.V_LV"], orb["CLH.P_LV"]
    sv = float(V.max() - V.min())
    q_ao = trapezoid(orb["CLH.Q_LV"], t)
    mu = orb.nontrivial_multipliers
    prm = c.parameters.values
    r_sys = sum(float(prm[k][0]) for k in ("branch0_seg0.R_poiseuille", "RCR_aorta.Rp", RD))
    return {"Rd": float(prm[RD][0]), "R_systemic": r_sys, "stroke_volume": sv, "aortic_valve_volume": q_ao,
            "cardiac_output": sv / orb.period, "ejection_fraction": sv / float(V.max()),
            "EDV": float(V.max()), "ESV": float(V.min()), "P_LV_max": float(P.max()),
            "mean_aortic_pressure": orb.time_average("P(J_heart_outlet)"),
            "mean_venous_pressure": orb.time_average("P(J_heart_inlet)"),
            "mean_vessel_flow": orb.time_average("Q(branch0_seg0)"),
            "max_abs_multiplier": float(np.abs(mu).max()) if len(mu) else 0.0,
            "iterations": orb.iterations, "converged": orb.converged, "residual": orb.residual}


def sweep(model_path, factors=(1.0,), rtol=1e-9, max_iter=25):
    """[(figures, orbit)] for Rd scaled by each factor (the first from two cycles after their
    initial condition, the others from the previous orbit)."""
    from hemocircuit.analyses.periodic import shoot

    c0, model = load(model_path)
    rd0 = float(c0.parameters.values[RD][0])
    x = start_state(c0, model)
    out = []
    for f in factors:
        c = c0.with_values({RD: f * rd0})
        orb = shoot(c, x, model.period, forced=True, rtol=rtol, max_iter=max_iter, progress=False)
        out.append((loop_figures(orb, c), orb))
        x = orb.x0
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", nargs="?", default=OUT, help="folder for the CSV and the PNG (default: examples/out/)")
    ap.add_argument("--model", default=DEFAULT_MODEL, help="closedLoopHeart_singleVessel.json (theirs)")
    ap.add_argument("--factors", default="1" if QUICK else "0.5,0.75,1,1.5,2",
                    help="scalings of the ClosedLoopRCR's Rd")
    ap.add_argument("--max-iter", type=int, default=6 if QUICK else 25, help="Newton iterations per orbit")
    args = ap.parse_args(argv)
    if not os.path.isfile(args.model):
        raise SystemExit(f"{args.model}: not found (their closedLoopHeart_singleVessel.json; --model PATH)")
    os.makedirs(args.out, exist_ok=True)
    factors = [float(v) for v in args.factors.split(",")]
    t0 = time.perf_counter()
    rows = sweep(args.model, factors, max_iter=args.max_iter)
    print(f"{len(rows)} periodic states in {time.perf_counter() - t0:.1f} s")
    keys = list(rows[0][0])
    with open(os.path.join(args.out, "svzerod_closed_loop.csv"), "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["Rd_factor"] + keys)
        for f, (fig, _) in zip(factors, rows):
            w.writerow([f] + [fig[k] for k in keys])
    print(f"{'Rd factor':>9s} {'Rd':>7s} {'SV [mL]':>8s} {'int Q_ao':>8s} {'CO [mL/s]':>9s} {'EF':>6s} "
          f"{'MAP [mmHg]':>10s} {'P_LV max':>8s} {'|mu|max':>7s} {'Newton':>6s}")
    for f, (fig, _) in zip(factors, rows):
        print(f"{f:9.2f} {fig['Rd']:7.4f} {fig['stroke_volume']:8.3f} {fig['aortic_valve_volume']:8.3f} "
              f"{fig['cardiac_output']:9.3f} {fig['ejection_fraction']:6.3f} {fig['mean_aortic_pressure']:10.3f} "
              f"{fig['P_LV_max']:8.3f} {fig['max_abs_multiplier']:7.3f} {fig['iterations']:6d}")
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(6, 5))
    for f, (_, orb) in zip(factors, rows):
        ax.plot(orb["CLH.V_LV"], orb["CLH.P_LV"], label=f"Rd x {f:g}")
    ax.set_xlabel("left ventricular volume [mL]")
    ax.set_ylabel("left ventricular pressure [mmHg]")
    ax.set_title("closedLoopHeart_singleVessel: periodic PV loops")
    ax.legend()
    fig.tight_layout()
    png = os.path.join(args.out, "svzerod_closed_loop.png")
    fig.savefig(png, dpi=120)
    print(f"wrote {png} and svzerod_closed_loop.csv")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
