"""Checks of ``constraint_force(c, body)`` / ``constraint_torque(c, body)`` (issue 23), once the
equations and the loops are known: ``c`` names an explicit constraint equation written in
positions (and orientations) of body points, or a loop-closing joint, and ``body`` is one the
constraint acts on.  The values are derived in mechanics/constraint_loads.py."""
from __future__ import annotations

from ..diagnostics import Diagnostic, did_you_mean
from ..model import exprs as X
from ..model import ir


def check(model: ir.Model) -> list[Diagnostic]:
    """E232 (no such constraint) and E233 (it exerts no force on that body at a point)."""
    out: list[Diagnostic] = []
    explicit = {c.name: c for c in model.constraints}
    joints = {j.name: j for j in model.joints}
    for o in model.outputs:
        seen = set()
        for n in X.walk(o.expr):
            if not isinstance(n, ir.ConstraintLoad) or (n.constraint, n.body) in seen:
                continue
            seen.add((n.constraint, n.body))
            d = _problem(model, n, explicit, joints, o.span)
            if d is not None:
                out.append(d)
                break
    return out


def _problem(model, n: ir.ConstraintLoad, explicit, joints, span) -> Diagnostic | None:
    fn = f"constraint_{n.what}({n.constraint}, {n.body})"
    c = explicit.get(n.constraint)
    if c is not None:
        coords = sorted({x.name for x in X.walk(c.residual) if isinstance(x, ir.Coord)})
        if coords:
            return Diagnostic("E233", f"{fn}: the constraint '{c.name}' is written in coordinates "
                                      f"({', '.join(coords)}), not in positions of body points, so it exerts no force "
                                      "at a point", span,
                              f"its multiplier lambda[{c.name}] is the generalized force it exerts on those "
                              "coordinates (docs/constraints.md); write the constraint in positions of points (a point's x, y, z, r) "
                              "to have its force")
        bodies = model.constraint_bodies(c)
        if n.body not in bodies:
            return Diagnostic("E233", f"{fn}: the constraint '{c.name}' does not act on '{n.body}'", span,
                              f"it names points of {', '.join(bodies) or 'no body'}")
        return None
    j = joints.get(n.constraint)
    if j is not None:
        if not j.closes_loop:
            return Diagnostic("E233", f"{fn}: joint '{j.name}' does not close a loop, so it is no constraint "
                                      "equation", span,
                              f"the force in a joint of the tree is reaction_{n.what}({j.name}) (child frame)")
        if n.body not in (j.child_body, j.parent_body):
            return Diagnostic("E233", f"{fn}: joint '{j.name}' joins '{j.parent_body}' and '{j.child_body}', "
                                      f"not '{n.body}'", span, f"name {j.parent_body} or {j.child_body}")
        return None
    names = [c.name for c in model.constraints] + [j.name for j in model.joints if j.closes_loop]
    hint = did_you_mean(n.constraint, names)
    return Diagnostic("E232", f"{fn}: no constraint named '{n.constraint}'", span,
                      hint or (f"constraints: {', '.join(names)}" if names else
                               "the model has no constraint equations and no loop-closing joints"))
