"""Phase 2, ``analyze``: one model definition (+ outer modifications) -> :class:`ir.Model`.

Declarations are registered first (extends expanded, modifications merged), then evaluated
lazily on demand with cycle detection, so declaration order never matters for meaning; the
output keeps declaration order everywhere.  Errors are collected per declaration/equation
and reported together.

The :class:`Flattener` owns the state and the lazy evaluation of entries (lookup, memoization,
cycles, budgets); each concern is a module of its own (see docs/internals/frontend.md):
declarations.py, instance_arrays.py (registering), scalar_decls.py, elements.py, attributes.py,
joint_vars.py, vector_starts.py (evaluating, mixins that call each other through the flattener),
equations.py and assemble.py (run once by `build`, functions of the flattener).
"""
from __future__ import annotations

import math

from ..frontend import ast
from ..model import ir
from ..frontend import limits
from ..model import units as U
from ..diagnostics import Diagnostic, DiagnosticBag, MechError, Span, did_you_mean
from . import values as V
from .assemble import build_model
from .attributes import Attributes
from .declarations import Declarations
from .elements import ComponentElements
from .entries import CompInst, Entry, Failed
from .equations import run_connects, run_equations
from .evaluate import BUILTIN_NAMES, EvalError, Evaluator, fail
from .instance_arrays import InstanceArrays
from .joint_vars import JointVariables
from .mods import Mod
from .scalar_decls import ScalarDeclarations
from .values import ANY, CompRef, Scalar, Val, ValError
from .vector_starts import VectorStarts

_BUDGET = {"coordinate": "coordinates", "output": "outputs", "component": "components"}  # kind -> limit


class Flattener(Declarations, InstanceArrays, ScalarDeclarations, ComponentElements, Attributes, JointVariables,
                VectorStarts, Evaluator):
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
        self.unsplit_arrays: dict = {}    # span of an array modifier not split over an instance array -> (name, n, reported)
        self._collect(model, outer or {}, [])
        self._check_modified_names(outer or {}, model.name)

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
            raise Failed()
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
            raise Failed() from None
        except ValError as ve:  # raised outside an expression (e.g. the shape of a ragged array)
            entry.state = 3
            at = entry.mod.value.span if entry.mod.value is not None else entry.decl.span
            self.diags.error(ve.code, ve.message, at, ve.help)
            raise Failed() from None
        except Failed:
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

    # ================================================================== evaluation of an entry
    def _evaluate_entry(self, e: Entry) -> Val:
        dims = self.entry_dims(e)
        if e.kind in ("parameter", "input"):
            return self._parameter(e, dims)
        if e.kind == "coordinate":
            return self._coordinate(e, dims)
        if e.kind in ("output", "variable"):
            return self._output(e, dims)
        return self._component(e, dims)

    # ================================================================== build
    def build(self) -> ir.Model:
        token = V.WARNINGS.set([])
        try:
            return self._build()
        finally:
            V.WARNINGS.reset(token)

    def _build(self) -> ir.Model:
        run_connects(self)
        for e in self.entries.values():
            try:
                self.value_of(e)
            except Failed:
                pass
        run_equations(self)
        return build_model(self)


__all__ = ["Flattener", "MechError", "Diagnostic"]
