"""Values of the analyzer: scalars (an IR expression with its dimension), arrays, strings and
references to components.  Arithmetic here checks shapes (E3xx) and units (E4xx).

Dimension markers: a :class:`~mechdsl.model.units.Dim`, ``None`` (unknown: a quantity declared
without a unit) or ``ANY`` (a literal number: dimensionless factor in products, wildcard in
sums).  Unknown dimensions never cause an error; two known, different ones do.
"""
from __future__ import annotations

import math

import contextvars
from fractions import Fraction

from ..model import exprs as X
from ..model import ir
from ..model import units as U
from ..model.records import record


class _Any:
    def __repr__(self) -> str:
        return "ANY"


ANY = _Any()




class ValError(Exception):
    """Raised by value operations; the evaluator attaches the span."""

    def __init__(self, code: str, message: str, help: str | None = None):
        super().__init__(message)
        self.code, self.message, self.help = code, message, help


class Val:
    pass


@record
class Scalar(Val):
    expr: ir.Expr
    dim: object = None           # Dim | None | ANY
    integer: bool = False        # a structural integer constant (loop variable, Integer parameter)
    boolean: bool = False
    approx: bool = False         # dimension inferred assuming a decimal literal (0.1, 9.81) is unitless

    @property
    def const(self) -> float | None:
        return self.expr.value if isinstance(self.expr, ir.Const) else None


@record
class Arr(Val):
    items: tuple[Val, ...]

    @property
    def shape(self) -> tuple[int, ...]:
        return shape_of(self)


@record
class Str(Val):
    value: str


@record
class CompRef(Val):
    """A reference to a component or a part of one.

    kind: 'body' | 'point' | 'joint' | 'force' | 'frame' | 'contact' | 'other'
    name: flat name (for bodies also the name of their origin point).
    """

    kind: str
    name: str
    type_name: str = ""


def const(v: float, integer: bool = False, approx: bool = False) -> Scalar:
    return Scalar(ir.Const(float(v)), ANY, integer=integer, approx=approx)


# Unit checking can be switched off (UNITS), and a dimension problem found in an expression
# whose dimension rests on a decimal literal being unitless is a warning, not an error: it is
# collected in WARNINGS (code, message, help) by whoever set the sink.
UNITS: contextvars.ContextVar[bool] = contextvars.ContextVar("mechdsl_units", default=True)
WARNINGS: contextvars.ContextVar[list | None] = contextvars.ContextVar("mechdsl_unit_warnings", default=None)


def _problem(code: str, message: str, help: str | None, approx: bool) -> None:
    if not UNITS.get():
        return
    if approx:
        sink = WARNINGS.get()
        if sink is not None:
            sink.append(("W" + code[1:], message, (help or "") + " (a number in this expression may carry a unit:"
                                                   " name it as a parameter with a unit)"))
        return
    raise ValError(code, message, help)


def shape_of(v: Val) -> tuple[int, ...]:
    if isinstance(v, Arr):
        if not v.items:
            return (0,)
        inner = shape_of(v.items[0])
        for it in v.items[1:]:
            if shape_of(it) != inner:
                raise ValError("E301", "array rows have different shapes", "make every row the same length")
        return (len(v.items),) + inner
    return ()


def describe_shape(v: Val) -> str:
    if isinstance(v, Str):
        return "a string"
    if isinstance(v, CompRef):
        return f"a {v.kind} reference"
    s = shape_of(v)
    if s == ():
        return "a scalar"
    if len(s) == 1:
        return f"a vector of {s[0]}"
    return "a " + "x".join(str(n) for n in s) + " matrix"


def dim_text(d) -> str:
    if d is None or d is ANY:
        return "unknown"
    return str(d)


# ----------------------------------------------------------------------------- dimensions


def zdim(s: Scalar):
    """The dimension of ``s`` for sums and products: an exact zero (literal 0, the zeros of
    zeros()/diagonal()/skew(), a product with one of them) takes any unit."""
    return ANY if s.const == 0.0 else s.dim


