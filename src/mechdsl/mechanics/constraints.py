"""Constraint residuals g(q, t, p) = 0: explicit ir.Constraints and loop closures.

A loop-closing (cut) joint between parent point P (parent body) and child point C (child
body) is replaced by the equations that its two joint frames coincide up to the joint's free
motion.  With R_P, R_C the joint frames' rotations (body rotation times the frame's axes in
its body, ir.Joint.parent_R / child_R), d = R_P^T (r_C - r_P) and R_rel = R_P^T R_C (both
in the parent joint frame):

- a cut joint without variables locks what its kind locks:
    translation 'all':    g = -d                     (names fx fy fz)
                'perp':   g = -(e1.d, e2.d)          (perpendicular to the axis)
                'normal': g = -e3.d                  (along the axis; planar joints)
    rotation    'full':   g = -vee(R_rel)            (tx ty tz)
                'axis':   g = ((R_rel e3).e2, -(R_rel e3).e1)   (keeps the axis e3 aligned)
- a cut joint whose variables are given (coordinates, prescribed or expressions) must reach
  its own motion (R_j, p_j):  g = p_j - d  and  -vee(R_rel R_j^T)  (6 equations).

(e1, e2, e3) is a right-handed basis with e3 the joint axis; for a coordinate axis the
letters are those of the parent joint frame axes (axis z: e1 = x, e2 = y), otherwise 1 2 3.
The signs make each multiplier the reaction force/torque component on the child along that
basis vector of the parent joint frame (constraint forces are -G^T lambda).
"""
from __future__ import annotations

import casadi as ca

from ..model import ir
from . import joints as J
from .rotations import rot, quat_matrix, unit_axis_index
from .spatial import vee
from .tree import Tree

LETTERS = "xyz"


def basis(a: ca.SX):
    """((e1, e2, e3), names) with e3 = a."""
    k = unit_axis_index(a)
    if k is not None:
        i, j = (k + 1) % 3, (k + 2) % 3
        E = ca.SX.eye(3)
        return (E[:, i], E[:, j], E[:, k]), (LETTERS[i], LETTERS[j], LETTERS[k])
    if all(a[i].is_constant() for i in range(3)):
        import numpy as np

        av = np.array([float(a[i]) for i in range(3)])
        av = av / np.linalg.norm(av)
        j = int(np.argmin(np.abs(av)))
        e1 = np.eye(3)[j] - av[j] * av
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(av, e1)
        return (ca.SX(e1), ca.SX(e2), ca.SX(av)), ("1", "2", "3")
    e3 = a / ca.norm_2(a)
    h = ca.if_else(ca.fabs(e3[0]) < 0.9, ca.vertcat(1, 0, 0), ca.vertcat(0, 1, 0))
    e1 = h - ca.dot(h, e3) * e3
    e1 = e1 / ca.norm_2(e1)
    e2 = ca.cross(e3, e1)
    return (e1, e2, e3), ("1", "2", "3")


class Closure:
    """The equations of one cut joint and the directions of their multipliers."""

    def __init__(self, joint: ir.Joint, P=None):
        self.joint = joint
        self.P = P                                      # parent joint frame axes in parent body axes
        self.rows: list[tuple[int, str, ca.SX]] = []   # (row in g, 'f' | 't', unit direction in parent joint frame)

    def loads(self, kin, lam) -> tuple[ca.SX, ca.SX]:
        """(force, torque) on the child, world axes, as SX in lam (the parent gets the opposite)."""
        R_P = _axes(kin.body_rot(self.joint.parent_body), self.P)
        F, T = ca.SX.zeros(3, 1), ca.SX.zeros(3, 1)
        for row, what, e in self.rows:
            if what == "f":
                F = F + lam[row] * e
            else:
                T = T + lam[row] * e
        return ca.mtimes(R_P, F), ca.mtimes(R_P, T)


