"""The brain in a beating body, measured the way the clinic measures autoregulation
(docs/body.md): transfer function analysis of spontaneous fluctuations, a thigh-cuff release
with its ARI, and the LF phase against the arterioles' Ca time constant.

netlists/body/fluctuations.yaml (the whole-body model with a fluctuating systemic resistance)
and fluctuations_impaired.yaml (passive arterioles) are run for T seconds; the last T - 30 s of
the arterial pressure P(art) and the left hemisphere's inflow Q(left.Rla) are beat-averaged and
analysed with the CARNet settings (hemocircuit.dca.tfa).  netlists/body/cuff_release.yaml is
run intact and with passive arterioles, and Tiecks' ARI fitted to each response.  Finally the
intact model is run at several art.tau_Ca (both hemispheres) and its LF phase reported.

Writes to examples/out/body_autoregulation/: tfa.csv (a row per case and band), ari.csv,
tau_phase.csv, and tfa.png, cuff.png, tau_phase.png.

Run:  python examples/body_autoregulation.py [--out-dir DIR]
(about 2-3 minutes on 2 cores; HEMOCIRCUIT_EXAMPLES_QUICK=1: shorter runs and windows, two
tau_Ca values; HEMOCIRCUIT_EXAMPLES_OUT=DIR: the default of --out-dir instead of examples/out/)
"""
from __future__ import annotations

import argparse
import csv
import os

import numpy as np

import hemocircuit as hc
from hemocircuit.dca.ari import fit_ari
from hemocircuit.dca.series import uniform_series
from hemocircuit.dca.tfa import tfa
from hemocircuit.io import pyplot, save_figure

HERE = os.path.dirname(os.path.abspath(__file__))
BODY = os.path.join(os.path.dirname(HERE), "netlists", "body")
QUICK = os.environ.get("HEMOCIRCUIT_EXAMPLES_QUICK", "") not in ("", "0")  # the test suite's smoke run
OUT = os.environ.get("HEMOCIRCUIT_EXAMPLES_OUT") or os.path.join(HERE, "out")

SKIP = 10.0 if QUICK else 30.0          # s: the start from the operating point, left out
T_RUN = 50.0 if QUICK else 330.0        # s: SKIP, then the analysed record
WINDOW = 20.0 if QUICK else 100.0       # s: Welch window (the white paper's 100 s; quick: 3 windows)
RELEASE = 20.0 if QUICK else 60.0       # s: the cuff release (cuff_release.yaml: 60 s; quick: a variant)
CUFF = (10.0, 15.0) if QUICK else (10.0, 30.0)  # baseline before, fit after the release [s]
TAUS = (2.0, 20.0) if QUICK else (0.1, 0.3, 1.0, 3.0, 10.0)  # art.tau_Ca [s] (body.yaml: 0.1 s)
P_IN, Q_OUT = "P(art)", "Q(left.Rla)"
PASSIVE = {"left.art.passive": True, "right.art.passive": True}
NO_TONE = {"left.art.pCa_shift": "0", "right.art.pCa_shift": "0"}  # fluctuations.yaml's tone noise off (a quantity replaces a waveform)


