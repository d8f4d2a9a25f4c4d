"""Completion: what may be typed at the cursor (context.py says where it is), from the symbol
index (the model's declarations and inherited ones, model instances' members) and the catalog
(classes, their fields and attributes, functions, settings)."""
from __future__ import annotations

from lsprotocol import types as T

from ..semantic import catalog as C
from ..semantic import components as K
from ..semantic.declarations import SCALAR_TYPES
from .context import PREFIXES, Context

_K = T.CompletionItemKind
KINDS = {
    "parameter": _K.Constant, "constant": _K.Constant, "coordinate": _K.Variable, "variable": _K.Variable,
    "output": _K.Property, "input": _K.Field, "component": _K.Module, "instance": _K.Module,
    "loop variable": _K.Variable, "model": _K.Class, "scene": _K.Event, "field": _K.Field, "point": _K.Reference,
    "joint variable": _K.Variable, "attribute": _K.Property, "setting": _K.Property, "function": _K.Function,
    "keyword": _K.Keyword, "class": _K.Class, "builtin": _K.Constant, "type": _K.TypeParameter,
}
ELEMENT_KEYWORDS = PREFIXES + ("extends", "equation", "end")
EQUATION_KEYWORDS = ("connect", "for", "force", "kinetic", "potential", "dissipation", "end")
EXPRESSION_KEYWORDS = ("if", "then", "elseif", "else", "and", "or", "not", "true", "false")


def completions(index, ctx: Context) -> list[T.CompletionItem]:
    items: list[T.CompletionItem] = []
    k = ctx.kind
    if k == "member":
        items = [_member(m) for m in _chain_members(index, ctx)] if index is not None else []
        items += [_symbol(s) for s in _chain_symbols(index, ctx)] if index is not None else []
    elif k == "modifier":
        items = _modifier_items(index, ctx)
    elif k == "top":
        items = [_kw(w) for w in ("model", "scene")]
    elif k == "type":
        items = [_item(t, "type", "a scalar type") for t in sorted(SCALAR_TYPES)]
    elif k == "model-name":
        items = [_symbol(s) for s in (index.units.values() if index else ()) if s.kind == "model"]
    elif k == "statement" and ctx.unit_kind == "scene":
        items = [_member(m) for m in C.setting_members()] + [_kw("model"), _kw("end")]
    elif k == "statement" and not ctx.equations:
        items = [_kw(w) for w in ELEMENT_KEYWORDS] + _classes() + [_item(t, "type", "a scalar type")
                                                                   for t in sorted(SCALAR_TYPES)]
        items += [_symbol(s) for s in (index.units.values() if index else ())
                  if s.kind == "model" and s.name != ctx.unit]
    elif k == "statement":
        items = [_kw(w) for w in EQUATION_KEYWORDS] + _expression_items(index, ctx)
    elif k == "expression":
        items = _expression_items(index, ctx) + [_kw(w) for w in EXPRESSION_KEYWORDS]
    return _unique(items)


# ----------------------------------------------------------------------------- items


def _item(label: str, kind: str, detail: str = "", doc: str = "") -> T.CompletionItem:
    return T.CompletionItem(label=label, kind=KINDS.get(kind, _K.Text), detail=detail or kind,
                            documentation=T.MarkupContent(kind=T.MarkupKind.Markdown, value=doc) if doc else None)


def _kw(word: str) -> T.CompletionItem:
    return _item(word, "keyword")


def _member(m: C.Member) -> T.CompletionItem:
    unit = f" [{m.unit}]" if m.unit and m.unit != "1" else ""
    default = "; required" if m.required else f"; default {m.default}" if m.default else ""
    return _item(m.name, m.kind, f"{m.kind}{unit}", m.doc + default)


def _symbol(s) -> T.CompletionItem:
    detail = s.kind if not s.type_name or s.kind in ("model", "scene") else f"{s.kind} {s.type_name}"
    return _item(s.name, s.kind, detail, s.doc or "")


