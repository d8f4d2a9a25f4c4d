"""Real, Integer and Boolean declarations evaluated: parameters and inputs (structural Integer and
Boolean values substituted, Real ones kept as `ir.Param` with their values), coordinates (start,
speed, fixed, per-element overrides), outputs and variables, with units and min/max. A mixin of
:class:`~mechdsl.semantic.flatten.Flattener`."""
from __future__ import annotations

import math

from ..frontend import ast
from ..model import exprs as X
from ..model import ir
from ..frontend import limits
from ..model import units as U
from ..diagnostics import did_you_mean
from . import values as V
from .entries import COORD_ATTRS, Entry, constval
from .evaluate import fail
from .mods import Mod
from .values import ANY, Arr, CompRef, Scalar, Str, Val

PARAM_ATTRS = {"unit", "min", "max", "displayUnit"}


class ScalarDeclarations:
    def _unit(self, e: Entry, mod: Mod) -> tuple[float, U.Dim | None, str | None]:
        u = mod.sub.get("unit")
        if u is None or u.value is None:
            return 1.0, None, None
        v = self.eval(u.value)
        if not isinstance(v, Str):
            fail("E404", "a unit must be a string", u.value.span, 'write unit = "m/s2"')
        if len(v.value) > limits.get("name_length"):  # pint's parser takes minutes on huge strings
            fail("E314", f"unit string is too long ({len(v.value):,} characters, more than "
                         f"{limits.get('name_length')})", u.value.span,
                 'units look like "kg", "m/s2", "N.m"; ' + limits.hint("name_length"))
        try:
            factor, dim = U.parse_unit(v.value)
        except ValueError:
            fail("E404", f"unknown unit '{v.value}'", u.value.span, 'units look like "kg", "m/s2", "N.m", "rad"')
        return factor, dim, v.value

    def _check_attrs(self, mod: Mod, allowed: set[str]) -> None:
        for k, m in mod.sub.items():
            if k not in allowed:
                fail("E204", f"unknown attribute '{k}'", m.span, did_you_mean(k, allowed) or
                     "allowed: " + ", ".join(sorted(allowed)))

    def _parameter(self, e: Entry, dims: tuple[int, ...]) -> Val:
        d = e.decl
        self._check_attrs(e.mod, PARAM_ATTRS)
        factor, dim, unit = self._unit(e, e.mod)
        if e.mod.value is None and e.kind == "input":     # an input's default value is 0
            sp = d.name_span
            e.mod.value = ast.Number(value=0, span=sp) if not dims else ast.Call(
                func=ast.Ref(parts=(ast.RefPart(name="fill", span=sp),), span=sp),
                args=(ast.Number(value=0, span=sp), *[ast.Number(value=n, span=sp) for n in dims]), span=sp)
        if e.mod.value is None:
            fail("E212", f"parameter '{d.name}' has no value", d.name_span,
                 f"give it one: {d.type_name} {d.name} = ...;" if d.type_name != "Real" else f"parameter Real {d.name} = 1;")
        val = self._parameter_value(e, dims, dim)
        structural = d.type_name in ("Integer", "Boolean")
        out_items = []
        for idx, s in _enumerate(val, dims):
            name = d.name + _suffix(idx)
            out_items.append(self._structural_item(e, name, s, unit) if structural
                             else self._real_item(e, name, s, factor, dim, unit))
        return _reshape(out_items, dims)

    def _parameter_value(self, e: Entry, dims: tuple[int, ...], dim) -> Val:
        """The parameter's value, checked: a number or an array of the declared shape, constant,
        of the declared dimension."""
        d = e.decl
        val = self.eval(e.mod.value)
        if isinstance(val, (Str, CompRef)):
            fail("E301", f"parameter '{d.name}' must be a number, got {V.describe_shape(val)}", e.mod.value.span,
                 "parameters hold numbers, vectors or matrices")
        want = dims
        got = V.shape_of(val)
        if got != want:
            self.unsplit_array_mismatch(e.mod.value.span, d.name, want, got)
            fail("E301", f"parameter '{d.name}' is declared with shape {_shape_text(want)} but its value is "
                         f"{V.describe_shape(val)}", e.mod.value.span,
                 "use fill(value, n) for arrays" if want and not got else
                 f"give a value of shape {_shape_text(want)}, or change the declared size")
        for s in V.flatten(val) if isinstance(val, Arr) else [val]:
            if X.depends_on_state(s.expr) or X.depends_on_time(s.expr):
                fail("E306", f"parameter '{d.name}' depends on coordinates or time", e.mod.value.span,
                     "parameters are constant; use an `output` or a `Real` variable instead")
            if dim is not None:
                self.check_dim(s, dim, f"the value of '{d.name}'", e.mod.value.span)
        return val

    def _structural_item(self, e: Entry, name: str, s: Scalar, unit) -> Val:
        """An Integer or Boolean parameter's element: a constant, recorded as structural."""
        d = e.decl
        if s.const is None:
            fail("E307", f"{d.type_name} parameter '{d.name}' must have a constant value", e.mod.value.span,
                 "Integer and Boolean parameters are structural: use literals and other Integer parameters")
        if d.type_name == "Integer" and not float(s.const).is_integer():
            fail("E307", f"Integer parameter '{d.name}' has non-integer value {X.fmt_num(s.const)}", e.mod.value.span,
                 f"give a whole number, or declare it as parameter Real {d.name}")
        if d.type_name == "Integer" and abs(s.const) > limits.get("integers"):
            fail("E315", f"Integer parameter '{name}' = {X.fmt_num(s.const)} is too large for a structural "
                         f"parameter (more than {limits.get('integers'):,} in magnitude)", e.mod.value.span,
                 "Integer parameters size arrays and loops; " + limits.hint("integers"))
        self._check_range(e, name, s.const)
        e.params.append(ir.Parameter(name, float(s.const), None, unit, d.doc or "", True, d.name_span))
        return Scalar(ir.Const(float(s.const)), U.ONE if d.type_name == "Boolean" else ANY,
                      integer=d.type_name == "Integer", boolean=d.type_name == "Boolean")

    def _real_item(self, e: Entry, name: str, s: Scalar, factor: float, dim, unit) -> Val:
        """A Real parameter's (or an input's default's) element: evaluated in SI, checked, recorded."""
        d = e.decl
        # numbers are in the declared unit (alpha(unit = "deg") = 30: 30 degrees); a value computed
        # from parameters with units (beta(unit = "deg") = alpha) is a quantity, already SI
        binding = s.expr if factor == 1.0 or isinstance(s.dim, U.Dim) else X.mul(X.const(factor), s.expr)
        try:
            with _quiet_numpy():
                value = X.evaluate(binding, self.param_values)
        except (ValueError, ZeroDivisionError, OverflowError, KeyError) as ex:
            fail("E303", f"parameter '{name}' cannot be evaluated: {ex}", e.mod.value.span,
                 "check the formula for division by zero and arguments outside a function's domain")
        except TypeError:  # a complex number: a negative base to a fractional power
            fail("E303", f"parameter '{name}' has no real value", e.mod.value.span,
                 "a negative number raised to a fractional power is complex")
        if not math.isfinite(value):
            fail("E303", f"parameter '{name}' evaluates to {value}", e.mod.value.span,
                 "check the formula for division by zero, overflow and arguments outside a function's domain")
        lo, hi = self._check_range(e, name, value)
        if e.kind == "input" and not isinstance(binding, ir.Const):
            fail("E230", f"the default value of input '{name}' must be a constant number",
                 e.mod.value.span, f"write input Real {d.name} = 0; (a default, used when nothing drives it)")
        used = {n.name for n in X.leaves_of(binding, ir.Param)} & self.input_names
        if e.kind == "parameter" and used:
            bad = sorted(used)[0]
            fail("E231", f"parameter '{name}' depends on input '{bad}'", e.mod.value.span,
                 "inputs change during a run; parameters are constant: use the input in the equations or forces")
        self.param_values[name] = value
        if e.kind == "input":
            self.input_names.add(name)
        e.params.append(ir.Parameter(name, value, None if isinstance(binding, ir.Const) else binding,
                                     unit, d.doc or "", False, d.name_span, input=e.kind == "input",
                                     min=lo, max=hi))
        return Scalar(ir.Param(name), dim if dim is not None else None)

    def _check_range(self, e: Entry, name: str, value: float) -> tuple[float | None, float | None]:
        """Check ``value`` against the declared min and max; returns them (None: not declared)."""
        found: dict[str, float] = {}
        for attr, bad in (("min", lambda v, b: v < b), ("max", lambda v, b: v > b)):
            m = e.mod.sub.get(attr)
            if m is not None and m.value is not None:
                b = self.eval(m.value)
                if not (isinstance(b, Scalar) and b.const is not None):
                    fail("E301", f"'{attr}' of '{e.decl.name}' must be a constant number", m.value.span,
                         f"e.g. {attr} = 0")
                found[attr] = float(b.const)
                if bad(value, b.const):
                    fail("E313", f"parameter '{name}' = {X.fmt_num(value)} is {'below its minimum' if attr == 'min' else 'above its maximum'} {X.fmt_num(b.const)}",
                         (e.mod.value.span if e.mod.value is not None else e.decl.span),
                         f"change the value or the {attr} bound")
        return found.get("min"), found.get("max")

    def _coordinate(self, e: Entry, dims: tuple[int, ...]) -> Val:
        d = e.decl
        if e.mod.value is not None:
            fail("E214", f"coordinate '{d.name}' cannot have a value", e.mod.value.span,
                 f"give its start value: coordinate Real {d.name}(start = ...);")
        self._check_attrs(e.mod, COORD_ATTRS)
        factor, dim, unit = self._unit(e, e.mod)
        n = math.prod(dims) if dims else 1
        starts = self._attr_values(e.mod, "start", dims, dim, factor)
        speeds = self._attr_values(e.mod, "speed", dims, V.dim_div(dim, U.TIME) if dim else None, factor)
        fixed = self._attr_values(e.mod, "fixed", dims, None, 1.0, default=1.0)
        sfixed = self._attr_values(e.mod, "speed_fixed", dims, None, 1.0, default=1.0)
        items = []
        names = [d.name + _suffix(idx) for idx, _ in (_enumerate(None, dims) if dims else [((), None)])]
        for key, em in e.element_mods.items():
            if key not in names:
                fail("E204", f"coordinate '{d.name}' has no element '{key}' to modify", em.name_span or d.name_span,
                     f"elements: {names[0]} ... {names[-1]}" if names else "it has no elements")
            self._check_attrs(em, {"start", "speed", "fixed", "speed_fixed"})
            k = names.index(key)
            for attr, lst, adim, f in (("start", starts, dim, factor),
                                       ("speed", speeds, V.dim_div(dim, U.TIME) if dim else None, factor),
                                       ("fixed", fixed, None, 1.0), ("speed_fixed", sfixed, None, 1.0)):
                lst[k] = (self._attr_values(em, attr, (), adim, f, default=None) or [lst[k]])[0]
        for k, name in enumerate(names):
            e.coords.append(ir.Coordinate(name, starts[k], speeds[k], bool(constval(fixed[k])),
                                          bool(constval(sfixed[k])), unit, d.doc or "", None, d.name_span))
            items.append(Scalar(ir.Coord(name), dim))
        assert len(items) == n
        return _reshape(items, dims)

    def _attr_values(self, mod: Mod, attr: str, dims, dim, factor, default: float | None = 0.0) -> list[ir.Expr]:
        """One expression per element of `attr` (start, speed, ...); [] when absent and no default."""
        n = math.prod(dims) if dims else 1
        m = mod.sub.get(attr)
        if m is None or m.value is None:
            return [] if default is None else [X.const(default)] * n
        v = self.eval(m.value)
        if isinstance(v, Scalar) and dims:
            vals = [v] * n
        else:
            if V.shape_of(v) != dims:
                self.unsplit_array_mismatch(m.value.span, attr, dims, V.shape_of(v))
                fail("E301", f"'{attr}' has shape {_shape_text(V.shape_of(v))}, expected {_shape_text(dims)}",
                     m.value.span, "give one value for all elements, or one per element")
            vals = V.flatten(v) if dims else [v]
        out = []
        for s in vals:
            if not isinstance(s, Scalar):
                fail("E301", f"'{attr}' must be numeric", m.value.span, f"e.g. {attr} = 0")
            if X.depends_on_state(s.expr) or X.depends_on_time(s.expr):
                fail("E306", f"the {attr} value may only depend on parameters", m.value.span,
                     "start values are numbers or expressions in parameters")
            if dim is not None and attr in ("start", "speed"):
                self.check_dim(s, dim, f"the {attr} value", m.value.span)
            out.append(s.expr if factor == 1.0 or isinstance(s.dim, U.Dim) else X.mul(X.const(factor), s.expr))
        return out

    def _output(self, e: Entry, dims: tuple[int, ...]) -> Val:
        d = e.decl
        if e.mod.value is None:
            fail("E212", f"'{d.name}' has no definition", d.name_span,
                 f"define it where it is declared: {d.prefix + ' ' if d.prefix else ''}Real {d.name} = ...; "
                 "(equations in mechdsl are constraints, not definitions)")
        self._check_attrs(e.mod, {"unit", "displayUnit"})
        _, dim, unit = self._unit(e, e.mod)
        val = self.eval(e.mod.value)
        if isinstance(val, (Str, CompRef)):
            fail("E301", f"'{d.name}' must be numeric, got {V.describe_shape(val)}", e.mod.value.span,
                 "for a point's position use its .r attribute")
        if V.shape_of(val) != dims:
            fail("E301", f"'{d.name}' is declared with shape {_shape_text(dims)} but its value is "
                         f"{V.describe_shape(val)}", e.mod.value.span,
                 f"declare it as {d.type_name} {d.name}[{', '.join(map(str, V.shape_of(val)))}]" if V.shape_of(val)
                 else f"give a value of shape {_shape_text(dims)}")
        flat = V.flatten(val) if dims else [val]
        for s in flat:
            if dim is not None:
                self.check_dim(s, dim, f"'{d.name}'", e.mod.value.span)
        if e.kind == "output":
            for (idx, _), s in zip(_enumerate(None, dims) if dims else [((), None)], flat):
                e.outputs.append(ir.Output(d.name + _suffix(idx), s.expr, unit, d.doc or "", d.name_span))
        if dim is not None:
            return _reshape([Scalar(s.expr, dim, s.integer, s.boolean) for s in flat], dims)
        return val


