"""The decomposed closed-loop heart (netlists/svzerod/closedLoopHeart_singleVessel_decomposed.json)
over 30 beats: our steps, time and error at several tolerances against our own run at rtol
1e-9 (their solver gives no converged reference: it stops, see below), and svZeroDSolver's own
run of the same 30 beats at their step and finer (when ``svzerod`` or ``pysvzerod`` is
importable: the PyPI wheel, or their source built as docs/performance.md says).

    python benchmarks/bench_closed_loops.py [--rtols 1e-4 1e-5 1e-6] [--theirs 1 2 5 10]
    python benchmarks/bench_closed_loops.py --jacobians   # the Jacobian's two ways, three beats

Errors: max over the last beat of |ours - reference| / the reference's range, worst over the
pressure columns (P) and the flow columns (Q) separately.  Times: wall seconds of one
in-process run each (outputs of the last beat only, 1000 rows)."""
from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
MODEL = os.path.join(ROOT, "netlists", "svzerod", "closedLoopHeart_singleVessel_decomposed.json")
PERIOD = 1.0169
BEATS = 30


def ours(rtol):
    from hemocircuit.analyses.transient import simulate
    from hemocircuit.svzerod import load_svzerod

    c = load_svzerod(MODEL, "mmHg")
    t0 = time.perf_counter()
    r = simulate(c, BEATS * PERIOD, dt=PERIOD / 1000, rtol=rtol, engine="compiled", progress=False,
                 output_from=(BEATS - 1) * PERIOD)
    return r, time.perf_counter() - t0


def worst(r, ref):
    out = {"P": 0.0, "Q": 0.0}
    for k in ref.data:
        if k[:2] not in ("P(", "Q("):
            continue
        b = np.asarray(ref[k])
        if np.ptp(b) > 0:
            out[k[0]] = max(out[k[0]], float(np.max(np.abs(np.asarray(r[k]) - b)) / np.ptp(b)))
    return out


def theirs(div):
    """(wall s, None) of their 30-cycle run at 1000 * div points per cycle, or (s, error)."""
    try:
        import pysvzerod as svz
    except ImportError:
        try:
            import svzerod as svz
        except ImportError:
            return None
    with open(MODEL) as fh:
        m = json.load(fh)
    sp = m["simulation_parameters"]
    sp.update(number_of_cardiac_cycles=BEATS, number_of_time_pts_per_cardiac_cycle=1000 * div,
              output_all_cycles=False)
    t0 = time.perf_counter()
    try:
        svz.simulate(m)
        return time.perf_counter() - t0, None
    except RuntimeError as exc:
        return time.perf_counter() - t0, str(exc)


def jacobian_rows(rtol=1e-6, periods=3, repeat=5):
    """The first ``periods`` beats from the netlist's start at ``rtol``, the state Jacobian
    composed element by element (the engine's default) against whole right-hand sides
    differenced (``local_jacobian=0``): in turn, medians of ``repeat`` calls of the compiled
    integrator each (CompiledSystem.integrate with the run's breakpoints, no outputs)."""
    from hemocircuit.analyses.transient import simulate
    from hemocircuit.kernels.system import CompiledSystem
    from hemocircuit.svzerod import load_svzerod

    c = load_svzerod(MODEL, "mmHg")
    x0 = simulate(c, 1e-3, dt=1e-3, engine="compiled", progress=False).x[0]  # the netlist's start
    system = CompiledSystem.of(c)
    P = system.params(c)[0]
    t_out = np.array([0.0, periods * PERIOD])
    breaks, kinks = c.jumps_and_kinks(0.0, periods * PERIOD)  # the activation's, as a run passes them
    times = {1: [], 0: []}
    stats = {}
    for lj in (1, 0):  # compiled (or loaded) outside the timings
        system.integrate(t_out, x0, P, rtol=rtol, breaks=breaks, kinks=kinks, local_jacobian=lj)
    for _ in range(repeat):
        for lj in (1, 0):
            t0 = time.perf_counter()
            _, stats[lj] = system.integrate(t_out, x0, P, rtol=rtol, breaks=breaks, kinks=kinks, local_jacobian=lj)
            times[lj].append(time.perf_counter() - t0)
    print(f"\n{periods} beats from the start at rtol {rtol:g}")
    print(f"{'state Jacobian':>24s} {'step attempts':>14s} {'rejected':>9s} {'f evals':>8s} {'median ms':>10s}")
    for lj, name in ((1, "element by element"), (0, "whole right-hand sides")):
        s = stats[lj]
        print(f"{name:>24s} {s['steps']:14d} {s['rejected']:9d} {s['nfev']:8d} {np.median(times[lj]) * 1e3:10.1f}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rtols", type=float, nargs="+", default=[1e-4, 1e-5, 1e-6])
    ap.add_argument("--theirs", type=int, nargs="*", default=[1, 2, 5, 10],
                    help="their runs at 1000 x these points per cycle")
    ap.add_argument("--jacobians", action="store_true",
                    help="only the first three beats with each way of forming the state Jacobian")
    args = ap.parse_args(argv)
    if args.jacobians:
        jacobian_rows()
        return
    ours(1e-4)  # compile (or load) the engine outside the timings
    ref, t_ref = ours(1e-9)
    print(f"reference rtol 1e-9: {ref.stats['steps']} steps, {t_ref:.1f} s")
    print("rtol     steps  rejected  f evals    wall s   error P   error Q")
    for rtol in args.rtols:
        r, t = ours(rtol)
        e = worst(r, ref)
        s = r.stats
        print(f"{rtol:<7.0e} {s['steps']:6d} {s['rejected']:9d} {s['nfev']:8d} {t:9.2f} {e['P']:9.1e} {e['Q']:9.1e}")
    for div in args.theirs:
        got = theirs(div)
        if got is None:
            print("svZeroDSolver: not importable (pysvzerod or svzerod)")
            break
        t, err = got
        print(f"svZeroDSolver, {1000 * div} points per cycle: {t:.2f} s, " + (err or f"{BEATS} cycles done"))


if __name__ == "__main__":
    main()
