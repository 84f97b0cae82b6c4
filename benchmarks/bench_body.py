"""The whole-body model (netlists/body/body.yaml): 10 minutes of beating circulation with
autoregulating arterioles, as a user runs it, and the valve-release landing of the compiled
integrator switched on and off on the same run.

    python benchmarks/bench_body.py [--t-end 600] [--repeat 3] [--rtol 1e-6]

``simulate``: wall seconds of ``c.simulate(t_end, dt=0.01)`` (integration and outputs; the engine
compiled and cached by a warm-up run).  ``engine, landing on/off``: wall seconds of the compiled
integration alone (CompiledSystem.integrate on the same 0.01 s grid from the same start), with
``land_releases`` 1 (the default) and 0, the two alternated; their steps and rejected steps; and
the largest difference of the two runs' states at the output times, relative to each state's
range.  Medians of ``--repeat`` runs."""
from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
MODEL = os.path.join(ROOT, "netlists", "body", "body.yaml")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--t-end", type=float, default=600.0, help="simulated seconds (default 600)")
    ap.add_argument("--repeat", type=int, default=3, help="runs of each, medians reported (default 3)")
    ap.add_argument("--rtol", type=float, default=1e-6, help="relative tolerance (default 1e-6, the default)")
    args = ap.parse_args(argv)

    import hemocircuit as hc
    from hemocircuit.kernels.system import CompiledSystem

    c = hc.load(MODEL)
    c.simulate(2, dt=0.01, rtol=args.rtol)  # compile (or load) the engine
    walls = []
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        r = c.simulate(args.t_end, dt=0.01, rtol=args.rtol)
        walls.append(time.perf_counter() - t0)
    print(f"simulate {args.t_end:g} s: {np.median(walls):.2f} s wall (median of {args.repeat}: "
          f"{', '.join(f'{w:.2f}' for w in walls)}); steps {r.stats['steps']}, rejected {r.stats['rejected']}")

    cs = CompiledSystem.of(c)
    P = cs.params(c)[0]
    x0 = np.asarray(c.operating_point().x, float)
    t = np.arange(0.0, args.t_end + 1e-9, 0.01)
    breaks, kinks = c.jumps_and_kinks(t[0], t[-1])
    times, stats, X = {1: [], 0: []}, {}, {}
    for _ in range(args.repeat):
        for land in (1, 0):
            t0 = time.perf_counter()
            X[land], stats[land] = cs.integrate(t, x0, P, rtol=args.rtol, breaks=breaks, kinks=kinks,
                                                land_releases=land)
            times[land].append(time.perf_counter() - t0)
    scale = np.maximum(np.ptp(X[0], axis=0), cs.scales)
    for land in (1, 0):
        st = stats[land]
        print(f"engine, landing {'on ' if land else 'off'}: {np.median(times[land]):.2f} s "
              f"({', '.join(f'{w:.2f}' for w in times[land])}); steps {st['steps']}, rejected {st['rejected']}, "
              f"f evaluations {st['nfev']}, limit events {st['limit_events']}")
    print(f"on/off time ratio {np.median(times[1]) / np.median(times[0]):.2f}; largest state difference "
          f"{np.max(np.abs(X[1] - X[0]) / scale):.2e} of its range")


if __name__ == "__main__":
    main()