def dim_join(a, b, what: str, approx: bool = False):
    """Dimension of a sum/comparison; error when both known and different."""
    if a is ANY or a is None:
        return b if a is ANY else (b if b not in (ANY,) else None)
    if b is ANY or b is None:
        return a
    if a != b:
        _problem("E401", f"incompatible units in {what}: {a} and {b}",
                 "both sides of +, -, comparisons and if-branches must have the same unit", approx)
        return None
    return a


def dim_mul(a, b):
    if a is ANY:
        return b
    if b is ANY:
        return a
    if a is None or b is None:
        return None
    return a * b


def dim_div(a, b):
    if b is ANY:
        return a
    if a is ANY:
        return None if b is None else U.ONE / b
    if a is None or b is None:
        return None
    return a / b


def require_dimensionless(d, what: str, approx: bool = False) -> None:
    if isinstance(d, U.Dim) and not d.dimensionless:
        _problem("E403", f"{what} must be dimensionless, got {d}",
                 "divide by a reference quantity, e.g. sin(x/L) or sin(w*time)", approx)


def check_dim(d, expected: U.Dim, what: str, approx: bool = False) -> None:
    if isinstance(d, U.Dim) and d != expected:
        _problem("E402", f"{what} has unit {d}, expected {expected}",
                 "check the parameters' units, or the formula", approx)


def check_val_dim(v: "Val", expected: U.Dim, what: str) -> None:
    for s in flatten(v) if isinstance(v, Arr) else [v]:
        if isinstance(s, Scalar):
            check_dim(s.dim, expected, what, s.approx)


# ----------------------------------------------------------------------------- elementwise helpers


def _scalar(v: Val, what: str) -> Scalar:
    if isinstance(v, Scalar):
        return v
    raise ValError("E301", f"{what} needs a scalar, got {describe_shape(v)}",
                   "pick an element with a subscript, e.g. v[1], or use norm(v)")


def elementwise(a: Val, b: Val, f, what: str) -> Val:
    if isinstance(a, Arr) and isinstance(b, Arr):
        if len(a.items) != len(b.items):
            raise ValError("E301", f"shape mismatch in {what}: {describe_shape(a)} and {describe_shape(b)}",
                       "both sides must have the same size")
        return Arr(tuple(elementwise(x, y, f, what) for x, y in zip(a.items, b.items)))
    if isinstance(a, Arr) or isinstance(b, Arr):
        raise ValError("E301", f"shape mismatch in {what}: {describe_shape(a)} and {describe_shape(b)}",
                       "scalars and arrays can be multiplied or divided, not added")
    return f(_scalar(a, what), _scalar(b, what))


def map1(a: Val, f) -> Val:
    if isinstance(a, Arr):
        return Arr(tuple(map1(x, f) for x in a.items))
    return f(_scalar(a, "this operation"))


def flatten(v: Val) -> list[Scalar]:
    if isinstance(v, Arr):
        out: list[Scalar] = []
        for it in v.items:
            out += flatten(it)
        return out
    return [_scalar(v, "this")]


# ----------------------------------------------------------------------------- arithmetic


def _num(v: Val) -> bool:
    return isinstance(v, (Scalar, Arr))


def _check_num(v: Val, op: str) -> None:
    if not _num(v):
        raise ValError("E302", f"'{op}' cannot be applied to {describe_shape(v)}",
                       "arithmetic works on numbers, vectors and matrices; use a point's .r for its position")


def add(a: Val, b: Val) -> Val:
    _check_num(a, "+"), _check_num(b, "+")
    return elementwise(a, b, lambda x, y: Scalar(X.add(x.expr, y.expr),
                                                 dim_join(zdim(x), zdim(y), "a sum", x.approx or y.approx),
                                                 x.integer and y.integer, approx=x.approx or y.approx), "a sum")


