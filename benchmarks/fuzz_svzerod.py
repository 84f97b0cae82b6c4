"""Fuzzing the svZeroDSolver surface: mutated copies of their shared test cases
(``../shared/svzerod/cases``), each imported and checked through the library and, for a share
of them, run with their settings (``tran MODEL.json --svzerod-output``), in a forked child
process with a time limit (20 s) and a memory limit (2 GiB above the parent's size).

    python benchmarks/fuzz_svzerod.py --cases 1000              # corpus in /tmp/hemocircuit-fuzz-svz
    python benchmarks/fuzz_svzerod.py --cases 100 --seed 3 --jobs 1
    python benchmarks/fuzz_svzerod.py --import-times            # the importer on chains of 2 000 .. 20 000 vessels

Mutations (:func:`mutate`): values replaced by None, true, strings (paths among them), lists,
mappings, NaN, infinities, huge integers (10**400), negative, zero, tiny and huge numbers;
numbers scaled by 10**-300 .. 10**300 or, plausibly, by 10**-8 .. 10**8, negated, zeroed;
keys and list items deleted; list items and whole blocks duplicated; a block given another's
name; simulation settings broken (None, "10", 2.5, -3, 0, 1e-30, 1e12, 1e300, NaN, inf, ...);
time series broken (NaN, inf, a string, None, a value dropped, reversed times, 1e300, emptied);
the initial condition broken; the JSON text cut, truncated or salted; nesting 30 .. 5000 deep.

Each case (a mutated JSON model) is, in its child:
  1. imported from its file (``import_svzerod(path)``, the input policy's JSON reader: NaN and
     Infinity literals refused there);
  2. imported from the parsed dict (``import_svzerod(cfg)``, the API: NaN and infinities reach
     the importer's own checks);
  3. checked (``hemocircuit check MODEL.json``) and, when accepted, ``hemocircuit op``;
  4. for a share of the accepted ones, ``hemocircuit tran MODEL.json --svzerod-output R.json
     --out S.csv``: their cycles and points per cycle (bounded by the SVZEROD_POINTS limit,
     lowered in the children to ``--max-points``: a valid model of millions of points is a
     long run, not a defect), both outputs then read back and checked to be finite.

Counts: clean errors (HemocircuitError, exit 2), accepted, tracebacks (any other exception),
runs over the time limit, runs over the memory limit (RLIMIT_AS in the child, and its
ru_maxrss), silent NaN/inf (a command that exits 0 with a non-finite number in what it printed
or wrote), reads outside the allowed folders (an audit hook in the child records every file
opened; a secret file with a random token is planted beside the corpus and named by some
mutations; its token must never appear in any output either).  The corpus and report
(report.json: the first examples of each failure kind with the case file) are written OUTSIDE
the project (``--dir``).

The mutations (:func:`mutate`) are also used by tests/test_svzerod_inputs.py (a quick sample).
"""
from __future__ import annotations

import argparse
import copy
import io
import json
import os
import random
import re
import shutil
import sys
import tempfile
import time
import traceback

from fork_children import wait_one as _wait  # noqa: E402 - a sibling module (benchmarks/)

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
SHARED = os.environ.get("SVZEROD_CASES", os.path.join(os.path.dirname(ROOT), "shared", "svzerod"))

NAME_KEYS = ("vessel_name", "bc_name", "junction_name", "name")
SIM_KEYS = ("number_of_cardiac_cycles", "number_of_time_pts_per_cardiac_cycle", "cardiac_period",
            "output_interval", "steady_initial", "output_all_cycles", "output_mean_only", "output_variable_based",
            "output_derivative", "use_cycle_to_cycle_error", "sim_cycle_to_cycle_percent_error",
            "absolute_tolerance")


