"""Modifications: the nested ``name(sub = ...) = value`` trees of Modelica, merged outer-over-inner."""
from __future__ import annotations

from dataclasses import field

from ..frontend import ast
from ..diagnostics import DiagnosticBag, Span
from ..model.records import record


@record(frozen=False)
class Mod:
    value: ast.Expr | None = None
    each: bool = False
    sub: dict[str, "Mod"] = field(default_factory=dict)
    span: Span = field(default_factory=Span)
    name_span: Span = field(default_factory=Span)


def from_ast(mods: tuple[ast.Modifier, ...] | None, diags: DiagnosticBag | None = None) -> dict[str, Mod]:
    """Dotted names (``j1.phi(start = 1)``) become nested entries."""
    out: dict[str, Mod] = {}
    for m in mods or ():
        path = m.name.split(".")
        node = Mod(value=m.value, each=m.each, sub=from_ast(m.modification, diags), span=m.span, name_span=m.span)
        for part in reversed(path[1:]):
            node = Mod(sub={part: node}, span=m.span, name_span=m.span)
        head = path[0]
        if head in out:
            if diags is not None and _overlaps(out[head], node):
                diags.error("E202", f"'{m.name}' is modified twice", m.span, "keep one modification")
            out[head] = merge(out[head], node)
        else:
            out[head] = node
    return out


def _overlaps(a: Mod, b: Mod) -> bool:
    if a.value is not None and b.value is not None:
        return True
    return any(k in a.sub and _overlaps(a.sub[k], v) for k, v in b.sub.items())


def merge(inner: Mod | None, outer: Mod | None) -> Mod:
    """outer's values win; sub-modifications are merged recursively."""
    if inner is None:
        return outer or Mod()
    if outer is None:
        return inner
    sub = dict(inner.sub)
    for k, v in outer.sub.items():
        sub[k] = merge(sub.get(k), v)
    if outer.value is not None:
        return Mod(value=outer.value, each=outer.each, sub=sub, span=outer.span, name_span=outer.name_span)
    return Mod(value=inner.value, each=inner.each, sub=sub, span=inner.span, name_span=inner.name_span)


def merge_dicts(inner: dict[str, Mod], outer: dict[str, Mod]) -> dict[str, Mod]:
    out = dict(inner)
    for k, v in outer.items():
        out[k] = merge(out.get(k), v)
    return out
