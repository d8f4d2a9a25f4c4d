"""Whole-file check for models that extend or contain themselves (E207), directly or through others.

Run by ``analyze`` for every file, so `mech check` finds mutual instances (A has a B, B has
an A) although both models are parts, which it otherwise checks only inside their users.
"""
from __future__ import annotations

from ..frontend import ast
from ..diagnostics import Diagnostic


def containment_cycles(models: dict[str, ast.ModelDef]) -> list[Diagnostic]:
    """E207 for each cycle of `extends` clauses and model instances, at the cycle's first model
    in the file, the cycle named (`A -> B -> A`); an iterative depth-first search."""
    uses = {name: [el.name if isinstance(el, ast.Extends) else el.type_name for el in m.elements
                   if isinstance(el, ast.Extends) or el.type_name in models]
            for name, m in models.items()}
    order = {name: i for i, name in enumerate(models)}
    cycles: dict[frozenset, list[str]] = {}
    state: dict[str, int] = {}   # 1 on the path, 2 done
    for root in models:
        if root in state:
            continue
        path, stack = [root], [iter(uses[root])]
        state[root] = 1
        while stack:  # iterative depth-first search: chains of parts may be long
            nxt = next(stack[-1], None)
            if nxt is None:
                state[path.pop()] = 2
                stack.pop()
            elif nxt not in models or state.get(nxt) == 2:
                continue
            elif state.get(nxt) == 1:
                cyc = path[path.index(nxt):]
                k = min(range(len(cyc)), key=lambda i: order[cyc[i]])  # start at the first in the file
                cycles.setdefault(frozenset(cyc), cyc[k:] + cyc[:k])
            else:
                state[nxt] = 1
                path.append(nxt)
                stack.append(iter(uses[nxt]))
    diags = []
    for cyc in cycles.values():
        m = models[cyc[0]]
        closed = list(zip(cyc, cyc[1:] + cyc[:1]))
        extends_only = all(any(isinstance(el, ast.Extends) and el.name == b for el in models[a].elements)
                           and not any(isinstance(el, ast.Declaration) and el.type_name == b
                                       for el in models[a].elements) for a, b in closed)
        what = "extends" if extends_only else "extends or contains"
        diags.append(Diagnostic("E207", f"model '{m.name}' {what} itself (through {' -> '.join(cyc + [cyc[0]])})",
                                m.name_span, "remove one of the extends clauses or instances in the cycle"))
    return diags
