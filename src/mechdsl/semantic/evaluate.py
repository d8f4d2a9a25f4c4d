"""Expressions: AST expression -> value (IR expression with shape and unit), in a scope.

The :class:`Evaluator` is a mixin of the flattener: it needs ``lookup(name, span)`` (a
declared name -> value), ``attribute(value, name, span)`` and ``loop_vars``.
"""
from __future__ import annotations

import abc
import math

from ..frontend import ast
from ..model import exprs as X
from ..model import ir
from ..frontend import limits
from ..model import units as U
from ..diagnostics import MechError, Diagnostic, Span
from . import values as V
from .values import ANY, Arr, CompRef, Scalar, Str, Val, ValError

BUILTIN_NAMES = {"time", "pi", "world"}
VECTOR_FUNCS = {"cross", "dot", "norm", "transpose", "identity", "zeros", "ones", "fill", "sum", "skew",
                "diagonal", "rotation", "size", "normalize", "rpy", "axis_angle"}
KINEMATIC_FUNCS = {"der", "position", "velocity", "kinetic_energy", "potential_energy", "energy",
                   "dissipation_function", "reaction_force", "reaction_torque", "constraint_force",
                   "constraint_torque"}
UNIT_FUNCS = {"deg": math.pi / 180, "rad": 1.0}     # a number in that unit, as an angle (SI): deg(45)
ALL_FUNCS = set(X.MATH_FUNCS) | VECTOR_FUNCS | KINEMATIC_FUNCS | set(UNIT_FUNCS)




class EvalError(Exception):
    """A diagnostic raised while evaluating; caught per declaration/equation and collected."""

    def __init__(self, diag: Diagnostic):
        super().__init__(diag.message)
        self.diag = diag


def fail(code: str, message: str, span: Span, help: str | None = None):
    raise EvalError(Diagnostic(code, message, span, help))


