"""Compile part of a new engine in a second process while the first compiles the rest.

A first run compiles the Rosenbrock integrator and the functions it calls.  The integrator
calls the four large ones (prepare_static, rhs_into_at, local_jacobian_into_at,
release_fraction) through their addresses (kernels.pointers), so its compilation needs their
types only, and numba caches each function on its own.  So :func:`start` launches ``python -m
hemocircuit.kernels.prebuild`` (the job on its stdin), and the two processes compile at once:

* the helper: ``elem_derivs_jac`` and ``elem_derivs`` (the element kernels the Jacobian and the
  right-hand side call), then the integrator itself (``integrate_batch``, for the argument
  types of a single run: :func:`kernels.pointers.single_run`) with its small callees (the
  scratch makers, dense output, event location, the LU), then ``release_fraction``;
* this process (:func:`before_integrator`): ``prepare_static`` (the element kernels of the
  nodal solve, the effective parameters, the condensation), ``rhs_into_at`` and
  ``local_jacobian_into_at`` (loading the helper's element kernels from the cache), each for
  the signature the integrator calls it with; then it waits until the helper's integrator and
  release_fraction are in numba's cache and loads them (docs/performance.md, "Start-up and
  first compile", has the figures).

The helper then goes on with ``nodal_outputs`` (the outputs of a long run, which this process
reaches only after the integration) at a lower priority, so that on a busy machine it does not
slow this process.  If the helper fails or is later than WAIT_S, this process compiles what is
missing itself, as without it.
"""
from __future__ import annotations

import os
import pickle
import subprocess
import sys
from pathlib import Path

import numpy as np

from . import pointers

#: engine modules this process has decided for (a helper started or not needed: once per
#: module, whatever the systems and calls), and the helpers' processes (kept to be reaped)
_decided: set = set()
_helpers: list = []
#: engine module name -> its helper, until :func:`before_integrator` has split the first compile
_pending: dict = {}
#: how long a first run waits for the helper's integrator at most [s] (about twice what
#: compiling it here takes on the slowest machine measured)
WAIT_S = 60.0


def helper_env() -> dict:
    """The environment of a compile helper process: this one's, with numba's optimisation level
    and loop vectorizer switch as this process compiles with (hemocircuit/__init__.py), so that
    both compile the same code."""
    env = dict(os.environ)
    numba = sys.modules.get("numba")
    if numba is not None:
        env.update(NUMBA_OPT=str(int(numba.config.OPT)), NUMBA_LOOP_VECTORIZE=str(int(numba.config.LOOP_VECTORIZE)))
    return env


def start(system):
    """Start the helper for ``system``'s engine, once per engine module and process, unless
    the integrator (``integrate_batch``) is compiled here or in numba's cache already (or
    ``$HEMOCIRCUIT_PREBUILD`` is 0: the benchmark's switch).  Called before every first
    integration (CompiledSystem.integrate_batch) and earlier by ``tran --compile wait``; costs a
    set lookup after the first call.  Returns the process or None."""
    name = system.mod.__name__
    if name in _decided:
        return None
    _decided.add(name)
    fn = system.mod.integrate_batch
    if os.environ.get("HEMOCIRCUIT_PREBUILD", "1") == "0" or fn.overloads or in_cache(fn):
        return None
    _helpers[:] = [p for p in _helpers if p.poll() is None]
    job = pickle.dumps({"module": str(system.mod.__file__), "lay": system.lay, "nx": int(system.scales.size),
                        "nP": int(system.layout.n_params), "scales": system.scales, "lim_i": system.lim_i,
                        "lim_b": system.lim_b, "lim_r": system.lim_r})
    try:
        proc = subprocess.Popen([sys.executable, "-m", "hemocircuit.kernels.prebuild"], stdin=subprocess.PIPE,
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True,
                                close_fds=True, env=helper_env())
        proc.stdin.write(job)  # the job through its stdin: no file to leave behind
        proc.stdin.close()
    except OSError:
        return None
    _helpers.append(proc)
    _pending[name] = proc
    return proc


