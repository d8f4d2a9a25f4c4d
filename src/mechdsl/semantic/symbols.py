"""A symbol index of one parsed file: every declaration (models, scenes, parameters, coordinates,
components, model instances, outputs, loop variables) and every name that refers to one, with
its span, resolved by the language's scoping rules:

- in a model, a name is one of its own declarations, else one inherited through ``extends``
  (base first, transitively), else a loop variable of an enclosing ``for``, else a built-in
  (``time``, ``pi``, ``world``);
- after a dot, a name is a declaration of the model a model instance is of (``s.m``), or a named
  point, joint variable, field or kinematic attribute of a built-in component (``rod.b``,
  ``j1.phi``, ``b.w_body``), or an attribute of ``world`` or of a point;
- in a modification, a name is a declaration of the modified model (``Sub s(m = 2)``, ``extends
  Base(m = 2)``, a scene's ``model M(m = 2)``), a field or joint variable of a component, or an
  attribute of a scalar declaration (``unit``, ``start``, ...).

Built from the AST alone, without flattening (cheap, and available for every file that parses,
also when the analysis finds errors).  mechdsl.lsp answers hover, go to definition, completion and
document symbols from it; the compiler itself does not use it.
"""
from __future__ import annotations

from collections import ChainMap
from dataclasses import dataclass, field

from ..diagnostics import Span
from ..frontend import ast
from . import ENERGY_SIGNALS
from . import components as K
from .declarations import SCALAR_TYPES
from .evaluate import ALL_FUNCS, BUILTIN_NAMES

DECLARATION_KINDS = ("parameter", "coordinate", "output", "input", "constant", "variable", "component",
                     "instance")


@dataclass(frozen=True)
class Symbol:
    """A declaration: kind is model, scene, loop variable or one of DECLARATION_KINDS."""

    name: str
    kind: str
    span: Span
    name_span: Span
    container: str | None = None      # the model (or scene) it is declared in
    type_name: str | None = None      # Real, Rod, Link, ...
    doc: str | None = None
    node: ast.Node | None = field(default=None, compare=False, repr=False)


@dataclass(frozen=True)
class Occurrence:
    """A name in the text.  role: definition (a declared name), reference (a name in an
    expression or a connect), member (after a dot or in a modification), type (a declaration's
    type, an extends or a scene's model), function, builtin, setting.

    symbol: the declaration in this file it means (None for built-in things and unknown names);
    owner: for names that have no declaration in the file, whose they are: ``class:Rod`` (a
    built-in class's member, or the class itself for a type), ``world``, ``point``,
    ``scalar:coordinate`` / ``scalar:parameter`` (a declaration's attribute), ``setting``,
    ``function``, ``builtin``, ``signal`` (a scene's ``outputs = {energy}``)."""

    span: Span
    name: str
    role: str
    symbol: Symbol | None = None
    owner: str | None = None
    container: str | None = None
    path: str = ""          # the dotted name up to this one (``rod1.b``; ``s.m`` in ``Sub s(m = 2)``)


# a "type" while resolving a dotted name: ("model", M) | ("class", C) | ("world",) | ("point",) | ("scalar", kind)
_Type = tuple


def _contains(span: Span, line: int, col: int, end_ok: bool = False) -> bool:
    if span.line <= 0:
        return False
    start = (span.line, span.col)
    end = (span.end_line, span.end_col)
    return start <= (line, col) < end or (end_ok and (line, col) == end)


def _width(span: Span) -> int:
    return (span.end_line - span.line) * 10_000 + span.end_col - span.col


def declaration_kind(d: ast.Declaration, model_names) -> str:
    if d.prefix in ("parameter", "coordinate", "output", "input", "constant"):
        return d.prefix
    if d.type_name in SCALAR_TYPES:
        return "variable"
    if d.type_name in model_names and d.type_name not in K.CLASSES:
        return "instance"
    return "component"