def sub(a: Val, b: Val) -> Val:
    _check_num(a, "-"), _check_num(b, "-")
    return elementwise(a, b, lambda x, y: Scalar(X.sub(x.expr, y.expr),
                                                 dim_join(zdim(x), zdim(y), "a difference", x.approx or y.approx),
                                                 x.integer and y.integer, approx=x.approx or y.approx), "a difference")


def neg(a: Val) -> Val:
    _check_num(a, "-")
    return map1(a, lambda x: Scalar(X.neg(x.expr), x.dim, x.integer, approx=x.approx))


def _smul(x: Scalar, y: Scalar) -> Scalar:
    d = ANY if x.const == 0.0 or y.const == 0.0 else dim_mul(x.dim, y.dim)
    return Scalar(X.mul(x.expr, y.expr), d, x.integer and y.integer, approx=x.approx or y.approx)


def mul(a: Val, b: Val) -> Val:
    _check_num(a, "*"), _check_num(b, "*")
    sa, sb = shape_of(a), shape_of(b)
    if sa == ():
        return map1(b, lambda y: _smul(a, y))
    if sb == ():
        return map1(a, lambda x: _smul(x, b))
    if len(sa) == 1 and len(sb) == 1:  # Modelica: vector * vector is the scalar product
        return dot(a, b)
    if len(sa) == 2 and len(sb) == 1:
        if sa[1] != sb[0]:
            raise ValError("E301", f"matrix-vector product needs matching sizes: {describe_shape(a)} * {describe_shape(b)}",
                           "an m x n matrix multiplies a vector of n")
        return Arr(tuple(dot(row, b) for row in a.items))
    if len(sa) == 1 and len(sb) == 2:
        if sa[0] != sb[0]:
            raise ValError("E301", f"vector-matrix product needs matching sizes: {describe_shape(a)} * {describe_shape(b)}",
                           "a vector of m multiplies an m x n matrix")
        return Arr(tuple(dot(a, col) for col in transpose(b).items))
    if len(sa) == 2 and len(sb) == 2:
        if sa[1] != sb[0]:
            raise ValError("E301", f"matrix product needs matching sizes: {describe_shape(a)} * {describe_shape(b)}",
                           "an m x n matrix multiplies an n x k matrix")
        bt = transpose(b)
        return Arr(tuple(Arr(tuple(dot(row, col) for col in bt.items)) for row in a.items))
    raise ValError("E301", f"cannot multiply {describe_shape(a)} and {describe_shape(b)}",
                   "'*' multiplies scalars, vectors and matrices of matching sizes")


def div(a: Val, b: Val) -> Val:
    _check_num(a, "/"), _check_num(b, "/")
    if shape_of(b) != ():
        raise ValError("E301", f"cannot divide by {describe_shape(b)}", "divide by a scalar")
    if isinstance(b, Scalar) and b.const == 0.0:
        raise ValError("E303", "division by zero", "check the divisor")

    def f(x: Scalar) -> Scalar:
        return Scalar(X.div(x.expr, b.expr), dim_div(x.dim, b.dim), approx=x.approx or b.approx)

    return map1(a, f)


