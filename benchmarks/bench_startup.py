"""Start-up and first-compile time of the command line (issue 8), whole processes.

    python benchmarks/bench_startup.py                 # all three rows, 5 runs each (median)
    python benchmarks/bench_startup.py --runs 3 --only first-tran
    python benchmarks/bench_startup.py --breakdown     # the first compile's CPU, by function

Rows:
  help        ``hemocircuit --help``
  warm-op     ``hemocircuit op netlists/payne06.yaml`` with the caches already filled
  first-tran  ``hemocircuit tran netlists/vasomotion.yaml --t-end 10`` with empty
              ``HEMOCIRCUIT_CACHE_DIR`` and ``NUMBA_CACHE_DIR`` (new folders for every run):
              the first run after install.  It starts the engine's build in the background
              and integrates on the scipy path meanwhile; "ready" is when the build's marker
              appeared (the benchmark waits for it before the next run)
  first-tran-wait   the same with ``--compile wait``: compilation of vasomotion's engine
              included in the run
  first-tran-long   ``tran netlists/vasomotion.yaml --t-end 1000 --dt 0.1`` kicked off the
              equilibrium (``--ic art.lambda=1.1356``, +0.1 %), default ``--compile``: scipy
              until the build is ready, compiled after

Each run is a child process; wall time from a monotonic clock, CPU time (user + system) from
the operating system's accounting of the child (``resource.getrusage(RUSAGE_CHILDREN)``), so
CPU figures stay meaningful on a busy machine; a first run's compile helper, which outlives the
run (it goes on with the outputs' nodal solve), is neither counted nor left running into the
next run (the benchmark waits for it).  Medians are printed.

``--breakdown``: where the first compile's CPU goes, in one child process without the second
(``HEMOCIRCUIT_PREBUILD=0``, empty caches): the first ``tran`` of the row's netlist, each numba
function's own compile CPU (numba's event API, ``numba.core.event``: its callees' compiles
subtracted), numba's passes summed over the functions, and LLVM's share (function passes,
final-module optimisation, machine code: numba's code libraries timed).
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
    "first-tran-wait": (["tran", os.path.join(NET, "vasomotion.yaml"), "--t-end", "10", "--compile", "wait"], True),
    "first-tran-long": (["tran", os.path.join(NET, "vasomotion.yaml"), "--t-end", "1000", "--dt", "0.1",
                         "--ic", "art.lambda=1.1356"], True),
}


def wait_ready(folder, started, timeout=900.0):
    """Seconds from ``started`` until a build's ready marker is in ``folder`` with no build
    running (None if none appeared)."""
    kernels = os.path.join(folder, "kernels")
    while time.perf_counter() - started < timeout:
        names = os.listdir(kernels) if os.path.isdir(kernels) else []
        if any(".ready-" in n for n in names) and not any(".building-" in n for n in names):
            return time.perf_counter() - started
        time.sleep(0.2)
    return None


def helpers_running() -> list[int]:
    """The pids of compile helpers (``python -m hemocircuit.kernels.prebuild``) still running: a
    first run's helper goes on compiling the outputs' nodal solve after the run has ended."""
    found = []
    for pid in os.listdir("/proc") if os.path.isdir("/proc") else []:
        try:
            with open(f"/proc/{pid}/cmdline", "rb") as fh:
                if b"hemocircuit.kernels.prebuild" in fh.read():
                    found.append(int(pid))
        except (OSError, ValueError):
            pass
    return found


def wait_for_helpers(timeout=120.0):
    """Wait until no compile helper runs, so that the next first run starts on an idle machine
    (as a user's first run does), not beside the previous run's helper."""
    end = time.monotonic() + timeout
    while helpers_running() and time.monotonic() < end:
        time.sleep(0.2)


def run_once(args, env):
    """(wall, CPU of the command's process, seconds until its engine was ready or None).  The
    CPU excludes a detached background build (not a child the benchmark waits for)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run(CLI + args, env={**env, "HEMOCIRCUIT_COMPILE": "background"}, check=True,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    hc_dir = env.get("HEMOCIRCUIT_CACHE_DIR")
    ready = wait_ready(hc_dir, t0) if hc_dir and "tran" in args else None
    wait_for_helpers()
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime), ready


BREAKDOWN = r"""
import os, sys, time
import numpy as np
import hemocircuit as hc  # first: its numba settings (-O1, no loop vectorizer) apply only before numba loads
from numba.core import codegen, event
own, passes, llvm, stack = {}, {}, {}, []

class Listener(event.Listener):
    def on_start(self, ev):
        name = ev.data["dispatcher"].py_func.__qualname__ if ev.kind == "numba:compile" else ev.data["name"]
        stack.append([ev.kind, name, time.process_time(), 0.0])

    def on_end(self, ev):
        kind, name, t0, inner = stack.pop()
        spent = time.process_time() - t0
        if stack:
            stack[-1][3] += spent
        if kind == "numba:compile":
            own[name] = own.get(name, 0.0) + spent - inner
        else:
            fn = next(s[1] for s in reversed(stack) if s[0] == "numba:compile")
            own[fn] = own.get(fn, 0.0) + spent - inner
            key = name.split(" [")[0]
            passes[key] = passes.get(key, 0.0) + spent - inner


def timed(name):
    orig = getattr(codegen.CPUCodeLibrary, name)

    def run(self, *a, **k):
        t0 = time.process_time()
        try:
            return orig(self, *a, **k)
        finally:
            llvm[name] = llvm.get(name, 0.0) + time.process_time() - t0
    setattr(codegen.CPUCodeLibrary, name, run)


for name in ("_optimize_functions", "_optimize_final_module", "_finalize_final_module"):
    timed(name)
event.register("numba:compile", Listener())
event.register("numba:run_pass", Listener())
from hemocircuit.analyses.transient import simulate
c = hc.load(sys.argv[1])
t0 = time.process_time()
simulate(c, t_end=10.0, progress=False, compile="wait")
total = time.process_time() - t0
import numba
print(f"first tran, one process: {total:.1f} s CPU, {len(own)} functions compiled "
      f"(numba -O{int(numba.config.OPT)}, loop vectorizer {'on' if numba.config.LOOP_VECTORIZE else 'off'})")
print("LLVM: function passes {:.1f} s, final-module optimisation {:.1f} s, machine code {:.1f} s".format(
    *(llvm.get(k, 0.0) for k in ("_optimize_functions", "_optimize_final_module", "_finalize_final_module"))))
print("passes: " + ", ".join(f"{k} {v:.1f}" for k, v in sorted(passes.items(), key=lambda kv: -kv[1])[:8]))
print("functions (own compile CPU):")
top = sorted(own.items(), key=lambda kv: -kv[1])
for name, v in top[:14]:
    print(f"  {name:32s} {v:6.2f} s")
print(f"  the other {len(top) - 14:3d}                   {sum(v for _, v in top[14:]):6.2f} s")
"""


def breakdown(row) -> int:
    """Where a first compile's CPU goes (see the module docstring), one child process."""
    args, _ = ROWS[row]
    tmp = tempfile.mkdtemp(prefix="hc-startup-")
    env = {**os.environ, "HEMOCIRCUIT_CACHE_DIR": os.path.join(tmp, "hc"), "NUMBA_CACHE_DIR": os.path.join(tmp, "numba"),
           "HEMOCIRCUIT_PREBUILD": "0"}
    try:
        return subprocess.run([sys.executable, "-c", BREAKDOWN, args[1]], env=env, cwd=ROOT).returncode
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--only", action="append", choices=ROWS, help="row to run (repeatable; default all)")
    ap.add_argument("--runs", type=int, default=5, help="runs per row (median; default 5)")
    ap.add_argument("--breakdown", action="store_true",
                    help="where the first compile's CPU goes (first-tran-wait's netlist, one process)")
    a = ap.parse_args()
    if a.breakdown:
        return breakdown("first-tran-wait")
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
        wall = statistics.median(w for w, _, _ in times)
        cpu = statistics.median(c for _, c, _ in times)
        ready = [r for _, _, r in times if r is not None]
        extra = f"; engine ready after {statistics.median(ready):.1f} s" if ready else ""
        print(f"{name:15s} wall {wall:7.2f} s  cpu {cpu:7.2f} s  (median of {a.runs}; "
              f"wall {min(w for w, _, _ in times):.2f}-{max(w for w, _, _ in times):.2f} s{extra})", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