class Evaluator(abc.ABC):
    loop_vars: dict[str, int]

    # provided by the flattener
    @abc.abstractmethod
    def lookup(self, name: str, span: Span) -> Val:
        """The value of a declared (or built-in) name."""

    @abc.abstractmethod
    def attribute(self, value: Val, name: str, span: Span) -> Val:
        """``value.name`` for component references."""

    def known_names(self) -> list[str]:  # pragma: no cover - abstract
        return []

    def note_warnings(self, items, span: Span) -> None:  # pragma: no cover - abstract
        pass

    # ------------------------------------------------------------------ entry point
    def eval(self, e: ast.Expr) -> Val:
        try:
            v = self._eval(e)
            if not _finite(v):
                raise ValError("E303", "this value overflows (it is infinite or not a number)",
                               "check the formula for products and powers of huge numbers")
            return v
        except ValError as ve:
            raise EvalError(Diagnostic(ve.code, ve.message, e.span, ve.help)) from None
        except RecursionError:
            raise EvalError(Diagnostic("E104", "expression nested too deeply", e.span,
                                       "split it with intermediate `Real` variables")) from None

    def _sub(self, e: ast.Expr) -> Val:
        """Evaluate a sub-expression, attributing value errors (and unit warnings) to its own span."""
        sink = V.WARNINGS.get()
        before = len(sink) if sink is not None else 0
        try:
            v = self._eval(e)
            if sink is not None and len(sink) > before:
                self.note_warnings(sink[before:], e.span)
                del sink[before:]
            return v
        except ValError as ve:
            raise EvalError(Diagnostic(ve.code, ve.message, e.span, ve.help)) from None

    def _eval(self, e: ast.Expr) -> Val:
        if isinstance(e, ast.Number):
            if not math.isfinite(e.value):
                raise ValError("E303", "number is too large", "numbers must be below about 1.8e308")
            # integers are pure numbers; a decimal literal (0.1, 9.81) may stand for a quantity
            return V.const(e.value, integer=isinstance(e.value, int), approx=isinstance(e.value, float))
        if isinstance(e, ast.String):
            return Str(e.value)
        if isinstance(e, ast.Bool):
            return Scalar(ir.Const(1.0 if e.value else 0.0), U.ONE, boolean=True)
        if isinstance(e, ast.Ref):
            return self.eval_ref(e)
        if isinstance(e, ast.BinOp):
            return self._binop(e)
        if isinstance(e, ast.UnaryOp):
            a = self._sub(e.operand)
            if e.op == "-":
                return V.neg(a)
            if e.op == "+":
                V._check_num(a, "+")
                return a
            return V.logic("not", a)
        if isinstance(e, ast.IfExpr):
            return self._if(e)
        if isinstance(e, ast.Array):
            return Arr(tuple(self._sub(i) for i in e.items))
        if isinstance(e, ast.Comprehension):
            out = []
            for i in self.range_values(e.range):
                self.loop_vars[e.var] = i
                try:
                    out.append(self._sub(e.expr))
                finally:
                    del self.loop_vars[e.var]
            return Arr(tuple(out))
        if isinstance(e, ast.Call):
            return self._call(e)
        raise ValError("E302", f"unexpected expression {type(e).__name__}", "this is not a value")

    def _binop(self, e: ast.BinOp) -> Val:
        if e.op in ("+", "-", "*", "/") and isinstance(e.left, ast.BinOp):
            # long left-nested chains: evaluate iteratively
            chain = []
            node: ast.Expr = e
            while isinstance(node, ast.BinOp) and node.op in ("+", "-", "*", "/") and len(chain) < 100000:
                chain.append((node.op, node.right))
                node = node.left
            acc = self._sub(node)
            for op, right in reversed(chain):
                acc = _ARITH[op](acc, self._sub(right))
            return acc
        a, b = self._sub(e.left), self._sub(e.right)
        if e.op in _ARITH:
            return _ARITH[e.op](a, b)
        if e.op == "^":
            return V.power(a, b)
        if e.op in ("and", "or"):
            return V.logic(e.op, a, b)
        return V.compare(e.op, a, b)

    def _if(self, e: ast.IfExpr) -> Val:
        # evaluate from the last branch backwards so constant conditions fold
        result = self._sub(e.otherwise)
        for cond, val in reversed(e.branches):
            c = self._sub(cond)
            if not isinstance(c, Scalar):
                raise ValError("E301", "an if-condition must be a scalar", "compare scalars: if x > 0 then ... else ...")
            if c.const is not None:
                if c.const:
                    result = self._sub(val)
                continue
            result = V.select(c, self._sub(val), result)
        return result

    # ------------------------------------------------------------------ references
    def eval_ref(self, r: ast.Ref) -> Val:
        first = r.parts[0]
        val = self.lookup(first.name, first.span)
        val = self.index(val, first.subscripts, first.span, first.name)
        for part in r.parts[1:]:
            val = self.attribute(val, part.name, part.span)
            val = self.index(val, part.subscripts, part.span, part.name)
        return val

    def int_value(self, e: ast.Expr, what: str) -> int:
        v = self._sub(e)
        if isinstance(v, Scalar) and v.const is not None and float(v.const).is_integer() and (
                v.integer or isinstance(v.expr, ir.Const)):
            if not v.integer and not _is_structural(v):
                fail("E307", f"{what} must be an Integer expression", e.span,
                     "use Integer parameters, loop variables and integer literals")
            return int(v.const)
        fail("E307", f"{what} must be an Integer constant", e.span,
             "declare sizes as `parameter Integer N = ...`; indices and bounds are Integer expressions")
        raise AssertionError  # unreachable

    def index(self, val: Val, subs: tuple[ast.Expr, ...], span: Span, name: str) -> Val:
        for s in subs:
            k = self.int_value(s, "an index")
            if not isinstance(val, Arr):
                fail("E303", f"'{name}' is not an array and cannot be indexed", s.span,
                     f"remove the subscript, or declare '{name}' with a size: {name}[n]")
            if not 1 <= k <= len(val.items):
                fail("E303", f"index {k} is out of range for '{name}' (1..{len(val.items)})", s.span,
                     "indices start at 1")
            val = val.items[k - 1]
        return val

    def range_values(self, rng: ast.Range) -> list[int]:
        a = self.int_value(rng.start, "a range bound")
        b = self.int_value(rng.stop, "a range bound")
        step = 1 if rng.step is None else self.int_value(rng.step, "a range step")
        if step == 0:
            fail("E303", "a range step must not be zero", rng.span, "write start:step:stop with a non-zero step, e.g. 1:2:9")
        n = (b - a) // step + 1
        if n > limits.get("arrays"):
            fail("E303", f"range {a}:{b} has {n} elements (limit {limits.get('arrays')})", rng.span,
                 "use a shorter range; " + limits.hint("arrays"))
        # nested loops multiply: bound the total work of a model, not only each range
        self._iterations = getattr(self, "_iterations", 0) + max(n, 0)
        if self._iterations > limits.get("iterations"):
            fail("E303", f"the loops of this model run more than {limits.get('iterations')} times", rng.span,
                 "use smaller ranges; " + limits.hint("iterations"))
        return list(range(a, b + (1 if step > 0 else -1), step))

    # ------------------------------------------------------------------ calls
    def _call(self, e: ast.Call) -> Val:
        name = e.func.dotted
        if len(e.func.parts) != 1 or e.func.parts[0].subscripts or name not in ALL_FUNCS:
            from ..diagnostics import did_you_mean

            fail("E213", f"unknown function '{name}'", e.func.span,
                 did_you_mean(name, ALL_FUNCS) or "see docs/language.md for the built-in functions")
        if name in ("kinetic_energy", "potential_energy", "energy", "dissipation_function"):
            if e.args:
                fail("E304", f"{name}() takes no arguments", e.span, f"write {name}()")
            kind = {"kinetic_energy": "kinetic", "potential_energy": "potential", "energy": "energy",
                    "dissipation_function": "dissipation"}[name]
            return Scalar(ir.EnergyRef(kind), U.POWER if kind == "dissipation" else U.ENERGY)
        if name in ("reaction_force", "reaction_torque"):
            return self._reaction(e, name)
        if name in ("constraint_force", "constraint_torque"):
            return self._constraint_load(e, name)
        if name == "size":
            return self._size(e)
        args = [self._sub(a) for a in e.args]
        if name == "der":
            if len(args) != 1:
                fail("E304", "der() takes 1 argument", e.span, "write der(q) for the speed of a coordinate q")
            return V.map1(args[0], lambda s: _der(s, e.args[0].span))
        if name in ("position", "velocity"):
            if len(args) != 1 or not isinstance(args[0], CompRef):
                fail("E209", f"{name}() takes a point or body", e.span, f"e.g. {name}(rod.b)")
            return self.attribute(args[0], "r" if name == "position" else "v", e.span)
        if name in UNIT_FUNCS:
            if len(args) != 1:
                fail("E304", f"{name}() takes 1 argument, got {len(args)}", e.span, f"write {name}(45)")
            return V.map1(args[0], lambda s: _in_unit(s, name, e.args[0].span))
        if name in X.MATH_FUNCS:
            return V.apply_func(name, args)
        return _vector_func(name, args, e)

    def _size(self, e: ast.Call) -> Val:
        if not 1 <= len(e.args) <= 2:
            fail("E304", "size() takes an array and optionally a dimension", e.span, "size(a) or size(a, 1)")
        v = self._sub(e.args[0])
        shape = V.shape_of(v)
        if len(e.args) == 2:
            k = self.int_value(e.args[1], "a dimension")
            if not 1 <= k <= len(shape):
                fail("E303", f"dimension {k} out of range", e.args[1].span,
                     f"the array has {len(shape)} dimension{'s' if len(shape) != 1 else ''}")
            return V.const(shape[k - 1], integer=True)
        if len(shape) != 1:
            fail("E304", "size(a) needs a vector", e.span, "for a matrix give the dimension: size(a, 1)")
        return V.const(shape[0], integer=True)

    def _reaction(self, e: ast.Call, name: str) -> Val:
        if len(e.args) != 1:
            fail("E304", f"{name}() takes one joint", e.span, f"e.g. {name}(j1)")
        j = self._sub(e.args[0])
        if not isinstance(j, CompRef) or j.kind != "joint":
            fail("E209", f"{name}() needs a joint, got {V.describe_shape(j)}", e.args[0].span,
                 "reactions are measured in joints: name a Revolute, Prismatic, ... component")
        what = "force" if name == "reaction_force" else "torque"
        d = U.FORCE if what == "force" else U.TORQUE
        return Arr(tuple(Scalar(ir.ReactionRef(j.name, what, i), d) for i in range(3)))


    def _constraint_load(self, e: ast.Call, name: str) -> Val:
        """``constraint_force(c, body)`` / ``constraint_torque(c, body)``: what the constraint c (an
        equation's name, or a loop-closing joint) exerts on the body, world axes, at the point where
        it acts.  The name is checked once the equations are known (semantic/constraint_loads.py)."""
        if len(e.args) != 2:
            fail("E304", f"{name}() takes a constraint and a body", e.span, f"e.g. {name}(rod, bob)")
        c = e.args[0]
        if not isinstance(c, ast.Ref) or any(p.subscripts for p in c.parts):
            fail("E209", f"the first argument of {name}() names a constraint (its description, e.g. rod) or a "
                         "loop-closing joint", c.span, f"e.g. {name}(rod, bob) for `x^2 + y^2 = L^2 \"rod\";`")
        try:
            v = self._sub(c)
        except EvalError:
            v = None                          # not a declaration: the name of a constraint equation
        cname = v.name if isinstance(v, CompRef) and v.kind == "joint" else c.dotted
        b = self._sub(e.args[1])
        if not isinstance(b, CompRef) or b.kind != "body":
            fail("E209", f"{name}() needs a body as its second argument, got {V.describe_shape(b)}", e.args[1].span,
                 "name the body the constraint acts on (a PointMass, Rod, Body, ...)")
        what = "force" if name == "constraint_force" else "torque"
        d = U.FORCE if what == "force" else U.TORQUE
        return Arr(tuple(Scalar(ir.ConstraintLoad(cname, b.name, what, i), d) for i in range(3)))


