"""Phase of the cerebral flow against the Ca time constant at 0.1 Hz (thesis figure
figautoregPhase; issue 5, "payne06 at 0.1 Hz").

netlists/payne06.yaml (active bed, kuo91), forced with Pa = 80 + 4 + 4 sin(2 pi 0.1 t) mmHg,
i.e. a 5 % step plus a 5 % sine of the 80 mmHg baseline (MODEL_NOTES "Analyses").  One batched
nonlinear frequency response (hemocircuit.analyses.freq) over the grid

    art.volume_flow in {true (as written), false (the bed's volume flow neglected)}
  x art.tau_Ca      in 12 log-spaced values, 0.5 .. 20 s

gives the phase of q1 = Q(Rla) (inflow) and q2 = Q(Rsv) (outflow) relative to Pa, positive when
the flow leads.  The script reports, for each case and flow, where the phase reverses from lead
to lag (linear interpolation of the phase in log tau_Ca between the bracketing grid values);
the thesis puts the reversal near tau_Ca = 2.5 s when the volume flow is neglected.

Writes examples/out/payne06_phase_vs_tau.csv (the frequency response, one row per run) and
examples/out/payne06_phase_vs_tau.png.

Run:  python examples/payne06_phase_vs_tau.py [--workers N] [--scheduler serial|processes|tcp://...]
                                             [--n-tau 12] [--out-dir DIR]
(about a minute; HEMOCIRCUIT_EXAMPLES_QUICK=1: 4 tau_Ca values by default;
HEMOCIRCUIT_EXAMPLES_OUT=DIR: the default of --out-dir instead of examples/out/)
"""
from __future__ import annotations

import argparse
import os
import time

import numpy as np

import hemocircuit as hc
from hemocircuit.analyses.freq import frequency_response

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
NETLIST = os.path.join(ROOT, "netlists", "payne06.yaml")
QUICK = os.environ.get("HEMOCIRCUIT_EXAMPLES_QUICK", "") not in ("", "0")  # the test suite's smoke run
OUT = os.environ.get("HEMOCIRCUIT_EXAMPLES_OUT") or os.path.join(HERE, "out")

FREQ = 0.1          # Hz
STEP = 0.05         # 80 -> 84 mmHg
AMPLITUDE = 0.05    # 4 mmHg
OUTPUTS = ("Q(Rla)", "Q(Rsv)")
LABEL = {"Q(Rla)": "q1 = Q(Rla)", "Q(Rsv)": "q2 = Q(Rsv)"}
CASES = ((True, "volume flow on (as written)"), (False, "volume flow neglected"))