def power(a: Val, b: Val) -> Val:
    _check_num(a, "^"), _check_num(b, "^")
    b = _scalar(b, "an exponent")
    require_dimensionless(b.dim, "an exponent", b.approx)
    a = _scalar(a, "'^' (use element-wise operations for arrays)")
    if b.const is not None and not math.isfinite(b.const):
        raise ValError("E303", f"the exponent {X.fmt_num(b.const)} is not a finite number",
                       "check the exponent for overflow (numbers must stay below about 1.8e308)")
    d = a.dim
    if isinstance(d, U.Dim) and not d.dimensionless:
        if b.const is None:
            _problem("E403", f"a quantity with unit {d} can only be raised to a constant power",
                     "use a constant exponent, or make the base dimensionless", a.approx or b.approx)
            d = None
        else:
            d = d ** b.const
    elif d is ANY:
        d = ANY if b.const is not None else U.ONE
    integer = a.integer and b.integer and b.const is not None and b.const >= 0
    if a.const is not None and b.const is not None:
        try:
            v = a.const ** b.const
        except (OverflowError, ZeroDivisionError):
            raise ValError("E303", "this power cannot be evaluated (overflow or division by zero)",
                           "check the base and the exponent") from None
        if isinstance(v, complex):
            raise ValError("E303", f"({X.fmt_num(a.const)})^{X.fmt_num(b.const)} has no real value",
                           "a negative number raised to a fractional power is complex")
        return Scalar(ir.Const(float(v)), d, integer, approx=a.approx or b.approx)
    return Scalar(X.power(a.expr, b.expr), d, integer, approx=a.approx or b.approx)


def dot(a: Val, b: Val) -> Scalar:
    if not (isinstance(a, Arr) and isinstance(b, Arr)) or shape_of(a) != shape_of(b) or len(shape_of(a)) != 1:
        raise ValError("E301", f"dot product needs two vectors of the same size, got {describe_shape(a)} and {describe_shape(b)}",
                       "e.g. dot({1, 0, 0}, v) with v a vector of 3")
    out = None
    for x, y in zip(a.items, b.items):
        term = _smul(x, y)
        out = term if out is None else Scalar(X.add(out.expr, term.expr),
                                              dim_join(zdim(out), zdim(term), "a dot product", out.approx or term.approx),
                                              approx=out.approx or term.approx)
    return out if out is not None else const(0)


def cross(a: Val, b: Val) -> Arr:
    if shape_of(a) != (3,) or shape_of(b) != (3,):
        raise ValError("E301", f"cross product needs two vectors of 3, got {describe_shape(a)} and {describe_shape(b)}",
                       "e.g. cross(r, F) with r and F vectors of 3")
    x, y = a.items, b.items

    def c(i, j):
        p, q = _smul(x[i], y[j]), _smul(x[j], y[i])
        return Scalar(X.sub(p.expr, q.expr), dim_join(zdim(p), zdim(q), "a cross product", p.approx or q.approx),
                      approx=p.approx or q.approx)

    return Arr((c(1, 2), c(2, 0), c(0, 1)))


def transpose(a: Val) -> Arr:
    s = shape_of(a)
    if len(s) != 2:
        raise ValError("E301", f"transpose needs a matrix, got {describe_shape(a)}", "e.g. transpose(rod.R)")
    return Arr(tuple(Arr(tuple(a.items[i].items[j] for i in range(s[0]))) for j in range(s[1])))


def norm(a: Val) -> Scalar:
    if len(shape_of(a)) != 1:
        raise ValError("E301", f"norm needs a vector, got {describe_shape(a)}", "e.g. norm(rod.b.r)")
    s = dot(a, a)
    d = s.dim ** Fraction(1, 2) if isinstance(s.dim, U.Dim) else s.dim
    return Scalar(X.func("sqrt", s.expr), d, approx=s.approx)


def compare(op: str, a: Val, b: Val) -> Scalar:
    a = _scalar(a, f"'{op}'")
    b = _scalar(b, f"'{op}'")
    dim_join(zdim(a), zdim(b), "a comparison", a.approx or b.approx)
    name = {"<": "lt", "<=": "le", ">": "gt", ">=": "ge", "==": "eq", "<>": "ne"}[op]
    if a.const is not None and b.const is not None:
        r = {"lt": a.const < b.const, "le": a.const <= b.const, "gt": a.const > b.const,
             "ge": a.const >= b.const, "eq": a.const == b.const, "ne": a.const != b.const}[name]
        return Scalar(ir.Const(1.0 if r else 0.0), U.ONE, boolean=True)
    return Scalar(ir.Op(name, (a.expr, b.expr)), U.ONE, boolean=True)


