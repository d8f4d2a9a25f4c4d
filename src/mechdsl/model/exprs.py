"""Operations on IR expressions: traversal, canonical text, and translation to CasADi/sympy."""
from __future__ import annotations

import math
from dataclasses import field
from typing import Callable

from . import ir
from .records import record
from .ir import (
    BodyAlpha,
    BodyOmega,
    BodyRot,
    Const,
    Coord,
    EnergyRef,
    Expr,
    Op,
    Param,
    PointAcc,
    PointPos,
    PointVel,
    ReactionRef,
    Speed,
    Time,
    TimeDer,
    children,
    depends_on_state,
    walk,
)

UNARY_FUNCS = ("sin", "cos", "tan", "asin", "acos", "atan", "sinh", "cosh", "tanh", "exp",
               "log", "log10", "sqrt", "abs", "sign", "floor", "ceil")
BINARY_FUNCS = ("atan2", "min", "max")
MATH_FUNCS = UNARY_FUNCS + BINARY_FUNCS

# --------------------------------------------------------------------------- traversal
# (children, walk and depends_on_state live with the node classes in ir.py)


def leaves_of(e: Expr, kind) -> list:
    seen, out = set(), []
    for n in walk(e):
        if isinstance(n, kind) and n not in seen:
            seen.add(n)
            out.append(n)
    return out


def depends_on_time(e: Expr) -> bool:
    return any(isinstance(n, Time) for n in walk(e))


def has_speed(e: Expr) -> bool:
    return any(isinstance(n, (Speed, PointVel, BodyOmega, EnergyRef, ReactionRef, PointAcc, BodyAlpha))
               for n in walk(e))


def needs_dynamics(e: Expr) -> bool:
    """True when e needs the forward dynamics (reactions, accelerations): outputs only."""
    return any(isinstance(n, (ReactionRef, PointAcc, BodyAlpha)) for n in walk(e))


def substitute(e: Expr, fn: Callable[[Expr], Expr | None]) -> Expr:
    """Rebuild e bottom-up; fn(node) returns a replacement or None to keep the node."""
    r = fn(e)
    if r is not None:
        return r
    if isinstance(e, Op):
        return Op(e.op, tuple(substitute(a, fn) for a in e.args))
    if isinstance(e, TimeDer):
        return TimeDer(substitute(e.expr, fn))
    return e


# --------------------------------------------------------------------------- constructors (light folding)


def const(v: float) -> Const:
    return Const(float(v))


_TOTAL_OPS = frozenset({"add", "sub", "mul", "neg", "sin", "cos", "abs", "sign", "min", "max", "floor", "ceil"})


def _always_finite(e: Expr) -> bool:
    """True when e is finite wherever its leaves are (parameters, coordinates and time are):
    no division except by a nonzero constant, no function with poles or a restricted domain.
    Only such an e may vanish from 0*e; 0*(1/(r - r)) must stay an error."""
    if isinstance(e, Const):
        return math.isfinite(e.value)
    for n in walk(e):
        if isinstance(n, Const):
            if not math.isfinite(n.value):
                return False
        elif isinstance(n, Op):
            if n.op == "div":
                d = n.args[1]
                if not (isinstance(d, Const) and d.value != 0.0 and math.isfinite(d.value)):
                    return False
            elif n.op == "pow":
                k = n.args[1]
                if not (isinstance(k, Const) and k.value >= 0 and k.value == int(k.value)):
                    return False
            elif n.op not in _TOTAL_OPS:
                return False
    return True


def is_const(e: Expr, v: float | None = None) -> bool:
    return isinstance(e, Const) and (v is None or e.value == v)


def add(a: Expr, b: Expr) -> Expr:
    if is_const(a, 0.0):
        return b
    if is_const(b, 0.0):
        return a
    if isinstance(a, Const) and isinstance(b, Const):
        return Const(a.value + b.value)
    return Op("add", (a, b))


def sub(a: Expr, b: Expr) -> Expr:
    if is_const(b, 0.0):
        return a
    if is_const(a, 0.0):
        return neg(b)
    if isinstance(a, Const) and isinstance(b, Const):
        return Const(a.value - b.value)
    return Op("sub", (a, b))


