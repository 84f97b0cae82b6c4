"""Single-run transients: 1000 s of the passive Payne06 circuit, the Kuo91 protocol A on the
isolated arteriole, and 1000 s of the full 8-state vasomotion model (limit cycle).

    python benchmarks/bench_transient.py
"""
import os
import time

import numpy as np

import hemocircuit as hc
from hemocircuit.batch_integrator import integrate

HERE = os.path.dirname(__file__)
NET = os.path.join(HERE, "..", "netlists")


def main():
    c = hc.load(os.path.join(NET, "payne06_passive.yaml"))
    c = c.with_values({"Pa.amplitude": "8 mmHg", "Pa.frequency": "0.1 Hz"})
    t0 = time.perf_counter()
    r = c.simulate(1000.0, dt=0.1)
    print(f"payne06_passive, 1000 s, 0.1 Hz sine, BDF: {time.perf_counter() - t0:.3f} s  {r.stats}")

    c = hc.load(os.path.join(NET, "isolated_arteriole.yaml"))
    t0 = time.perf_counter()
    r = c.simulate(None, dt=1.0, protocol=os.path.join(HERE, "..", "examples", "protocols", "kuo91_A.yaml"))
    print(f"isolated arteriole, Kuo91 protocol A (450 s), BDF: {time.perf_counter() - t0:.3f} s  {r.stats}")
    c = hc.load(os.path.join(NET, "isolated_arteriole.yaml"))
    c = c.with_values({"Pup.amplitude": "5 cmH2O", "Pup.frequency": "0.05 Hz"})
    t0 = time.perf_counter()
    r = c.simulate(1000.0, dt=1.0)
    print(f"isolated arteriole, 1000 s with a 0.05 Hz sine, BDF: {time.perf_counter() - t0:.3f} s  {r.stats}")

    c = hc.load(os.path.join(NET, "vasomotion.yaml"))
    op = c.operating_point()
    x0 = op.x.copy()
    x0[3:7] *= 1.001  # kick the arteriole's states off the unstable equilibrium
    for method in ("LSODA", "BDF"):
        t0 = time.perf_counter()
        r = c.simulate(1000.0, dt=0.1, x0=x0, method=method, rtol=1e-6, atol=1e-6)
        rr = r["art.r"][-3000:]
        print(f"vasomotion, 1000 s, {method} rtol 1e-6: {time.perf_counter() - t0:.1f} s  "
              f"r {rr.min():.2f}..{rr.max():.2f} um  {r.stats}")
    t0 = time.perf_counter()
    b = integrate(c, x0[None], np.arange(0, 1000.01, 0.1), rtol=1e-6, atol=1e-6)
    print(f"vasomotion, 1000 s, batch integrator (B=1) rtol 1e-6: {time.perf_counter() - t0:.1f} s  {b.stats}")


if __name__ == "__main__":
    main()
