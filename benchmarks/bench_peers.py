"""hemocircuit against roadrunner (libroadrunner: SBML compiled by LLVM, CVODE), side by side in
one process, on the same scenarios.  The peer models are the hand-written Antimony files in
../shared/peers/ (see their README; not a project dependency:
``pip install libroadrunner==2.10.0 antimony==3.3.0``).

    python benchmarks/bench_peers.py                       # every scenario
    python benchmarks/bench_peers.py --only vasomotion     # one (repeatable flag)
    python benchmarks/bench_peers.py --only rhs --rr-repeats 9
    python benchmarks/bench_peers.py --method LSODA --engine compiled   # passed to the hemocircuit API

Scenarios (``--only`` names):
  vasomotion  8-state whole-brain model, Pa = 80 mmHg, 1000 s, output every 0.1 s, from the
              equilibrium with the radius raised by 0.1 %; solve time at each ``--rtols`` and the
              limit-cycle statistics over the last 300 s against the README's reference cycle.
  artcomp     arterial-compliance model, Pa = 80 mmHg, +10 % step + 10 % sine at 0.1 Hz for
              t > 0, 1000 s; solve time and the largest relative difference between the tools.
  envelope    hemocircuit's ``envelope`` analysis, 5 Pa (60..100 mmHg) x 2 zeta (0.1, 0.2),
              1000 s each, on ``--workers`` cores, against roadrunner doing the same 10 runs
              one by one (same start states, same rtol, same statistics).
  freq        hemocircuit's ``frequency_response``, 30 frequencies (0.001-1 Hz) x 2 tau_Ca
              (1 s, 10 s) on ``--workers`` cores, against roadrunner doing the same 60 runs
              one by one with freq.py's settle rule (blocks of whole periods, DFT); both tools'
              errors against an untimed roadrunner reference at ``--freq-ref-rtol``.
  rhs         one right-hand-side evaluation of the vasomotion circuit (``c.rhs(0, x)``), plus
              the compiled evaluator if the circuit offers one (see HOOK below).

Timing: medians over repeats.  roadrunner: ``resetAll()`` + (parameter/state settings) +
``simulate``; the Antimony load and LLVM compile are excluded and reported separately.
hemocircuit: the in-process call of the public API (``simulate``, ``envelope``,
``frequency_response``); ``load`` and the operating point are excluded and reported
separately (single runs); the batches are timed whole (their operating points, worker
processes and results included) after an untimed warm-up call on another circuit, the
counterpart of roadrunner's excluded load (``warm_up``; ``--cold-batches``: time the
process's first call instead).  Ratios are hemocircuit / roadrunner (> 1: hemocircuit is slower).

Output: a table on stdout and JSON in benchmarks/results/peers.json (with ``--only`` the
other scenarios already in the file are kept).  Only the public hemocircuit API is used, so
the script keeps working while the engine is rewritten.
"""
from __future__ import annotations

import argparse
import datetime
import inspect
import json
import os
import platform
import statistics
import subprocess
import sys
import time
import timeit

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
NET = os.path.join(ROOT, "netlists")
OUT = os.path.join(HERE, "results", "peers.json")
PEERS = os.path.normpath(os.path.join(ROOT, "..", "shared", "peers"))

sys.path.insert(0, ROOT)  # run from a checkout without installing

import hemocircuit as hc  # noqa: E402
from hemocircuit.analyses.envelope import envelope  # noqa: E402
from hemocircuit.analyses.freq import frequency_response  # noqa: E402
from hemocircuit.analyses.op import operating_point  # noqa: E402

try:
    from hemocircuit.units import PA_PER_MMHG  # noqa: E402
except ImportError:  # pint's conventional mmHg
    PA_PER_MMHG = 133.322387415

SCENARIOS = ("vasomotion", "artcomp", "envelope", "freq", "rhs")

# Reference cycle of ../shared/peers/README.md (scipy at rtol 1e-9, checked against roadrunner
# at 1e-9): Pa = 80 mmHg, 1000 s, output every 0.1 s, statistics over the last 300 s.
REF_CYCLE = {"r_min_um": 60.68080, "r_max_um": 102.03100, "r_mean_um": 81.59841, "period_s": 7.71301,
             "q2_mean_mLs": 9.44802}
REF_RESETS = 118
ACCEPT = 1e-3  # relative, the issue's acceptance for the cycle statistics

# hemocircuit state -> roadrunner symbol (brain_vasomotion.ant); art.lambda maps to r via art.r
HC2RR_VASO = {"Cv.V": "Vv", "Ca.V": "Va", "Cic.V": "Vic", "art.Ca": "Ca", "art.dCa": "dCa", "art.Cw": "Cw",
              "Lb.q": "q2"}


# ----------------------------------------------------------------------------- helpers ----
def log(msg):
    print(msg, flush=True)


class Clock:
    """Wall time and CPU time (this process + reaped worker processes) of a block.

    The machine is shared: CPU time is the robust figure when other jobs compete for the
    cores (wall time then overstates both tools); both are reported."""

    def __enter__(self):
        self.w0, self.c0 = time.perf_counter(), _cpu()
        return self

    def __exit__(self, *exc):
        self.wall, self.cpu = time.perf_counter() - self.w0, _cpu() - self.c0
        return False


def _cpu():
    import resource
    ch = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + ch.ru_utime + ch.ru_stime


def repeated(n, run, setup=None):
    """``run(setup())`` (or ``run()``) n times, each timed without its setup: (the first
    result, median wall, median CPU, all walls).  A batch is one call of a few hundred ms on a
    shared VM, whose speed moves by +-20 % from call to call: the median of a few calls of each
    tool says more than one."""
    out, walls, cpus = None, [], []
    for k in range(max(1, n)):
        arg = None if setup is None else setup()
        with Clock() as ck:
            r = run() if setup is None else run(arg)
        out = r if k == 0 else out
        walls.append(ck.wall)
        cpus.append(ck.cpu)
    return out, float(np.median(walls)), float(np.median(cpus)), walls


def timed(fn, repeats):
    """{median_s, times_s, cpu_median_s, cpu_s} and the last result of ``repeats`` calls of fn()."""
    walls, cpus, res = [], [], None
    for _ in range(max(1, repeats)):
        with Clock() as ck:
            res = fn()
        walls.append(ck.wall)
        cpus.append(ck.cpu)
    return {"median_s": statistics.median(walls), "times_s": walls, "cpu_median_s": statistics.median(cpus),
            "cpu_s": cpus}, res


def rel(a, b):
    """Relative difference |a - b| / |b|."""
    return float(abs(a - b) / abs(b)) if b != 0 else float("nan")


def period(t, y):
    """Mean interval between upward crossings of the mean, NaN if < 2 (hemocircuit's envelope
    definition, which the peers README uses too)."""
    from hemocircuit.analyses.envelope import period_of

    return period_of(t, y)


def on_grid(t, dt, t0=0.0):
    """Mask of the points of t that lie on the output grid t0 + k dt (hemocircuit's result also
    holds the restart points of hard-limit events, which are off the grid)."""
    k = np.round((t - t0) / dt)
    return np.abs(t - t0 - k * dt) < 1e-7 * max(1.0, dt)


def cycle_stats(t, r_um, q2, window=300.0):
    """Statistics of the settled cycle over the last ``window`` s (both ends included)."""
    w = t >= t[-1] - window - 1e-9
    tw, rw, qw = t[w], r_um[w], q2[w]
    return {"r_min_um": float(rw.min()), "r_max_um": float(rw.max()), "r_mean_um": float(rw.mean()),
            "period_s": period(tw, rw), "q2_mean_mLs": float(qw.mean())}


