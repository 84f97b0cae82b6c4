"""The four Kuo91 dynamic experiments A-D (Kuo, Chilian & Davis 1991, fig. 2; thesis section
dynfitting, figures figKuo91Fig2A-D, figKuo91Fig2ACombo and figKuo91Fig2AStates).

Runs ``netlists/isolated_arteriole.yaml`` through the protocols
``examples/protocols/kuo91_{A,B,C,D}.yaml`` (first-order Ca, table tabTauCaVals) and
``kuo91_{A,B,C,D}_2nd.yaml`` (second-order Ca, table tabOmegaZeta), plus experiment A with
tau_Ca = 230 s throughout (the dashed line of figKuo91Fig2ACombo).  The pressure levels of
the protocols are assumptions (docs/kuo91_protocols.md); the event times and Ca time constants
are the thesis's.

Writes to examples/out/:
  kuo91_<run>.csv            time series (t, Pup, Pdown, P, dP, r, lambda, Ca, Cw, cGMP, ...)
  kuo91_features.csv         response features per event (radius before, extreme, epoch end)
  kuo91_{A,B,C,D}.png        radius (1st and 2nd order) over P and dP, like Kuo91 fig. 2
  kuo91_fig2_overview.png    the four first-order radius traces (figKuo91Fig2A-D)
  kuo91_A_states.png         radius, wall NO with NO_U, Ca and cGMP in A (figKuo91Fig2AStates)

Run:  python examples/kuo91_dynamics.py   (about 10 s once the engine is compiled;
HEMOCIRCUIT_EXAMPLES_QUICK=1: the same runs written every 1 s instead of 0.25 s;
HEMOCIRCUIT_EXAMPLES_OUT=DIR: write to DIR instead of examples/out/)
"""
from __future__ import annotations

import csv
import os
import time

import numpy as np
import yaml

import hemocircuit as hc
from hemocircuit.protocol import Protocol
from hemocircuit.units import conversion_factor

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
NETLIST = os.path.join(ROOT, "netlists", "isolated_arteriole.yaml")
PROTOCOLS = os.path.join(HERE, "protocols")
QUICK = os.environ.get("HEMOCIRCUIT_EXAMPLES_QUICK", "") not in ("", "0")  # the test suite's smoke run
OUT = os.environ.get("HEMOCIRCUIT_EXAMPLES_OUT") or os.path.join(HERE, "out")

CMH2O_PER_MMHG = conversion_factor("mmHg", "cmH2O")
DT = 1.0 if QUICK else 0.25  # output interval [s]
EXPERIMENTS = ("A", "B", "C", "D")
SERIES = ("r", "lambda", "Ca", "dCa", "Cw", "Cb_mean", "cGMP", "M", "Mp", "AMp", "AM", "sigma",
          "tau_hat", "Q")


def protocol_path(exp, order):
    return os.path.join(PROTOCOLS, f"kuo91_{exp}{'_2nd' if order == 2 else ''}.yaml")


def a_tau230_protocol(circuit):
    """Experiment A with tau_Ca = 230 s throughout (figKuo91Fig2ACombo, dashed line)."""
    with open(protocol_path("A", 1)) as fh:
        data = yaml.safe_load(fh)
    for ev in data["events"]:
        ev["set"].pop("art.tau_Ca", None)
    data["description"] = "Kuo91 fig. 2A with tau_Ca = 230 s throughout (figKuo91Fig2ACombo, dashed)"
    return Protocol.from_dict(data, None, circuit)


def run(circuit, protocol):
    """Simulate one protocol; returns (dict of arrays, protocol object, runtime [s])."""
    t0 = time.perf_counter()
    proto = Protocol.load(protocol, circuit) if isinstance(protocol, str) else protocol
    res = circuit.simulate(proto.t_end, dt=DT, protocol=proto)
    wall = time.perf_counter() - t0
    pup = res["P(up)"] * CMH2O_PER_MMHG
    pdown = res["P(down)"] * CMH2O_PER_MMHG
    d = {"t": res.t, "Pup": pup, "Pdown": pdown, "P": 0.5 * (pup + pdown), "dP": pup - pdown}
    for k in SERIES:
        if f"art.{k}" in res.columns:
            d[k] = np.asarray(res[f"art.{k}"])
    d["_units"] = {k: res.units.get(f"art.{k}", "") for k in SERIES}
    return d, proto, wall


