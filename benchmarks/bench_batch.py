"""Batch workloads (issue 5): the thesis frequency sweep and the zeta-envelope map.

    python benchmarks/bench_batch.py freq       # 3 cases x 30 frequencies, 0.001-1 Hz
    python benchmarks/bench_batch.py envelope   # 6 zeta x 40 pressures, 1000 s each
    python benchmarks/bench_batch.py envelope --pressures 8   # a smaller map

Prints wall time, runs per second per core and the speed-up over running the same runs one
by one in a loop (each as its own batch of one, in this process).  Results go to
benchmarks/results/*.json.
"""
import argparse
import json
import os
import time

import numpy as np

import hemocircuit as hc
from hemocircuit.analyses.envelope import envelope
from hemocircuit.analyses.freq import frequency_response
from hemocircuit.execution import default_workers

HERE = os.path.dirname(os.path.abspath(__file__))
NET = os.path.join(HERE, "..", "netlists")
OUT = os.path.join(HERE, "results")


def save(name, data):
    os.makedirs(OUT, exist_ok=True)
    with open(os.path.join(OUT, f"{name}.json"), "w") as fh:
        json.dump(data, fh, indent=1, default=str)


def bench_freq(loop_sample=6):
    c = hc.load(os.path.join(NET, "arterial_compliance.yaml"))
    freqs = np.logspace(-3, 0, 30)
    cases = [({"art.tau_Ca": "1 s", "Pa.value": "80 mmHg"}), ({"art.tau_Ca": "10 s", "Pa.value": "80 mmHg"}),
             ({"art.tau_Ca": "1 s", "Pa.value": "30 mmHg"})]
    workers = default_workers()
    t0 = time.perf_counter()
    unsettled = errors = 0
    for case in cases:
        res = frequency_response(c.with_values(case), freqs, workers=workers)
        unsettled += int(np.sum(~np.asarray(res["settled"], dtype=bool)))
        errors += int(np.sum(np.asarray(res["error"]) != ""))
    wall = time.perf_counter() - t0
    n = len(cases) * len(freqs)
    # one by one: a sample of the same runs, each alone (batch of one), extrapolated
    sample = freqs[:: max(1, len(freqs) // loop_sample)]
    t1 = time.perf_counter()
    for f in sample:
        for case in cases:
            cc = c.with_values(case)
            frequency_response(cc, [f], scheduler="serial")
    loop = (time.perf_counter() - t1) / (len(sample) * len(cases)) * n
    res = {"runs": n, "wall_s": wall, "workers": workers, "runs_per_s_per_core": n / wall / workers,
           "one_by_one_estimate_s": loop, "speedup": loop / wall,
           "unsettled": unsettled, "errors": errors}
    print(json.dumps(res, indent=1))
    save("freq_sweep", res)


def bench_envelope(n_pressures=40, t_end=1000.0, rtol=1e-6):
    c = hc.load(os.path.join(NET, "vasomotion.yaml"))
    pressures = np.linspace(20, 200, n_pressures)
    zetas = [0.0, 0.05, 0.1, 0.15, 0.2, 0.3]
    workers = default_workers()
    t0 = time.perf_counter()
    env = envelope(c, ("Pa.value", list(pressures)), [("art.zeta", zetas)], outputs=["art.r", "Q(Rla)"],
                   t_end=t_end, workers=workers, rtol=rtol)
    wall = time.perf_counter() - t0
    n = env.n_rows
    near80 = (np.abs(env["Pa.value"] - 80.0) < 3) & (env["art.zeta"] == 0.1)
    res = {"rtol": rtol, "r_range_Pa80_zeta0.1": [(lo, hi) for lo, hi in zip(env["min(art.r)"][near80],
                                                                           env["max(art.r)"][near80])],
           "runs": n, "t_end_s": t_end, "wall_s": wall, "workers": workers, "runs_per_s_per_core": n / wall / workers,
           "oscillating": int(np.sum(env["oscillating"])),
           "errors": int(np.sum(np.asarray(env["error"]) != ""))}
    # one by one: a few members alone
    t1 = time.perf_counter()
    picks = [(80.0, 0.1), (120.0, 0.0), (40.0, 0.3)]
    for pa, z in picks:
        envelope(c, ("Pa.value", [pa]), [("art.zeta", [z])], t_end=t_end, scheduler="serial", rtol=rtol)
    res["one_by_one_sample_s_per_run"] = (time.perf_counter() - t1) / len(picks)
    res["one_by_one_estimate_s"] = res["one_by_one_sample_s_per_run"] * n
    res["speedup"] = res["one_by_one_estimate_s"] / wall
    print(json.dumps(res, indent=1))
    save(f"envelope_{len(zetas)}x{n_pressures}_rtol{rtol:g}", res)


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("which", choices=["freq", "envelope"])
    ap.add_argument("--pressures", type=int, default=40)
    ap.add_argument("--t-end", type=float, default=1000.0)
    ap.add_argument("--rtol", type=float, default=1e-5)
    a = ap.parse_args()
    if a.which == "freq":
        bench_freq()
    else:
        bench_envelope(a.pressures, a.t_end, a.rtol)
