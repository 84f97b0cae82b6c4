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
import os
import tempfile

import numpy as np
import yaml


def _atomic_write(path, text):
    d = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(dir=d, prefix=".tmp_", suffix=os.path.basename(path))
    try:
        with os.fdopen(fd, "w") as fh:
            fh.write(text)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def _atomic_figure(fig, path):
    from ..io import save_figure
    d = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(dir=d, prefix=".tmp_", suffix=".png")
    os.close(fd)
    try:
        save_figure(fig, tmp)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


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
    from .. import __version__
    return __version__


def fragment(problem, result, out_dir):
    """The fitted netlist fragment (YAML text): extends the netlist, changes every value the fit
    set (start_from, fixed, estimated without an epoch, tied) and the global options."""
    change = {}

    def put(path, text):
        eid, _, name = path.partition(".")
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
    rel = os.path.relpath(problem.netlist_path, os.path.abspath(out_dir))
    epochs = [f"{p.path} = {_q(v, u)}" for p, v, u in zip(problem.spec.parameters, result["p"], problem.units)
              if p.epoch is not None]
    head = [f"# written by hemocircuit fit: {problem.spec.name}",
            f"# spec: {problem.spec.file}", f"# netlist: {problem.netlist_path}",
            f"# rms error (sum over datasets): {result['rms_error']:.6g}"]
    if epochs:
        head.append("# epoch values (in the protocol_*.yaml files, not in this netlist): " + ", ".join(epochs))
    body = {"name": f"{problem.circuit.netlist.name}-fit", "extends": rel, "change": change}
    return "\n".join(head) + "\n" + yaml.safe_dump(body, sort_keys=False, default_flow_style=None)


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
        with open(e.protocol.file) as fh:
            data = yaml.safe_load(fh)
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
    _atomic_figure(fig, path)


def table_csv(problem, result):
    lines = ["dataset,row,x,data,target,model,residual"]
    for d, m, t in zip(problem.datasets, result["predictions"], result["targets"]):
        for i in range(d.n):
            lines.append(f"{d.name},{i},{d.x[i]:.10g},{d.y[i]:.10g},{t[i]:.10g},{m[i]:.10g},"
                         f"{(m[i] - t[i]) / d.sigma[i]:.6g}")
    return "\n".join(lines) + "\n"


def write(problem, result, out_dir, plot_png=True):
    """Write every output (atomically) into out_dir; returns {kind: path}."""
    os.makedirs(out_dir, exist_ok=True)
    paths = {"report": os.path.join(out_dir, "report.json"), "fragment": os.path.join(out_dir, "fitted.yaml"),
             "csv": os.path.join(out_dir, "fit.csv")}
    _atomic_write(paths["report"], json.dumps(summary(problem, result), indent=1, default=_json_default))
    _atomic_write(paths["fragment"], fragment(problem, result, out_dir))
    _atomic_write(paths["csv"], table_csv(problem, result))
    for name, text in fitted_protocols(problem, result).items():
        paths[f"protocol {name}"] = os.path.join(out_dir, f"protocol_{name}.yaml")
        _atomic_write(paths[f"protocol {name}"], text)
    if plot_png:
        paths["plot"] = os.path.join(out_dir, "fit.png")
        plot(problem, result, paths["plot"])
    return paths


def _json_default(o):
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, np.bool_):
        return bool(o)
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
    corr = np.nan_to_num(result["corr"])
    hi = [(problem.parameters[i], problem.parameters[j], corr[i, j]) for i in range(len(corr))
          for j in range(i + 1, len(corr)) if abs(corr[i, j]) > 0.95]
    if hi:
        lines.append("  strongly correlated (|r| > 0.95): " + ", ".join(f"{a}/{b} {c:+.3f}" for a, b, c in hi))
    return "\n".join(lines)
