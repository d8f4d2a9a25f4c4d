"""Arrays of model instances (issue 17): `Link links[N](mods)` becomes N ordinary instances
`links[1]` ... `links[N]` with their modifiers split per element, and `links[i].x` in
expressions names element i. A mixin of :class:`~mechdsl.semantic.flatten.Flattener`."""
from __future__ import annotations

import dataclasses

from .. import ast
from .. import limits
from .entries import Failed
from .evaluate import EvalError, fail
from .mods import Mod
from .values import Arr


class InstanceArrays:
    def _instance_array(self, d: ast.Declaration, outer: dict[str, Mod], chain: list[str]) -> None:
        """`Link links[N](mods)`: N instances `links[1]` ... `links[N]` (issue 17). The size is an
        Integer expression of names declared before the array. A modifier marked `each`, or whose
        value is not an array of N entries, is given to every element; an array of N entries
        (a literal, or a name of an array of N) is split, one entry per element."""
        try:
            n = self.int_value(d.dims[0], "the size of an array of instances")
        except EvalError as ex:
            self.diags.items.append(ex.diag)
            return
        except Failed:
            return
        if n > limits.get("components"):
            self.diags.error("E316", f"{n} instances of {d.type_name} exceed the limit of {limits.get('components')} "
                                     "components", d.dims[0].span, limits.hint("components"))
            return
        self.instance_arrays[d.name] = n
        mods = self._split_arrays(d.modification, n, d.name, outer)
        for k in range(1, n + 1):
            dk = dataclasses.replace(d, name=f"{d.name}[{k}]", dims=(), modification=self._element_mods(mods, k, n))
            self._instance(dk, outer, chain)

    def _split_arrays(self, mods, n: int, path: str, outer):
        """Modifier values that are arrays of n (not literal, not `each`) become a hidden array
        variable `<path>.<modifier>` that each element indexes."""
        if not mods:
            return mods
        out = []
        for m in mods:
            value = m.value
            if (value is not None and not m.each and not isinstance(value, ast.Array)
                    and self._is_array_of(value, n)):
                name = f"{path}.{m.name}"
                if name not in self.entries:
                    self._declare(ast.Declaration(prefix=None, type_name="Real", name=name,
                                                  dims=(ast.Number(value=n, span=value.span),), value=value,
                                                  span=value.span, name_span=value.span), outer)
                value = ast.Ref(parts=(ast.RefPart(name=name, span=value.span),), span=value.span)
            sub = m.modification if m.each else self._split_arrays(m.modification, n, f"{path}.{m.name}", outer)
            out.append(dataclasses.replace(m, value=value, modification=sub))
        return tuple(out)

    def _element_mods(self, mods, k: int, n: int):
        """Element k's modifiers: `each` ones as they are, arrays of n entries split."""
        if not mods:
            return mods
        out = []
        for m in mods:
            value = m.value
            if value is not None and not m.each:
                if isinstance(value, ast.Array) and len(value.items) == n:
                    value = value.items[k - 1]
                elif isinstance(value, ast.Ref) and not value.parts[-1].subscripts and self._is_array_of(value, n):
                    last = value.parts[-1]
                    index = ast.Number(value=k, span=value.span)
                    value = dataclasses.replace(value, parts=value.parts[:-1] + (
                        dataclasses.replace(last, subscripts=(index,)),))
            sub = self._element_mods(m.modification, k, n) if not m.each else m.modification
            out.append(dataclasses.replace(m, value=value, modification=sub, each=False))
        return tuple(out)

    def _is_array_of(self, ref: ast.Ref, n: int) -> bool:
        try:
            v = self.eval(ref)
        except (EvalError, Failed):
            return False
        return isinstance(v, Arr) and len(v.items) == n

    def _instance_element(self, r: ast.Ref) -> ast.Ref:
        first = r.parts[0]
        n = self.instance_arrays.get(first.name)
        if n is None or not first.subscripts:
            if n is not None and len(r.parts) > 1:
                fail("E303", f"'{first.name}' is an array of {n} model instances: pick one, e.g. {first.name}[1]",
                     first.span, f"write {first.name}[i].{r.parts[1].name}")
            return r
        if len(first.subscripts) != 1:
            fail("E303", f"'{first.name}' has one dimension", first.span, f"write {first.name}[i]")
        k = self.int_value(first.subscripts[0], "an index")
        if not 1 <= k <= n:
            fail("E303", f"index {k} is out of range for '{first.name}' (1..{n})", first.subscripts[0].span,
                 "indices start at 1")
        if len(r.parts) == 1:
            fail("E201", f"'{first.name}[{k}]' is a model instance, not a value", first.span,
                 f"refer to one of its declarations, e.g. {first.name}[{k}].{next(iter(self._own(f'{first.name}[{k}]')), 'x')}")
        return dataclasses.replace(r, parts=(dataclasses.replace(first, name=f"{first.name}[{k}]", subscripts=()),)
                                   + r.parts[1:])
