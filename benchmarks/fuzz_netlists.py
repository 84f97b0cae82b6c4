"""Fuzzing the input side: thousands of mutated copies of the bundled netlists, each run as
``hemocircuit check`` and, when accepted, ``hemocircuit op``, in a forked child process with a
time limit (15 s) and a memory limit (2 GiB above the parent's start-up size).

    python benchmarks/fuzz_netlists.py --cases 3000             # corpus in /tmp/hemocircuit-fuzz
    python benchmarks/fuzz_netlists.py --cases 200 --seed 7 --jobs 1

Counts: clean errors, accepted, tracebacks (any exception other than hemocircuit's own errors),
runs over the time limit, runs over the memory limit, silent NaN/inf (``op`` exits 0 printing a
non-finite value), and file contents quoted from outside the allowed folders (a secret file
with a random token is planted outside the corpus folder and named by some mutations; /etc/passwd
as well).  The corpus and report are written OUTSIDE the project (``--dir``); the report
(report.json) lists the first examples of every failure kind with the case file.

The mutation corpus (:func:`mutations`) is also used by tests/test_fuzz.py (a bounded sample).
"""
from __future__ import annotations

import argparse
import io
import json
import os
import random
import re
import shutil
import sys
import time
import traceback

from fork_children import wait_one as _wait  # noqa: E402 - a sibling module (benchmarks/)

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
BUNDLED = os.path.join(ROOT, "netlists")

# values that have broken loaders before: overflow, NaN, huge/tiny, integer powers, bad units,
# references, expressions, paths outside the allowed folders
HOSTILE = [
    "1e300 mmHg", "-1e300 mmHg", "1e-300 mmHg", "0 mmHg", "-1 mmHg", "nan mmHg", "inf mmHg", "-inf mL",
    "1e300 1/mL", "1e300 mL", "1e-300 mL/mmHg", "1e300 mmHg*s/mL", "1e-300 mmHg*s/mL", "1e999 mmHg",
    "10**10**10 mmHg", "9**9**9**9", "(((((1))))) mmHg", "1 mmHg**1e300", "1 //", "abc", "", "0", "-0",
    "1e308 M", "nan", "inf", "-1", "1e-320", "1e20", "true", "null", "[1, 2]", "{a: 1}",
    "${nope}", "${Pic}${Pic}", "= 9**9**9**9", "= 1e300 ** 2", "= exp(1e300)", "= log(-1)", "= sqrt(-1)",
    "= 1/0", "= __import__('os')", "= (lambda: 1)()", "= " + "+".join(["1"] * 20000), "= " + "(" * 300 + "1" + ")" * 300,
    "= " + "-" * 5000 + "1", "1" * 5000 + " mmHg", "{pwl: {file: /etc/passwd}}", "{pwl: {file: SECRET}}",
    "{pwl: {file: ../../../../../etc/shadow}}", "{steps: [[0 s, 1e300 mmHg], [1 s, nan mmHg]]}",
    "{sine: {offset: 80 mmHg, amplitude: inf mmHg, frequency: 1 Hz}}",
    "{sine: {frequency: -1 Hz}}", "{sum: [{sum: [{sum: [1 mmHg]}]}]}", "90mmHg", "2 L/min", "60 um", "1 degC",
]
OPTION_VALUES = ["1e-20", "0", "-1", "nan", "inf", "abc", "1e400", "true", "3", "[1]", "{a: b}", "1e-300", "1e300"]
KEYS = ["extends", "add", "remove", "change", "outputs", "input", "derived", "parameters", "constraints",
        "scale", "units_reading", "preset", "ca_order", "file", "value", "R", "C", "k", "P0", "Vn"]


def bundled_netlists():
    return sorted(f for f in os.listdir(BUNDLED) if f.endswith(".yaml"))


def _alias_bomb(levels=9):
    lines = ['a0: &a0 ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]']
    for i in range(1, levels):
        lines.append(f"a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * 9) + "]")
    return "\n".join(lines) + "\nelements: *a%d\n" % (levels - 1)


def _doubling_params(n=40):
    lines = ["parameters:", "  p0: 1 mmHg"] + [f"  p{i}: ${{p{i - 1}}} + ${{p{i - 1}}}" for i in range(1, n)]
    return "\n".join(lines) + "\n"


