"""Running batches: local processes (default), in-process, or a Dask cluster.

A batch job is split into chunks; each chunk is ONE vectorised batch (a circuit with a batch
of parameter sets, integrated together), so a worker pays Python overhead once per step for
its whole chunk.  Chunks go to worker processes (``concurrent.futures``) or to Dask
(``scheduler='tcp://HOST:PORT'``, extra ``hemocircuit[distributed]``).  A member's numbers do
not depend on which chunk or executor ran it (the batched integrator works member by member),
so results are identical whichever executor ran them.  A failing member is recorded with its
reason and does not lose the others.

Failures and signals (the caller turns both into rows marked failed or not run):
* ``failures='collect'``: a chunk whose function raises becomes a :class:`ChunkFailed` (its
  reason) in the returned list; the other chunks finish.
* SIGINT / SIGTERM (a KeyboardInterrupt; the CLI turns SIGTERM into one, see
  :class:`hemocircuit.errors.Interrupted`): the worker processes are terminated and joined
  (none is left running), the executor's manager thread is made to end (see
  :func:`stop_workers`: a worker killed while sending its result would otherwise leave it
  waiting forever, and the interpreter's exit waiting for it), and
  :class:`~hemocircuit.errors.Interrupted` is raised with ``chunk_results`` (None for the
  chunks that had not finished).  Workers ignore SIGINT (a Ctrl-C reaches the whole process
  group; the parent decides) and, on Linux, die with the parent even if it is killed
  outright (``PR_SET_PDEATHSIG``).

The number of local worker processes is checked here (:func:`check_workers`, for the command
line's ``--workers`` and the API's ``workers=`` alike): at least 1, at most the WORKERS limit
(:mod:`hemocircuit.limits`).
"""
from __future__ import annotations

import os
import time

from .errors import HemocircuitError, Interrupted


def default_workers() -> int:
    return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1))


def check_workers(workers):
    """The number of local worker processes to use: ``workers`` checked (a whole number from 1
    to the WORKERS limit), or :func:`default_workers` for None."""
    if workers is None:
        return default_workers()
    import numbers

    from .limits import how_to_raise, limit
    if isinstance(workers, bool) or not isinstance(workers, numbers.Integral):
        raise HemocircuitError(f"the number of worker processes (--workers, workers=) must be a whole number, "
                               f"got {workers!r}")
    workers = int(workers)
    if workers < 1:
        raise HemocircuitError(f"--workers {workers}: the number of worker processes must be at least 1 "
                               f"(omit it for one per core, {default_workers()} here)")
    if workers > limit("WORKERS"):
        raise HemocircuitError(f"--workers {workers}: more worker processes than allowed {how_to_raise('WORKERS')}")
    return workers


def split(items, n_chunks, interleave=False):
    """Split a list into at most n_chunks nearly equal chunks: contiguous (order kept), or with
    ``interleave`` round-robin (chunk j takes items j, j + n, ...: neighbours, which tend to
    cost alike, e.g. adjacent frequencies, go to different chunks and the chunks balance)."""
    n = len(items)
    if n == 0:
        return []
    n_chunks = max(1, min(n_chunks, n))
    if interleave:
        return [items[j::n_chunks] for j in range(n_chunks)]
    bounds = [round(k * n / n_chunks) for k in range(n_chunks + 1)]
    return [items[bounds[k]:bounds[k + 1]] for k in range(n_chunks) if bounds[k + 1] > bounds[k]]


