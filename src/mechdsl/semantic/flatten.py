"""Phase 2, ``analyze``: one model definition (+ outer modifications) -> :class:`ir.Model`.

Declarations are registered first (extends expanded, modifications merged), then evaluated
lazily on demand with cycle detection, so declaration order never matters for meaning; the
output keeps declaration order everywhere.  Errors are collected per declaration/equation
and reported together.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from .. import ast
from .. import exprs as X
from .. import ir
from .. import limits
from .. import units as U
from ..diagnostics import Diagnostic, DiagnosticBag, MechError, Span, did_you_mean
from ..printer import expr as print_expr
from . import components as K
from . import instances as Inst
from . import mods as Mods
from . import values as V
from .evaluate import BUILTIN_NAMES, EvalError, Evaluator, fail
from .constraint_names import constraint_name
from .friction import friction_force
from .mods import Mod
from .values import ANY, Arr, CompRef, Scalar, Str, Val, ValError
from .instance_arrays import InstanceArrays
from .vector_starts import VECTOR_STARTS, VectorStarts

SCALAR_TYPES = {"Real", "Integer", "Boolean"}
PARAM_ATTRS = {"unit", "min", "max", "displayUnit"}
COORD_ATTRS = {"start", "speed", "fixed", "speed_fixed", "unit", "displayUnit", "min", "max"}
FIELD_RANK = {"scalar": 0, "vec3": 1, "mat3": 2, "point": 0, "body": 0, "bodies": 1, "coordinate": 0,
              "string": 0, "bool": 0}
RESERVED_NAMES = {"time", "world"}


@dataclass
class Entry:
    decl: ast.Declaration
    kind: str                       # parameter input coordinate output variable component
    mod: Mod
    order: int
    cls: K.ComponentClass | None = None
    dims: tuple[int, ...] | None = None
    value: Val | None = None
    state: int = 0                  # 0 new, 1 busy, 2 done, 3 failed
    params: list[ir.Parameter] = field(default_factory=list)
    coords: list[ir.Coordinate] = field(default_factory=list)
    outputs: list[ir.Output] = field(default_factory=list)
    elements: list["CompInst"] = field(default_factory=list)
    cache: dict = field(default_factory=dict)   # evaluated array-level modifier values
    element_mods: dict = field(default_factory=dict)   # "q[2]" -> Mod: an override of one element (API, --set)


_BUDGET = {"coordinate": "coordinates", "output": "outputs", "component": "components"}  # kind -> limit


@dataclass
class CompInst:
    name: str
    entry: Entry
    k: int                          # element index (0-based), -1 for scalar components
    connections: dict[str, Val] = field(default_factory=dict)
    fields: dict[str, Val] = field(default_factory=dict)
    jointvars: list[ir.JointVar] | None = None
    coords: list[ir.Coordinate] = field(default_factory=list)
    built: K.Built | None = None
    busy: set = field(default_factory=set)

    @property
    def cls(self) -> K.ComponentClass:
        return self.entry.cls  # type: ignore[return-value]


class _Failed(Exception):
    """An entry already reported an error; dependants stay quiet."""


class Flattener(InstanceArrays, VectorStarts, Evaluator):
    Failed = _Failed           # for the mixins (instance_arrays.py, vector_starts.py)

    def __init__(self, program, model: ast.ModelDef, outer: dict[str, Mod] | None = None):
        self.program = program
        self.model = model
        self.diags = DiagnosticBag()
        self.used: dict[str, int] = {}  # budgets charged so far (limits.py): coordinates, outputs, ...
        self.loop_vars: dict[str, int] = {}
        self.entries: dict[str, Entry] = {}
        self.equations: list[ast.EquationItem] = []
        self.param_values: dict[str, float] = {}
        self.input_names: set[str] = set()      # declared inputs (a parameter must not depend on one)
        self.insts: dict[str, CompInst] = {}
        self.constraints: list[ir.Constraint] = []
        self.terms: list[ir.Term] = []
        self.gen_forces: list[ir.GeneralizedForce] = []
        self.joint_frames: set[str] = set()     # joints without a child whose massless frame is used
        self.connect_failed = False     # a connect(...) was reported: missing parent/child stay quiet
        self.instances: dict[str, ast.Declaration] = {}   # model instances, by (prefixed) name
        self.instance_arrays: dict[str, int] = {}         # arrays of model instances: name -> size
        self._collect(model, outer or {}, [])
        self._check_modified_names(outer or {}, model.name)

    # ================================================================== declarations
    def _collect(self, m: ast.ModelDef, outer: dict[str, Mod], chain: list[str], prefix: str = "",
                 names: set[str] | None = None) -> None:
        """Register m's declarations and equations; `prefix` (e.g. 's.') when m is an instance `s`,
        `names`: the instance's own names, renamed with the prefix (m's, or a derived model's)."""
        if m.name in chain:
            what = "extends or contains" if prefix else "extends"
            self.diags.error("E207", f"model '{m.name}' {what} itself (through {' -> '.join(chain + [m.name])})",
                             m.name_span, "remove one of the extends clauses or instances in the cycle")
            return
        chain = chain + [m.name]
        if prefix and names is None:
            names = Inst.declared_names(self.program, m)
        own_names = {prefix + e.name for e in m.elements if isinstance(e, ast.Declaration)}
        for el in m.elements:
            if isinstance(el, ast.Extends):
                base = self.program.model_def(el.name)
                if base is None:
                    self.diags.error("E206", f"unknown model '{el.name}' in extends", el.span,
                                     did_you_mean(el.name, self.program.model_names())
                                     or f"models in this file: {', '.join(self.program.model_names())}")
                    continue
                ext = Mods.from_ast(Inst.rename(el.modification, names or set(), prefix), self.diags)
                ext = {prefix + k: v for k, v in ext.items()}
                # modifications for inherited names: extends-clause, then ours (outer) on top
                passed = Mods.merge_dicts(ext, {k: v for k, v in outer.items() if k not in own_names})
                self._collect(base, passed, chain, prefix, names)
                self._check_modified_names(ext, base.name, prefix)
        for el in m.elements:
            if isinstance(el, ast.Declaration):
                d = Inst.rename(el, names or set(), prefix)
                if self.program.model_def(d.type_name) is not None and d.type_name not in K.CLASSES:
                    self._instance(d, outer, chain)
                else:
                    self._declare(d, outer)
        self.equations.extend(Inst.rename(m.equations, names or set(), prefix))

    def _instance(self, d: ast.Declaration, outer: dict[str, Mod], chain: list[str]) -> None:
        """`Sub s(mods);`: Sub's declarations and equations are added as s.x, with mods on top."""
        sub = self.program.model_def(d.type_name)
        problem = None
        if d.prefix is not None:
            problem = ("E215", f"'{d.prefix}' cannot be applied to a model instance", d.span, f"remove '{d.prefix}'")
        elif len(d.dims) > 1:
            problem = ("E301", "arrays of model instances have one dimension", d.dims[1].span,
                       f"write {d.type_name} {d.name}[n](...)")
        elif d.value is not None:
            problem = ("E214", f"a model instance takes modifiers, not a value", d.value.span,
                       f"write {d.type_name} {d.name}(parameter = ...)")
        elif d.name in self.entries or d.name in self.instances:
            problem = ("E202", f"'{d.name}' is declared twice", d.name_span, "rename one of them")
        if problem:
            self.diags.error(*problem)
            return
        if d.dims:
            self._instance_array(d, outer, chain)
            return
        self.instances[d.name] = d
        mod = Mods.merge(Mod(sub=Mods.from_ast(d.modification, self.diags), span=d.span, name_span=d.name_span),
                         outer.get(d.name))
        inner = {f"{d.name}.{k}": v for k, v in mod.sub.items()}
        self._collect(sub, inner, chain, d.name + ".")  # type: ignore[arg-type]
        self._check_modified_names(inner, sub.name, d.name + ".")  # type: ignore[union-attr]

    def _check_modified_names(self, mods: dict[str, Mod], model_name: str, prefix: str = "") -> None:
        """A modification (scene, extends, API override) must name a declaration of the model."""
        for k, m in mods.items():
            base = k.split("[", 1)[0]
            if "[" in k and base in self.entries and self.entries[base].kind == "coordinate":
                continue                    # an element's start (q[2].start): checked where q is built
            if k not in self.entries and k not in self.instances:
                local = k[len(prefix):] if k.startswith(prefix) else k
                own = self._own(prefix[:-1]) if prefix else list(self.entries)
                self.diags.error("E204", f"model '{model_name}' has no declaration '{local}' to modify", m.name_span,
                                 did_you_mean(local, own) or "modify its parameters and start values")

    def _declare(self, d: ast.Declaration, outer: dict[str, Mod]) -> None:
        if d.name in self.instances:
            self.diags.error("E202", f"'{d.name}' is declared twice (first at line "
                                     f"{self.instances[d.name].name_span.line})", d.name_span, "rename one of them")
            return
        if d.name in self.entries:
            prev = self.entries[d.name].decl
            self.diags.error("E202", f"'{d.name}' is declared twice (first at line {prev.name_span.line})",
                             d.name_span, "rename one of them")
            return
        if d.name in RESERVED_NAMES:
            self.diags.error("E216", f"'{d.name}' is a built-in name and cannot be declared", d.name_span,
                             "choose another name")
            return
        mod = Mods.merge(Mod(value=d.value, sub=Mods.from_ast(d.modification, self.diags), span=d.span,
                             name_span=d.name_span), outer.get(d.name))
        cls = None
        if d.type_name in SCALAR_TYPES:
            kind = {"parameter": "parameter", "constant": "parameter", "input": "input",
                    "coordinate": "coordinate", "output": "output", None: "variable"}[d.prefix]
            if d.type_name != "Real" and kind in ("coordinate", "input"):
                self.diags.error("E215", f"{'an' if d.prefix == 'input' else 'a'} {d.prefix} must be Real, "
                                         f"not {d.type_name}", d.span,
                                 f"declare it as {d.prefix} Real {d.name}")
                return
            if d.type_name != "Real" and kind == "variable":
                kind = "parameter"
        else:
            cls = K.CLASSES.get(d.type_name)
            if cls is None:
                types = list(K.CLASSES) + sorted(SCALAR_TYPES) + self.program.model_names()
                self.diags.error("E203", f"unknown type '{d.type_name}'", d.span,
                                 did_you_mean(d.type_name, types)
                                 or "built-in types: " + ", ".join(sorted(K.CLASSES)))
                return
            if d.prefix is not None:
                self.diags.error("E215", f"'{d.prefix}' applies to Real, Integer and Boolean declarations, "
                                         f"not to a {d.type_name}", d.span, f"remove '{d.prefix}'")
                return
            if d.value is not None:
                self.diags.error("E214", f"a {d.type_name} takes modifiers, not a value", d.value.span,
                                 f"write {d.type_name} {d.name}(field = ...)")
                return
            kind = "component"
        self.entries[d.name] = Entry(d, kind, mod, len(self.entries), cls,
                                     element_mods={k: v for k, v in outer.items() if k.startswith(d.name + "[")})

    # ================================================================== lookup
    def known_names(self) -> list[str]:
        return list(self.entries) + sorted(BUILTIN_NAMES) + list(self.loop_vars)

    # ------------------------------------------------------------------ units
    def check_dim(self, s: Val, expected: U.Dim, what: str, span: Span) -> None:
        """A dimension check with its span: an error, or a warning when it rests on a decimal literal."""
        try:
            V.check_val_dim(s, expected, what)
        except ValError as ve:
            fail(ve.code, ve.message, span, ve.help)
        sink = V.WARNINGS.get()
        if sink:
            self.note_warnings(list(sink), span)
            sink.clear()

    def note_warnings(self, items, span: Span) -> None:
        for code, message, help in items:
            if not any(w.code == code and w.message == message and w.span == span for w in self.diags.warnings):
                self.diags.warning(code, message, span, help)

    def lookup(self, name: str, span: Span) -> Val:
        if name in self.loop_vars:
            return V.const(self.loop_vars[name], integer=True)
        if name in self.entries:
            return self.value_of(self.entries[name], span)
        if name == "time":
            return Scalar(ir.Time(), U.TIME)
        if name == "pi":
            return Scalar(ir.Const(math.pi), ANY)
        if name == "world":
            return CompRef("world", "world", "World")
        if name in self.instances:
            fail("E201", f"'{name}' is a model instance ({self.instances[name].type_name}), not a value", span,
                 f"refer to one of its declarations, e.g. {name}.{next(iter(self._own(name)), 'x')}")
        fail("E201", f"undefined name '{name}'", span,
             did_you_mean(name, self.known_names()) or f"declare it, e.g. `parameter Real {name} = ...;`")
        raise AssertionError

    def eval_ref(self, r: ast.Ref) -> Val:
        """`s.x.y` where `s` is a model instance: the longest declared name `s.x` first, then fields;
        `links[i].x` where `links` is an array of instances: element i's `x`."""
        r = self._instance_element(r)
        if len(r.parts) > 1 and r.parts[0].name in self.instances and not r.parts[0].subscripts:
            names = [p.name for p in r.parts]
            for k in range(len(r.parts), 1, -1):
                joined = ".".join(names[:k])
                if joined in self.entries and all(not p.subscripts for p in r.parts[:k - 1]):
                    last = r.parts[k - 1]
                    val = self.index(self.lookup(joined, last.span), last.subscripts, last.span, joined)
                    for part in r.parts[k:]:
                        val = self.attribute(val, part.name, part.span)
                        val = self.index(val, part.subscripts, part.span, part.name)
                    return val
            head = next((k for k in range(len(names) - 1, 0, -1) if ".".join(names[:k]) in self.instances), 1)
            inst, rest = ".".join(names[:head]), names[head]
            own = self._own(inst)
            fail("E201", f"model instance '{inst}' has no declaration '{rest}'", r.parts[head].span,
                 did_you_mean(rest, own) or f"declarations of {inst}: {', '.join(own[:8])}")
        return super().eval_ref(r)

    def _own(self, inst: str) -> list[str]:
        return [n[len(inst) + 1:] for n in self.entries if n.startswith(inst + ".")]

    def value_of(self, entry: Entry, span: Span | None = None) -> Val:
        if entry.state == 2:
            return entry.value  # type: ignore[return-value]
        if entry.state == 3:
            raise _Failed()
        if entry.state == 1:
            fail("E208", f"'{entry.decl.name}' is defined in terms of itself", span or entry.decl.name_span,
                 "break the cycle of definitions")
        entry.state = 1
        try:
            entry.value = self._evaluate_entry(entry)
            entry.state = 2
        except EvalError as e:
            entry.state = 3
            self.diags.items.append(e.diag)
            raise _Failed() from None
        except ValError as ve:  # raised outside an expression (e.g. the shape of a ragged array)
            entry.state = 3
            at = entry.mod.value.span if entry.mod.value is not None else entry.decl.span
            self.diags.error(ve.code, ve.message, at, ve.help)
            raise _Failed() from None
        except _Failed:
            entry.state = 3
            raise
        return entry.value

    def entry_dims(self, entry: Entry) -> tuple[int, ...]:
        if entry.dims is None:
            dims = []
            for d in entry.decl.dims:
                n = self.int_value(d, "an array size")
                if n < 0:
                    fail("E307", f"array size {n} is negative", d.span, "array sizes are 0 or more")
                dims.append(n)
                if math.prod(dims) > limits.get("arrays"):
                    fail("E303", f"array '{entry.decl.name}' would have more than {limits.get('arrays')} elements",
                         d.span, "use a smaller size; " + limits.hint("arrays"))
            span = entry.decl.dims[-1].span if entry.decl.dims else entry.decl.name_span
            for budget in (_BUDGET.get(entry.kind), None if entry.kind == "component" else "scalars"):
                if budget:
                    self.charge(budget, math.prod(dims), span)
            entry.dims = tuple(dims)
        return entry.dims

    def charge(self, budget: str, n: int, span: Span, total: int | None = None) -> None:
        """Count `n` more coordinates/outputs/components/scalars against the model's budget.

        `total` replaces the running count (the built model's exact number).  An excess (E316)
        stops the analysis of the model at once: going on is the work the budget bounds."""
        used = self.used[budget] = self.used.get(budget, 0) + n if total is None else total
        if used > limits.get(budget):
            self.diags.error("E316", f"model '{self.model.name}' has more than {limits.get(budget):,} "
                                     f"{limits.LIMITS[budget].meaning.split(' of ')[0]}", span,
                             "mechdsl derives and compiles every scalar symbolically; " + limits.hint(budget))
            self.diags.raise_if_errors()

    # ================================================================== entries
    def _evaluate_entry(self, e: Entry) -> Val:
        dims = self.entry_dims(e)
        if e.kind in ("parameter", "input"):
            return self._parameter(e, dims)
        if e.kind == "coordinate":
            return self._coordinate(e, dims)
        if e.kind in ("output", "variable"):
            return self._output(e, dims)
        return self._component(e, dims)

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
        val = self.eval(e.mod.value)
        if isinstance(val, (Str, CompRef)):
            fail("E301", f"parameter '{d.name}' must be a number, got {V.describe_shape(val)}", e.mod.value.span,
                 "parameters hold numbers, vectors or matrices")
        want = dims
        got = V.shape_of(val)
        if got != want:
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
        structural = d.type_name in ("Integer", "Boolean")
        out_items = []
        for idx, s in _enumerate(val, dims):
            name = d.name + _suffix(idx)
            if structural:
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
                out_items.append(Scalar(ir.Const(float(s.const)), U.ONE if d.type_name == "Boolean" else ANY,
                                        integer=d.type_name == "Integer", boolean=d.type_name == "Boolean"))
                continue
            binding = s.expr if factor == 1.0 else X.mul(X.const(factor), s.expr)
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
            out_items.append(Scalar(ir.Param(name), dim if dim is not None else None))
        return _reshape(out_items, dims)

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
            e.coords.append(ir.Coordinate(name, starts[k], speeds[k], bool(_constval(fixed[k])),
                                          bool(_constval(sfixed[k])), unit, d.doc or "", None, d.name_span))
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
            out.append(s.expr if factor == 1.0 else X.mul(X.const(factor), s.expr))
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

    # ================================================================== components
    def _component(self, e: Entry, dims: tuple[int, ...]) -> Val:
        d = e.decl
        if len(dims) > 1:
            fail("E301", "arrays of components have one dimension", d.span, f"write {d.type_name} {d.name}[n](...)")
        cartesian = {"x", "y", "z"} if e.cls.name == "PointMass" and ("r" in e.mod.sub or "v" in e.mod.sub) else set()
        allowed = {f.name for f in e.cls.fields} | {r for r, _ in e.cls.roles} | set(VECTOR_STARTS.get(e.cls.name, ())) | cartesian | (
            {r for r, _ in K.QUATERNION_ROLES} if e.cls.name in ("Spherical", "Free") else set())
        for k, m in e.mod.sub.items():
            if k not in allowed:
                fail("E204", f"{e.cls.name} has no field '{k}'", m.name_span,
                     did_you_mean(k, allowed) or "fields: " + ", ".join(f.name for f in e.cls.fields))
        if not e.elements:
            if dims:
                e.elements = [CompInst(f"{d.name}[{k + 1}]", e, k) for k in range(dims[0])]
            else:
                e.elements = [CompInst(d.name, e, -1)]
            for inst in e.elements:
                self.insts[inst.name] = inst
        kind = {"body": "body", "point": "point", "frame": "body", "joint": "joint", "force": "force",
                "contact": "contact"}[e.cls.category]
        refs = [CompRef(kind, i.name, e.cls.name) for i in e.elements]
        return Arr(tuple(refs)) if dims else refs[0]

    def _elements(self, e: Entry) -> list[CompInst]:
        self.value_of(e)
        return e.elements

    def field_value(self, inst: CompInst, fname: str) -> Val | None:
        """The value of one field of a component element (None when optional and absent)."""
        if fname in inst.fields:
            return inst.fields[fname]
        cls = inst.cls
        f = cls.field(fname)
        assert f is not None, fname
        if fname in inst.connections:
            val = inst.connections[fname]
        else:
            m = inst.entry.mod.sub.get(fname)
            if m is not None and m.value is not None:
                key = ("field", fname)
                if (fname, "busy") in inst.busy:
                    fail("E208", f"'{inst.name}.{fname}' is defined in terms of itself", m.value.span,
                         "break the cycle of definitions")
                inst.busy.add((fname, "busy"))
                try:
                    if key not in inst.entry.cache:
                        inst.entry.cache[key] = self.eval(m.value)
                finally:
                    inst.busy.discard((fname, "busy"))
                val = _pick(inst.entry.cache[key], inst, FIELD_RANK[f.kind], m.each)
                val = self._frame_of_joint(val, f, m.value.span)
                self._check_field(inst, f, val, m.value.span)
            elif f.default is K.REQUIRED:
                hint = None
                if cls.connect_fields and fname in cls.connect_fields and self.connect_failed:
                    raise _Failed()  # most likely set by the connect(...) already reported
                if cls.connect_fields and fname in cls.connect_fields:
                    hint = f"set it with {fname} = ..., or connect({cls.connect_fields[0]}, {inst.entry.decl.name}, " \
                           f"{cls.connect_fields[1]}) in the equation section"
                fail("E210", f"{cls.name} '{inst.name}' needs '{fname}'", inst.entry.decl.name_span,
                     hint or f"add {fname} = ... to its modifiers")
                raise AssertionError
            elif f.default is None:
                val = None
            elif f.default == "world":
                val = CompRef("world", "world", "World")
            else:
                val = K.python_to_val(f.default)
        inst.fields[fname] = val
        return val

    def _frame_of_joint(self, val: Val, f: K.Field | None, span: Span) -> Val:
        """A joint named where a body or point is expected (`parent = turn`) means the joint's
        own massless frame, when the joint has no child of its own (issue 17)."""
        if not (isinstance(val, CompRef) and val.kind == "joint") or (f is not None and f.kind not in ("point", "body")):
            return val
        inst = self.insts.get(val.name)
        if inst is None or inst.cls.field("child") is None:
            return val
        child = self.field_value(inst, "child")
        if child is not None:
            fail("E209", f"joint '{val.name}' has the child '{child.name}' (a joint is not a point)", span,  # type: ignore[union-attr]
                 f"name its child ({child.name}) or a point on it; a joint without a child is a massless frame"  # type: ignore[union-attr]
                 " that others can use")
        self.joint_frames.add(val.name)
        return CompRef("body", val.name, "JointFrame")

    def _check_field(self, inst: CompInst, f: K.Field, val: Val, span: Span) -> None:
        try:
            if f.kind in ("point", "body"):
                if not isinstance(val, CompRef):
                    fail("E209", f"'{f.name}' of {inst.cls.name} '{inst.name}' must be a {f.kind}, "
                                 f"got {V.describe_shape(val)}", span,
                         "name a body, a point on a body (e.g. rod.a) or world" if f.kind == "point"
                         else "name a body or world")
                ok = {"point": ("point", "body", "world"), "body": ("body", "world")}[f.kind]
                if val.kind not in ok:
                    fail("E209", f"'{f.name}' of '{inst.name}' must be a {f.kind}, got the {val.kind} '{val.name}'", span,
                         "name a body, a point on a body (e.g. rod.a) or world" if f.kind == "point"
                         else "name a body or world")
            elif f.kind == "bodies":
                items = val.items if isinstance(val, Arr) else ()
                if not items or not all(isinstance(i, CompRef) and i.kind == "body" for i in items):
                    fail("E209", f"'{f.name}' must be a list of bodies", span, "e.g. bodies = {sun, earth}")
            elif f.kind == "string":
                if not isinstance(val, Str):
                    fail("E301", f"'{f.name}' must be a string", span,
                         f'{f.name} = "{f.choices[0] if f.choices else "..."}"')
                if f.choices and val.value not in f.choices:
                    fail("E217", f"'{val.value}' is not a valid {f.name}", span,
                         "choose one of: " + ", ".join(f.choices))
            elif f.kind == "coordinate":
                if not (isinstance(val, Scalar) and isinstance(val.expr, ir.Coord)):
                    fail("E218", f"'{f.name}' must be a coordinate", span, "name a `coordinate` or a joint variable such as j1.phi")
            elif f.kind in ("scalar", "bool"):
                if not isinstance(val, Scalar):
                    fail("E301", f"'{f.name}' of '{inst.name}' must be a scalar, got {V.describe_shape(val)}", span,
                         "give one number or expression")
                if f.dim is not None:
                    self.check_dim(val, f.dim, f"'{f.name}' of '{inst.name}'", span)
            elif f.kind in ("vec3", "mat3"):
                want = (3,) if f.kind == "vec3" else (3, 3)
                if not isinstance(val, Arr) or V.shape_of(val) != want:
                    fail("E301", f"'{f.name}' of '{inst.name}' must be {'a vector of 3' if f.kind == 'vec3' else 'a 3x3 matrix'}, "
                                 f"got {V.describe_shape(val)}", span,
                         "write it as {x, y, z}" if f.kind == "vec3" else "write it as {{..}, {..}, {..}}")
                if f.dim is not None:
                    for s in V.flatten(val):
                        self.check_dim(s, f.dim, f"'{f.name}' of '{inst.name}'", span)
        except ValError as ve:
            fail(ve.code, ve.message, span, ve.help)

    # ------------------------------------------------------------------ attributes
    def attribute(self, value: Val, name: str, span: Span) -> Val:
        if isinstance(value, Arr):
            return Arr(tuple(self.attribute(v, name, span) for v in value.items))
        if not isinstance(value, CompRef):
            fail("E219", f"{V.describe_shape(value)} has no attribute '{name}'", span,
                 "attributes (.x, .r, .R, .phi, ...) belong to components")
        if value.kind == "world":
            zero = V.const(0.0)
            table = {"r": Arr((zero,) * 3), "v": Arr((zero,) * 3), "a": Arr((zero,) * 3), "x": zero, "y": zero,
                     "z": zero, "w": Arr((zero,) * 3), "w_body": Arr((zero,) * 3), "alpha": Arr((zero,) * 3), "R": Arr(tuple(Arr(tuple(V.const(float(i == j)) for j in range(3)))
                                                        for i in range(3)))}
            if name in table:
                return table[name]
            fail("E219", f"world has no attribute '{name}'", span, "world has r, v, a, x, y, z, R, w, w_body, alpha")
        if value.kind == "joint" and name in ("r", "v", "a", "x", "y", "z", "R", "w", "w_body", "alpha"):
            jinst = self.insts.get(value.name)     # a child-less joint's frame; a joint variable (f.x) wins
            if (jinst is not None and jinst.cls.field("child") is not None and self.field_value(jinst, "child") is None
                    and name not in [jv.role for jv in self.joint_vars(jinst)]):
                value = self._frame_of_joint(value, None, span)
        if value.kind in ("point", "body"):
            inst = self.insts.get(value.name)
            if inst is not None and name in inst.cls.points:   # rod.a is Rod's end point a, not an acceleration
                return CompRef("point", f"{inst.name}.{name}", "Point")
            kin = _kinematic_attr(value, name)
            if kin is not None:
                return kin
        inst = self.insts.get(value.name)
        if inst is None:  # a named point of a body (rod.a) or a derived point
            fail("E219", f"'{value.name}' has no attribute '{name}'", span, "points have r, v, a, x, y, z")
        cls = inst.cls
        if name in cls.points:
            return CompRef("point", f"{inst.name}.{name}", "Point")
        if cls.category == "joint":
            for jv in self.joint_vars(inst):
                if jv.role == name:
                    dim = dict(cls.roles + K.QUATERNION_ROLES).get(name)
                    return Scalar(jv.motion, dim)
        f = cls.field(name)
        if f is not None:
            val = self.field_value(inst, name)
            if val is None:
                fail("E219", f"'{inst.name}.{name}' is not set", span, f"give it a value: {name} = ... in the modifiers")
            return val
        roles = [jv.role for jv in self.joint_vars(inst)] if cls.category == "joint" else []
        opts = list(cls.points) + [f.name for f in cls.fields] + roles
        if cls.category in ("body", "point", "frame"):
            opts += ["r", "v", "a", "x", "y", "z"] + (["R", "w", "w_body", "alpha"] if cls.category != "point" else [])
        fail("E219", f"{cls.name} '{inst.name}' has no attribute '{name}'", span,
             did_you_mean(name, opts) or ("attributes: " + ", ".join(dict.fromkeys(opts)) if opts else None))
        raise AssertionError

    # ------------------------------------------------------------------ joints
    def joint_vars(self, inst: CompInst) -> list[ir.JointVar]:
        if inst.jointvars is not None:
            return inst.jointvars
        if ("jointvars", "busy") in inst.busy:
            fail("E208", f"the variables of joint '{inst.name}' are defined in terms of themselves",
                 inst.entry.decl.name_span, "break the cycle of definitions")
        inst.busy.add(("jointvars", "busy"))
        try:
            cls = inst.cls
            param = "euler"
            if cls.field("parametrization") is not None:
                param = self.field_value(inst, "parametrization").value  # type: ignore[union-attr]
            child = self.field_value(inst, "child")
            point_mass_child = isinstance(child, CompRef) and self._body_class_of(child) == "PointMass"
            roles = K.joint_roles(cls, param, point_mass_child)
            out: list[ir.JointVar] = []
            for role, dim in roles:
                m = inst.entry.mod.sub.get(role)
                if m is not None and m.value is not None:
                    key = ("role", role)
                    if key not in inst.entry.cache:
                        inst.entry.cache[key] = self.eval(m.value)
                    v = _pick(inst.entry.cache[key], inst, 0, m.each)
                    if not isinstance(v, Scalar):
                        fail("E301", f"joint variable '{role}' of '{inst.name}' must be a scalar, "
                                     f"got {V.describe_shape(v)}", m.value.span,
                             f"bind it to a coordinate ({role} = q) or a function of time ({role} = omega*time)")
                    self.check_dim(v, dim, f"'{role}' of '{inst.name}'", m.value.span)
                    if X.has_speed(v.expr):
                        fail("E308", f"joint variable '{role}' of '{inst.name}' depends on speeds", m.value.span,
                             "a joint's motion may depend on coordinates and time only")
                    if m.sub:
                        fail("E214", f"'{role}' of '{inst.name}' is bound to an expression", m.span,
                             "set start values on the coordinate itself: coordinate Real q(start = ...)")
                    coord = v.expr.name if isinstance(v.expr, ir.Coord) else None
                    out.append(ir.JointVar(role, v.expr, coord))
                    continue
                c = self._own_coordinate(inst, role, "rad" if dim == U.ONE else "m", inst.name,
                                         {"start": X.const(1.0 if role == "q0" else 0.0)})
                inst.coords.append(c)
                out.append(ir.JointVar(role, ir.Coord(c.name), c.name))
            self._vector_starts(inst, out, param)
            inst.jointvars = out
            return out
        finally:
            inst.busy.discard(("jointvars", "busy"))

    def _own_coordinate(self, inst: CompInst, role: str, unit: str, owner: str, defaults: dict) -> ir.Coordinate:
        """The coordinate `<inst>.<role>` a component owns, with the attributes of its modifier
        `role(start = .., speed = .., fixed = .., speed_fixed = ..)` over `defaults`."""
        m = inst.entry.mod.sub.get(role)
        sub = m.sub if m is not None else {}
        self._check_attrs(Mod(sub=sub), COORD_ATTRS)
        name = f"{inst.name}.{role}"
        vals = {"start": X.const(0.0), "speed": X.const(0.0), "fixed": X.const(1.0), "speed_fixed": X.const(1.0)}
        vals.update(defaults)
        for attr in vals:
            sm = sub.get(attr)
            if sm is None or sm.value is None:
                continue
            key = ("role", role, attr)
            if key not in inst.entry.cache:
                inst.entry.cache[key] = self.eval(sm.value)
            v = _pick(inst.entry.cache[key], inst, 0, sm.each)
            if not isinstance(v, Scalar):
                fail("E301", f"{attr} of '{name}' must be a scalar", sm.value.span, f"e.g. {role}({attr} = 0)")
            if X.depends_on_state(v.expr) or X.depends_on_time(v.expr):
                fail("E306", f"the {attr} value may only depend on parameters", sm.value.span,
                     "start values are numbers or expressions in parameters")
            vals[attr] = v.expr
        return ir.Coordinate(name, vals["start"], vals["speed"], bool(_constval(vals["fixed"])),
                             bool(_constval(vals["speed_fixed"])), unit, "", owner, inst.entry.decl.name_span)

    def _body_class_of(self, ref: CompRef) -> str:
        base = ref.name
        inst = self.insts.get(base)
        if inst is None and "." in base:
            inst = self.insts.get(base.rsplit(".", 1)[0])
        if inst is None:
            return ""
        if inst.cls.name == "Point":
            b = self.field_value(inst, "body")
            return self._body_class_of(b) if isinstance(b, CompRef) and b.name != inst.name else ""
        return inst.cls.name

    def body_of_point(self, pname: str) -> str:
        """The body a point name lies on ('world' for world points)."""
        if pname == "world":
            return "world"
        inst = self.insts.get(pname)
        if inst is not None:
            if inst.cls.name == "Point":
                b = self.field_value(inst, "body")
                return self.body_of_point(b.name)  # type: ignore[union-attr]
            return inst.name
        return self.body_of_point(pname.rsplit(".", 1)[0])

    # ================================================================== equations
    def run_connects(self) -> None:
        """connect(...) equations first: they complete components before anything reads their fields."""
        for eq in self.equations:
            if not self._guard(lambda eq=eq: self._equation(eq, connects=True), eq.span):
                self.connect_failed = True

    def run_equations(self) -> None:
        for eq in self.equations:
            self._guard(lambda eq=eq: self._equation(eq, connects=False), eq.span)

    def _guard(self, fn, span: Span) -> bool:
        try:
            fn()
            return True
        except EvalError as e:
            self.diags.items.append(e.diag)
        except _Failed:
            pass
        except ValError as ve:
            self.diags.error(ve.code, ve.message, span, ve.help)
        return False

    def _equation(self, eq, connects: bool) -> None:
        if isinstance(eq, ast.ForEquation):
            if not _has_work(eq, connects):
                return  # each pass runs only the loops that hold its kind of equation
            if eq.var in self.entries:
                fail("E202", f"loop variable '{eq.var}' hides the declaration of the same name", eq.span,
                     "rename the loop variable")
            values = self.range_values(eq.range)
            for i in values:
                self.loop_vars[eq.var] = i
                try:
                    for item in eq.body:
                        self._equation(item, connects)
                finally:
                    del self.loop_vars[eq.var]
            return
        if isinstance(eq, ast.Connect):
            if connects:
                self._connect(eq)
            return
        if connects:
            return
        if isinstance(eq, ast.EnergyEquation):
            v = self.eval(eq.expr)
            if not isinstance(v, Scalar):
                fail("E301", f"the {eq.kind} energy must be a scalar, got {V.describe_shape(v)}", eq.expr.span,
                     "for a vector v use dot(v, v)")
            want = U.POWER if eq.kind == "dissipation" else U.ENERGY
            self.check_dim(v, want, f"the {eq.kind} {'function' if eq.kind == 'dissipation' else 'energy'}",
                           eq.expr.span)
            if eq.kind == "potential" and X.has_speed(v.expr):
                fail("E308", "the potential energy must not depend on speeds", eq.expr.span,
                     "velocity-dependent forces go into force(q) = ... or the dissipation function")
            if any(isinstance(n, ir.EnergyRef) for n in X.walk(v.expr)) or X.needs_dynamics(v.expr):
                fail("E308", f"the {eq.kind} energy cannot refer to energies, reactions or accelerations", eq.expr.span,
                     "write the expression itself; kinetic_energy() etc. are for outputs")
            self.terms.append(ir.Term(eq.kind, v.expr, f"{eq.kind}@{eq.span.line}", eq.span))
            return
        if isinstance(eq, ast.ForceEquation):
            c = self.eval(eq.coordinate)
            if not (isinstance(c, Scalar) and isinstance(c.expr, ir.Coord)):
                fail("E218", f"force(...) needs a coordinate, got {print_expr(eq.coordinate)}", eq.coordinate.span,
                     "force(q) = ... names a `coordinate` or a joint variable such as j1.phi")
            q = self.eval(eq.expr)
            if not isinstance(q, Scalar):
                fail("E301", "a generalized force must be a scalar", eq.expr.span, "one equation per coordinate: force(q) = Q;")
            if isinstance(c.dim, U.Dim):
                self.check_dim(q, U.ENERGY / c.dim, f"the generalized force on {c.expr.name}", eq.expr.span)
            self.gen_forces.append(ir.GeneralizedForce(f"force({c.expr.name})", c.expr.name, q.expr, eq.span))
            return
        if isinstance(eq, ast.SimpleEquation):
            lhs, rhs = self.eval(eq.lhs), self.eval(eq.rhs)
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
                alias = f"c{len(self.constraints) + 1}"
                nm = constraint_name(eq.doc, self.loop_vars.values(), k if len(items) > 1 else None,
                                     self.constraints) or alias
                self.constraints.append(ir.Constraint(nm, s.expr, text + (f" [{k + 1}]" if len(items) > 1 else ""),
                                                      eq.span, alias=alias))
            return
        raise AssertionError(type(eq))

    def _connect(self, eq: ast.Connect) -> None:
        el = self.eval(eq.element)
        if not isinstance(el, CompRef) or el.name not in self.insts:
            fail("E209", f"connect(a, element, b) needs a joint, spring or damper as its second argument, got "
                         f"{print_expr(eq.element)}", eq.element.span, "e.g. connect(rod1.b, j2, rod2.a)")
        inst = self.insts[el.name]
        names = inst.cls.connect_fields
        if names is None:
            fail("E209", f"a {inst.cls.name} cannot be connected", eq.element.span,
                 "connect joints, springs and dampers between two points")
        for fname, ref in zip(names, (eq.a, eq.b)):
            if fname in inst.connections or (inst.entry.mod.sub.get(fname) and inst.entry.mod.sub[fname].value is not None):
                fail("E211", f"'{fname}' of '{inst.name}' is set twice", ref.span,
                     "set it either with a modifier or with one connect(...)")
            v = self._frame_of_joint(self.eval(ref), inst.cls.field(fname), ref.span)
            self._check_field(inst, inst.cls.field(fname), v, ref.span)
            inst.connections[fname] = v

    # ================================================================== assembly
    def build(self) -> ir.Model:
        token = V.WARNINGS.set([])
        try:
            return self._build()
        finally:
            V.WARNINGS.reset(token)

    def _build(self) -> ir.Model:
        self.run_connects()
        for e in self.entries.values():
            try:
                self.value_of(e)
            except _Failed:
                pass
        self.run_equations()
        params, coords, outputs = [], [], []
        built = K.Built()
        for e in sorted(self.entries.values(), key=lambda x: x.order):
            if e.state != 2:
                continue
            params += e.params
            coords += e.coords
            outputs += e.outputs
            if e.kind == "component":
                for inst in e.elements:
                    try:
                        b = self._build_inst(inst)
                    except EvalError as ex:
                        self.diags.items.append(ex.diag)
                        continue
                    except _Failed:
                        continue
                    except ValError as ve:
                        self.diags.error(ve.code, ve.message, inst.entry.decl.span, ve.help)
                        continue
                    coords += inst.coords
                    for k in ("bodies", "points", "joints", "forces", "terms", "contacts"):
                        getattr(built, k).extend(getattr(b, k))
            # joints own coordinates too: the exact count, located at the declaration that passes it
            self.charge("coordinates", 0, e.decl.span, total=len(coords))
        for j in built.joints:
            jinst = self.insts.get(j.name)
            if (j.child == j.name and j.name not in self.joint_frames and jinst is not None
                    and not self.connect_failed):
                cn = jinst.cls.connect_fields
                self.diags.error("E210", f"{jinst.cls.name} '{j.name}' needs 'child'", jinst.entry.decl.name_span,
                                 f"set it with child = ..., or connect({cn[0]}, {jinst.entry.decl.name}, {cn[1]}) in the "
                                 f"equation section; a joint without a child is a massless frame only when another "
                                 f"joint or point uses it (parent = {j.name})")
        self.diags.raise_if_errors()
        forces = built.forces + self.gen_forces
        model = ir.Model(
            name=self.model.name, doc=self.model.doc or "", parameters=tuple(params), coordinates=tuple(coords),
            bodies=tuple(built.bodies), points=(ir.Point("world", "world", span=self.model.span),) + tuple(built.points),
            joints=tuple(built.joints), forces=tuple(forces), terms=tuple(built.terms + self.terms),
            constraints=tuple(self.constraints), outputs=tuple(outputs), contacts=tuple(built.contacts),
            span=self.model.span)
        from .topology import check_model

        return check_model(model, self.diags)

    def _fields(self, inst: CompInst) -> dict[str, Val | None]:
        return {f.name: self.field_value(inst, f.name) for f in inst.cls.fields}

    def _build_inst(self, inst: CompInst) -> K.Built:
        if inst.built is not None:
            return inst.built
        cls, span, name = inst.cls, inst.entry.decl.span, inst.name
        f = self._fields(inst)
        out = K.Built()
        if cls.category == "body":
            if cls.name == "Body" and f.get("I") is not None:
                if any(n.startswith("I_") and inst.entry.mod.sub.get(n) for n in f):
                    fail("E211", f"give either I or I_11 ... I_32 for '{name}', not both", span, "remove one of them")
            out = K.build_body(cls, name, f, span)
            if cls.name == "PointMass":
                j = self._cartesian_point_mass(inst, span)
                if j is not None:
                    out.joints.append(j)
        elif cls.category == "point":
            body = f["body"]
            out.points.append(ir.Point(name, self.body_of_point(body.name), K.as_vec3(f["r"], "r"), span))
        elif cls.category == "frame":
            parent = f["parent"]
            axis = K.normalized(K.as_vec3(f["axis"], "axis"), "axis")
            if f.get("R") is not None:
                if inst.entry.mod.sub.get("angle") is not None:
                    fail("E211", f"give either R or axis and angle for '{name}', not both", span, "remove one of them")
                R = K.as_mat3(f["R"], "R")
            else:
                R = K.rodrigues(axis, K.as_expr(f["angle"], "angle"))
            for c in [*K.as_vec3(f["r"], "r"), *(x for row in R for x in row)]:
                if X.depends_on_state(c):
                    fail("E306", f"the motion of frame '{name}' may depend on time and parameters only", span,
                         "a frame moves as a prescribed function of time")
            z = X.const(0.0)
            out.bodies.append(ir.Body(name, "frame", span=span))
            out.points += [ir.Point(name, name, (z, z, z), span)]
            out.joints.append(ir.Joint(f"{name}.motion", "frame", parent.name, name, self.body_of_point(parent.name),
                                       name, (z, z, X.const(1.0)), (), None, K.as_vec3(f["r"], "r"), R, (), False,
                                       span))
        elif cls.category == "joint":
            out.joints.append(self._build_joint(inst, f, span, out))
        elif cls.category == "force":
            out = self._build_force(inst, f, span)
        elif cls.category == "contact":
            fields = []
            for fl in cls.fields:
                v = f[fl.name]
                if isinstance(v, CompRef):
                    fields.append((fl.name, v.name))
                elif isinstance(v, Str):
                    fields.append((fl.name, v.value))
                elif isinstance(v, Arr):
                    fields.append((fl.name, K.as_vec3(v, fl.name)))
                elif isinstance(v, Scalar):
                    fields.append((fl.name, v.expr))
            out.contacts.append(ir.Contact(name, self._contact_kind(inst, f, span), tuple(fields), span))
        inst.built = out
        return out

    def _contact_kind(self, inst: CompInst, f, span) -> str:
        """'fix' (Fixation), 'gap' (Contact with a gap expression) or the Contact's surface."""
        if inst.cls.name == "Fixation":
            return "fix"
        gap = f.get("gap")
        if gap is not None:
            if f.get("point") is not None:
                fail("E211", f"give either a gap or a point for contact '{inst.name}', not both", span)
            if X.has_speed(gap.expr):
                fail("E306", f"the gap of contact '{inst.name}' may depend on coordinates and time, not on speeds",
                     span)
            return "gap"
        if f.get("point") is None:
            fail("E210", f"Contact '{inst.name}' needs 'point' (or a 'gap' expression)", inst.entry.decl.name_span,
                 "add point = ... (and surface, normal, ...) or gap = ... to its modifiers")
        return f["surface"].value

    def _build_joint(self, inst: CompInst, f, span, out: K.Built) -> ir.Joint:
        cls, name = inst.cls, inst.name
        if cls.name == "RigidLink":
            a, b = f["a"], f["b"]
            end = f"{name}.end"
            out.points.append(ir.Point(end, self.body_of_point(a.name), K.as_vec3(f["r"], "r"), span))
            z = X.const(0.0)
            return ir.Joint(name, "fixed", end, _point_name(b), self.body_of_point(a.name), self.body_of_point(b.name),
                            (z, z, X.const(1.0)), (), None, None, None, (), False, span)
        parent, child = f["parent"], f["child"]
        if child is None:                   # the joint's own massless frame
            z = X.const(0.0)
            out.bodies.append(ir.Body(name, "frame", span=span))
            out.points.append(ir.Point(name, name, (z, z, z), span))
            child = CompRef("body", name, "JointFrame")
        pb, cb = self.body_of_point(parent.name), self.body_of_point(child.name)
        kind = cls.name.lower()
        axis = K.normalized(K.as_vec3(f["axis"], "axis"), "axis") if cls.field("axis") else (
            X.const(0.0), X.const(0.0), X.const(1.0))
        options = []
        if cls.field("sequence"):
            seq = f["sequence"].value
            try:
                K.check_sequence(seq)
            except ValError as ve:
                fail(ve.code, ve.message, inst.entry.mod.sub["sequence"].value.span if "sequence" in inst.entry.mod.sub else span, ve.help)
            options = [("parametrization", f["parametrization"].value), ("sequence", seq)]
        plane = None
        if kind == "planar":
            try:
                plane = K.plane_axes(axis)
            except ValError as ve:
                fail(ve.code, ve.message, span, ve.help)
        jv = self.joint_vars(inst)
        return ir.Joint(name, kind, _point_name(parent), _point_name(child), pb, cb, axis, tuple(jv), plane,
                        None, None, tuple(options), False, span)

    def _build_force(self, inst: CompInst, f, span) -> K.Built:
        cls, name = inst.cls, inst.name
        out = K.Built()
        e = K.as_expr
        if cls.name == "Gravity":
            out.forces.append(ir.Gravity(name, K.as_vec3(f["g"], "g"), span))
        elif cls.name in ("Spring", "Damper", "SpringDamper"):
            a, b = _point_name(f["a"]), _point_name(f["b"])
            if a == b:
                fail("E503", f"{cls.name} '{name}' connects a point to itself", span, "a and b must be different points")
            zero = X.const(0.0)
            kind = {"Spring": "spring", "Damper": "damper", "SpringDamper": "spring-damper"}[cls.name]
            out.forces.append(ir.SpringDamper(name, kind, a, b, e(f["k"], "k") if "k" in f else zero,
                                              e(f["c"], "c") if "c" in f else zero,
                                              e(f["l0"], "l0") if "l0" in f else zero, span))
        elif cls.name == "Force":
            out.forces.append(ir.AppliedForce(name, _point_name(f["point"]), K.as_vec3(f["F"], "F"),
                                              f["frame"].name, span))
        elif cls.name == "Torque":
            out.forces.append(ir.AppliedTorque(name, f["body"].name, K.as_vec3(f["tau"], "tau"), f["frame"].name, span))
        elif cls.name == "GeneralizedForce":
            out.forces.append(ir.GeneralizedForce(name, f["coordinate"].expr.name, e(f["Q"], "Q"), span))
        elif cls.name == "Friction":
            out.forces.append(friction_force(self, name, f, span))
        elif cls.name == "Gravitation":
            names = tuple(b.name for b in f["bodies"].items)
            if len(set(names)) != len(names):
                fail("E202", f"a body appears twice in '{name}'", span, "list each body once")
            out.forces.append(ir.Gravitation(name, names, e(f["G"], "G"), span))
        elif cls.name == "Potential":
            v = f["V"]
            if X.has_speed(v.expr):
                fail("E308", f"potential '{name}' must not depend on speeds", span,
                     "velocity-dependent forces go into a Force, GeneralizedForce or the dissipation function")
            out.terms.append(ir.Term("potential", v.expr, name, span))
        return out


