"""Build the report: run the sections in thesis order (a failed section is recorded and the
others go on), judge the statements, write statements.csv, provenance.json and index.html."""
from __future__ import annotations

import datetime as _dt
import json
import os
import sys
import time

import numpy as np

from . import registry
from .core import SectionRun, run_section
from .statements import STATEMENTS, evaluate


class Report:
    def __init__(self, out, runs, rows, provenance, index):
        self.out, self.runs, self.rows, self.provenance, self.index = out, runs, rows, provenance, index

    @property
    def counts(self):
        out = {}
        for r in self.rows:
            out[r.kind] = out.get(r.kind, 0) + 1
        return out


def build(out, quick=False, only=None, progress=True, argv=None):
    """Run the sections (all, or ``only`` those keys) into the folder ``out``; returns a
    :class:`Report`.  Progress per section goes to stderr."""
    from ..provenance import netlist_sources, versions

    keys = registry.check_keys(only) if only else list(registry.SECTIONS)
    os.makedirs(out, exist_ok=True)
    started = time.perf_counter()
    runs = {}
    bar = _progress(keys, progress)
    for n, key in enumerate(keys, 1):
        if bar is not None:
            bar.set_description(f"reproduce {key}")
        try:
            module = registry.load(key)
        except Exception as exc:  # noqa: BLE001 - a section that cannot even be imported is a failed section
            runs[key] = SectionRun(key, key, [], 0, None, "failed", f"{type(exc).__name__}: {exc}")
        else:
            runs[key] = run_section(module, key, out, quick)
        r = runs[key]
        if progress:
            msg = f"[{n}/{len(keys)}] {key}: {r.status} in {r.seconds:.1f} s"
            (bar.write(msg, file=sys.stderr) if bar is not None else print(msg, file=sys.stderr))
        if bar is not None:
            bar.update(1)
    if bar is not None:
        bar.close()
    for key in registry.SECTIONS:  # sections left out by --only: listed as not run
        if key not in runs:
            mod = _try_load(key)
            runs[key] = SectionRun(key, getattr(mod, "TITLE", key), getattr(mod, "LABELS", []),
                                   getattr(mod, "CHAPTER", 0))
    rows = evaluate(runs)
    netlists = sorted({p for r in runs.values() if r.ctx for p in r.ctx.netlists})
    prov = {
        **versions(),
        "date": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "command": " ".join(["hemocircuit", *argv]) if argv is not None else None,
        "mode": "quick" if quick else "full",
        "only": list(only) if only else None,
        "wall_time_s": round(time.perf_counter() - started, 2),
        "netlists": {os.path.relpath(p, os.path.dirname(os.path.dirname(p))):
                     netlist_sources(p).sha256() for p in netlists},
        "sections": {k: {"status": runs[k].status, "seconds": round(runs[k].seconds, 2),
                         "settings": runs[k].ctx.settings if runs[k].ctx else {}} for k in registry.SECTIONS},
    }
    _write_statements(out, rows, prov)
    from ..io import atomic_write
    atomic_write(os.path.join(out, "provenance.json"), json.dumps(_plain(prov), indent=2))
    from .html import render
    index = os.path.join(out, "index.html")
    atomic_write(index, render(runs, rows, prov, out))
    return Report(out, runs, rows, prov, index)


def _try_load(key):
    try:
        return registry.load(key)
    except Exception:  # noqa: BLE001
        return None


def _progress(keys, progress):
    if not progress:
        return None
    try:
        from tqdm import tqdm
    except ImportError:
        return None
    return tqdm(total=len(keys), file=sys.stderr, unit="section", leave=False)


def _plain(v):
    from ..results import jsonable
    return jsonable(v)


def _write_statements(out, rows, prov):
    """statements.csv: one row per statement (thesis value and line, computed values per
    reading, relative difference, verdict), with the report's provenance."""
    from ..results import Result

    def col(f, dtype=float):
        return np.array([f(r) for r in rows], dtype=dtype)

    nan = float("nan")
    res = Result({
        "id": col(lambda r: r.st.id, object),
        "thesis_line": col(lambda r: r.st.line, int),
        "statement": col(lambda r: r.st.text, object),
        "unit": col(lambda r: r.st.unit, object),
        "check": col(lambda r: r.st.check, object),
        "thesis_value": col(lambda r: r.st.thesis),
        "tolerance": col(lambda r: r.st.tol if r.st.check in ("rel", "abs") else nan),
        "computed": col(lambda r: nan if r.value is None else r.value),
        "computed_other_reading": col(lambda r: next((v for k, v in r.values.items() if k != r.st.decides), nan)),
        "rel_difference": col(lambda r: nan if r.rel_diff is None else r.rel_diff),
        "verdict": col(lambda r: r.verdict, object),
        "model_notes": col(lambda r: r.st.note, object),
    }, index=["id"], metadata={"analysis": "reproduce", "provenance": dict(prov)})
    res.save(os.path.join(out, "statements.csv"))


def n_statements():
    return len(STATEMENTS)