def run_chunks(fn, chunks, scheduler=None, workers=None, progress=None, desc="runs", sizes=None,
               failures="raise", warm=None):
    """[fn(chunk) for chunk in chunks], in order, on the chosen executor.

    scheduler: None / 'processes' (local worker processes), 'serial' (this process), a Dask
    scheduler address 'tcp://HOST:PORT', or a dask.distributed Client.
    progress: a bar counting runs (:class:`hemocircuit.progress.Tracker`); ``sizes[i]`` is the
    number of runs in chunk i (default 1 each); ``fn`` may report runs as they finish with
    :func:`hemocircuit.progress.advance`.
    failures: 'raise' (a chunk's exception propagates) or 'collect' (it becomes a
    :class:`ChunkFailed` in the list; the other chunks finish).
    warm: a callable run in this process before local worker processes are forked, for what
    every worker would otherwise do again at its start (e.g. a zero-length integration, which
    loads the compiled integrator from the cache, ~0.4 s); forked workers inherit it.
    An interruption raises :class:`~hemocircuit.errors.Interrupted` with the finished chunks.
    """
    from functools import partial

    from . import progress as _progress

    workers = check_workers(workers)
    results = [None] * len(chunks)
    try:
        with _progress.Tracker(sizes or [1] * len(chunks), desc, progress) as bar:
            def done(i, r):
                results[i] = r
                bar.chunk_done(i)

            if scheduler == "serial" or (scheduler in (None, "processes") and (workers == 1 or len(chunks) <= 1)):
                for i, c in enumerate(chunks):
                    done(i, _call(partial(_progress.call_in_chunk, fn, i), c, failures))
            elif scheduler in (None, "processes"):
                if warm is not None and hasattr(os, "fork"):
                    try:
                        warm()
                    except Exception:  # noqa: BLE001 - only a head start: a real fault shows in the chunks
                        pass
                _run_processes(fn, chunks, workers, done, failures, bar)
            else:
                client = _dask_client(scheduler)
                try:
                    futs = client.map(fn, chunks, pure=False)
                    from dask.distributed import as_completed as das_completed
                    index = {f.key: i for i, f in enumerate(futs)}
                    for f in das_completed(futs):
                        done(index[f.key], _outcome(f, failures))
                finally:
                    if client is not scheduler:  # made here from an address: do not leak it
                        client.close()
    except KeyboardInterrupt as exc:  # SIGINT, or SIGTERM through the CLI's handler
        raise Interrupted.of(exc, chunk_results=list(results)) from None
    return results


def _dask_client(scheduler):
    try:
        from dask.distributed import Client
    except ImportError:
        raise HemocircuitError("a Dask scheduler was given but dask.distributed is not installed: "
                               "pip install 'hemocircuit[distributed]'") from None
    if isinstance(scheduler, Client):
        return scheduler
    try:
        return Client(scheduler, timeout="10s")
    except OSError as exc:
        raise HemocircuitError(f"cannot reach the Dask scheduler {scheduler}: {exc}") from None


# ---------------------------------------------------------------- failures and signals ----
class ChunkFailed:
    """What :func:`run_chunks` (``failures='collect'``) gives for a chunk whose function
    raised: ``reason`` (text naming the exception)."""

    def __init__(self, reason):
        self.reason = reason

    def __repr__(self):
        return f"ChunkFailed({self.reason!r})"


def failure_reason(exc):
    """An exception as a member's failure reason: a HemocircuitError's own message; anything
    else with its type (an internal error, reported rather than losing the other members)."""
    if isinstance(exc, HemocircuitError):
        return str(exc)
    from concurrent.futures.process import BrokenProcessPool
    if isinstance(exc, BrokenProcessPool):
        return f"a worker process died ({exc})"
    return f"internal error ({type(exc).__name__}: {exc})"


def _call(fn, chunk, failures):
    if failures != "collect":
        return fn(chunk)
    try:
        return fn(chunk)
    except Exception as exc:  # noqa: BLE001 - reported per member; the others finish
        return ChunkFailed(failure_reason(exc))


def _outcome(future, failures):
    if failures != "collect":
        return future.result()
    try:
        return future.result()
    except Exception as exc:  # noqa: BLE001
        return ChunkFailed(failure_reason(exc))