def loop_closures(model: ir.Model, tree: Tree, kin, offset: int = 0) -> tuple[list, list[str], list[Closure]]:
    """Residuals, names and per-joint multiplier directions; rows are numbered from `offset`."""
    res, names, closures = [], [], []
    E3 = ca.SX.eye(3)

    def add(cl, exprs_, nm, what, dirs):
        for x, n_, d in zip(exprs_, nm, dirs):
            cl.rows.append((offset + len(res), what, d))
            res.append(x)
            names.append(n_)

    for joint in model.joints:
        if not joint.closes_loop:
            continue
        P, C = tree.joint_axes(joint)
        R_P, R_C = _axes(kin.body_rot(joint.parent_body), P), _axes(kin.body_rot(joint.child_body), C)
        d = ca.mtimes(R_P.T, kin.point_pos(joint.child) - kin.point_pos(joint.parent))
        R_rel = ca.mtimes(R_P.T, R_C)
        child_point = joint.child_body != "world" and model.body(joint.child_body).kind == "point"
        kind = J.kind_of(joint)
        jn = joint.name
        clo = Closure(joint, P)
        closures.append(clo)
        xyz = [E3[:, i] for i in range(3)]
        if joint.variables or joint.kind == "frame":
            E, p = _joint_motion(tree, joint, kind.elements(joint, child_point))
            g = p - d
            add(clo, [g[i] for i in range(3)], [f"{jn}.f{c}" for c in LETTERS], "f", xyz)
            if not child_point:
                gt = -vee(ca.mtimes(R_rel, E.T))
                add(clo, [gt[i] for i in range(3)], [f"{jn}.t{c}" for c in LETTERS], "t", xyz)
            continue
        cl = kind.closure
        a = tree.unit(joint.axis)
        (e1, e2, e3), ln = basis(a)
        if cl.translation == "all":
            add(clo, [-d[i] for i in range(3)], [f"{jn}.f{c}" for c in LETTERS], "f", xyz)
        elif cl.translation == "perp":
            add(clo, [-ca.dot(e1, d), -ca.dot(e2, d)], [f"{jn}.f{ln[0]}", f"{jn}.f{ln[1]}"], "f", [e1, e2])
        elif cl.translation == "normal":
            add(clo, [-ca.dot(e3, d)], [f"{jn}.f{ln[2]}"], "f", [e3])
        if child_point:
            continue
        if cl.rotation == "full":
            gt = -vee(R_rel)
            add(clo, [gt[i] for i in range(3)], [f"{jn}.t{c}" for c in LETTERS], "t", xyz)
        elif cl.rotation == "axis":
            ra = ca.mtimes(R_rel, e3)
            add(clo, [ca.dot(ra, e2), -ca.dot(ra, e1)], [f"{jn}.t{ln[0]}", f"{jn}.t{ln[1]}"], "t", [e1, e2])
    return res, names, closures


def _axes(R, axes):
    """World axes of a joint frame whose axes in its body are ``axes`` (None: the body's)."""
    return R if axes is None else ca.mtimes(R, axes)


def _joint_motion(tree: Tree, joint: ir.Joint, elements) -> tuple[ca.SX, ca.SX]:
    """(R_j, p_j) of a joint from its element chain (variables in SX, not registered as dofs)."""
    E, p = ca.SX.eye(3), ca.SX.zeros(3, 1)
    for el in elements:
        if el.kind in ("R", "P"):
            a = tree.unit(el.axis)
            x = tree.var(el.vars[0], joint, count=False).x
            if el.kind == "R":
                E = ca.mtimes(E, rot(a, x))
            else:
                p = p + ca.mtimes(E, a * x)
        elif el.kind == "Q":
            x = ca.vertcat(*[tree.var(v, joint, count=False).x for v in el.vars])
            E = ca.mtimes(E, quat_matrix(x))
        elif el.kind == "T":
            p = p + ca.mtimes(E, tree.vec(el.r))
            E = ca.mtimes(E, tree.mat(el.R))
    return E, p
