"""What a constraint exerts on a body: ``constraint_force(c, body)``, ``constraint_torque(c, body)``
(issue 23), as SX in (q, t, p) and the multipliers EOM.lam.

An explicit constraint g(r_P1, R_B1, ...) = 0 written in positions of body points (and body
orientations) adds -G' lambda to Lagrange's equations.  By virtual work the same term is a
force and a torque on each body B it names: give B a virtual translation dx and rotation dth
about its reference point r_B (the first of its points the equation names; a body named only
by its orientation: its origin), so that every point P of B moves by dx + dth x (r_P - r_B) and
its rotation by skew(dth) R_B; then

    F_B = -lambda dg/d(dx),   T_B = -lambda dg/d(dth)   (world axes, T_B about r_B).

Summed over the bodies these are the generalized force -G' lambda (tests/test_constraint_forces.py
checks this at random states).  A loop-closing joint's multipliers are its reaction on the child
(mechanics/constraints.py, Closure.loads); the parent gets the opposite.
"""
from __future__ import annotations

import casadi as ca

from ..model import exprs, ir


def explicit_loads(model: ir.Model, c: ir.Constraint, env: exprs.CasadiEnv, kin, query, lam_i) -> dict:
    """body -> (F (3,), T (3,)) in world axes for the explicit constraint ``c`` with multiplier ``lam_i``."""
    tree = kin.tree
    bodies = model.constraint_bodies(c)
    ref = {}
    for n in exprs.walk(c.residual):
        if isinstance(n, ir.PointPos):
            ref.setdefault(tree.point(n.point).body, kin.point_pos(n.point))
    for b in bodies:
        ref.setdefault(b, kin.point_pos(b) if b != "world" else ca.SX.zeros(3))
    dx = {b: ca.SX.sym(f"dx{k}", 3) for k, b in enumerate(bodies)}
    dth = {b: ca.SX.sym(f"dth{k}", 3) for k, b in enumerate(bodies)}

    def moved(n):
        if isinstance(n, ir.PointPos):
            b = tree.point(n.point).body
            r = kin.point_pos(n.point)
            return (r + dx[b] + ca.cross(dth[b], r - ref[b]))[n.i]
        if isinstance(n, ir.BodyRot):
            R = kin.body_rot(n.body)
            return ca.mtimes(ca.SX.eye(3) + ca.skew(dth[n.body]), R)[n.i, n.j]
        return query(n)

    g = exprs.CasadiEnv(env.coords, env.params, env.q, env.qd, env.t, env.p, query=moved, inputs=env.inputs,
                        u=env.u).translate(c.residual)
    g = ca.SX(g)
    syms = ca.vertcat(*[ca.vertcat(dx[b], dth[b]) for b in bodies])
    out = {}
    for b in bodies:
        F = -lam_i * ca.jacobian(g, dx[b]).T
        T = -lam_i * ca.jacobian(g, dth[b]).T
        FT = ca.substitute(ca.vertcat(F, T), syms, ca.SX.zeros(syms.numel()))
        out[b] = (FT[:3], FT[3:])
    return out


def closure_loads(clo, kin, lam) -> dict:
    """body -> (F, T) world axes of a loop-closing joint: its reaction on the child (at the child
    point), the opposite on the parent (at the parent point, which coincides with it)."""
    F, T = clo.loads(kin, lam)
    j = clo.joint
    return {j.child_body: (F, T), j.parent_body: (-F, -T)}
