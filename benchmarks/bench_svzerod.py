"""Our in-process solve time against svZeroDSolver's on their five timed test cases.

    python benchmarks/bench_svzerod.py [--folder ../shared/svzerod] [--repeat 7] [--case NAME]

Reads the cases and their times (the README's speed table: Release build, in-process
``pysvzerod.simulate``, median of 5) from a folder laid out like ``../shared/svzerod/``; skips
when it is absent.  Ours: the conformance runner's solve (hemocircuit.svzerod.conformance:
operating point, their initial condition or, for a case that keeps its start, their
steady_initial procedure, then the transient at the case's integrator tolerance, rows of the
cycles they write), after one untimed run that loads the compiled
engine and the compiled loops of its outputs (and a wait until no compile helper of it runs,
bench_startup.wait_for_helpers); loading the model and compiling are excluded, as in theirs.  Prints the median and
minimum wall time, the median CPU time, the ratios of our median wall and CPU times to the
middle of their range, and the accuracy of the timed run: its largest error against their
converged results (``converged/``, relative to each variable's range, as the conformance
runner) next to the acceptance tolerance of the case.  The machine is shared: the load
average is printed, and under load the CPU times are the figures to read.

Where their Python module is importable (``pysvzerod`` built from their source, or ``svzerod``
from their PyPI wheel, ``pip install svzerod``; not a dependency of this project), their solver is also timed here, in this process, on the same
JSON (``pysvzerod.simulate``: one untimed call, then ``--repeat`` rounds of one run of ours and one
of theirs, medians of each), and the ratios are to that side-by-side time ("here"); the README's
figure stays in its column.

``--matched`` (needs their module) adds their accuracy-matched time: their solver at 1, 2, 3, 5 and 7
times the case's points per cycle (conformance.compare_their_rows against ``converged/``, by
the runner's rules), the first that meets the case's tolerance, and our time over theirs
there: ours and theirs at that step timed again in turn, in the same rounds, as the
side-by-side column is (their multiples' own column times each alone).  Where none does, their
time at 10x (the converged run itself, so exact by construction) bounds what it needs from
above and the 7x time from below, and our side-by-side time over those two bounds the ratio.

The periodic steady state by shooting (``shooting_rows``) on closedLoopHeart_singleVessel and
the decomposed heart of netlists/svzerod, against their 10 cycles at their step and at their
first step meeting the tolerance.
"""
from __future__ import annotations

import argparse
import json
import os
import re
import sys

import numpy as np

from bench_startup import wait_for_helpers  # (this folder is on the path of a script run from it)

HERE = os.path.dirname(os.path.abspath(__file__))
TIMED = ("steadyFlow_R_RCR", "pulsatileFlow_R_RCR", "pulsatileFlow_R_coronary", "closedLoopHeart_singleVessel",
         "chamber_elastance_inductor")


def their_ms(text):
    """'7.0-7.8 ms' -> 7.4 (the middle of the range), '18.5 ms' -> 18.5."""
    nums = [float(x) for x in re.findall(r"[\d.]+", text)]
    return float(np.mean(nums)) if nums else float("nan")


def their_module():
    """Their Python module: ``pysvzerod`` (built from source) or ``svzerod`` (their PyPI wheel),
    or None."""
    for name in ("pysvzerod", "svzerod"):
        try:
            return __import__(name)
        except ImportError:
            pass
    return None


