"""The abstract syntax tree ("ast" IR): what ``parse`` hands to ``analyze``.

Small frozen dataclasses (made by :func:`mechdsl.model.records.record`: the same classes at a
fraction of dataclass's cost at import), keyword-only, each with a source :class:`Span`.  Spans do not
take part in equality, so ``parse(print(parse(x))) == parse(x)`` is the round-trip check.
"""
from __future__ import annotations

from dataclasses import field, fields
from typing import Iterator, Union

from ..diagnostics import Span
from ..model.records import record


@record(kw_only=True)
class Node:
    span: Span = field(default_factory=Span, compare=False, repr=False)

    def child_nodes(self) -> Iterator["Node"]:
        for f in fields(self):
            if f.name == "span":
                continue
            v = getattr(self, f.name)
            if isinstance(v, Node):
                yield v
            elif isinstance(v, tuple):
                for x in v:
                    if isinstance(x, Node):
                        yield x
                    elif isinstance(x, tuple):
                        yield from (y for y in x if isinstance(y, Node))


# ----------------------------------------------------------------------------- expressions


@record(kw_only=True)
class Expr(Node):
    pass


@record(kw_only=True)
class Number(Expr):
    value: int | float


@record(kw_only=True)
class String(Expr):
    value: str


@record(kw_only=True)
class Bool(Expr):
    value: bool


@record(kw_only=True)
class RefPart(Node):
    name: str
    subscripts: tuple[Expr, ...] = ()


@record(kw_only=True)
class Ref(Expr):
    """A component reference ``a.b[i].c``."""

    parts: tuple[RefPart, ...]

    @property
    def dotted(self) -> str:
        return ".".join(p.name for p in self.parts)

    @property
    def simple(self) -> str | None:
        """The name when the reference is a single name without subscripts."""
        if len(self.parts) == 1 and not self.parts[0].subscripts:
            return self.parts[0].name
        return None


@record(kw_only=True)
class Call(Expr):
    func: Ref
    args: tuple[Expr, ...] = ()


@record(kw_only=True)
class BinOp(Expr):
    """op: + - * / ^ and or < <= > >= == <>"""

    op: str
    left: Expr
    right: Expr


@record(kw_only=True)
class UnaryOp(Expr):
    """op: - + not"""

    op: str
    operand: Expr


@record(kw_only=True)
class IfExpr(Expr):
    """if c1 then v1 elseif c2 then v2 ... else other."""

    branches: tuple[tuple[Expr, Expr], ...]
    otherwise: Expr


@record(kw_only=True)
class Array(Expr):
    items: tuple[Expr, ...] = ()


@record(kw_only=True)
class Range(Node):
    """start:stop or start:step:stop (Modelica order)."""

    start: Expr
    stop: Expr
    step: Expr | None = None


@record(kw_only=True)
class Comprehension(Expr):
    """{expr for var in range}"""

    expr: Expr
    var: str
    range: Range
    var_span: Span = field(default_factory=Span, compare=False, repr=False)


# ----------------------------------------------------------------------------- declarations


@record(kw_only=True)
class Modifier(Node):
    """``name(sub-modifiers) = value`` inside a modification; ``each`` broadcasts over arrays."""

    name: str
    each: bool = False
    modification: tuple["Modifier", ...] | None = None
    value: Expr | None = None
    name_span: Span = field(default_factory=Span, compare=False, repr=False)


@record(kw_only=True)
class Declaration(Node):
    """``prefix Type name[dims](modification) = value "doc";``"""

    prefix: str | None  # parameter | coordinate | output | input | constant | None
    type_name: str
    name: str
    dims: tuple[Expr, ...] = ()
    modification: tuple[Modifier, ...] | None = None
    value: Expr | None = None
    doc: str | None = None
    name_span: Span = field(default_factory=Span, compare=False, repr=False)
    type_span: Span = field(default_factory=Span, compare=False, repr=False)


@record(kw_only=True)
class Extends(Node):
    name: str
    modification: tuple[Modifier, ...] | None = None
    name_span: Span = field(default_factory=Span, compare=False, repr=False)


# ----------------------------------------------------------------------------- equations


@record(kw_only=True)
class SimpleEquation(Node):
    lhs: Expr
    rhs: Expr
    doc: str | None = None


@record(kw_only=True)
class EnergyEquation(Node):
    kind: str  # kinetic | potential | dissipation
    expr: Expr
    doc: str | None = None


@record(kw_only=True)
class ForceEquation(Node):
    coordinate: Ref
    expr: Expr
    doc: str | None = None


@record(kw_only=True)
class Connect(Node):
    """connect(a, element, b): attach a joint or two-point force element between points a and b."""

    a: Ref
    element: Ref
    b: Ref
    doc: str | None = None


@record(kw_only=True)
class ForEquation(Node):
    var: str
    range: Range
    body: tuple["EquationItem", ...] = ()
    var_span: Span = field(default_factory=Span, compare=False, repr=False)


EquationItem = Union[SimpleEquation, EnergyEquation, ForceEquation, Connect, ForEquation]

# ----------------------------------------------------------------------------- units


@record(kw_only=True)
class ModelDef(Node):
    name: str
    doc: str | None = None
    elements: tuple[Declaration | Extends, ...] = ()
    equations: tuple[EquationItem, ...] = ()
    name_span: Span = field(default_factory=Span, compare=False, repr=False)


@record(kw_only=True)
class SceneModel(Node):
    name: str
    modification: tuple[Modifier, ...] | None = None
    name_span: Span = field(default_factory=Span, compare=False, repr=False)


@record(kw_only=True)
class Setting(Node):
    name: str
    value: Expr
    name_span: Span = field(default_factory=Span, compare=False, repr=False)


@record(kw_only=True)
class SceneDef(Node):
    name: str
    doc: str | None = None
    items: tuple[SceneModel | Setting, ...] = ()
    name_span: Span = field(default_factory=Span, compare=False, repr=False)


@record(kw_only=True)
class File(Node):
    items: tuple[ModelDef | SceneDef, ...] = ()
    filename: str = field(default="<input>", compare=False)

    @property
    def models(self) -> tuple[ModelDef, ...]:
        return tuple(i for i in self.items if isinstance(i, ModelDef))

    @property
    def scenes(self) -> tuple[SceneDef, ...]:
        return tuple(i for i in self.items if isinstance(i, SceneDef))


def walk(node: Node) -> Iterator[Node]:
    """Every node below (and including) ``node``, pre-order, iteratively."""
    stack = [node]
    while stack:
        n = stack.pop()
        yield n
        stack.extend(reversed(list(n.child_nodes())))
