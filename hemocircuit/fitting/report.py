"""The fit's outputs, written atomically into one folder:

* ``report.json``  best values with units, standard errors, correlation matrix, rms per
  dataset, bound flags, every start, and provenance (netlist, spec, settings, time, version);
* ``fitted.yaml``  a netlist fragment: ``extends:`` the netlist, ``change:`` the fitted, tied,
  fixed and start_from values, so ``hemocircuit op fitted.yaml`` loads the fitted circuit
  (and a later stage can name it in ``start_from:``);
* ``protocol_<dataset>.yaml``  for epoch parameters (``art.tau_Ca@239s``): the protocol with
  the fitted epoch values;
* ``fit.csv``  data, normalised target and model for every row; ``fit.png`` the fit over the data.
"""
from __future__ import annotations

import datetime
import json
import math
import os
import re

import numpy as np
import yaml

from ..io import atomic_write, save_figure
from ..names import split_path

#: the files a fit writes into its folder (a folder holding only these may be written again)
OUTPUT_FILES = ("report.json", "fitted.yaml", "netlist.yaml", "fit.csv", "fit.png")
_OUTPUT_PATTERN = re.compile(r"^(protocol_.+\.yaml)$")


def _q(value, unit):
    """'2.64e-08 N' (a quantity string for netlists); bare number if dimensionless."""
    if unit in ("", "dimensionless", "1"):
        return float(f"{float(value):.10g}")
    return f"{float(value):.10g} {unit}"


def summary(problem, result):
    """The report as a dict (what report.json holds)."""
    spec = problem.spec
    params = []
    for j, path in enumerate(problem.parameters):
        params.append({"path": path, "value": float(result["p"][j]), "unit": problem.units[j],
                       "se": float(result["se"][j]),
                       "rel_se": float(result["se"][j] / abs(result["p"][j])) if result["p"][j] else None,
                       "lower": float(problem.lower[j]), "upper": float(problem.upper[j]),
                       "log": bool(problem.log[j]), "start": float(problem.start[j]),
                       "on_bound": result["bounds_hit"][j] or None,
                       "identifiable": not bool(result["unidentifiable"][j])})
    return {
        "name": spec.name,
        "parameters": params,
        "tied": {k: {"value": v, "unit": problem.circuit.param_unit(k)} for k, v in result["tied"].items()},
        "correlation": np.nan_to_num(result["corr"]).round(6).tolist(),
        "rms": {d.name: {"value": float(r), "unit": d.unit} for d, r in zip(problem.datasets, result["rms"])},
        "rms_error": float(result["rms_error"]),
        "ssr": result["ssr"], "dof": result["dof"], "residual_variance": result["s2"],
        "condition_number_JTJ_in_u": result["cond"],
        "starts": [{"index": i, "cost": s["cost"], "nfev": s["nfev"], "njev": s["njev"], "status": s["status"],
                    "message": s["message"], "seconds": round(s["seconds"], 3),
                    "start": [float(v) for v in problem_space_to_p(problem, s["z0"])],
                    "end": [float(v) for v in problem_space_to_p(problem, s["z"])]}
                   for i, s in enumerate(result["starts"])],
        "best_start": result["best"],
        "provenance": {"netlist": problem.netlist_path, "spec": spec.file, "start_from": spec.start_from,
                       "settings": result["settings"], "fixed": problem.fixed,
                       "datasets": {d.name: d.spec.file for d in problem.datasets},
                       "written": datetime.datetime.now().isoformat(timespec="seconds"),
                       "hemocircuit": _version(), "seconds": round(result["seconds"], 2)},
    }


def problem_space_to_p(problem, u):
    from .optimizer import Space
    return Space(problem).to_p(u)


def _version():
    from ..version import __version__
    return __version__


def fragment(problem, result, out_dir, extends=None):
    """The fitted netlist fragment (YAML text): extends the netlist (or ``extends``, a path
    relative to ``out_dir``), changes every value the fit set (start_from, fixed, estimated
    without an epoch, tied) and the global options."""
    change = {}

    def put(path, text):
        eid, name = split_path(path)
        change.setdefault(eid, {})[name] = text

    for path, v in problem.start_from.items():
        put(path, v)
    for path, v in problem.spec.options.items():
        put(path, v)
    for path, v in problem.fixed.items():
        put(path, _q(v, problem.circuit.param_unit(path)))
    for p, val, unit in zip(problem.spec.parameters, result["p"], problem.units):
        if p.epoch is None:
            put(p.base_path, _q(val, unit))
    for path, v in result["tied"].items():
        put(path, _q(v, problem.circuit.param_unit(path)))
    rel = extends or os.path.relpath(problem.netlist_path, os.path.abspath(out_dir))
    epochs = [f"{p.path} = {_q(v, u)}" for p, v, u in zip(problem.spec.parameters, result["p"], problem.units)
              if p.epoch is not None]
    head = [f"# written by hemocircuit fit: {problem.spec.name}",
            f"# spec: {problem.spec.file}", f"# netlist: {problem.netlist_path}",
            f"# rms error (sum over datasets): {result['rms_error']:.6g}"]
    if extends:
        head.append(f"# {extends}: a copy of the netlist (its folder cannot be read from here)")
    if epochs:
        head.append("# epoch values (in the protocol_*.yaml files, not in this netlist): " + ", ".join(epochs))
    body = {"name": f"{problem.circuit.netlist.name}-fit", "extends": rel, "change": change}
    return "\n".join(head) + "\n" + yaml.safe_dump(body, sort_keys=False, default_flow_style=None)


