"""Go to definition and document symbols, from the symbol index."""
from __future__ import annotations

from lsprotocol import types as T

from ..semantic.symbols import Symbol
from .positions import Lines

_S = T.SymbolKind
SYMBOL_KINDS = {
    "model": _S.Class, "scene": _S.Event, "parameter": _S.Constant, "constant": _S.Constant,
    "coordinate": _S.Variable, "variable": _S.Variable, "output": _S.Property, "input": _S.Field,
    "component": _S.Object, "instance": _S.Module,
}


def lsp_range(lines: Lines, span) -> T.Range:
    (l0, c0), (l1, c1) = lines.range(span)
    return T.Range(start=T.Position(line=l0, character=c0), end=T.Position(line=l1, character=c1))


def definition(index, lines: Lines, uri: str, line: int, col: int) -> T.Location | None:
    occ = index.at(line, col)
    if occ is None or occ.symbol is None:
        return None
    return T.Location(uri=uri, range=lsp_range(lines, occ.symbol.name_span))


def document_symbols(index, lines: Lines) -> list[T.DocumentSymbol]:
    """Models (with their declarations) and scenes (with their settings), in document order."""
    out = []
    for sym in index.units.values():
        children = []
        if sym.kind == "model":
            children = [_symbol(lines, s, []) for s in index.own(sym.name).values()]
        else:
            for it in getattr(sym.node, "items", ()):
                name = getattr(it, "name", "")
                kind = _S.Module if type(it).__name__ == "SceneModel" else _S.Property
                detail = "model" if kind == _S.Module else "setting"
                children.append(T.DocumentSymbol(name=name, kind=kind, detail=detail,
                                                 range=lsp_range(lines, it.span),
                                                 selection_range=lsp_range(lines, it.name_span)))
        out.append(_symbol(lines, sym, children))
    return out


def _symbol(lines: Lines, s: Symbol, children) -> T.DocumentSymbol:
    detail = s.kind if not s.type_name else f"{s.kind} {s.type_name}"
    rng, sel = lsp_range(lines, s.span), lsp_range(lines, s.name_span)
    return T.DocumentSymbol(name=s.name, kind=SYMBOL_KINDS.get(s.kind, _S.Variable), detail=detail,
                            range=rng, selection_range=sel, children=children or None)


__all__ = ["definition", "document_symbols", "lsp_range"]
