"""Interrupts (issue "Every input under one policy", item 5) and the bound on --workers.

SIGTERM during a ``--grid`` run ends the command within seconds, grids included: exit status
143, the finished members in NAME.partial.EXT, no worker process left.  It used to hang at
exit when a worker was killed while writing its result into the executor's result pipe: the
executor's manager thread waited forever for the rest of the message, and the interpreter's
exit waited for that thread.  ``benchmarks/sigterm_grid.py`` runs 20 such signals.
"""
import os
import signal
import struct
import subprocess
import sys
import threading
import time

import pytest

from paths import ROOT

from hemocircuit.cli import EXIT_ERROR, main
from hemocircuit.errors import HemocircuitError, Interrupted
from hemocircuit.execution import check_workers, default_workers, run_chunks
from hemocircuit.limits import limit
from hemocircuit.results import Result

VASOMOTION = ROOT / "netlists" / "vasomotion.yaml"
PROC = os.path.isdir("/proc")


# ---------------------------------------------------------------- helpers ----
def _group(pgid):
    """PIDs (zombies excluded) in process group ``pgid``."""
    out = []
    for d in os.listdir("/proc"):
        if d.isdigit():
            try:
                with open(f"/proc/{d}/stat") as fh:
                    fields = fh.read().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if fields[0] != "Z" and int(fields[2]) == pgid:
                out.append(int(d))
    return out


def _children(pid):
    """PIDs (zombies excluded) whose parent is ``pid``."""
    out = []
    for d in os.listdir("/proc"):
        if d.isdigit():
            try:
                with open(f"/proc/{d}/stat") as fh:
                    fields = fh.read().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if fields[0] != "Z" and int(fields[1]) == pid:
                out.append(int(d))
    return out


def _writing_to_a_pipe(pid):
    try:
        with open(f"/proc/{pid}/wchan") as fh:
            return "pipe_write" in fh.read()
    except OSError:
        return False


def _wchan_shows_pipe_writes():
    """Whether this kernel names a pipe write in /proc/PID/wchan (some hide wchan)."""
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:  # pragma: no cover - the child
        try:
            os.write(w, b"x" * 1_000_000)
        finally:
            os._exit(0)
    try:
        t = time.time() + 5
        while time.time() < t:
            if _writing_to_a_pipe(pid):
                return True
            time.sleep(0.01)
        return False
    finally:
        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
        os.close(r)
        os.close(w)


