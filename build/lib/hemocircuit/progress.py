"""Progress: runs done / total with an ETA, on stderr (tqdm).

Two kinds of bar, both silent unless progress is on:

* :func:`bar` for one long computation: a transient's simulated time, a DC sweep's points,
  shooting's Newton iterations.  ``with bar(total, "tran", unit="s") as b: b.update_to(t)``.
* :class:`Tracker` for a batch of runs spread over chunks (:func:`hemocircuit.execution.run_chunks`):
  it counts RUNS, not chunks.  A chunk function may report runs as they finish with
  :func:`advance` (from a worker process too: forked workers inherit a queue the parent
  reads); whatever a chunk did not report is counted when the chunk returns.

Progress is on when the analysis is asked (``progress=True``) or, with ``progress=None``
(the analyses' default), when :func:`enable` turned it on: the command line does that unless
``--quiet``; the Python API stays silent.  While a batch bar is shown, single-run bars inside
it stay silent (one bar at a time).
"""
from __future__ import annotations

import contextlib
import sys
import threading

_enabled = False
_active = None      # the Tracker shown in this process, if any
_channel = None     # in a forked worker: the parent's queue for advance()
_chunk = None       # in a worker: the index of the chunk it is running


def enable(on=True):
    """Turn progress bars on (the command line, unless --quiet) or off."""
    global _enabled
    _enabled = bool(on)


def wanted(progress=None):
    """Whether to show progress: ``progress`` if given, else the global setting; never inside
    a batch (its own bar counts the runs) or a worker process."""
    if _active is not None or _channel is not None or _chunk is not None:
        return False
    return _enabled if progress is None else bool(progress)


def _tqdm(total, desc, unit):
    from tqdm import tqdm
    return tqdm(total=total, desc=desc, unit=unit, file=sys.stderr, dynamic_ncols=True, mininterval=0.5,
                smoothing=0.1)


class _Bar:
    """A single computation's bar (a no-op when progress is off)."""

    def __init__(self, total, desc, unit, on):
        self._t = _tqdm(total, desc, unit) if on else None
        self._n = 0.0

    def update_to(self, value, **postfix):
        if self._t is None:
            return
        value = min(float(value), float(self._t.total or value))
        if value > self._n:
            self._t.update(value - self._n)
            self._n = value
        if postfix:
            self._t.set_postfix(postfix, refresh=False)

    def update(self, n=1, **postfix):
        self.update_to(self._n + n, **postfix)

    def close(self):
        if self._t is not None:
            self._t.close()


@contextlib.contextmanager
def bar(total, desc, unit="run", progress=None):
    """A bar for one computation (``update_to(value)`` / ``update(n)``); silent unless wanted."""
    b = _Bar(total, desc, unit, wanted(progress))
    try:
        yield b
    finally:
        b.close()


def advance(n=1):
    """Report ``n`` runs finished by the chunk being computed (in this process or a worker)."""
    if _channel is not None:
        _channel.put((_chunk, n))
    elif _active is not None:
        _active.report(_chunk, n)


def call_in_chunk(fn, i, chunk):
    """Run ``fn(chunk)`` as chunk ``i`` (so :func:`advance` can say which chunk reports)."""
    global _chunk
    prev, _chunk = _chunk, i
    try:
        return fn(chunk)
    finally:
        _chunk = prev


class Tracker:
    """Counts the runs of a batch of chunks (``sizes[i]`` runs in chunk i) on one bar."""

    def __init__(self, sizes, desc, progress=None):
        self.sizes = list(sizes)
        self.counted = [0] * len(self.sizes)
        self.on = wanted(progress)
        self._t = _tqdm(sum(self.sizes), desc, "run") if self.on else None
        self._lock = threading.Lock()
        self._queue = self._thread = None

    def __enter__(self):
        global _active
        if self.on:
            _active = self
        return self

    def __exit__(self, *exc):
        global _active, _channel
        if self._queue is not None:
            # no sentinel through the queue: a worker terminated while writing to it (an
            # interrupted batch) may have left its lock held, and a put would then block forever
            self._stop.set()
            self._thread.join(timeout=5)
            _channel = None
        if self._t is not None:
            self._t.close()
        if _active is self:
            _active = None
        return False

    def report(self, i, n):
        """``n`` more runs of chunk ``i`` finished (capped at the chunk's size)."""
        if self._t is None or i is None or not 0 <= i < len(self.sizes):
            return
        with self._lock:
            k = max(0, min(n, self.sizes[i] - self.counted[i]))
            self.counted[i] += k
            if k:
                self._t.update(k)

    def chunk_done(self, i):
        self.report(i, self.sizes[i])

    def listen_to_workers(self, ctx):
        """A queue forked workers report to (set before the pool forks) and a thread reading it."""
        global _channel
        if self._t is None or ctx is None:
            return
        self._queue = ctx.SimpleQueue()
        self._stop = threading.Event()
        _channel = self._queue

        def read():
            while not self._stop.is_set():
                if self._queue.empty():
                    self._stop.wait(0.05)
                    continue
                self.report(*self._queue.get())

        self._thread = threading.Thread(target=read, daemon=True)
        self._thread.start()
