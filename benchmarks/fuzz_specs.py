"""Fuzzing fit and sensitivity specs: mutated copies of the specs in examples/fitting/,
examples/sensitivity/ and of the test suite's specs on tests/fitting/*.yaml, each in a forked
child process with a time limit (20 s of CPU time, and 60 s of wall-clock time for what waits
without computing) and a memory limit (2 GiB above the parent's size):

1. *load*: the spec parsed and validated against its netlist, nothing run
   (``fitting.load_problem``; for a sensitivity spec ``load_spec``, ``make_objective`` and
   ``sensitivity.prepare``, which resolves the space and checks the run limits);
2. *run* (``--mode run``, the default): then the command itself with tiny budgets:
   ``hemocircuit fit ... --starts 0 --max-nfev 2 --workers 1 --no-plot --out OUT`` and
   ``hemocircuit op OUT/fitted.yaml``, or ``hemocircuit sensitivity ... --n 2 (4 for sobol)
   --trajectories 2 --scheduler serial --out OUT.csv``.

    python benchmarks/fuzz_specs.py --cases 500              # corpus in /tmp/hemocircuit-fuzz-specs
    python benchmarks/fuzz_specs.py --cases 60 --mode load --seed 3

Mutations: values set to None, strings, lists, mappings, huge, negative, zero, NaN, inf;
keys deleted or added; paths (data ``file``, ``start_from``, ``protocol``, ``fit_error``) to
/etc/passwd, /dev/zero, a FIFO inside and one outside the project, ``../../`` paths, a secret
file outside the project; YAML alias bombs and deep nesting; mutated data files (Latin-1,
NaN, no header, one row, too many rows, long lines); mutated protocols.

Counts: clean errors (exit 2 / a HemocircuitError), accepted, tracebacks (any other
exception), runs over the time limit, runs over the memory limit, reads outside the allowed
folders (every file read through ``hemocircuit.inputs`` is logged and checked against the
corpus project, the repository and the output folders; any open of the outside folder,
/etc/*, /dev/zero or a FIFO counts too), text of outside files in the output (the secret's
random token, /etc/passwd's root line), and silent NaN (a run that exits 0 with NaN in
report.json, which is not JSON, in fit.csv, or in the sensitivity table without a reported
failure).  The corpus and report.json are written OUTSIDE the project (``--dir``).
"""
from __future__ import annotations

import argparse
import io
import json
import math
import os
import random
import re
import shutil
import signal
import sys
import time
import traceback

from fork_children import wait_one as _wait  # noqa: E402 - a sibling module (benchmarks/)

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
ARTERIOLE = os.path.join(ROOT, "netlists", "isolated_arteriole.yaml")

# (spec relative to the corpus project, netlist: 'bundled' or relative to the project, kind)
BASES = [
    ("examples/fitting/kuo91_1_passive.yaml", "bundled", "fit"),
    ("examples/fitting/kuo91_2_active.yaml", "bundled", "fit"),
    ("examples/fitting/kuo91_3_flow.yaml", "bundled", "fit"),
    ("examples/fitting/kuo91_4_dynamic.yaml", "bundled", "fit"),
    ("examples/fitting/kuo91_A_epochs.yaml", "bundled", "fit"),
    ("examples/fitting/falcone91_1_passive.yaml", "bundled", "fit"),
    ("examples/sensitivity/kuo91_fit17.yaml", "bundled", "fit"),
    ("examples/sensitivity/arteriole_op.yaml", "bundled", "sensitivity"),
    ("examples/sensitivity/kuo91_A_dynamic.yaml", "bundled", "sensitivity"),
    ("examples/sensitivity/kuo91_fit_error.yaml", "bundled", "sensitivity"),
    ("tests/fitting/linear_spec.yaml", "tests/fitting/linear.yaml", "fit"),
    ("tests/fitting/rc_spec.yaml", "tests/fitting/rc.yaml", "fit"),
    ("tests/fitting/linear_sens.yaml", "tests/fitting/linear.yaml", "sensitivity"),
]

