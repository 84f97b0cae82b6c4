"""Relative myosin phosphorylation (Mp + AMp) of the 4-state kinetic model against [Ca2+]
for several [cGMP] (thesis figure figrPhospCa, kinetics fitted to Lee et al. 1997; table
tab4State, preset kuo91).

[Ca2+] from 10 nM to 100 uM; [cGMP] from 0.1 nM to 10 uM (one curve per decade, dashed as in the
thesis), plus the two conditions of the Lee97 data: [8Br-cGMP] = 0 (control) and 2 uM.
The Lee97 data points themselves are not in the thesis text and are not drawn.

Writes examples/out/lee97_phosphorylation.csv (Ca, cGMP, Mp + AMp, long format) and
examples/out/lee97_phosphorylation.png.

Run:  python examples/lee97_phosphorylation.py   (a second or two; HEMOCIRCUIT_EXAMPLES_QUICK=1:
41 Ca values; HEMOCIRCUIT_EXAMPLES_OUT=DIR: write to DIR instead of examples/out/)
"""
from __future__ import annotations

import csv
import os
import time

import numpy as np

from hemocircuit.components.arteriole import make_params
from hemocircuit.reproduce.ch4_lee97 import phosphorylation_curves

HERE = os.path.dirname(os.path.abspath(__file__))
QUICK = os.environ.get("HEMOCIRCUIT_EXAMPLES_QUICK", "") not in ("", "0")  # the test suite's smoke run
OUT = os.environ.get("HEMOCIRCUIT_EXAMPLES_OUT") or os.path.join(HERE, "out")

CA = np.logspace(-8, -4, 41 if QUICK else 161)  # 10 nM .. 100 uM
CGMP = np.logspace(-10, -5, 6)         # 0.1 nM .. 10 uM
LEE97 = (0.0, 2e-6)                    # Lee97 conditions: control, 2 uM 8Br-cGMP


def main():
    t0 = time.perf_counter()
    os.makedirs(OUT, exist_ok=True)
    p = make_params("kuo91")
    Ca, cg, phos = phosphorylation_curves(p, CA, CGMP)
    _, cg_lee, phos_lee = phosphorylation_curves(p, CA, np.array(LEE97))

    with open(os.path.join(OUT, "lee97_phosphorylation.csv"), "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["cGMP [M]", "Ca [M]", "Mp+AMp [-]", "curve"])
        for cgs, ph, kind in ((cg, phos, "decade"), (cg_lee, phos_lee, "lee97_condition")):
            for i, c in enumerate(cgs):
                for j, ca in enumerate(Ca):
                    w.writerow([f"{c:.4g}", f"{ca:.6g}", f"{ph[i, j]:.6g}", kind])

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.8))
    colors = plt.cm.viridis(np.linspace(0, 0.9, len(cg)))
    ax.semilogx(Ca, phos_lee[0], "-", color="0.5", lw=3, alpha=0.6, label="[cGMP] = 0 (Lee97 control)")
    ax.semilogx(Ca, phos_lee[1], "-", color="tab:red", lw=3, alpha=0.4, label="[cGMP] = 2 uM (Lee97 8Br-cGMP)")
    for i, c in enumerate(cg):
        ax.semilogx(Ca, phos[i], "--", color=colors[i], lw=1.5, label=f"[cGMP] = {c:.0e} M")
    ax.set_xlabel("[Ca$^{2+}$] (M)")
    ax.set_ylabel("relative phosphorylation Mp + AMp (-)")
    ax.set_xlim(Ca[0], Ca[-1])
    ax.set_ylim(0, 1)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8, loc="upper left")
    ax.set_title("4-state kinetics at steady state, tab4State (cf. figrPhospCa)", fontsize=10)
    fig.tight_layout()
    fig.savefig(os.path.join(OUT, "lee97_phosphorylation.png"), dpi=120)
    plt.close(fig)

    for ca in (1e-8, 1e-7, 1e-6, 1e-5, 1e-4):
        j = int(np.argmin(abs(np.log(Ca / ca))))
        print(f"Ca = {ca:.0e} M: Mp+AMp = " + ", ".join(f"{x:.3f}" for x in phos[:, j])
              + f"  (cGMP {cg[0]:.0e}..{cg[-1]:.0e} M);  control {phos_lee[0, j]:.3f}, 2 uM {phos_lee[1, j]:.3f}")
    print(f"wrote {OUT}/lee97_phosphorylation.csv and .png ({time.perf_counter() - t0:.1f} s)")


if __name__ == "__main__":
    main()
