"""The equation section, run by the flattener's build: `connect(a, element, b)` first (they
complete components before anything reads their fields), then energies (terms), generalized forces
`force(q) = Q` and holonomic constraints; for-loops unrolled. Functions of the
:class:`~mechdsl.semantic.flatten.Flattener` `fl`, whose lists they fill."""
from __future__ import annotations

from ..frontend import ast
from ..model import ir
from ..model import exprs as X
from ..model import units as U
from ..diagnostics import Span
from ..frontend.printer import expr as print_expr
from . import values as V
from .constraint_names import constraint_name
from .entries import Failed
from .evaluate import EvalError, fail
from .values import Arr, CompRef, Scalar, ValError


def run_connects(fl) -> None:
    """connect(...) equations first: they complete components before anything reads their fields."""
    for eq in fl.equations:
        if not _guard(fl, lambda eq=eq: _equation(fl, eq, connects=True), eq.span):
            fl.connect_failed = True

def run_equations(fl) -> None:
    for eq in fl.equations:
        _guard(fl, lambda eq=eq: _equation(fl, eq, connects=False), eq.span)

def _guard(fl, fn, span: Span) -> bool:
    try:
        fn()
        return True
    except EvalError as e:
        fl.diags.items.append(e.diag)
    except Failed:
        pass
    except ValError as ve:
        fl.diags.error(ve.code, ve.message, span, ve.help)
    return False

def _equation(fl, eq, connects: bool) -> None:
    if isinstance(eq, ast.ForEquation):
        if not _has_work(eq, connects):
            return  # each pass runs only the loops that hold its kind of equation
        if eq.var in fl.entries:
            fail("E202", f"loop variable '{eq.var}' hides the declaration of the same name", eq.span,
                 "rename the loop variable")
        values = fl.range_values(eq.range)
        for i in values:
            fl.loop_vars[eq.var] = i
            try:
                for item in eq.body:
                    _equation(fl, item, connects)
            finally:
                del fl.loop_vars[eq.var]
        return
    if isinstance(eq, ast.Connect):
        if connects:
            _connect(fl, eq)
        return
    if connects:
        return
    if isinstance(eq, ast.EnergyEquation):
        v = fl.eval(eq.expr)
        if not isinstance(v, Scalar):
            fail("E301", f"the {eq.kind} energy must be a scalar, got {V.describe_shape(v)}", eq.expr.span,
                 "for a vector v use dot(v, v)")
        want = U.POWER if eq.kind == "dissipation" else U.ENERGY
        fl.check_dim(v, want, f"the {eq.kind} {'function' if eq.kind == 'dissipation' else 'energy'}",
                     eq.expr.span)
        if eq.kind == "potential" and X.has_speed(v.expr):
            fail("E308", "the potential energy must not depend on speeds", eq.expr.span,
                 "velocity-dependent forces go into force(q) = ... or the dissipation function")
        if any(isinstance(n, ir.EnergyRef) for n in X.walk(v.expr)) or X.needs_dynamics(v.expr):
            fail("E308", f"the {eq.kind} energy cannot refer to energies, reactions or accelerations", eq.expr.span,
                 "write the expression itself; kinetic_energy() etc. are for outputs")
        fl.terms.append(ir.Term(eq.kind, v.expr, f"{eq.kind}@{eq.span.line}", eq.span))
        return
    if isinstance(eq, ast.ForceEquation):
        c = fl.eval(eq.coordinate)
        if not (isinstance(c, Scalar) and isinstance(c.expr, ir.Coord)):
            fail("E218", f"force(...) needs a coordinate, got {print_expr(eq.coordinate)}", eq.coordinate.span,
                 "force(q) = ... names a `coordinate` or a joint variable such as j1.phi")
        q = fl.eval(eq.expr)
        if not isinstance(q, Scalar):
            fail("E301", "a generalized force must be a scalar", eq.expr.span, "one equation per coordinate: force(q) = Q;")
        if isinstance(c.dim, U.Dim):
            fl.check_dim(q, U.ENERGY / c.dim, f"the generalized force on {c.expr.name}", eq.expr.span)
        fl.gen_forces.append(ir.GeneralizedForce(f"force({c.expr.name})", c.expr.name, q.expr, eq.span))
        return
    if isinstance(eq, ast.SimpleEquation):
        lhs, rhs = fl.eval(eq.lhs), fl.eval(eq.rhs)
        try:
            res = V.sub(lhs, rhs)
        except ValError as ve:
            fail(ve.code, ve.message, eq.span, ve.help)
        items = V.flatten(res) if isinstance(res, Arr) else [res]
        text = eq.doc or f"{print_expr(eq.lhs)} = {print_expr(eq.rhs)}"
        for k, s in enumerate(items):
            if X.has_speed(s.expr):
                fail("E308", "a constraint equation must not contain speeds", eq.span,
                     "only holonomic (position-level) constraints are supported: g(q, t) = 0")
            if not any(isinstance(n, (ir.Coord, ir.PointPos, ir.BodyRot)) for n in X.walk(s.expr)):
                fail("E309", "this equation involves no coordinate", eq.span,
                     "an equation is a constraint on coordinates; to define a quantity use `Real x = ...;`")
            alias = f"c{len(fl.constraints) + 1}"
            nm = constraint_name(eq.doc, fl.loop_vars.values(), k if len(items) > 1 else None,
                                 fl.constraints) or alias
            fl.constraints.append(ir.Constraint(nm, s.expr, text + (f" [{k + 1}]" if len(items) > 1 else ""),
                                                eq.span, alias=alias,
                                                dim=s.dim if isinstance(s.dim, U.Dim) else None))
        return
    raise AssertionError(type(eq))

def _connect(fl, eq: ast.Connect) -> None:
    el = fl.eval(eq.element)
    if not isinstance(el, CompRef) or el.name not in fl.insts:
        fail("E209", f"connect(a, element, b) needs a joint, spring or damper as its second argument, got "
                     f"{print_expr(eq.element)}", eq.element.span, "e.g. connect(rod1.b, j2, rod2.a)")
    inst = fl.insts[el.name]
    names = inst.cls.connect_fields
    if names is None:
        fail("E209", f"a {inst.cls.name} cannot be connected", eq.element.span,
             "connect joints, springs and dampers between two points")
    for fname, ref in zip(names, (eq.a, eq.b)):
        if fname in inst.connections or (inst.entry.mod.sub.get(fname) and inst.entry.mod.sub[fname].value is not None):
            fail("E211", f"'{fname}' of '{inst.name}' is set twice", ref.span,
                 "set it either with a modifier or with one connect(...)")
        v = fl._frame_of_joint(fl.eval(ref), inst.cls.field(fname), ref.span)
        fl._check_field(inst, inst.cls.field(fname), v, ref.span)
        inst.connections[fname] = v


def _has_work(eq: ast.ForEquation, connects: bool) -> bool:
    """Whether a for-loop holds connect(...) equations (connects=True) or other equations."""
    for item in eq.body:
        if isinstance(item, ast.ForEquation):
            if _has_work(item, connects):
                return True
        elif isinstance(item, ast.Connect) == connects:
            return True
    return False