def mul(a: Expr, b: Expr) -> Expr:
    # 0*x folds to 0 only for a finite constant x: x = 1/(r - r) must stay an error, not vanish
    if (is_const(a, 0.0) and _always_finite(b)) or (is_const(b, 0.0) and _always_finite(a)):
        return Const(0.0)
    if is_const(a, 1.0):
        return b
    if is_const(b, 1.0):
        return a
    if isinstance(a, Const) and isinstance(b, Const):
        return Const(a.value * b.value)
    return Op("mul", (a, b))


def div(a: Expr, b: Expr) -> Expr:
    if is_const(b, 1.0):
        return a
    if isinstance(a, Const) and isinstance(b, Const) and b.value != 0.0:
        return Const(a.value / b.value)
    return Op("div", (a, b))   # 0/b is 0 only for b != 0, which a symbolic b does not promise


def neg(a: Expr) -> Expr:
    if isinstance(a, Const):
        return Const(-a.value)
    if isinstance(a, Op) and a.op == "neg":
        return a.args[0]
    return Op("neg", (a,))


def power(a: Expr, b: Expr) -> Expr:
    if is_const(b, 1.0):
        return a
    if is_const(b, 0.0):
        return Const(1.0)
    return Op("pow", (a, b))


def func(name: str, *args: Expr) -> Expr:
    return Op(name, tuple(args))


def vsum(items) -> Expr:
    """Sum as a balanced tree (depth log n: long sums stay shallow)."""
    items = [i for i in items if not is_const(i, 0.0)]
    if not items:
        return Const(0.0)
    while len(items) > 1:
        items = [add(items[i], items[i + 1]) if i + 1 < len(items) else items[i] for i in range(0, len(items), 2)]
    return items[0]


# --------------------------------------------------------------------------- canonical text

_INFIX = {"add": ("+", 1), "sub": ("-", 1), "mul": ("*", 2), "div": ("/", 2), "pow": ("^", 4),
          "lt": ("<", 0), "le": ("<=", 0), "gt": (">", 0), "ge": (">=", 0), "eq": ("==", 0),
          "ne": ("<>", 0), "and": ("and", -1), "or": ("or", -2)}


def fmt_num(v: float) -> str:
    if math.isfinite(v) and v == int(v) and abs(v) < 1e15:
        return str(int(v))
    return repr(float(v))


def to_text(e: Expr) -> str:
    """Deterministic, readable text for an IR expression (used by --emit model)."""
    return _text(e)[0]


def _text(e: Expr) -> tuple[str, int]:
    if isinstance(e, Const):
        s = fmt_num(e.value)
        return (s, 5) if e.value >= 0 else (f"({s})", 5)
    if isinstance(e, Param):
        return e.name, 5
    if isinstance(e, Coord):
        return e.name, 5
    if isinstance(e, Speed):
        return f"der({e.name})", 5
    if isinstance(e, Time):
        return "time", 5
    if isinstance(e, TimeDer):
        return f"der({to_text(e.expr)})", 5
    if isinstance(e, PointPos):
        return f"{e.point}.r[{e.i + 1}]", 5
    if isinstance(e, PointVel):
        return f"{e.point}.v[{e.i + 1}]", 5
    if isinstance(e, BodyRot):
        return f"{e.body}.R[{e.i + 1},{e.j + 1}]", 5
    if isinstance(e, BodyOmega):
        return f"{e.body}.{'w' if e.frame == 'world' else 'w_body'}[{e.i + 1}]", 5
    if isinstance(e, PointAcc):
        return f"{e.point}.a[{e.i + 1}]", 5
    if isinstance(e, BodyAlpha):
        return f"{e.body}.alpha[{e.i + 1}]", 5
    if isinstance(e, EnergyRef):
        return f"{e.kind}_energy()" if e.kind in ("kinetic", "potential") else f"{e.kind}()", 5
    if isinstance(e, ReactionRef):
        return f"reaction_{e.what}({e.joint})[{e.i + 1}]", 5
    if isinstance(e, Op):
        if e.op in _INFIX:
            sym, prec = _INFIX[e.op]
            a, pa = _text(e.args[0])
            b, pb = _text(e.args[1])
            if pa < prec or (pa == prec and e.op == "pow"):
                a = f"({a})"
            if pb < prec or (pb == prec and e.op in ("sub", "div")):
                b = f"({b})"
            return f"{a} {sym} {b}" if prec < 4 else f"{a}{sym}{b}", prec
        if e.op == "neg":
            a, pa = _text(e.args[0])
            return (f"-{a}" if pa >= 2 else f"-({a})"), 3
        if e.op == "not":
            a, _ = _text(e.args[0])
            return f"not ({a})", 3
        if e.op == "if":
            c, t, f = (to_text(x) for x in e.args)
            return f"(if {c} then {t} else {f})", 5
        return f"{e.op}({', '.join(to_text(a) for a in e.args)})", 5
    raise TypeError(f"not an IR expression: {e!r}")