def at(d, t, key="r"):
    """Value of a series at time t (linear interpolation)."""
    return float(np.interp(t, d["t"], d[key]))


def event_features(d, proto):
    """For each event: radius just before, the extreme within 30 s after (max for a rise of P
    or a flow onset, min otherwise, with its time) and the radius at the end of the epoch."""
    rows = []
    times = [ev.at for ev in proto.events] + [d["t"][-1]]
    for k, ev in enumerate(proto.events):
        t_ev, t_next = ev.at, times[k + 1]
        # the output grid holds the post-event value at t_ev itself: read the levels one step away
        P_b, P_a = at(d, t_ev - DT, "P"), at(d, t_ev + DT, "P")
        dP_b, dP_a = at(d, t_ev - DT, "dP"), at(d, t_ev + DT, "dP")
        if abs(P_a - P_b) > 1e-6:
            what = f"P {P_b:.0f} -> {P_a:.0f} cmH2O"
        elif abs(dP_a - dP_b) > 1e-6:
            what = f"dP {dP_b:.0f} -> {dP_a:.0f} cmH2O"
        else:
            what = "parameter change"
        up = (P_a > P_b + 1e-6) or (dP_a > dP_b + 1e-6)
        m = (d["t"] > t_ev) & (d["t"] <= min(t_ev + 30.0, t_next))
        j = np.argmax(d["r"][m]) if up else np.argmin(d["r"][m])
        rows.append({"event_t": t_ev, "change": what, "r_before": at(d, t_ev - 1e-3),
                     "r_extreme": float(d["r"][m][j]), "t_extreme": float(d["t"][m][j]),
                     "r_epoch_end": at(d, t_next - 1e-3)})
    return rows


def a_features(d, NO_U):
    """The features of experiment A that the thesis describes (figKuo91Fig2ACombo/States)."""
    t, r = d["t"], d["r"]
    f = {"r_50": at(d, 50.0), "r_60": at(d, 60.0), "r_238": at(d, 238.0)}
    m = (t > 51) & (t < 100)
    f["r_peak_step"], f["t_peak_step"] = float(r[m].max()), float(t[m][np.argmax(r[m])])
    # slow myogenic contraction: time from the peak until 63 % of the fall to r(238)
    m = (t >= f["t_peak_step"]) & (t <= 238)
    target = f["r_peak_step"] - (1 - np.exp(-1)) * (f["r_peak_step"] - f["r_238"])
    f["t63_contraction"] = float(t[m][np.argmax(r[m] <= target)] - f["t_peak_step"])
    target = f["r_peak_step"] - 0.9 * (f["r_peak_step"] - f["r_238"])
    f["t90_contraction"] = float(t[m][np.argmax(r[m] <= target)] - f["t_peak_step"])
    # flow dilation: plateau (r just before flow stops) and the time to 90 % of the rise
    f["r_plateau_flow"] = at(d, 299.9)
    f["r_250"] = at(d, 250.0)
    m = (t >= 239) & (t <= 300)
    target = f["r_238"] + 0.9 * (f["r_plateau_flow"] - f["r_238"])
    f["t90_flow_dilation"] = float(t[m][np.argmax(r[m] >= target)] - 239.0)
    # delayed constriction after flow stops at 300 s
    m = t >= 300
    f["delay_r_drop_1um"] = float(t[m][np.argmax(r[m] < f["r_plateau_flow"] - 1.0)] - 300.0)
    f["delay_Cw_below_NO_U"] = float(t[m][np.argmax(d["Cw"][m] < NO_U)] - 300.0)
    f["Cw_peak"] = float(d["Cw"][m].max())
    f["r_400"] = at(d, 400.0)
    f["r_end"] = float(r[-1])
    return f