def logic(op: str, a: Val, b: Val | None = None) -> Scalar:
    a = _scalar(a, f"'{op}'")
    if b is None:
        if a.const is not None:
            return Scalar(ir.Const(0.0 if a.const else 1.0), U.ONE, boolean=True)
        return Scalar(ir.Op("not", (a.expr,)), U.ONE, boolean=True)
    b = _scalar(b, f"'{op}'")
    if a.const is not None and b.const is not None:
        r = (bool(a.const) and bool(b.const)) if op == "and" else (bool(a.const) or bool(b.const))
        return Scalar(ir.Const(1.0 if r else 0.0), U.ONE, boolean=True)
    return Scalar(ir.Op(op, (a.expr, b.expr)), U.ONE, boolean=True)


def select(cond: Scalar, a: Val, b: Val) -> Val:
    """if cond then a else b (folded when cond is constant)."""
    if cond.const is not None:
        return a if cond.const else b
    return elementwise(a, b, lambda x, y: Scalar(ir.Op("if", (cond.expr, x.expr, y.expr)),
                                                 dim_join(zdim(x), zdim(y), "the branches of an if-expression",
                                                          x.approx or y.approx), approx=x.approx or y.approx),
                       "the branches of an if-expression")


def apply_func(name: str, args: list[Val]) -> Val:
    """Math functions, element-wise over arrays."""
    if name in X.UNARY_FUNCS:
        if len(args) != 1:
            raise ValError("E304", f"{name}() takes 1 argument, got {len(args)}", f"write {name}(x)")

        def f(x: Scalar) -> Scalar:
            if name in ("abs", "sign", "floor", "ceil"):
                d = x.dim if name == "abs" else U.ONE
            elif name == "sqrt":
                d = x.dim ** Fraction(1, 2) if isinstance(x.dim, U.Dim) else x.dim
            else:
                require_dimensionless(x.dim, f"the argument of {name}()", x.approx)
                d = U.ONE
            if x.const is not None:
                try:
                    v = _NUMERIC[name](x.const)
                except (ValueError, OverflowError, ZeroDivisionError):
                    raise ValError("E303", f"{name}({X.fmt_num(x.const)}) is undefined",
                                   f"the argument is outside the domain of {name}() or the result overflows") from None
                return Scalar(ir.Const(float(v)), d, integer=x.integer and name in ("abs", "sign", "floor", "ceil"),
                              approx=x.approx)
            return Scalar(X.func(name, x.expr), d, approx=x.approx)

        return map1(args[0], f)
    if name in X.BINARY_FUNCS:
        if len(args) != 2:
            raise ValError("E304", f"{name}() takes 2 arguments, got {len(args)}", f"write {name}(a, b)")

        def g(x: Scalar, y: Scalar) -> Scalar:
            d = dim_join(zdim(x), zdim(y), f"{name}()", x.approx or y.approx)
            if name == "atan2":
                d = U.ONE
            if x.const is not None and y.const is not None:
                v = {"atan2": math.atan2, "min": min, "max": max}[name](x.const, y.const)
                return Scalar(ir.Const(float(v)), d, integer=x.integer and y.integer and name != "atan2",
                              approx=x.approx or y.approx)
            return Scalar(X.func(name, x.expr, y.expr), d, approx=x.approx or y.approx)

        return elementwise(args[0], args[1], g, f"{name}()")
    raise ValError("E213", f"unknown function '{name}'", "see docs/language.md for the built-in functions")


_NUMERIC = {
    "sin": math.sin, "cos": math.cos, "tan": math.tan, "asin": math.asin, "acos": math.acos, "atan": math.atan,
    "sinh": math.sinh, "cosh": math.cosh, "tanh": math.tanh, "exp": math.exp, "log": math.log,
    "log10": math.log10, "sqrt": math.sqrt, "abs": abs, "sign": lambda v: float((v > 0) - (v < 0)),
    "floor": math.floor, "ceil": math.ceil,
}