def _classes() -> list[T.CompletionItem]:
    return [_item(c.name, "class", f"{c.category} class", c.doc) for c in K.CLASSES.values()]


def _unique(items: list[T.CompletionItem]) -> list[T.CompletionItem]:
    seen: dict[str, T.CompletionItem] = {}
    for it in items:
        seen.setdefault(it.label, it)
    return list(seen.values())


# ----------------------------------------------------------------------------- scopes


def _scope_model(ctx: Context) -> str | None:
    return ctx.scene_model if ctx.unit_kind == "scene" else ctx.unit


def _expression_items(index, ctx: Context) -> list[T.CompletionItem]:
    items = []
    model = _scope_model(ctx)
    if index is not None and model:
        items += [_symbol(s) for s in index.scope(model).values()]
        items += [_symbol(s) for s in index.symbols if s.kind == "loop variable" and s.container == model]
    items += [_item(n, "builtin", "built-in", d) for n, d in C.BUILTIN_VALUES.items()]
    items += [_item(n, "function", sig, d) for n, (sig, d) in C.FUNCTIONS.items()]
    return items


def _resolve(index, model: str | None, names: list[str]):
    """The type a dotted chain of names leads into (see SymbolIndex.type_of) and the declaration
    of its last name (None when it has none)."""
    if not names:
        return None, None
    sym = None
    if names[0] == "world":
        cur = ("world",)
    else:
        sym = index.scope(model).get(names[0]) if model else None
        cur = index.type_of(sym)
    for name in names[1:]:
        if cur is None:
            return None, None
        if cur[0] == "model":
            sym = index.scope(cur[1]).get(name)
            cur = index.type_of(sym)
        elif cur[0] == "class":
            cls, sym = K.CLASSES[cur[1]], None
            cur = ("point",) if name in cls.points else None
        else:
            return None, None
    return cur, sym


def _chain_members(index, ctx: Context) -> list[C.Member]:
    cur, sym = _resolve(index, _scope_model(ctx), ctx.chain)
    if cur is None:
        return []
    if cur[0] == "class":
        mods = {m.name for m in (getattr(sym.node, "modification", None) or ())} if sym is not None else set()
        return C.class_members(cur[1], joint_frame="child" not in mods)
    if cur[0] == "world":
        return C.world_members()
    if cur[0] == "point":
        return C.point_members()
    return []


def _chain_symbols(index, ctx: Context) -> list:
    cur, _ = _resolve(index, _scope_model(ctx), ctx.chain)
    if cur is not None and cur[0] == "model":
        return list(index.scope(cur[1]).values())
    return []


def _modifier_items(index, ctx: Context) -> list[T.CompletionItem]:
    words = ctx.owner
    if not words:
        return []
    if words[0] == "decl":
        _, prefix, type_name, _name, *nested = words
        if type_name in K.CLASSES:
            cur = ("class", type_name)
        elif index is not None and type_name in index.models:
            cur = ("model", type_name)
        elif type_name in SCALAR_TYPES:
            cur = ("scalar", prefix or "variable")
        else:
            return []
    else:
        cur, nested = ("model", words[1]), words[2:]
    for name in nested:
        if cur[0] == "class":
            cls = K.CLASSES[cur[1]]
            cur = ("scalar", "joint variable") if any(r == name for r, _ in cls.roles + K.QUATERNION_ROLES) else None
        elif cur[0] == "model" and index is not None:
            cur = index.type_of(index.scope(cur[1]).get(name.split(".")[-1]))
        else:
            cur = None
        if cur is None:
            return []
    if cur[0] == "class":
        return [_member(m) for m in C.modifier_members(cur[1])]
    if cur[0] == "scalar":
        return [_member(m) for m in C.scalar_members(cur[1])]
    if cur[0] == "model" and index is not None:
        return [_symbol(s) for s in index.scope(cur[1]).values()]
    return []


__all__ = ["completions"]
