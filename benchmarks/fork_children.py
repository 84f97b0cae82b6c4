"""The fuzz benchmarks' one way of waiting for forked children (fuzz_netlists, fuzz_svzerod,
fuzz_specs): each case runs in a forked child with its limits; the parent reaps them."""
import os
import signal
import time


def wait_one(running, timeout, reap):
    """Wait until one child of ``running`` ({pid: (case, started, out, path)}) ends or passes
    ``timeout`` seconds (then it is killed); ``reap(pid, status or None, rusage, why)`` is
    called for it."""
    while True:
        for pid, (_, started, _, _) in list(running.items()):
            if time.time() - started > timeout:
                os.kill(pid, signal.SIGKILL)
                _, st, ru = os.wait4(pid, 0)
                reap(pid, None, ru, "timeout")
                return
        # its own children only: wait4(-1) would also reap other children of this process (a
        # test run's background engine builds), which are not in ``running``
        for pid in list(running):
            got, st, ru = os.wait4(pid, os.WNOHANG)
            if got:
                reap(pid, st, ru, "")
                return
        time.sleep(0.01)
