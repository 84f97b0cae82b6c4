"""Cost of sensitivity analyses (issue 11 acceptance, 2 cores):

* a constellation on the thesis's 17-parameter fit error (examples/sensitivity/
  kuo91_fit_error.yaml: tabBounds parameters, +/-10 % around kuo91, the rms between the model
  radius and the generated Kuo91 data with and without flow: 26 operating points per
  parameter set); the acceptance case is n = 1000 points, 18,000 parameter sets;
* the dynamic analysis on Kuo91 A (examples/sensitivity/kuo91_A_dynamic.yaml): 100 x 6 runs.

Wall time and CPU time (this process and its workers) are printed: the machine may be
shared, so the CPU time is the better measure of the work done.

    python benchmarks/bench_sensitivity.py [--n 1000] [--workers 2] [--skip-dynamic] [--skip-fit]
"""
from __future__ import annotations

import argparse
import os
import resource
import time

from hemocircuit.circuit import load
from hemocircuit.sensitivity import load_spec, run
from hemocircuit.sensitivity.outputs import make_objective

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
NETLIST = os.path.join(ROOT, "netlists", "isolated_arteriole.yaml")
EXAMPLES = os.path.join(ROOT, "examples", "sensitivity")


def cpu_seconds():
    own, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def timed(spec, workers):
    obj = make_objective(spec, load(NETLIST), NETLIST)
    t0, c0 = time.perf_counter(), cpu_seconds()
    res = run(spec, obj, workers=workers, progress=True)
    return res, obj, time.perf_counter() - t0, cpu_seconds() - c0


def bench_fit(n, workers):
    spec = load_spec(os.path.join(EXAMPLES, "kuo91_fit_error.yaml"), {"n": n})
    res, _, wall, cpu = timed(spec, workers)
    print(f"fit error (17 parameters, +/-10 %): {res.n_runs} parameter sets x 26 operating points in "
          f"{wall:.1f} s wall, {cpu:.1f} s CPU on {workers} workers ({wall / res.n_runs * 1e3:.2f} ms wall per set), "
          f"{len(res.failures)} failed")
    print("  top 5:", res.ranking(0)[:5])


def bench_dynamic(workers, n=None):
    spec = load_spec(os.path.join(EXAMPLES, "kuo91_A_dynamic.yaml"), {"n": n} if n else None)
    res, obj, wall, cpu = timed(spec, workers)
    print(f"dynamic Kuo91 A: {res.n_runs} transients ({len(obj.times)} output times) in {wall:.1f} s wall, "
          f"{cpu:.1f} s CPU on {workers} workers, {len(res.failures)} failed")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1000, help="constellation points on the fit error (n x 18 sets)")
    ap.add_argument("--dynamic-n", type=int, default=None, help="points of the dynamic analysis (default: 100)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--skip-dynamic", action="store_true")
    ap.add_argument("--skip-fit", action="store_true")
    a = ap.parse_args()
    print(f"load average at start: {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    if not a.skip_fit:
        bench_fit(a.n, a.workers)
    if not a.skip_dynamic:
        bench_dynamic(a.workers, a.dynamic_n)
    print(f"load average at end: {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