def write_csv(path, d):
    keys = [k for k in ("t", "Pup", "Pdown", "P", "dP") + SERIES if k in d]
    units = {"t": "s", "Pup": "cmH2O", "Pdown": "cmH2O", "P": "cmH2O", "dP": "cmH2O", **d["_units"]}
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow([f"{k} [{units[k]}]" for k in keys])
        for j in range(len(d["t"])):
            w.writerow([f"{d[k][j]:.8g}" for k in keys])


def _plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def plot_experiment(exp, runs, protos, path):
    plt = _plt()
    fig, axs = plt.subplots(3, 1, figsize=(7, 6.2), sharex=True, gridspec_kw={"height_ratios": [3, 1, 1]})
    d1, d2 = runs[(exp, 1)], runs[(exp, 2)]
    axs[0].plot(d1["t"], d1["r"], "r-", lw=2, label="model, 1st-order Ca (tabTauCaVals)")
    axs[0].plot(d2["t"], d2["r"], "b--", lw=1.5, label="model, 2nd-order Ca (tabOmegaZeta)")
    if (exp, "tau230") in runs:
        d3 = runs[(exp, "tau230")]
        axs[0].plot(d3["t"], d3["r"], "k:", lw=1.5, label="1st order, tau_Ca = 230 s throughout")
    axs[0].set_ylabel("radius r ($\\mu$m)")
    axs[0].legend(fontsize=8)
    axs[1].plot(d1["t"], d1["P"], "k-")
    axs[1].set_ylabel("P (cmH$_2$O)")
    axs[2].plot(d1["t"], d1["dP"], "k-")
    axs[2].set_ylabel("$\\Delta$P (cmH$_2$O)")
    axs[2].set_ylim(-0.5, 5)
    axs[2].set_xlabel("time (s)")
    for ax in axs:
        for ev in protos[(exp, 1)].events:
            ax.axvline(ev.at, color="gray", lw=0.6, ls=":")
        ax.grid(alpha=0.3)
    axs[0].set_title(f"Kuo91 fig. 2{exp} (cf. figKuo91Fig2{exp}): radius, P and $\\Delta$P\n"
                     f"{event_summary(d1, protos[(exp, 1)])} (cmH$_2$O; levels assumed)", fontsize=9)
    axs[1].set_ylim(d1["P"].min() - 5, d1["P"].max() + 5)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def event_summary(d, proto):
    """'51 s: P 60 -> 80 cmH2O; 239 s: dP 0 -> 4 cmH2O; ...' for titles."""
    return "; ".join(f"{r['event_t']:g} s: {r['change'].replace(' cmH2O', '')}" for r in event_features(d, proto))


