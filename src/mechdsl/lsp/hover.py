"""Hover: what the name under the cursor is, in Markdown: a declaration's text, kind, unit,
description and value (from the model flattened alone, or in the scene's model for a scene's
modifiers); a built-in class's description and fields; an attribute's meaning and unit; a
built-in function's signature."""
from __future__ import annotations

import math

from ..frontend import ast
from ..frontend import printer as P
from ..model.exprs import evaluate, fmt_num
from ..model.units import si_unit
from ..numbers import in_unit
from ..semantic import catalog as C
from ..semantic import components as K


def hover_text(analysis, occ) -> str | None:
    """Markdown for an Occurrence of analysis.index (None when there is nothing to say)."""
    if occ.symbol is not None:
        return _symbol(analysis, occ.symbol, occ)
    owner = occ.owner or ""
    if owner.startswith("class:"):
        cls = owner[len("class:"):]
        if occ.role == "type":
            return class_text(cls)
        m = C.class_member(cls, occ.name)
        return _member(m, f"of {cls}") if m else None
    if owner in ("world", "point"):
        m = next((x for x in (C.world_members() if owner == "world" else C.point_members()) if x.name == occ.name),
                 None)
        return _member(m, "of world" if owner == "world" else "of a point") if m else None
    if owner.startswith("scalar:"):
        doc = C.SCALAR_ATTRIBUTES.get(occ.name)
        return f"**{occ.name}** (attribute of a declaration)\n\n{doc}" if doc else None
    if owner == "setting":
        doc = C.SETTINGS.get(occ.name)
        return f"**{occ.name}** (scene setting)\n\n{doc}" if doc else None
    if owner == "function":
        sig, doc = C.FUNCTIONS[occ.name]
        return f"```mech\n{sig}\n```\nbuilt-in function: {doc}"
    if owner == "signal":
        return f"**{occ.name}** (recorded signal): {C.FUNCTIONS[occ.name][1]}"
    if owner == "builtin":
        return f"**{occ.name}** (built-in)\n\n{C.BUILTIN_VALUES.get(occ.name, '')}"
    if owner == "scalar-type":
        return f"**{occ.name}**: a scalar type"
    return None


def class_text(name: str) -> str | None:
    cls = K.CLASSES.get(name)
    if cls is None:
        return None
    lines = [f"**{cls.name}** (built-in {cls.category} class): {cls.doc}", "",
             "| field | unit | default | meaning |", "|---|---|---|---|"]
    for m in C.field_members(cls):
        lines.append(f"| `{m.name}` | {m.unit} | {'(required)' if m.required else m.default} | {m.doc} |")
    if cls.points:
        lines += ["", "named points: " + ", ".join(f"`{p}`" for p in cls.points)]
    if cls.roles:
        lines += ["", "joint variables: " + ", ".join(f"`{r}`" for r, _ in cls.roles)]
    return "\n".join(lines)


def _member(m: C.Member, where: str) -> str:
    unit = f" [{m.unit}]" if m.unit and m.unit != "1" else ""
    default = "; required" if m.required else f"; default {m.default}" if m.default else ""
    return f"**{m.name}**{unit} ({m.kind} {where})\n\n{m.doc}{default}"


def _symbol(analysis, sym, occ) -> str | None:
    node = sym.node
    if sym.kind in ("model", "scene"):
        return _unit_text(analysis, sym)
    if sym.kind == "loop variable":
        return f"**{sym.name}**: loop variable (Integer) in {sym.container}"
    if not isinstance(node, ast.Declaration):
        return None
    lines = [f"```mech\n{P.element(node)}\n```", f"{sym.kind} of model {sym.container}"]
    unit = _unit_of(node)
    if unit:
        lines[-1] += f", unit {unit}"
    if node.doc:
        lines.append(node.doc)
    if sym.kind == "component" and node.type_name in K.CLASSES:
        cls = K.CLASSES[node.type_name]
        lines.append(f"{cls.name}: {cls.doc}")
    elif sym.kind == "instance":
        sub = analysis.index.models.get(node.type_name) if analysis.index else None
        if sub is not None:
            lines.append(f"an instance of model {sub.name}" + (f": {sub.doc}" if sub.doc else ""))
    values = value_lines(analysis, sym, occ)
    if values:
        lines.append("\n".join(values))
    return "\n\n".join(lines)


def _unit_text(analysis, sym) -> str:
    node = sym.node
    kind = "model" if isinstance(node, ast.ModelDef) else "scene"
    lines = [f"**{kind} {node.name}**" + (f": {node.doc}" if node.doc else "")]
    if isinstance(node, ast.ModelDef):
        bases = [el.name for el in node.elements if isinstance(el, ast.Extends)]
        if bases:
            lines.append("extends " + ", ".join(bases))
        m = analysis.flat.get(node.name)
        if m is not None:
            lines.append(f"{len(m.coordinates)} coordinates, {len(m.real_parameters)} parameters, "
                         f"{len(m.bodies)} bodies, {len(m.joints)} joints, {len(m.outputs)} outputs")
    else:
        target = next((it.name for it in node.items if isinstance(it, ast.SceneModel)), None)
        if target:
            lines.append(f"simulates model {target}")
        settings = [f"{it.name} = {P.expr(it.value)}" for it in node.items if isinstance(it, ast.Setting)]
        if settings:
            lines.append("; ".join(settings))
    return "\n\n".join(lines)


def _unit_of(d: ast.Declaration) -> str | None:
    for m in d.modification or ():
        if m.name == "unit" and isinstance(m.value, ast.String):
            return m.value.value
    return None


def _model_for(analysis, occ):
    """The flattened model the occurrence's names live in."""
    if occ.container in analysis.scene_models:
        return analysis.scene_models[occ.container]
    return analysis.flat.get(occ.container)


def value_lines(analysis, sym, occ) -> list[str]:
    """The values of the declaration at ``occ.path`` in its model: a parameter's value, a
    coordinate's start value and speed, a joint's coordinates, an output's unit."""
    m = _model_for(analysis, occ)
    if m is None:
        return []
    path = occ.path
    values = {p.name: p.value for p in m.parameters}
    out = []
    for p in m.parameters:
        if p.name == path or p.name.startswith(path + "["):
            out.append(f"{p.name} = {fmt_num(in_unit(p.value, p.unit))}" + (f" {p.unit}" if p.unit else "")
                       + (" (input default)" if p.input else ""))
    for c in m.coordinates:
        if c.name == path or c.name.startswith(path + "[") or c.name.startswith(path + "."):
            try:
                start, speed = (in_unit(evaluate(e, values), c.unit) for e in (c.start, c.speed))
                unit = f" {c.unit}" if c.unit else ""
                out.append(f"{c.name}: start {_num(start)}{unit}, speed {_num(speed)}" + ("" if c.fixed else " (guess)"))
            except (ArithmeticError, KeyError, ValueError, TypeError):
                out.append(f"{c.name}: coordinate")
    for o in m.outputs:
        if o.name == path or o.name.startswith(path + "["):
            out.append(f"{o.name}: output" + (f" [{si_unit(o.unit)}]" if o.unit else ""))
    return out[:12] + ([f"... {len(out) - 12} more"] if len(out) > 12 else [])


def _num(v: float) -> str:
    return fmt_num(v) if math.isfinite(v) else str(v)


__all__ = ["hover_text", "class_text", "value_lines"]
