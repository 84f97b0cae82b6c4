"""Compare the thesis's variants, and a compartment the thesis only discusses, side by side.

Steady states over Pa = 20..200 mmHg for payne06, arterial_compliance, icp, inertia and
two_generations (a passive first arteriolar generation before the active bed, added with
netlist edits only), then the thesis's 10 % step (80 -> 72 mmHg) and the 0.1 Hz sine protocol
on arterial_compliance vs two_generations.  Writes result CSVs and overlay PNGs under
examples/output/compare/.   Run:  python examples/compare_variants.py   (about a minute)
Same as the CLI:
    hemocircuit compare netlists/payne06.yaml netlists/arterial_compliance.yaml ... \
        --sweep Pa.value=20:200:2mmHg --out cmp.csv --plot cmp.png
"""
import os

import hemocircuit as hc
from hemocircuit.analyses.compare import compare_sweep, compare_transient, plot_overlays

HERE = os.path.dirname(os.path.abspath(__file__))
NET = os.path.join(HERE, "..", "netlists")
OUT = os.path.join(HERE, "output", "compare")


def main():
    os.makedirs(OUT, exist_ok=True)
    names = ["payne06", "arterial_compliance", "icp", "inertia", "two_generations"]
    circuits = [hc.load(os.path.join(NET, f"{n}.yaml")) for n in names]
    res = compare_sweep(circuits, "Pa.value", "20:200:2 mmHg")
    res.save(os.path.join(OUT, "steady.csv"))
    files = plot_overlays(os.path.join(OUT, "steady"), res, ["flow", "bed_radius", "V_a", "V_v", "Va_over_Vv", "P_ic"],
                          "Pa [mmHg]")
    i80 = int(abs(res.parts["payne06"][0] - 80).argmin())
    print(f"{'netlist':>22} {'flow':>8} {'radius':>8} {'Va/Vv':>7}   at Pa = 80 mmHg")
    for name, (x, q, units, failed) in res.parts.items():
        print(f"{name:>22} {q['flow'][i80]:8.4f} {q['bed_radius'][i80]:8.3f} {q['Va_over_Vv'][i80]:7.4f}")
    pair = [hc.load(os.path.join(NET, f"{n}.yaml")) for n in ("arterial_compliance", "two_generations")]
    for proto in ("step_80_72", "sine_0p1Hz"):
        tr = compare_transient(pair, os.path.join(HERE, "protocols", f"{proto}.yaml"), dt=0.05)
        tr.save(os.path.join(OUT, f"{proto}.csv"))
        files += plot_overlays(os.path.join(OUT, proto), tr, ["Q(Rla)", "Q(Rsv)", "bed_radius"], "time [s]")
    print("wrote", len(files), "figures to", OUT)


if __name__ == "__main__":
    main()