# the test suite's specs on tests/fitting/*.yaml (tests/test_fit.py, tests/test_sensitivity.py)
LINEAR_SPEC = """name: linear
parameters:
  Ps.value: {bounds: [-50 mmHg, 50 mmHg], start: 0 mmHg}
  R1.R: {bounds: [0.1 mmHg*s/mL, 20 mmHg*s/mL], log: true, start: 0.5 mmHg*s/mL}
datasets:
  - {name: line, file: line.csv, observe: P(b), column: P, sigma: 0.5 mmHg,
     experiment: {type: op, inputs: {Qs.value: Q}}}
settings: {starts: 1, seed: 0, max_nfev: 50, workers: 1}
"""
RC_SPEC = """name: rc
parameters:
  C1.C: {bounds: [0.1 mL/mmHg, 2 mL/mmHg], log: true, start: 1 mL/mmHg}
  R1.R@5s: {bounds: [0.5 mmHg*s/mL, 20 mmHg*s/mL], log: true, start: 1 mmHg*s/mL}
datasets:
  - {name: step, file: rc.csv, observe: P(a), column: P,
     experiment: {type: tran, protocol: rc_protocol.yaml, time: t}}
settings: {starts: 1, max_nfev: 40, workers: 1}
"""
LINEAR_SENS = """description: P(b) of the linear circuit
seed: 1
method: {name: constellation, scheme: additive, n: 10, designs: 3}
parameters:
  - {path: R1.R, lower: 1 mmHg*s/mL, upper: 3 mmHg*s/mL}
ties:
  - {path: Ps.value, scale_with: R1.R, power: -1}
output:
  dc: {column: P(b), sweep: {Qs.value: "0.5:2:0.5 mL/s"}}
"""

HOSTILE_VALUES = [None, "", "abc", [], [1, 2], {}, {"a": 1}, True, 0, -1, 1, 2 ** 40, -(2 ** 40), 2 ** 70,
                  1e308, -1e308, float("nan"), float("inf"), float("-inf"), 1e-320, "nan", "inf", "-1e999",
                  "1e999 mmHg", "nan um", "1 mmHg", "10**10**10", "= 9**9**9**9", "x" * 5000, "1" * 400,
                  "\x00", "ä€\u202e", "${x}", "many", "0.5", 0.5, "1e-300 s", "-5 s", "239s", "2**40"]
PATH_KEYS = ("file", "start_from", "protocol", "fit_error")


def hostile_paths(ctx):
    return ["/etc/passwd", "/dev/zero", "/dev/null", ctx["fifo_in"], ctx["fifo_out"], ctx["secret"],
            "../../../../../../../../etc/shadow", "../" * 12 + "etc/passwd", "..", ".", "/", "",
            os.path.relpath(ctx["secret"], ctx["case_dir"]), "nope.csv", "data", "/proc/self/environ",
            "~/.ssh/id_rsa", "a\x00b", "x" * 5000, ctx["big"], ctx["latin1"]]


def _alias_bomb(levels=9):
    lines = ['a0: &a0 ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]']
    for i in range(1, levels):
        lines.append(f"a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * 9) + "]")
    return lines


def _paths(tree, prefix=()):
    """Every (path, parent, key) of a parsed YAML tree."""
    out = []
    if isinstance(tree, dict):
        for k, v in tree.items():
            out.append((prefix + (k,), tree, k))
            out += _paths(v, prefix + (k,))
    elif isinstance(tree, list):
        for i, v in enumerate(tree):
            out.append((prefix + (i,), tree, i))
            out += _paths(v, prefix + (i,))
    return out


def data_mutation(rnd, text):
    """A mutated data CSV (bytes)."""
    lines = text.splitlines()
    head = [i for i, ln in enumerate(lines) if ln and not ln.startswith("#")][0]
    kind = rnd.choice(["latin1", "nan", "inf", "empty", "header_only", "one_row", "many_rows", "long_line",
                       "bad_unit", "dup_column", "junk", "bom_crlf", "cells", "zero"])
    if kind == "latin1":
        return ("\n".join(lines) + "\n# caf\xe9\n").encode("latin-1")
    if kind in ("nan", "inf", "zero", "cells"):
        i = rnd.randrange(head + 1, len(lines))
        cells = lines[i].split(",")
        j = rnd.randrange(len(cells))
        cells[j] = {"nan": "nan", "inf": "-inf", "zero": "0"}.get(kind) or rnd.choice(["x", "", "1,2", "1e999",
                                                                                         "0x10", "--1"])
        lines[i] = ",".join(cells)
    elif kind == "empty":
        return b""
    elif kind == "header_only":
        lines = lines[:head + 1]
    elif kind == "one_row":
        lines = lines[:head + 2]
    elif kind == "many_rows":
        lines = lines[:head + 1] + [lines[head + 1]] * rnd.choice([2000, 120_000])
    elif kind == "long_line":
        lines.insert(head + 1, "SECRETISH" + "y" * rnd.choice([100, 20000]))
    elif kind == "bad_unit":
        lines[head] = lines[head].replace("[", "[furlong*", 1)
    elif kind == "dup_column":
        lines[head] = lines[head] + "," + lines[head].split(",")[0]
    elif kind == "junk":
        return bytes(rnd.randrange(256) for _ in range(rnd.randint(1, 3000)))
    else:
        return ("\ufeff" + "\r\n".join(lines) + "\r\n").encode()
    return ("\n".join(lines) + "\n").encode()


