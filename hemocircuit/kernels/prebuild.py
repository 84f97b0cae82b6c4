"""Compile part of a new engine in a second process while the first compiles the rest.

A first compilation of an engine is one numba compilation of the integrator, which types and
lowers every function it calls, one after the other, on one core.  Numba caches each function
on its own: when the integrator reaches a callee that is already in the cache for the same
argument types, it loads it instead of compiling it.  So :func:`start` launches ``python -m
hemocircuit.kernels.prebuild`` (the job on its stdin), and the two processes split the callees,
each compiling what the other does not need first:

* the helper: ``elem_derivs_jac`` and ``elem_derivs`` (the kernels only the Jacobian and the
  right-hand side call), then ``local_jacobian_into_at``, which by then loads the nodal solve's
  element kernels from this process's cache, then the Jacobian's scratch maker
  ``make_jac_work``, the Rosenbrock integrator's small callees (``hermite_root``, ``hermite``,
  ``stage_dense`` of kernels.dense, ``finish_member`` of kernels.runs: shared by every engine,
  so often in the cache already) and the evaluation's scratch maker ``make_work``; all by
  signature (:func:`helper_signatures`), the scratch buffers (named tuples) typed from the
  Python twins of the makers;
* this process (:func:`before_integrator`): ``prepare_static`` (the element kernels of the
  nodal solve, the effective parameters, the condensation) and ``rhs_into`` (loading
  ``elem_derivs`` from the helper's cache); then it waits for the helper's part before
  compiling the integrator itself, whose own body and final link are the one part that cannot
  be split (docs/performance.md, "Start-up and first compile", has the figures).

The helper then goes on with ``nodal_outputs`` (the outputs of a long run, which this process
reaches only after the integration) at a lower priority, so that on a busy machine it does not
slow the integrator's compile.  If the helper fails or is later than WAIT_S, the integrator
compiles what is missing itself, as without it.
"""
from __future__ import annotations

import glob
import os
import pickle
import subprocess
import sys
from pathlib import Path

import numpy as np


#: engine modules this process has decided for (a helper started or not needed: once per
#: module, whatever the systems and calls), and the helpers' processes (kept to be reaped)
_decided: set = set()
_helpers: list = []
#: engine module name -> its helper, until :func:`before_integrator` has split the first compile
_pending: dict = {}
#: how long the integrator's first compile waits for the helper's local Jacobian at most [s]
#: (about twice what compiling it here takes on the slowest machine measured)
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
    ``local_jacobian_into_at`` is compiled here or in numba's cache already (or
    ``$HEMOCIRCUIT_PREBUILD`` is 0: the benchmark's switch).  Called before every first
    integration (CompiledSystem.integrate_batch) and earlier by ``tran --compile wait``; costs a
    set lookup after the first call.  Returns the process or None."""
    name = system.mod.__name__
    if name in _decided:
        return None
    _decided.add(name)
    fn = system.mod.local_jacobian_into_at
    if os.environ.get("HEMOCIRCUIT_PREBUILD", "1") == "0" or fn.overloads or in_cache(fn):
        return None
    _helpers[:] = [p for p in _helpers if p.poll() is None]
    job = pickle.dumps({"module": str(system.mod.__file__), "lay": system.lay, "nx": int(system.scales.size),
                        "nP": int(system.layout.n_params)})
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
    launched a helper for its engine: compile the nodal solve and the right-hand side here
    (``prepare_static`` and ``rhs_into``, by the signatures the integrators call them with),
    and for a Rosenbrock integrator its callee ``release_fraction`` (which calls rhs_into: the
    helper, busy with the Jacobian, could not start it earlier; here it fills the time this
    process would wait for the helper), then wait while the helper is running until its
    ``local_jacobian_into_at`` and scratch makers are in numba's cache (at most WAIT_S), so that
    the integrator loads them instead of compiling them a second time.
    Without this the integrator reaches the Jacobian in its own typing order (make_work,
    prepare_static, rhs_into_at, local_jacobian_into_at) and compiled it itself whenever the helper was
    seconds late.  Once per engine module and process."""
    import time

    proc = _pending.pop(system.mod.__name__, None)
    if proc is None:
        return
    mod = system.mod
    try:
        import numba

        work = mod.make_work.py_func(system.lay)  # the scratch buffers' types, as make_work's compiled twin
        x, P = np.empty(int(system.scales.size)), np.empty(int(system.layout.n_params))
        P.setflags(write=False)  # a row of the integrators' read-only parameter matrix
        t, vx, lay = numba.float64, numba.typeof(x), numba.typeof(system.lay)
        sig_w = (t, vx, numba.typeof(P), lay, numba.typeof(work))
        mod.prepare_static.compile(sig_w)
        # the right-hand side proper: its layout and work tuples by reference (kernels.refs)
        mod.rhs_into_at.compile((t, vx, numba.typeof(P), numba.types.CPointer(lay),
                                 numba.types.CPointer(numba.typeof(work)), vx))
        if rosenbrock:  # (t, hh, tlim, x, f, xn, P, lay, work, lim_i, lim_b, lim_r, atol, held, xe, fe, xh, fh)
            f64 = numba.float64
            mod.release_fraction.compile((f64, f64, f64, vx, vx, vx) + sig_w[2:] + (
                numba.typeof(system.lim_i), numba.typeof(system.lim_b), numba.typeof(system.lim_r), vx,
                numba.typeof(np.zeros(1, dtype=np.bool_)), vx, vx, vx, vx))
    except Exception:  # noqa: BLE001 - only a head start: the integrator compiles what is missing
        pass
    # the helper's part the integrator reaches first, in the helper's order
    helpers = (mod.local_jacobian_into_at, mod.make_jac_work, mod.make_work)
    end = time.monotonic() + WAIT_S
    while proc.poll() is None and not all(in_cache(f) for f in helpers) and time.monotonic() < end:
        time.sleep(0.05)


