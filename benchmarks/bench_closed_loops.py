"""The decomposed closed-loop heart (netlists/svzerod/closedLoopHeart_singleVessel_decomposed.json)
over 30 beats: our steps, time and error at several tolerances against our own run at rtol
1e-9 (their solver gives no converged reference: it stops, see below), and svZeroDSolver's own
run of the same 30 beats at their step and finer (when ``svzerod`` or ``pysvzerod`` is
importable: the PyPI wheel, or their source built as docs/performance.md says).

    python benchmarks/bench_closed_loops.py [--rtols 1e-4 1e-5 1e-6] [--theirs 1 2 5 10]

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


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rtols", type=float, nargs="+", default=[1e-4, 1e-5, 1e-6])
    ap.add_argument("--theirs", type=int, nargs="*", default=[1, 2, 5, 10],
                    help="their runs at 1000 x these points per cycle")
    args = ap.parse_args(argv)
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
