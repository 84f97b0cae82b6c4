"""First run of a set of component types: the compiled engine builds in a background process
while the run integrates on the scipy path, and the run hands over to the compiled engine when
the build is ready (hemocircuit.kernels.background, transient.simulate(compile='background'))."""
import os
import subprocess
import sys
import time

import numpy as np
import pytest

import hemocircuit as hc
from hemocircuit.analyses.op import operating_point
from hemocircuit.kernels import background
from hemocircuit.kernels.system import CompiledSystem

from paths import ROOT, TESTS

TEST_NETLISTS = os.path.join(TESTS, "netlists")
NETLISTS = os.path.join(ROOT, "netlists")


class FakeBuild:
    """background.start/ready stand-ins: no process; 'ready' after ``after`` checks."""

    def __init__(self, monkeypatch, after):
        self.checks, self.starts, self.after = 0, 0, after
        monkeypatch.setattr(background, "ready", self.ready)
        monkeypatch.setattr(background, "start", self.start)

    def ready(self, system):
        self.checks += 1
        return self.after is not None and self.checks > self.after

    def start(self, system, circuit, x0, t0, rtol):
        self.starts += 1
        return True


def _forced(tmp_path):
    """Arterial compliance driven by a 0.1 Hz sine, with a protocol step of Pa at 30 s."""
    c = hc.load(os.path.join(NETLISTS, "arterial_compliance.yaml"))
    c = c.with_values({"Pa.amplitude": "8 mmHg", "Pa.frequency": "0.1 Hz"})
    proto = tmp_path / "step.yaml"
    proto.write_text("t_end: 60 s\nevents:\n  - {at: 30 s, set: {Pa.value: 90 mmHg}}\n")
    return c, str(proto)


def test_handover_to_the_compiled_engine(tmp_path, monkeypatch):
    """The run starts on scipy, switches at the end of a piece once the build is ready, and
    continues compiled through a later protocol event: the output grid is exactly the
    requested one (pieces add no rows) and the course is the compiled engine's own."""
    c, proto = _forced(tmp_path)
    ref = c.simulate(None, dt=0.1, protocol=proto, engine="compiled", rtol=1e-8)
    fake = FakeBuild(monkeypatch, after=3)
    res = c.simulate(None, dt=0.1, protocol=proto, rtol=1e-8, compile="background")
    assert fake.starts == 1
    t_s = res.stats["switched_at"]
    assert 0 < t_s < 30.0  # handed over before the event, which the compiled part applies
    assert "scipy" in res.stats["method"] and "compiled" in res.stats["method"]
    assert res.stats["scipy"]["nsteps"] > 0 and res.stats["steps"] > 0
    assert np.allclose(res.t, ref.t, rtol=0, atol=1e-9) and len(res.t) == len(ref.t)
    for col in ("art.r", "Q(Rla)", "V(Ca)"):
        scale = np.max(np.abs(ref[col]))
        assert np.max(np.abs(res[col] - ref[col])) / scale < 2e-6, col
    # the step of Pa to 90 mmHg at 30 s is applied after the switch: the input's mean rises
    assert abs(np.mean(res["P(in)"][res.t > 30.05]) - 90.0) < 1.0
    assert abs(np.mean(res["P(in)"][(res.t > 0) & (res.t < 30)]) - float(np.ravel(c.parameters.values["Pa.value"])[0])) < 1.0


def test_build_never_ready_scipy_to_the_end(tmp_path, monkeypatch):
    """A build that does not finish during the run: the whole run on scipy, in pieces that
    keep the requested grid, marked as such; same course as one scipy run."""
    c, proto = _forced(tmp_path)
    ref = c.simulate(None, dt=0.1, protocol=proto, engine="scipy", rtol=1e-8)
    fake = FakeBuild(monkeypatch, after=None)
    res = c.simulate(None, dt=0.1, protocol=proto, rtol=1e-8, compile="background")
    assert fake.checks >= 3  # it was asked between pieces
    assert res.stats["compiled_engine"] == "building in the background" and res.stats["method"] == "BDF"
    assert np.array_equal(res.t, ref.t)
    for col in ("art.r", "Q(Rla)"):
        scale = np.max(np.abs(ref[col]))
        assert np.max(np.abs(res[col] - ref[col])) / scale < 2e-6, col