def hostile(rnd, secret):
    """A value that has broken readers before."""
    return rnd.choice([
        None, True, False, "", "abc", "1.5", "x" * 20000, [], [1, 2], [[1.0]], {}, {"a": 1}, {"t": [0, 1]},
        float("nan"), float("inf"), float("-inf"), 10 ** 400, -10 ** 400, 10 ** 30, 2 ** 63, -1, -5, 0, 0.0, -0.0,
        1e300, -1e300, 1e-300, 5e-324, 2.5, 1e12, 1e308, secret, "/etc/passwd", "../outside/secret.txt",
        [float("nan"), 1.0], ["a", "b"], [None], [1e300, -1e300],
    ])


def sim_value(rnd):
    """A hostile value for a simulation parameter."""
    return rnd.choice([None, "10", "abc", 2.5, -3, -1, 0, 1, 2, 0.0, 1e-30, 1e12, 1e300, float("nan"), float("inf"),
                       10 ** 400, 10 ** 12, True, False, [5], {"n": 5}, 3.0, 7])


def _paths(node, path=()):
    """Every (path, value) of the JSON tree below ``node`` (the 'description' left out)."""
    out = []
    if isinstance(node, dict):
        for k, v in node.items():
            if path == () and k in ("description", "_comment") or str(k).startswith("_diagram"):
                continue
            out.append((path + (k,), v))
            out += _paths(v, path + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            out.append((path + (i,), v))
            out += _paths(v, path + (i,))
    return out


def _get(node, path):
    for k in path:
        node = node[k]
    return node


def _blocks(cfg):
    return [b for k in ("vessels", "boundary_conditions", "junctions", "valves", "chambers", "closed_loop_blocks")
            for b in (cfg.get(k) or []) if isinstance(b, dict)]


def mutate(rnd: random.Random, cfg: dict, secret: str):
    """One mutated model from ``cfg`` (left unchanged): (the model as a dict, or None when the
    mutation is of the text; the JSON text written to the case file)."""
    cfg = copy.deepcopy(cfg)
    kind = rnd.choice(["value"] * 5 + ["scale"] * 2 + ["tweak"] * 3 + ["delete"] * 2 +
                      ["duplicate", "rename", "sim", "sim", "series", "series", "ic", "text", "nest"])
    for _ in range(rnd.randint(1, 3) if kind in ("value", "scale", "tweak", "delete") else 1):
        spots = _paths(cfg)
        if kind == "value" and spots:
            leaves = [(p, v) for p, v in spots if not isinstance(v, (dict, list))]
            path, _ = rnd.choice(leaves if leaves and rnd.random() < 0.8 else spots)
            _get(cfg, path[:-1])[path[-1]] = hostile(rnd, secret)
        elif kind == "scale":
            nums = [(p, v) for p, v in spots if isinstance(v, (int, float)) and not isinstance(v, bool)]
            if nums:
                path, v = rnd.choice(nums)
                new = rnd.choice([-v, v * 10.0 ** rnd.randint(-300, 300), v + 0.5, 0 * v, int(v) * 10 ** 20])
                _get(cfg, path[:-1])[path[-1]] = new
        elif kind == "tweak":  # a plausible-looking change (often still a valid model): the numerics
            nums = [(p, v) for p, v in spots if isinstance(v, (int, float)) and not isinstance(v, bool)
                    and "simulation_parameters" not in p]
            if nums:
                path, v = rnd.choice(nums)
                new = rnd.choice([-v, v * 10.0 ** rnd.randint(-8, 8), v * rnd.uniform(0, 3), 0.0, v + 1])
                _get(cfg, path[:-1])[path[-1]] = new
        elif kind == "delete" and spots:
            path, _ = rnd.choice(spots)
            del _get(cfg, path[:-1])[path[-1]]
    if kind == "duplicate":  # a block twice (duplicate names), or a list item repeated
        lists = [(p, v) for p, v in _paths(cfg) if isinstance(v, list) and v]
        if lists:
            path, v = rnd.choice(lists)
            v.insert(rnd.randrange(len(v) + 1), copy.deepcopy(rnd.choice(v)))
    elif kind == "rename":  # a block takes the name of another one
        named = [(b, k) for b in _blocks(cfg) for k in NAME_KEYS if k in b]
        if len(named) > 1:
            (b, k), (o, ok) = rnd.sample(named, 2)
            b[k] = o[ok]
    elif kind == "sim":
        sp = cfg.setdefault("simulation_parameters", {})
        if isinstance(sp, dict):
            for _ in range(rnd.randint(1, 2)):
                sp[rnd.choice(SIM_KEYS)] = sim_value(rnd)
    elif kind == "series":  # a time series with NaN, inf, a string, a wrong length, unsorted times, 1e300
        series = [(p, v) for p, v in _paths(cfg) if isinstance(v, list) and len(v) > 1
                  and all(isinstance(x, (int, float)) for x in v)]
        if series:
            path, v = rnd.choice(series)
            i = rnd.randrange(len(v))
            op = rnd.choice(["nan", "inf", "str", "short", "unsorted", "huge", "none", "empty"])
            if op in ("nan", "inf", "str", "huge", "none"):
                v[i] = {"nan": float("nan"), "inf": float("inf"), "str": "1.0", "huge": 1e300, "none": None}[op]
            elif op == "short":
                del v[i]
            elif op == "unsorted":
                v.reverse()
            else:
                v.clear()
    elif kind == "ic":
        ic = cfg.setdefault("initial_condition", {})
        if isinstance(ic, dict):
            key = rnd.choice(list(ic) + ["pressure_all", "flow_all", "nope:x"]) if ic else "pressure_all"
            ic[key] = hostile(rnd, secret)
        else:
            cfg["initial_condition"] = hostile(rnd, secret)
    elif kind == "nest":  # deep nesting or a top-level section of the wrong kind
        if rnd.random() < 0.5:  # the text holds the deep list; the dict (for the API) 60 levels of it
            depth = rnd.choice([30, 60, 5000])
            deep = 0
            for _ in range(min(depth, 60)):
                deep = [deep]
            key = rnd.choice(["vessels", "junctions", "boundary_conditions", "initial_condition"])
            cfg[key] = "__DEEP__"
            text = json.dumps(cfg, indent=1).replace('"__DEEP__"', "[" * depth + "0" + "]" * depth)
            cfg[key] = deep
            return cfg, text
        else:
            cfg[rnd.choice(["vessels", "junctions", "boundary_conditions", "valves", "chambers",
                            "closed_loop_blocks", "simulation_parameters", "initial_condition"])] = hostile(rnd, secret)
    try:
        text = json.dumps(cfg, indent=1)
    except (ValueError, RecursionError):  # an integer json cannot write, or nesting too deep for it
        cfg["vessels"] = "unwritable"
        text = json.dumps(cfg, indent=1)
    if kind == "text":  # cut, repeat or insert raw text: mostly invalid JSON
        pos = rnd.randrange(max(1, len(text)))
        op = rnd.choice(["cut", "insert", "truncate"])
        if op == "cut":
            text = text[:pos] + text[pos + rnd.randint(1, 40):]
        elif op == "insert":
            junk = "".join(rnd.choice('{}[]:,"\\ 0123456789eE.-NaInfty') for _ in range(rnd.randint(1, 8)))
            text = text[:pos] + junk + text[pos:]
        else:
            text = text[:pos]
        return None, text
    return cfg, text


# ------------------------------------------------------------------------------ the child ----
def _allowed_roots(corpus):
    import site
    import sysconfig

    roots = {ROOT, corpus, sys.prefix, sys.base_prefix, sys.exec_prefix, "/proc", "/sys", "/dev",
             os.path.expanduser("~/.cache"), os.path.expanduser("~/.config/matplotlib"),
             "/usr/lib", "/usr/lib64", "/lib", "/lib64", "/usr/share", "/etc/ld.so.cache", "/etc/localtime",
             "/etc/fonts", "/usr/local/lib", tempfile.gettempdir() + os.sep + "hemocircuit_svz_",
             os.environ.get("HEMOCIRCUIT_CACHE_DIR") or "/nonexistent",
             os.environ.get("NUMBA_CACHE_DIR") or "/nonexistent"}
    for p in list(sysconfig.get_paths().values()) + list(getattr(site, "getsitepackages", lambda: [])()):
        roots.add(p)
    return tuple(os.path.realpath(r) if not r.endswith("_") else r for r in roots)


def _finite_outputs(paths):
    """The first non-finite number written in these output files (CSV or JSON), or None."""
    for p in paths:
        if not os.path.exists(p):
            continue
        with open(p, errors="replace") as fh:
            text = fh.read()
        body = "\n".join(ln for ln in text.splitlines() if not ln.startswith("#"))
        m = re.search(r"(?<![\w.])-?(nan|inf|infinity)(?![\w])", body, re.I)
        if m:
            return f"{os.path.basename(p)}: {m.group(0)}"
    return None


def _child(case_path, cfg, out_path, mem_bytes, run_tran, corpus, max_points, token):
    """In the forked child: limits, audit hook, the steps of the module's docstring."""
    import resource

    resource.setrlimit(resource.RLIMIT_AS, (mem_bytes, mem_bytes))
    fd = os.open(out_path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
    os.dup2(fd, 1)
    os.dup2(fd, 2)
    sys.stdout = io.TextIOWrapper(os.fdopen(1, "wb", buffering=0), write_through=True)
    sys.stderr = sys.stdout
    os.environ["HEMOCIRCUIT_MAX_SVZEROD_POINTS"] = str(max_points)
    roots = _allowed_roots(corpus)
    outside = []

    def hook(event, args):
        if event == "open" and args and isinstance(args[0], (str, bytes, os.PathLike)):
            p = os.fsdecode(args[0])
            real = os.path.realpath(p) if not os.path.isabs(p) or ".." in p or os.path.islink(p) else p
            if not real.startswith(roots) and token not in real:
                outside.append(real)
            elif "outside" in real and "secret" in real:
                outside.append(real)
    sys.addaudithook(hook)
    from hemocircuit.cli import main
    from hemocircuit.errors import HemocircuitError
    from hemocircuit.svzerod import import_svzerod

    code = 0
    try:
        for label, arg in (("import(file)", case_path), ("import(dict)", cfg)):
            if arg is None:
                continue
            print(f"$ {label}")
            try:
                import_svzerod(arg)
                print("[ok]")
            except HemocircuitError as exc:
                print(f"[error] {str(exc)[:400]}")
        argvs = [["check", case_path], ["op", case_path]]
        if run_tran:
            argvs.append(["tran", case_path, "--svzerod-output", case_path[:-5] + ".result.json", "--out",
                          case_path[:-5] + ".series.csv", "--quiet"])
        for argv in argvs:
            print(f"$ hemocircuit {' '.join(argv)}")
            code = main(argv)
            print(f"[exit {code}]")
            if code:
                break
        if code == 0:
            bad = _finite_outputs([case_path[:-5] + ".result.json", case_path[:-5] + ".series.csv"])
            if bad:
                print(f"SILENT-NONFINITE {bad}")
        code = 2 if code else 0
    except MemoryError:
        print("MEMORY-OVERRUN")
        code = 4
    except BaseException:  # noqa: BLE001 - what the fuzzer looks for
        traceback.print_exc()
        code = 3
    if outside:
        print("READ-OUTSIDE " + " ".join(sorted(set(outside))[:5]))
    sys.stdout.flush()
    os._exit(code)


def classify(output: str, status: str, token: str) -> list[str]:
    kinds = []
    if status == "timeout":
        kinds.append("timeout")
    if status == "memory" or "MEMORY-OVERRUN" in output or "MemoryError" in output:
        kinds.append("memory")
    elif "Traceback (most recent call last)" in output:
        kinds.append("traceback")
    if token in output or re.search(r"root:[x*!]?:0:0", output) or "READ-OUTSIDE" in output:
        kinds.append("read_outside")
    if "SILENT-NONFINITE" in output:
        kinds.append("silent_nonfinite")
    for cmd in ("op", "tran"):
        part = output.split(f"$ hemocircuit {cmd}", 1)
        if len(part) == 2:
            body = part[1].split("$ hemocircuit", 1)[0]
            if "[exit 0]" in body and re.search(r"(?<![\w.])-?(nan|inf)(?![\w])", body, re.I):
                kinds.append("silent_nonfinite")
    return kinds


# ------------------------------------------------------------------------------ the runner ----
def load_cases(folder=None):
    # SHARED read at call time: tests/test_svzerod_inputs.py points it elsewhere after import
    cases = os.path.join(folder or SHARED, "cases")
    out = {}
    for f in sorted(os.listdir(cases)):
        if f.endswith(".json"):
            with open(os.path.join(cases, f)) as fh:
                out[f[:-5]] = json.load(fh)
    return out


def warm_up(bases, quiet=True):
    """Run each base case once in this process: the compiled engines of their sets of component
    types are built (or loaded from the cache) here, and every forked child inherits them."""
    import contextlib

    from hemocircuit.cli import main

    with tempfile.TemporaryDirectory() as d:
        for name in bases:
            path = os.path.join(SHARED, "cases", name + ".json")
            with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
                main(["tran", path, "--svzerod-output", os.path.join(d, "r.json"), "--quiet", "--compile", "wait"])


def run(cases, seed, folder, jobs=2, timeout=20.0, mem_gib=2.0, quiet=False, tran_share=0.5, tran_bases=None,
        max_points=100_000, budget_s=None, keep=False):
    """Run ``cases`` mutated models; stop launching new ones after ``budget_s`` seconds.
    ``tran_bases``: the base cases whose mutants may run ``tran`` (default all).  Returns the
    report (also written to report.json)."""
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    rnd = random.Random(seed)
    corpus = os.path.join(folder, "corpus")
    secret_dir = os.path.join(folder, "outside")
    shutil.rmtree(corpus, ignore_errors=True)
    os.makedirs(corpus)
    os.makedirs(secret_dir, exist_ok=True)
    token = f"SECRET-TOKEN-{rnd.getrandbits(64):016x}"
    secret = os.path.join(secret_dir, "secret.txt")
    with open(secret, "w") as fh:
        fh.write(f'{{"{token}": "{token}"}}\n')
    bases = load_cases()
    tran_bases = sorted(bases) if tran_bases is None else list(tran_bases)
    import hemocircuit.analyses.op  # noqa: F401 - imported once in the parent, inherited by every child
    import hemocircuit.circuit  # noqa: F401
    import hemocircuit.cli  # noqa: F401
    from hemocircuit.units import registry

    registry()
    t_warm = time.time()
    warm_up(tran_bases)
    t_warm = time.time() - t_warm
    with open("/proc/self/status") as fh:
        vm = int(re.search(r"VmSize:\s+(\d+)", fh.read()).group(1)) * 1024
    mem_bytes = vm + int(mem_gib * 2 ** 30)
    counts = {k: 0 for k in ("accepted", "clean_error", "traceback", "timeout", "memory", "silent_nonfinite",
                             "read_outside")}
    counts["tran_runs"] = 0
    examples: dict = {}
    errors: dict = {}  # the clean errors by kind (their first line, names and numbers masked)
    running = {}
    longest = [0.0, None]
    t0 = time.time()
    done = 0

    def reap(pid, status_code, rusage, st):
        nonlocal done
        case, started, out, path = running.pop(pid)
        took = time.time() - started
        if took > longest[0]:
            longest[:] = [took, path]
        with open(out, errors="replace") as fh:
            output = fh.read()
        status = st or ("memory" if rusage.ru_maxrss * 1024 > mem_gib * 2 ** 30 + vm else "")
        kinds = classify(output, status, token)
        code = os.waitstatus_to_exitcode(status_code) if status_code is not None else None
        if not kinds:
            kinds = ["accepted"] if code == 0 else ["clean_error"] if code == 2 else ["traceback"]
            if code not in (0, 2):
                output += f"\n[child ended with {code}]"
        if "$ hemocircuit tran" in output:
            counts["tran_runs"] += 1
        for k in kinds:
            counts[k] += 1
            if k not in ("accepted", "clean_error") and len(examples.setdefault(k, [])) < 25:
                tail = [ln for ln in output.strip().splitlines() if ln.strip()][-3:]
                examples[k].append({"case": path, "tail": [ln[:300] for ln in tail]})
        if "clean_error" in kinds:
            err = next((ln for ln in output.splitlines()
                        if ln.startswith(("[error]", "hemocircuit: error", "error:"))), "")
            err = re.sub(r"^(\[error\]|error:)\s*", "", err).replace(path, "MODEL")
            key = re.sub(r"(?<![A-Za-z_])[-+]?\d[\d.e+-]*", "#", err)[:110]
            errors[key] = errors.get(key, 0) + 1
        if not keep and not any(k not in ("accepted", "clean_error") for k in kinds):
            for suffix in (".out", ".result.json", ".series.csv"):
                with_suffix = path[:-5] + suffix
                if os.path.exists(with_suffix):
                    os.unlink(with_suffix)
        done += 1
        if not quiet and done % 100 == 0:
            print(f"{done}/{cases} in {time.time() - t0:.0f} s: {counts}", flush=True)

    for n in range(cases):
        if budget_s is not None and time.time() - t0 > budget_s:
            break
        base = rnd.choice(sorted(bases))
        cfg, text = mutate(rnd, bases[base], secret)
        path = os.path.join(corpus, f"case_{n:05d}_{base}.json")
        with open(path, "w") as fh:
            fh.write(text)
        out = path[:-5] + ".out"
        run_tran = base in tran_bases and rnd.random() < tran_share
        while len(running) >= jobs:
            _wait(running, timeout, reap)
        pid = os.fork()
        if pid == 0:
            _child(path, cfg, out, mem_bytes, run_tran, corpus, max_points, token)
        running[pid] = (n, time.time(), out, path)
    while running:
        _wait(running, timeout, reap)
    report = {"cases": done, "seed": seed, "seconds": round(time.time() - t0, 1), "warm_up_s": round(t_warm, 1),
              "counts": counts, "longest_case_s": round(longest[0], 2), "longest_case": longest[1],
              "limits": {"timeout_s": timeout, "memory_gib": mem_gib, "svzerod_points": max_points},
              "examples": examples, "errors": dict(sorted(errors.items(), key=lambda kv: -kv[1]))}
    with open(os.path.join(folder, "report.json"), "w") as fh:
        json.dump(report, fh, indent=1)
    return report


BAD = ("traceback", "timeout", "memory", "silent_nonfinite", "read_outside")


def chain(n):
    """An svZeroDSolver model of n vessels in series (FLOW -> v0 -> J0 -> v1 -> ... -> RESISTANCE)."""
    vessels = [{"vessel_id": i, "vessel_name": f"branch{i}_seg0", "zero_d_element_type": "BloodVessel",
                "zero_d_element_values": {"R_poiseuille": 100.0, "C": 1e-4}} for i in range(n)]
    vessels[0]["boundary_conditions"] = {"inlet": "INFLOW"}
    vessels[-1].setdefault("boundary_conditions", {})["outlet"] = "OUT"
    return {"simulation_parameters": {"number_of_cardiac_cycles": 2, "number_of_time_pts_per_cardiac_cycle": 5},
            "vessels": vessels,
            "junctions": [{"junction_name": f"J{i}", "junction_type": "NORMAL_JUNCTION", "inlet_vessels": [i],
                           "outlet_vessels": [i + 1]} for i in range(n - 1)],
            "boundary_conditions": [{"bc_name": "INFLOW", "bc_type": "FLOW",
                                     "bc_values": {"Q": [5.0, 6.0, 5.0], "t": [0.0, 0.5, 1.0]}},
                                    {"bc_name": "OUT", "bc_type": "RESISTANCE", "bc_values": {"R": 100.0, "Pd": 0.0}}]}


def import_times(sizes=(2000, 8000, 20000), repeat=3):
    """Wall time [s] of importing a chain of n vessels from its file (best of ``repeat``): the
    read under the input policy and import_svzerod, and of writing its netlist (import-svzerod)."""
    from hemocircuit.svzerod import import_svzerod, write_netlist

    out = {}
    with tempfile.TemporaryDirectory() as d:
        for n in sizes:
            path = os.path.join(d, f"chain{n}.json")
            with open(path, "w") as fh:
                json.dump(chain(n), fh)
            best = [1e9, 1e9]
            for _ in range(repeat):
                t0 = time.perf_counter()
                m = import_svzerod(path)
                t1 = time.perf_counter()
                write_netlist(m.netlist, os.path.join(d, "m.yaml"))
                t2 = time.perf_counter()
                best = [min(best[0], t1 - t0), min(best[1], t2 - t1)]
            out[n] = {"MB": round(os.path.getsize(path) / 1e6, 2), "import_s": round(best[0], 3),
                      "write_netlist_s": round(best[1], 3)}
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=20250)
    ap.add_argument("--dir", default="/tmp/hemocircuit-fuzz-svz", help="corpus and report (outside the project)")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--timeout", type=float, default=20.0, help="seconds per case")
    ap.add_argument("--memory-gib", type=float, default=2.0)
    ap.add_argument("--tran-share", type=float, default=0.5, help="share of the cases that also run tran")
    ap.add_argument("--keep", action="store_true", help="keep every case's output (not only the failures')")
    ap.add_argument("--max-points", type=int, default=100_000,
                    help="HEMOCIRCUIT_MAX_SVZEROD_POINTS in the children (output points of one tran run)")
    ap.add_argument("--import-times", action="store_true",
                    help="only time the import of chains of 2 000, 8 000 and 20 000 vessels (no fuzzing)")
    args = ap.parse_args(argv)
    if args.import_times:
        for n, row in import_times().items():
            print(f"{n:6d} vessels ({row['MB']} MB): import {row['import_s']:.2f} s, write netlist "
                  f"{row['write_netlist_s']:.2f} s")
        return 0
    if not os.path.isdir(os.path.join(SHARED, "cases")):
        ap.error(f"no svZeroDSolver cases in {SHARED} (set SVZEROD_CASES)")
    if os.path.realpath(args.dir).startswith(os.path.realpath(ROOT) + os.sep):
        ap.error("--dir must be outside the project")
    report = run(args.cases, args.seed, args.dir, args.jobs, args.timeout, args.memory_gib,
                 tran_share=args.tran_share, max_points=args.max_points, keep=args.keep)
    print(json.dumps({k: report[k] for k in ("cases", "seconds", "warm_up_s", "counts", "longest_case_s")}, indent=1))
    for k, ex in report["examples"].items():
        print(f"\n{k}: {len(ex)} example(s), e.g.")
        for e in ex[:8]:
            print(f"  {e['case']}: {' | '.join(e['tail'])}")
    return 1 if sum(report["counts"][k] for k in BAD) else 0


if __name__ == "__main__":
    sys.exit(main())
