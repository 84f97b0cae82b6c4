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


def timed(label, run):
    """run() once untimed (a first call loads or compiles the engine), then timed; prints the
    wall time and the integrator the result reports."""
    run()
    t0 = time.perf_counter()
    r = run()
    wall = time.perf_counter() - t0
    stats = getattr(r, "stats", {})
    print(f"{label}: {wall:.3f} s  {stats.get('method', '')}  {stats}")
    return r


def main():
    c = hc.load(os.path.join(NET, "payne06_passive.yaml"))
    c = c.with_values({"Pa.amplitude": "8 mmHg", "Pa.frequency": "0.1 Hz"})
    timed("payne06_passive, 1000 s, 0.1 Hz sine", lambda: c.simulate(1000.0, dt=0.1))

    c = hc.load(os.path.join(NET, "isolated_arteriole.yaml"))
    protocol = os.path.join(HERE, "..", "examples", "protocols", "kuo91_A.yaml")
    timed("isolated arteriole, Kuo91 protocol A (450 s)", lambda: c.simulate(None, dt=1.0, protocol=protocol))
    c2 = c.with_values({"Pup.amplitude": "5 cmH2O", "Pup.frequency": "0.05 Hz"})
    timed("isolated arteriole, 1000 s with a 0.05 Hz sine", lambda: c2.simulate(1000.0, dt=1.0))

    c = hc.load(os.path.join(NET, "vasomotion.yaml"))
    op = c.operating_point()
    x0 = op.x.copy()
    x0[3:7] *= 1.001  # kick the arteriole's states off the unstable equilibrium
    for integrator in ("rodas5p", "bdf", "lsoda"):
        r = timed(f"vasomotion, 1000 s, {integrator} rtol 1e-6",
                  lambda: c.simulate(1000.0, dt=0.1, x0=x0, integrator=integrator, rtol=1e-6, atol=1e-6))
        rr = r["art.r"][-3000:]
        print(f"    r over the last 300 s: {rr.min():.2f}..{rr.max():.2f} um")
    t = np.arange(0, 1000.01, 0.1)
    timed("vasomotion, 1000 s, batch integrator (B=1, compiled engine) rtol 1e-6",
          lambda: integrate(c, x0[None], t, rtol=1e-6, atol=1e-6))
    timed("vasomotion, 100 s, batch integrator (B=1, engine='numpy': ROS34PW2 in numpy) rtol 1e-6",
          lambda: integrate(c, x0[None], t[:1001], rtol=1e-6, atol=1e-6, engine="numpy"))


if __name__ == "__main__":
    main()