def mild(rnd, tree):
    """A plausible variant (most of them valid): another method, scheme or setting, a number
    scaled a little."""
    import yaml

    if "method" in tree or "output" in tree:  # a sensitivity spec
        m = tree.get("method")
        m = dict(m) if isinstance(m, dict) else {"name": m or "constellation"}
        choice = rnd.choice(["method", "scheme", "range", "seed"])
        if choice == "method" and "tran" not in (tree.get("output") or {}):
            m = {"name": rnd.choice(["constellation", "morris", "sobol", "local"]), "scheme": m.get("scheme", "additive")}
        elif choice == "scheme" and "fit_error" in (tree.get("output") or {}):
            m["scheme"] = rnd.choice(["additive", "multiplicative"])
        elif choice == "range":
            m["range"] = rnd.choice([1, 5, 25, 50, 90, 99.9])
        else:
            tree["seed"] = rnd.choice([0, 7, 2 ** 32 - 1])
        tree["method"] = m
    else:
        s = dict(tree.get("settings") or {})
        choice = rnd.choice(["bounds", "start_current", "tol", "scale"])
        if choice == "bounds":
            s["bounds"] = rnd.choice(["transform", "reflective"])
        elif choice == "start_current":
            s["start_current"] = rnd.choice([True, False])
        elif choice == "tol":
            s[rnd.choice(["ftol", "xtol", "gtol"])] = rnd.choice([1e-3, 1e-8, 0.5, 0])
        else:
            params = tree.get("parameters") or {}
            if isinstance(params, dict) and params:
                body = params[rnd.choice(list(params))]
                if isinstance(body, dict) and body.get("start") is not None:
                    v = str(body["start"])
                    m = re.match(r"^\s*(-?[\d.]+(?:e-?\d+)?)(.*)$", v)
                    if m:
                        body["start"] = f"{float(m.group(1)) * rnd.choice([0.5, 0.9, 1.1, 2]):g}{m.group(2)}"
        tree["settings"] = s
    return yaml.safe_dump(tree, sort_keys=False)