def _quiet_numpy():
    import numpy as np

    return np.errstate(all="ignore")  # nan/inf are checked and reported as diagnostics


def _suffix(idx: tuple[int, ...]) -> str:
    return "" if not idx else "[" + ",".join(str(i + 1) for i in idx) + "]"


def _shape_text(s: tuple[int, ...]) -> str:
    return "scalar" if not s else "[" + ", ".join(map(str, s)) + "]"


def _enumerate(val: Val | None, dims: tuple[int, ...]):
    """(index tuple, scalar) pairs in row-major order."""
    if not dims:
        return [((), val)]
    idxs = [()]
    for n in dims:
        idxs = [i + (k,) for i in idxs for k in range(n)]
    out = []
    for idx in idxs:
        v = val
        if v is not None:
            for k in idx:
                v = v.items[k]  # type: ignore[union-attr]
        out.append((idx, v))
    return out


def _reshape(items: list[Val], dims: tuple[int, ...]) -> Val:
    if not dims:
        return items[0]

    def build(level: int, offset: int) -> tuple[Val, int]:
        if level == len(dims):
            return items[offset], offset + 1
        out = []
        for _ in range(dims[level]):
            v, offset = build(level + 1, offset)
            out.append(v)
        return Arr(tuple(out)), offset

    return build(0, 0)[0]
