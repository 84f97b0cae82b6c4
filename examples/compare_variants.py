"""Compare the thesis's variants, and a compartment the thesis only discusses, side by side.

Steady states over Pa = 20..200 mmHg for payne06, arterial_compliance, icp, inertia and
two_generations (a passive first arteriolar generation before the active bed, added with
netlist edits only), then the thesis's 10 % step (80 -> 72 mmHg) and the 0.1 Hz sine protocol
on arterial_compliance vs two_generations.

Writes to examples/out/compare/:
  steady.csv, steady.png                 the sweep (a row per netlist and Pa; a panel per unit)
  step_80_72.csv, step_80_72.png         the step protocol (protocols/step_80_72.yaml)
  sine_0p1Hz.csv, sine_0p1Hz.png         the sine protocol (protocols/sine_0p1Hz.yaml)
Each CSV reloads with hemocircuit.Result.load; each PNG is the result's own plot
(``res.plot(path, select=[...])``: a line per netlist, a panel per unit).

Run:  python examples/compare_variants.py   (about 15 s once its engines are compiled; HEMOCIRCUIT_EXAMPLES_QUICK=1: a
coarser sweep and 40 s transients, a few seconds; HEMOCIRCUIT_EXAMPLES_OUT=DIR: write DIR/compare/)
Same as the CLI:
    hemocircuit compare netlists/payne06.yaml netlists/arterial_compliance.yaml ... \
        --sweep Pa.value=20:200:2mmHg --out cmp.csv --plot cmp.png
"""
import os

import numpy as np

import hemocircuit as hc
from hemocircuit.analyses.compare import compare_sweep, compare_transient
from hemocircuit.protocol import Protocol

HERE = os.path.dirname(os.path.abspath(__file__))
NET = os.path.join(HERE, "..", "netlists")
QUICK = os.environ.get("HEMOCIRCUIT_EXAMPLES_QUICK", "") not in ("", "0")  # the test suite's smoke run
OUT = os.path.join(os.environ.get("HEMOCIRCUIT_EXAMPLES_OUT") or os.path.join(HERE, "out"), "compare")

NAMES = ["payne06", "arterial_compliance", "icp", "inertia", "two_generations"]
SWEEP = "20:200:20 mmHg" if QUICK else "20:200:2 mmHg"
T_END = 40.0 if QUICK else None          # None: the protocol's own t_end (120 s)
DT = 0.25 if QUICK else 0.05
STEADY = ["flow", "bed_radius", "V_a", "V_v", "Va_over_Vv", "P_ic"]
TRANSIENT = ["Q(Rla)", "Q(Rsv)", "bed_radius"]


def main():
    os.makedirs(OUT, exist_ok=True)
    circuits = [hc.load(os.path.join(NET, f"{n}.yaml")) for n in NAMES]
    res = compare_sweep(circuits, "Pa.value", SWEEP)
    res.save(os.path.join(OUT, "steady.csv"))
    files = [os.path.join(OUT, "steady.png")]
    res.plot(files[0], select=STEADY)
    print(f"{'netlist':>22} {'flow':>8} {'radius':>8} {'Va/Vv':>7}   at Pa = 80 mmHg")
    for name in dict.fromkeys(res["netlist"]):
        sel = res["netlist"] == name
        i80 = int(np.argmin(np.abs(res["Pa.value"][sel] - 80.0)))
        print(f"{name:>22} {res['flow'][sel][i80]:8.4f} {res['bed_radius'][sel][i80]:8.3f} "
              f"{res['Va_over_Vv'][sel][i80]:7.4f}")
    pair = [hc.load(os.path.join(NET, f"{n}.yaml")) for n in ("arterial_compliance", "two_generations")]
    for proto in ("step_80_72", "sine_0p1Hz"):
        protocol = Protocol.load(os.path.join(HERE, "protocols", f"{proto}.yaml"), pair[0])
        tr = compare_transient(pair, protocol, t_end=T_END, dt=DT)
        tr.save(os.path.join(OUT, f"{proto}.csv"))
        png = os.path.join(OUT, f"{proto}.png")
        tr.plot(png, select=TRANSIENT)
        files.append(png)
    print("wrote", len(files), "figures and their CSVs to", OUT)


if __name__ == "__main__":
    main()
