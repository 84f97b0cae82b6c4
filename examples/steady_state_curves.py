"""Steady-state radius of the isolated arteriole against intramural pressure (thesis figures
figPassiveFitBoth, figActiveFitKuo, figActiveFitFalcone; data of Kuo91 fig. 4 / Falcone91 fig. 1).

For both presets (kuo91, falcone91) and P = 20..140 cmH2O:
  passive          ``art.passive: true`` (Ca = 0, no myogenic response), no flow
  active, no flow  Pup = Pdown = P
  active, flow     dP = 4 cmH2O: Pup = P + 2, Pdown = P - 2 cmH2O (Kuo's method, mean P held)
Each curve is one batched operating point of ``netlists/isolated_arteriole.yaml`` (all
pressures solved at once).

Writes examples/out/steady_state_curves.csv (long format, one row per preset x case x P)
and the PNGs steady_kuo91.png, steady_falcone91.png and steady_passive_both.png.

Run:  python examples/steady_state_curves.py   (a few seconds; HEMOCIRCUIT_EXAMPLES_QUICK=1: P in
steps of 10 cmH2O; HEMOCIRCUIT_EXAMPLES_OUT=DIR: write to DIR instead of examples/out/)
"""
from __future__ import annotations

import csv
import os
import time

import numpy as np

import hemocircuit as hc
from hemocircuit.units import conversion_factor

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
NETLIST = os.path.join(ROOT, "netlists", "isolated_arteriole.yaml")
QUICK = os.environ.get("HEMOCIRCUIT_EXAMPLES_QUICK", "") not in ("", "0")  # the test suite's smoke run
OUT = os.environ.get("HEMOCIRCUIT_EXAMPLES_OUT") or os.path.join(HERE, "out")

MMHG_PER_CMH2O = conversion_factor("cmH2O", "mmHg")  # 0.7356
P_CMH2O = np.arange(20.0, 140.0 + 1e-9, 10.0 if QUICK else 2.0)  # intramural pressure grid
DP_FLOW = 4.0                                          # cmH2O, Kuo91 fig. 4 'with flow'
PRESETS = ("kuo91", "falcone91")
CASES = (  # name, structural options, dP [cmH2O]
    ("passive", {"art.passive": True}, 0.0),
    ("active_no_flow", {}, 0.0),
    ("active_flow", {}, DP_FLOW),
)
COLUMNS = ("r", "lambda", "Ca", "Cw", "cGMP", "AMp", "AM", "sigma", "tau_hat", "Q")


def curve(base, preset, options, dP, P=P_CMH2O):
    """Operating points of the isolated arteriole for every P (cmH2O) in one batch.

    Returns {observable: (len(P),) array} with the element's observables (art.r in um, ...)."""
    c = base.with_options({"art.preset": preset, **options}).batch(len(P))
    c = c.with_values({"Pup.value": (P + dP / 2) * MMHG_PER_CMH2O})  # declared unit: mmHg
    c = c.with_values({"Pdown.value": (P - dP / 2) * MMHG_PER_CMH2O})
    op = c.operating_point()
    return {k: np.asarray(op[f"art.{k}"], dtype=float) for k in COLUMNS}, op.units


def plateau(P, r, lo=60.0, hi=120.0):
    """Autoregulation measures on [lo, hi] cmH2O: total change r(hi) - r(lo) and the largest
    rise over any sub-interval (<= 0 means r never increases with P there)."""
    m = (P >= lo - 1e-9) & (P <= hi + 1e-9)
    rr = r[m]
    max_rise = max(rr[j] - rr[:j + 1].min() for j in range(len(rr)))
    return rr[-1] - rr[0], max_rise