def mutate(rnd, text, ctx):
    """A mutated spec text and {file name: bytes} of side files to write beside it."""
    import yaml

    side = {}
    if rnd.random() < 0.3:
        return mild(rnd, yaml.safe_load(text)), side
    kind = rnd.choice(["value"] * 5 + ["scale"] * 3 + ["path"] * 3 + ["delete", "add", "data", "data", "protocol",
                                                                      "alias", "deep", "text", "dupkey"])
    if kind == "alias":  # a billion laughs in the description (or the name)
        levels = rnd.choice([6, 9, 12])
        key = rnd.choice(["description", "description", "name"])
        bomb = "".join(f"  - {line.split(': ', 1)[1]}\n" for line in _alias_bomb(levels))
        return re.sub(rf"^{key}:.*$", "", text, flags=re.M) + f"{key}:\n{bomb}", side
    if kind == "deep":
        n = rnd.choice([45, 500, 50000])
        return text + rnd.choice(["\nextra_deep: ", "\ndescription: "]) + "[" * n + "]" * n + "\n", side
    if kind == "dupkey":
        return text + "\nname: twice\nname: again\n", side
    if kind == "text":
        pos = rnd.randrange(max(1, len(text)))
        junk = "".join(rnd.choice("{}[]:,-'\"&*!|>%@` \n\t$=#0123456789eE.") for _ in range(rnd.randint(1, 8)))
        return text[:pos] + junk + text[pos + rnd.randint(0, 5):], side
    tree = yaml.safe_load(text)
    for _ in range(rnd.randint(1, 3)):
        spots = _paths(tree)
        if not spots:
            break
        if kind == "path":
            keyed = [s for s in spots if s[2] in PATH_KEYS or (s[2] == "fit_error")]
            if keyed:
                _, parent, key = rnd.choice(keyed)
                parent[key] = rnd.choice(hostile_paths(ctx))
                continue
            tree["start_from"] = rnd.choice(hostile_paths(ctx))
            continue
        if kind == "data":
            keyed = [s for s in spots if s[2] == "file"]
            if keyed:
                _, parent, key = rnd.choice(keyed)
                src = os.path.join(ctx["case_dir"], parent[key])
                try:
                    base = open(src).read()
                except OSError:
                    base = "t [s],r [um]\n0,1\n1,2\n"
                name = f"mut_{ctx['n']:05d}.csv"
                side[name] = data_mutation(rnd, base)
                parent[key] = name
                continue
        if kind == "protocol":
            keyed = [s for s in spots if s[2] == "protocol"]
            if keyed:
                _, parent, key = rnd.choice(keyed)
                name = f"mut_{ctx['n']:05d}_protocol.yaml"
                side[name] = rnd.choice([
                    b"t_end: 1e300 s\nevents: [{at: 1e299 s, set: {}}]\n", b"t_end: nan s\n", b"events: 5\n",
                    b"t_end: 10 s\ninitial: {art.tau_Ca: -1 s}\n", b"initial: {Nope.x: 1}\n",
                    ("t_end: 10 s\nevents:\n" + "".join(f"  - {{at: {i} ms, set: {{}}}}\n" for i in range(3000))).encode(),
                    b"\n".join(x.encode() for x in _alias_bomb(9)) + b"\nevents: *a8\n"])
                parent[key] = name
                continue
        if kind == "delete":
            path, parent, key = rnd.choice(spots)
            if isinstance(parent, dict):
                del parent[key]
            elif parent:
                parent.pop(key)
            continue
        if kind == "add":
            path, parent, key = rnd.choice(spots)
            target = parent[key] if isinstance(parent[key], dict) else tree
            target[rnd.choice(["colour", "n", "designs", "starts", "workers", "x" * 300, 1, None])] = \
                rnd.choice(HOSTILE_VALUES)
            continue
        if kind == "scale":  # a plausible-looking change: a number scaled, a count changed
            nums = [sp for sp in spots if isinstance(sp[1][sp[2]], (int, float, str)) and not isinstance(sp[1][sp[2]], bool)
                    and re.match(r"^\s*-?[\d.]+(e-?\d+)?", str(sp[1][sp[2]]))]
            if nums:
                _, parent, key = rnd.choice(nums)
                v = parent[key]
                m = re.match(r"^\s*(-?[\d.]+(?:e-?\d+)?)(.*)$", str(v))
                try:
                    x = float(m.group(1)) * rnd.choice([0, -1, 0.5, 2, 10, 1e3, 1e-3, 1e6, 1e-6, 1e30, 1e-30])
                except ValueError:
                    continue
                parent[key] = (int(x) if isinstance(v, int) and abs(x) < 2 ** 62 else x) if not isinstance(v, str) \
                    else f"{x:g}{m.group(2)}"
                continue
        path, parent, key = rnd.choice(spots)
        parent[key] = rnd.choice(HOSTILE_VALUES)
    try:
        out = yaml.safe_dump(tree, sort_keys=False, allow_unicode=False)
    except (yaml.YAMLError, ValueError):
        out = text
    return out, side