def record(c, t_end, skip=SKIP):
    """The beat-averaged pressure and flow of a run after its first ``skip`` seconds (the
    start from the operating point of a beating heart)."""
    r = c.simulate(t_end, dt=0.01)
    keep = r.t >= skip
    return uniform_series(r.t[keep], r[P_IN][keep], r[Q_OUT][keep], beats=True, names=(P_IN, Q_OUT),
                          units=("mmHg", "mL/s"))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out-dir", default=OUT)
    args = ap.parse_args(argv)
    out = os.path.join(args.out_dir, "body_autoregulation")
    os.makedirs(out, exist_ok=True)

    # 1. TFA of spontaneous fluctuations, intact and impaired
    rows, spectra = [], {}
    for case, name in (("intact", "fluctuations.yaml"), ("impaired", "fluctuations_impaired.yaml")):
        c = hc.load(os.path.join(BODY, name))
        if QUICK:  # 20 s windows cannot tell the tone's 0.01-0.07 Hz from LF: no tone (tests/test_body.py has it)
            c = c.with_values(NO_TONE)
        res, sp = tfa(record(c, T_RUN), window=WINDOW)
        spectra[case] = sp
        for k, band in enumerate(res["band"]):
            rows.append({"case": case, "band": band, "gain": res["gain"][k], "gain_norm": res["gain_norm"][k],
                         "phase_deg": res["phase"][k], "coherence": res["coherence"][k]})
            print(f"TFA {case:8s} {band:3s}: gain {res['gain'][k]:.3f} mL/s/mmHg ({res['gain_norm'][k]:.2f} %/mmHg), "
                  f"phase {res['phase'][k]:6.1f} deg, coherence {res['coherence'][k]:.2f}")
    _write(os.path.join(out, "tfa.csv"), rows)
    plt = pyplot()
    fig, axes = plt.subplots(3, 1, figsize=(6.4, 7), sharex=True)
    for case, sp in spectra.items():
        f = (sp.f > 0) & (sp.f <= 0.5)
        for ax, v in zip(axes, (sp.gain, sp.phase_deg, sp.coherence)):
            ax.plot(sp.f[f], v[f], "o-", ms=3, label=case)
    for ax, label in zip(axes, ("gain [mL/s/mmHg]", "phase [deg]", "coherence")):
        ax.set_ylabel(label)
        for lo in (0.07, 0.2):
            ax.axvline(lo, color="0.7", lw=0.8)
    axes[0].legend(fontsize=8)
    axes[2].set_xlabel("frequency [Hz]")
    save_figure(fig, os.path.join(out, "tfa.png"))

    # 2. Thigh-cuff release and ARI, intact and impaired
    baseline, duration = CUFF
    ari_rows = []
    fig, ax = plt.subplots(figsize=(6.4, 3.6))
    cuff_net = os.path.join(BODY, "cuff_release.yaml")
    if RELEASE != 60.0:  # a variant of the bundled netlist with the release moved
        cuff_net = os.path.join(out, "cuff_release.yaml")
        with open(cuff_net, "w") as fh:
            fh.write(f"name: cuff_release_at_{RELEASE:g}s\nextends: {os.path.join(BODY, 'cuff_release.yaml')}\n"
                     f"parameters: {{t_release: {RELEASE} s, t_recovered: {RELEASE + 20} s}}\n")
    cuff = hc.load(cuff_net)
    for case, c in (("intact", cuff), ("impaired", cuff.with_options(PASSIVE))):
        s = record(c, RELEASE + duration + 5.0, skip=0.0)
        at = RELEASE
        ari, _, errors, fitted, tf = fit_ari(s.t, s.x, s.y, at, baseline, duration)
        ari_rows.append({"case": case, "ari": ari, "error": float(errors.min())})
        print(f"ARI {case}: {ari:.1f} (fit error {errors.min():.2g})")
        keep = (s.t >= at - baseline) & (s.t <= at + duration)
        ax.plot(s.t[keep] - at, s.y[keep] / np.mean(s.y[(s.t >= at - baseline) & (s.t < at)]), label=f"{case}")
        ax.plot(tf - at, fitted / np.mean(s.y[(s.t >= at - baseline) & (s.t < at)]), "--", lw=0.8,
                label=f"Tiecks ARI {ari:.1f}")
    ax.set_xlabel("time from release [s]")
    ax.set_ylabel("Q(left.Rla) / baseline")
    ax.legend(fontsize=8)
    save_figure(fig, os.path.join(out, "cuff.png"))
    _write(os.path.join(out, "ari.csv"), ari_rows)

    # 3. LF phase against tau_Ca (both hemispheres)
    base = hc.load(os.path.join(BODY, "fluctuations.yaml"))
    tau_rows = []
    for tau in TAUS:
        c = base.with_values({"left.art.tau_Ca": f"{tau} s"})  # the right hemisphere follows (body.yaml)
        res, _ = tfa(record(c, T_RUN), window=WINDOW)
        lf = list(res["band"]).index("LF")
        tau_rows.append({"tau_Ca_s": tau, "lf_phase_deg": res["phase"][lf], "lf_gain": res["gain"][lf]})
        print(f"tau_Ca {tau:5.1f} s: LF phase {res['phase'][lf]:6.1f} deg, gain {res['gain'][lf]:.3f}")
    _write(os.path.join(out, "tau_phase.csv"), tau_rows)
    fig, ax = plt.subplots(figsize=(5, 3.4))
    ax.semilogx([r["tau_Ca_s"] for r in tau_rows], [r["lf_phase_deg"] for r in tau_rows], "o-")
    ax.set_xlabel("art.tau_Ca [s]")
    ax.set_ylabel("LF phase [deg]")
    save_figure(fig, os.path.join(out, "tau_phase.png"))
    print(f"wrote {out}")


def _write(path, rows):
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)


if __name__ == "__main__":
    main()