def _finite(v: Val) -> bool:
    if isinstance(v, Scalar):
        return v.const is None or math.isfinite(v.const)
    if isinstance(v, Arr):
        return all(_finite(x) for x in v.items)
    return True


def _is_structural(v: Scalar) -> bool:
    return v.integer


def _der(s: Scalar, span: Span) -> Scalar:
    d = V.dim_div(s.dim, U.TIME) if s.dim is not ANY else None
    if isinstance(s.expr, ir.Coord):
        return Scalar(ir.Speed(s.expr.name), d)
    if X.has_speed(s.expr):
        fail("E305", "der() of an expression with speeds: accelerations are not available here", span,
             "der() applies to coordinates and expressions of coordinates and time")
    if not X.depends_on_state(s.expr) and not X.depends_on_time(s.expr):
        return Scalar(ir.Const(0.0), d)
    return Scalar(ir.TimeDer(s.expr), d)


_ARITH = {"+": V.add, "-": V.sub, "*": V.mul, "/": V.div}


def _vector_func(name: str, args: list[Val], e: ast.Call) -> Val:
    c = _Call(name, args, e)
    entry = _BUILTINS.get(name)
    if entry is None:
        fail("E213", f"unknown function '{name}'", e.span, "see docs/language.md for the built-in functions")
    arity, fn = entry
    if arity is not None:
        c.need(arity)
    return fn(c)