def against_ref(stats):
    d = {k: rel(stats[k], v) for k, v in REF_CYCLE.items()}
    return d, bool(all(np.isfinite(v) and v <= ACCEPT for v in d.values()))


def api_kwargs(func, wanted):
    """The subset of ``wanted`` {name: value} that ``func`` accepts (all of it if it takes
    **kwargs); the rest is returned as ignored."""
    try:
        sig = inspect.signature(func)
    except (TypeError, ValueError):
        return dict(wanted), {}
    if any(p.kind is p.VAR_KEYWORD for p in sig.parameters.values()):
        return dict(wanted), {}
    ok = {k: v for k, v in wanted.items() if k in sig.parameters}
    return ok, {k: v for k, v in wanted.items() if k not in ok}


def default_of(func, name, fallback):
    try:
        p = inspect.signature(func).parameters.get(name)
    except (TypeError, ValueError):
        return fallback
    return fallback if p is None or p.default is inspect.Parameter.empty else p.default


def law_states(c):
    """Indices of the states held by a conservation law (envelope kicks only the others)."""
    held = set()
    try:
        for s in c.law_specs:
            for g, i, _vol, _sign in s["terms"]:
                held.update(int(j) for j in np.ravel(g.sidx[i]))
    except Exception:  # noqa: BLE001  (structure changed: fall back to the compliance volumes)
        held = {j for j, n in enumerate(c.state_names) if n.endswith(".V")}
    return held


def radius_um(c, x):
    return float(c.outputs(0.0, np.atleast_2d(x))["art.r"][0])


def raise_radius(c, x, factor):
    """x with art.lambda changed so that the radius is multiplied by ``factor``.

    components/arteriole/equations.py (l2r): r = (lambda l0 n_c / pi - t_w) / 2 is affine in lambda,
    so two evaluations of the public output 'art.r' give the exact lambda (no unit assumptions).
    """
    il = c.state_names.index("art.lambda")
    lam = x[il]
    r0 = radius_um(c, x)
    x1 = x.copy()
    x1[il] = lam * 1.001
    slope = (radius_um(c, x1) - r0) / (x1[il] - lam)
    out = x.copy()
    out[il] = lam + (factor - 1.0) * r0 / slope
    return out


# --------------------------------------------------------------------------- roadrunner ----
def rr_load(path, init=None):
    """(RoadRunner, seconds for Antimony + SBML + LLVM compile [+ init regeneration])."""
    import antimony
    import roadrunner
    t0 = time.perf_counter()
    antimony.clearPreviousLoads()
    if antimony.loadAntimonyFile(path) < 0:
        raise RuntimeError(f"antimony: {antimony.getLastError()}")
    rr = roadrunner.RoadRunner(antimony.getSBMLString(antimony.getMainModuleName()))
    for k, v in (init or {}).items():
        rr[f"init({k})"] = v
    return rr, time.perf_counter() - t0


def rr_tolerances(rr, rtol, atol=None, max_step=None):
    rr.integrator.relative_tolerance = rtol
    if atol is not None:
        rr.integrator.absolute_tolerance = atol
    rr.integrator.maximum_time_step = 0.0 if max_step is None else max_step  # 0: no limit
    return {"rtol": rtol, "atol": float(rr.integrator.absolute_tolerance)}


# ---------------------------------------------------------------------------- scenarios ----
def bench_vasomotion(a, hc_kw):
    res = {"description": "brain vasomotion, Pa = 80 mmHg, 1000 s, output every 0.1 s, radius +0.1 % "
                          "from the equilibrium; statistics over the last 300 s",
           "reference_cycle": REF_CYCLE, "acceptance_rel": ACCEPT, "runs": []}
    rr, t_compile = rr_load(os.path.join(a.peers, "brain_vasomotion.ant"))
    res["roadrunner_compile_s"] = t_compile
    t0 = time.perf_counter()
    c = hc.load(os.path.join(NET, "vasomotion.yaml"))
    t_load = time.perf_counter() - t0
    t0 = time.perf_counter()
    op = operating_point(c)
    t_op = time.perf_counter() - t0
    x0 = raise_radius(c, np.asarray(op.x, float), 1.001)
    res.update(hemocircuit_load_s=t_load, hemocircuit_op_s=t_op,
               hemocircuit_start={"r_op_um": float(op["art.r"]), "r_start_um": radius_um(c, x0)},
               roadrunner_start={"r_start_um": None})
    kw, ignored = api_kwargs(c.simulate, hc_kw)
    res["hemocircuit_api_kwargs"], res["ignored_kwargs"] = {k: str(v) for k, v in kw.items()}, list(ignored)
    for rtol in a.rtols:
        row = {"rtol": rtol}
        # roadrunner
        row["roadrunner_tolerances"] = rr_tolerances(rr, rtol, a.rr_atol)

        def run_rr():
            rr.resetAll()
            return np.array(rr.simulate(0, 1000, 10001, ["time", "r", "q2", "n_reset"]))
        tm, S = timed(run_rr, a.rr_repeats)
        med = tm["median_s"]
        st = cycle_stats(S[:, 0], S[:, 1] * 1e6, S[:, 2])
        d, ok = against_ref(st)
        row["roadrunner"] = {**tm, "stats": st, "rel_to_ref": d, "accepted": ok, "ca_floor_resets": int(S[-1, 3])}
        res["roadrunner_start"]["r_start_um"] = float(S[0, 1] * 1e6)
        log(f"  roadrunner rtol {rtol:g}: {med:.3f} s (cpu {tm['cpu_median_s']:.3f} s)  r {st['r_min_um']:.5f}..{st['r_max_um']:.5f} um "
            f"period {st['period_s']:.5f} s  resets {int(S[-1, 3])}")
        # hemocircuit
        log(f"  hemocircuit rtol {rtol:g}: running {a.hc_repeats} x 1000 s ...")

        def run_hc():
            return c.simulate(1000.0, dt=0.1, x0=x0, rtol=rtol, **kw)
        try:
            tm_h, r = timed(run_hc, a.hc_repeats)
            med_h = tm_h["median_s"]
        except Exception as exc:  # noqa: BLE001  (report and keep going)
            row["hemocircuit"] = {"error": f"{type(exc).__name__}: {exc}"}
            log(f"  hemocircuit rtol {rtol:g}: FAILED {exc}")
            res["runs"].append(row)
            continue
        m = on_grid(r.t, 0.1)
        qcol = "Q(Lb)" if "Q(Lb)" in r.columns else "Lb.q"
        st_h = cycle_stats(r.t[m], np.asarray(r["art.r"])[m], np.asarray(r[qcol])[m])
        d_h, ok_h = against_ref(st_h)
        # floor hits: restart points (off the grid) where Ca sits on its floor
        ca = np.asarray(r["art.Ca"])
        n_floor = int(np.sum(~m & (ca <= 1e-12 * (1 + 1e-9))))
        row["hemocircuit"] = {**tm_h, "stats": st_h, "rel_to_ref": d_h,
                              "accepted": ok_h, "ca_floor_hits": n_floor, "solver_stats": _jsonable(r.stats)}
        row["ratio_hc_over_rr"] = med_h / med
        row["cpu_ratio_hc_over_rr"] = tm_h["cpu_median_s"] / tm["cpu_median_s"]
        row["hc_vs_rr_stats_rel"] = {k: rel(st_h[k], st[k]) for k in st}
        log(f"  hemocircuit rtol {rtol:g}: {med_h:.2f} s (cpu {tm_h['cpu_median_s']:.2f} s)  "
            f"r {st_h['r_min_um']:.5f}..{st_h['r_max_um']:.5f} um period {st_h['period_s']:.5f} s  floor hits {n_floor}  {r.stats}")
        res["runs"].append(row)
    return res