# ------------------------------------------------------------------------------ corpus ----
def make_corpus(folder, rnd):
    """The corpus project (a pyproject.toml marks it) with copies of the examples and the test
    specs, a FIFO inside it, and the outside folder with a secret and a FIFO."""
    proj = os.path.join(folder, "proj")
    shutil.rmtree(folder, ignore_errors=True)
    os.makedirs(proj)
    open(os.path.join(proj, "pyproject.toml"), "w").close()
    for sub in ("examples/fitting", "examples/sensitivity", "examples/protocols"):
        shutil.copytree(os.path.join(ROOT, sub), os.path.join(proj, sub),
                        ignore=shutil.ignore_patterns("output", "results", "*.py", "*.png"))
    tf = os.path.join(proj, "tests", "fitting")
    shutil.copytree(os.path.join(ROOT, "tests", "fitting"), tf)
    import numpy as np
    q = np.linspace(0.5, 4.0, 8)
    with open(os.path.join(tf, "line.csv"), "w") as fh:
        fh.write("Q [mL/s],P [mmHg]\n" + "".join(f"{a:.6g},{10 + 2 * a:.6g}\n" for a in q))
    t = np.arange(0.0, 12.0 + 1e-9, 0.25)
    p5 = 100.0 * (1 - math.exp(-4.0))
    p = np.where(t < 1, 0.0, np.where(t < 5, 100.0 * (1 - np.exp(-(t - 1))), 100.0 - (100.0 - p5) * np.exp(-(t - 5) / 2)))
    with open(os.path.join(tf, "rc.csv"), "w") as fh:
        fh.write("t [s],P [mmHg]\n" + "".join(f"{a:.6g},{b:.6g}\n" for a, b in zip(t, p)))
    for name, text in (("linear_spec.yaml", LINEAR_SPEC), ("rc_spec.yaml", RC_SPEC), ("linear_sens.yaml", LINEAR_SENS)):
        with open(os.path.join(tf, name), "w") as fh:
            fh.write(text)
    for stage in ("kuo91_1_passive", "kuo91_2_active", "kuo91_3_flow"):  # the start_from of the later stages
        out = os.path.join(proj, "examples", "fitting", "output", stage)
        os.makedirs(out)
        with open(os.path.join(out, "fitted.yaml"), "w") as fh:
            fh.write(f"extends: {os.path.relpath(ARTERIOLE, out)}\nchange: {{art: {{preset: kuo91}}}}\n")
    outside = os.path.join(folder, "outside")
    os.makedirs(outside)
    token = f"SECRET-TOKEN-{rnd.getrandbits(64):016x}"
    secret = os.path.join(outside, "secret.csv")
    with open(secret, "w") as fh:
        fh.write(f"{token} [um],{token}\n{token},1\n1,2\n")
    fifo_out, fifo_in = os.path.join(outside, "fifo"), os.path.join(proj, "examples", "fitting", "fifo.csv")
    os.mkfifo(fifo_out)
    os.mkfifo(fifo_in)
    big = os.path.join(proj, "examples", "fitting", "big.csv")
    with open(big, "w") as fh:  # over the 16 MiB file limit
        fh.write("P [mmHg],r [um]\n")
        fh.write("1,2\n" * (5 * 2 ** 20))
    latin1 = os.path.join(proj, "examples", "fitting", "latin1.csv")
    with open(latin1, "wb") as fh:
        fh.write("P [cmH2O],Pup [cmH2O],Pdown [cmH2O],r [um]\n# caf\xe9\n20,20,20,90\n".encode("latin-1"))
    return {"proj": proj, "outside": outside, "secret": secret, "token": token, "fifo_in": fifo_in,
            "fifo_out": fifo_out, "big": big, "latin1": latin1, "out": os.path.join(folder, "out")}


# ------------------------------------------------------------------------------ the child ----
def _watch_reads(log, allowed, forbidden):
    """Log every file read through hemocircuit.inputs (outside ``allowed``: a violation) and
    every open of a ``forbidden`` path by anything."""
    import builtins

    from hemocircuit import inputs

    real_read, real_open, real_os_open = inputs.read_bytes, builtins.open, os.open

    def is_forbidden(p):
        try:
            r = os.path.realpath(os.fspath(p)) if not isinstance(p, int) else ""
        except (TypeError, ValueError):
            return False
        return any(r == f or r.startswith(f.rstrip("/") + "/") for f in forbidden)

    def read_bytes(path, *a, **k):
        data = real_read(path, *a, **k)
        r = os.path.realpath(path)
        if not any(r == f or r.startswith(f.rstrip("/") + "/") for f in allowed):
            log.append(f"READ-OUTSIDE {r}")
        return data

    def open_(file, *a, **k):
        if is_forbidden(file):
            log.append(f"OPEN-FORBIDDEN {file}")
        return real_open(file, *a, **k)

    def os_open(path, *a, **k):
        if is_forbidden(path):
            log.append(f"OPEN-FORBIDDEN {path}")
        return real_os_open(path, *a, **k)

    inputs.read_bytes = read_bytes
    builtins.open = open_
    os.open = os_open