class _Call:
    """A call of a built-in vector function: its name, evaluated arguments and node, and the
    checks the functions share (argument count, sizes)."""

    def __init__(self, name: str, args: list[Val], e: ast.Call):
        self.name, self.args, self.e = name, args, e

    def need(self, n: int) -> None:
        if len(self.args) != n:
            fail("E304", f"{self.name}() takes {n} argument{'s' if n != 1 else ''}, got {len(self.args)}",
                 self.e.span, "see docs/language.md for the built-in functions")

    def count(self, v: Val, what: str) -> int:
        if isinstance(v, Scalar) and v.const is not None and float(v.const).is_integer() and v.const >= 0:
            if v.const > limits.get("arrays"):
                fail("E303", f"{what} {X.fmt_num(v.const)} is too large (limit {limits.get('arrays')})", self.e.span,
                     "use a smaller size")
            return int(v.const)
        fail("E307", f"{what} must be a non-negative Integer constant", self.e.span,
             "use an integer literal or an Integer parameter")
        raise AssertionError

    def sizes(self, args, what: str = "a size") -> list[int]:
        dims = [self.count(a, what) for a in args]
        if math.prod(dims) > limits.get("arrays"):
            fail("E303", f"{self.name}() would build more than {limits.get('arrays')} elements", self.e.span,
                 "use smaller sizes; " + limits.hint("arrays"))
        return dims


def _identity(c: _Call) -> Val:
    n = c.sizes([c.args[0]] * 2, "the size")[0]
    return Arr(tuple(Arr(tuple(V.const(1.0 if i == j else 0.0) for j in range(n))) for i in range(n)))


def _zeros_ones(c: _Call) -> Val:
    if not c.args:
        fail("E304", f"{c.name}() needs a size", c.e.span, f"e.g. {c.name}(3) or {c.name}(3, 3)")
    return _filled(V.const(0.0 if c.name == "zeros" else 1.0), c.sizes(c.args))


