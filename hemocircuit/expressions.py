"""Parameter expressions: a parameter that follows other elements' quantities.

A value written as ``"= rho_b * art.L / (pi * art.r**2 * art.n)"`` is an expression.  Names
are netlist parameters (``rho_b``), other elements' parameters (``art.L``) or state-only
observables (``art.r``), plus ``pi`` and the functions exp, log, sqrt.  At load time pint
checks the expression's dimension against the target parameter's unit and finds the factor
to it; at run time it is evaluated with every quantity in coherent SI base units (one float
factor per name, computed once), so the hot path is plain numpy.
"""
from __future__ import annotations

import ast
import contextlib
import sys
from dataclasses import dataclass

import numpy as np

from . import limits
from .errors import NetlistError, excerpt
from .units import Q_, memo, parse_with_unit, si_factor

_FUNCS = {"exp": np.exp, "log": np.log, "sqrt": np.sqrt}
_ALLOWED = (ast.Expression, ast.BinOp, ast.UnaryOp, ast.Constant, ast.Name, ast.Attribute, ast.Load, ast.Call,
            ast.Add, ast.Sub, ast.Mult, ast.Div, ast.Pow, ast.USub, ast.UAdd)


def parse_bounded(text: str, allowed: tuple, what: str, where: dict, funcs=()) -> ast.Expression:
    """Parse ``text`` as a Python expression within the input limits (length, syntax-tree size
    and depth: compiling and evaluating a deeper tree recurses without bound), allowing only the
    node types ``allowed`` and calls of the names ``funcs``.  Integer literals become floats: Python integer powers
    (``9**9**9**9``) can take unbounded time and memory, float powers overflow at once."""
    limits.check_value_length(text, where, what)
    try:
        tree = ast.parse(text, mode="eval")
    except SyntaxError as exc:
        raise NetlistError(f"cannot parse {what} {excerpt(text)}: {exc.msg}", **where) from None
    except (RecursionError, MemoryError, ValueError):
        raise NetlistError(f"{what}: {excerpt(text)} is nested too deeply {limits.how_to_raise('EXPR_DEPTH')}",
                           **where) from None
    max_nodes, max_depth = limits.limit("EXPR_NODES"), limits.limit("EXPR_DEPTH")
    count, stack = 0, [(tree, 0)]
    while stack:  # iterative: the tree may be thousands deep
        node, depth = stack.pop()
        count += 1
        if count > max_nodes:
            raise NetlistError(f"{what}: {excerpt(text)} has more than {max_nodes} terms "
                               f"{limits.how_to_raise('EXPR_NODES')}", **where)
        if depth > max_depth:
            raise NetlistError(f"{what}: {excerpt(text)} is nested more than {max_depth} levels deep "
                               f"{limits.how_to_raise('EXPR_DEPTH')}", **where)
        if not isinstance(node, allowed):
            raise NetlistError(f"{what}: {type(node).__name__} is not allowed in {excerpt(text)} "
                               "(use + - * / **, numbers, names and the listed functions)", **where)
        if isinstance(node, ast.Call) and not (isinstance(node.func, ast.Name) and node.func.id in funcs):
            raise NetlistError(f"{what}: {excerpt(text)}: only {', '.join(funcs)} may be called", **where)
        if isinstance(node, ast.Constant):
            if type(node.value) is int:
                node.value = float(node.value)
            elif type(node.value) is not float:
                raise NetlistError(f"{what}: {excerpt(text)}: only numbers are allowed as constants", **where)
        stack.extend((child, depth + 1) for child in ast.iter_child_nodes(node))
    return tree


@contextlib.contextmanager
def _deep_enough():
    """Python's recursion limit raised for the tree walks of an expression within the
    EXPR_DEPTH limit (ast.unparse takes about three frames per level)."""
    old = sys.getrecursionlimit()
    sys.setrecursionlimit(max(old, 8 * limits.limit("EXPR_DEPTH")
                              + 1000))
    try:
        yield
    finally:
        sys.setrecursionlimit(old)


def is_expression(value) -> bool:
    return isinstance(value, str) and value.lstrip().startswith("=")


@dataclass
class Reference:
    element: str | None  # None: a netlist parameter (a constant)
    name: str
    unit: str
    kind: str  # 'param', 'observable' or 'constant'
    constant: float = 0.0  # SI value when kind == 'constant'
    base_unit: str = ""  # its SI base unit (pint's spelling)

    @property
    def pint(self):
        """A constant as a pint quantity in SI base units (the load-time dimension check).
        Made when asked rather than stored: a stored pint quantity travels with every circuit
        sent to a worker process, whose first unpickling then builds pint's application
        registry (1.56 s per worker, measured on the vasomotion circuit)."""
        return Q_(self.constant, self.base_unit)


