"""What a reproduce section gets and gives: its settings (quick or full), the files it writes
(figures as PNG, data as CSV through :meth:`Result.save`, both with provenance) and the values
it computes for the statements table (:mod:`hemocircuit.reproduce.statements`).

A section is a module of this package with ``TITLE``, ``LABELS`` (the thesis figures it
regenerates) and ``run(ctx)``; :mod:`hemocircuit.reproduce.registry` lists them in thesis order.
"""
from __future__ import annotations

import importlib.util
import os
import time

import numpy as np

from ..errors import HemocircuitError

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))  # reproduce/ sits in the checkout's root


def repo_path(*parts):
    """A file of the repository (netlists/, examples/): the report is built from the bundled
    netlists and protocols only.  A clear error when the package runs outside its checkout."""
    path = os.path.join(ROOT, *parts)
    if not os.path.exists(path):
        raise HemocircuitError(f"reproduce needs the repository's file {os.path.join(*parts)} (looked in {ROOT}); "
                               "run it from a checkout installed with 'pip install -e .'")
    return path


def example(name):
    """An example script of examples/ as a module (its functions are reused, not copied)."""
    path = repo_path("examples", f"{name}.py")
    spec = importlib.util.spec_from_file_location(f"hemocircuit_example_{name}", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


class Context:
    """One section's run: settings, output folders and everything it records.

    ``quick``: coarser grids and shorter runs (the --quick report).  ``figures``: [(label,
    file, caption)]; ``data``: [file]; ``values``: {statement id: {reading: value}};
    ``netlists``: the netlist files it loaded (hashed in the provenance)."""

    def __init__(self, key, out_dir, quick):
        self.key, self.out, self.quick = key, out_dir, bool(quick)
        self.figures, self.data_files, self.values, self.notes, self.netlists = [], [], {}, [], []
        self.settings = {}
        os.makedirs(os.path.join(out_dir, "figures"), exist_ok=True)
        os.makedirs(os.path.join(out_dir, "data"), exist_ok=True)

    # ---------------------------------------------------------------- settings ------------
    def pick(self, quick, full):
        """``quick`` in the quick report, ``full`` otherwise."""
        return quick if self.quick else full

    def setting(self, name, quick, full):
        """A named setting of this section (recorded in the provenance); returns its value."""
        v = self.pick(quick, full)
        self.settings[name] = v.tolist() if isinstance(v, np.ndarray) else v
        return v

    # ---------------------------------------------------------------- inputs --------------
    def load(self, name):
        """netlists/<name>.yaml as a circuit (recorded for the provenance hashes)."""
        from ..circuit import load
        path = repo_path("netlists", f"{name}.yaml")
        if path not in self.netlists:
            self.netlists.append(path)
        return load(path)

    def protocol(self, name):
        return repo_path("examples", "protocols", f"{name}.yaml")

    # ---------------------------------------------------------------- outputs -------------
    def figure_path(self, name):
        return os.path.join(self.out, "figures", f"{self.key}_{name}.png")

    def figure(self, name, fig, caption, label=""):
        """Write a matplotlib figure (atomically) and record it with its thesis label."""
        from ..io import save_figure
        path = self.figure_path(name)
        save_figure(fig, path, dpi=100)
        self.figures.append((label, os.path.relpath(path, self.out), caption))
        return path

    def existing_figure(self, name, caption, label=""):
        """Record a PNG that reused code wrote to :meth:`figure_path`."""
        self.figures.append((label, os.path.relpath(self.figure_path(name), self.out), caption))

    def save(self, name, result, circuit=None, settings=None):
        """Write a Result as data/<section>_<name>.csv with its provenance (the section's
        settings are added to the result's own)."""
        from ..provenance import stamp
        md = result.metadata
        if "analysis" not in md:
            stamp(result, f"reproduce:{self.key}", circuit, settings)
        md.setdefault("provenance", {})
        if circuit is not None and getattr(circuit, "file", None):
            md["provenance"].setdefault("netlist", str(circuit.file))
        md["reproduce"] = {"section": self.key, "quick": self.quick, **(settings or {})}
        path = os.path.join(self.out, "data", f"{self.key}_{name}.csv")
        result.save(path)
        self.data_files.append(os.path.relpath(path, self.out))
        return path

    def table(self, name, columns, units, index=(), circuit=None, settings=None):
        """Write a table computed here (not by an analysis) as a Result CSV."""
        from ..results import Result
        return self.save(name, Result(columns, units, index=index), circuit, settings)

    def rows(self, name, rows, columns, circuit=None, settings=None):
        """Write a list of row dicts with ``columns`` {key: unit} as a Result CSV."""
        cols = {}
        for k in columns:
            vals = [r.get(k) for r in rows]
            numeric = all(isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool)
                          for v in vals)
            cols[k] = np.array(vals, dtype=float if numeric else object)
        return self.table(name, cols, {k: u for k, u in columns.items()}, circuit=circuit, settings=settings)

    def value(self, sid, value, reading="as implemented"):
        """The value computed now for statement ``sid`` (in the statement's unit).  A statement
        with two readings (MODEL_NOTES) gets one call per reading."""
        self.values.setdefault(sid, {})[reading] = float(value)

    def note(self, text):
        self.notes.append(text)


class SectionRun:
    """The outcome of one section: its context, status ('ok', 'failed', 'not run'), error
    text and run time."""

    def __init__(self, key, title, labels, chapter, ctx=None, status="not run", error="", seconds=0.0):
        self.key, self.title, self.labels, self.chapter = key, title, labels, chapter
        self.ctx, self.status, self.error, self.seconds = ctx, status, error, seconds


def run_section(module, key, out_dir, quick):
    """Run one section, catching its failure (the report records it and goes on)."""
    import traceback

    ctx = Context(key, out_dir, quick)
    t0 = time.perf_counter()
    try:
        module.run(ctx)
        status, error = "ok", ""
    except Exception as exc:  # noqa: BLE001 - a failed section is reported in the page, the rest goes on
        status = "failed"
        error = f"{type(exc).__name__}: {exc}\n\n" + "".join(traceback.format_exc(limit=6))
    return SectionRun(key, module.TITLE, module.LABELS, module.CHAPTER, ctx, status, error,
                      time.perf_counter() - t0)


def plt():
    from ..io import pyplot
    return pyplot()
