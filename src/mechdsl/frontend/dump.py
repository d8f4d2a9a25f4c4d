"""Deterministic text dumps of the named intermediate forms (``mech compile --emit``)."""
from __future__ import annotations

import dataclasses

from . import ast
from ..model import ir
from ..model.exprs import fmt_num, to_text
from .printer import expr as print_expr


# ----------------------------------------------------------------------------- ast


def dump_ast(node: ast.Node, spans: bool = True) -> str:
    lines: list[str] = []
    _ast_lines(node, 0, lines, spans, "")
    return "\n".join(lines) + "\n"


def _ast_lines(node, depth: int, out: list[str], spans: bool, label: str) -> None:
    ind = "  " * depth
    name = type(node).__name__
    scalars, children = [], []
    for f in dataclasses.fields(node):
        if f.name.endswith("span") or f.name == "filename":   # positions: shown as @line:col
            continue
        v = getattr(node, f.name)
        if isinstance(v, ast.Node):
            children.append((f.name, v))
        elif isinstance(v, tuple) and any(isinstance(x, (ast.Node, tuple)) for x in v):
            for i, x in enumerate(v):
                if isinstance(x, tuple):  # if-branches
                    for j, y in enumerate(x):
                        children.append((f"{f.name}[{i}][{j}]", y))
                else:
                    children.append((f"{f.name}[{i}]", x))
        elif v is not None and v != ():
            scalars.append(f"{f.name}={v!r}")
    pos = f" @{node.span.line}:{node.span.col}" if spans and node.span.line else ""
    head = f"{ind}{label + ': ' if label else ''}{name}"
    if isinstance(node, ast.Expr) and not isinstance(node, ast.Array):
        head += f" `{print_expr(node)}`"
    out.append(head + (" " + " ".join(scalars) if scalars else "") + pos)
    if isinstance(node, ast.Expr) and isinstance(node, (ast.Number, ast.String, ast.Bool, ast.Ref)):
        return
    for lab, ch in children:
        _ast_lines(ch, depth + 1, out, spans, lab)


# ----------------------------------------------------------------------------- model


def _v(v) -> str:
    return "{" + ", ".join(to_text(c) for c in v) + "}"


def _m(m) -> str:
    return "{" + ", ".join(_v(r) for r in m) + "}"


def dump_model(model: ir.Model) -> str:
    from ..semantic.topology import counts

    L: list[str] = [f"model {model.name}" + (f'  "{model.doc}"' if model.doc else "")]
    c = counts(model)
    L.append("  counts: " + ", ".join(f"{k} {v}" for k, v in c.items()))
    if model.parameters:
        L.append("parameters:")
        for p in model.parameters:
            kind = "Integer " if p.integer else ("input " if p.input else "")
            b = f" := {to_text(p.binding)}" if p.binding is not None else ""
            u = f" [{p.unit}]" if p.unit else ""
            L.append(f"  {kind}{p.name} = {fmt_num(p.value)}{u}{b}")
    L.append("coordinates:")
    for q in model.coordinates:
        own = f" (joint {q.owner})" if q.owner else ""
        u = f" [{q.unit}]" if q.unit else ""
        fx = "" if q.fixed else " free-start"
        L.append(f"  {q.name}{u}: start {to_text(q.start)}, speed {to_text(q.speed)}{fx}{own}")
    if model.bodies:
        L.append("bodies:")
        for b in model.bodies:
            L.append(f"  {b.name} ({b.kind}{' ' + b.shape if b.shape else ''}{', measured inertia' if b.measured else ''}): m = {to_text(b.mass)}, "
                     f"com = {_v(b.com)}, I = {_m(b.inertia)}")
    pts = [p for p in model.points if p.name != "world"]
    if pts:
        L.append("points:")
        for p in pts:
            L.append(f"  {p.name} on {p.body} at {_v(p.r)}" + (f", axes {_m(p.R)}" if p.R is not None else ""))
    if model.shapes:
        L.append("shapes:")
        for sh in model.shapes:
            axes = f", axes {_m(sh.R)}" if sh.R is not None else ""
            along = f", axis {_v(sh.axis)}" if sh.kind in ("rod", "disk", "cylinder") else ""
            L.append(f"  {sh.name} on {sh.body}: {sh.kind} {_v(sh.size)} at {_v(sh.r)}{axes}{along}")
    if model.joints:
        L.append("joints:")
        for j in model.joints:
            vs = ", ".join(f"{v.role} = {to_text(v.motion)}" + ("" if v.coordinate else
                           (" (prescribed)" if v.prescribed else " (expression)")) for v in j.variables)
            extra = ""
            if j.kind == "frame":
                extra = f" r = {_v(j.frame_r)}, R = {_m(j.frame_R)}"
            opts = "".join(f", {k} {v}" for k, v in j.options)
            for what, m in (("parent axes", j.parent_R), ("child axes", j.child_R)):
                opts += f", {what} {_m(m)}" if m is not None else ""
            cut = " [closes loop]" if j.closes_loop else ""
            L.append(f"  {j.name}: {j.kind} {j.parent} -> {j.child}, axis {_v(j.axis)}{opts}"
                     f"{'; ' + vs if vs else ''}{extra}{cut}")
    if model.forces:
        L.append("forces:")
        for f in model.forces:
            L.append("  " + _force(f))
    if model.terms:
        L.append("terms:")
        for t in model.terms:
            L.append(f"  {t.kind} += {to_text(t.expr)}")
    if model.constraints:
        L.append("constraints:")
        for k in model.constraints:
            L.append(f"  {k.name}: 0 = {to_text(k.residual)}   // {k.doc}")
    if model.loops:
        L.append("loops:")
        for lp in model.loops:
            L.append(f"  {lp.name}: closed by {lp.joint}: {' -> '.join(lp.bodies)}")
    if model.outputs:
        L.append("outputs:")
        for o in model.outputs:
            L.append(f"  {o.name} = {to_text(o.expr)}")
    if model.contacts:
        L.append("contacts:")
        for k in model.contacts:
            fs = ", ".join(f"{a} = {_field(v)}" for a, v in k.fields)
            L.append(f"  {k.name}: {k.kind}; {fs}")
    return "\n".join(L) + "\n"


def _field(v) -> str:
    if isinstance(v, ir.Expr):
        return to_text(v)
    if isinstance(v, tuple):
        return _v(v)
    return str(v)


def _force(f) -> str:
    if isinstance(f, ir.Gravity):
        return f"{f.name}: gravity g = {_v(f.g)}"
    if isinstance(f, ir.SpringDamper):
        return (f"{f.name}: {f.kind} {f.a} -- {f.b}, k = {to_text(f.k)}, c = {to_text(f.c)}, "
                f"l0 = {to_text(f.l0)}")
    if isinstance(f, ir.AppliedForce):
        return f"{f.name}: force at {f.point} F = {_v(f.F)} in {f.frame} axes"
    if isinstance(f, ir.AppliedTorque):
        return f"{f.name}: torque on {f.body} tau = {_v(f.tau)} in {f.frame} axes"
    if isinstance(f, ir.GeneralizedForce):
        return f"{f.name}: generalized force on {f.coordinate}: {to_text(f.Q)}"
    if isinstance(f, ir.Gravitation):
        return f"{f.name}: gravitation between {', '.join(f.bodies)}, G = {to_text(f.G)}"
    return repr(f)


__all__ = ["dump_ast", "dump_model", "fmt_num"]
