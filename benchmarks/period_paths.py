"""Every integration path on the same limit cycle: vasomotion's period from each integrator.

    python benchmarks/period_paths.py                        # rodas5p, bdf, scipy-bdf at rtol 1e-8
    python benchmarks/period_paths.py --rtol 1e-10 scipy-radau lsoda

The run of issue "One definition of the physics": netlists/vasomotion.yaml for 1000 s, kicked
off its unstable equilibrium by a protocol (Pa.value 88 mmHg at 0.5 s, back to 80 mmHg at
1.5 s).  The period is the mean spacing of the upward crossings of art.lambda's mean over
500-1000 s, each crossing interpolated linearly on a 0.01 s output grid (first to last
crossing over the number of cycles: the interpolation error of the two ends, ~1e-6 s, is
divided by ~64 cycles).  The compiled integrators take a few seconds; scipy's solve_ivp
evaluates the right-hand side from Python (BDF ~2 min at rtol 1e-8, Radau ~5 min).
"""
from __future__ import annotations

import argparse
import os
import tempfile
import time

import numpy as np

import hemocircuit as hc
from hemocircuit.analyses.transient import simulate

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
KICK = "events:\n  - {at: 0.5 s, set: {Pa.value: 88 mmHg}}\n  - {at: 1.5 s, set: {Pa.value: 80 mmHg}}\n"


def period(t, y):
    """Mean spacing [s] of the upward crossings of y's mean (linear interpolation)."""
    z = y - y.mean()
    up = np.nonzero((z[:-1] < 0) & (z[1:] >= 0))[0]
    tc = t[up] - z[up] * (t[up + 1] - t[up]) / (z[up + 1] - z[up])
    return (tc[-1] - tc[0]) / (tc.size - 1), tc.size - 1


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("integrators", nargs="*", default=["rodas5p", "bdf", "scipy-bdf"])
    ap.add_argument("--rtol", type=float, default=1e-8)
    args = ap.parse_args(argv)
    c = hc.load(os.path.join(ROOT, "netlists", "vasomotion.yaml"))
    i = c.state_names.index("art.lambda")
    periods = {}
    with tempfile.TemporaryDirectory() as d:
        protocol = os.path.join(d, "kick.yaml")
        with open(protocol, "w") as fh:
            fh.write(KICK)
        for name in args.integrators:
            t0 = time.perf_counter()
            r = simulate(c, 1000.0, dt=0.01, protocol=protocol, integrator=name, rtol=args.rtol, progress=False)
            w = r.t >= 500.0
            periods[name], n = period(r.t[w], r.x[w, i])
            print(f"{name:12s} rtol {args.rtol:g}: period {periods[name]:.9f} s over {n} cycles "
                  f"({time.perf_counter() - t0:.1f} s)", flush=True)
    p = np.array(list(periods.values()))
    print(f"largest relative difference between paths: {np.ptp(p) / p.mean():.1e}")


if __name__ == "__main__":
    main()