def time_theirs(cfg, repeat):
    """Median wall time [ms] of their in-process solve of ``cfg``, or None without their module."""
    pysvzerod = their_module()
    if pysvzerod is None:
        return None
    import time
    pysvzerod.simulate(cfg)
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        pysvzerod.simulate(cfg)
        times.append(time.perf_counter() - t0)
    return float(np.median(times)) * 1e3


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--folder", default=os.path.join(HERE, "..", "..", "shared", "svzerod"))
    ap.add_argument("--repeat", type=int, default=7)
    ap.add_argument("--case", action="append")
    ap.add_argument("--matched", action="store_true",
                    help="also time their solver at finer steps, to the case's tolerance (needs their module)")
    args = ap.parse_args(argv)
    folder = os.path.abspath(args.folder)
    if not os.path.isdir(os.path.join(folder, "cases")):
        print(f"no svZeroDSolver cases in {folder}: skipped")
        return 0
    from hemocircuit.svzerod.conformance import compare, read_result, simulate_case, their_times
    from hemocircuit.svzerod.tolerances import case_rtol, tolerances
    from hemocircuit.svzerod.importer import guess_units, import_svzerod

    from hemocircuit import elementwise
    # compiling is excluded, as in theirs: the untimed first run of each case also compiles the
    # compiled loops its outputs' element groups use (from 64 rows on), which a process makes
    # itself after elementwise.LOOP_COMPILE_CALLS element calls, or finds in numba's cache
    elementwise.LOOP_COMPILE_CALLS = 0
    theirs = their_times(os.path.join(folder, "README.md"))
    print("load average %.1f %.1f %.1f" % os.getloadavg())
    print(f"{'case':30s} {'rtol':>6s} {'ours median':>12s} {'min':>9s} {'CPU':>9s} {'theirs':>12s} "
          f"{'here':>9s} {'wall x':>6s} {'CPU x':>6s} {'err P / Q vs converged':>22s} {'tol':>6s}")
    matched = []
    for name in args.case or TIMED:
        path = os.path.join(folder, "cases", f"{name}.json")
        with open(path) as fh:
            cfg = json.load(fh)
        model = import_svzerod(path, units=guess_units(cfg))
        simulate_case(model)  # loads (or compiles) the engine
        wait_for_helpers()  # a compile's helper runs on at nice 10 (the outputs' nodal solve)
        res, keep, t_out, times, here = alternate(model, cfg, args.repeat)
        # a model without states gives its outputs (a dict), not a result with metadata
        rtol = getattr(res, "metadata", {}).get("conformance", {}).get("rtol", case_rtol(model))
        err = "-"
        conv = os.path.join(folder, "converged", f"result_{name}.json")
        if os.path.isfile(conv):
            e_p, e_q, _, _ = compare(model, res, keep, t_out, read_result(conv))
            err = f"{e_p:.1e} / {e_q:.1e}"
        wall, cpu = np.median(times, axis=0) * 1e3
        ref = theirs.get(name, "")
        base = their_ms(ref) if here is None else here
        here_s = "-" if here is None else f"{here:.2f} ms"
        print(f"{name:30s} {rtol:6.0e} {wall:9.2f} ms {times[:, 0].min() * 1e3:6.2f} ms {cpu:6.2f} ms "
              f"{ref:>12s} {here_s:>9s} {wall / base:6.2f} {cpu / base:6.2f} {err:>22s} "
              f"{tolerances(name, model)[0]:6.0e}")
        if args.matched and here is not None and os.path.isfile(conv):
            rows = matched_row(model, cfg, read_result(conv), args.repeat)
            matched.append((name, wall, rows, matched_in_turn(model, cfg, rows, args.repeat)))
    firsts = {}
    if matched:
        firsts = print_matched(matched)
    if "closedLoopHeart_singleVessel" in (args.case or TIMED):
        shooting_rows(folder, args.repeat, firsts)
    print("load average %.1f %.1f %.1f" % os.getloadavg())
    return 0


def alternate(model, cfg, repeat):
    """Ours (the conformance runner's solve) and theirs (``pysvzerod.simulate``) in turn, one
    run each a round, after one untimed run of each: a host whose speed drifts slows both
    alike.  (our result, its rows and times as simulate_case, our times (repeat, 2) [s],
    their median wall time [ms] or None without their module)."""
    import time

    from hemocircuit.svzerod.conformance import simulate_case

    pysvzerod = their_module()
    their = []

    def theirs():
        t0 = time.perf_counter()
        pysvzerod.simulate(cfg)
        their.append(time.perf_counter() - t0)

    if pysvzerod is not None:
        pysvzerod.simulate(cfg)
    res, keep, t_out, ours = simulate_case(model, timed_runs=repeat, between=theirs if pysvzerod else None)
    return res, keep, t_out, ours, (float(np.median(their)) * 1e3 if their else None)


MULTIPLES = (1, 2, 3, 5, 7, 10)