def bench_artcomp(a, hc_kw):
    Pa0, s, amp, f = 80.0, 0.1, 0.1, 0.1
    res = {"description": "arterial compliance, Pa = 80 mmHg (1 + 0.1 + 0.1 sin(2 pi 0.1 t)) for t > 0, "
                          "1000 s, output every 0.1 s, from the Pa = 80 equilibrium", "runs": []}
    rr, t_compile = rr_load(os.path.join(a.peers, "brain_artcomp.ant"),
                            init={"Pa0": Pa0, "s_step": s, "a_sine": amp, "f_sine": f})
    res["roadrunner_compile_s"] = t_compile
    t0 = time.perf_counter()
    c = hc.load(os.path.join(NET, "arterial_compliance.yaml"))
    t_load = time.perf_counter() - t0
    t0 = time.perf_counter()
    x0 = np.asarray(operating_point(c).x, float)
    t_op = time.perf_counter() - t0
    # the forcing as the pressure source's parameters (components/sources.py):
    # value + amplitude sin(2 pi frequency (t - start) + phase) for t >= start
    c = c.with_values({"Pa.value": Pa0 * (1 + s), "Pa.amplitude": Pa0 * amp, "Pa.frequency": f,
                       "Pa.phase": 0.0, "Pa.start": 0.0})
    res.update(hemocircuit_load_s=t_load, hemocircuit_op_s=t_op)
    kw, ignored = api_kwargs(c.simulate, hc_kw)
    res["hemocircuit_api_kwargs"], res["ignored_kwargs"] = {k: str(v) for k, v in kw.items()}, list(ignored)
    sel = ["time", "r", "q1", "q2", "P_alpha", "Ca"]
    last = None
    for rtol in a.rtols:
        row = {"rtol": rtol, "roadrunner_tolerances": rr_tolerances(rr, rtol, a.rr_atol)}

        def run_rr():
            rr.resetAll()
            return np.array(rr.simulate(0, 1000, 10001, sel))
        tm, S = timed(run_rr, a.rr_repeats)
        med = tm["median_s"]
        row["roadrunner"] = tm

        def run_hc():
            return c.simulate(1000.0, dt=0.1, x0=x0, rtol=rtol, **kw)
        try:
            tm_h, r = timed(run_hc, a.hc_repeats)
            med_h = tm_h["median_s"]
        except Exception as exc:  # noqa: BLE001
            row["hemocircuit"] = {"error": f"{type(exc).__name__}: {exc}"}
            log(f"  hemocircuit rtol {rtol:g}: FAILED {exc}")
            res["runs"].append(row)
            continue
        row["hemocircuit"] = {**tm_h, "solver_stats": _jsonable(r.stats)}
        row["ratio_hc_over_rr"] = med_h / med
        row["cpu_ratio_hc_over_rr"] = tm_h["cpu_median_s"] / tm["cpu_median_s"]
        row.update(compare_artcomp(r, S, sel))
        last = (rtol, r) if last is None or rtol <= last[0] else last
        log(f"  rtol {rtol:g}: roadrunner {med * 1e3:.1f} ms, hemocircuit {med_h:.2f} s "
            f"(x{med_h / med:.0f}); max rel diff {row.get('max_rel_diff_over_run')}")
        res["runs"].append(row)
    if last is not None:
        # physics check: roadrunner with hemocircuit's mmHg constant (the .ant files use
        # 133.322 Pa/mmHg) and from hemocircuit's start state, at the tightest rtol: what is
        # left is integration error and any real difference between the two models
        rtol, r = last
        rr_tolerances(rr, rtol, a.rr_atol)
        rr.resetAll()
        rr["MMHG"] = PA_PER_MMHG
        rr["dP0"] = 60 * PA_PER_MMHG  # an initial assignment in the .ant: set with the constant
        sx = dict(zip(c.state_names, x0))
        for hn, rrn in (("Cv.V", "Vv"), ("Ca.V", "Va"), ("art.Ca", "Ca"), ("art.Cw", "Cw")):
            rr[rrn] = float(sx[hn])
        rr["r"] = radius_um(c, x0) * 1e-6
        S = np.array(rr.simulate(0, 1000, 10001, sel))
        diag = compare_artcomp(r, S, sel)
        res["same_constants_check"] = {"rtol": rtol, "mmHg_Pa": PA_PER_MMHG, **diag}
        log(f"  same constants and start, rtol {rtol:g}: max rel diff {diag.get('max_rel_diff_over_run')}")
    return res


ARTCOMP_COLS = {"r [um]": ("art.r", "r", 1e6), "q1 = Q(Rla) [mL/s]": ("Q(Rla)", "q1", 1.0),
                "q2 = Q(Rsv) [mL/s]": ("Q(Rsv)", "q2", 1.0), "P(alpha) [mmHg]": ("P(alpha)", "P_alpha", 1.0),
                "Ca [M]": ("art.Ca", "Ca", 1.0)}


def compare_artcomp(r, S, sel):
    """Largest relative differences (t > 0) and values at a few times, hemocircuit result r
    against the roadrunner array S (columns sel), on the common 0.1 s grid."""
    m = on_grid(r.t, 0.1)
    th = r.t[m]
    if len(th) != S.shape[0] or np.max(np.abs(th - S[:, 0])) > 1e-6:
        return {"comparison_error": f"grids differ ({len(th)} vs {S.shape[0]} points)"}
    cmpd, at = {}, {}
    probe = [int(np.argmin(np.abs(th - tp))) for tp in (1.0, 10.0, 100.0, 500.0, 1000.0)]
    # t > 0 only: at t = 0 roadrunner's Pa is still Pa0 (piecewise 'time > 0') while the
    # source's step is already on (value + sine for t >= start): one instant, same ODE
    pos = th > 0
    for lab, (hcol, rcol, scale) in ARTCOMP_COLS.items():
        yh = np.asarray(r[hcol])[m]
        yr = S[:, sel.index(rcol)] * scale
        d = np.abs(yh - yr) / np.maximum(np.abs(yr), 1e-300)
        cmpd[lab] = float(d[pos].max())
        at[lab] = {f"t={th[i]:g}": {"hemocircuit": float(yh[i]), "roadrunner": float(yr[i])} for i in probe}
    return {"max_rel_diff_over_run": cmpd, "values_at": at}


def warm_up(call):
    """The batches' counterpart of roadrunner's excluded model load: one small untimed call of
    the same analysis on a separately loaded circuit (nothing it computes is reused by the
    timed call: operating points and other per-circuit results stay with that circuit), which
    leaves in this process what a second call of a session finds -- numba imported, the
    compiled integrator loaded from its cache.  ``--cold-batches`` times the first call instead.
    Returns its wall time [s]."""
    t0 = time.perf_counter()
    call()
    dt = time.perf_counter() - t0
    log(f"  warm-up call (untimed, like roadrunner's load): {dt:.2f} s")
    return dt


