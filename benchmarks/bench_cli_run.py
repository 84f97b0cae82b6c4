"""A 1000 s vasomotion run as a user runs it, written to a file, against roadrunner (issue 35).

    python benchmarks/bench_cli_run.py --runs 7 --peers ../shared/peers

Both sides are whole processes timed from outside, in alternating order (hemocircuit long,
hemocircuit short, roadrunner long, roadrunner short, ...), and each side's figure is its long
run less its short run (2 s of the same model): what the run and the writing cost, without
the start-up (imports, loading the compiled code) both pay once.

* hemocircuit: ``hemocircuit tran netlists/vasomotion.yaml --t-end 1000 --dt 0.1
  --ic art.lambda=1.1356 --out FILE`` (every output column, CSV), the compiled engine warm;
* roadrunner: its Antimony model of the same circuit (``brain_vasomotion.ant``, rtol 1e-6,
  10 001 points), ``simulate`` and the result written with ``numpy.savetxt`` (CSV).

Prints the medians (wall and CPU) of each side and the ratio hemocircuit / roadrunner.
"""
from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RR_SCRIPT = """
import sys, antimony, roadrunner, numpy as np
antimony.loadAntimonyFile(sys.argv[1])
rr = roadrunner.RoadRunner(antimony.getSBMLString(antimony.getMainModuleName()))
rr.integrator.relative_tolerance = 1e-6
t_end = float(sys.argv[2])
rr.resetAll()
S = rr.simulate(0, t_end, int(round(t_end / 0.1)) + 1)
np.savetxt(sys.argv[3], np.asarray(S), delimiter=",", header=",".join(S.colnames), comments="")
"""


def timed(cmd):
    """(wall s, CPU s) of one child process."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=7)
    ap.add_argument("--peers", default=os.path.join(ROOT, "..", "shared", "peers"))
    a = ap.parse_args(argv)
    tmp = tempfile.mkdtemp(prefix="bench_cli_run_")
    rr_py = os.path.join(tmp, "rr_run.py")
    with open(rr_py, "w") as fh:
        fh.write(RR_SCRIPT)
    model = os.path.join(a.peers, "brain_vasomotion.ant")
    net = os.path.join(ROOT, "netlists", "vasomotion.yaml")

    def hc(t_end):
        return [sys.executable, "-m", "hemocircuit.cli", "tran", net, "--t-end", str(t_end), "--dt", "0.1",
                "--ic", "art.lambda=1.1356", "--compile", "wait", "--quiet",
                "--out", os.path.join(tmp, f"hc{t_end}.csv")]

    def rr(t_end):
        return [sys.executable, rr_py, model, str(t_end), os.path.join(tmp, f"rr{t_end}.csv")]

    cmds = {"hc_long": hc(1000), "hc_short": hc(2), "rr_long": rr(1000), "rr_short": rr(2)}
    for cmd in cmds.values():  # warm-up: the compiled engine built, files in the page cache
        timed(cmd)
    res = {k: [] for k in cmds}
    for _ in range(a.runs):
        for k, cmd in cmds.items():
            res[k].append(timed(cmd))

    def med(k, i):
        return statistics.median(r[i] for r in res[k])

    print(f"{a.runs} runs each, load {os.getloadavg()[0]:.2f}")
    for i, what in ((0, "wall"), (1, "CPU")):
        hc_s = med("hc_long", i) - med("hc_short", i)
        rr_s = med("rr_long", i) - med("rr_short", i)
        print(f"{what}: hemocircuit {med('hc_long', i):.2f} - {med('hc_short', i):.2f} = {hc_s:.2f} s; "
              f"roadrunner {med('rr_long', i):.2f} - {med('rr_short', i):.2f} = {rr_s:.2f} s; "
              f"ratio {hc_s / rr_s:.2f}")
        # the same from each round's own differences (the four commands of a round run one
        # after the other, so a drift of the machine's speed between rounds cancels)
        ratios = [(h[i] - hs[i]) / (r[i] - rs[i])
                  for h, hs, r, rs in zip(res["hc_long"], res["hc_short"], res["rr_long"], res["rr_short"])]
        print(f"{what}: per-round ratio median {statistics.median(ratios):.2f} "
              f"(range {min(ratios):.2f}-{max(ratios):.2f})")


if __name__ == "__main__":
    main()