def _fill(c: _Call) -> Val:
    if len(c.args) < 2:
        fail("E304", "fill(value, n, ...) needs a value and a size", c.e.span, "e.g. fill(0.5, 3)")
    return _filled(c.args[0], c.sizes(c.args[1:]))


def _sum(c: _Call) -> Val:
    a = c.args[0]
    items: list[Val] = list(V.flatten(a)) if isinstance(a, Arr) else [a]
    if not items:
        return V.const(0.0)
    while len(items) > 1:  # balanced: long sums stay shallow
        items = [V.add(items[i], items[i + 1]) if i + 1 < len(items) else items[i]
                 for i in range(0, len(items), 2)]
    return items[0]


def _skew(c: _Call) -> Val:
    if V.shape_of(c.args[0]) != (3,):
        fail("E301", "skew() needs a vector of 3", c.e.span, "e.g. skew({wx, wy, wz})")
    x, y, z = c.args[0].items  # type: ignore[union-attr]
    zero = V.const(0.0)
    return Arr((Arr((zero, V.neg(z), y)), Arr((z, zero, V.neg(x))), Arr((V.neg(y), x, zero))))


def _diagonal(c: _Call) -> Val:
    if len(V.shape_of(c.args[0])) != 1:
        fail("E301", "diagonal() needs a vector", c.e.span, "e.g. diagonal({1, 2, 3})")
    items = c.args[0].items  # type: ignore[union-attr]
    n = len(items)
    return Arr(tuple(Arr(tuple(items[i] if i == j else V.const(0.0) for j in range(n))) for i in range(n)))


def _rotation(c: _Call) -> Val:
    from .components import as_expr, as_vec3, normalized, rodrigues

    axis = normalized(as_vec3(c.args[0], "the rotation axis"), "the rotation axis")
    ang = c.args[1]
    if isinstance(ang, Scalar):
        V.require_dimensionless(ang.dim, "a rotation angle", ang.approx)
    R = rodrigues(axis, as_expr(ang, "the rotation angle"))
    return Arr(tuple(Arr(tuple(Scalar(x, U.ONE) for x in row)) for row in R))


def _orientation(c: _Call) -> Val:
    from .orientation import call_axis_angle, call_rpy

    return call_rpy(c.args) if c.name == "rpy" else call_axis_angle(c.args)


# name -> (the number of arguments, checked first; None: the function checks), the function
_BUILTINS = {
    "cross": (2, lambda c: V.cross(c.args[0], c.args[1])),
    "dot": (2, lambda c: V.dot(c.args[0], c.args[1])),
    "norm": (1, lambda c: V.norm(c.args[0])),
    "normalize": (1, lambda c: V.div(c.args[0], V.norm(c.args[0]))),
    "transpose": (1, lambda c: V.transpose(c.args[0])),
    "identity": (1, _identity), "zeros": (None, _zeros_ones), "ones": (None, _zeros_ones),
    "fill": (None, _fill), "sum": (1, _sum), "skew": (1, _skew), "diagonal": (1, _diagonal),
    "rotation": (2, _rotation), "rpy": (None, _orientation), "axis_angle": (None, _orientation),
}


def _filled(v: Val, dims: list[int]) -> Val:
    if not dims:
        return v
    inner = _filled(v, dims[1:])
    return Arr(tuple(inner for _ in range(dims[0])))


__all__ = ["Evaluator", "EvalError", "fail", "BUILTIN_NAMES", "ALL_FUNCS", "math"]


def _in_unit(s: Val, name: str, span: Span) -> Scalar:
    """deg(x), rad(x): the number x in that unit, an angle in SI (a quantity: a parameter declared
    in any angle unit takes it as it is, semantic/scalar_decls.py)."""
    if not isinstance(s, Scalar) or (isinstance(s.dim, U.Dim) and s.dim != U.ONE):
        fail("E402", f"{name}() takes a number" + (f", got a value in {s.dim}" if isinstance(s, Scalar) else ""), span,
             f"write {name}(45): the number in {'degrees' if name == 'deg' else 'radians'}")
    f = UNIT_FUNCS[name]
    if s.const is not None:
        return Scalar(ir.Const(float(s.const) * f), U.ONE, approx=s.approx)
    return Scalar(s.expr if f == 1.0 else X.mul(X.const(f), s.expr), U.ONE, approx=s.approx)