def envelope_summary(t, y_r, y_q, window, osc_tol):
    """Mirror of hemocircuit.analyses.envelope._summary for outputs (art.r, Q(Rla))."""
    n_win = max(int(len(t) * window), 4)
    tw, ys = t[-n_win:], {"art.r": y_r[-n_win:], "Q(Rla)": y_q[-n_win:]}
    osc = {}
    for o, y in ys.items():
        half = len(y) // 2
        osc[o] = bool(np.ptp(y) > osc_tol * abs(np.mean(y)) and np.ptp(y[half:]) >= 0.5 * np.ptp(y[:half]))
    z = ys["art.r"] - ys["art.r"].mean()
    up = np.nonzero((z[:-1] < 0) & (z[1:] >= 0))[0]
    sel = slice(up[0], up[-1] + 1) if any(osc.values()) and len(up) >= 2 else slice(None)
    row = {}
    for o, y in ys.items():
        row.update({f"{o} min": float(y.min()), f"{o} max": float(y.max()), f"{o} mean": float(y[sel].mean())})
    row["oscillating"] = bool(any(osc.values()))
    row["period [s]"] = period(tw, ys["art.r"]) if row["oscillating"] else float("nan")
    return row


def _envelope_rows(res):
    """Member rows {"Pa.value", "art.zeta", "<output> min|max|mean", "period [s]", "oscillating"
    [, "error"]} from the envelope's result (a list of such rows, or the columnar
    EnvelopeResult with min(o)/max(o)/mean(o)/period/oscillating/error columns)."""
    if isinstance(res, list):
        return res
    rows = []
    for k in range(len(res["period"])):
        r = {"Pa.value": float(res["Pa.value"][k]), "art.zeta": float(res["art.zeta"][k])}
        if res["error"][k]:
            r["error"] = res["error"][k]
        else:
            for o in ("art.r", "Q(Rla)"):
                for q in ("min", "max", "mean"):
                    r[f"{o} {q}"] = float(res[f"{q}({o})"][k])
            r["period [s]"] = float(res["period"][k])
            r["oscillating"] = bool(res["oscillating"][k])
        rows.append(r)
    return rows


def bench_envelope(a, hc_kw):
    pas, zetas = [60.0, 70.0, 80.0, 90.0, 100.0], [0.1, 0.2]
    t_end, dt = 1000.0, 0.1
    rtol = default_of(envelope, "rtol", 1e-5)
    kick = default_of(envelope, "kick", 1e-3)
    window = default_of(envelope, "window", 0.3)
    osc_tol = default_of(envelope, "osc_tol", 1e-3)
    res = {"description": f"envelope: Pa {pas} mmHg x zeta {zetas}, {t_end:g} s each, output every {dt:g} s, "
                          f"statistics over the last {window:g} of the run; hemocircuit on {a.workers} worker "
                          "processes, roadrunner one by one from the same start states",
           "rtol": rtol, "kick": kick, "workers": a.workers}
    t0 = time.perf_counter()
    c = hc.load(os.path.join(NET, "vasomotion.yaml"))
    res["hemocircuit_load_s"] = time.perf_counter() - t0
    kw, ignored = api_kwargs(envelope, hc_kw)
    res["hemocircuit_api_kwargs"], res["ignored_kwargs"] = {k: str(v) for k, v in kw.items()}, list(ignored)
    if not a.cold_batches:
        res["hemocircuit_warmup_s"] = warm_up(lambda: envelope(
            hc.load(os.path.join(NET, "vasomotion.yaml")), ("Pa.value", [80.0]), outputs=["art.r", "Q(Rla)"],
            t_end=1.0, dt=dt, workers=a.workers, **kw))
    log(f"  hemocircuit envelope, {len(pas) * len(zetas)} runs on {a.workers} workers ...")
    rows, t_hc, cpu_hc, walls_hc = repeated(a.batch_repeats, lambda cc: envelope(
        cc, ("Pa.value", pas), [("art.zeta", zetas)], outputs=["art.r", "Q(Rla)"], t_end=t_end, dt=dt,
        workers=a.workers, **kw), setup=lambda: hc.load(os.path.join(NET, "vasomotion.yaml")))  # a new circuit
    rows = _envelope_rows(rows)
    log(f"  hemocircuit envelope: {t_hc:.2f} s (cpu incl. workers {cpu_hc:.2f} s; calls {walls_hc})")
    # the same start states for roadrunner: operating point at each Pa + the envelope's kick
    t0 = time.perf_counter()
    free = [j for j in range(c.nx) if j not in law_states(c)]
    starts = {}
    for pa in pas:
        cc = c.with_values({"Pa.value": pa})
        x = np.asarray(operating_point(cc).x, float).copy()
        x[free] += kick * cc.state_scales[free]
        st = {rrn: float(x[c.state_names.index(hn)]) for hn, rrn in HC2RR_VASO.items()}
        st["r"] = radius_um(cc, x) * 1e-6
        starts[pa] = st
    res["start_states_s"] = time.perf_counter() - t0
    rr, t_compile = rr_load(os.path.join(a.peers, "brain_vasomotion.ant"))
    res["roadrunner_compile_s"] = t_compile
    res["roadrunner_tolerances"] = rr_tolerances(rr, rtol, a.rr_atol)
    grid_n = int(round(t_end / dt)) + 1
    def rr_envelope():
        out = []
        for pa in pas:
            for z in zetas:
                rr.resetAll()
                rr["Pa0"], rr["zeta"] = pa, z
                for k, v in starts[pa].items():
                    rr[k] = v
                S = np.array(rr.simulate(0, t_end, grid_n, ["time", "r", "q1"]))
                out.append({"Pa.value": pa, "art.zeta": z,
                            **envelope_summary(S[:, 0], S[:, 1] * 1e6, S[:, 2], window, osc_tol)})
        return out

    rr_rows, t_rr, cpu_rr, walls_rr = repeated(a.batch_repeats, rr_envelope)
    log(f"  roadrunner, the same runs one by one: {t_rr:.2f} s (cpu {cpu_rr:.2f} s; calls {walls_rr})")
    res.update(hemocircuit_wall_s=t_hc, roadrunner_wall_s=t_rr, ratio_hc_over_rr=t_hc / t_rr,
               hemocircuit_cpu_s=cpu_hc, roadrunner_cpu_s=cpu_rr, cpu_ratio_hc_over_rr=cpu_hc / cpu_rr,
               batch_repeats=a.batch_repeats, hemocircuit_walls_s=walls_hc, roadrunner_walls_s=walls_rr)
    # compare member by member
    keys = ["art.r min", "art.r max", "art.r mean", "period [s]", "Q(Rla) mean"]
    # largest differences over the members on which both tools agree whether they oscillate
    # (a member whose verdict differs is listed, not averaged in: near a Hopf boundary the
    # growth or decay over 1000 s is tolerance-sensitive in either tool)
    worst = {k: 0.0 for k in keys}
    verdicts_differ, members = [], []
    for rh in rows:
        pa, z = float(rh["Pa.value"]), float(rh["art.zeta"])
        rrr = next(r for r in rr_rows if r["Pa.value"] == pa and r["art.zeta"] == z)
        if "error" in rh:
            members.append({"Pa": pa, "zeta": z, "hemocircuit_error": rh["error"]})
            continue
        m = {"Pa": pa, "zeta": z, "oscillating": [rh["oscillating"], rrr["oscillating"]]}
        if rh["oscillating"] != rrr["oscillating"]:
            verdicts_differ.append((pa, z))
        for k in keys:
            m[k] = [rh[k], rrr[k]]
            if rh["oscillating"] != rrr["oscillating"]:
                continue
            if np.isfinite(rh[k]) and np.isfinite(rrr[k]):
                d = rel(rh[k], rrr[k])
                worst[k] = max(worst[k], d)
        members.append(m)
    res.update(members_hc_rr=members, max_rel_diff=worst, oscillation_verdicts_differ=verdicts_differ)
    log(f"  max rel diff hc vs rr: {worst}; verdicts differ: {verdicts_differ}")
    if a.envelope_ref_rtol:
        # both tools against one untimed reference: equal rtol is not equal accuracy by itself
        ref = _envelope_rows(envelope(c, ("Pa.value", pas), [("art.zeta", zetas)], outputs=["art.r", "Q(Rla)"],
                                      t_end=t_end, dt=dt, workers=a.workers, **{**kw, "rtol": a.envelope_ref_rtol}))
        acc = {"reference": f"hemocircuit envelope at rtol {a.envelope_ref_rtol:g}"}
        for tool, rws in (("hemocircuit", rows), ("roadrunner", rr_rows)):
            err, differ = {k: 0.0 for k in keys}, []
            for r in rws:
                q = next((x for x in ref if x["Pa.value"] == r["Pa.value"] and x["art.zeta"] == r["art.zeta"]), None)
                if q is None or "error" in r or "error" in q:
                    continue
                if r["oscillating"] != q["oscillating"]:
                    differ.append((r["Pa.value"], r["art.zeta"]))
                    continue
                for k in keys:
                    if np.isfinite(r[k]) and np.isfinite(q[k]):
                        err[k] = max(err[k], rel(r[k], q[k]))
            acc[tool] = {"max_rel_err": err, "verdicts_differ": differ}
        res["accuracy_vs_reference"] = acc
        log(f"  against {acc['reference']}: hemocircuit {acc['hemocircuit']}, roadrunner {acc['roadrunner']}")
    return res