def test_engine_ready_means_no_background(tmp_path, monkeypatch):
    """With the engine built (ready marker present), compile='background' runs compiled from
    the start and starts no build."""
    c, proto = _forced(tmp_path)
    c.simulate(1.0, engine="compiled")  # builds (or loads) and marks ready
    system = CompiledSystem.of(c)
    assert background.ready(system)
    started = []
    monkeypatch.setattr(background, "start", lambda *a: started.append(a) or True)
    res = c.simulate(5.0, dt=0.1, compile="background")
    assert not started and "switched_at" not in res.stats and "compiled" in res.stats["method"]


def test_failed_build_compiles_in_the_foreground(monkeypatch):
    """After a failed background build no new one starts (start() is False): the run
    compiles in the foreground, where an error would show."""
    c = hc.load(os.path.join(TEST_NETLISTS, "base_rc.yaml"))
    system = CompiledSystem.of(c)
    monkeypatch.setattr(background, "ready", lambda s: False)
    monkeypatch.setattr(background, "failed", lambda s: True)
    res = c.simulate(2.0, dt=0.1, x0=np.zeros(c.nx), compile="background")
    assert "compiled" in res.stats["method"] and "switched_at" not in res.stats
    assert background.start(system, c, np.zeros(c.nx), 0.0, 1e-6) is False


def test_builder_process_marks_ready():
    """The real builder: a detached process that compiles (or loads) the engine, runs the
    transient entry points and leaves the ready marker, no running marker and its log."""
    c = hc.load(os.path.join(TEST_NETLISTS, "base_rc.yaml"))
    system = CompiledSystem.of(c)
    ready = background._marker(system, "ready")
    ready.unlink(missing_ok=True)
    assert background.start(system, c, np.zeros(c.nx), 0.0, 1e-6)
    assert background.start(system, c, np.zeros(c.nx), 0.0, 1e-6)  # one build at a time: no second
    deadline = time.monotonic() + 600  # a cold compile on a busy 2-core machine
    while not (background.ready(system) or background.failed(system)) and time.monotonic() < deadline:
        time.sleep(0.5)
    assert background.ready(system), background._marker(system, "failed").read_text() if background.failed(system) else ""
    for _ in range(40):  # the builder removes its running marker just before marking ready
        if not background.building(system):
            break
        time.sleep(0.25)
    assert not background.building(system)
    log = ready.with_name(ready.name.split(".")[0] + ".build.log").read_text()
    assert "ready after" in log


def test_compile_option_checked():
    """A bad --compile / $HEMOCIRCUIT_COMPILE value is a clear error, not a traceback."""
    env = dict(os.environ, HEMOCIRCUIT_COMPILE="soon")
    p = subprocess.run([sys.executable, "-m", "hemocircuit.cli", "tran", os.path.join(TEST_NETLISTS, "base_rc.yaml"),
                        "--t-end", "1", "--quiet"], capture_output=True, text=True, env=env, cwd=ROOT)
    assert p.returncode != 0
    assert "HEMOCIRCUIT_COMPILE" in p.stderr and "Traceback" not in p.stderr
    with pytest.raises(hc.errors.SolverError, match="choose 'wait' or 'background'"):
        hc.load(os.path.join(TEST_NETLISTS, "base_rc.yaml")).simulate(1.0, compile="later")