def in_cache(dispatcher) -> bool:
    """True when numba's on-disk cache holds some compilation of ``dispatcher`` (its index
    file exists; numba keeps one per function).  True as well when that cannot be told (another
    numba's internals): then no helper starts, as before there was one.  The index is
    ``MODULE.QUALNAME-DISAMBIGUATOR.pyXY.nbi`` in the cache's folder (numba.core.caching)."""
    try:
        folder = Path(dispatcher._cache.cache_path)
        py = dispatcher.py_func
    except AttributeError:
        return True
    stem = f"{Path(py.__code__.co_filename).stem}.{py.__qualname__.replace('<locals>', '')}-"
    return any(folder.glob(glob.escape(stem) + "*.nbi"))


def helper_signatures(mod, lay, nx, n_params):
    """[(dispatcher, signature)] the helper compiles, in its order: the argument types its
    callers (local_jacobian_into_at, rhs_into_at, integrate_batch) pass, the scratch tuples typed
    from the Python twins of make_work and make_jac_work (tested against the signatures the
    integrator's own compilation leaves)."""
    import numba

    x, P = np.empty(nx), np.empty(n_params)
    P.setflags(write=False)  # integrate_batch's P is a read-only view (np.broadcast_to) in a single run
    vx, J = numba.typeof(x), numba.typeof(np.empty((1, 1)))
    work, jw = mod.make_work.py_func(lay), mod.make_jac_work.py_func(lay)
    ref = numba.types.CPointer  # the tuples by reference (kernels.refs)
    # one element's buffers as the callers pass them: (k, pl, xl, ul, t, il, dl)
    elem = (numba.int64, numba.typeof(work.pl), numba.typeof(work.xl), numba.typeof(work.ul), numba.float64,
            numba.typeof(work.il), numba.typeof(work.dl))
    return [(mod.elem_derivs_jac, elem + (numba.typeof(jw.Jx), numba.typeof(jw.Ju))),
            (mod.elem_derivs, elem),
            (mod.local_jacobian_into_at, (numba.float64, vx, numba.typeof(P), ref(numba.typeof(lay)),
                                          ref(numba.typeof(work)), ref(numba.typeof(jw)), vx, J, vx, numba.boolean, vx,
                                          numba.boolean)),
            (mod.make_jac_work, (numba.typeof(lay),)),
            # the Rosenbrock integrator's own small callees (event location, dense output, the
            # end of a member's run), which the first process reaches ~1 s into its compile
            (mod.hermite_root, (numba.float64,) * 4),
            (mod.hermite, (vx, vx, vx, vx, numba.float64, numba.float64, vx)),
            (mod.stage_dense, (vx, vx, J, numba.int64, numba.float64, vx)),
            (mod.finish_member, (J, numba.int64, J, numba.int64, numba.int64, numba.float64)
             + (numba.int64,) * 4)]


def _run() -> int:
    import importlib.util

    import numba

    spec = pickle.load(sys.stdin.buffer)
    path = Path(spec["module"])
    loader = importlib.util.spec_from_file_location(path.stem, path)
    mod = importlib.util.module_from_spec(loader)
    sys.modules[path.stem] = mod
    loader.loader.exec_module(mod)
    # first the element kernels only the Jacobian and the right-hand side call, while the first
    # process compiles the ones the nodal solve calls (prepare_static), which the Jacobian then
    # loads from the cache instead of compiling them at the same time; the scratch makers after
    # the Jacobian (the first process compiles prepare_static and rhs_into meanwhile, the
    # longer part)
    for fn, sig in helper_signatures(mod, spec["lay"], spec["nx"], spec["nP"]):
        fn.compile(sig)
    mod.make_work.compile((numba.typeof(spec["lay"]),))  # the last the first process waits for
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
