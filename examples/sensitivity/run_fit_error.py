"""The thesis's sensitivity case (chapter 4, "Sensitivity Analysis"): the rms error of the
17-parameter Kuo91 fit (kuo91_fit17.yaml, generated data with 1 um noise) analysed with the
constellation method in the three schemes of the thesis, with SALib's Morris and Sobol on the
+/-10 % space and with local derivatives at the centre.  Writes, per analysis, a CSV, a PNG
(not for local) and a log (runs, failures, wall and CPU time, the full ranking) into results/
(the results committed with the example) or --out DIR, and prints a table row per analysis
with its top five.

    python examples/sensitivity/run_fit_error.py [--n 1000] [--n-wide 300] [--n-sobol 512] [--workers 2]
                                                 [--only NAME ...] [--out DIR]

The full run takes about 15 minutes of wall time on a 2-core machine (the costs measured are in
docs/sensitivity.md).  HEMOCIRCUIT_EXAMPLES_QUICK=1 (the test suite's smoke run): n = n-wide = 2,
n-sobol = 4 (10 Morris trajectories, the least) by default, writing HEMOCIRCUIT_EXAMPLES_OUT/sensitivity
(default examples/out/sensitivity) so the committed results stay as they are.
"""
from __future__ import annotations

import argparse
import os
import resource
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))
NETLIST = os.path.join(ROOT, "netlists", "isolated_arteriole.yaml")
SPEC = os.path.join(HERE, "kuo91_fit_error.yaml")
RESULTS = os.path.join(HERE, "results")
QUICK = os.environ.get("HEMOCIRCUIT_EXAMPLES_QUICK", "") not in ("", "0")  # the test suite's smoke run
OUT = os.path.join(os.environ.get("HEMOCIRCUIT_EXAMPLES_OUT") or os.path.join(os.path.dirname(HERE), "out"),
                   "sensitivity") if QUICK else RESULTS


def analyses(n, n_wide, n_sobol=512):
    """name -> spec overrides.  The constellation runs have n (k + 1) = 18 n model runs; the
    +/-50 % and additive spaces (where many sets have no operating point) use n_wide points."""
    return {
        "mult10": {"name": "constellation", "scheme": "multiplicative", "range": 10, "n": n},
        "mult50": {"name": "constellation", "scheme": "multiplicative", "range": 50, "n": n_wide},
        "additive": {"name": "constellation", "scheme": "additive", "n": n_wide},
        "morris10": {"name": "morris", "scheme": "multiplicative", "range": 10, "trajectories": max(n // 10, 10)},
        "sobol10": {"name": "sobol", "scheme": "multiplicative", "range": 10, "n": n_sobol},
        "local": {"name": "local"},
    }


def cpu_seconds():
    own = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def main():
    from hemocircuit.analyses.sensitivity import sensitivity, write_outputs
    from hemocircuit.circuit import load

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=2 if QUICK else 1000,
                    help="constellation points at +/-10 %% (default 1000)")
    ap.add_argument("--n-wide", type=int, default=2 if QUICK else 300,
                    help="constellation points at +/-50 %% and additive (default 300)")
    ap.add_argument("--n-sobol", type=int, default=4 if QUICK else 512, help="Sobol base samples (default 512)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--only", nargs="*", help="run only these analyses (mult10 mult50 additive morris10 sobol10 local)")
    ap.add_argument("--out", default=OUT, help="folder for the CSVs, PNGs and logs (default: results/, the committed "
                    "results; with HEMOCIRCUIT_EXAMPLES_QUICK=1 examples/out/sensitivity)")
    a = ap.parse_args()
    out = a.out
    os.makedirs(out, exist_ok=True)
    c = load(NETLIST)
    lines = []
    for name, over in analyses(a.n, a.n_wide, a.n_sobol).items():
        if a.only and name not in a.only:
            continue
        t0, c0 = time.perf_counter(), cpu_seconds()
        res = sensitivity(c, SPEC, NETLIST, workers=a.workers, progress=False, overrides=over)
        wall, cpu = time.perf_counter() - t0, cpu_seconds() - c0
        write_outputs(res, os.path.join(out, f"fit_error_{name}.csv"),
                      None if name == "local" else os.path.join(out, f"fit_error_{name}.png"))
        key = res.extra.get("rank_key", "mu_star") if name != "local" else "normalised"
        vals = res.values(key)
        rank = sorted(vals, key=lambda p: -abs(vals[p]) if vals[p] == vals[p] else 1.0)
        top = ", ".join(f"{p.split('.')[-1]} {vals[p]:.3g}" for p in rank[:5])
        line = (f"| {name} | {res.n_runs} | {len(res.failures)} | {wall:.0f} s | {cpu:.0f} s | {key}: {top} |")
        print(line, flush=True)
        lines.append(line)
        with open(os.path.join(out, f"fit_error_{name}.log"), "w") as fh:
            fh.write(f"{res.method} {res.space.scheme}: {res.n_runs} runs, {len(res.failures)} failed, "
                     f"{wall:.1f} s wall, {cpu:.1f} s CPU on {a.workers} workers\n")
            fh.write(f"ranking by {key}: " + ", ".join(f"{p} {vals[p]:.4g}" for p in rank) + "\n")
            for desc, reason in res.failures[:10]:
                fh.write(f"failed: {desc}: {reason[:160]}\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
