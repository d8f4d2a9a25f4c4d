"""AST -> canonical .mech text.  ``parse(to_source(parse(x))) == parse(x)`` for every model."""
from __future__ import annotations

import math

from . import ast

INDENT = "  "

# precedence: higher binds tighter
_PREC = {"or": 1, "and": 2, "not": 3, "<": 4, "<=": 4, ">": 4, ">=": 4, "==": 4, "<>": 4,
         "+": 5, "-": 5, "*": 6, "/": 6, "unary": 7, "^": 8}
_PRIMARY = 9


def to_source(node: ast.Node) -> str:
    if isinstance(node, ast.File):
        return "\n".join(_unit(u) for u in node.items)
    if isinstance(node, (ast.ModelDef, ast.SceneDef)):
        return _unit(node)
    if isinstance(node, ast.Expr):
        return expr(node)
    raise TypeError(f"cannot print {type(node).__name__}")


def _unit(u) -> str:
    lines = [header(u)]
    if isinstance(u, ast.ModelDef):
        lines += [INDENT + element(e) for e in u.elements]
        if u.equations:
            lines.append("equation")
            for eq in u.equations:
                lines += equation(eq, 1)
    else:
        lines += [INDENT + scene_item(it) for it in u.items]
    lines.append(f"end {u.name};")
    return "\n".join(lines) + "\n"


def header(u) -> str:
    """The first line of a model or scene: ``model Name "doc"``."""
    kind = "model" if isinstance(u, ast.ModelDef) else "scene"
    return f"{kind} {u.name}{_doc(u.doc)}"


def scene_item(it) -> str:
    if isinstance(it, ast.SceneModel):
        return f"model {it.name}{_mods(it.modification)};"
    return f"{it.name} = {expr(it.value)};"


def _doc(doc: str | None) -> str:
    return "" if doc is None else " " + string(doc)


def string(s: str) -> str:
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n").replace("\t", "\\t") + '"'


def element(e) -> str:
    if isinstance(e, ast.Extends):
        return f"extends {e.name}{_mods(e.modification)};"
    parts = []
    if e.prefix:
        parts.append(e.prefix + " ")
    parts.append(f"{e.type_name} {e.name}")
    if e.dims:
        parts.append("[" + ", ".join(expr(d) for d in e.dims) + "]")
    parts.append(_mods(e.modification))
    if e.value is not None:
        parts.append(f" = {expr(e.value)}")
    parts.append(_doc(e.doc))
    return "".join(parts) + ";"


def _mods(mods) -> str:
    if mods is None:
        return ""
    return "(" + ", ".join(modifier(m) for m in mods) + ")"


def modifier(m: ast.Modifier) -> str:
    s = ("each " if m.each else "") + m.name + _mods(m.modification)
    if m.value is not None:
        s += f" = {expr(m.value)}"
    return s


def equation(eq, depth: int) -> list[str]:
    ind = INDENT * depth
    if isinstance(eq, ast.SimpleEquation):
        return [f"{ind}{expr(eq.lhs)} = {expr(eq.rhs)}{_doc(eq.doc)};"]
    if isinstance(eq, ast.EnergyEquation):
        return [f"{ind}{eq.kind} = {expr(eq.expr)}{_doc(eq.doc)};"]
    if isinstance(eq, ast.ForceEquation):
        return [f"{ind}force({expr(eq.coordinate)}) = {expr(eq.expr)}{_doc(eq.doc)};"]
    if isinstance(eq, ast.Connect):
        return [f"{ind}connect({expr(eq.a)}, {expr(eq.element)}, {expr(eq.b)}){_doc(eq.doc)};"]
    if isinstance(eq, ast.ForEquation):
        out = [ind + for_header(eq)]
        for b in eq.body:
            out += equation(b, depth + 1)
        out.append(f"{ind}end for;")
        return out
    raise TypeError(type(eq).__name__)


def for_header(eq: ast.ForEquation) -> str:
    return f"for {eq.var} in {_range(eq.range)} loop"


def _range(r: ast.Range) -> str:
    if r.step is None:
        return f"{expr(r.start)}:{expr(r.stop)}"
    return f"{expr(r.start)}:{expr(r.step)}:{expr(r.stop)}"


def number(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if math.isinf(v):
        return "1e999"
    r = repr(float(v))        # the shortest text that reads back as the same float
    if "e" in r:              # 1e-09 -> 1e-9
        mantissa, exponent = r.split("e")
        r = f"{mantissa}e{int(exponent)}"
    return r


def expr(e: ast.Expr) -> str:
    return _expr(e)[0]


def _wrap(s: str, p: int, need: int) -> str:
    return f"({s})" if p < need else s


def _expr(e) -> tuple[str, int]:
    """Text and precedence of e, iteratively safe for long left-nested chains."""
    if isinstance(e, ast.BinOp) and isinstance(e.left, ast.BinOp) and e.left.op == e.op and e.op in "+-*/":
        # flatten a left-nested chain of one operator without deep recursion
        chain = []
        node = e
        while isinstance(node, ast.BinOp) and node.op == e.op:
            chain.append(node.right)
            node = node.left
        p = _PREC[e.op]
        text = _wrap(*_expr(node), p)
        for right in reversed(chain):
            rs, rp = _expr(right)
            text += _sep(e.op) + _wrap(rs, rp, p + 1)
        return text, p
    if isinstance(e, ast.Number):
        return number(e.value), _PRIMARY
    if isinstance(e, ast.String):
        return string(e.value), _PRIMARY
    if isinstance(e, ast.Bool):
        return ("true" if e.value else "false"), _PRIMARY
    if isinstance(e, ast.Ref):
        return ref(e), _PRIMARY
    if isinstance(e, ast.Call):
        return f"{ref(e.func)}({', '.join(expr(a) for a in e.args)})", _PRIMARY
    if isinstance(e, ast.Array):
        return "{" + ", ".join(expr(a) for a in e.items) + "}", _PRIMARY
    if isinstance(e, ast.Comprehension):
        return "{" + f"{expr(e.expr)} for {e.var} in {_range(e.range)}" + "}", _PRIMARY
    if isinstance(e, ast.IfExpr):
        s = " elseif ".join(f"{expr(c)} then {expr(v)}" for c, v in e.branches)
        return f"if {s} else {expr(e.otherwise)}", 0
    if isinstance(e, ast.UnaryOp):
        if e.op == "not":
            s, p = _expr(e.operand)
            return "not " + _wrap(s, p, _PREC["not"]), _PREC["not"]
        s, p = _expr(e.operand)
        return e.op + _wrap(s, p, _PREC["unary"]), _PREC["unary"]
    if isinstance(e, ast.BinOp):
        p = _PREC[e.op]
        ls, lp = _expr(e.left)
        rs, rp = _expr(e.right)
        if e.op == "^":
            return _wrap(ls, lp, _PRIMARY) + "^" + _wrap(rs, rp, _PREC["unary"]), p
        if p == 4:  # comparisons are not associative
            return f"{_wrap(ls, lp, p + 1)} {e.op} {_wrap(rs, rp, p + 1)}", p
        return _wrap(ls, lp, p) + _sep(e.op) + _wrap(rs, rp, p + 1), p
    raise TypeError(f"cannot print {type(e).__name__}")


def _sep(op: str) -> str:
    return {"*": "*", "/": "/", "^": "^"}.get(op, f" {op} ")


def ref(r: ast.Ref) -> str:
    out = []
    for part in r.parts:
        s = part.name
        if part.subscripts:
            s += "[" + ", ".join(expr(x) for x in part.subscripts) + "]"
        out.append(s)
    return ".".join(out)
