"""Scaling of the operating point and a 100 s transient with circuit size: ladders of N
resistor + log-compliance segments (benchmarks/ladder.py) driven by an 80 +- 10 mmHg, 1 Hz sine.

    python benchmarks/bench_ladder.py                  # sizes 300 .. 3000 elements
    python benchmarks/bench_ladder.py --segments 150 1500 --repeat 2

Every (size, analysis) runs in a fresh process, as the command line would (``hemocircuit op``,
``hemocircuit tran``): import, load, then the analysis with default settings (op; simulate
100 s, BDF at rtol 1e-6 with the solver's own output steps).  Reported per run: wall and CPU
time of each phase, the whole process's wall time, and its peak resident memory (ru_maxrss, as
/usr/bin/time -v reports it).  The growth exponent is the least-squares slope of log(time)
against log(elements) over the sizes (analysis time alone, and whole process).  Results go to
benchmarks/results/ladder.json.  The machine may be shared: CPU times are the steadier figure.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.join(HERE, "results", "ladder.json")
T_END = 100.0


def child(analysis: str, N: int, netlist: str) -> dict:
    """One measured run in this (fresh) process."""
    import resource

    def now():
        return time.perf_counter(), time.process_time()

    t0 = now()
    import hemocircuit as hc
    t1 = now()
    c = hc.load(netlist)
    t2 = now()
    info = {}
    if analysis == "op":
        op = c.operating_point()
        info = {"method": op.method, "residual": op.residual}
    else:
        r = c.simulate(T_END)
        info = {"points": int(len(r.t)), **{k: (v if isinstance(v, (int, float, str)) else str(v))
                                             for k, v in r.stats.items()}}
    t3 = now()
    return {"analysis": analysis, "segments": N, "elements": len(c.elements), "unknowns": c.n, "states": c.nx,
            "sparse": bool(getattr(c, "sparse", False)),
            "import_s": t1[0] - t0[0], "load_s": t2[0] - t1[0], "analysis_s": t3[0] - t2[0],
            "analysis_cpu_s": t3[1] - t2[1], "load_cpu_s": t2[1] - t1[1],
            "peak_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0, **info}


def run_one(analysis: str, N: int, tmp: str) -> dict:
    sys.path.insert(0, HERE)
    from ladder import write_ladder

    path = write_ladder(os.path.join(tmp, f"ladder_{N}.yaml"), N)
    t0 = time.perf_counter()
    p = subprocess.run([sys.executable, os.path.abspath(__file__), "--child", analysis, str(N), path],
                       capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if p.returncode != 0:
        return {"analysis": analysis, "segments": N, "error": p.stderr.strip().splitlines()[-1:]}
    res = json.loads(p.stdout.strip().splitlines()[-1])
    res["process_s"] = wall
    return res


def slope(xs, ys):
    import numpy as np

    xs, ys = np.log(np.asarray(xs, float)), np.log(np.asarray(ys, float))
    return float(np.polyfit(xs, ys, 1)[0])


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--child", nargs=3, metavar=("ANALYSIS", "N", "NETLIST"), help=argparse.SUPPRESS)
    ap.add_argument("--segments", type=int, nargs="+", default=[150, 300, 500, 1000, 1500])
    ap.add_argument("--analyses", nargs="+", default=["op", "tran"])
    ap.add_argument("--repeat", type=int, default=1, help="runs per point (the fastest is kept)")
    ap.add_argument("--out", default=OUT)
    a = ap.parse_args()
    if a.child:
        print(json.dumps(child(a.child[0], int(a.child[1]), a.child[2])))
        return
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for N in a.segments:
            for analysis in a.analyses:
                runs = [run_one(analysis, N, tmp) for _ in range(a.repeat)]
                ok = [r for r in runs if "error" not in r]
                best = min(ok, key=lambda r: r["analysis_s"]) if ok else runs[0]
                rows.append(best)
                if "error" in best:
                    print(f"{analysis:>4} N={N}: FAILED {best['error']}", flush=True)
                    continue
                print(f"{analysis:>4} {best['elements']:>5} elements ({best['unknowns']} unknowns, "
                      f"{best['states']} states): analysis {best['analysis_s']:7.2f} s wall "
                      f"({best['analysis_cpu_s']:.2f} s CPU), process {best['process_s']:6.2f} s, "
                      f"peak {best['peak_rss_mib']:6.0f} MiB", flush=True)
    summary = {}
    for analysis in a.analyses:
        ok = [r for r in rows if r["analysis"] == analysis and "error" not in r]
        if len(ok) >= 2:
            el = [r["elements"] for r in ok]
            summary[analysis] = {
                "exponent_analysis_wall": slope(el, [r["analysis_s"] for r in ok]),
                "exponent_analysis_cpu": slope(el, [r["analysis_cpu_s"] for r in ok]),
                "exponent_process_wall": slope(el, [r["process_s"] for r in ok]),
                "max_process_s": max(r["process_s"] for r in ok),
                "max_peak_rss_mib": max(r["peak_rss_mib"] for r in ok),
            }
            s = summary[analysis]
            print(f"{analysis}: time ~ elements^{s['exponent_analysis_wall']:.2f} (analysis wall), "
                  f"^{s['exponent_analysis_cpu']:.2f} (CPU), ^{s['exponent_process_wall']:.2f} (whole process)")
    os.makedirs(os.path.dirname(a.out), exist_ok=True)
    with open(a.out, "w") as f:
        json.dump({"machine": os.uname().machine, "cpus": os.cpu_count(), "t_end_s": T_END,
                   "load_average": os.getloadavg(), "runs": rows, "summary": summary}, f, indent=1)
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