def _grid(out, taus):
    """A tran grid of 11 MB members (30 001 rows x 47 columns): written in pieces into the
    result pipe, long enough to be caught writing.  Progress bars on, stderr to NAME.err.
    Results as .npz: as CSV, writing the finished members alone takes seconds here."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    out = out.with_suffix(".npz")
    with open(out.with_suffix(".err"), "w") as err:
        return subprocess.Popen([sys.executable, "-m", "hemocircuit.cli", "tran", str(VASOMOTION), "--t-end", "60",
                                 "--dt", "0.002", "--grid", f"art.tau_Ca={taus}s", "--workers", "2", "--out",
                                 str(out)], stdout=subprocess.DEVNULL, stderr=err, env=env, start_new_session=True)


def _members_done(err_file):
    """Members the progress bar ('k/N') last showed finished."""
    import re
    counts = re.findall(r"\| *(\d+)/\d+ \[", err_file.read_text(errors="replace"))
    return int(counts[-1]) if counts else 0


# ---------------------------------------------------------------- SIGTERM during grids ----
@pytest.mark.skipif(not PROC or not hasattr(os, "fork"), reason="needs /proc and fork")
def test_sigterm_during_grids_exits_promptly_keeping_what_finished(tmp_path):
    """Three grids at once, each SIGTERMed at another moment: (a) while a worker writes the
    first member's result into the result pipe (hung at exit before the fix, every time here),
    (b) half a second after the workers started (nothing finished: no partial file), (c) while
    a worker writes a result after one member had finished (its row kept).  Each: exit 143
    within 10 s, NAME.partial.npz exactly when a member finished, no process of its group left."""
    by_wchan = _wchan_shows_pipe_writes()
    # a: four members, two rounds of writes, so a write missed by the poll in the first round (the
    # window is short on a loaded host) is caught in the second; if both are missed, a is signalled
    # once its second round has started (the hang itself is tested deterministically below)
    runs = {"a": _grid(tmp_path / "a.csv", "1,2,3,4"), "b": _grid(tmp_path / "b.csv", "1,2"),
            "c": _grid(tmp_path / "c.csv", "1,2,3,4,5,6")}
    started, sent = {}, {}
    deadline = time.time() + 300
    try:
        while len(sent) < len(runs) and time.time() < deadline:
            for k, p in runs.items():
                if k in sent or p.poll() is not None:
                    continue
                workers = [w for w in _group(p.pid) if w != p.pid]
                if workers and k not in started:
                    started[k] = time.time()
                if k not in started:
                    continue
                now = [w for w in workers if _writing_to_a_pipe(w)]
                since = time.time() - started[k]
                if (k == "b" and since >= 0.5) or (by_wchan and k == "a" and now) \
                        or (k == "a" and _members_done(tmp_path / "a.err") >= 2) \
                        or (by_wchan and k == "c" and now and _members_done(tmp_path / "c.err")) \
                        or (not by_wchan and since >= {"a": 3.0, "c": 8.0}.get(k, 0.5)):
                    os.kill(p.pid, signal.SIGTERM)
                    sent[k] = time.time()
            time.sleep(0.002)
        for k, p in runs.items():
            assert k in sent, f"grid {k} ended before its signal: status {p.returncode}"
        for k, p in runs.items():
            try:
                p.wait(timeout=max(0.1, sent[k] + 10 - time.time()))
            except subprocess.TimeoutExpired:
                pytest.fail(f"grid {k} still running 10 s after SIGTERM (the result pipe's manager thread)")
            err = (tmp_path / f"{k}.err").read_text(errors="replace")
            assert p.returncode == 143, (k, err)
            assert "interrupted by SIGTERM" in err
            time.sleep(0.2)
            assert _group(p.pid) == [], f"grid {k}: processes left in its group"
            part, out = tmp_path / f"{k}.partial.npz", tmp_path / f"{k}.npz"
            assert not out.exists()
            if k == "b":
                assert not part.exists() and "members finished" not in err
            if k == "c" and by_wchan:
                assert part.exists(), err
            if part.exists():
                res = Result.load(part)
                assert res.status == "partial" and res.metadata["interrupted"] == "SIGTERM"
                assert "grid members finished" in err and str(part) in err
    finally:
        for p in runs.values():
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGKILL)
                p.wait()


# ---------------------------------------------------------------- the executor's manager thread ----
def _half_a_result(chunk):
    """In a worker: write half a message into the executor's result pipe (a header announcing
    1 MB, then 1 kB), as a worker killed while sending its result leaves it, interrupt the
    parent (SIGUSR1, a KeyboardInterrupt there) and wait to be stopped."""
    if chunk != [0]:
        time.sleep(60)
        return chunk
    frame = sys._getframe()
    while frame is not None and "result_queue" not in frame.f_locals:
        frame = frame.f_back
    writer = frame.f_locals["result_queue"]._writer
    writer._send(struct.pack("!i", 1_000_000) + b"x" * 1000)
    os.kill(os.getppid(), signal.SIGUSR1)
    time.sleep(60)
    return chunk


def _manager_threads():
    from concurrent.futures.process import _ExecutorManagerThread
    return [t for t in threading.enumerate() if isinstance(t, _ExecutorManagerThread)]


@pytest.mark.skipif(not PROC or not hasattr(os, "fork"), reason="needs /proc and fork")
def test_interrupt_while_a_worker_writes_its_result_ends_the_manager_thread():
    """Deterministic form of the hang: a worker stopped halfway through writing its result.
    run_chunks raises Interrupted at once, no worker is left, and the executor's manager
    thread ends (before the fix it waited forever in recv(), and so did the exit)."""
    def interrupt(signum, frame):
        raise KeyboardInterrupt

    before, children = set(_manager_threads()), set(_children(os.getpid()))
    previous = signal.signal(signal.SIGUSR1, interrupt)
    t0 = time.perf_counter()
    try:
        with pytest.raises(Interrupted) as info:
            run_chunks(_half_a_result, [[0], [1]], scheduler="processes", workers=2)
        elapsed = time.perf_counter() - t0
        assert info.value.chunk_results == [None, None]
        assert elapsed < 20
        assert set(_children(os.getpid())) <= children, "a worker outlived the interruption"
        stuck = [t for t in set(_manager_threads()) - before if (t.join(5), t.is_alive())[1]]
        assert not stuck, "the executor's manager thread still waits for the rest of the result"
    finally:
        signal.signal(signal.SIGUSR1, previous)
        for t in set(_manager_threads()) - before:  # unblock it (as the fix does) so pytest can exit
            try:
                t.result_queue._writer.close()
            except OSError:
                pass


# ---------------------------------------------------------------- --workers ----
def test_workers_above_the_limit_are_refused_naming_it(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("HEMOCIRCUIT_MAX_WORKERS", "3")
    rc = main(["op", str(VASOMOTION), "--grid", "art.tau_Ca=1,2s", "--workers", "42", "--out", str(tmp_path / "o.csv")])
    err = capsys.readouterr().err
    assert rc == EXIT_ERROR and "Traceback" not in err
    assert "--workers 42" in err and "limit 3" in err and "HEMOCIRCUIT_MAX_WORKERS" in err
    assert not (tmp_path / "o.csv").exists()
    with pytest.raises(HemocircuitError, match="limit 3"):  # the API's workers= gets the same check
        run_chunks(len, [[1], [2]], workers=4)
    assert check_workers(3) == 3
    monkeypatch.delenv("HEMOCIRCUIT_MAX_WORKERS")
    assert limit("WORKERS") == 4 * default_workers()  # 4 per usable core
    with pytest.raises(HemocircuitError, match="HEMOCIRCUIT_MAX_WORKERS"):
        check_workers(limit("WORKERS") + 1)


@pytest.mark.parametrize("n", ["0", "-2"])
def test_zero_or_negative_workers_are_refused(tmp_path, capsys, n):
    rc = main(["op", str(VASOMOTION), "--grid", "art.tau_Ca=1,2s", "--workers", n, "--out", str(tmp_path / "o.csv")])
    err = capsys.readouterr().err
    assert rc == EXIT_ERROR and "Traceback" not in err
    assert f"--workers {n}: the number of worker processes must be at least 1" in err
    with pytest.raises(HemocircuitError, match="at least 1"):
        run_chunks(len, [[1], [2]], workers=int(n))
    with pytest.raises(HemocircuitError, match="whole number"):
        check_workers(2.5)