def matched_row(model, cfg, converged, repeat):
    """[(multiple, their median wall time [ms], err P, err Q, meets the tolerance)] of their
    solver at MULTIPLES of the case's points per cycle (N -> k (N - 1) + 1: every output time
    of the case kept), against their converged rows."""
    pysvzerod = their_module()
    from hemocircuit.svzerod.conformance import compare_their_rows, parse_result
    from hemocircuit.svzerod.tolerances import tolerances

    tol_p, tol_q = tolerances(model.name, model)
    n = cfg["simulation_parameters"]["number_of_time_pts_per_cardiac_cycle"]
    rows = []
    for k in MULTIPLES:
        c = json.loads(json.dumps(cfg))
        c["simulation_parameters"]["number_of_time_pts_per_cardiac_cycle"] = k * (n - 1) + 1
        ms = time_theirs(c, repeat)
        e_p, e_q = compare_their_rows(model, parse_result(json.loads(pysvzerod.simulate(c).to_json())), converged)
        rows.append((k, ms, e_p, e_q, e_p <= tol_p and e_q <= tol_q))
    return rows


def matched_in_turn(model, cfg, rows, repeat):
    """(our median, their median) [ms] of our solve (as always, at the case's tolerance) and
    theirs at their first multiple meeting the tolerance (rows: matched_row's), timed in turn
    in the same rounds (alternate), as the
    side-by-side column is: a separate run of theirs alone finds its caches warm (the steady
    case: 1.4 ms alone against 1.8-2.0 ms in turn with ours).  None where no multiple below
    the converged run meets it."""
    first = next((r for r in rows[:-1] if r[4]), None)
    if first is None:
        return None
    c = json.loads(json.dumps(cfg))
    n = c["simulation_parameters"]["number_of_time_pts_per_cardiac_cycle"]
    c["simulation_parameters"]["number_of_time_pts_per_cardiac_cycle"] = first[0] * (n - 1) + 1
    _, _, _, ours, theirs = alternate(model, c, repeat)
    return float(np.median(ours[:, 0])) * 1e3, theirs


def print_matched(matched):
    """Print the matched table; {case: their first multiple meeting the tolerance}."""
    firsts = {}
    print("\ntheir solver at finer steps, against converged/ (x10 is the converged run itself)")
    print(f"{'case':30s} " + " ".join(f"{'x%d ms / err P, Q' % k:>24s}" for k in MULTIPLES)
          + f" {'matched':>8s} {'ours, theirs in turn':>22s} {'ours x':>7s}")
    for name, wall, rows, in_turn in matched:
        cells = " ".join(f"{ms:7.1f} {e_p:7.1e} {e_q:7.1e}{'*' if ok else ' '}" for _, ms, e_p, e_q, ok in rows)
        first = next((r for r in rows[:-1] if r[4]), None)
        if first is not None:
            firsts[name] = first[0]
            ours, theirs = in_turn
            m, pair, ratio = f"x{first[0]}", f"{ours:.1f} / {theirs:.1f} ms", f"{ours / theirs:.2f}"
        else:  # between the last multiple that fails and the converged run (ours side by side, theirs alone)
            lo, hi = rows[-2][1], rows[-1][1]
            m, pair, ratio = "none", f"{wall:.1f} / {lo:.0f}-{hi:.0f} ms", f"{wall / hi:.2f}-{wall / lo:.2f}"
        print(f"{name:30s} {cells} {m:>8s} {pair:>22s} {ratio:>7s}")
    print("(* meets the case's tolerance; the matched ratio: ours over theirs at that step, timed in turn)")
    return firsts


#: the periodic state by shooting on these closed loops: (case file, their cases folder or None
#: for this repository's netlists/svzerod, rtol: the case's (svzerod.tolerances.case_rtol))
SHOOTING = (("closedLoopHeart_singleVessel", "cases"),
            ("closedLoopHeart_singleVessel_decomposed", None))


