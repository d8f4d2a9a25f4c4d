"""Models used as component types: `Sub s(p = 1);` inlines Sub's declarations and equations as
`s.p`, `s.q`, ... (Modelica's instance hierarchy, flattened by renaming).

Inside an instance every reference to one of Sub's own declarations (inherited ones included)
is renamed with the instance prefix, so after renaming all expressions live in one flat
namespace; modifications written by the parent (`s(p = a)`) keep the parent's names, which are
renamed by the parent's own prefix when the parent is itself an instance.
"""
from __future__ import annotations

import dataclasses

from ..frontend import ast


def declared_names(program, m: ast.ModelDef, seen: frozenset[str] = frozenset()) -> set[str]:
    """The names a model declares, its extends chain included (cycles are reported elsewhere)."""
    if m.name in seen:
        return set()
    out: set[str] = set()
    for el in m.elements:
        if isinstance(el, ast.Declaration):
            out.add(el.name)
        elif isinstance(el, ast.Extends):
            base = program.model_def(el.name)
            if base is not None:
                out |= declared_names(program, base, seen | {m.name})
    return out


def rename(node, names: set[str], prefix: str):
    """`node` with references to `names` (and declarations of them) prefixed."""
    if not prefix:
        return node
    return _rename(node, names, prefix)


def _rename(node, names, prefix):
    if isinstance(node, tuple):
        return tuple(_rename(x, names, prefix) for x in node)
    if not isinstance(node, ast.Node):
        return node
    if isinstance(node, ast.Ref):
        parts = tuple(dataclasses.replace(p, subscripts=_rename(p.subscripts, names, prefix)) for p in node.parts)
        if parts[0].name in names:
            parts = (dataclasses.replace(parts[0], name=prefix + parts[0].name),) + parts[1:]
        return dataclasses.replace(node, parts=parts)
    changes = {}
    for f in dataclasses.fields(node):
        if f.name == "span" or (isinstance(node, ast.Call) and f.name == "func"):
            continue
        v = getattr(node, f.name)
        if isinstance(v, (ast.Node, tuple)):
            nv = _rename(v, names, prefix)
            if nv is not v:
                changes[f.name] = nv
    if isinstance(node, ast.Declaration) and node.name in names:
        changes["name"] = prefix + node.name
    return dataclasses.replace(node, **changes) if changes else node
