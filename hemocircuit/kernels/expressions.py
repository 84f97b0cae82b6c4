"""Parameter expressions (hemocircuit.expressions) as bytecode for a compiled stack machine.

``encode(expr, slot) -> (code, consts)`` compiles an :class:`~hemocircuit.expressions.Expression`;
``eval_expr(code, c0, consts, k0, P, O)`` runs the program that starts at ``code[c0]`` with its
constants starting at ``consts[k0]`` (so many programs can be concatenated, see ``concat``) and
returns the value in the target parameter's unit, equal to ``Expression.evaluate``.

``slot(ref) -> (kind, index)`` maps every non-constant :class:`~hemocircuit.expressions.Reference`
of ``expr.refs`` to ``('param', i)`` (the value is ``P[i]``, in the reference's declared unit) or
``('obs', i)`` (``O[i]``).  Netlist constants are folded in, as is every sub-expression made of
constants only (computed in Python with the same operations ``evaluate`` performs).

Program (int64 ``code``; operands follow their opcode; constant operands are indices relative
to ``k0``):

    CONST k       push consts[k0+k]
    PARAM i k     push P[i] * consts[k0+k]     (consts[k0+k]: the reference's SI factor)
    OBS i k       push O[i] * consts[k0+k]
    ADD SUB MUL DIV POW   pop b, pop a, push a (op) b
    NEG           negate the top
    EXP LOG SQRT  apply to the top
    END           return the top

Every program ends with ``CONST out_factor, MUL, END`` (the conversion from SI to the target
unit, as ``evaluate`` does last), or with ``CONST value, END`` when it is constant altogether.
The machine's stack holds ``MAX_STACK`` numbers; ``encode`` rejects deeper expressions.
"""
from __future__ import annotations

import ast

import numba
import numpy as np

from ..expressions import dotted_reference

OP_END, OP_CONST, OP_PARAM, OP_OBS = 0, 1, 2, 3
OP_ADD, OP_SUB, OP_MUL, OP_DIV, OP_POW = 4, 5, 6, 7, 8
OP_NEG, OP_EXP, OP_LOG, OP_SQRT = 9, 10, 11, 12
#: stack size of ``eval_expr`` (the deepest expression ``encode`` accepts)
MAX_STACK = 32

_BINOPS = {ast.Add: OP_ADD, ast.Sub: OP_SUB, ast.Mult: OP_MUL, ast.Div: OP_DIV, ast.Pow: OP_POW}
_PYBIN = {OP_ADD: lambda a, b: a + b, OP_SUB: lambda a, b: a - b, OP_MUL: lambda a, b: a * b,
          OP_DIV: lambda a, b: a / b, OP_POW: lambda a, b: a ** b}
_FUNCS = {"exp": OP_EXP, "log": OP_LOG, "sqrt": OP_SQRT}
_PYFUN = {OP_EXP: np.exp, OP_LOG: np.log, OP_SQRT: np.sqrt}
_KINDS = {"param": OP_PARAM, "obs": OP_OBS, "observable": OP_OBS}


class ExpressionTooDeep(ValueError):
    """The expression needs more stack than ``MAX_STACK``."""


# --- compile: AST -> (folded) tree -> postfix --------------------------------------------------
# Tree nodes: ('const', value) | ('load', opcode, index, si_factor) | ('bin', op, a, b)
#             | ('un', op, a)      (op: OP_NEG or a function)

def _tree(node, expr, slot, loads):
    if isinstance(node, ast.Expression):
        return _tree(node.body, expr, slot, loads)
    if isinstance(node, ast.Constant):
        v = node.value
        if type(v) is int:  # as Expression: integer literals become floats
            v = float(v)
        if isinstance(v, (str, bytes, complex)) or v is None or v is Ellipsis:
            raise ValueError(f"expression {expr.text!r}: constant {v!r} is not a real number")
        return ("const", v)
    if isinstance(node, ast.BinOp):
        op = _BINOPS.get(type(node.op))
        if op is None:
            raise ValueError(f"expression {expr.text!r}: operator {type(node.op).__name__} not supported")
        return _fold(("bin", op, _tree(node.left, expr, slot, loads), _tree(node.right, expr, slot, loads)))
    if isinstance(node, ast.UnaryOp):
        a = _tree(node.operand, expr, slot, loads)
        if isinstance(node.op, ast.UAdd):
            return _fold(("un", "pos", a))
        if isinstance(node.op, ast.USub):
            return _fold(("un", OP_NEG, a))
        raise ValueError(f"expression {expr.text!r}: operator {type(node.op).__name__} not supported")
    if isinstance(node, ast.Call):
        if not (isinstance(node.func, ast.Name) and node.func.id in _FUNCS) or len(node.args) != 1 or node.keywords:
            raise ValueError(f"expression {expr.text!r}: only exp(x), log(x), sqrt(x) may be called")
        return _fold(("un", _FUNCS[node.func.id], _tree(node.args[0], expr, slot, loads)))
    if dotted_reference(node) is not None:  # ELEMENT.NAME (a dotted instance element too)
        return _ref(".".join(dotted_reference(node)), expr, slot, loads)
    if isinstance(node, ast.Name):
        if node.id == "pi":
            return ("const", np.pi)
        if node.id in _FUNCS:
            raise ValueError(f"expression {expr.text!r}: {node.id} is a function (call it: {node.id}(x))")
        return _ref(node.id, expr, slot, loads)
    raise ValueError(f"expression {expr.text!r}: {type(node).__name__} not supported")