def _dft(y, n_per, k):
    """As hemocircuit.analyses.freq._dft: k-th harmonic (complex, sine-phase convention)."""
    n = y.shape[-1]
    ph = np.exp(-2j * np.pi * k * np.arange(n) / n_per)
    return 2.0 / n * np.sum(y * ph, axis=-1)


def rr_freq_run(rr, f, tau, opt):
    """One forced run with freq.py's rule: 10 % step + 10 % sine from the Pa0 equilibrium,
    blocks of whole periods (SAMPLES per period, h_max = period/32) until the fundamental of
    each output changes by < settle_tol between the last two periods (and the mean drifts less),
    then the DFT over the last n_periods periods."""
    ns = opt["samples"]
    T = 1.0 / f
    rr.resetAll()
    rr["tauCa"], rr["s_step"], rr["a_sine"], rr["f_sine"] = tau, opt["step"], opt["amplitude"], f
    rr.integrator.maximum_time_step = T / 32
    y0 = None
    t, total = 0.0, 0
    block = opt["block_periods"]
    while True:
        S = np.array(rr.simulate(t, t + block * T, block * ns + 1, ["time", "q1", "q2", "Pa"]))
        if y0 is None:  # steady outputs at P0: the initial state is the Pa0 equilibrium
            y0 = np.array([S[0, 1], S[0, 2]])
        Y, Xin = S[:, 1:3].T, S[:, 3]
        a1 = _dft(Y[:, -ns:], ns, 1)
        a0 = _dft(Y[:, -2 * ns:-ns], ns, 1)
        total += block
        den = np.maximum(np.abs(a1), 0.01 * np.abs(y0) + 1e-300)
        relc = np.maximum(np.abs(a1 - a0) / den, np.abs(Y[:, -ns:].mean(axis=1) - Y[:, -2 * ns:-ns].mean(axis=1)) / den)
        t = float(S[-1, 0])
        if np.all(relc < opt["settle_tol"]) or total >= opt["max_periods"]:
            n = opt["n_periods"] * ns
            X1 = _dft(Xin[-n:], ns, 1)
            Y1 = _dft(Y[:, -n:], ns, 1)
            return [{"rel_amplitude": float(abs(Y1[i]) / abs(y0[i])),
                     "phase [deg]": float(np.degrees(np.angle(Y1[i] / X1))),
                     "periods": total, "settled": bool(np.all(relc < opt["settle_tol"]))} for i in range(2)]


def bench_freq(a, hc_kw):
    freqs = np.logspace(-3, 0, 30)
    taus = [1.0, 10.0]
    fr = frequency_response
    try:
        from hemocircuit.analyses.freq import SAMPLES
    except ImportError:
        SAMPLES = 64
    n_periods = default_of(fr, "n_periods", 2)
    opt = {"samples": SAMPLES, "step": default_of(fr, "step", 0.1), "amplitude": default_of(fr, "amplitude", 0.1),
           "settle_tol": default_of(fr, "settle_tol", 1e-3), "n_periods": n_periods,
           "block_periods": max(default_of(fr, "block_periods", 4), n_periods + 1),
           "max_periods": default_of(fr, "max_periods", 400)}
    rtol = default_of(fr, "rtol", 1e-8)
    res = {"description": f"frequency response on arterial_compliance: {len(freqs)} frequencies "
                          f"{freqs[0]:g}-{freqs[-1]:g} Hz x tau_Ca {taus} s, step {opt['step']:g} + sine "
                          f"{opt['amplitude']:g}; hemocircuit on {a.workers} worker processes, roadrunner "
                          "one by one with the same settle rule", "rtol": rtol, "settings": opt,
           "workers": a.workers}
    t0 = time.perf_counter()
    c = hc.load(os.path.join(NET, "arterial_compliance.yaml"))
    res["hemocircuit_load_s"] = time.perf_counter() - t0
    kw, ignored = api_kwargs(fr, hc_kw)
    res["hemocircuit_api_kwargs"], res["ignored_kwargs"] = {k: str(v) for k, v in kw.items()}, list(ignored)
    if not a.cold_batches:
        res["hemocircuit_warmup_s"] = warm_up(lambda: fr(
            hc.load(os.path.join(NET, "arterial_compliance.yaml")), [0.5], outputs=["Q(Rla)", "Q(Rsv)"],
            workers=a.workers, **kw))
    log(f"  hemocircuit frequency_response, {len(freqs) * len(taus)} runs on {a.workers} workers ...")
    rows, t_hc, cpu_hc, walls_hc = repeated(a.batch_repeats, lambda cc: fr(
        cc, freqs, outputs=["Q(Rla)", "Q(Rsv)"], grid=[("art.tau_Ca", [f"{v:g} s" for v in taus])],
        workers=a.workers, **kw), setup=lambda: hc.load(os.path.join(NET, "arterial_compliance.yaml")))
    rows = _freq_rows(rows, ["Q(Rla)", "Q(Rsv)"])
    log(f"  hemocircuit frequency_response: {t_hc:.3f} s (cpu incl. workers {cpu_hc:.3f} s; calls {walls_hc})")
    rr, t_compile = rr_load(os.path.join(a.peers, "brain_artcomp.ant"))
    res["roadrunner_compile_s"] = t_compile
    res["roadrunner_tolerances"] = rr_tolerances(rr, rtol, a.rr_atol)
    rr_res, t_rr, cpu_rr, walls_rr = repeated(a.batch_repeats, lambda: {
        (tau, float(f)): rr_freq_run(rr, float(f), tau, opt) for tau in taus for f in freqs})
    log(f"  roadrunner, the same runs one by one: {t_rr:.3f} s (cpu {cpu_rr:.3f} s; calls {walls_rr})")
    res.update(hemocircuit_wall_s=t_hc, roadrunner_wall_s=t_rr, ratio_hc_over_rr=t_hc / t_rr,
               hemocircuit_cpu_s=cpu_hc, roadrunner_cpu_s=cpu_rr, cpu_ratio_hc_over_rr=cpu_hc / cpu_rr,
               batch_repeats=a.batch_repeats, hemocircuit_walls_s=walls_hc, roadrunner_walls_s=walls_rr)
    worst_amp, worst_ph, errors, unsettled_hc, worst_at = 0.0, 0.0, [], 0, None
    table = []
    outs = ["Q(Rla)", "Q(Rsv)"]
    for r in rows:
        tau = float(str(r["art.tau_Ca"]).split()[0])
        f = float(r["frequency [Hz]"])
        if r.get("error"):
            errors.append((tau, f, r["error"]))
            continue
        key = min(rr_res, key=lambda k: abs(k[0] - tau) + abs(np.log(k[1] / f)))
        rp = rr_res[key][outs.index(r["output"])]
        da = rel(r["rel_amplitude"], rp["rel_amplitude"])
        dp = abs((r["phase [deg]"] - rp["phase [deg]"] + 180.0) % 360.0 - 180.0)
        if da > worst_amp:
            worst_amp, worst_at = da, (tau, f, r["output"])
        worst_ph = max(worst_ph, dp)
        unsettled_hc += 0 if r.get("settled", True) else 1
        table.append({"tau_Ca": tau, "f": f, "output": r["output"],
                      "rel_amplitude": [r["rel_amplitude"], rp["rel_amplitude"]],
                      "phase_deg": [r["phase [deg]"], rp["phase [deg]"]], "periods": [r["periods"], rp["periods"]]})
    res.update(max_rel_diff_amplitude=worst_amp, worst_amplitude_at=worst_at, max_abs_diff_phase_deg=worst_ph,
               hemocircuit_errors=errors, hemocircuit_unsettled=unsettled_hc,
               roadrunner_unsettled=sum(1 for v in rr_res.values() if not v[0]["settled"]), rows_hc_rr=table)
    log(f"  amplitude max rel diff {worst_amp:.3g} at {worst_at}, phase max diff {worst_ph:.3g} deg")
    if a.freq_ref_rtol:
        res["accuracy_vs_reference"] = freq_accuracy(rr, rows, rr_res, taus, freqs, opt, a.freq_ref_rtol, outs)
    return res