def mutations(rnd: random.Random, text: str, secret: str) -> str:
    """One mutated netlist text from ``text`` (seeded by ``rnd``); ``secret`` is the path of a
    file outside the allowed folders."""
    kind = rnd.choice(["value", "value", "value", "value", "option", "text", "text", "struct", "struct",
                       "limit", "event"])
    lines = text.splitlines()
    if kind == "value":  # replace one value after 'key:' with a hostile one
        for _ in range(rnd.randint(1, 3)):
            spots = [(i, m) for i, ln in enumerate(lines) for m in re.finditer(r"(\w+):\s*([^,{}\[\]#]+)", ln)]
            if not spots:
                break
            i, m = rnd.choice(spots)
            v = rnd.choice(HOSTILE).replace("SECRET", secret)
            if rnd.random() < 0.3:  # or scale the number by a random power of ten
                num = re.match(r"\s*(-?[\d.]+(?:e-?\d+)?)", m.group(2))
                if num:
                    v = m.group(2).replace(num.group(1), f"{float(num.group(1) or 0) * 10.0 ** rnd.randint(-300, 300):g}", 1)
            quoted = v if v.startswith(("{", "[")) else json.dumps(v)
            lines[i] = lines[i][:m.start(2)] + quoted + lines[i][m.end(2):]
        return "\n".join(lines) + "\n"
    if kind == "option":  # an option with a hostile value on some element
        i = rnd.randrange(len(lines))
        opt = rnd.choice(["scale", "units_reading", "clamp_at_zero", "extended", "ca_order", "preset", "passive"])
        lines[i] = re.sub(r"\}\s*$", f", {opt}: {rnd.choice(OPTION_VALUES)}}}", lines[i], count=1)
        return "\n".join(lines) + "\n"
    if kind == "text":  # cut, repeat or insert raw text
        pos = rnd.randrange(max(1, len(text)))
        op = rnd.choice(["cut", "dup", "insert"])
        if op == "cut":
            return text[:pos] + text[pos + rnd.randint(1, 40):]
        if op == "dup":
            i = rnd.randrange(len(lines))
            return "\n".join(lines[:i] + [lines[i]] * rnd.randint(2, 5) + lines[i:]) + "\n"
        junk = "".join(rnd.choice("{}[]:,-'\"&*!|>%@` \n\t$=#0123456789eE.") for _ in range(rnd.randint(1, 8)))
        return text[:pos] + junk + text[pos:]
    if kind == "struct":  # top-level keys pointing at files, references that grow, odd sections
        choice = rnd.choice(["extends_abs", "extends_rel", "extends_secret", "extends_self", "doubling", "cycle",
                             "derived", "unknown_key", "outputs", "input", "table_secret"])
        if choice == "extends_abs":
            return "extends: /etc/passwd\n"
        if choice == "extends_rel":
            return "extends: ../../../../../../etc/shadow\n"
        if choice == "extends_secret":
            return f"extends: {secret}\n"
        if choice == "extends_self":
            return "extends: case.yaml\n" + text
        if choice == "doubling":
            return _doubling_params(rnd.randint(20, 60)) + re.sub(r"^parameters:.*$", "", text, flags=re.M)
        if choice == "cycle":
            return "parameters: {pa: '${pb}', pb: '${pa}'}\n" + re.sub(r"^parameters:.*$", "", text, flags=re.M)
        if choice == "derived":
            expr = rnd.choice(["9**9**9**9", "Q(Rxx)", "1/0", "(" * 500 + "1" + ")" * 500, "+".join(["1"] * 20000),
                               "__import__('os')", "P(in) ** 1e300"])
            return re.sub(r"^derived:.*$", "", text, flags=re.M) + f"\nderived:\n  bad: {{expr: {json.dumps(expr)}, unit: mmHg}}\n"
        if choice == "unknown_key":
            return text + f"\n{rnd.choice(['elemnts', 'parameter', 'extend', 'x' * 300])}: 1\n"
        if choice == "outputs":
            return text + "\noutputs: [Q(Rxx), P(nowhere)]\n"
        if choice == "input":
            return text + "\ninput: Nope.value\n"
        return text.replace("value: 80 mmHg", f"value: {{pwl: {{file: {secret}}}}}", 1)
    if kind == "limit":  # documents that test the input limits
        choice = rnd.choice(["deep", "deep_block", "alias", "long_value", "many_elements", "big_file"])
        if choice == "deep":
            n = rnd.choice([50, 200, 5000, 50000])
            return "elements: " + "[" * n + "]" * n + "\n"
        if choice == "deep_block":
            return "elements:\n" + "".join("  " * i + "- \n" for i in range(rnd.choice([60, 500]))) + "\n"
        if choice == "alias":
            return _alias_bomb(rnd.choice([6, 9, 12]))
        if choice == "long_value":
            return text.replace("mmHg", "mmHg" + " " * 10 + "*1" * rnd.choice([3000, 50000]), 1)
        if choice == "many_elements":
            n = rnd.choice([1000, 300_000])
            rows = "".join(f"  - {{id: R{i}, type: resistor, nodes: [in, a], R: 1 mmHg*s/mL}}\n" for i in range(n))
            return "elements:\n  - {id: Ps, type: pressure_source, nodes: [in, ground], value: 1 mmHg}\n" + rows
        return text + "#" + "x" * (30 * 2 ** 20) + "\n"  # a 30 MiB file
    # an event at t = 0 through a protocol is covered by the test suite; here: a hostile 'extends' chain
    return "extends: " + rnd.choice(bundled_netlists()) + "\nchange:\n  " + \
        rnd.choice(["Pa: {value: 1e300 mmHg}", "Cv: {k: 1e300 1/mL}", "Cv: {P0: 1e300 mmHg}",
                    "Rla: {R: 1e-300 mmHg*s/mL}", "Rxx: {R: 1 mmHg*s/mL}", "Pa: {value: '= 9**9**9**9'}",
                    "NOv: {scale: nan}", "NOv: {scale: abc}", "NOv: {scale: -1}", "art: {preset: nope}",
                    "Cv: {Vn: nan mL}", "Pa: {value: {sine: {amplitude: 1e308 mmHg, frequency: 1e308 Hz}}}"]) + "\n"