def _strict_json(path):
    def no(c):
        raise ValueError(f"{c} in {path}")
    with open(path) as fh:
        json.loads(fh.read(), parse_constant=no)


def _load_only(kind, netlist, case):
    """Parse and validate (nothing run)."""
    if kind == "fit":
        from hemocircuit.fitting import load_problem
        load_problem(netlist, case)
    else:
        from hemocircuit.circuit import load
        from hemocircuit.sensitivity import prepare
        from hemocircuit.sensitivity.outputs import make_objective
        from hemocircuit.sensitivity.spec import load_spec
        from hemocircuit.spec_inputs import spec_access
        c = load(netlist)
        spec = load_spec(case, None, spec_access(case, netlist))
        prepare(spec, make_objective(spec, c, netlist, "serial"))


def _nonfinite(text):
    """A cell that reads as NaN or an infinity."""
    try:
        return not math.isfinite(float(text))
    except (TypeError, ValueError):
        return False


def _run_tiny(kind, netlist, case, out):
    """The command with tiny budgets; checks the outputs for silent NaN.  Returns the exit code."""
    from hemocircuit.cli import main
    if kind == "fit":
        code = main(["fit", netlist, case, "--starts", "0", "--max-nfev", "2", "--workers", "1", "--no-plot",
                     "--quiet", "--out", out])
        if code == 0:
            _strict_json(os.path.join(out, "report.json"))
            import csv
            with open(os.path.join(out, "fit.csv"), newline="") as fh:
                rows = list(csv.reader(fh))[1:]
            # the numbers (the first column is the dataset's name, which may read 'nan')
            if any(_nonfinite(c) for r in rows for c in r[1:]):
                print("SILENT-NAN fit.csv")
            print(f"$ hemocircuit op {out}/fitted.yaml")
            code = main(["op", os.path.join(out, "fitted.yaml"), "--quiet"])
            if code != 0:
                print("FRAGMENT-UNLOADABLE")
        return code
    import yaml
    method = ((yaml.safe_load(open(case)) or {}).get("method") if os.path.getsize(case) < 10 ** 6 else None)
    sobol = isinstance(method, dict) and method.get("name") == "sobol" or method == "sobol"
    csv_out = out + ".csv"
    code = main(["sensitivity", netlist, case, "--n", "4" if sobol else "2", "--trajectories", "2", "--scheduler",
                 "serial", "--quiet", "--out", csv_out])
    if code == 0:
        import csv
        with open(csv_out, newline="") as fh:
            table = list(csv.DictReader(fh))
        words = ("output", "parameter", "unit", "EE unit", "derivative unit")  # names, not numbers
        if any(_nonfinite(v) for r in table for k, v in r.items() if k not in words):
            print("MAYBE-NAN table")
    return code