def shooting_rows(folder, repeat, matched, tol=1e-5):
    """The periodic steady state of each SHOOTING closed loop by Anderson-accelerated shooting
    (analyses.periodic.shoot, method='anderson', no multipliers) from their initial condition
    at the case's rtol (svzerod.tolerances.case_rtol), to a residual ``tol`` (scaled x(T) - x(0);
    below the residual their 10 cycles leave, printed beside it), its orbit's output included.  Printed beside it: the orbit's largest distance
    from a tight orbit (rtol 1e-9, residual 1e-9) relative to each state's range over the cycle
    (the case's tolerance is 1e-2 of the range); the residual their 10 cycles leave, cycle by
    cycle with our integrator at the same rtol; their 10 cycles at their step and, where the
    matched table found it, at their first step meeting the case's tolerance.  Where their
    solver stops before 10 cycles, its time to the failure and its time per cycle."""
    import time

    from hemocircuit.analyses.periodic import _flow, shoot
    from hemocircuit.ic import apply_ic
    from hemocircuit.svzerod import import_svzerod, load_svzerod
    from hemocircuit.svzerod.tolerances import case_rtol

    for name, sub in SHOOTING:
        base = os.path.join(folder, sub) if sub else os.path.join(HERE, "..", "netlists", "svzerod")
        path = os.path.join(base, f"{name}.json")
        if not os.path.isfile(path):
            continue
        c, model = load_svzerod(path, units="mmHg"), import_svzerod(path, units="mmHg")
        x0 = apply_ic(c, np.zeros(c.nx), model.initial)
        S, T, rtol = c.state_scales, model.period, case_rtol(model)
        run = lambda r=rtol, t=tol: shoot(c, x0, T, forced=True, rtol=r, tol=t, max_iter=30,  # noqa: E731
                                          method="anderson", multipliers=False, progress=False)
        with open(path) as fh:
            cfg = json.load(fh)
        cfg["simulation_parameters"]["number_of_cardiac_cycles"] = 10
        orb = run()
        wait_for_helpers()
        time_theirs_or_failure(cfg, 1, warm=False)  # their first run in this process: untimed
        times, at_step = [], []  # ours, and theirs at their step in the same rounds
        for _ in range(repeat):
            t0 = time.perf_counter()
            orb = run()
            times.append(time.perf_counter() - t0)
            at_step.append(time_theirs_or_failure(cfg, 1, warm=False))
        ref = run(1e-9, 1e-9)
        span = np.ptp(ref.x, axis=0)
        moving = span > 1e-9 * S
        err = float(np.max(np.abs(orb.x - ref.x)[:, moving] / span[moving]))
        x = x0.copy()
        for _ in range(9):
            x = _flow(c, x[None], np.array([T]), rtol=rtol)[0][0]
        x10 = _flow(c, x[None], np.array([T]), rtol=rtol)[0][0]
        ms = float(np.median(times)) * 1e3
        print(f"\nshooting {name} (anderson, rtol {rtol:g}): {ms:.1f} ms, {orb.iterations} periods, residual "
              f"{orb.residual:.1e}, orbit {err:.1e} of the range off the rtol 1e-9 orbit (their 10 cycles leave "
              f"a residual {np.max(np.abs((x10 - x) / S)):.1e} at this rtol)")
        if at_step[0][0] is None:
            print("  their module is not importable: no side-by-side time")
            continue
        for k in sorted({1, matched.get(name, 1)}):
            c10 = json.loads(json.dumps(cfg))
            n = c10["simulation_parameters"]["number_of_time_pts_per_cardiac_cycle"]
            c10["simulation_parameters"]["number_of_time_pts_per_cardiac_cycle"] = k * (n - 1) + 1
            theirs, failed = ((float(np.median([ms_k for ms_k, _ in at_step])), at_step[0][1]) if k == 1
                              else time_theirs_or_failure(c10, repeat))
            if failed is None:
                print(f"  their 10 cycles at x{k} their step: {theirs:.1f} ms; ours x{ms / theirs:.2f}")
            else:
                print(f"  their 10 cycles at x{k} their step: stop at t = {failed:.2f} s ({failed / T:.1f} cycles) "
                      f"after {theirs:.1f} ms, {theirs / (failed / T):.1f} ms a cycle; ours against 10 of those "
                      f"cycles x{ms / (10 * theirs / (failed / T)):.2f}")


def time_theirs_or_failure(cfg, repeat, warm=True):
    """(median wall time [ms], None) of their solve of ``cfg`` (after one untimed run when
    ``warm``), or (time to their failure [ms], the time t [s] their solver reports it stopped
    at); (None, None) without their module."""
    import time

    pysvzerod = their_module()
    if pysvzerod is None:
        return None, None
    times = []
    for _ in range(repeat + int(warm)):
        t0 = time.perf_counter()
        try:
            pysvzerod.simulate(cfg)
        except RuntimeError as exc:
            found = re.search(r"time ([\d.]+)", str(exc))
            return (time.perf_counter() - t0) * 1e3, float(found.group(1)) if found else float("nan")
        times.append(time.perf_counter() - t0)
    return float(np.median(times[int(warm):])) * 1e3, None


if __name__ == "__main__":
    sys.exit(main())
