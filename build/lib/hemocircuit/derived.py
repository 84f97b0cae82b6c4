"""Derived quantities: expressions of output columns declared in a netlist.

    derived:
      flow:        {expr: "Q(Rla)", unit: mL/s}
      Va_over_Vv:  {expr: "(V(Ca) + V(art)) / V(Cv)", unit: dimensionless}

Column names (``P(a)``, ``Q(Rla)``, ``V(Cv)``, ``art.r``) appear as they are; the expression may
use + - * / **, numbers, and abs/min/max/exp/log/sqrt.  Values are in the columns' own units;
the declared unit is the label of the result (variants that extend a netlist inherit and may
override its derived quantities, so compare can line them up by name).
"""
from __future__ import annotations

import ast
import re

import numpy as np

from .errors import NetlistError
from .expressions import parse_bounded

_FUNCS = {"abs": np.abs, "exp": np.exp, "log": np.log, "sqrt": np.sqrt, "min": np.minimum, "max": np.maximum}
_ALLOWED = (ast.Expression, ast.BinOp, ast.UnaryOp, ast.Constant, ast.Name, ast.Load, ast.Call, ast.Add, ast.Sub,
            ast.Mult, ast.Div, ast.Pow, ast.USub, ast.UAdd)


def evaluate_derived(derived: dict, columns: dict, file=None) -> dict:
    """{name: array} for each derived quantity, from ``columns`` {column name: array}."""
    names = sorted(columns, key=len, reverse=True)
    out = {}
    for name, spec in derived.items():
        text = str(spec["expr"])
        env = {}
        expr = text
        for k, col in enumerate(names):
            if col in expr:
                var = f"_c{k}"
                expr = re.sub(r"(?<![\w.])" + re.escape(col) + r"(?![\w(])", var, expr)
                env[var] = np.asarray(columns[col], dtype=float)
        tree = parse_bounded(expr, _ALLOWED, f"derived quantity '{name}'", {"file": file}, tuple(_FUNCS))
        for node in ast.walk(tree):
            if isinstance(node, ast.Name) and node.id not in env and node.id not in _FUNCS and node.id != "pi":
                raise NetlistError(f"derived quantity '{name}': unknown column or name '{node.id}' in {text!r} "
                                   f"(columns: {sorted(columns)[:20]}...)", file=file)
        try:
            with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
                out[name] = eval(compile(tree, "<derived>", "eval"), {"__builtins__": {}},
                                 {**env, **_FUNCS, "pi": np.pi})
        except (ArithmeticError, ValueError, TypeError, RecursionError) as exc:
            raise NetlistError(f"derived quantity '{name}': cannot evaluate {text[:60]!r}: {exc}", file=file) from None
    return out


def check_derived(derived: dict, columns: list, file=None):
    """Check every derived expression against the circuit's column names at load (parse,
    names, limits, constant overflow such as 9**9**9**9) by evaluating it on columns of ones."""
    if derived:
        evaluate_derived(derived, {c: np.ones(1) for c in columns}, file)


def derived_units(derived: dict) -> dict:
    return {name: str(spec.get("unit", "")) for name, spec in derived.items()}