def _run_processes(fn, chunks, workers, done, failures, bar):
    """Chunks on local worker processes; on any interruption the workers are stopped first.
    ``bar`` (a progress Tracker) hears the runs the workers report as they finish."""
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor, as_completed  # not for the CLI's signal handling
    from functools import partial

    from . import progress as _progress
    ctx = mp.get_context("fork") if hasattr(os, "fork") else None
    bar.listen_to_workers(ctx)
    ex = ProcessPoolExecutor(max_workers=min(workers, len(chunks)), mp_context=ctx, initializer=_worker_init,
                             initargs=(os.getpid(),))
    try:
        futs = {ex.submit(partial(_progress.call_in_chunk, fn, i), c): i for i, c in enumerate(chunks)}
        for f in as_completed(futs):
            done(futs[f], _outcome(f, failures))
        ex.shutdown(wait=True)
    except BaseException:
        stop_workers(ex)
        raise


def stop_workers(executor, timeout=2.0):
    """Stop a ProcessPoolExecutor now: drop its queued work, terminate (SIGTERM, then SIGKILL
    after ``timeout`` s) and join every worker process, and make its manager thread end.  No
    worker outlives this call, and the interpreter's exit does not wait for the executor.

    Why the manager thread needs help: it reads the workers' results from one pipe, a message
    at a time.  A worker killed while writing its result (a grid member's is megabytes, written
    in pieces as the thread reads them) leaves half a message, and the thread waits in
    ``recv()`` for the rest forever: this process holds the pipe's write end too (the queue was
    made here), so no end-of-file comes.  concurrent.futures joins that thread at exit
    (``_python_exit``, then threading's join of non-daemon threads): SIGTERM during a grid
    wrote the partial result, then hung at exit (2 of 7 runs; one for 770 s).  Closing this
    process's copy of the write end once the workers are dead ends the read (EOF): the thread
    marks the pool broken and returns."""
    procs = list((getattr(executor, "_processes", None) or {}).values())
    manager = getattr(executor, "_executor_manager_thread", None)
    result_queue = getattr(executor, "_result_queue", None)
    lock = getattr(executor, "_shutdown_lock", None)
    if lock is None or lock.acquire(timeout=1.0):  # not held by a submit() the signal cut short
        if lock is not None:
            lock.release()
        executor.shutdown(wait=False, cancel_futures=True)
    for p in procs:
        if p.is_alive():
            p.terminate()
    deadline = time.monotonic() + timeout
    for p in procs:
        p.join(max(0.0, deadline - time.monotonic()))
    for p in procs:
        if p.is_alive():
            p.kill()
            p.join(1.0)
    if result_queue is not None and not any(p.is_alive() for p in procs):
        try:
            result_queue._writer.close()
        except (AttributeError, OSError):
            pass
    if manager is not None and manager.is_alive():
        manager.join(timeout)
        if manager.is_alive():
            _abandon(manager)


_abandoned = []  # executor manager threads that did not end when their executor was stopped


def _abandon(thread):
    """Exit must not wait for ``thread`` (an executor's manager thread that did not end): take
    it off concurrent.futures' exit-time join and, where threading keeps its shutdown locks in
    a set (Python 3.10-3.12), off threading's join of non-daemon threads.  Otherwise (newer
    Pythons) :func:`leave_if_stuck` lets the command line leave without waiting for it."""
    import threading
    from concurrent.futures import process as _cfp
    _abandoned.append(thread)
    getattr(_cfp, "_threads_wakeups", {}).pop(thread, None)
    locks, guard = getattr(threading, "_shutdown_locks", None), getattr(threading, "_shutdown_locks_lock", None)
    tlock = getattr(thread, "_tstate_lock", None)
    if isinstance(locks, set) and guard is not None and tlock is not None:
        with guard:
            locks.discard(tlock)
        _abandoned.remove(thread)


def leave_if_stuck(code):
    """For the command line, after an interruption's partial result was written: if a stopped
    executor's thread could not be ended nor taken off the interpreter's exit-time joins,
    flush the output and leave now with ``code`` (exit would wait for that thread forever);
    otherwise return ``code``."""
    if any(t.is_alive() for t in _abandoned):
        import sys
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (OSError, ValueError):
                pass
        os._exit(code)
    return code