def test_handover_at_a_hard_limit(monkeypatch):
    """In an oscillation every piece of the scipy path may end on a hard limit (the Ca floor
    of vasomotion): the build's readiness is asked there too, and the compiled engine goes on
    from the state put on the bound.  Pieces here run to the end of the segment, so the only
    chances to switch are the floor events."""
    from hemocircuit.analyses import transient

    c = hc.load(os.path.join(NETLISTS, "vasomotion.yaml"))
    x0 = operating_point(c).x.copy()
    x0[c.state_names.index("art.lambda")] *= 1.05
    ref = c.simulate(60.0, dt=0.1, x0=x0, engine="compiled", rtol=1e-8)
    FakeBuild(monkeypatch, after=1)
    monkeypatch.setattr(transient._Handover, "end_of", lambda self, cur, b, t_grid: b)
    res = c.simulate(60.0, dt=0.1, x0=x0, rtol=1e-8, compile="background")
    t_s = res.stats["switched_at"]
    assert 0 < t_s < 60.0 and abs(t_s / 0.1 - round(t_s / 0.1)) > 1e-6  # at an event, off the grid
    assert res.stats["limit_events"] >= 2 and np.min(res["art.Ca"]) >= c.hard_limits()[0][1] - 1e-15
    on_grid = np.isin(np.round(res.t, 9), np.round(ref.t, 9))
    assert np.max(np.abs(res["art.r"][on_grid] - ref["art.r"])) < 0.05  # um, on ~40 um swings


_PREBUILD_SCRIPT = r"""
import json, os, sys
import numpy as np
import hemocircuit as hc
from hemocircuit.kernels import prebuild
from hemocircuit.kernels.system import CompiledSystem
c = hc.load(sys.argv[1])
system = CompiledSystem.of(c)
fn = system.mod.integrate_batch
before = prebuild.in_cache(fn)
proc = prebuild.start(system)
rc = proc.wait(timeout=900) if proc is not None else None
after = prebuild.in_cache(fn)
again = prebuild.start(system)  # cached now: no second helper
t = np.linspace(0.0, 5.0, 101)
X, st = system.integrate_batch(t, np.zeros((1, c.nx)), system.params(c), rtol=1e-8)
out = c.outputs(t, X[0])  # 101 rows: through the compiled nodal solve, which the helper compiled too
nf, rf = system.mod.nodal_outputs, system.mod.release_fraction
print(json.dumps({"before": before, "rc": rc, "after": after, "again": again is None,
                  "loaded_not_compiled": [bool(f.stats.cache_hits and not f.stats.cache_misses) for f in (fn, rf, nf)],
                  # prebuild.before_integrator compiled these by signature before the integrator:
                  # one specialisation each means the integrator called those, not new ones
                  "specialisations": [len(getattr(system.mod, name).overloads)
                                      for name in ("prepare_static", "rhs_into_at", "local_jacobian_into_at")],
                  "V": X[0, :, c.state_names.index("C1.V")].tolist(), "Q": out["Q(R1)"].tolist(),
                  "status": float(st[0, 0])}))
"""


