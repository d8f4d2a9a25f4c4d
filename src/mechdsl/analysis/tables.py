"""Plain-text tables for the analysis commands (mech equilibrium, mech linearize)."""
from __future__ import annotations

import ast
import math
import operator

import numpy as np

from ..diagnostics import UsageError


def num(v: float, width: int = 0) -> str:
    if isinstance(v, complex) or np.iscomplexobj(v):
        v = complex(v)
        if abs(v.imag) <= 1e-12 * max(1.0, abs(v)):
            return num(v.real, width)
        s = f"{v.real:.6g}{v.imag:+.6g}i"
    else:
        v = float(v)
        s = "0" if v == 0 else f"{v:.6g}"
    return s.rjust(width) if width else s


def table(headers: list[str], rows: list[list[str]], indent: str = "  ") -> str:
    w = [len(h) for h in headers]
    for r in rows:
        for i, c in enumerate(r):
            w[i] = max(w[i], len(c))
    lines = [indent + "  ".join(h.ljust(w[i]) for i, h in enumerate(headers)).rstrip()]
    for r in rows:
        lines.append(indent + "  ".join(c.ljust(w[i]) for i, c in enumerate(r)).rstrip())
    return "\n".join(lines)


def matrix(name: str, A: np.ndarray, rows, cols, indent: str = "  ") -> str:
    A = np.asarray(A)
    if A.size == 0:
        return f"{indent}{name} = [] (empty)"
    body = [[str(r)] + [num(v) for v in A[i]] for i, r in enumerate(rows)]
    return f"{indent}{name}:\n" + table([""] + [str(c) for c in cols], body, indent + "  ")


_OPS = {ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul, ast.Div: operator.truediv,
        ast.Pow: operator.pow, ast.USub: operator.neg, ast.UAdd: operator.pos}
_NAMES = {"pi": math.pi, "e": math.e}
_FUNCS = {"sqrt": math.sqrt, "sin": math.sin, "cos": math.cos, "tan": math.tan, "acos": math.acos,
          "asin": math.asin, "atan": math.atan, "deg": math.radians}


def number(text: str) -> float:
    """A number from the command line: 1.5, -pi/2, 2*pi/3, sqrt(2), 30*pi/180, deg(30)."""
    try:
        tree = ast.parse(text.strip().replace("^", "**"), mode="eval")
        v = float(_eval(tree.body))
    except (SyntaxError, ValueError, TypeError, ZeroDivisionError, KeyError, OverflowError):
        raise UsageError(f"not a number: {text!r} (numbers, pi, + - * / ^, sqrt, sin, cos, deg)") from None
    if not math.isfinite(v):
        raise UsageError(f"not a finite number: {text!r}")
    return v


def _eval(node):
    if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)) and not isinstance(node.value, bool):
        return node.value
    if isinstance(node, ast.BinOp) and type(node.op) in _OPS:
        return _OPS[type(node.op)](_eval(node.left), _eval(node.right))
    if isinstance(node, ast.UnaryOp) and type(node.op) in _OPS:
        return _OPS[type(node.op)](_eval(node.operand))
    if isinstance(node, ast.Name) and node.id in _NAMES:
        return _NAMES[node.id]
    if (isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in _FUNCS
            and len(node.args) == 1 and not node.keywords):
        return _FUNCS[node.func.id](_eval(node.args[0]))
    raise ValueError("unsupported")


def assignments(items: list[str] | None) -> dict[str, float]:
    """NAME=VALUE items (also comma-separated inside one item) -> {name: value}."""
    out: dict[str, float] = {}
    flat: list[str] = []
    for item in items or []:
        flat.extend(item if isinstance(item, (list, tuple)) else [item])
    for item in flat:
        for part in [s for s in item.split(",") if s.strip()]:
            if "=" not in part:
                raise UsageError(f"expected NAME=VALUE, got {part!r}")
            k, v = part.split("=", 1)
            k = k.strip()
            if not k:
                raise UsageError(f"expected NAME=VALUE, got {part!r}")
            out[k] = number(v)
    return out


def load_model(args):
    """mechdsl.load with --model/--scene/--no-units and --set NAME=VALUE applied."""
    from ..api import load

    m = load(args.file, model=args.model, scene=args.scene, units=not getattr(args, "no_units", False))
    values = assignments(getattr(args, "set", None))
    return m.with_params(**values) if values else m