def _worker_init(parent_pid):
    """In each worker: ignore SIGINT (the parent handles Ctrl-C and stops the workers),
    default SIGTERM (how the parent stops them), and die with the parent (Linux)."""
    import signal
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    try:
        import ctypes
        libc = ctypes.CDLL(None, use_errno=True)
        PR_SET_PDEATHSIG = 1
        libc.prctl(PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0)
    except (OSError, AttributeError):  # not Linux: the parent's own cleanup still applies
        pass
    if os.getppid() != parent_pid:  # the parent died before prctl took effect
        os._exit(1)


NOT_RUN = "not run (interrupted)"


def member_results(n, where, results):
    """Chunk results -> one entry per member: ``where[i]`` the member indices of chunk i and
    ``results[i]`` its list of per-member results, a :class:`ChunkFailed` (every member of the
    chunk gets ``{'error': reason}``) or None (not run: ``{'error': NOT_RUN}``)."""
    out = [{"error": NOT_RUN} for _ in range(n)]
    for chunk, r in zip(where, results):
        for j, k in enumerate(chunk):
            if r is None:
                continue
            out[k] = {"error": r.reason} if isinstance(r, ChunkFailed) else r[j]
    return out


def finish_batch(res, interrupted=None):
    """Mark a batch result: status 'partial' when a member failed or did not run,
    ``members_done``; with ``interrupted`` (an Interrupted) raise it carrying the result."""
    failed = res.metadata.get("failed", [])
    n_not_run = sum(1 for _, why in failed if why == NOT_RUN)
    if failed:
        res.metadata["status"] = "partial"
    if interrupted is not None:
        res.metadata["members_done"] = f"{res.n_rows - n_not_run} of {res.n_rows} members finished"
        raise Interrupted.of(interrupted, partial=res) from None
    return res


# ---------------------------------------------------------------- the front's signal handler ----
_pending = []  # a signal that arrived inside compiled code, not yet raised
#: True once an Interrupted has been raised (by the handler or by check_interrupted): later
#: signals, among them the handler's own re-delivery of a kept one, are ignored while stopping
_stopping = [False]
_redeliver = []  # the timer that delivers a kept signal again (cancelled once it is raised)


def catch_signals():
    """Make SIGINT and SIGTERM raise :class:`~hemocircuit.errors.Interrupted` in the main thread
    (once: a second signal while stopping is ignored).  A signal that arrives while compiled
    (numba) code has called back into Python must not raise there (numba turns it into a
    SystemError or crashes): it is kept, raised by the next :func:`check_interrupted` (the
    compiled integrators' pieces call it) or delivered again shortly.  Returns the previous
    handlers for :func:`restore_signals`."""
    import signal
    _stopping[0] = False

    def handler(signum, frame):
        if _stopping[0]:
            return
        if frame is not None and f"{os.sep}numba{os.sep}" in frame.f_code.co_filename:
            _pending[:] = [signum]
            import threading
            again = threading.Timer(0.2, os.kill, (os.getpid(), signum))
            again.daemon = True
            _cancel_redelivery()
            _redeliver.append(again)
            again.start()
            return
        _stopping[0] = True
        _pending.clear()
        raise Interrupted(signum)

    previous = {}
    try:
        for sig in (signal.SIGINT, signal.SIGTERM):
            previous[sig] = signal.signal(sig, handler)
    except ValueError:  # not the main thread: leave the handlers alone
        pass
    return previous


def _cancel_redelivery():
    while _redeliver:
        _redeliver.pop().cancel()


def restore_signals(previous):
    import signal
    _pending.clear()
    _cancel_redelivery()  # a re-delivery after this would meet the default handler: killed, not 143
    for sig, h in previous.items():
        signal.signal(sig, h)


def check_interrupted():
    """Raise the Interrupted of a signal kept while compiled code ran (see catch_signals).
    From then on the process is stopping: the kept signal's re-delivery (0.2 s later) is
    ignored, instead of raising a second Interrupted inside the partial result's writing."""
    if _pending:
        signum = _pending.pop()
        _pending.clear()
        _stopping[0] = True
        _cancel_redelivery()
        raise Interrupted(signum)
