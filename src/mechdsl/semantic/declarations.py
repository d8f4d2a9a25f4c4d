"""Declarations of a model registered before anything is evaluated: extends clauses expanded
base-first, model instances `Sub s(mods)` added as `s.x`, modifications merged outer-over-inner
(scene > extends clause > declaration), names checked (E202 twice, E203 unknown type, E204 no such
declaration, E206 unknown base, E207 cycles, E214/E215/E216). A mixin of
:class:`~mechdsl.semantic.flatten.Flattener`."""
from __future__ import annotations

from ..frontend import ast
from ..diagnostics import did_you_mean
from . import components as K
from . import instances as Inst
from . import mods as Mods
from .entries import Entry
from .mods import Mod

SCALAR_TYPES = {"Real", "Integer", "Boolean"}
RESERVED_NAMES = {"time", "world"}


class Declarations:
    def _collect(self, m: ast.ModelDef, outer: dict[str, Mod], chain: list[str], prefix: str = "",
                 names: set[str] | None = None) -> None:
        """Register m's declarations and equations; `prefix` (e.g. 's.') when m is an instance `s`,
        `names`: the instance's own names, renamed with the prefix (m's, or a derived model's)."""
        if m.name in chain:
            what = "extends or contains" if prefix else "extends"
            self.diags.error("E207", f"model '{m.name}' {what} itself (through {' -> '.join(chain + [m.name])})",
                             m.name_span, "remove one of the extends clauses or instances in the cycle")
            return
        chain = chain + [m.name]
        if prefix and names is None:
            names = Inst.declared_names(self.program, m)
        own_names = {prefix + e.name for e in m.elements if isinstance(e, ast.Declaration)}
        for el in m.elements:
            if isinstance(el, ast.Extends):
                base = self.program.model_def(el.name)
                if base is None:
                    self.diags.error("E206", f"unknown model '{el.name}' in extends", el.span,
                                     did_you_mean(el.name, self.program.model_names())
                                     or f"models in this file: {', '.join(self.program.model_names())}")
                    continue
                ext = Mods.from_ast(Inst.rename(el.modification, names or set(), prefix), self.diags)
                ext = {prefix + k: v for k, v in ext.items()}
                # modifications for inherited names: extends-clause, then ours (outer) on top
                passed = Mods.merge_dicts(ext, {k: v for k, v in outer.items() if k not in own_names})
                self._collect(base, passed, chain, prefix, names)
                self._check_modified_names(ext, base.name, prefix)
        for el in m.elements:
            if isinstance(el, ast.Declaration):
                d = Inst.rename(el, names or set(), prefix)
                if self.program.model_def(d.type_name) is not None and d.type_name not in K.CLASSES:
                    self._instance(d, outer, chain)
                else:
                    self._declare(d, outer)
        self.equations.extend(Inst.rename(m.equations, names or set(), prefix))

    def _instance(self, d: ast.Declaration, outer: dict[str, Mod], chain: list[str]) -> None:
        """`Sub s(mods);`: Sub's declarations and equations are added as s.x, with mods on top."""
        sub = self.program.model_def(d.type_name)
        problem = None
        if d.prefix is not None:
            problem = ("E215", f"'{d.prefix}' cannot be applied to a model instance", d.span, f"remove '{d.prefix}'")
        elif len(d.dims) > 1:
            problem = ("E301", "arrays of model instances have one dimension", d.dims[1].span,
                       f"write {d.type_name} {d.name}[n](...)")
        elif d.value is not None:
            problem = ("E214", f"a model instance takes modifiers, not a value", d.value.span,
                       f"write {d.type_name} {d.name}(parameter = ...)")
        elif d.name in self.entries or d.name in self.instances:
            problem = ("E202", f"'{d.name}' is declared twice", d.name_span, "rename one of them")
        if problem:
            self.diags.error(*problem)
            return
        if d.dims:
            self._instance_array(d, outer, chain)
            return
        self.instances[d.name] = d
        mod = Mods.merge(Mod(sub=Mods.from_ast(d.modification, self.diags), span=d.span, name_span=d.name_span),
                         outer.get(d.name))
        inner = {f"{d.name}.{k}": v for k, v in mod.sub.items()}
        self._collect(sub, inner, chain, d.name + ".")  # type: ignore[arg-type]
        self._check_modified_names(inner, sub.name, d.name + ".")  # type: ignore[union-attr]

    def _check_modified_names(self, mods: dict[str, Mod], model_name: str, prefix: str = "") -> None:
        """A modification (scene, extends, API override) must name a declaration of the model."""
        for k, m in mods.items():
            base = k.split("[", 1)[0]
            if "[" in k and base in self.entries and self.entries[base].kind == "coordinate":
                continue                    # an element's start (q[2].start): checked where q is built
            if k not in self.entries and k not in self.instances:
                local = k[len(prefix):] if k.startswith(prefix) else k
                own = self._own(prefix[:-1]) if prefix else list(self.entries)
                n = self.instance_arrays.get(base)
                if n is not None:       # the array itself, or an element it does not have
                    self.diags.error("E204", f"'{base[len(prefix):]}' of model '{model_name}' is an array of {n} "
                                             f"model instances" + ("" if "[" not in k else f"; {local} is not one"),
                                     m.name_span, f"modify one element, {base[len(prefix):]}[i](...) with i in 1..{n}")
                    continue
                self.diags.error("E204", f"model '{model_name}' has no declaration '{local}' to modify", m.name_span,
                                 did_you_mean(local, own) or "modify its parameters and start values")

    def _declare(self, d: ast.Declaration, outer: dict[str, Mod]) -> None:
        if d.name in self.instances:
            self.diags.error("E202", f"'{d.name}' is declared twice (first at line "
                                     f"{self.instances[d.name].name_span.line})", d.name_span, "rename one of them")
            return
        if d.name in self.entries:
            prev = self.entries[d.name].decl
            self.diags.error("E202", f"'{d.name}' is declared twice (first at line {prev.name_span.line})",
                             d.name_span, "rename one of them")
            return
        if d.name in RESERVED_NAMES:
            self.diags.error("E216", f"'{d.name}' is a built-in name and cannot be declared", d.name_span,
                             "choose another name")
            return
        mod = Mods.merge(Mod(value=d.value, sub=Mods.from_ast(d.modification, self.diags), span=d.span,
                             name_span=d.name_span), outer.get(d.name))
        cls = None
        if d.type_name in SCALAR_TYPES:
            kind = {"parameter": "parameter", "constant": "parameter", "input": "input",
                    "coordinate": "coordinate", "output": "output", None: "variable"}[d.prefix]
            if d.type_name != "Real" and kind in ("coordinate", "input"):
                self.diags.error("E215", f"{'an' if d.prefix == 'input' else 'a'} {d.prefix} must be Real, "
                                         f"not {d.type_name}", d.span,
                                 f"declare it as {d.prefix} Real {d.name}")
                return
            if d.type_name != "Real" and kind == "variable":
                kind = "parameter"
        else:
            cls = K.CLASSES.get(d.type_name)
            if cls is None:
                types = list(K.CLASSES) + sorted(SCALAR_TYPES) + self.program.model_names()
                self.diags.error("E203", f"unknown type '{d.type_name}'", d.span,
                                 did_you_mean(d.type_name, types)
                                 or "built-in types: " + ", ".join(sorted(K.CLASSES)))
                return
            if d.prefix is not None:
                self.diags.error("E215", f"'{d.prefix}' applies to Real, Integer and Boolean declarations, "
                                         f"not to a {d.type_name}", d.span, f"remove '{d.prefix}'")
                return
            if d.value is not None:
                self.diags.error("E214", f"a {d.type_name} takes modifiers, not a value", d.value.span,
                                 f"write {d.type_name} {d.name}(field = ...)")
                return
            kind = "component"
        self.entries[d.name] = Entry(d, kind, mod, len(self.entries), cls,
                                     element_mods={k: v for k, v in outer.items() if k.startswith(d.name + "[")})