def freq_accuracy(rr, rows, rr_res, taus, freqs, opt, ref_rtol, outs):
    """Each tool's error against a reference: roadrunner's same runs (same settle rule, so the
    same periods) at a much tighter rtol, untimed.  Equal rtol is not equal accuracy (roadrunner's
    absolute tolerance is a flat 1e-12, hemocircuit's rtol x each state's scale): this says how
    close each tool's answer is to the converged one."""
    rr_tolerances(rr, ref_rtol)
    steps = rr.integrator.maximum_num_steps
    rr.integrator.maximum_num_steps = 10_000_000
    try:
        ref = {(tau, float(f)): rr_freq_run(rr, float(f), tau, opt) for tau in taus for f in freqs}
    finally:
        rr.integrator.maximum_num_steps = steps
    out = {"reference": f"roadrunner, rtol {ref_rtol:g}, same settle rule", "hemocircuit": {}, "roadrunner": {}}
    per_tool = {"hemocircuit": [], "roadrunner": []}
    for r in rows:
        if r.get("error"):
            continue
        tau, f = float(str(r["art.tau_Ca"]).split()[0]), float(r["frequency [Hz]"])
        key = min(ref, key=lambda k: abs(k[0] - tau) + abs(np.log(k[1] / f)))
        i = outs.index(r["output"])
        rf = ref[key][i]
        per_tool["hemocircuit"].append((r["rel_amplitude"], r["phase [deg]"], rf))
        per_tool["roadrunner"].append((rr_res[key][i]["rel_amplitude"], rr_res[key][i]["phase [deg]"], rf))
    for tool, vals in per_tool.items():
        out[tool] = {"max_rel_err_amplitude": max(rel(a_, rf["rel_amplitude"]) for a_, _, rf in vals),
                     "max_abs_err_phase_deg": max(abs((p_ - rf["phase [deg]"] + 180.0) % 360.0 - 180.0)
                                                  for _, p_, rf in vals)}
    log(f"  against {out['reference']}: hemocircuit amplitude {out['hemocircuit']['max_rel_err_amplitude']:.2g}, "
        f"phase {out['hemocircuit']['max_abs_err_phase_deg']:.2g} deg; roadrunner amplitude "
        f"{out['roadrunner']['max_rel_err_amplitude']:.2g}, phase {out['roadrunner']['max_abs_err_phase_deg']:.2g} deg")
    return out


def _freq_rows(res, outs):
    """A FreqResult (one row per grid member x frequency) as one dict per (member, frequency,
    output), the layout the comparison below reads."""
    if isinstance(res, list):
        return res
    rows = []
    for i in range(res.n_rows):
        for o in outs:
            rows.append({"art.tau_Ca": res["art.tau_Ca"][i], "frequency [Hz]": res["frequency"][i], "output": o,
                         "rel_amplitude": res[f"rel_amplitude({o})"][i],
                         "phase [deg]": res[f"phase({o}/{res.input})"][i], "periods": res["periods"][i],
                         "settled": bool(res["settled"][i]), "error": res["error"][i] if "error" in res else ""})
    return rows


# ---- HOOK: compiled evaluator --------------------------------------------------------------
# The engine rewrite will give the circuit a compiled evaluator (something like a `compiled`
# kernel).  Its exact API is not settled: _compiled_rhs looks for the attribute named by
# --compiled-attr (default 'compiled') and accepts (a) an object with .rhs(t, x), (b) a callable
# f(t, x) -> dx/dt, or (c) a zero-argument factory returning (a) or (b).  Adjust HERE once the
# API exists; everything else in the rhs scenario stays as it is.
def _compiled_rhs(c, attr):
    """Per-row cost of the compiled right-hand side (hemocircuit.kernels): one call evaluates
    many rows, so the figure is what the compiled integrator pays per evaluation."""
    from hemocircuit.kernels.system import CompiledSystem

    system = CompiledSystem.of(c)
    if system is None:
        return None, "the circuit has a component type without a compiled kernel"
    P = system.params(c)
    rows = 20000

    def per_row(t, x):
        X = np.repeat(np.asarray(x, float)[None], rows, axis=0)
        return system.rhs(t, X, P)[0]

    per_row.rows = rows
    return per_row, None
# ---- end of HOOK ----------------------------------------------------------------------------


def per_call(fn, number, repeats, timer=time.perf_counter):
    """Median seconds per call over ``repeats`` batches of ``number`` calls."""
    fn()
    return statistics.median(t / number for t in timeit.repeat(fn, number=number, repeat=repeats, timer=timer))


