"""What a small circuit's operating point loads (issue 32: a warm ``op payne06`` within 0.5 s).

The dense path scatters stamps with numpy and the System imports scipy.sparse
(``hemocircuit.sparse``) only for circuits above ``SPARSE_MIN_UNKNOWNS`` nodal unknowns, and
numba only when it chooses the compiled engine: ``op``, ``check`` and ``--help`` load neither.
Each check runs the command through the CLI's ``main`` in a fresh interpreter, then reads
``sys.modules``.
"""
from __future__ import annotations

import json
import subprocess
import sys

import pytest

from paths import ROOT

PAYNE06 = str(ROOT / "netlists" / "payne06.yaml")
LADDER_UNKNOWNS = 200


def loaded_after(args):
    """The top-level packages (and hemocircuit/scipy submodules) in sys.modules after
    ``hemocircuit ARGS`` ran in a new interpreter, with its exit status."""
    code = ("import io, json, sys, contextlib\n"
            "from hemocircuit.cli import main\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            "    try:\n"
            f"        status = main({list(args)!r})\n"
            "    except SystemExit as exc:\n"
            "        status = exc.code\n"
            "print(json.dumps({'status': status, 'modules': sorted(sys.modules)}))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.fixture(scope="module")
def op_modules():
    """The modules of a warm ``op payne06`` (a first run fills the units cache, which a new
    checkout or an edited units.py starts empty: that run reads its values with pint)."""
    loaded_after(["op", PAYNE06])
    res = loaded_after(["op", PAYNE06])
    assert res["status"] in (0, None)
    return set(res["modules"])


@pytest.mark.parametrize("heavy", ["scipy.sparse", "hemocircuit.sparse", "numba"])
def test_op_of_a_small_circuit_does_not_import(op_modules, heavy):
    assert heavy not in op_modules


@pytest.mark.parametrize("heavy", ["networkx", "importlib.metadata", "hemocircuit.components.svzerod"])
def test_op_of_payne06_does_not_import(op_modules, heavy):
    """networkx (the topology checks use a disjoint-set forest), importlib.metadata (the
    entry-point scan and pint's version) and the svZeroDSolver blocks (a built-in type is
    imported alone): ~0.3 s of a 0.5 s operating point."""
    assert heavy not in op_modules


@pytest.mark.parametrize("args", [["check", PAYNE06], ["--help"]])
def test_check_and_help_do_not_import_numba(args):
    assert "numba" not in loaded_after(args)["modules"]


def test_a_batch_operating_point_does_not_import_numba():
    """Ten members of vasomotion (5 Pa x 2 zeta) at once through the API in a new interpreter:
    its Jacobians solve 90 batch rows a call, which the compiled solve and element loops would
    take once numba is loaded; loading it for them (~0.4 s) cost more than the whole operating
    point as numpy and Python (0.6 -> 0.14 s), so they stay numpy until numba is loaded anyway
    (or enough rows pay for it: linalg.NUMBA_AMORTISED_ROWS, elementwise.LOOP_COMPILE_CALLS).
    The states are right: every member at the steady Pa it was given, P(in) = Pa."""
    code = ("import json, sys\n"
            "import hemocircuit as hc\n"
            "from hemocircuit.batch import build_batches, expand_grid, member_operating_points, resolve_values\n"
            f"c = hc.load({str(ROOT / 'netlists' / 'vasomotion.yaml')!r})\n"
            "grids = resolve_values(c, [('Pa.value', [60., 70., 80., 90., 100.]), ('art.zeta', [0.1, 0.2])])\n"
            "(bc, idx), = build_batches(c, expand_grid(grids))\n"
            "X0, opv, errors = member_operating_points(bc)\n"
            "print(json.dumps({'numba': 'numba' in sys.modules, 'errors': errors, 'P_in': list(opv['P(in)'])}))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, check=True)
    res = json.loads(out.stdout.strip().splitlines()[-1])
    assert res["numba"] is False and res["errors"] == [None] * 10, res
    assert res["P_in"] == pytest.approx([60.0] * 2 + [70.0] * 2 + [80.0] * 2 + [90.0] * 2 + [100.0] * 2), res


def test_a_large_circuit_takes_the_sparse_path(tmp_path):
    """The other side of the threshold: a ladder of resistors and compliances with more nodal
    unknowns than SPARSE_MIN_UNKNOWNS loads scipy.sparse for its operating point (so the test
    above can fail: the import is where the sparse path needs it)."""
    from hemocircuit.system import SPARSE_MIN_UNKNOWNS

    assert LADDER_UNKNOWNS > SPARSE_MIN_UNKNOWNS
    lines = ["name: ladder", "elements:",
             "  - {id: Pa, type: pressure_source, nodes: [n0, ground], value: 100 mmHg}"]
    for k in range(LADDER_UNKNOWNS):
        lines.append(f"  - {{id: R{k}, type: resistor, nodes: [n{k}, n{k + 1}], R: 0.01 mmHg*s/mL}}")
        lines.append(f"  - {{id: C{k}, type: compliance, nodes: [n{k + 1}, ground], C: 0.1 mL/mmHg}}")
    lines.append(f"  - {{id: Rout, type: resistor, nodes: [n{LADDER_UNKNOWNS}, ground], R: 1 mmHg*s/mL}}")
    path = tmp_path / "ladder.yaml"
    path.write_text("\n".join(lines) + "\n")
    res = loaded_after(["op", str(path)])
    assert res["status"] in (0, None)
    assert "scipy.sparse" in res["modules"] and "hemocircuit.sparse" in res["modules"]


def test_a_warm_run_with_expressions_needs_no_pint(tmp_path, monkeypatch):
    """units.memo keeps what pint computed (conversions, a constant's SI value, an expression's
    dimension check) in the cache folder: the second run of a netlist with an expression
    (inertia.yaml: L = rho_b * art.L / (pi * art.r**2 * art.n)) imports no pint (~0.5 s), and
    gives the same operating point.  The first run, with an empty cache, does import it."""
    monkeypatch.setenv("HEMOCIRCUIT_CACHE_DIR", str(tmp_path))
    net = str(ROOT / "netlists" / "inertia.yaml")
    code = ("import io, json, sys, contextlib\n"
            "from hemocircuit.cli import main\n"
            "out = io.StringIO()\n"
            "with contextlib.redirect_stdout(out):\n"
            f"    main(['op', {net!r}])\n"
            "print(json.dumps({'pint': 'pint' in sys.modules, 'out': out.getvalue()}))\n")
    runs = [json.loads(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300,
                                      check=True).stdout.strip().splitlines()[-1]) for _ in range(2)]
    assert runs[0]["pint"] and not runs[1]["pint"]
    assert runs[0]["out"] == runs[1]["out"] and "Lb" in runs[1]["out"]


def test_each_builtin_type_alone_is_the_registry_s_class():
    """registry.get_type's fast path (a built-in type imported alone through the index read
    from the sources) gives, for every built-in type, the class the full registry finds, and
    the index names every built-in type.  In a fresh interpreter: the fast path only runs
    before the full registry is built."""
    code = ("import json\n"
            "from hemocircuit import registry\n"
            "fast = {n: (lambda c: c and c.__module__ + '.' + c.__qualname__)(registry.get_type(n))\n"
            "        for n in registry._builtin_index()}\n"
            "full = {n: c.__module__ + '.' + c.__qualname__ for n, c in registry.component_types().items()}\n"
            "print(json.dumps([fast, full]))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, check=True)
    fast, full = json.loads(out.stdout.strip().splitlines()[-1])
    assert len(fast) >= 25 and fast == {n: full[n] for n in fast}
    builtin = {n for n, path in full.items() if path.startswith("hemocircuit.components.")}
    assert builtin <= set(fast)  # (a plug-in, e.g. the documented one, may be installed too)


_NUMBA_SETTINGS = ("NUMBA_OPT", "NUMBA_LOOP_VECTORIZE")
_SHOW_SETTINGS = "import hemocircuit, numba\nprint(int(numba.config.OPT), int(numba.config.LOOP_VECTORIZE))\n"


@pytest.mark.parametrize("env, numba_first, expect", [
    ({}, False, "1 0"),
    ({"NUMBA_OPT": "3"}, False, "3 0"),
    ({"NUMBA_LOOP_VECTORIZE": "1"}, False, "1 1"),
    ({}, True, "3 1")])
def test_engine_numba_settings(env, numba_first, expect):
    """hemocircuit compiles at LLVM -O1 without the loop vectorizer (the same run speed as
    numba's -O3 with it, a shorter first compile; docs/performance.md), each unless the user set
    it or loaded numba first (numba's defaults: -O3, the loop vectorizer on)."""
    import os
    code = ("import numba\n" if numba_first else "") + _SHOW_SETTINGS
    environ = {k: v for k, v in os.environ.items() if k not in _NUMBA_SETTINGS}
    environ.update(env)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, check=True,
                         env=environ)
    assert out.stdout.strip().splitlines()[-1] == expect


@pytest.mark.parametrize("numba_first, expect", [(False, "1 0"), (True, "3 1")])
def test_compile_helpers_get_this_process_numba_settings(numba_first, expect):
    """The compile helpers (kernels.prebuild, kernels.background) are started with the level and
    loop vectorizer switch this process compiles with, so both compile the same code (a user who
    imported numba first keeps numba's defaults in the helpers too, though their own ``import
    hemocircuit`` would set -O1 without the vectorizer)."""
    import os
    code = (("import numba\n" if numba_first else "") + "import hemocircuit, numba\n"
            "from hemocircuit.kernels.prebuild import helper_env\n"
            "print(' '.join(helper_env()[k] for k in ('NUMBA_OPT', 'NUMBA_LOOP_VECTORIZE')))\n")
    environ = {k: v for k, v in os.environ.items() if k not in _NUMBA_SETTINGS}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, check=True,
                         env=environ)
    assert out.stdout.strip().splitlines()[-1] == expect