def needs_copy(problem, out_dir) -> bool:
    """Whether ``out_dir/fitted.yaml`` could not extend the netlist itself: a netlist loads
    files only inside its own project (hemocircuit.access), so when the output folder lies
    outside the project of the netlist (or of a file its loading read: extends chain, tables)
    the fragment extends a copy instead.  An svZeroDSolver JSON model is always copied (its
    numbers' unit system was an option of the fit, which the fragment could not carry)."""
    from ..access import Access

    if problem.netlist_path.lower().endswith(".json"):
        return True
    access = Access.for_netlist(os.path.join(os.path.abspath(out_dir), "fitted.yaml"))
    netlist = problem.base_circuit.netlist
    read = list(getattr(netlist.sources, "paths", None) or []) or [problem.netlist_path]
    return not all(access.allows(f) for f in read)


def flattened(circuit) -> str:
    """The netlist of ``circuit`` (as loaded: extends chain resolved, ${} substituted, table
    files as absolute paths) as one self-contained YAML netlist."""
    n = circuit.netlist
    body = {"name": n.name}
    if n.description:
        body["description"] = n.description
    if n.parameters:
        body["parameters"] = dict(n.parameters)
    body["elements"] = [{"id": e.id, "type": e.type, "nodes": list(e.nodes), **e.values} for e in n.elements]
    for k in ("constraints", "outputs", "derived", "ic"):
        if getattr(n, k):
            body[k] = getattr(n, k)
    if n.input:
        body["input"] = n.input
    head = f"# the netlist {n.file}, as loaded (extends chain resolved), for fitted.yaml to extend\n"
    return head + yaml.safe_dump(body, sort_keys=False, default_flow_style=None)


def fitted_protocols(problem, result):
    """{dataset name: protocol YAML text} for tran datasets whose epochs were estimated."""
    from .experiments import TransientExperiment
    out = {}
    epochs = {(p.base_path, p.epoch): _q(v, u) for p, v, u in zip(problem.spec.parameters, result["p"], problem.units)
              if p.epoch is not None}
    if not epochs:
        return out
    for d in problem.datasets:
        e = d.experiment
        if not isinstance(e, TransientExperiment):
            continue
        from ..inputs import read_yaml
        data = read_yaml(e.protocol.file, "protocol file", problem.spec.access)
        for (path, t), text in epochs.items():
            if t == 0.0 and path in (data.get("initial") or {}):
                data["initial"][path] = text
            for ev in data.get("events") or []:
                from ..units import parse_quantity
                if parse_quantity(ev["at"], "s") == t and path in ev["set"]:
                    ev["set"][path] = text
        data["description"] = f"{data.get('description', '')} [epoch values fitted by hemocircuit fit]".strip()
        out[d.name] = (f"# {e.protocol.file} with the epoch values fitted by {problem.spec.file}\n"
                       + yaml.safe_dump(data, sort_keys=False, default_flow_style=None))
    return out


def plot(problem, result, path):
    from ..io import pyplot
    plt = pyplot()
    n = len(problem.datasets)
    fig, axes = plt.subplots(n, 1, figsize=(7, 3.2 * n), squeeze=False)
    for ax, d, m, t, rms in zip(axes[:, 0], problem.datasets, result["predictions"], result["targets"], result["rms"]):
        tran = d.x_label.startswith("time")
        ax.plot(d.x, t, "o" if not tran else ".", ms=4 if not tran else 2, color="tab:blue",
                label="data" + (" (normalised)" if d.spec.normalise else ""))
        ax.plot(d.x, m, "-", color="tab:red", lw=1.8, label="model, fitted")
        ax.set_xlabel(d.x_label)
        ax.set_ylabel(f"{d.spec.observe} [{d.unit}]")
        ax.set_title(f"{d.name}: rms {rms:.4g} {d.unit}", fontsize=9)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(f"{problem.spec.name}", fontsize=10)
    save_figure(fig, path)


def table_csv(problem, result):
    lines = ["dataset,row,x,data,target,model,residual"]
    for d, m, t in zip(problem.datasets, result["predictions"], result["targets"]):
        for i in range(d.n):
            lines.append(f"{d.name},{i},{d.x[i]:.10g},{d.y[i]:.10g},{t[i]:.10g},{m[i]:.10g},"
                         f"{(m[i] - t[i]) / d.sigma[i]:.6g}")
    return "\n".join(lines) + "\n"