def bench_rhs(a, hc_kw):
    c = hc.load(os.path.join(NET, "vasomotion.yaml"))
    x = raise_radius(c, np.asarray(operating_point(c).x, float), 1.001)
    n, reps = a.rhs_calls, max(a.rr_repeats, 5)
    res = {"description": "one right-hand-side evaluation of the vasomotion circuit at its start state "
                          f"(median over {reps} x {n} calls)"}
    res["hemocircuit_rhs_s"] = per_call(lambda: c.rhs(0.0, x), n, reps)
    res["hemocircuit_jacobian_s"] = per_call(lambda: c.jacobian(0.0, x), max(n // 5, 10), reps)
    rr, _ = rr_load(os.path.join(a.peers, "brain_vasomotion.ant"))
    rr.resetAll()
    # roadrunner's model evaluation through its Python API (rates of the 8 rate rules at the
    # current state); includes the Python -> C++ call, like c.rhs does
    res["roadrunner_getRatesOfChange_s"] = per_call(rr.getRatesOfChange, n * 10, reps)
    res["ratio_hc_over_rr"] = res["hemocircuit_rhs_s"] / res["roadrunner_getRatesOfChange_s"]
    res["hemocircuit_rhs_cpu_s"] = per_call(lambda: c.rhs(0.0, x), n, reps, time.process_time)
    res["roadrunner_getRatesOfChange_cpu_s"] = per_call(rr.getRatesOfChange, n * 10, reps, time.process_time)
    res["cpu_ratio_hc_over_rr"] = res["hemocircuit_rhs_cpu_s"] / res["roadrunner_getRatesOfChange_cpu_s"]
    fn, why = _compiled_rhs(c, a.compiled_attr)
    if fn is None:
        res["compiled"] = {"available": False, "why": why}
    else:
        try:
            dx_ref = np.asarray(c.rhs(0.0, x), float)
            dx = np.asarray(fn(0.0, x), float).reshape(-1)
            rows = getattr(fn, "rows", 1)
            t_c = per_call(lambda: fn(0.0, x), 3, reps) / rows
            res["compiled"] = {"available": True, "rhs_s": t_c, "ratio_to_rhs": t_c / res["hemocircuit_rhs_s"],
                               "rhs_cpu_s": per_call(lambda: fn(0.0, x), 3, reps, time.process_time) / rows,
                               "ratio_hc_over_rr": t_c / res["roadrunner_getRatesOfChange_s"],
                               # in the states' scales, relative to the vector's largest entry: the
                               # volumes' derivatives are ~1e-14 at this start (rounding of zero)
                               "max_rel_diff_vs_rhs": float(np.max(np.abs(dx - dx_ref) / c.state_scales) /
                                                            np.max(np.abs(dx_ref) / c.state_scales))}
        except Exception as exc:  # noqa: BLE001
            res["compiled"] = {"available": False, "why": f"calling it failed: {type(exc).__name__}: {exc}"}
    log(f"  rhs: hemocircuit {res['hemocircuit_rhs_s'] * 1e6:.1f} us, roadrunner "
        f"{res['roadrunner_getRatesOfChange_s'] * 1e6:.2f} us; compiled: {res['compiled']}")
    return res


# ------------------------------------------------------------------------------- output ----
def _jsonable(o):
    if isinstance(o, dict):
        return {str(k): _jsonable(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_jsonable(v) for v in o]
    if isinstance(o, (np.floating, float)):
        return None if not np.isfinite(o) else float(o)
    if isinstance(o, np.integer):
        return int(o)
    if isinstance(o, np.bool_):
        return bool(o)
    if isinstance(o, np.ndarray):
        return _jsonable(o.tolist())
    return o


def fmt_s(v):
    if v is None or not np.isfinite(v):
        return "-"
    return f"{v * 1e6:.1f} us" if v < 1e-3 else f"{v * 1e3:.1f} ms" if v < 1 else f"{v:.2f} s"


def table(results):
    """One line per scenario (and rtol): wall-time medians, the ratios hemocircuit / roadrunner
    in wall time and in CPU time, and the accuracy / agreement figures."""
    head = (f"{'scenario':<38}{'rtol':>7}{'roadrunner':>12}{'hemocircuit':>13}{'hc/rr':>8}{'hc/rr cpu':>11}"
            "  accuracy / agreement")
    lines = [head, "-" * 130]

    def line(name, rtol, t_rr, t_hc, ratio, cpu_ratio, acc):
        rt = f"{rtol:>7.0e}" if rtol else f"{'':>7}"
        ratio = f"{ratio:>8.1f}" if ratio is not None and np.isfinite(ratio) else f"{'-':>8}"
        cpu_ratio = f"{cpu_ratio:>11.1f}" if cpu_ratio is not None and np.isfinite(cpu_ratio) else f"{'-':>11}"
        lines.append(f"{name:<38}{rt}{fmt_s(t_rr):>12}{fmt_s(t_hc):>13}{ratio}{cpu_ratio}  {acc}")

    v = results.get("vasomotion")
    if v:
        for row in v["runs"]:
            h, r = row.get("hemocircuit", {}), row["roadrunner"]
            acc = (f"cycle vs README ref: rr {max(r['rel_to_ref'].values()):.1e} "
                   f"{'ok' if r['accepted'] else 'FAIL'}, hc " +
                   (f"{max(h['rel_to_ref'].values()):.1e} {'ok' if h['accepted'] else 'FAIL'}"
                    if "rel_to_ref" in h else h.get("error", "-")))
            line("vasomotion 1000 s, single run", row["rtol"], r["median_s"], h.get("median_s"),
                 row.get("ratio_hc_over_rr"), row.get("cpu_ratio_hc_over_rr"), acc)
    v = results.get("artcomp")
    if v:
        for row in v["runs"]:
            h, r = row.get("hemocircuit", {}), row["roadrunner"]
            d = row.get("max_rel_diff_over_run")
            acc = (f"max rel diff hc-rr: r {d['r [um]']:.1e}, q1 {d['q1 = Q(Rla) [mL/s]']:.1e}, "
                   f"q2 {d['q2 = Q(Rsv) [mL/s]']:.1e}" if d else row.get("comparison_error", h.get("error", "-")))
            line("artcomp forced 1000 s, single run", row["rtol"], r["median_s"], h.get("median_s"),
                 row.get("ratio_hc_over_rr"), row.get("cpu_ratio_hc_over_rr"), acc)
        sc = v.get("same_constants_check", {}).get("max_rel_diff_over_run")
        if sc:
            lines.append(f"{'':<38}{'':>7}{'':>12}{'':>13}{'':>8}{'':>11}  same mmHg constant + start: "
                         f"r {sc['r [um]']:.1e}, q1 {sc['q1 = Q(Rla) [mL/s]']:.1e}, q2 {sc['q2 = Q(Rsv) [mL/s]']:.1e}")
    v = results.get("envelope")
    if v:
        d = v["max_rel_diff"]
        acc = (f"max rel diff r min/max/mean {d['art.r min']:.1e}/{d['art.r max']:.1e}/{d['art.r mean']:.1e}, "
               f"period {d['period [s]']:.1e}; oscillation verdicts differ at (Pa, zeta) "
               f"{v['oscillation_verdicts_differ'] or 'none'}")
        ref = v.get("accuracy_vs_reference")
        if ref:
            acc += "; vs ref r max / period: " + ", ".join(
                f"{t} {ref[t]['max_rel_err']['art.r max']:.1e} / {ref[t]['max_rel_err']['period [s]']:.1e}"
                for t in ("hemocircuit", "roadrunner"))
        line(f"envelope 5 Pa x 2 zeta (hc {v['workers']} workers)", v["rtol"], v["roadrunner_wall_s"],
             v["hemocircuit_wall_s"], v["ratio_hc_over_rr"], v.get("cpu_ratio_hc_over_rr"), acc)
    v = results.get("freq")
    if v:
        acc = (f"max rel diff amplitude {v['max_rel_diff_amplitude']:.1e}, phase {v['max_abs_diff_phase_deg']:.2g} "
               f"deg; unsettled hc {v['hemocircuit_unsettled']} rr {v['roadrunner_unsettled']}")
        ref = v.get("accuracy_vs_reference")
        if ref:
            acc += "; vs ref: " + ", ".join(f"{t} {ref[t]['max_rel_err_amplitude']:.1e} / "
                                            f"{ref[t]['max_abs_err_phase_deg']:.1e} deg" for t in ("hemocircuit", "roadrunner"))
        line(f"freq 30 f x 2 tau_Ca (hc {v['workers']} workers)", v["rtol"], v["roadrunner_wall_s"],
             v["hemocircuit_wall_s"], v["ratio_hc_over_rr"], v.get("cpu_ratio_hc_over_rr"), acc)
    v = results.get("rhs")
    if v:
        line("rhs, one evaluation (vasomotion)", None, v["roadrunner_getRatesOfChange_s"], v["hemocircuit_rhs_s"],
             v["ratio_hc_over_rr"], v.get("cpu_ratio_hc_over_rr"),
             f"hc jacobian {fmt_s(v['hemocircuit_jacobian_s'])}; rr: getRatesOfChange()")
        cp = v.get("compiled", {})
        if cp.get("available"):
            line("rhs, compiled evaluator (HOOK)", None, v["roadrunner_getRatesOfChange_s"], cp["rhs_s"],
                 cp["ratio_hc_over_rr"], cp["rhs_cpu_s"] / v["roadrunner_getRatesOfChange_cpu_s"],
                 f"max rel diff vs c.rhs {cp['max_rel_diff_vs_rhs']:.1e}")
        else:
            lines.append(f"{'rhs, compiled evaluator (HOOK)':<38}  not available: {cp.get('why')}")
    lines.append("-" * 130)
    lines.append("wall-time medians (roadrunner: resetAll + simulate; hemocircuit: the API call); hc/rr cpu: the "
                 "same ratio in CPU time (robust on a busy machine).\ncompile, load and operating point excluded "
                 "(see the JSON); batches: the median of --batch-repeats calls of each tool (a new circuit each),\n"
                 "hemocircuit on worker processes, roadrunner one by one; "
                 "hemocircuit's batches after an untimed warm-up call on another circuit (as roadrunner's load), "
                 "unless --cold-batches.")
    return "\n".join(lines)


def meta(a, hc_kw):
    def git(*args):
        try:
            return subprocess.run(["git", "-C", ROOT, *args], capture_output=True, text=True, timeout=10).stdout.strip()
        except Exception:  # noqa: BLE001
            return None
    try:
        import roadrunner
        rr_v = roadrunner.__version__
    except Exception:  # noqa: BLE001
        rr_v = None
    try:
        import antimony
        am_v = antimony.__version__
    except Exception:  # noqa: BLE001
        am_v = None
    dirty = git("status", "--porcelain")
    return {"date": datetime.datetime.now().isoformat(timespec="seconds"), "git_head": git("rev-parse", "--short", "HEAD"),
            "working_tree_changes": len(dirty.splitlines()) if dirty else 0,
            "hemocircuit": getattr(hc, "__version__", None), "roadrunner": rr_v, "antimony": am_v,
            "python": platform.python_version(), "numpy": np.__version__, "machine": platform.machine(),
            "cores": os.cpu_count(), "loadavg": list(os.getloadavg()), "argv": sys.argv[1:],
            "hemocircuit_kwargs": {k: str(v) for k, v in hc_kw.items()}, "label": a.label,
            "hemocircuit_path": os.path.dirname(hc.__file__), "components_path": _components_path(),
            "simulate_signature": str(inspect.signature(hc.Circuit.simulate)) if hasattr(hc.Circuit, "simulate") else None}


def _components_path():
    try:
        import hemocircuit.components as comps
        return list(comps.__path__)
    except Exception:  # noqa: BLE001
        return None


def parse_kw(items):
    import yaml
    out = {}
    for it in items or []:
        k, _, v = it.partition("=")
        val = yaml.safe_load(v)
        if isinstance(val, str):  # YAML 1.1 reads 5e-6 (no dot) as a string
            try:
                val = float(val)
            except ValueError:
                pass
        out[k.strip()] = val
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--only", action="append", choices=SCENARIOS, help="scenario to run (repeatable; default all)")
    ap.add_argument("--rtols", default="1e-6,1e-8", help="tolerances of the single runs (default 1e-6,1e-8)")
    ap.add_argument("--rr-repeats", type=int, default=5, help="repeats of each roadrunner single run (median)")
    ap.add_argument("--hc-repeats", type=int, default=1, help="repeats of each hemocircuit single run (median)")
    ap.add_argument("--rhs-calls", type=int, default=200, help="calls per timing batch in the rhs scenario")
    ap.add_argument("--workers", type=int, default=2, help="worker processes of the hemocircuit batches")
    ap.add_argument("--batch-repeats", type=int, default=3,
                    help="timed calls of each batch scenario per tool (median; default 3)")
    ap.add_argument("--cold-batches", action="store_true",
                    help="time the batches as the first call of this process (numba import and the loading of "
                         "the compiled integrator included; roadrunner's load stays excluded); default: after an "
                         "untimed warm-up call on another circuit (see warm_up)")
    ap.add_argument("--envelope-ref-rtol", type=float, default=0.0,
                    help="envelope: rtol of an untimed hemocircuit reference both tools' statistics are measured "
                         "against (e.g. 1e-9, ~30 s more; 0: skip)")
    ap.add_argument("--freq-ref-rtol", type=float, default=1e-11,
                    help="freq: rtol of the untimed roadrunner reference both tools' errors are measured "
                         "against (0: skip)")
    ap.add_argument("--method", help="passed as method= to hemocircuit's simulate (e.g. BDF, LSODA, Radau)")
    ap.add_argument("--engine", help="passed as engine= to every hemocircuit API call that accepts it")
    ap.add_argument("--hc-kw", action="append", metavar="KEY=VALUE",
                    help="extra keyword for the hemocircuit API calls that accept it (repeatable, YAML value)")
    ap.add_argument("--rr-atol", type=float, help="roadrunner absolute tolerance (default: roadrunner's, 1e-12)")
    ap.add_argument("--compiled-attr", default="compiled", help="circuit attribute of the compiled evaluator (HOOK)")
    ap.add_argument("--peers", default=PEERS, help="directory of the Antimony peer models")
    ap.add_argument("--out", default=OUT, help="JSON output (default benchmarks/results/peers.json)")
    ap.add_argument("--label", help="free text stored with the results (e.g. which engine was measured)")
    a = ap.parse_args(argv)
    a.rtols = [float(v) for v in a.rtols.split(",") if v.strip()]
    hc_kw = parse_kw(a.hc_kw)
    if a.method:
        hc_kw["method"] = a.method
    if a.engine:
        hc_kw["engine"] = a.engine
    todo = a.only or list(SCENARIOS)
    funcs = {"vasomotion": bench_vasomotion, "artcomp": bench_artcomp, "envelope": bench_envelope,
             "freq": bench_freq, "rhs": bench_rhs}
    results = {}
    for name in SCENARIOS:
        if name not in todo:
            continue
        log(f"== {name}")
        t0 = time.perf_counter()
        results[name] = funcs[name](a, hc_kw)
        results[name]["scenario_wall_s"] = time.perf_counter() - t0
    print()
    print(table(results))
    data = {}
    if os.path.exists(a.out):
        try:
            with open(a.out) as fh:
                data = json.load(fh)
        except (OSError, ValueError):
            data = {}
    data.setdefault("scenarios", {})
    m = meta(a, hc_kw)
    for name, r in results.items():
        r["meta"] = m
        data["scenarios"][name] = r
    data["meta"] = m
    os.makedirs(os.path.dirname(os.path.abspath(a.out)), exist_ok=True)
    with open(a.out, "w") as fh:
        json.dump(_jsonable(data), fh, indent=1)
    print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