def _ref(key, expr, slot, loads):
    ref = expr.refs[key]
    if ref.kind == "constant":
        return ("const", ref.constant)
    if key not in loads:
        kind, index = slot(ref)
        if kind not in _KINDS:
            raise ValueError(f"slot({key}) gave kind {kind!r}; expected 'param' or 'obs'")
        loads[key] = ("load", _KINDS[kind], int(index), float(expr.si_factor(key)))
    return loads[key]


def _fold(node):
    """Compute a node whose operands are all constants, with the Python operations
    Expression.evaluate would apply (same types, same results); left as is when that raises
    (division by zero, overflow) or leaves the reals -- the machine then gives inf/NaN."""
    if node[0] == "bin" and node[2][0] == "const" and node[3][0] == "const":
        f = lambda: _PYBIN[node[1]](node[2][1], node[3][1])  # noqa: E731
    elif node[0] == "un" and node[2][0] == "const":
        a = node[2][1]
        f = (lambda: +a) if node[1] == "pos" else (lambda: -a) if node[1] == OP_NEG else (lambda: _PYFUN[node[1]](a))
    elif node[0] == "un" and node[1] == "pos":
        return node[2]  # +x is x
    else:
        return node
    try:
        with np.errstate(all="ignore"):
            v = f()
    except (ArithmeticError, ValueError, TypeError):
        return node
    if isinstance(v, complex) or not np.isrealobj(v):
        return node
    return ("const", v)


def _depth(node):
    if node[0] in ("const", "load"):
        return 1
    if node[0] == "un":
        return _depth(node[2])
    return max(_depth(node[2]), 1 + _depth(node[3]))


def _emit(node, code, consts):
    kind = node[0]
    if kind == "const":
        code += [OP_CONST, len(consts)]
        consts.append(float(node[1]))
    elif kind == "load":
        code += [node[1], node[2], len(consts)]
        consts.append(node[3])
    elif kind == "un":
        _emit(node[2], code, consts)
        if node[1] != "pos":
            code.append(node[1])
    else:
        _emit(node[2], code, consts)
        _emit(node[3], code, consts)
        code.append(node[1])


def encode(expr, slot) -> tuple[np.ndarray, np.ndarray]:
    """(code int64, consts float64): the program of ``expr`` (see the module docstring)."""
    tree = ast.parse(expr.text, mode="eval")
    body = _tree(tree, expr, slot, {})
    body = _fold(("bin", OP_MUL, body, ("const", expr.out_factor)))
    depth = _depth(body)
    if depth > MAX_STACK:
        raise ExpressionTooDeep(f"expression {expr.text!r} needs a stack of {depth} numbers; the compiled "
                                f"evaluator holds {MAX_STACK} (split it, or use fewer nested parentheses)")
    code: list[int] = []
    consts: list[float] = []
    _emit(body, code, consts)
    code.append(OP_END)
    return np.asarray(code, dtype=np.int64), np.asarray(consts, dtype=np.float64)


def concat(programs) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(code, consts, c0, k0): several (code, consts) programs joined, with each one's offsets."""
    programs = list(programs)
    c0 = np.cumsum([0] + [len(c) for c, _ in programs[:-1]]).astype(np.int64) if programs else np.zeros(0, np.int64)
    k0 = np.cumsum([0] + [len(k) for _, k in programs[:-1]]).astype(np.int64) if programs else np.zeros(0, np.int64)
    code = np.concatenate([np.asarray(c, np.int64) for c, _ in programs]) if programs else np.zeros(0, np.int64)
    consts = np.concatenate([np.asarray(k, np.float64) for _, k in programs]) if programs else np.zeros(0)
    return code, consts, c0, k0


@numba.njit(cache=True, nogil=True, error_model="numpy")
def eval_expr(code, c0, consts, k0, P, O):
    """Value of the program at ``code[c0:]`` (constants at ``consts[k0:]``), parameters ``P``,
    observables ``O``."""
    return eval_expr_with(code, c0, consts, k0, P, O, np.empty(MAX_STACK))


@numba.njit(cache=True, nogil=True, error_model="numpy")
def eval_expr_with(code, c0, consts, k0, P, O, stack):
    """eval_expr with a caller-owned (MAX_STACK,) scratch stack: the engine runs without numba's
    runtime (no allocation, no reference counting) in its hot loop."""
    sp = 0
    pc = c0
    while True:
        op = code[pc]
        if op == OP_CONST:
            stack[sp] = consts[k0 + code[pc + 1]]
            sp += 1
            pc += 2
        elif op == OP_PARAM:
            stack[sp] = P[code[pc + 1]] * consts[k0 + code[pc + 2]]
            sp += 1
            pc += 3
        elif op == OP_OBS:
            stack[sp] = O[code[pc + 1]] * consts[k0 + code[pc + 2]]
            sp += 1
            pc += 3
        elif op == OP_END:
            return stack[sp - 1]
        elif op >= OP_NEG:
            a = stack[sp - 1]
            if op == OP_NEG:
                a = -a
            elif op == OP_EXP:
                a = np.exp(a)
            elif op == OP_LOG:
                a = np.log(a)
            else:
                a = np.sqrt(a)
            stack[sp - 1] = a
            pc += 1
        else:
            b = stack[sp - 1]
            a = stack[sp - 2]
            if op == OP_ADD:
                a = a + b
            elif op == OP_SUB:
                a = a - b
            elif op == OP_MUL:
                a = a * b
            elif op == OP_DIV:
                a = a / b
            else:
                a = a ** b
            sp -= 1
            stack[sp - 1] = a
            pc += 1