# ---------------------------------------------------------------------------- helpers


def _quiet_numpy():
    import numpy as np

    return np.errstate(all="ignore")  # nan/inf are checked and reported as diagnostics


def _point_name(v: Val) -> str:
    assert isinstance(v, CompRef)
    return v.name


def _kinematic_attr(ref: CompRef, name: str) -> Val | None:
    p = ref.name
    if name == "r":
        return Arr(tuple(Scalar(ir.PointPos(p, i), U.LENGTH) for i in range(3)))
    if name == "v":
        return Arr(tuple(Scalar(ir.PointVel(p, i), U.VELOCITY) for i in range(3)))
    if name == "a":
        return Arr(tuple(Scalar(ir.PointAcc(p, i), U.ACCEL) for i in range(3)))
    if name in ("x", "y", "z"):
        return Scalar(ir.PointPos(p, "xyz".index(name)), U.LENGTH)
    if ref.kind == "body" and ref.type_name not in ("Point",):
        if name == "R":
            return Arr(tuple(Arr(tuple(Scalar(ir.BodyRot(p, i, j), U.ONE) for j in range(3))) for i in range(3)))
        if name in ("w", "w_body"):
            frame = "world" if name == "w" else "body"
            return Arr(tuple(Scalar(ir.BodyOmega(p, i, frame), U.dim(s=-1)) for i in range(3)))
        if name == "alpha":
            return Arr(tuple(Scalar(ir.BodyAlpha(p, i), U.dim(s=-2)) for i in range(3)))
    return None


def _pick(val: Val, inst: CompInst, rank: int, each: bool) -> Val:
    """The value of an array-level modifier for one element (split or broadcast)."""
    if inst.k < 0 or each:
        return val
    n = len(inst.entry.elements)
    if isinstance(val, Arr) and len(val.items) == n and _rank(val) == rank + 1:
        return val.items[inst.k]
    return val


def _has_work(eq: ast.ForEquation, connects: bool) -> bool:
    """Whether a for-loop holds connect(...) equations (connects=True) or other equations."""
    for item in eq.body:
        if isinstance(item, ast.ForEquation):
            if _has_work(item, connects):
                return True
        elif isinstance(item, ast.Connect) == connects:
            return True
    return False


def _rank(val: Val) -> int:
    """Number of array levels, along the first elements (O(rank), unlike shape_of: once per element)."""
    r = 0
    while isinstance(val, Arr):
        r += 1
        if not val.items:
            break
        val = val.items[0]
    return r


def _constval(e: ir.Expr) -> float:
    return e.value if isinstance(e, ir.Const) else 1.0


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


__all__ = ["Flattener", "MechError", "Diagnostic"]
