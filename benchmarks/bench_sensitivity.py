"""Cost of sensitivity analyses (issue 11 acceptance, 2 cores):

* op throughput: a constellation on an op-based stand-in for the thesis's 17-parameter fit
  error (tabBounds parameters, +/-10 % around kuo91; the radius at the Kuo91 pressures
  20..140 cmH2O step 20, with and without flow (dP = 4 cmH2O): 14 operating points per
  parameter set, as the fit error evaluates them), extrapolated to the 1000-point
  constellation's 18,000 parameter sets;
* the dynamic analysis on Kuo91 A (examples/sensitivity/kuo91_A_dynamic.yaml): 100 x 6 runs.

    python benchmarks/bench_sensitivity.py [--n 10] [--workers 2] [--skip-dynamic]
"""
from __future__ import annotations

import argparse
import os
import time

from hemocircuit.circuit import load
from hemocircuit.sensitivity import load_spec, parse_spec, run
from hemocircuit.sensitivity.outputs import make_objective

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
NETLIST = os.path.join(ROOT, "netlists", "isolated_arteriole.yaml")
TAB_BOUNDS = ["h_w", "s_w", "gamma_wb", "r_db", "r_dw", "k_tau", "NO_L", "NO_U", "pcGMP_L", "pcGMP_U",
              "sigma_L", "sigma_U", "pCa_L", "pCa_U", "f1", "lambda_opt", "eta"]


def kuo91_settings():
    at = []
    for dP in (0.0, 4.0):
        for P in range(20, 141, 20):
            at.append({"Pup.value": f"{P + dP / 2:g} cmH2O", "Pdown.value": f"{P - dP / 2:g} cmH2O"})
    return at


def bench_op(n, workers):
    c = load(NETLIST)
    spec = parse_spec({"method": {"name": "constellation", "scheme": "multiplicative", "range": 10, "n": n},
                       "parameters": [f"art.{p}" for p in TAB_BOUNDS],
                       "output": {"op": {"column": "art.r", "at": kuo91_settings()}}})
    obj = make_objective(spec, c)
    t0 = time.perf_counter()
    res = run(spec, obj, workers=workers, progress=True)
    dt = time.perf_counter() - t0
    sets = res.n_runs
    print(f"op stand-in for the fit error: {sets} parameter sets x 14 operating points in {dt:.1f} s "
          f"({dt / sets * 1e3:.1f} ms per set, {dt / sets / 14 * 1e3:.2f} ms per operating point), "
          f"{len(res.failures)} failed; 18,000 sets would take {dt / sets * 18000 / 60:.1f} min on {workers} workers")
    print("  top 5 of the first output:", res.ranking(0)[:5])


def bench_dynamic(workers, n=None):
    c = load(NETLIST)
    spec = load_spec(os.path.join(ROOT, "examples", "sensitivity", "kuo91_A_dynamic.yaml"),
                     {"n": n} if n else None)
    obj = make_objective(spec, c, NETLIST)
    t0 = time.perf_counter()
    res = run(spec, obj, workers=workers, progress=True)
    dt = time.perf_counter() - t0
    print(f"dynamic Kuo91 A: {res.n_runs} transients ({len(obj.times)} output times) in {dt:.1f} s "
          f"on {workers} workers, {len(res.failures)} failed")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=10, help="constellation points for the op benchmark (n x 18 sets)")
    ap.add_argument("--dynamic-n", type=int, default=None, help="points of the dynamic analysis (default: 100)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--skip-dynamic", action="store_true")
    ap.add_argument("--skip-op", action="store_true")
    a = ap.parse_args()
    if not a.skip_op:
        bench_op(a.n, a.workers)
    if not a.skip_dynamic:
        bench_dynamic(a.workers, a.dynamic_n)


if __name__ == "__main__":
    main()