class Expression:
    """A compiled expression; ``refs`` lists what it reads, ``evaluate`` computes it."""

    def __init__(self, text, target_unit, resolve, where):
        self.text = text.lstrip()[1:].strip()
        self.where = where
        tree = parse_bounded(self.text, _ALLOWED, "expression", where, tuple(_FUNCS))
        self.refs: dict[str, Reference] = {}
        self._tree = tree
        self._key = {}
        with _deep_enough():
            self._collect(tree.body, resolve)
            renamed = ast.fix_missing_locations(_Rename(self._key).visit(tree))
            self._source = ast.unparse(renamed)  # kept so the compiled code can be rebuilt after pickling
            code = compile(self._source, "<expr>", "eval")
        self._code = code
        # dimension check and output factor, evaluated once with pint (and remembered: units.memo)
        try:
            memo("expression_checked", [self._source, target_unit,
                                        [[k, r.kind, r.unit, r.constant, r.base_unit]
                                         for k, r in sorted(self._named().items())]],
                 lambda: self._check(code, target_unit))
        except Exception as exc:
            raise NetlistError(f"expression {excerpt(self.text)} does not give a quantity in {target_unit}: {exc}",
                               **where) from None
        self.out_factor = 1.0 / si_factor(target_unit)
        self.si = {k: (si_factor(r.unit) if r.kind != "constant" else None) for k, r in self._named().items()}

    def __getstate__(self):
        # code objects do not pickle (circuits are sent to worker processes): rebuild on load
        state = dict(self.__dict__)
        state.pop("_code", None)
        state.pop("_tree", None)
        return state

    def __setstate__(self, state):
        self.__dict__.update(state)
        self._code = compile(self._source, "<expr>", "eval")

    def _check(self, code, target_unit):
        """Evaluate the expression on pint quantities; raises unless it gives ``target_unit``."""
        env = {"pi": np.pi, **_FUNCS}
        for name, ref in self._named().items():
            env[name] = ref.pint if ref.kind == "constant" else Q_(1.0, ref.unit)
        sample = eval(code, {"__builtins__": {}}, env)
        sample = sample if hasattr(sample, "to") else Q_(sample, "dimensionless")
        sample.to(target_unit)
        return True

    def si_factor(self, key):
        """The factor from reference ``key``'s unit to SI, as the expression applies it."""
        return self.si[self._key[key]]

    def _named(self):
        return {self._key[k]: r for k, r in self.refs.items()}

    def _collect(self, node, resolve):
        dotted = dotted_reference(node)
        if dotted is not None:
            element, attr = dotted
            key = f"{element}.{attr}"
            if key not in self.refs:
                self.refs[key] = resolve(element, attr)
                self._key[key] = f"_r{len(self._key)}"
            return
        if isinstance(node, ast.Attribute):
            raise NetlistError(f"expression {excerpt(self.text)}: write references as ELEMENT.NAME", **self.where)
        if isinstance(node, ast.Name):
            if node.id in _FUNCS or node.id == "pi":
                return
            if node.id not in self.refs:
                self.refs[node.id] = resolve(None, node.id)
                self._key[node.id] = f"_r{len(self._key)}"
            return
        for child in ast.iter_child_nodes(node):
            self._collect(child, resolve)

    def evaluate(self, values: dict):
        """``values``: reference key -> array in that reference's unit.  Returns target-unit value."""
        env = {"pi": np.pi, **_FUNCS}
        for key, ref in self.refs.items():
            name = self._key[key]
            env[name] = ref.constant if ref.kind == "constant" else values[key] * self.si[name]
        return eval(self._code, {"__builtins__": {}}, env) * self.out_factor


def dotted_reference(node):
    """(element, name) of a reference ELEMENT.NAME, the element's id possibly dotted itself (a
    subcircuit instance's element, ``left.art.tau_Ca``); None for anything else."""
    parts = []
    while isinstance(node, ast.Attribute):
        parts.append(node.attr)
        node = node.value
    if not parts or not isinstance(node, ast.Name):
        return None
    parts.append(node.id)
    parts.reverse()
    return ".".join(parts[:-1]), parts[-1]


def instance_references(text, elements, prefix, constants):
    """An instance's copy of one of its child netlist's expressions (``= art.r * 2``): references
    to the child's elements become the instance's (``= left.art.r * 2``), and names of the child's
    netlist parameters become ``PREFIX__NAME`` (the instance's copy of the parameter, which the
    including netlist carries; ``pi`` and the functions keep their meaning).  Returns (text, the
    parameter names used, the child's element ids read).  Text that does not parse is returned
    as it is: its error is reported where the expression is read."""
    body = text.lstrip()[1:]
    try:
        tree = ast.parse(body.strip(), mode="eval")
    except SyntaxError:
        return text, set(), set()
    used, read = set(), set()

    class Prefix(ast.NodeTransformer):
        def visit_Attribute(self, node):
            dotted = dotted_reference(node)
            if dotted is None:
                return self.generic_visit(node)
            if dotted[0] not in elements:
                return node
            read.add(dotted[0])
            new = ast.Name(id=prefix, ctx=ast.Load())
            for part in (*dotted[0].split("."), dotted[1]):
                new = ast.Attribute(value=new, attr=part, ctx=ast.Load())
            return ast.copy_location(new, node)

        def visit_Name(self, node):
            if node.id in constants and node.id not in _FUNCS and node.id != "pi":
                used.add(node.id)
                return ast.copy_location(ast.Name(id=f"{prefix}__{node.id}", ctx=ast.Load()), node)
            return node

    out = ast.fix_missing_locations(Prefix().visit(tree))
    return "= " + ast.unparse(out), used, read


class _Rename(ast.NodeTransformer):
    def __init__(self, key):
        self.key = key

    def visit_Attribute(self, node):
        dotted = dotted_reference(node)
        if dotted is not None:
            return ast.copy_location(ast.Name(id=self.key[".".join(dotted)], ctx=ast.Load()), node)
        return node

    def visit_Name(self, node):
        if node.id in self.key:
            return ast.copy_location(ast.Name(id=self.key[node.id], ctx=ast.Load()), node)
        return node


def constant_reference(name, raw, where) -> Reference:
    """A netlist-level parameter used in an expression: a constant, stored in SI."""
    def read():
        q = parse_with_unit(raw)
        base = q.to_base_units()
        return str(q.units), float(base.magnitude), str(base.units)

    try:
        key = raw if isinstance(raw, str) else None  # numbers are read by pint every time
        unit, si, base_unit = memo("constant_reference", key, read) if key is not None else read()
        ref = Reference(None, name, unit, "constant", si, base_unit)
    except Exception as exc:
        raise NetlistError(f"parameter {name}: {exc}", **where) from None
    return ref