def _child(kind, netlist, case, out, mode, mem_bytes, cpu_s, out_path, allowed, forbidden):
    import resource

    resource.setrlimit(resource.RLIMIT_AS, (mem_bytes, mem_bytes))
    resource.setrlimit(resource.RLIMIT_CPU, (int(cpu_s), int(cpu_s) + 5))  # SIGXCPU past the time limit
    fd = os.open(out_path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
    os.dup2(fd, 1)
    os.dup2(fd, 2)
    sys.stdout = io.TextIOWrapper(os.fdopen(1, "wb", buffering=0), write_through=True)
    sys.stderr = sys.stdout
    from hemocircuit.errors import HemocircuitError

    log = []
    _watch_reads(log, allowed, forbidden)
    code = 0
    try:
        try:
            _load_only(kind, netlist, case)
            print("[load ok]")
        except HemocircuitError as exc:
            print(f"error: {exc}")
            code = 2
        if code == 0 and mode == "run":
            code = _run_tiny(kind, netlist, case, out)
        print(f"[exit {code}]")
    except MemoryError:
        print("MEMORY-OVERRUN")
        code = 4
    except BaseException:  # noqa: BLE001 - what the fuzzer looks for
        traceback.print_exc()
        code = 3
    for line in log[:20]:
        print(line)
    sys.stdout.flush()
    os._exit(code)


def classify(output, status, token):
    kinds = []
    if status == "timeout":
        kinds.append("timeout")
    if status == "memory" or "MEMORY-OVERRUN" in output or "MemoryError" in output:
        kinds.append("memory")
    elif "Traceback (most recent call last)" in output:
        kinds.append("traceback")
    if "READ-OUTSIDE" in output or "OPEN-FORBIDDEN" in output:
        kinds.append("read_outside")
    if token in output or re.search(r"root:[x*!]?:0:0", output):
        kinds.append("quoted_outside")
    if "SILENT-NAN" in output or re.search(r"not JSON|NaN in .*report\.json|Infinity in .*report\.json", output):
        kinds.append("silent_nan")
    if "MAYBE-NAN" in output and re.search(r"model evaluations, 0 failed", output):
        kinds.append("silent_nan")
    if "FRAGMENT-UNLOADABLE" in output:
        kinds.append("fragment_unloadable")
    return kinds


BAD = ("traceback", "timeout", "memory", "read_outside", "quoted_outside", "silent_nan", "fragment_unloadable")


def run(cases, seed, folder, jobs=2, timeout=20.0, mem_gib=2.0, mode="run", quiet=False, budget_s=None, keep=False,
        wall_limit=None):
    """Run ``cases`` mutated specs; returns the report (also written to FOLDER/report.json)."""
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    rnd = random.Random(seed)
    wall_limit = wall_limit or 3 * timeout
    ctx = make_corpus(folder, rnd)
    import hemocircuit.analyses.fit  # noqa: F401 - imported once in the parent, inherited by every child
    import hemocircuit.analyses.op  # noqa: F401
    import hemocircuit.analyses.sensitivity  # noqa: F401
    import hemocircuit.circuit
    import hemocircuit.cli  # noqa: F401
    import hemocircuit.fitting  # noqa: F401
    import hemocircuit.sensitivity.outputs  # noqa: F401
    from hemocircuit.units import registry

    registry()
    c = hemocircuit.circuit.load(ARTERIOLE)
    c.operating_point()
    if mode == "run":  # the compiled batch integrator of the arteriole loaded (or built) once, before forking
        import numpy as np

        from hemocircuit.batch_integrator import integrate
        from hemocircuit.fitting.experiments import solve_steady
        for net in (c, hemocircuit.circuit.load(os.path.join(ctx["proj"], "tests", "fitting", "rc.yaml"))):
            b = net.batch(2)
            X, _, _ = solve_steady(b)
            integrate(b, X, np.array([0.0, 1.0]), rtol=1e-6)
    with open("/proc/self/status") as fh:
        vm = int(re.search(r"VmSize:\s+(\d+)", fh.read()).group(1)) * 1024
    mem_bytes = vm + int(mem_gib * 2 ** 30)
    os.makedirs(ctx["out"], exist_ok=True)
    allowed = [os.path.realpath(p) for p in (ctx["proj"], ROOT, ctx["out"])]
    forbidden = [os.path.realpath(ctx["outside"]), "/etc/passwd", "/etc/shadow", "/dev/zero",
                 os.path.realpath(ctx["fifo_in"])]
    texts = {b[0]: open(os.path.join(ctx["proj"], b[0])).read() for b in BASES}
    counts = {k: 0 for k in ("accepted", "clean_error") + BAD}
    examples: dict = {}
    stats = {"max_cpu_s": 0.0, "max_wall_s": 0.0, "max_rss_mib": 0.0}
    running = {}
    t0 = time.time()
    done = 0

    def reap(pid, status_code, rusage, st):
        nonlocal done
        n, started, out, path = running.pop(pid)
        output = open(out, errors="replace").read()
        cpu = rusage.ru_utime + rusage.ru_stime
        wall = time.time() - started
        stats["max_cpu_s"] = max(stats["max_cpu_s"], round(cpu, 2))
        stats["max_wall_s"] = max(stats["max_wall_s"], round(wall, 2))
        stats["max_rss_mib"] = max(stats["max_rss_mib"], round(rusage.ru_maxrss / 1024, 1))
        if status_code is not None and os.WIFSIGNALED(status_code) and os.WTERMSIG(status_code) in (
                signal.SIGXCPU, signal.SIGKILL) and cpu >= timeout - 0.5:
            st = "timeout"  # the CPU time limit
        status = st or ("memory" if rusage.ru_maxrss * 1024 > mem_gib * 2 ** 30 + vm else "")
        kinds = classify(output, status, ctx["token"])
        code = os.waitstatus_to_exitcode(status_code) if status_code is not None else None
        if not kinds:
            kinds = ["accepted"] if code == 0 else ["clean_error"] if code == 2 else ["traceback"]
            if code not in (0, 2):
                output += f"\n[child ended with {code}]"
        for k in kinds:
            counts[k] += 1
            if k in BAD and len(examples.setdefault(k, [])) < 25:
                last = [ln for ln in output.strip().splitlines() if ln.strip()][-4:]
                examples[k].append({"case": path, "seconds": round(wall, 1), "cpu_s": round(cpu, 1),
                                    "tail": [ln[:300] for ln in last]})
        if not any(k in BAD for k in kinds) and not keep:
            os.unlink(out)
        done += 1
        if not quiet and done % 50 == 0:
            print(f"{done}/{cases} in {time.time() - t0:.0f} s: {counts}", flush=True)

    for n in range(cases):
        if budget_s is not None and time.time() - t0 > budget_s:
            break
        base, netlist, kind = rnd.choice(BASES)
        case_dir = os.path.join(ctx["proj"], os.path.dirname(base))
        ctx.update(n=n, case_dir=case_dir)
        text, side = mutate(rnd, texts[base], ctx)
        for name, data in side.items():
            with open(os.path.join(case_dir, name), "wb") as fh:
                fh.write(data)
        path = os.path.join(case_dir, f"case_{n:05d}_{os.path.splitext(os.path.basename(base))[0]}.yaml")
        with open(path, "w") as fh:
            fh.write(text)
        netlist_path = ARTERIOLE if netlist == "bundled" else os.path.join(ctx["proj"], netlist)
        out = path[:-5] + ".out"
        result_dir = os.path.join(ctx["out"], f"case_{n:05d}")
        while len(running) >= jobs:
            _wait(running, wall_limit, reap)
        pid = os.fork()
        if pid == 0:
            _child(kind, netlist_path, path, result_dir, mode, mem_bytes, timeout, out, allowed, forbidden)
        running[pid] = (n, time.time(), out, path)
    while running:
        _wait(running, wall_limit, reap)
    report = {"cases": done, "seed": seed, "mode": mode, "seconds": round(time.time() - t0, 1), "counts": counts,
              "limits": {"cpu_s": timeout, "wall_s": wall_limit, "memory_gib": mem_gib}, **stats,
              "examples": examples}
    with open(os.path.join(folder, "report.json"), "w") as fh:
        json.dump(report, fh, indent=1)
    return report


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", type=int, default=500)
    ap.add_argument("--seed", type=int, default=20251)
    ap.add_argument("--dir", default="/tmp/hemocircuit-fuzz-specs", help="corpus and report (outside the project)")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--timeout", type=float, default=20.0,
                    help="CPU seconds per case (load and tiny run); a case is also stopped after 3x that in wall-clock "
                         "time (a hang uses no CPU; the wall clock alone misjudges a shared machine)")
    ap.add_argument("--memory-gib", type=float, default=2.0)
    ap.add_argument("--mode", choices=("load", "run"), default="run")
    ap.add_argument("--keep", action="store_true", help="keep every case's output (CASE.out), not only the bad ones")
    args = ap.parse_args(argv)
    if os.path.realpath(args.dir).startswith(os.path.realpath(ROOT) + os.sep):
        ap.error("--dir must be outside the project")
    report = run(args.cases, args.seed, args.dir, args.jobs, args.timeout, args.memory_gib, args.mode,
                 keep=args.keep)
    print(json.dumps({k: report[k] for k in ("cases", "mode", "seconds", "max_cpu_s", "max_wall_s", "max_rss_mib",
                                             "counts")}, indent=1))
    for k, ex in report["examples"].items():
        print(f"\n{k}: {len(ex)} example(s), e.g.")
        for e in ex[:6]:
            print(f"  {e['case']} ({e['seconds']} s, CPU {e['cpu_s']} s): {' | '.join(e['tail'])}")
    return 1 if sum(report["counts"][k] for k in BAD) else 0


if __name__ == "__main__":
    sys.exit(main())