def _run_in_fresh_cache(script, tmp_path):
    """Run ``script`` on base_rc.yaml in a new process with empty numba and hemocircuit caches
    (the prebuild helper on); returns the JSON it prints last."""
    import json

    env = {**os.environ, "HEMOCIRCUIT_CACHE_DIR": str(tmp_path / "hc"), "NUMBA_CACHE_DIR": str(tmp_path / "nb"),
           "HEMOCIRCUIT_ENGINE_TYPES": "used", "HEMOCIRCUIT_PREBUILD": "1"}
    out = subprocess.run([sys.executable, "-c", script, os.path.join(TEST_NETLISTS, "base_rc.yaml")],
                         env=env, capture_output=True, text=True, timeout=1200)
    assert out.returncode == 0, out.stderr[-3000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_prebuild_helper_compiles_the_integrator(tmp_path):
    """kernels.prebuild in a fresh cache: the helper process compiles the Rosenbrock integrator
    (for a single run's argument types, its callees as addresses), release_fraction and the
    outputs' nodal_outputs into numba's cache, so this process loads them instead of compiling
    them (numba's cache hit, no miss); this process compiles prepare_static, rhs_into_at and
    local_jacobian_into_at by the signatures the integrator calls them with (one
    specialisation each); no second helper starts once it is cached, and the run is right (R-C
    charging, V = C P (1 - exp(-t/RC)), Q = P/R exp(-t/RC))."""
    r = _run_in_fresh_cache(_PREBUILD_SCRIPT, tmp_path)
    assert r["before"] is False and r["rc"] == 0 and r["after"] is True and r["again"] is True
    assert r["loaded_not_compiled"] == [True, True, True], r
    assert r["specialisations"] == [1, 1, 1], r
    t = np.linspace(0.0, 5.0, 101)
    assert r["status"] == 0
    assert np.max(np.abs(np.array(r["V"]) - 0.5 * 80.0 * (1 - np.exp(-t)))) < 2e-7 * 40.0
    # the flow through R = 2 mmHg s/mL: (80 mmHg - V/C) / R = 40 exp(-t) mL/s
    assert np.max(np.abs(np.array(r["Q"]) - 40.0 * np.exp(-t))) < 2e-7 * 40.0


_BEFORE_SCRIPT = r"""
import json, subprocess, sys
import numpy as np
import hemocircuit as hc
from hemocircuit.kernels import prebuild
from hemocircuit.kernels.system import CompiledSystem
c = hc.load(sys.argv[1])
system = CompiledSystem.of(c)
mod = system.mod
# a stand-in helper that compiles nothing and ends after 1 s: before_integrator must compile the
# nodal solve, the right-hand side and the Jacobian here, then wait for it (the integrator never
# appears in the cache)
proc = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(1.0)"])
prebuild._pending[mod.__name__] = proc
prebuild._decided.add(mod.__name__)  # and no real helper for the integrator below: it compiles everything here
prebuild.before_integrator(system)
rc_at_return = proc.returncode  # set by before_integrator's poll only if it saw the helper end
compiled_here = [len(mod.prepare_static.overloads), len(mod.rhs_into_at.overloads), len(mod.release_fraction.overloads),
                 len(mod.local_jacobian_into_at.overloads)]
prebuild.before_integrator(system)  # once per module: returns at once
t = np.linspace(0.0, 5.0, 101)
X, st = system.integrate_batch(t, np.zeros((1, c.nx)), system.params(c), rtol=1e-8)
# the run compiled the helper's part itself here: the signatures the helper compiles by are the
# ones the run used, so the helper's work is loaded, not done again
from hemocircuit.kernels import pointers
types, sigs = pointers.single_run(mod, system.lay, c.nx, system.layout.n_params, system.scales, system.lim_i,
                                  system.lim_b, system.lim_r)
helper_sigs = [sig in fn.signatures for fn, sig in prebuild.helper_signatures(mod, system.lay, c.nx,
                                                                              system.layout.n_params)]
helper_sigs += [types in mod.integrate_batch.signatures, sigs[3].args in mod.release_fraction.signatures]
print(json.dumps({"compiled_here": compiled_here, "rc_at_return": rc_at_return, "helper_sigs": helper_sigs,
                  "finish_member_sigs": len(mod.finish_member.signatures),
                  "after": [len(mod.prepare_static.overloads), len(mod.rhs_into_at.overloads),
                            len(mod.release_fraction.overloads)],
                  "V": X[0, :, c.state_names.index("C1.V")].tolist(), "status": float(st[0, 0])}))
"""


def test_before_integrator_compiles_its_part_here_and_waits_for_the_helper(tmp_path):
    """kernels.prebuild.before_integrator, with a stand-in helper that compiles nothing and
    ends after 1 s: it compiles prepare_static, rhs_into_at and local_jacobian_into_at in this
    process (one specialisation each, which the integrator then calls: still one each after the
    run), not release_fraction (the helper's part), and returns only once the helper has ended,
    since the integrator never appears in the cache; the run then compiles the helper's part
    itself, with the signatures the helper compiles by (prebuild.helper_signatures and
    pointers.single_run: else the helper's work would be done twice); the run is right
    (V = C P (1 - exp(-t/RC)))."""
    r = _run_in_fresh_cache(_BEFORE_SCRIPT, tmp_path)
    assert r["compiled_here"] == [1, 1, 0, 1], r
    # elem_derivs_jac, elem_derivs, the integrator, release_fraction; and one finish_member for
    # every call (no literal specialisation)
    assert r["helper_sigs"] == [True] * 4 and r["finish_member_sigs"] == 1, r
    assert r["rc_at_return"] == 0, r  # it returned after the helper ended, not before
    assert r["after"] == [1, 1, 1] and r["status"] == 0, r
    t = np.linspace(0.0, 5.0, 101)
    assert np.max(np.abs(np.array(r["V"]) - 0.5 * 80.0 * (1 - np.exp(-t)))) < 2e-7 * 40.0