def plot(preset, data, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 5.4))
    P = P_CMH2O
    ax.plot(P, data[(preset, "passive")]["r"], "k-", lw=2, label="passive (Ca = 0)")
    ax.plot(P, data[(preset, "active_no_flow")]["r"], "m-", lw=2, label="active, no flow")
    ax.plot(P, data[(preset, "active_flow")]["r"], "m--", lw=2,
            label=f"active, flow ($\\Delta P$ = {DP_FLOW:g} cmH$_2$O)")
    # the thesis's set point (figPassiveFitBoth): r = 60 um at P = 60 mmHg, active, no flow
    ax.plot([60.0 / MMHG_PER_CMH2O], [60.0], "o", mfc="none", mec="tab:blue", ms=9,
            label="thesis set point (60 um at 60 mmHg)")
    ax.set_xlabel("intramural pressure P (cmH$_2$O)")
    ax.set_ylabel("radius r ($\\mu$m)")
    ax.set_xlim(P[0], P[-1])
    ax.set_title(f"Steady state, preset {preset} (cf. thesis fig. "
                 f"{'figActiveFitKuo' if preset == 'kuo91' else 'figActiveFitFalcone'})", fontsize=10)
    top = ax.secondary_xaxis("top", functions=(lambda x: x * MMHG_PER_CMH2O, lambda x: x / MMHG_PER_CMH2O))
    top.set_xlabel("P (mmHg)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=2, frameon=False)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_passive_both(data, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 5.4))
    P = P_CMH2O
    for preset, col in (("kuo91", "tab:blue"), ("falcone91", "tab:gray")):
        ax.plot(P, data[(preset, "passive")]["r"], "-", color=col, lw=2, label=f"{preset} passive")
        ax.plot(P, data[(preset, "active_no_flow")]["r"], "--", color=col, lw=1.5,
                label=f"{preset} active, no flow")
    ax.plot([60.0 / MMHG_PER_CMH2O], [60.0], "o", mfc="none", mec="tab:red", ms=9,
            label="set point r = 60 um at 60 mmHg")
    ax.set_xlabel("intramural pressure P (cmH$_2$O)")
    ax.set_ylabel("radius r ($\\mu$m)")
    ax.set_xlim(P[0], P[-1])
    ax.set_title("Passive and active no-flow curves, both presets (cf. figPassiveFitBoth)", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=2, frameon=False)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main():
    t0 = time.perf_counter()
    os.makedirs(OUT, exist_ok=True)
    base = hc.load(NETLIST)
    data, units = {}, None
    for preset in PRESETS:
        for case, opts, dP in CASES:
            data[(preset, case)], units = curve(base, preset, opts, dP)

    csv_path = os.path.join(OUT, "steady_state_curves.csv")
    with open(csv_path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["preset", "case", "P [cmH2O]", "P [mmHg]", "dP [cmH2O]"]
                   + [f"{k} [{units['art.' + k]}]" for k in COLUMNS])
        for preset in PRESETS:
            for case, _, dP in CASES:
                d = data[(preset, case)]
                for j, P in enumerate(P_CMH2O):
                    w.writerow([preset, case, f"{P:g}", f"{P * MMHG_PER_CMH2O:.4f}", f"{dP:g}"]
                               + [f"{d[k][j]:.6g}" for k in COLUMNS])
    for preset in PRESETS:
        plot(preset, data, os.path.join(OUT, f"steady_{preset}.png"))
    plot_passive_both(data, os.path.join(OUT, "steady_passive_both.png"))

    # summary
    P = P_CMH2O
    show = [20, 40, 60, 80, 100, 120, 140]
    idx = [int(np.argmin(abs(P - s))) for s in show]
    print("radius [um] at P [cmH2O] =", show)
    for preset in PRESETS:
        for case, _, _ in CASES:
            r = data[(preset, case)]["r"]
            total, rise = plateau(P, r)
            print(f"  {preset:9s} {case:15s}", " ".join(f"{r[i]:6.1f}" for i in idx),
                  f"| 60-120 cmH2O: change {total:+5.1f} um, largest rise {rise:4.1f} um")
        shift = data[(preset, "active_flow")]["r"] - data[(preset, "active_no_flow")]["r"]
        print(f"  {preset:9s} flow shift (flow - no flow): min {shift.min():.1f} um, max {shift.max():.1f} um")
    # the set point: kuo91, active, no flow, 60 mmHg
    c = base.with_values({"Pup.value": "60 mmHg"})
    c = c.with_values({"Pdown.value": "60 mmHg"})
    print(f"kuo91 active, no flow, P = 60 mmHg: r = {c.operating_point()['art.r']:.2f} um (thesis: 60)")
    print(f"wrote {csv_path} and PNGs in {OUT} ({time.perf_counter() - t0:.1f} s)")


if __name__ == "__main__":
    main()
