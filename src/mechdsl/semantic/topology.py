"""The kinematic graph: spanning tree from the world, cut joints, loops, and model checks."""
from __future__ import annotations

import dataclasses

from ..model import exprs as X
from ..model import ir
from ..diagnostics import DiagnosticBag


def spanning_tree(model: ir.Model, diags: DiagnosticBag) -> tuple[list[ir.Joint], list[ir.Joint], set[str]]:
    """Sweep the joints in declaration order until nothing changes: (tree, cut, reached bodies)."""
    reached = {"world"}
    tree: list[ir.Joint] = []
    cut: list[ir.Joint] = []
    pending: list[ir.Joint] = []
    for j in model.joints:
        if j.parent_body == j.child_body:
            diags.error("E503", f"joint '{j.name}' connects body '{j.child_body}' to itself", j.span,
                        "a joint's parent and child must lie on different bodies")
        elif j.child_body == "world":
            diags.error("E504", f"joint '{j.name}' has the world as its child", j.span,
                        "swap parent and child: the parent is the side nearer the world")
        else:
            pending.append(j)
    changed = True
    while changed:
        changed = False
        rest = []
        for j in pending:
            if j.parent_body in reached:
                if j.child_body in reached:
                    cut.append(j)
                else:
                    reached.add(j.child_body)
                    tree.append(j)
                changed = True
            else:
                rest.append(j)
        pending = rest
    for j in pending:
        if j.child_body in reached:
            if j.kind == "frame":
                continue
            diags.error("E505", f"joint '{j.name}' goes from '{j.parent_body}' to '{j.child_body}', but only "
                                f"'{j.child_body}' is connected to the world", j.span,
                        "swap parent and child so that the parent is the side nearer the world")
    return tree, cut, reached


def loop_path(tree: list[ir.Joint], j: ir.Joint) -> tuple[str, ...]:
    parent = {t.child_body: t.parent_body for t in tree}

    def up(b: str) -> list[str]:
        out = [b]
        while b in parent:
            b = parent[b]
            out.append(b)
        return out

    a, b = up(j.child_body), up(j.parent_body)
    common = next(x for x in a if x in b)
    return tuple(a[:a.index(common) + 1] + list(reversed(b[:b.index(common)])))


def check_model(model: ir.Model, diags: DiagnosticBag) -> ir.Model:
    tree, cut, reached = spanning_tree(model, diags)
    # a body hanging from a reversed joint (E505) is reported there, not again as unconnected
    reversed_parents = {j.parent_body for j in model.joints
                        if j.parent_body not in reached and j.child_body in reached and j.kind != "frame"}
    for body in model.bodies:
        if body.name not in reached and body.name not in reversed_parents:
            diags.error("E501", f"body '{body.name}' is not connected to the world", body.span,
                        f"attach it with a joint, or make it free: Free f(child = {body.name});")
    cut_names = {j.name for j in cut}
    dropped: set[str] = set()
    joints = []
    for j in model.joints:
        if j.name in cut_names:
            for v in j.variables:
                if v.coordinate is None or v.coordinate != f"{j.name}.{v.role}":
                    diags.error("E507", f"joint '{j.name}' closes a loop: its variable '{v.role}' is fixed by the "
                                        f"loop and cannot be bound to '{X.to_text(v.motion)}'", j.span,
                                "leave the loop-closing joint's variables unset, or close the loop at another joint")
                else:
                    dropped.add(v.coordinate)
            j = dataclasses.replace(j, closes_loop=True, variables=())
        joints.append(j)
    joints = tuple(joints)
    coords = tuple(c for c in model.coordinates if c.name not in dropped)
    model = dataclasses.replace(model, coordinates=coords)
    loops = tuple(ir.Loop(f"loop{k + 1}", j.name, loop_path(tree, j), j.span) for k, j in enumerate(cut))
    if not model.coordinates:
        diags.error("E506", f"model '{model.name}' has no coordinates (no degrees of freedom)", model.span,
                    "declare `coordinate Real q(start = ...);` or add a joint with a free variable")
    _warn_unused_coordinates(model, diags)
    from .physical import value_problems

    diags.extend(value_problems(model))
    diags.raise_if_errors()
    return dataclasses.replace(model, joints=joints, loops=loops)


def _warn_unused_coordinates(model: ir.Model, diags: DiagnosticBag) -> None:
    used: set[str] = set()
    for j in model.joints:
        for v in j.variables:
            used.update(n.name for n in X.walk(v.motion) if isinstance(n, ir.Coord))
    for t in model.terms:
        if t.kind == "kinetic":
            used.update(n.name for n in X.walk(t.expr) if isinstance(n, (ir.Speed, ir.Coord)))
    for c in model.coordinates:
        if c.name not in used:
            diags.warning("W501", f"coordinate '{c.name}' does not appear in the kinetic energy or any joint",
                          c.span, "its mass matrix row will be zero: bind it to a joint or use it in `kinetic = ...`")


def counts(model: ir.Model) -> dict[str, int]:
    """What `mech check` and the dumps count.  A constant Frame (a fixed offset and orientation:
    no motion in time) is a placement, not a body and a joint, so it is not counted."""
    cut_eqs = sum(6 - _joint_dof(j) for j in model.joints if j.closes_loop)
    placed = {j.child_body for j in model.joints if constant_frame(j)}
    return {
        "bodies": sum(b.name not in placed for b in model.bodies),
        "joints": sum(not constant_frame(j) for j in model.joints),
        "coordinates": len(model.coordinates),
        "constraints": len(model.constraints) + cut_eqs,
        "explicit_constraints": len(model.constraints),
        "loops": len(model.loops),
    }


def _joint_dof(j: ir.Joint) -> int:
    return {"revolute": 1, "prismatic": 1, "cylindrical": 2, "planar": 3, "spherical": 3, "free": 6,
            "fixed": 0, "frame": 0}.get(j.kind, len(j.variables))


def constant_frame(j: ir.Joint) -> bool:
    """A Frame's motion joint whose offset and orientation do not change in time."""
    if j.kind != "frame":
        return False
    parts = [*(j.frame_r or ()), *(x for row in (j.frame_R or ()) for x in row)]
    return not any(X.depends_on_time(e) or X.depends_on_state(e) for e in parts)
