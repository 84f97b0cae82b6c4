"""Build a circuit's compiled engine in a background process while the first run goes on.

Compiling an engine for a new set of component types takes 20-45 s on 2 cores (see
docs/performance.md).  ``hemocircuit tran`` does not wait for it: when the engine is not
built yet it starts this module as a detached process (``python -m
hemocircuit.kernels.background JOB``), integrates on the scipy path meanwhile, and hands the
rest of the run over to the compiled engine as soon as the build reports ready
(hemocircuit.analyses.transient).  Later runs find the engine built and use it from the start.

Files, beside the engine module in the cache folder (:func:`freshness.cache_dir`):
  ``<engine>.ready-<N>``   the transient entry points are compiled and in numba's cache
                           (N: a hash of ``NUMBA_CACHE_DIR``, where that cache lives)
  ``<engine>.building-<N>`` a build is running (its process id; stale when that process is gone)
  ``<engine>.failed-<N>``  the last build failed (its log): no more background builds are
                           started; runs compile in the foreground, which shows the error
  ``<engine>.build.log``   the builder's output
A marker is only a hint: if it is wrong, a run compiles in the foreground as without it.
"""
from __future__ import annotations

import hashlib
import os
import pickle
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from .prebuild import helper_env

#: simulated time [s] of the builder's run: enough to call every transient entry point
BUILD_RUN = 1e-6


#: the markers' paths by engine module, kind and NUMBA_CACHE_DIR: every compiled run asks
#: for its ready marker (building the path took ~40 us of a small circuit's ~1 ms run)
_markers: dict = {}


def _marker(system, kind: str) -> Path:
    numba_dir = os.environ.get("NUMBA_CACHE_DIR", "")
    key = (system.mod.__file__, kind, numba_dir)
    path = _markers.get(key)
    if path is None:
        tag = hashlib.sha256(numba_dir.encode()).hexdigest()[:8]
        mod = Path(system.mod.__file__)
        path = _markers[key] = mod.with_name(f"{mod.stem}.{kind}-{tag}")
    return path


def ready(system) -> bool:
    """True when this system's engine has been compiled for transient runs (marker present)."""
    return _marker(system, "ready").exists()


def mark_ready(system) -> None:
    """Record that the transient entry points of ``system``'s engine are compiled (a marker
    already there is left as it is: every compiled run ends here)."""
    marker = _marker(system, "ready")
    if marker.exists():
        return
    try:
        marker.touch()
    except OSError:  # a read-only cache folder: later runs compile (or load) in the foreground
        pass


def failed(system) -> bool:
    return _marker(system, "failed").exists()


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's process: alive
        return True
    return True


def building(system) -> bool:
    """True while a build process for this engine runs (its marker names a live process)."""
    path = _marker(system, "building")
    try:
        pid = int(path.read_text().strip() or 0)
    except (OSError, ValueError):
        return False
    return pid > 0 and _alive(pid)


def start(system, circuit, x0, t0: float, rtol: float) -> bool:
    """Start a background build of ``system``'s engine (unless one runs).  ``circuit`` (one
    parameter set), ``x0`` and ``t0``: what the builder integrates for BUILD_RUN seconds.
    Returns False when no build can run (the last one failed, or the cache folder is not
    writable): the caller then compiles in the foreground."""
    if failed(system):
        return False
    if building(system):
        return True
    job = Path(system.mod.__file__).with_suffix(f".{os.getpid()}.job")
    log = Path(system.mod.__file__).with_suffix(".build.log")
    try:
        with open(job, "wb") as fh:
            pickle.dump({"circuit": circuit, "x0": np.asarray(x0, dtype=float), "t0": float(t0),
                         "rtol": float(rtol)}, fh)
        with open(log, "ab") as out:
            proc = subprocess.Popen([sys.executable, "-m", "hemocircuit.kernels.background", str(job)],
                                    stdin=subprocess.DEVNULL, stdout=out, stderr=out, start_new_session=True,
                                    close_fds=True, env=helper_env())
        _marker(system, "building").write_text(str(proc.pid))
    except (OSError, pickle.PicklingError, TypeError, AttributeError):
        job.unlink(missing_ok=True)
        return False
    return True


def _build(job: Path) -> int:
    """The builder (in its own process): the transient run the foreground would make, for
    BUILD_RUN seconds, so that numba compiles and caches the same specialisations."""
    from ..analyses.compiled_run import simulate_compiled
    from .system import CompiledSystem

    with open(job, "rb") as fh:
        spec = pickle.load(fh)
    job.unlink(missing_ok=True)
    c = spec["circuit"]
    system = CompiledSystem.of(c)
    if system is None:
        print(f"{time.strftime('%Y-%m-%d %H:%M:%S')} nothing to build: the circuit has no compiled engine",
              flush=True)
        return 1
    started = time.perf_counter()
    print(f"{time.strftime('%Y-%m-%d %H:%M:%S')} building {Path(system.mod.__file__).stem}", flush=True)
    try:
        simulate_compiled(system, c, spec["x0"], spec["t0"], spec["t0"] + BUILD_RUN, None, [], spec["rtol"],
                           None, np.inf, None)
        # and the outputs' nodal solve, which a long run's outputs use (its few rows here do not)
        system.nodal_outputs(np.full(1, spec["t0"]), np.asarray(spec["x0"], dtype=float)[None], system.params(c))
    except Exception as exc:  # noqa: BLE001 - recorded; the foreground then shows it itself
        _marker(system, "failed").write_text(f"{type(exc).__name__}: {exc}\n")
        print(f"failed: {type(exc).__name__}: {exc}", flush=True)
        return 1
    finally:
        _marker(system, "building").unlink(missing_ok=True)
    mark_ready(system)
    print(f"{time.strftime('%Y-%m-%d %H:%M:%S')} ready after {time.perf_counter() - started:.1f} s", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(_build(Path(sys.argv[1])))