# --------------------------------------------------------------------------- numeric evaluation (params only)


def evaluate(e: Expr, values: dict[str, float], t: float = 0.0) -> float:
    """Evaluate an expression in Params (and Time) numerically."""
    import numpy as np

    def leaf(n):
        if isinstance(n, Const):
            return n.value
        if isinstance(n, Param):
            return values[n.name]
        if isinstance(n, Time):
            return t
        raise ValueError(f"{to_text(n)} is not known before simulation")

    return float(_translate(e, leaf, _NUMPY_OPS, np))


# --------------------------------------------------------------------------- translation


def _translate(e: Expr, leaf, ops, lib):
    """Post-order translation with memoization (shared subtrees translated once)."""
    memo: dict[int, object] = {}
    stack = [(e, False)]
    while stack:
        n, done = stack.pop()
        if id(n) in memo:
            continue
        if isinstance(n, Op):
            if not done:
                stack.append((n, True))
                stack.extend((a, False) for a in n.args if id(a) not in memo)
                continue
            args = [memo[id(a)] for a in n.args]
            memo[id(n)] = ops(n.op, args, lib)
        elif isinstance(n, TimeDer):
            memo[id(n)] = leaf(n)
        else:
            memo[id(n)] = leaf(n)
    return memo[id(e)]


def _common_op(op, a, lib, minf, maxf, iff, sign, floor, ceil):
    if op == "add":
        return a[0] + a[1]
    if op == "sub":
        return a[0] - a[1]
    if op == "mul":
        return a[0] * a[1]
    if op == "div":
        return a[0] / a[1]
    if op == "pow":
        return a[0] ** a[1]
    if op == "neg":
        return -a[0]
    if op == "min":
        return minf(a[0], a[1])
    if op == "max":
        return maxf(a[0], a[1])
    if op == "if":
        return iff(a[0], a[1], a[2])
    if op == "sign":
        return sign(a[0])
    if op == "floor":
        return floor(a[0])
    if op == "ceil":
        return ceil(a[0])
    return None


def _numpy_ops(op, a, np):
    r = _common_op(op, a, np, min, max, lambda c, x, y: x if c else y, np.sign, np.floor, np.ceil)
    if r is not None:
        return r
    logic = {"lt": lambda: a[0] < a[1], "le": lambda: a[0] <= a[1], "gt": lambda: a[0] > a[1],
             "ge": lambda: a[0] >= a[1], "eq": lambda: a[0] == a[1], "ne": lambda: a[0] != a[1],
             "and": lambda: bool(a[0]) and bool(a[1]), "or": lambda: bool(a[0]) or bool(a[1]),
             "not": lambda: not bool(a[0])}
    if op in logic:
        return 1.0 if logic[op]() else 0.0
    if op == "atan2":
        return np.arctan2(a[0], a[1])
    names = {"asin": "arcsin", "acos": "arccos", "atan": "arctan"}
    return getattr(np, names.get(op, op))(a[0])


_NUMPY_OPS = _numpy_ops


def _casadi_ops(op, a, ca):
    r = _common_op(op, a, ca, ca.fmin, ca.fmax, ca.if_else, ca.sign, ca.floor, ca.ceil)
    if r is not None:
        return r
    logic = {"lt": ca.lt, "le": ca.le, "gt": ca.gt, "ge": ca.ge, "eq": ca.eq, "ne": ca.ne,
             "and": ca.logic_and, "or": ca.logic_or}
    if op in logic:
        return logic[op](a[0], a[1])
    if op == "not":
        return ca.logic_not(a[0])
    if op == "atan2":
        return ca.atan2(a[0], a[1])
    if op == "abs":
        return ca.fabs(a[0])
    if op == "log10":
        return ca.log10(a[0])
    return getattr(ca, op)(a[0])