def reversals(tau, phase):
    """tau values where the phase crosses from lead (> 0) to lag (<= 0), interpolated in log tau."""
    out = []
    lt = np.log(tau)
    for k in range(len(tau) - 1):
        a, b = phase[k], phase[k + 1]
        if a > 0 >= b:
            out.append(float(np.exp(lt[k] + (lt[k + 1] - lt[k]) * a / (a - b))))
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--scheduler", default=None)
    ap.add_argument("--n-tau", type=int, default=4 if QUICK else 12)
    ap.add_argument("--out-dir", default=OUT)
    args = ap.parse_args(argv)

    c = hc.load(NETLIST)
    P0 = float(c.parameters.values["Pa.value"][0])
    taus = np.logspace(np.log10(0.5), np.log10(20.0), args.n_tau)
    grid = [("art.volume_flow", [vf for vf, _ in CASES]), ("art.tau_Ca", list(taus))]
    print(f"payne06: Pa = {P0:g} + {STEP * P0:g} + {AMPLITUDE * P0:g} sin(2 pi {FREQ:g} t) mmHg; "
          f"{len(CASES)} cases x {len(taus)} tau_Ca values ({taus[0]:.3g}..{taus[-1]:.3g} s)")
    t0 = time.perf_counter()
    res = frequency_response(c, [FREQ], outputs=OUTPUTS, input="Pa", step=STEP, amplitude=AMPLITUDE, grid=grid,
                             scheduler=args.scheduler, workers=args.workers)
    wall = time.perf_counter() - t0
    print(f"{res.n_rows} runs in {wall:.1f} s")
    rows = res.rows()  # one per run: grid values, frequency, per output phase(o/Pa.value), ...

    for r in rows:
        if r["error"]:
            print(f"FAILED: volume_flow={r['art.volume_flow']} tau_Ca={r['art.tau_Ca']:.4g} s: {r['error']}")

    table = {}  # (volume_flow, output) -> (tau, phase, rel_amplitude, periods, settled)
    for vf, _ in CASES:
        for o in OUTPUTS:
            rs = sorted((r for r in rows if r["art.volume_flow"] == vf and not r["error"]),
                        key=lambda r: r["art.tau_Ca"])
            table[vf, o] = tuple(np.array([r[k] for r in rs]) for k in
                                 ("art.tau_Ca", f"phase({o}/Pa.value)", f"rel_amplitude({o})", "periods", "settled"))

    print()
    hdr = f"{'tau_Ca [s]':>10}"
    for vf, name in CASES:
        for o in OUTPUTS:
            hdr += f" {('VF on ' if vf else 'VF off ') + o.replace('Q(', '').rstrip(')') + ' ph':>14}"
    print(hdr + "   (phase [deg], + = flow leads Pa)")
    for i, tau in enumerate(taus):
        line = f"{tau:>10.4g}"
        for vf, _ in CASES:
            for o in OUTPUTS:
                ts, ph = table[vf, o][0], table[vf, o][1]
                j = np.nonzero(np.isclose(ts, tau))[0]
                line += f" {ph[j[0]]:>+14.2f}" if j.size else f" {'failed':>14}"
        print(line)

    print()
    summary = {}
    for vf, name in CASES:
        for o in OUTPUTS:
            ts, ph, amp, per, st = table[vf, o]
            rv = reversals(ts, ph)
            summary[vf, o] = rv
            where = ", ".join(f"{v:.3g} s" for v in rv) if rv else (
                "none (leads throughout)" if np.all(ph > 0) else "none (lags throughout)" if np.all(ph <= 0)
                else "none from lead to lag")
            print(f"{name:>28}, {LABEL[o]}: lead -> lag at tau_Ca = {where}; "
                  f"periods simulated {int(per.min())}..{int(per.max())}, all settled: {bool(np.all(st))}")
    print("thesis: reversal near tau_Ca = 2.5 s with the volume flow neglected")

    os.makedirs(args.out_dir, exist_ok=True)
    csv_path = os.path.join(args.out_dir, "payne06_phase_vs_tau.csv")
    res.save(csv_path)
    png_path = os.path.join(args.out_dir, "payne06_phase_vs_tau.png")
    plot(png_path, table, summary)
    print(f"wrote {csv_path}\nwrote {png_path}\ntotal {time.perf_counter() - t0:.1f} s")
    return res, summary, wall


def plot(path, table, summary):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 4.8))
    styles = {(True, "Q(Rla)"): ("C0", "-o"), (True, "Q(Rsv)"): ("C0", "--s"),
              (False, "Q(Rla)"): ("C3", "-o"), (False, "Q(Rsv)"): ("C3", "--s")}
    for vf, name in CASES:
        for o in OUTPUTS:
            ts, ph = table[vf, o][0], table[vf, o][1]
            col, st = styles[vf, o]
            same = (not vf and o == "Q(Rsv)" and np.allclose(ph, table[vf, "Q(Rla)"][1], atol=1e-6))
            ax.semilogx(ts, ph, st, color=col, ms=4, label=f"{LABEL[o]}, {name}" + (" (= q1)" if same else ""))
            for v in summary[vf, o]:
                ax.axvline(v, color=col, lw=0.6, ls=":")
    ax.axhline(0.0, color="k", lw=0.8)
    ax.axvline(2.5, color="0.5", lw=1.0, ls="-.", label="thesis: reversal near 2.5 s (VF neglected)")
    ax.set_xlabel("tau_Ca [s]")
    ax.set_ylabel("phase of flow vs Pa at 0.1 Hz [deg] (+ = leads)")
    ax.set_title("payne06: Pa = 80 + 4 + 4 sin(2 pi 0.1 t) mmHg")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    main()
