"""SIGTERM during ``--grid`` runs: every run must end promptly, keep what finished, leave no
worker behind.

Each trial starts the whole command line (``hemocircuit.cli.main``) in its own session (so its
own process group), waits for its worker processes to start, sends SIGTERM to the command's
process (as ``kill PID``, systemd or a batch scheduler do) a delay later (spread over
``--delays``; the delay counts from the workers' start, so that start-up time, which varies
with the machine's load, does not decide whether members had finished) and checks:

* it exits within ``--limit`` seconds (default 10) with status 143;
* NAME.partial.csv (.npz for ``send``, below) exists when the command says members had
  finished ("k of N grid members finished", k > 0), and NAME.csv does not;
* no process of its process group is left (workers included; /proc, zombies ignored).

Trials cycle over four grids: a ``tran`` grid (members of 1 MB of results each), ``send`` (a
``tran`` grid of 11 MB members, signalled the moment a worker is seen writing a result into
the result pipe, /proc/PID/wchan, at the first such moment after the delay: a worker killed
then left the parent's executor waiting forever for the rest of the message, and its exit with
it), an ``op`` grid (many small members) and a ``dc`` grid; every other trial with progress
bars (a second pipe from the workers), the others ``--quiet``.  A run that hangs gets its
threads' stacks dumped (faulthandler on SIGUSR1) before it is killed.

    python benchmarks/sigterm_grid.py                # 20 trials, delays 1-4 s
    python benchmarks/sigterm_grid.py -n 40 --only send --delays 0:8
"""
from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
NET = str(ROOT / "netlists" / "vasomotion.yaml")
TAUS = "art.tau_Ca=1,2,3,4,5,6,7,8s"
GRIDS = {
    "tran": ["tran", NET, "--t-end", "300", "--dt", "0.1", "--grid", TAUS],
    "send": ["tran", NET, "--t-end", "60", "--dt", "0.002", "--grid", "art.tau_Ca=1,2,3,4s"],
    "op": ["op", NET, "--grid", TAUS, "--grid", "Pa.value=60:120:10mmHg"],
    "dc": ["dc", NET, "--sweep", "Pa.value=20:200:2mmHg", "--grid", TAUS],
}
# the partial result's format: .npz for the 11 MB members of "send" (as CSV, writing two of them
# takes seconds on a loaded 2-core machine: that would time the CSV writer, not the interrupt)
EXT = {"send": "npz"}
# the command line's main with faulthandler on SIGUSR1 (all threads' stacks to stderr)
LAUNCH = ("import faulthandler, signal, sys; faulthandler.register(signal.SIGUSR1, all_threads=True); "
          "from hemocircuit.cli import main; sys.exit(main(sys.argv[1:]))")


def group_members(pgid):
    """PIDs (not zombies) whose process group is ``pgid``."""
    out = []
    for d in os.listdir("/proc"):
        if not d.isdigit():
            continue
        try:
            with open(f"/proc/{d}/stat") as fh:
                fields = fh.read().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if fields[0] != "Z" and int(fields[2]) == pgid:
            out.append(int(d))
    return out


def writing_to_a_pipe(pid):
    """Whether process ``pid`` waits in a pipe write (its wchan; '' where the kernel hides it)."""
    try:
        with open(f"/proc/{pid}/wchan") as fh:
            return "pipe_write" in fh.read()
    except OSError:
        return False


def launch(argv, out, stderr_path, quiet):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    with open(stderr_path, "w") as err:
        return subprocess.Popen([sys.executable, "-c", LAUNCH, *argv, "--out", str(out)] + ["--quiet"] * quiet,
                                stdout=subprocess.DEVNULL, stderr=err, env=env, start_new_session=True)