@record(frozen=False)
class CasadiEnv:
    """Symbols for translating IR expressions to CasADi SX.

    q, qd: SX column vectors in coordinate order; t: SX scalar; p: SX vector in
    ``model.real_parameters`` order.  ``query`` resolves kinematic leaves (PointPos, ...,
    EnergyRef, ReactionRef) to SX; it is supplied by ``derive``.
    """

    coords: tuple[str, ...]
    params: tuple[str, ...]
    q: object
    qd: object
    t: object
    p: object
    query: Callable[[Expr], object] | None = None
    inputs: tuple[str, ...] = ()        # control inputs: their Param leaves translate to u
    u: object = None
    _ci: dict = field(default_factory=dict)
    _pi: dict = field(default_factory=dict)
    _ui: dict = field(default_factory=dict)

    def __post_init__(self):
        self._ci = {n: i for i, n in enumerate(self.coords)}
        self._pi = {n: i for i, n in enumerate(self.params)}
        self._ui = {n: i for i, n in enumerate(self.inputs)}

    @staticmethod
    def symbols(coords, params, query=None, inputs=()) -> "CasadiEnv":
        import casadi as ca

        return CasadiEnv(tuple(coords), tuple(params), ca.SX.sym("q", len(coords)),
                         ca.SX.sym("qd", len(coords)), ca.SX.sym("t"), ca.SX.sym("p", len(params)),
                         query, tuple(inputs), ca.SX.sym("u", len(inputs)))

    def leaf(self, n: Expr):
        if isinstance(n, Const):
            return n.value
        if isinstance(n, Param):
            i = self._ui.get(n.name)
            return self.p[self._pi[n.name]] if i is None else self.u[i]
        if isinstance(n, Coord):
            return self.q[self._ci[n.name]]
        if isinstance(n, Speed):
            return self.qd[self._ci[n.name]]
        if isinstance(n, Time):
            return self.t
        if isinstance(n, TimeDer):
            import casadi as ca

            inner = self.translate(n.expr)
            return ca.jtimes(inner, self.q, self.qd) + ca.jacobian(inner, self.t)
        if self.query is not None:
            return self.query(n)
        raise ValueError(f"cannot translate {to_text(n)} here")

    def translate(self, e: Expr):
        import casadi as ca

        return _translate(e, self.leaf, _casadi_ops, ca)


def to_casadi(e: Expr, env: CasadiEnv):
    return env.translate(e)


def _sympy_ops(op, a, sp):
    r = _common_op(op, a, sp, sp.Min, sp.Max, lambda c, x, y: sp.Piecewise((x, c), (y, True)),
                   sp.sign, sp.floor, sp.ceiling)
    if r is not None:
        return r
    logic = {"lt": sp.Lt, "le": sp.Le, "gt": sp.Gt, "ge": sp.Ge, "eq": sp.Eq, "ne": sp.Ne,
             "and": sp.And, "or": sp.Or}
    if op in logic:
        return logic[op](a[0], a[1])
    if op == "not":
        return sp.Not(a[0])
    if op == "log10":
        return sp.log(a[0], 10)
    if op == "abs":
        return sp.Abs(a[0])
    return getattr(sp, op)(*a)


def to_sympy(e: Expr, leaf: Callable[[Expr], object]):
    """Translate to sympy; ``leaf`` maps Param/Coord/Speed/Time/... nodes to sympy objects."""
    import sympy as sp

    def lf(n):
        if isinstance(n, Const):
            v = n.value
            if v == int(v) and abs(v) < 1e15:
                return sp.Integer(int(v))
            from fractions import Fraction

            r = Fraction(v).limit_denominator(1000)   # 0.5 -> 1/2 when it is exactly that float
            return sp.Rational(r.numerator, r.denominator) if float(r) == v else sp.Float(v)
        return leaf(n)

    return _translate(e, lf, _sympy_ops, sp)


__all__ = ["walk", "children", "substitute", "to_text", "to_casadi", "to_sympy", "CasadiEnv",
           "evaluate", "depends_on_state", "depends_on_time", "has_speed", "leaves_of",
           "add", "sub", "mul", "div", "neg", "power", "func", "vsum", "const", "ir"]