class SymbolIndex:
    def __init__(self, file: ast.File):
        self.file = file
        self.models: dict[str, ast.ModelDef] = {}
        self.scenes: dict[str, ast.SceneDef] = {}
        self.units: dict[str, Symbol] = {}             # model and scene symbols, by name
        self.symbols: list[Symbol] = []                # every declaration, in document order
        self.occurrences: list[Occurrence] = []
        self._own: dict[str, dict[str, Symbol]] = {}   # model -> its own declarations
        self._scopes: dict[str, dict[str, Symbol]] = {}
        for item in file.items:
            table = self.models if isinstance(item, ast.ModelDef) else self.scenes
            if item.name in self.units:
                continue                               # E202; the first one counts here
            table[item.name] = item
            kind = "model" if isinstance(item, ast.ModelDef) else "scene"
            sym = Symbol(item.name, kind, item.span, item.name_span, None, None, item.doc, item)
            self.units[item.name] = sym
        for m in self.models.values():
            own: dict[str, Symbol] = {}
            for el in m.elements:
                if isinstance(el, ast.Declaration):
                    sym = Symbol(el.name, declaration_kind(el, self.models), el.span, el.name_span, m.name,
                                 el.type_name, el.doc, el)
                    own.setdefault(el.name, sym)
            self._own[m.name] = own
        _Walker(self).run()
        self.occurrences.sort(key=lambda o: (o.span.line, o.span.col))

    # ------------------------------------------------------------------ scopes
    def own(self, model: str) -> dict[str, Symbol]:
        """A model's own declarations, in order."""
        return self._own.get(model, {})

    def scope(self, model: str) -> dict[str, Symbol]:
        """Every declaration a name in ``model`` may mean: its own, then its bases' (extends)."""
        if model not in self._scopes:
            out: dict[str, Symbol] = {}
            seen: set[str] = set()
            todo = [model]
            while todo:                       # own first, then each base (a cycle is E207: stop)
                name = todo.pop(0)
                if name in seen or name not in self.models:
                    continue
                seen.add(name)
                for k, v in self._own[name].items():
                    out.setdefault(k, v)
                todo += [el.name for el in self.models[name].elements if isinstance(el, ast.Extends)]
            self._scopes[model] = out
        return self._scopes[model]

    def type_of(self, sym: Symbol | None) -> _Type | None:
        """What a dot after this declaration leads into."""
        if sym is None:
            return None
        if sym.kind == "instance":
            return ("model", sym.type_name)
        if sym.kind == "component" and sym.type_name in K.CLASSES:
            return ("class", sym.type_name)
        if sym.kind in ("parameter", "coordinate", "input", "output", "constant", "variable"):
            return ("scalar", sym.kind)
        return None

    # ------------------------------------------------------------------ queries
    def at(self, line: int, col: int) -> Occurrence | None:
        """The innermost name at a position (1-based line and column); a name that ends just
        before the position counts when no name contains it (a cursor after a word)."""
        for end_ok in (False, True):
            best = None
            for o in self.occurrences:
                if _contains(o.span, line, col, end_ok) and (best is None or _width(o.span) < _width(best.span)):
                    best = o
            if best is not None:
                return best
        return None

    def unit_at(self, line: int, col: int) -> ast.ModelDef | ast.SceneDef | None:
        """The model or scene a position is in."""
        for item in self.file.items:
            if _contains(item.span, line, col, end_ok=True):
                return item
        return None

    def references(self, sym: Symbol) -> list[Occurrence]:
        return [o for o in self.occurrences if o.symbol == sym]


