"""Running batches: local processes (default), in-process, or a Dask cluster.

A batch job is split into chunks; each chunk is ONE vectorised batch (a circuit with a batch
of parameter sets, integrated together), so a worker pays Python overhead once per step for
its whole chunk.  Chunks go to worker processes (``concurrent.futures``) or to Dask
(``scheduler='tcp://HOST:PORT'``, extra ``hemocircuit[distributed]``).  A member's numbers do
not depend on which chunk or executor ran it (the batched integrator works member by member),
so results are identical whichever executor ran them.  A failing member is recorded with its
reason and does not lose the others.
"""
from __future__ import annotations

import os
from concurrent.futures import ProcessPoolExecutor, as_completed

from .errors import HemocircuitError


def default_workers() -> int:
    return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1))


def split(items, n_chunks):
    """Split a list into at most n_chunks contiguous, nearly equal chunks (order kept)."""
    n = len(items)
    n_chunks = max(1, min(n_chunks, n))
    bounds = [round(k * n / n_chunks) for k in range(n_chunks + 1)]
    return [items[bounds[k]:bounds[k + 1]] for k in range(n_chunks) if bounds[k + 1] > bounds[k]]


def run_chunks(fn, chunks, scheduler=None, workers=None, progress=None, desc="runs", sizes=None):
    """[fn(chunk) for chunk in chunks], in order, on the chosen executor.

    scheduler: None / 'processes' (local worker processes), 'serial' (this process), a Dask
    scheduler address 'tcp://HOST:PORT', or a dask.distributed Client.
    progress: a bar counting runs (:class:`hemocircuit.progress.Tracker`); ``sizes[i]`` is the
    number of runs in chunk i (default 1 each); ``fn`` may report runs as they finish with
    :func:`hemocircuit.progress.advance`.
    """
    from functools import partial

    from . import progress as _progress

    workers = workers or default_workers()
    results = [None] * len(chunks)
    with _progress.Tracker(sizes or [1] * len(chunks), desc, progress) as bar:
        def done(i, r):
            results[i] = r
            bar.chunk_done(i)

        if scheduler == "serial" or (scheduler in (None, "processes") and (workers == 1 or len(chunks) == 1)):
            for i, c in enumerate(chunks):
                done(i, _progress.call_in_chunk(fn, i, c))
        elif scheduler in (None, "processes"):
            import multiprocessing as mp
            ctx = mp.get_context("fork") if hasattr(os, "fork") else None
            bar.listen_to_workers(ctx)
            with ProcessPoolExecutor(max_workers=min(workers, len(chunks)), mp_context=ctx) as ex:
                futs = {ex.submit(partial(_progress.call_in_chunk, fn, i), c): i for i, c in enumerate(chunks)}
                for f in as_completed(futs):
                    done(futs[f], f.result())
        else:
            client = _dask_client(scheduler)
            futs = client.map(fn, chunks, pure=False)
            from dask.distributed import as_completed as das_completed
            index = {f.key: i for i, f in enumerate(futs)}
            for f in das_completed(futs):
                done(index[f.key], f.result())
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