def before_integrator(system, rosenbrock=True):
    """Just before the first call of a compiled integrator in this process, when :func:`start`
    launched a helper for its engine: compile here the functions the Rosenbrock integrator calls
    through their addresses (prepare_static, rhs_into_at, local_jacobian_into_at,
    release_fraction, for the signatures of a single run: kernels.pointers), then wait while the
    helper is running until its integrator is in numba's cache (at most WAIT_S), so that this
    process loads it instead of compiling it a second time.  A BDF integrator (which calls its
    callees directly) compiles here, with the helper's element kernels.  Once per engine module
    and process."""
    import time

    proc = _pending.pop(system.mod.__name__, None)
    if proc is None or not rosenbrock:
        return
    mod = system.mod
    try:
        _, sigs = pointers.single_run(mod, system.lay, int(system.scales.size), int(system.layout.n_params),
                                      system.scales, system.lim_i, system.lim_b, system.lim_r)
        for name, sig in zip(pointers.NAMES[:3], sigs[:3]):  # release_fraction: the helper's
            getattr(mod, name).compile(sig.args)
    except Exception:  # noqa: BLE001 - only a head start: the integrator compiles what is missing
        pass
    end = time.monotonic() + WAIT_S
    while (proc.poll() is None and not (in_cache(mod.integrate_batch) and in_cache(mod.release_fraction))
           and time.monotonic() < end):
        time.sleep(0.05)


def in_cache(dispatcher) -> bool:
    """True when numba's on-disk cache holds some compilation of ``dispatcher`` (its index
    file exists; numba keeps one per function).  True as well when that cannot be told (another
    numba's internals): then no helper starts, as before there was one.  The index is
    ``MODULE.QUALNAME-LINE.pyXY<abiflags>.nbi`` in the cache's folder (numba.core.caching:
    '<' and '>' dropped from the name, LINE the function's first line, the disambiguator of
    numba's source-file locators): one stat, ~30 us, where a glob of the folder took ~13 ms
    in a cache of 13 000 files (a first run's wait for the helper polls this every 50 ms)."""
    try:
        folder = Path(dispatcher._cache.cache_path)
        code = dispatcher.py_func.__code__
        qualname = dispatcher.py_func.__qualname__
    except AttributeError:
        return True
    name = "{}.{}-{}.py{}{}{}.nbi".format(Path(code.co_filename).stem, qualname.replace("<", "").replace(">", ""),
                                         code.co_firstlineno, *sys.version_info[:2], getattr(sys, "abiflags", ""))
    return (folder / name).exists()


def helper_signatures(mod, lay, nx, n_params):
    """[(dispatcher, signature)] the helper compiles before the integrator: the element kernels
    the Jacobian and the right-hand side call, for one element's buffers as their callers pass
    them (the scratch tuples typed from the Python twins of make_work and make_jac_work; tested
    against the signatures a run's own compilation leaves)."""
    import numba

    work, jw = mod.make_work.py_func(lay), mod.make_jac_work.py_func(lay)
    # (k, pl, xl, ul, t, il, dl)
    elem = (numba.int64, numba.typeof(work.pl), numba.typeof(work.xl), numba.typeof(work.ul), numba.float64,
            numba.typeof(work.il), numba.typeof(work.dl))
    return [(mod.elem_derivs_jac, elem + (numba.typeof(jw.Jx), numba.typeof(jw.Ju))), (mod.elem_derivs, elem)]


def _run() -> int:
    import importlib.util

    import numba

    spec = pickle.load(sys.stdin.buffer)
    path = Path(spec["module"])
    loader = importlib.util.spec_from_file_location(path.stem, path)
    mod = importlib.util.module_from_spec(loader)
    sys.modules[path.stem] = mod
    loader.loader.exec_module(mod)
    # first the element kernels the Jacobian and the right-hand side call, while the first
    # process compiles the ones the nodal solve calls (prepare_static): its Jacobian then loads
    # them from the cache; then the integrator, which the first process waits for
    for fn, sig in helper_signatures(mod, spec["lay"], spec["nx"], spec["nP"]):
        fn.compile(sig)
    types, sigs = pointers.single_run(mod, spec["lay"], spec["nx"], spec["nP"], spec["scales"], spec["lim_i"],
                                      spec["lim_b"], spec["lim_r"])
    mod.integrate_batch.compile(types)
    # and the one of the integrator's callees the first process reaches last (it calls the
    # right-hand side, which that process has compiled by now)
    mod.release_fraction.compile(sigs[3].args)
    # then the outputs' nodal solve (CompiledSystem.nodal_outputs, with its argument types),
    # which the first process's run reaches only after the integration: at a lower priority,
    # so that on a busy machine it leaves the core to the integrator's compile
    try:
        os.nice(10)
    except OSError:
        pass
    v, m, P2 = numba.typeof(np.empty(1)), numba.typeof(np.empty((1, 1))), np.empty((1, spec["nP"]))
    P2.setflags(write=False)
    mod.nodal_outputs.compile((v, m, numba.typeof(P2), numba.typeof(spec["lay"]), m, m))
    return 0


if __name__ == "__main__":
    sys.exit(_run())