class _Walker:
    """Records the occurrences of one file (iteratively over expressions: no recursion limit)."""

    def __init__(self, index: SymbolIndex):
        self.ix = index

    def add(self, span: Span, name: str, role: str, symbol=None, owner=None, container=None, path=None) -> None:
        if span.line > 0:
            self.ix.occurrences.append(Occurrence(span, name, role, symbol, owner, container, path or name))

    def run(self) -> None:
        ix = self.ix
        for item in ix.file.items:
            if ix.units.get(item.name) is None or ix.units[item.name].node is not item:
                continue
            self.add(item.name_span, item.name, "definition", ix.units[item.name], container=item.name)
            if isinstance(item, ast.ModelDef):
                self.model(item)
            else:
                self.scene(item)

    # ------------------------------------------------------------------ units
    def model(self, m: ast.ModelDef) -> None:
        ix = self.ix
        env = ChainMap({}, ix.scope(m.name))
        for el in m.elements:
            if isinstance(el, ast.Extends):
                self.type_name(el.name, el.name_span, m.name)
                base = ("model", el.name) if el.name in ix.models else None
                self.mods(el.modification, base, env, m.name, "")
                continue
            sym = ix.own(m.name).get(el.name)
            if sym is not None and sym.node is el:
                self.add(el.name_span, el.name, "definition", sym, container=m.name)
                ix.symbols.append(sym)
            self.type_name(el.type_name, el.type_span, m.name)
            for d in el.dims:
                self.expr(d, env, m.name)
            kind = declaration_kind(el, ix.models)
            target = ix.type_of(Symbol(el.name, kind, el.span, el.name_span, m.name, el.type_name))
            self.mods(el.modification, target, env, m.name, el.name + ".")
            if el.value is not None:
                self.expr(el.value, env, m.name)
        self.equations(m.equations, env, m.name)

    def scene(self, s: ast.SceneDef) -> None:
        ix = self.ix
        model = next((it.name for it in s.items if isinstance(it, ast.SceneModel)), None)
        env = ChainMap({}, ix.scope(model) if model in ix.models else {})
        for it in s.items:
            if isinstance(it, ast.SceneModel):
                self.type_name(it.name, it.name_span, s.name)
                self.mods(it.modification, ("model", it.name) if it.name in ix.models else None, env, s.name, "")
            else:
                self.add(it.name_span, it.name, "setting", owner="setting", container=s.name)
                self.expr(it.value, env, s.name)

    def type_name(self, name: str, span: Span, container: str) -> None:
        ix = self.ix
        if name in K.CLASSES:
            self.add(span, name, "type", owner=f"class:{name}", container=container)
        elif name in ix.models:
            self.add(span, name, "type", ix.units[name], container=container)
        elif name in SCALAR_TYPES:
            self.add(span, name, "type", owner="scalar-type", container=container)
        else:
            self.add(span, name, "type", container=container)

    # ------------------------------------------------------------------ modifications
    def mods(self, mods, owner: _Type | None, env, container: str, prefix: str) -> None:
        todo = [(mods, owner, prefix)]
        while todo:
            mods, owner, prefix = todo.pop()
            for m in mods or ():
                nxt = self.modifier_name(m, owner, container, prefix)
                if m.modification:
                    todo.append((m.modification, nxt, prefix + m.name + "."))
                if m.value is not None:
                    self.expr(m.value, env, container)

    def modifier_name(self, m: ast.Modifier, owner: _Type | None, container: str, prefix: str) -> _Type | None:
        """Record the parts of a (dotted) modifier name; the type its sub-modification modifies."""
        parts = m.name.split(".")
        span = m.name_span
        spans: list[Span | None] = [None] * len(parts)
        if span.line == span.end_line and span.end_col - span.col == len(m.name):
            col = span.col
            for i, p in enumerate(parts):
                base = p.split("[")[0]
                spans[i] = Span(span.file, span.line, col, span.line, col + len(base))
                col += len(p) + 1
        cur = owner
        for i, p in enumerate(parts):
            cur = self.member(p.split("[")[0], spans[i], cur, container, prefix + ".".join(parts[:i + 1]))
        return cur

    # ------------------------------------------------------------------ members
    def member(self, name: str, span: Span | None, owner: _Type | None, container: str, path: str) -> _Type | None:
        """Record `name` as a member of `owner`; the type a further dot leads into."""
        ix = self.ix
        sp = span or Span()
        if owner is None:              # after an unknown name, or a field holding a reference
            self.add(sp, name, "member", container=container, path=path)
            return None
        if owner[0] == "model":
            sym = ix.scope(owner[1]).get(name)
            self.add(sp, name, "member", sym, container=container, path=path)
            return ix.type_of(sym)
        if owner[0] == "class":
            cls = K.CLASSES[owner[1]]
            self.add(sp, name, "member", owner=f"class:{cls.name}", container=container, path=path)
            if name in cls.points:
                return ("point",)
            if cls.category == "joint" and name in {r for r, _ in cls.roles + K.QUATERNION_ROLES}:
                return ("scalar", "joint variable")
            return None
        if owner[0] in ("world", "point"):
            self.add(sp, name, "member", owner=owner[0], container=container, path=path)
            return None
        if owner[0] == "scalar":
            self.add(sp, name, "member", owner=f"scalar:{owner[1]}", container=container, path=path)
        return None

    # ------------------------------------------------------------------ equations and expressions
    def equations(self, eqs, env, container: str) -> None:
        todo = [(eq, env) for eq in reversed(eqs)]
        while todo:
            eq, env = todo.pop()
            if isinstance(eq, ast.SimpleEquation):
                self.expr(eq.lhs, env, container)
                self.expr(eq.rhs, env, container)
            elif isinstance(eq, ast.EnergyEquation):
                self.expr(eq.expr, env, container)
            elif isinstance(eq, ast.ForceEquation):
                self.expr(eq.coordinate, env, container)
                self.expr(eq.expr, env, container)
            elif isinstance(eq, ast.Connect):
                for r in (eq.a, eq.element, eq.b):
                    self.expr(r, env, container)
            elif isinstance(eq, ast.ForEquation):
                self.range(eq.range, env, container)
                inner = self.loop_var(eq.var, eq.var_span, eq.span, env, container)
                todo += [(b, inner) for b in reversed(eq.body)]

    def loop_var(self, var: str, var_span: Span, span: Span, env, container: str):
        sym = Symbol(var, "loop variable", span, var_span, container, "Integer")
        self.ix.symbols.append(sym)
        self.add(var_span, var, "definition", sym, container=container)
        return env.new_child({var: sym})

    def range(self, r: ast.Range, env, container: str) -> None:
        for e in (r.start, r.step, r.stop):
            if e is not None:
                self.expr(e, env, container)

    def expr(self, e: ast.Node, env, container: str) -> None:
        stack = [(e, env)]
        while stack:
            n, env = stack.pop()
            if isinstance(n, ast.Ref):
                self.ref(n, env, container)
                stack += [(s, env) for p in n.parts for s in p.subscripts]
            elif isinstance(n, ast.Call):
                f = n.func
                if len(f.parts) == 1 and not f.parts[0].subscripts and f.parts[0].name in ALL_FUNCS:
                    p = f.parts[0]
                    self.add(_name_span(p), p.name, "function", owner="function", container=container)
                else:
                    self.ref(f, env, container)
                stack += [(a, env) for a in n.args]
            elif isinstance(n, ast.Comprehension):
                self.range(n.range, env, container)
                stack.append((n.expr, self.loop_var(n.var, n.var_span, n.span, env, container)))
            else:
                stack += [(c, env) for c in n.child_nodes()]

    def ref(self, r: ast.Ref, env, container: str) -> None:
        first = r.parts[0]
        sym = env.get(first.name)
        if sym is not None:
            self.add(_name_span(first), first.name, "reference", sym, container=container)
            cur = self.ix.type_of(sym)
        elif first.name in BUILTIN_NAMES:
            self.add(_name_span(first), first.name, "builtin", owner="builtin", container=container)
            cur = ("world",) if first.name == "world" else None
        elif first.name in ENERGY_SIGNALS and container in self.ix.scenes:      # outputs = {energy}
            self.add(_name_span(first), first.name, "builtin", owner="signal", container=container)
            cur = None
        else:
            self.add(_name_span(first), first.name, "reference", container=container)
            cur = None
        path = first.name
        for p in r.parts[1:]:
            path += "." + p.name
            cur = self.member(p.name, _name_span(p), cur, container, path)


def _name_span(p: ast.RefPart) -> Span:
    s = p.span
    return Span(s.file, s.line, s.col, s.line, s.col + len(p.name)) if s.line > 0 else s


__all__ = ["SymbolIndex", "Symbol", "Occurrence", "DECLARATION_KINDS", "declaration_kind"]
