"""One reader of the numbers a person types: ``number("2*pi/3")`` and ``assignments(["m=2,L=0.5"])``.

Python's ``ast`` restricted to arithmetic, evaluated in floating point (so that ``9^9^9``
overflows instead of building a huge integer); values finite, at most 200 characters.  Used
by every command's ``--set``/``--guess``/``--at`` (commands/_common.py) and by the sweeps'
value tables (sweep/spec.py).
"""
from __future__ import annotations

import ast
import math
import operator
import re

from .diagnostics import UsageError

MAX_VALUE_TEXT = 200          # characters in one value: enough for any expression a person types

_OPS = {ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul, ast.Div: operator.truediv,
        ast.Pow: operator.pow, ast.USub: operator.neg, ast.UAdd: operator.pos}
_NAMES = {"pi": math.pi, "e": math.e}
_FUNCS = {"sin": math.sin, "cos": math.cos, "tan": math.tan, "asin": math.asin, "acos": math.acos,
          "atan": math.atan, "sqrt": math.sqrt, "exp": math.exp, "log": math.log, "abs": abs,
          "deg": math.radians}
_TOP_COMMA = re.compile(r",(?![^(]*\))")        # commas outside parentheses


def number(text: str, what: str = "value") -> float:
    """A finite number from the command line: 1.5, 2e-3, -pi/2, 2*pi/3, sqrt(2), deg(30), 2^3."""
    s = str(text).strip()
    hint = "(numbers, pi, e, + - * / ^, sqrt, sin, cos, tan, asin, acos, atan, exp, log, abs, deg)"
    if len(s) > MAX_VALUE_TEXT:
        raise UsageError(f"{what}: a value of {len(s)} characters is too long (at most {MAX_VALUE_TEXT})")
    try:
        v = float(_ev(ast.parse(s.replace("^", "**"), mode="eval").body))
    except OverflowError:
        raise UsageError(f"{what}: {s!r} is out of the floating-point range (|x| < 1.8e308)") from None
    except (SyntaxError, ValueError, TypeError, ZeroDivisionError, KeyError, RecursionError, MemoryError):
        raise UsageError(f"{what}: cannot read {s!r} as a number {hint}") from None
    if not math.isfinite(v):
        raise UsageError(f"{what}: {s!r} is not a finite number")
    return v


def _ev(n) -> float:
    """Floating-point evaluation of a tiny arithmetic tree (ints become floats first, so a power
    overflows instead of building a huge integer)."""
    if isinstance(n, ast.Constant) and isinstance(n.value, (int, float)) and not isinstance(n.value, bool):
        return float(n.value)
    if isinstance(n, ast.BinOp) and type(n.op) in _OPS:
        a, b = _ev(n.left), _ev(n.right)
        v = _OPS[type(n.op)](a, b)
        if isinstance(v, complex):
            raise ValueError("complex result")
        return v
    if isinstance(n, ast.UnaryOp) and type(n.op) in _OPS:
        return _OPS[type(n.op)](_ev(n.operand))
    if isinstance(n, ast.Name):
        return _NAMES[n.id]
    if (isinstance(n, ast.Call) and isinstance(n.func, ast.Name) and n.func.id in _FUNCS and len(n.args) == 1
            and not n.keywords):
        return float(_FUNCS[n.func.id](_ev(n.args[0])))
    raise ValueError("not an arithmetic expression")


def assignments(items, option: str = "--set") -> dict[str, float]:
    """``NAME=VALUE`` items (several per item, comma-separated) -> {name: value}, in order."""
    out: dict[str, float] = {}
    for item in items or []:
        for part in item if isinstance(item, (list, tuple)) else [item]:
            for piece in [s for s in _TOP_COMMA.split(str(part)) if s.strip()]:
                if "=" not in piece:
                    raise UsageError(f"{option} expects NAME=VALUE, got {piece.strip()!r}")
                name, text = (s.strip() for s in piece.split("=", 1))
                if not name:
                    raise UsageError(f"{option} expects NAME=VALUE, got {piece.strip()!r}")
                out[name] = number(text, what=f"{option} {name}")
    return out
