"""Arrays of model instances (issue 17): `Link links[N](mods)` becomes N ordinary instances
`links[1]` ... `links[N]` with their modifiers split per element, and `links[i].x` in
expressions names element i. A mixin of :class:`~mechdsl.semantic.flatten.Flattener`."""
from __future__ import annotations

import dataclasses

from ..frontend import ast
from ..frontend import limits
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
        if n < 0:
            self.diags.error("E307", f"array size {n} is negative", d.dims[0].span, "array sizes are 0 or more")
            return
        if n > limits.get("components"):
            self.diags.error("E316", f"{n} instances of {d.type_name} exceed the limit of {limits.get('components')} "
                                     "components", d.dims[0].span, limits.hint("components"))
            return
        self.instance_arrays[d.name] = n
        mods = self._split_arrays(d.modification, n, d.name, outer)
        for k in range(1, n + 1):
            dk = dataclasses.replace(d, name=f"{d.name}[{k}]", dims=(), modification=self._element_mods(mods, k, n, d.name))
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

    def _element_mods(self, mods, k: int, n: int, array: str):
        """Element k's modifiers: `each` ones as they are, arrays of n entries split (a literal
        array of another length is given whole to every element, and remembered for the error
        if it does not fit: unsplit_array_mismatch)."""
        if not mods:
            return mods
        out = []
        for m in mods:
            value = m.value
            if value is not None and not m.each:
                if isinstance(value, ast.Array) and len(value.items) == n:
                    value = value.items[k - 1]
                elif isinstance(value, ast.Array):
                    self.unsplit_arrays.setdefault(value.span, [array, n, False])
                elif isinstance(value, ast.Ref) and not value.parts[-1].subscripts and self._is_array_of(value, n):
                    last = value.parts[-1]
                    index = ast.Number(value=k, span=value.span)
                    value = dataclasses.replace(value, parts=value.parts[:-1] + (
                        dataclasses.replace(last, subscripts=(index,)),))
            sub = self._element_mods(m.modification, k, n, array) if not m.each else m.modification
            out.append(dataclasses.replace(m, value=value, modification=sub, each=False))
        return tuple(out)

    def unsplit_array_mismatch(self, span, name: str, want: tuple, got: tuple) -> None:
        """A parameter of an instance array's element whose value is a literal array that was
        not split (its length is not the array's size) and does not fit: one error for all the
        elements, saying why (E301), instead of one shape error per element."""
        seen = self.unsplit_arrays.get(span)
        if seen is None:
            return
        array, n, reported = seen
        if reported:
            raise Failed()
        seen[2] = True
        attr = name.rsplit(".", 1)[-1]
        fail("E301", f"'{attr}' of the array '{array}' has {got[0] if got else 1} entries for {n} elements",
             span, f"give {n} entries, one per element (a comprehension {{... for i in 1:N}} over the array's size "
                   f"follows it), or `each {attr} = ...` for the same value in every element")

    def _is_array_of(self, ref: ast.Ref, n: int) -> bool:
        try:
            v = self.eval(ref)
        except (EvalError, Failed):
            return False
        return isinstance(v, Arr) and len(v.items) == n

    def _instance_element(self, r: ast.Ref) -> ast.Ref:
        """`links[i].x` -> `links[3].x`, also inside parts (`links[2].subs[1].x`): each indexed
        part that names an array of instances becomes that element's name."""
        parts, prefix = list(r.parts), ""
        for j, part in enumerate(parts):
            path = prefix + part.name
            n = self.instance_arrays.get(path)
            if n is None:
                if part.subscripts or j > 0 and prefix[:-1] not in self.instances:
                    break           # an indexed value, or no longer inside instances
                prefix = path + "."
                continue
            if not part.subscripts:
                if j + 1 < len(parts):
                    fail("E303", f"'{path}' is an array of {n} model instances: pick one, e.g. {path}[1]",
                         part.span, f"write {path}[i].{parts[j + 1].name}")
                break
            if len(part.subscripts) != 1:
                fail("E303", f"'{path}' has one dimension", part.span, f"write {path}[i]")
            k = self.int_value(part.subscripts[0], "an index")
            if not 1 <= k <= n:
                fail("E303", f"index {k} is out of range for '{path}' (1..{n})", part.subscripts[0].span,
                     "indices start at 1")
            if j + 1 == len(parts):
                fail("E201", f"'{path}[{k}]' is a model instance, not a value", part.span,
                     f"refer to one of its declarations, e.g. {path}[{k}].{next(iter(self._own(f'{path}[{k}]')), 'x')}")
            parts[j] = dataclasses.replace(part, name=f"{part.name}[{k}]", subscripts=())
            prefix = f"{path}[{k}]."
        return dataclasses.replace(r, parts=tuple(parts))