def trial(kind, delay, workdir, limit, workers=None, quiet=True):
    ext = EXT.get(kind, "csv")
    out = workdir / f"{kind}.{ext}"
    part = workdir / f"{kind}.partial.{ext}"
    errf = workdir / f"{kind}.err"
    for f in (out, part):
        f.unlink(missing_ok=True)
    argv = GRIDS[kind] + (["--workers", str(workers)] if workers else [])
    p = launch(argv, out, errf, quiet)
    pgid = p.pid  # start_new_session: the leader of its own group
    row = {"kind": kind, "delay": delay, "ok": False, "why": "", "quiet": quiet}
    deadline = time.time() + 300
    while p.poll() is None and len(group_members(pgid)) < 2 and time.time() < deadline:
        time.sleep(0.05)  # the workers not started yet
    started = time.perf_counter()
    time.sleep(delay)
    if kind == "send":  # then the first moment a worker writes a result into the pipe
        while p.poll() is None and not any(writing_to_a_pipe(w) for w in group_members(pgid) if w != pgid):
            time.sleep(0.002)
    if p.poll() is not None:
        row["why"] = f"finished before the signal (status {p.returncode}); use shorter delays"
        return row
    sent = time.perf_counter()
    os.kill(p.pid, signal.SIGTERM)
    row["at"] = sent - started
    while p.poll() is None and len(group_members(pgid)) > 1 and time.perf_counter() - sent < limit:
        time.sleep(0.01)
    row["stopped"] = time.perf_counter() - sent  # the workers gone (what follows: writing what finished)
    try:
        p.wait(timeout=max(0.0, limit - row["stopped"]))
        row["latency"] = time.perf_counter() - sent
    except subprocess.TimeoutExpired:
        row["latency"] = None
        os.kill(p.pid, signal.SIGUSR1)  # stacks of every thread to the stderr file
        time.sleep(1.0)
        os.killpg(pgid, signal.SIGKILL)
        p.wait()
    time.sleep(0.2)  # a worker would be gone by now if it only had to notice its parent's death
    left = group_members(pgid)
    err = errf.read_text(errors="replace")
    import re
    m = re.search(r"(\d+) of (\d+) grid members finished", err)
    finished = int(m.group(1)) if m else 0
    row.update(status=p.returncode, finished=finished, left=left, partial=part.exists())
    problems = []
    if row["latency"] is None:
        problems.append(f"still running {limit:g} s after SIGTERM")
    elif p.returncode != 143:
        problems.append(f"exit status {p.returncode}")
    if finished and not part.exists():
        problems.append(f"{finished} members finished but no {part.name}")
    if out.exists():
        problems.append(f"{out.name} written by an interrupted run")
    if left:
        problems.append(f"processes left in its group: {left}")
        for pid in left:
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
    if problems:
        row["why"] = "; ".join(problems)
        row["stderr"] = err[-6000:]
    else:
        row["ok"] = True
    return row


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("-n", type=int, default=20, help="trials (default 20)")
    ap.add_argument("--delays", default="1:4", help="SIGTERM A..B seconds after the workers started, spread "
                    "evenly (default 1:4)")
    ap.add_argument("--only", choices=sorted(GRIDS), action="append", help="only these grids (repeatable)")
    ap.add_argument("--limit", type=float, default=10.0, help="seconds allowed to exit (default 10)")
    ap.add_argument("--workers", type=int, help="--workers for the grids (default: the command's)")
    a = ap.parse_args()
    lo, hi = (float(x) for x in a.delays.split(":"))
    kinds = a.only or ["tran", "send", "op", "dc"]
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        # compile first (a grid compiles before it runs; not what is measured here)
        warm = subprocess.run([sys.executable, "-m", "hemocircuit.cli", "tran", NET, "--t-end", "1", "--quiet",
                               "--grid", "art.tau_Ca=1,2s", "--out", str(work / "warm.csv")],
                              capture_output=True, text=True, env={**os.environ, "PYTHONPATH": str(ROOT)})
        if warm.returncode:
            sys.exit(f"warm-up run failed:\n{warm.stderr}")
        rows = []
        for k in range(a.n):
            delay = lo + (hi - lo) * ((k * 7) % a.n) / max(1, a.n - 1)  # spread, not monotone
            kind = kinds[k % len(kinds)]
            r = trial(kind, round(delay, 2), work, a.limit, a.workers, quiet=k % 2 == 0)
            rows.append(r)
            lat = "-" if r.get("latency") is None else f"{r['latency']:.2f} s"
            print(f"{k + 1:3d} {kind:5s}{'' if r['quiet'] else ' (bars)'} SIGTERM {r.get('at', r['delay']):.2f} s after "
                  f"the workers started: {'ok  ' if r['ok'] else 'FAIL'} "
                  f"exit {r.get('status')} in {lat} (workers gone in {r.get('stopped', 0):.2f} s), "
                  f"{r.get('finished', 0)} finished, "
                  f"partial file {'yes' if r.get('partial') else 'no'}"
                  + (f"  <- {r['why']}" if r["why"] else ""), flush=True)
            if not r["ok"] and r.get("stderr"):
                print("    stderr (tail):\n" + "\n".join("    " + ln for ln in r["stderr"].splitlines()[-60:]))
    counted = [r for r in rows if "status" in r]
    ok = sum(r["ok"] for r in counted)
    lats = sorted(r["latency"] for r in counted if r.get("latency") is not None)
    print(f"\n{ok}/{len(counted)} interrupted runs ended correctly"
          + (f" ({len(rows) - len(counted)} finished before the signal, not counted)" if len(rows) > len(counted) else ""))
    if lats:
        print(f"exit latency after SIGTERM: median {lats[len(lats) // 2]:.2f} s, max {lats[-1]:.2f} s "
              f"(limit {a.limit:g} s)")
        stops = sorted(r["stopped"] for r in counted if r.get("latency") is not None)
        print(f"workers gone after SIGTERM: median {stops[len(stops) // 2]:.2f} s, max {stops[-1]:.2f} s")
    sys.exit(0 if counted and ok == len(counted) else 1)


if __name__ == "__main__":
    main()
