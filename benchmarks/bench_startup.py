"""Start-up and first-compile time of the command line (issue 8), whole processes.

    python benchmarks/bench_startup.py                 # all three rows, 5 runs each (median)
    python benchmarks/bench_startup.py --runs 3 --only first-tran

Rows:
  help        ``hemocircuit --help``
  warm-op     ``hemocircuit op netlists/payne06.yaml`` with the caches already filled
  first-tran  ``hemocircuit tran netlists/vasomotion.yaml --t-end 10`` with empty
              ``HEMOCIRCUIT_CACHE_DIR`` and ``NUMBA_CACHE_DIR`` (new folders for every run):
              the first run after install, compilation of vasomotion's engine included

Each run is a child process; wall time from a monotonic clock, CPU time (user + system) from
the operating system's accounting of the child (``resource.getrusage(RUSAGE_CHILDREN)``), so
CPU figures stay meaningful on a busy machine.  Medians are printed.
"""
from __future__ import annotations

import argparse
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
NET = os.path.join(ROOT, "netlists")
CLI = [sys.executable, "-m", "hemocircuit.cli"]
ROWS = {
    "help": (["--help"], False),
    "warm-op": (["op", os.path.join(NET, "payne06.yaml")], False),
    "first-tran": (["tran", os.path.join(NET, "vasomotion.yaml"), "--t-end", "10"], True),
}


def run_once(args, env):
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run(CLI + args, env=env, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--only", action="append", choices=ROWS, help="row to run (repeatable; default all)")
    ap.add_argument("--runs", type=int, default=5, help="runs per row (median; default 5)")
    a = ap.parse_args()
    for name in a.only or ROWS:
        args, cold = ROWS[name]
        env = dict(os.environ)
        if not cold:
            run_once(args, env)  # warm-up: fills the caches
        times = []
        for _ in range(a.runs):
            tmp = tempfile.mkdtemp(prefix="hc-startup-") if cold else None
            if cold:
                env = {**os.environ, "HEMOCIRCUIT_CACHE_DIR": os.path.join(tmp, "hc"),
                       "NUMBA_CACHE_DIR": os.path.join(tmp, "numba")}
            try:
                times.append(run_once(args, env))
            finally:
                if tmp:
                    shutil.rmtree(tmp, ignore_errors=True)
        wall = statistics.median(w for w, _ in times)
        cpu = statistics.median(c for _, c in times)
        print(f"{name:11s} wall {wall:7.2f} s  cpu {cpu:7.2f} s  (median of {a.runs}; "
              f"wall {min(w for w, _ in times):.2f}-{max(w for w, _ in times):.2f} s)", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