# ------------------------------------------------------------------------------ runner ----
def _child(argv_list, out_path, mem_bytes):
    """In the forked child: limits, redirect, run each command until one fails."""
    import resource

    resource.setrlimit(resource.RLIMIT_AS, (mem_bytes, mem_bytes))
    fd = os.open(out_path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
    os.dup2(fd, 1)
    os.dup2(fd, 2)
    sys.stdout = io.TextIOWrapper(os.fdopen(1, "wb", buffering=0), write_through=True)
    sys.stderr = sys.stdout
    from hemocircuit.cli import main

    code = 0
    try:
        for argv in argv_list:
            print(f"$ hemocircuit {' '.join(argv)}")
            code = main(argv)
            print(f"[exit {code}]")
            if code:
                break
    except MemoryError:
        print("MEMORY-OVERRUN")
        code = 4
    except BaseException:  # noqa: BLE001 - what the fuzzer looks for
        traceback.print_exc()
        code = 3
    os._exit(code)


def classify(output: str, status: str, secret_token: str) -> list[str]:
    kinds = []
    if status == "timeout":
        kinds.append("timeout")
    if status == "memory" or "MEMORY-OVERRUN" in output or "MemoryError" in output:
        kinds.append("memory")
    elif "Traceback (most recent call last)" in output:
        kinds.append("traceback")
    if secret_token in output or re.search(r"root:[x*!]?:0:0", output):
        kinds.append("quoted_outside")
    op = output.split("$ hemocircuit op", 1)
    if len(op) == 2 and "[exit 0]" in op[1] and re.search(r"\s(nan|-?inf)\s*$", op[1], re.M | re.I):
        kinds.append("silent_nonfinite")
    return kinds


def run(cases, seed, folder, jobs, timeout, mem_gib, quiet=False, commands=("check", "op"), budget_s=None):
    """Run ``cases`` mutated netlists (``commands`` on each until one fails); stop launching
    new cases after ``budget_s`` seconds.  Returns the report (also written to report.json)."""
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
        fh.write(f"{token}: {token}\nelements: [{token}]\n")
    for f in bundled_netlists():  # the corpus folder holds copies, so extends chains resolve
        shutil.copy(os.path.join(BUNDLED, f), corpus)
    import hemocircuit.circuit  # noqa: F401 - imported once in the parent, inherited by every child
    import hemocircuit.cli  # noqa: F401
    import hemocircuit.analyses.op  # noqa: F401
    from hemocircuit.units import registry

    registry()  # pint's registry and the component types, built once, not in every child
    for f in bundled_netlists():
        hemocircuit.circuit.load(os.path.join(BUNDLED, f))
    with open("/proc/self/status") as fh:
        vm = int(re.search(r"VmSize:\s+(\d+)", fh.read()).group(1)) * 1024
    mem_bytes = vm + int(mem_gib * 2 ** 30)
    texts = {f: open(os.path.join(BUNDLED, f)).read() for f in bundled_netlists()}
    counts = {k: 0 for k in ("accepted", "clean_error", "traceback", "timeout", "memory", "silent_nonfinite",
                             "quoted_outside")}
    examples: dict = {}
    running = {}  # pid -> (case, started, out path, case file)
    t0 = time.time()
    done = 0

    def reap(pid, status_code, rusage, st):
        nonlocal done
        case, started, out, path = running.pop(pid)
        output = open(out, errors="replace").read()
        status = st or ("memory" if rusage.ru_maxrss * 1024 > mem_gib * 2 ** 30 + vm else "")
        kinds = classify(output, status, token)
        code = os.waitstatus_to_exitcode(status_code) if status_code is not None else None
        if not kinds:
            kinds = ["accepted"] if code == 0 else ["clean_error"] if code == 2 else ["traceback"]
            if code not in (0, 2):
                output += f"\n[child ended with {code}]"
        for k in kinds:
            counts[k] += 1
            if k not in ("accepted", "clean_error") and len(examples.setdefault(k, [])) < 25:
                last = [ln for ln in output.strip().splitlines() if ln.strip()][-3:]
                examples[k].append({"case": path, "tail": [ln[:300] for ln in last]})
        if not any(k not in ("accepted", "clean_error") for k in kinds):
            os.unlink(out)
        done += 1
        if not quiet and done % 100 == 0:
            print(f"{done}/{cases} in {time.time() - t0:.0f} s: {counts}", flush=True)

    for n in range(cases):
        if budget_s is not None and time.time() - t0 > budget_s:
            break
        base = rnd.choice(sorted(texts))
        text = mutations(rnd, texts[base], secret)
        path = os.path.join(corpus, f"case_{n:05d}_{os.path.splitext(base)[0]}.yaml")
        with open(path, "w") as fh:
            fh.write(text)
        out = path[:-5] + ".out"
        while len(running) >= jobs:
            _wait(running, timeout, reap)
        pid = os.fork()
        if pid == 0:
            _child([[cmd, path] for cmd in commands], out, mem_bytes)
        running[pid] = (n, time.time(), out, path)
    while running:
        _wait(running, timeout, reap)
    report = {"cases": done, "seed": seed, "seconds": round(time.time() - t0, 1), "counts": counts,
              "limits": {"timeout_s": timeout, "memory_gib": mem_gib}, "examples": examples}
    with open(os.path.join(folder, "report.json"), "w") as fh:
        json.dump(report, fh, indent=1)
    return report


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", type=int, default=3000)
    ap.add_argument("--seed", type=int, default=20240)
    ap.add_argument("--dir", default="/tmp/hemocircuit-fuzz", help="corpus and report (outside the project)")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--timeout", type=float, default=15.0, help="seconds per case (check + op)")
    ap.add_argument("--memory-gib", type=float, default=2.0)
    args = ap.parse_args(argv)
    if os.path.realpath(args.dir).startswith(os.path.realpath(ROOT) + os.sep):
        ap.error("--dir must be outside the project")
    report = run(args.cases, args.seed, args.dir, args.jobs, args.timeout, args.memory_gib)
    print(json.dumps({k: report[k] for k in ("cases", "seconds", "counts")}, indent=1))
    for k, ex in report["examples"].items():
        print(f"\n{k}: {len(ex)} example(s), e.g.")
        for e in ex[:5]:
            print(f"  {e['case']}: {' | '.join(e['tail'])}")
    bad = sum(report["counts"][k] for k in ("traceback", "timeout", "memory", "silent_nonfinite", "quoted_outside"))
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