def plot_overview(runs, protos, path):
    plt = _plt()
    fig, axs = plt.subplots(2, 2, figsize=(10, 6.5))
    for ax, exp in zip(axs.ravel(), EXPERIMENTS):
        d = runs[(exp, 1)]
        ax.plot(d["t"], d["r"], "r-", lw=2)
        for ev in protos[(exp, 1)].events:
            ax.axvline(ev.at, color="gray", lw=0.6, ls=":")
        ax.set_title(f"{exp}: {event_summary(d, protos[(exp, 1)])} (cmH$_2$O)", fontsize=8)
        ax.set_xlabel("time (s)")
        ax.set_ylabel("radius ($\\mu$m)")
        ax.grid(alpha=0.3)
    fig.suptitle("Kuo91 fig. 2A-D, model with first-order Ca (figKuo91Fig2A-D)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_a_states(d, NO_U, NO_L, path):
    plt = _plt()
    fig, axs = plt.subplots(4, 1, figsize=(7, 8), sharex=True)
    axs[0].plot(d["t"], d["r"], "r-", lw=2)
    axs[0].set_ylabel("radius ($\\mu$m)")
    axs[1].semilogy(d["t"], d["Cw"], "g-", lw=2, label="wall [NO] $C_w$")
    axs[1].axhline(NO_U, color="k", ls="--", lw=1, label="NO$_U$ (cGMP 95 % saturated)")
    axs[1].axhline(NO_L, color="gray", ls=":", lw=1, label="NO$_L$ (5 %)")
    axs[1].set_ylabel("[NO] (M)")
    axs[1].legend(fontsize=8, loc="upper left")
    axs[2].plot(d["t"], d["cGMP"] * 1e9, "m-", lw=2)
    axs[2].set_ylabel("[cGMP] (nM)")
    axs[3].plot(d["t"], d["Ca"] * 1e9, "b-", lw=2)
    axs[3].set_ylabel("[Ca$^{2+}$] (nM)")
    axs[3].set_xlabel("time (s)")
    for ax in axs:
        for tt in (51, 239, 300):
            ax.axvline(tt, color="gray", lw=0.6, ls=":")
        ax.grid(alpha=0.3)
    axs[0].set_title("States during Kuo91 fig. 2A, first-order Ca (cf. figKuo91Fig2AStates);\n"
                     "step of P at 51 s, flow 239-300 s", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main():
    t_start = time.perf_counter()
    os.makedirs(OUT, exist_ok=True)
    circuit = hc.load(NETLIST)
    NO_U = float(circuit.parameters.values["art.NO_U"][0])
    NO_L = float(circuit.parameters.values["art.NO_L"][0])
    runs, protos, walls = {}, {}, {}
    for exp in EXPERIMENTS:
        for order in (1, 2):
            runs[(exp, order)], protos[(exp, order)], walls[(exp, order)] = run(circuit, protocol_path(exp, order))
    p230 = a_tau230_protocol(circuit)
    runs[("A", "tau230")], protos[("A", "tau230")], walls[("A", "tau230")] = run(circuit, p230)

    names = {1: "{}", 2: "{}_2nd", "tau230": "{}_tau230"}
    feature_rows = []
    for (exp, order), d in runs.items():
        name = names[order].format(exp)
        write_csv(os.path.join(OUT, f"kuo91_{name}.csv"), d)
        for row in event_features(d, protos[(exp, order)]):
            feature_rows.append({"run": name, **row})
    with open(os.path.join(OUT, "kuo91_features.csv"), "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(feature_rows[0]))
        w.writeheader()
        for row in feature_rows:
            w.writerow({k: (f"{v:.4g}" if isinstance(v, float) else v) for k, v in row.items()})
    for exp in EXPERIMENTS:
        plot_experiment(exp, runs, protos, os.path.join(OUT, f"kuo91_{exp}.png"))
    plot_overview(runs, protos, os.path.join(OUT, "kuo91_fig2_overview.png"))
    plot_a_states(runs[("A", 1)], NO_U, NO_L, os.path.join(OUT, "kuo91_A_states.png"))

    # summary
    print("run        runtime  events: change, r before -> extreme (t) -> epoch end [um]")
    for (exp, order), d in runs.items():
        name = names[order].format(exp)
        evs = [f"{r['change']}: {r['r_before']:.1f} -> {r['r_extreme']:.1f} ({r['t_extreme']:.1f} s) -> "
               f"{r['r_epoch_end']:.1f}" for r in feature_rows if r["run"] == name]
        print(f"{name:10s} {walls[(exp, order)]:5.2f} s  " + "\n                     ".join(evs))
    for exp in EXPERIMENTS:
        d1, d2 = runs[(exp, 1)], runs[(exp, 2)]
        print(f"{exp}: max |r(1st) - r(2nd)| = {np.max(np.abs(d1['r'] - d2['r'])):.2f} um")
    fa = a_features(runs[("A", 1)], NO_U)
    print("experiment A (first order):")
    for k, v in fa.items():
        print(f"  {k:22s} {v:10.4g}")
    fb = a_features(runs[("A", "tau230")], NO_U)
    print(f"A with tau_Ca = 230 s throughout: r(250) = {fb['r_250']:.2f}, r(299.9) = {fb['r_plateau_flow']:.2f} um "
          f"(first-order A: {fa['r_plateau_flow']:.2f})")
    print(f"wrote CSVs and PNGs in {OUT} ({time.perf_counter() - t_start:.1f} s)")


if __name__ == "__main__":
    main()