def check_out_dir(out_dir, flag="--out"):
    """The output folder of a fit, checked before fitting: created if missing (its parent must
    exist); an existing folder may hold only a previous fit's outputs (they are replaced), not
    other files; a file is refused."""
    from ..errors import HemocircuitError
    from ..io import prepare_folder

    out_dir = str(out_dir)
    if os.path.isdir(out_dir):
        other = sorted(f for f in os.listdir(out_dir) if not is_output_file(f))
        if other:
            raise HemocircuitError(f"{flag} {out_dir}: the folder holds files a fit does not write "
                                   f"({', '.join(repr(f) for f in other[:5])}{' ...' if len(other) > 5 else ''}); "
                                   "give an empty or new folder, or the folder of a previous fit (its outputs "
                                   "are replaced)")
    return prepare_folder(out_dir, flag)


def is_output_file(name) -> bool:
    """A file a fit writes (or the temporary file of one, left by an interrupted write)."""
    m = re.match(r"^\.(.+)\.[^.]+\.tmp$", name)
    base = m.group(1) if m else name
    return base in OUTPUT_FILES or bool(_OUTPUT_PATTERN.match(base))


def write(problem, result, out_dir, plot_png=True):
    """Write every output (atomically, replacing a previous fit's) into out_dir; returns {kind: path}."""
    check_out_dir(out_dir, "output folder")
    paths = {"report": os.path.join(out_dir, "report.json"), "fragment": os.path.join(out_dir, "fitted.yaml"),
             "csv": os.path.join(out_dir, "fit.csv")}
    atomic_write(paths["report"], json.dumps(_finite(summary(problem, result)), indent=1, allow_nan=False,
                                             default=_json_default))
    extends = None
    if needs_copy(problem, out_dir):
        paths["netlist"] = os.path.join(out_dir, "netlist.yaml")
        atomic_write(paths["netlist"], flattened(problem.base_circuit))
        extends = "netlist.yaml"
    atomic_write(paths["fragment"], fragment(problem, result, out_dir, extends))
    atomic_write(paths["csv"], table_csv(problem, result))
    for name, text in fitted_protocols(problem, result).items():
        paths[f"protocol {name}"] = os.path.join(out_dir, f"protocol_{_safe_name(name)}.yaml")
        atomic_write(paths[f"protocol {name}"], text)
    if plot_png:
        paths["plot"] = os.path.join(out_dir, "fit.png")
        plot(problem, result, paths["plot"])
    return paths


def _safe_name(name):
    """A dataset name as part of a file name (letters, digits, '-', '_', '.')."""
    return re.sub(r"[^A-Za-z0-9_.-]", "_", str(name))[:80] or "dataset"


def _finite(o):
    """``o`` with every non-finite number as None (JSON has no NaN or Infinity: a standard
    error that does not exist is null)."""
    if isinstance(o, dict):
        return {k: _finite(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_finite(v) for v in o]
    if isinstance(o, np.ndarray):
        return _finite(o.tolist())
    if isinstance(o, (float, np.floating)):
        return float(o) if math.isfinite(o) else None
    if isinstance(o, np.integer):
        return int(o)
    if isinstance(o, np.bool_):
        return bool(o)
    return o


def _json_default(o):
    return str(o)


def text(problem, result):
    """A human-readable summary (what the CLI prints)."""
    lines = [f"fit '{problem.spec.name}': best of {len(result['starts'])} start(s) (start {result['best']}), "
             f"{result['seconds']:.1f} s"]
    w = max(len(p) for p in problem.parameters)
    lines.append(f"  {'parameter':<{w}}  {'value':>12}  {'std. error':>10}  unit")
    for j, p in enumerate(problem.parameters):
        flag = f"  ON {result['bounds_hit'][j].upper()} BOUND (suspect)" if result["bounds_hit"][j] else ""
        if result["unidentifiable"][j]:
            flag += "  NOT IDENTIFIABLE from these data"
        lines.append(f"  {p:<{w}}  {result['p'][j]:12.6g}  {result['se'][j]:10.3g}  {problem.units[j]}{flag}")
    for k, v in result["tied"].items():
        lines.append(f"  {k:<{w}}  {v:12.6g}  (tied)")
    for d, r in zip(problem.datasets, result["rms"]):
        lines.append(f"  rms {d.name}: {r:.6g} {d.unit}")
    lines.append(f"  rms error (sum over datasets, the thesis's objective): {result['rms_error']:.6g}")
    if result["dof"] <= 0:
        lines.append(f"  no standard errors: {problem.n_residuals} data row(s) for {len(problem.parameters)} "
                     "parameter(s) leave no degrees of freedom for the residual variance (null in report.json)")
    corr = np.nan_to_num(result["corr"])
    hi = [(problem.parameters[i], problem.parameters[j], corr[i, j]) for i in range(len(corr))
          for j in range(i + 1, len(corr)) if abs(corr[i, j]) > 0.95]
    if hi:
        lines.append("  strongly correlated (|r| > 0.95): " + ", ".join(f"{a}/{b} {c:+.3f}" for a, b, c in hi))
    return "\n".join(lines)
